"""Pinocchio + Crocoddyl + mim_solvers CSQP backend of the reaching DOC (the seed paper's own solver stack).

It solves the problem of :mod:`reachirl.doc.task` on the same discretisation as :mod:`reachirl.features`: ``N
= task.n_nodes`` intervals of ``dt = duration / N``, semi-implicit Euler (Crocoddyl's
``IntegratedActionModelEuler``), control ``u = τ`` and ``x_0 = (q0, 0)``.

Layers, Crocoddyl's vocabulary from the bottom up:

* **State.** ``StateMultibody`` of :meth:`ArmModel.pinocchio_model` (with two extra frames at the segments'
  centres of mass) for the arm; the knots of the shooting problem carry the *augmented* state ``x = (q, q̇,
  τ_prev)`` (``StateVector(6)``) because the torque change ``τ̇_k = (τ_k − τ_{k−1}) / dt`` couples consecutive
  knots.
* **Costs** (Crocoddyl built-ins, C++), one ``CostModelSum`` per knot, items named by :data:`FEATURES`,
  Crocoddyl weight ``2 ω`` because its quadratic activation is ``½‖r‖²``:

  - ``cartesian_velocity``: ``ResidualModelFrameVelocity`` of ``fingertip``, linear part. Its norm is the same
    in every orientation, so the LOCAL frame is used: with pin 4.0.0 + crocoddyl 3.2.1 the LOCAL_WORLD_ALIGNED
    variant's ``∂r/∂q`` is wrong (off by the frame-rotation term; the finite-difference test catches it),
    which made CSQP stall at non-stationary points.
  - ``geodesic``: ``q̇ᵀM(q)q̇ = Σ_i m_i‖v_{c,i}‖² + I_i ω_i²`` (twice the kinetic energy), as two
    ``ResidualModelFrameVelocity`` of the CoM frames with weighted activations ``(m, m, m, 0, 0, I)``; the
    forearm's item is ``geodesic/forearm`` and always carries the same weight as ``geodesic``.
  - ``joint_acceleration``: ``ResidualModelJointAcceleration`` (the forward dynamics ``q̈_k``, which is
    exactly the Euler acceleration ``(q̇_{k+1} − q̇_k) / dt`` of features.py).
  - ``joint_velocity``: ``ResidualModelState`` with activation on ``q̇``.
  - ``joint_torque``: ``ResidualModelControl``.
* **Action model per knot**: wraps the knot's ``IntegratedActionModelEuler`` (C++, dynamics and the costs
  above) and adds the two terms that need the augmented state or are non-smooth, with analytic derivatives
  (Gauss-Newton Hessians, like Crocoddyl's residual costs). It is compiled (``knot.cpp``, built once per machine
  by :mod:`.native`, so that CSQP never calls into Python per knot); :class:`KnotModel` is the same knot in
  Python, bit for bit, used where the compiled one cannot be built or with ``CsqpOptions(compiled_knots=False)``:

  - ``torque_change``: ``(ω/dt) ‖τ_k − τ_{k−1}‖²``, with ``τ_{−1} = g(q0)`` (held at rest) carried in ``x_0``.
  - ``energy``: ``ω dt (√(r² + ε²) − ε)``, ``r = q̇_kᵀτ_k``. This smooth absolute value differs from ``|r|``
    by at most ``ε`` (default 1e-3 W), so ``Φ2`` by at most ``ε · duration``; the reported ``cost`` is always
    :func:`reachirl.features.trajectory_cost` of the solution (the exact, non-smoothed objective).

* **Constraints** (``ConstraintModelManager`` of ``ConstraintModelResidual`` per knot, bounds owned by the
  knot model so a new task only rewrites numbers): ``q_lower ≤ q ≤ q_upper`` and ``|q̇| ≤ qd_max`` on knots
  ``1..N−1``; on the terminal knot the joint bounds, ``q̇_N = 0`` and the fingertip ``x = target_x``
  (equalities as ``lb = ub``, which is how CSQP takes them).

One shooting problem is built per ``(arm, N, n_windows)`` and cached; ``q0``, ``dt``, the target, the bounds
and the weights are updated in place before each solve (weights through ``costs.costs[name].weight``).

* **Solver**: mim_solvers CSQP (Gauss-Newton SQP, each QP solved by ADMM with Riccati sweeps, ~75 µs per
  ADMM iteration here), merit line search. A Python callback (``_Monitor``) replaces CSQP's stopping test by
  a KKT test with a separate absolute feasibility tolerance and an IPOPT-like "acceptable level", and sets
  each QP's tolerance from the last KKT residual (inexact SQP); on a cold start it holds the line search back
  (after α = 1, halving from twice the last accepted step). Why each option is what it is:
  :class:`CsqpOptions`.

The modules: :mod:`.knots` (the knot's action model and cost), :mod:`.native` (the compiled knot),
:mod:`.problem` (the shooting problem), :mod:`.options` (the CSQP settings) and :mod:`.solver` (the stopping
test, the cold start and the retries).
"""

from . import solver
from .knots import CROCODDYL_COST_ITEMS, KnotModel
from .options import DEFAULT_OPTIONS, CsqpOptions
from .problem import ReachingProblem, build_problem
from .solver import initial_guess, solve, weight_scale

__all__ = [
    "CROCODDYL_COST_ITEMS",
    "DEFAULT_OPTIONS",
    "CsqpOptions",
    "KnotModel",
    "ReachingProblem",
    "build_problem",
    "initial_guess",
    "solve",
    "solver",
    "weight_scale",
]
