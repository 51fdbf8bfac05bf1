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
* **Action model per knot** (:class:`KnotModel`, Python): wraps the knot's ``IntegratedActionModelEuler``
  (C++, dynamics and the costs above) and adds the two terms that need the augmented state or are non-smooth,
  with analytic derivatives (Gauss-Newton Hessians, like Crocoddyl's residual costs):

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
"""

from __future__ import annotations

import functools
import logging
import math
import threading
import time
from dataclasses import dataclass, replace

import crocoddyl
import mim_solvers
import numpy as np
import pinocchio as pin

from ..arm import ArmModel
from ..errors import interrupt_pending, solver_interrupts
from ..features import FEATURES, N_FEATURES, euler_knots, trajectory_cost, window_index
from .task import DocSolution, ReachingTask, min_jerk, rest_to_rest_knots

__all__ = [
    "CROCODDYL_COST_ITEMS", "CsqpOptions", "KnotModel", "ReachingProblem", "build_problem", "solve", "weight_scale",
]

log = logging.getLogger(__name__)

# Feature -> the Crocoddyl cost items that carry it (built-in, inside each knot's CostModelSum).
CROCODDYL_COST_ITEMS: dict[str, tuple[str, ...]] = {
    "cartesian_velocity": ("cartesian_velocity",),
    "geodesic": ("geodesic", "geodesic/forearm"),
    "joint_acceleration": ("joint_acceleration",),
    "joint_velocity": ("joint_velocity",),
    "joint_torque": ("joint_torque",),
}
_J_ENERGY = FEATURES.index("energy")
_J_TORQUE_CHANGE = FEATURES.index("torque_change")
_NX, _NU = 6, 2  # augmented state (q, q̇, τ_prev) and control τ


@dataclass(frozen=True)
class CsqpOptions:
    """CSQP settings of the Crocoddyl backend (tuned on the problems of ``benchmarks/bench_backends.py``; the
    measurements behind each value are in ``docs/design-notes.md``, "CSQP settings").

    Convergence, tested after each QP by :class:`_Monitor` (which replaces CSQP's own test):

    * ``termination_tolerance``: CSQP's KKT residual (max-norm of the Lagrangian gradient, the dynamics gaps and
      the constraint violation) must fall below it, relative to the cold initial guess's cost per knot
      ``J(guess) / N``, so that it depends neither on the scale of the weights nor on a warm start.
    * ``feasibility_tolerance`` (absolute: rad, rad/s, N·m, m): the gaps' max-norm and the constraints' summed
      violation must also fall below it.
    * ``acceptable_factor``, ``acceptable_iter``, ``acceptable_cost_change``: as IPOPT's "solved to an acceptable
      level", a feasible point whose KKT residual stays within ``acceptable_factor`` × the tolerance for
      ``acceptable_iter`` iterations while the cost moves by less than ``acceptable_cost_change`` (relative)
      counts as converged, and so does an acceptable point where no descent step exists even along a tight-QP
      direction (ADMM's multipliers are only as accurate as its tolerance, so CSQP's final convergence is
      linear).
    * ``max_iter``: SQP iterations at most.

    QPs (ADMM):

    * inexact SQP: each QP's tolerance (``eps_abs``; ``eps_rel = 0``) follows the last KKT residual,
      ``clip(qp_forcing · KKT, qp_eps_min · tol, qp_eps_max)``; ``max_qp_iters`` bounds a QP's iterations.
    * ``reset_rho = False``: ADMM's penalty ρ carries over from one QP to the next; ``adaptive_rho_tolerance``
      lets ADMM change ρ only when its estimate is that many times off.
    * ``admm_relaxation``: ADMM's over-relaxation α (1: none; CSQP's default is 1.6).
    * ``rho_update_interval``: how often ADMM updates ρ, which is also how often it tests its residuals, so a QP
      takes at least that many iterations.
    * when CSQP stops early (no acceptable step along an inexact QP direction) it is restarted from where it
      stopped with the tightest QP tolerance.
    * ``qp_stall_ratio``, ``qp_stall_window``: when the KKT residual has not fallen below ``qp_stall_ratio`` × its
      value ``qp_stall_window`` QPs before, the cap on the QP tolerance is cut tenfold (down to
      ``qp_eps_min · tol``).

    Scale and merit:

    * ``objective_scale``: CSQP is not scale-invariant (its merit penalty, ADMM's ρ and its tolerances are
      absolute numbers), so the weights are multiplied by ``objective_scale / J(cold guess)`` inside the solver;
      the minimiser does not change, and the reported ``cost`` is the unscaled one.
    * ``merit_penalty``, ``merit_penalty_factor``: the line search's ℓ1 merit ``J + μ_dyn‖gaps‖₁ +
      μ_c‖violation‖₁`` is an exact penalty only when μ exceeds the multipliers; the monitor raises μ_dyn and μ_c
      (never lowers them) from ``merit_penalty`` to ``merit_penalty_factor`` × the largest dynamics and
      constraint multipliers of the last QP. ``use_filter_line_search`` selects CSQP's filter line search
      instead.
    * ``energy_smoothing``: ε of the smooth energy ``√(r² + ε²) − ε``, in W.
    * ``energy_exact_hessian``: add the energy's ``d1·∂²r/∂q̇∂τ`` term to the Gauss-Newton Hessian.
    * ``fallback_exact_hessian``: a failed solve is solved again, cold, with the exact energy Hessian
      (``DocSolution.attempts`` = 2; iterations and time add up), as the CasADi backend falls back from fatrop
      to IPOPT; ``fallback_smoothing_factor``: a solve that still fails is solved once more, cold, with ε × this
      factor and refined at ε from that solution (0: off).

    Speed:

    * ``screen_bounds``: the running knots' joint limits and speed bound (400 rows at N = 100) are left out of
      the first solve (infinite bounds, which ADMM never projects). A screened solution that meets every bound
      (to ``feasibility_tolerance``) is a KKT point of the full problem as well, with zero multipliers on the
      bounds; one that breaks a bound is solved again with every bound, warm from there, and a screened solve
      that fails is solved again with every bound from the original start (``DocSolution.attempts`` counts
      both).
    * ``line_search_growth``: after α = 1, a cold solve's line search halves from min(½, growth × the last
      accepted α), rounded down to a power of two, instead of from ½ (the monitor sets ``alphas`` before each
      search); 0 keeps CSQP's own search, which warm starts and retries always use.
    """

    max_iter: int = 200
    termination_tolerance: float = 5e-3
    feasibility_tolerance: float = 1e-5
    acceptable_factor: float = 10.0
    acceptable_iter: int = 3
    acceptable_cost_change: float = 1e-6
    max_qp_iters: int = 1000
    qp_eps_max: float = 1e-3
    qp_eps_min: float = 0.1
    qp_forcing: float = 0.1
    qp_stall_ratio: float = 0.5  # KKT not below this × the last qp_stall_window: tighten the QP tolerance cap
    qp_stall_window: int = 2
    reset_rho: bool = False
    admm_relaxation: float = 1.0  # ADMM's over-relaxation α (CSQP's default 1.6)
    rho_update_interval: int = 25
    adaptive_rho_tolerance: int = 20
    merit_penalty: float = 10.0
    merit_penalty_factor: float = 1.2  # >0: raise the penalties to this factor × the largest multipliers
    energy_smoothing: float = 1e-3  # ε of the smooth |q̇ᵀτ|, in W
    objective_scale: float = 10.0  # the weights are scaled so that the cold guess costs this much
    use_filter_line_search: bool = False
    energy_exact_hessian: bool = False  # add the energy's d1·∂²r/∂q̇∂τ term (not Gauss-Newton)
    fallback_exact_hessian: bool = True  # a failed solve is solved again, cold, with energy_exact_hessian
    fallback_smoothing_factor: float = 10.0  # then with ε × this (cold), refined at ε from there; 0: off
    screen_bounds: bool = True  # first solve without the running knots' joint-limit and speed bounds
    line_search_growth: float = 2.0  # >0: after α = 1, a cold line search starts at min(½, this × last α)


DEFAULT_OPTIONS = CsqpOptions()


# ---------------------------------------------------------------------- the knot model
class KnotData(crocoddyl.ActionDataAbstract):
    """The knot's data, with numpy views of its own and the inner model's arrays made once (the arrays never
    move): each eigenpy attribute access builds a new view (~1 µs), and copying into a ready view with
    ``np.copyto`` costs half of a sliced assignment."""

    def __init__(self, model: KnotModel):
        crocoddyl.ActionDataAbstract.__init__(self, model)
        self.inner = di = model.inner.createData()
        self.Fu[4:, :] = np.eye(_NU)  # τ_prev at the next knot is this knot's τ
        Fx, Fu, Lx, Lu, Lxx, Lxu, Luu = self.Fx, self.Fu, self.Lx, self.Lu, self.Lxx, self.Lxu, self.Luu
        self.xnext_, self.g_, self.Lx_, self.Lu_, self.Lxx_, self.Lxu_, self.Luu_ = (
            self.xnext, self.g, Lx, Lu, Lxx, Lxu, Luu)
        # (destination view, source view) pairs copied after the inner model's calcDiff
        self.copies_running = [(Fx[:4, :4], di.Fx), (Fu[:4], di.Fu), (Lx[:4], di.Lx), (Lu, di.Lu),
                               (Lxx[:4, :4], di.Lxx), (Lxu[:4], di.Lxu), (Luu, di.Luu)]
        self.copies_terminal = [(Lx[:4], di.Lx), (Lxx[:4, :4], di.Lxx)]
        if model.n_constraints:
            self.copies_running += [(self.Gx[:, :4], di.Gx), (self.Gu, di.Gu)]
            self.copies_terminal.append((self.Gx[:, :4], di.Gx))
        self.inner_xnext, self.inner_g = di.xnext, di.g
        self.xnext4, self.xnext_tau = self.xnext[:4], self.xnext[4:]


class KnotModel(crocoddyl.ActionModelAbstract):
    """One knot of the reach with the augmented state ``x = (q, q̇, τ_prev)`` and control ``u = τ``.

    ``inner`` is the knot's ``IntegratedActionModelEuler`` on ``(q, q̇)``; it holds the built-in costs (its
    differential model's ``costs``) and constraints. This model adds ``energy`` and ``torque_change`` and owns
    the constraint bounds ``g_lb``/``g_ub``. Set the knot's weights with :meth:`set_weights`.
    """

    def __init__(self, inner, first: bool, terminal: bool, energy_smoothing: float):
        self.inner = inner
        self.dam = inner.differential
        self.costs = self.dam.costs
        ng = int(self.dam.constraints.ng) if self.dam.constraints is not None else 0
        crocoddyl.ActionModelAbstract.__init__(self, crocoddyl.StateVector(_NX), _NU, 1, ng, 0)
        self.first, self.terminal = first, terminal
        self.n_constraints = ng
        self.eps = float(energy_smoothing)
        self.exact_hessian = False
        self.dt = float(inner.dt)
        self.w_energy = 0.0
        self.w_torque_change = 0.0
        # keep the cost items (shared with the C++ sum) to change their weights without a map lookup
        self._items = (
            {name: self.costs.costs[name] for names in CROCODDYL_COST_ITEMS.values() for name in names}
            if not terminal
            else {}
        )

    def createData(self):  # noqa: N802  (Crocoddyl's API)
        return KnotData(self)

    def set_dt(self, dt: float) -> None:
        self.dt = float(dt)
        if not self.terminal:
            self.inner.dt = self.dt

    def set_weights(self, w: np.ndarray) -> None:
        """This knot's row of ω (7 numbers in FEATURES order)."""
        for feature, names in CROCODDYL_COST_ITEMS.items():
            weight = 2.0 * float(w[FEATURES.index(feature)])
            for name in names:
                self._items[name].weight = weight
        self.w_energy = float(w[_J_ENERGY])
        self.w_torque_change = float(w[_J_TORQUE_CHANGE])

    # Crocoddyl calls calc(data, x) on the terminal knot and calc(data, x, u) on the others.
    def calc(self, data, x, u=None):
        di = data.inner
        if u is None or self.terminal:
            self.inner.calc(di, x[:4])
            data.cost = di.cost
            np.copyto(data.xnext_, x)
        else:
            self.inner.calc(di, x[:4], u)
            cost = di.cost
            if self.w_energy > 0.0 or self.w_torque_change > 0.0:
                _, _, v0, v1, p0, p1 = x.tolist()
                u0, u1 = u.tolist()
                if self.w_energy > 0.0:
                    r = v0 * u0 + v1 * u1
                    cost += self.w_energy * self.dt * (math.sqrt(r * r + self.eps * self.eps) - self.eps)
                if self.w_torque_change > 0.0:
                    d0, d1 = u0 - p0, u1 - p1
                    cost += self.w_torque_change / self.dt * (d0 * d0 + d1 * d1)
            data.cost = cost
            np.copyto(data.xnext4, data.inner_xnext)
            np.copyto(data.xnext_tau, u)
        if self.n_constraints:
            np.copyto(data.g_, data.inner_g)

    def calcDiff(self, data, x, u=None):  # noqa: N802  (Crocoddyl's API)
        di = data.inner
        if u is None or self.terminal:
            self.inner.calcDiff(di, x[:4])
            for dst, src in data.copies_terminal:
                np.copyto(dst, src)
            return
        self.inner.calcDiff(di, x[:4], u)
        for dst, src in data.copies_running:
            np.copyto(dst, src)
        Lx, Lu, Lxx, Lxu, Luu = data.Lx_, data.Lu_, data.Lxx_, data.Lxu_, data.Luu_
        # the two Python terms, in scalars (numpy calls on 2-vectors cost more than the arithmetic)
        _, _, v0, v1, p0, p1 = x.tolist()
        u0, u1 = u.tolist()
        if self.w_energy > 0.0:
            r = v0 * u0 + v1 * u1
            s = math.sqrt(r * r + self.eps * self.eps)
            c = self.w_energy * self.dt
            d1 = c * r / s  # first and second derivative of the smooth |r|
            d2 = c * self.eps * self.eps / (s * s * s)
            Lx[2] += d1 * u0
            Lx[3] += d1 * u1
            Lu[0] += d1 * v0
            Lu[1] += d1 * v1
            # Gauss-Newton, like Crocoddyl's residual costs: the term d1·∂²r/∂q̇∂τ = d1·I is left out
            a, b, e = d2 * u0 * u0, d2 * u0 * u1, d2 * u1 * u1
            Lxx[2, 2] += a
            Lxx[2, 3] += b
            Lxx[3, 2] += b
            Lxx[3, 3] += e
            h = d1 if self.exact_hessian else 0.0  # d1·∂²r/∂q̇∂τ = d1·I
            Lxu[2, 0] += d2 * u0 * v0 + h
            Lxu[2, 1] += d2 * u0 * v1
            Lxu[3, 0] += d2 * u1 * v0
            Lxu[3, 1] += d2 * u1 * v1 + h
            a, b, e = d2 * v0 * v0, d2 * v0 * v1, d2 * v1 * v1
            Luu[0, 0] += a
            Luu[0, 1] += b
            Luu[1, 0] += b
            Luu[1, 1] += e
        # always written (τ_prev's entries are not copied from the inner model, and a weight may become 0)
        c = 2.0 * self.w_torque_change / self.dt
        d0, d1 = c * (u0 - p0), c * (u1 - p1)
        Lx[4], Lx[5] = -d0, -d1
        Lxx[4, 4] = Lxx[5, 5] = c
        Lxu[4, 0] = Lxu[5, 1] = -c
        if c > 0.0:
            Lu[0] += d0
            Lu[1] += d1
            Luu[0, 0] += c
            Luu[1, 1] += c


# ---------------------------------------------------------------------- the problem
def _com_frames(model, arm: ArmModel) -> tuple[int, int]:
    """Add a frame at each segment's centre of mass; return their ids."""
    ids = []
    for name, joint, c in (("upper_arm_com", 1, arm.c1), ("forearm_com", 2, arm.c2)):
        ids.append(
            model.addFrame(
                pin.Frame(name, joint, 0, pin.SE3(np.eye(3), np.array([c, 0.0, 0.0])), pin.FrameType.OP_FRAME)
            )
        )
    return ids[0], ids[1]


class ReachingProblem:
    """The Crocoddyl shooting problem of one ``(arm, N, n_windows)`` shape; tasks and weights go in in place.
    """

    def __init__(self, arm: ArmModel, n: int, n_windows: int, options: CsqpOptions = DEFAULT_OPTIONS):
        self.arm, self.n, self.n_windows, self.options = arm, n, n_windows, options
        self.window = window_index(n, n_windows)
        model = arm.pinocchio_model()
        com1, com2 = _com_frames(model, arm)
        self.pin_model = model
        state = crocoddyl.StateMultibody(model)
        actuation = crocoddyl.ActuationModelFull(state)
        nu = actuation.nu
        tip = model.getFrameId("fingertip")
        zero_motion = pin.Motion.Zero()
        local = pin.ReferenceFrame.LOCAL  # not LOCAL_WORLD_ALIGNED: see the module docstring

        def cost(residual, activation=None):
            if activation is None:
                return crocoddyl.CostModelResidual(state, residual)
            return crocoddyl.CostModelResidual(state, activation, residual)

        # Cost models are stateless; the knots share them and keep their own weights in their sums.
        cost_models = {
            "cartesian_velocity": cost(
                crocoddyl.ResidualModelFrameVelocity(state, tip, zero_motion, local, nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])),
            ),
            "geodesic": cost(
                crocoddyl.ResidualModelFrameVelocity(state, com1, zero_motion, local, nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([arm.m1] * 3 + [0.0, 0.0, arm.i1])),
            ),
            "geodesic/forearm": cost(
                crocoddyl.ResidualModelFrameVelocity(state, com2, zero_motion, local, nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([arm.m2] * 3 + [0.0, 0.0, arm.i2])),
            ),
            "joint_acceleration": cost(crocoddyl.ResidualModelJointAcceleration(state, nu)),
            "joint_velocity": cost(
                crocoddyl.ResidualModelState(state, np.zeros(4), nu),
                crocoddyl.ActivationModelWeightedQuad(np.array([0.0, 0.0, 1.0, 1.0])),
            ),
            "joint_torque": cost(crocoddyl.ResidualModelControl(state, nu)),
        }
        inf = np.full(4, np.inf)
        bounds_residual = crocoddyl.ResidualModelState(state, np.zeros(4), nu)
        tip_residual = crocoddyl.ResidualModelFrameTranslation(state, tip, np.zeros(3), nu)

        dt = 1.0 / n
        running = []
        for k in range(n):
            costs = crocoddyl.CostModelSum(state, nu)
            for name, c in cost_models.items():
                costs.addCost(name, c, 0.0)
            constraints = crocoddyl.ConstraintModelManager(state, nu)
            if k > 0:  # x_0 is fixed
                constraints.addConstraint(
                    "state_bounds", crocoddyl.ConstraintModelResidual(state, bounds_residual, -inf, inf)
                )
            dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs, constraints)
            running.append(
                KnotModel(
                    crocoddyl.IntegratedActionModelEuler(dam, dt),
                    first=(k == 0),
                    terminal=False,
                    energy_smoothing=options.energy_smoothing,
                )
            )
        costs = crocoddyl.CostModelSum(state, nu)
        constraints = crocoddyl.ConstraintModelManager(state, nu)
        constraints.addConstraint(
            "state_bounds", crocoddyl.ConstraintModelResidual(state, bounds_residual, -inf, inf)
        )
        constraints.addConstraint(
            "fingertip",
            crocoddyl.ConstraintModelResidual(state, tip_residual, np.full(3, -np.inf), np.full(3, np.inf)),
        )
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs, constraints)
        terminal = KnotModel(
            crocoddyl.IntegratedActionModelEuler(dam, 0.0),
            first=False,
            terminal=True,
            energy_smoothing=options.energy_smoothing,
        )
        self.running, self.terminal = running, terminal
        self.problem = crocoddyl.ShootingProblem(np.zeros(_NX), running, terminal)
        self.lock = threading.Lock()

    def update(self, task: ReachingTask, weights: np.ndarray, running_bounds: bool = True) -> None:
        """Write the task's numbers and the weights into the problem (no rebuild). With ``running_bounds``
        false the running knots' joint-limit and speed rows get infinite bounds: CSQP's ADMM then gives them
        its minimal penalty and never projects them (the terminal knot keeps all of its constraints)."""
        if task.arm != self.arm or task.n_nodes != self.n or weights.shape != (self.n_windows, N_FEATURES):
            raise ValueError("task or weights do not match this problem's shape")
        self.problem.x0 = np.r_[task.q0, 0.0, 0.0, task.arm.gravity_torque(task.q0)]  # at rest: τ_{−1} = g(q0)
        if running_bounds:
            lb = np.r_[task.q_lower, -task.qd_max]
            ub = np.r_[task.q_upper, task.qd_max]
        else:
            lb, ub = np.full(4, -np.inf), np.full(4, np.inf)
        for k, m in enumerate(self.running):
            m.exact_hessian = self.options.energy_exact_hessian
            m.set_dt(task.dt)
            m.set_weights(weights[self.window[k]])
            if m.n_constraints:
                m.g_lb, m.g_ub = lb, ub
        # the manager stacks its constraints in the order of their names: "fingertip", then "state_bounds"
        t = self.terminal
        t.g_lb = np.r_[task.target_x, -np.inf, -np.inf, task.q_lower, 0.0, 0.0]
        t.g_ub = np.r_[task.target_x, np.inf, np.inf, task.q_upper, 0.0, 0.0]

    def make_solver(self, tolerance: float, eps: float, callbacks=()):
        """A fresh CSQP solver (no state carried over from earlier solves, so results are reproducible) with the
        KKT tolerance ``tolerance`` and QP tolerance ``eps``.
        """
        o = self.options
        solver = mim_solvers.SolverCSQP(self.problem)
        solver.termination_tolerance = tolerance
        solver.max_qp_iters = o.max_qp_iters
        solver.eps_abs = eps
        solver.eps_rel = 0.0
        solver.reset_rho = o.reset_rho
        solver.alpha = o.admm_relaxation
        solver.rho_update_interval = o.rho_update_interval
        solver.adaptive_rho_tolerance = o.adaptive_rho_tolerance
        solver.mu_dynamic = solver.mu_constraint = o.merit_penalty
        solver.use_filter_line_search = o.use_filter_line_search
        solver.with_callbacks = False
        if callbacks:
            solver.setCallbacks(list(callbacks))
        return solver


class _Monitor(mim_solvers.CallbackAbstract):
    """CSQP's callback, run after each QP just before CSQP's own test ``KKT <= termination_tolerance``.

    It replaces that test by the one of :class:`CsqpOptions` (setting ``termination_tolerance`` to the KKT
    residual to stop, to −1 to go on), sets the next QP's tolerance and, with ``line_search_growth``, the next line
    search's step lengths.
    """

    def __init__(self, tol: float, options: CsqpOptions):
        mim_solvers.CallbackAbstract.__init__(self)
        self.tol, self.o = tol, options
        self.eps_min = options.qp_eps_min * tol
        self.eps_max = options.qp_eps_max
        self.history: list[tuple[float, float, float, float, int]] = []  # KKT, cost, gaps, constraints, QP iters
        self.reason = ""
        self.acceptable = False  # the last point is feasible and its KKT residual within acceptable_factor·tol
        self._n_acceptable = 0
        self.mu = (options.merit_penalty, options.merit_penalty)  # CSQP's (mu_dynamic, mu_constraint)
        self._tightened = 0  # len(history) when the QP tolerance cap was last tightened
        self._last_step: tuple[np.ndarray, np.ndarray] | None = None  # (us, du) of the last QP

    def __call__(self, solver, name):
        o = self.o
        kkt, cost, cons = float(solver.KKT), float(solver.cost), float(solver.constraint_norm)
        # one array per list (eigenpy builds a list of 101 vectors per access; a max per vector costs 4 µs)
        gap = float(np.abs(np.concatenate(solver.fs)).max())
        self.history.append((kkt, cost, gap, cons, int(solver.qp_iters)))
        feasible = gap <= o.feasibility_tolerance and cons <= o.feasibility_tolerance
        self.acceptable = feasible and kkt <= o.acceptable_factor * self.tol
        stop = False
        if interrupt_pending():  # Ctrl-C or SIGTERM: stop now; solver_interrupts raises it after the solve
            stop, self.reason = True, "interrupted"
        elif feasible and kkt <= self.tol:
            stop, self.reason = True, "converged"
        elif self.acceptable:
            self._n_acceptable += 1
            costs = [h[1] for h in self.history[-o.acceptable_iter - 1 :]]
            if (
                self._n_acceptable >= o.acceptable_iter
                and max(costs) - min(costs) <= o.acceptable_cost_change * abs(cost)
            ):
                stop, self.reason = True, "converged to an acceptable level"
        else:
            self._n_acceptable = 0
        if o.merit_penalty_factor > 0.0:
            # the ℓ1 merit is an exact penalty only while its penalties exceed the multipliers (‖λ‖∞, ‖y‖∞),
            # which grow with the weights: raise them (never lower them) before the line search
            lam = float(np.abs(np.concatenate(solver.lag_mul)).max())
            y = np.abs(np.concatenate(solver.y))
            y = float(y.max()) if y.size else 0.0
            self.mu = (max(self.mu[0], o.merit_penalty_factor * lam), max(self.mu[1], o.merit_penalty_factor * y))
            solver.mu_dynamic, solver.mu_constraint = self.mu
        solver.termination_tolerance = kkt if stop else -1.0
        # inexact SQP: the QP tolerance follows the KKT residual, but ADMM's own residuals (ρ times the change
        # of its iterates) can pass a loose tolerance while its multipliers are still far off, and the SQP then
        # cycles with a KKT residual that never falls: when the KKT residual has not halved in qp_stall_window QPs,
        # tighten the cap on the QP tolerance tenfold (down to eps_min)
        kkts = [h[0] for h in self.history[-o.qp_stall_window - 1 : -1]]
        since = len(self.history) - self._tightened
        if since > o.qp_stall_window and kkt > o.qp_stall_ratio * min(kkts):
            self.eps_max = max(self.eps_min, 0.1 * self.eps_max)
            self._tightened = len(self.history)
        solver.eps_abs = min(self.eps_max, max(self.eps_min, o.qp_forcing * kkt))
        if o.line_search_growth > 0.0 and not stop:
            self._set_step_lengths(solver)

    def _set_step_lengths(self, solver) -> None:
        """The next line search tries α = 1, then halves from min(½, growth × the last accepted α), rounded down
        to a power of two (the last α is the controls' move along the last QP's direction: ``us`` and ``du``
        move together)."""
        u, du = np.concatenate(solver.us), np.concatenate(solver.du)
        start = 0.5
        if self._last_step is not None:
            u0, du0 = self._last_step
            den = float(du0 @ du0)
            alpha = float((u - u0) @ du0) / den if den > 0.0 else 0.0
            if alpha > 0.0:
                start = min(0.5, self.o.line_search_growth * alpha)
        self._last_step = (u, du)
        k = max(1, math.ceil(-math.log2(start) - 1e-9))
        solver.alphas = [1.0] + [2.0**-j for j in range(k, k + 9)]


def build_problem(
    arm: ArmModel, n: int, n_windows: int, options: CsqpOptions | None = None
) -> ReachingProblem:
    """The cached problem of one ``(arm, N, n_windows)`` shape (and solver options)."""
    return _cached_problem(arm, int(n), int(n_windows), options or DEFAULT_OPTIONS)


@functools.lru_cache(maxsize=8)
def _cached_problem(arm: ArmModel, n: int, n_windows: int, options: CsqpOptions) -> ReachingProblem:
    t0 = time.perf_counter()
    p = ReachingProblem(arm, n, n_windows, options)
    log.debug(
        "built the Crocoddyl problem N=%d, %d windows in %.3f s", n, n_windows, time.perf_counter() - t0
    )
    return p


# ---------------------------------------------------------------------- initial guess and solve
def initial_guess(task: ReachingTask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A dynamically consistent cold start ``(q, q̇, τ)``: a minimum-jerk joint path from ``q0`` to the
    posture with the fingertip on the bar at (at most) its starting height, q̇ by Euler differences, τ by
    inverse dynamics.
    """
    arm, n, dt = task.arm, task.n_nodes, task.dt
    y0 = float(arm.fk(task.q0)[1])
    y_max = np.sqrt(max((0.98 * arm.length) ** 2 - task.target_x**2, 0.0))
    qf = np.clip(
        arm.ik(np.array([task.target_x, np.clip(y0, -y_max, y_max)])),
        task.q_lower + 1e-3,
        task.q_upper - 1e-3,
    )
    q = task.q0 + min_jerk(np.linspace(0.0, 1.0, n + 1))[:, None] * (qf - task.q0)
    q[-1] = q[-2]
    return euler_knots(arm, q, dt)


def _to_shooting(task: ReachingTask, q, qd, tau) -> tuple[list[np.ndarray], list[np.ndarray]]:
    g0 = task.arm.gravity_torque(task.q0)  # at rest before the reach: τ_{−1} = g(q0)
    tau_prev = np.vstack([g0, tau])
    xs = np.hstack([q, qd, tau_prev])
    xs[0] = np.r_[task.q0, 0.0, 0.0, g0]
    return list(xs), list(np.asarray(tau, dtype=float))


def _task_key(task: ReachingTask) -> tuple:
    """What must match for a warm start: everything in the task but the weights."""
    return (task.n_nodes, task.arm, tuple(task.q0), task.target_x, task.duration, tuple(task.q_lower),
            tuple(task.q_upper), tuple(task.qd_max))


def weight_scale(task: ReachingTask, weights: np.ndarray, options: CsqpOptions | None = None,
                 cold=None) -> tuple[float, float]:
    """``(scale, J0)``: the solver sees ``scale × weights``, with ``J0`` the cost of the cold guess (``cold``,
    by default :func:`initial_guess`) under ``weights``, so that the cold guess costs
    ``options.objective_scale`` (scale 1 when that is ≤ 0)."""
    options = options or DEFAULT_OPTIONS
    xs, us = cold if cold is not None else _to_shooting(task, *initial_guess(task))
    x = np.asarray(xs)
    j0 = trajectory_cost(task.arm, x[:, :2], x[:, 2:4], np.asarray(us), task.dt, weights)
    scale = options.objective_scale / max(j0, 1e-12) if options.objective_scale > 0 else 1.0
    return scale, j0


def _bound_violation(task: ReachingTask, X: np.ndarray) -> float:
    """The largest violation of the joint limits and the speed bound along the states ``X`` (rad, rad/s)."""
    q, qd = X[:, :2], X[:, 2:4]
    return float(max(np.max(q - task.q_upper), np.max(task.q_lower - q), np.max(np.abs(qd) - task.qd_max), 0.0))


def _attempt(prob: ReachingProblem, task: ReachingTask, weights: np.ndarray, xs, us, tol: float,
             options: CsqpOptions, running_bounds: bool = True):
    """One CSQP solve (and its polishing restart) of ``prob`` under the (scaled) ``weights`` from ``(xs, us)``:
    ``(ok, X, U, monitor, iterations, seconds)``."""
    with prob.lock:  # one problem's data is not re-entrant
        prob.update(task, weights, running_bounds)
        t0 = time.perf_counter()
        monitor = _Monitor(tol, options)
        solver = prob.make_solver(tol, options.qp_eps_max, [monitor])
        # a signal is only recorded meanwhile (a Python exception inside CSQP aborts the process): the monitor
        # stops the solve at the next QP and the signal is raised when the guard ends
        with solver_interrupts(stop_solver=False):
            ok = bool(solver.solve(list(xs), list(us), options.max_iter, False))
        iterations = int(solver.iter)
        if not ok and iterations < options.max_iter:
            # stopped early (no acceptable step along an inexact QP direction): polish with tight QPs
            monitor.eps_max = monitor.eps_min
            polisher = prob.make_solver(tol, monitor.eps_min, [monitor])
            polisher.mu_dynamic, polisher.mu_constraint = monitor.mu
            with solver_interrupts(stop_solver=False):
                ok = bool(polisher.solve(list(solver.xs), list(solver.us), options.max_iter - iterations, False))
            iterations += int(polisher.iter)
            solver = polisher
            if not ok and iterations < options.max_iter and monitor.acceptable:
                # no descent step even along an accurate QP direction: stop if the point is acceptable
                ok, monitor.reason = True, "converged to an acceptable level (no descent step)"
        elapsed = time.perf_counter() - t0
        return ok, np.array(solver.xs), np.array(solver.us), monitor, iterations, elapsed


def solve(
    task: ReachingTask,
    weights: np.ndarray,
    warm_start: DocSolution | None = None,
    options: CsqpOptions | None = None,
    guess: np.ndarray | None = None,
) -> DocSolution:
    """Solve the reaching DOC with CSQP; ``warm_start`` (a previous Crocoddyl solution of the same task, under
    other weights) seeds the primal trajectory ``(q, q̇, τ)`` (CSQP has no dual warm start); a solution of
    another task (or backend) is ignored, as :func:`reachirl.doc.solve_doc` documents (warm-start timings:
    ``reachirl bench backends``).
    ``status`` reports the last KKT residual, the gaps' max-norm, the summed constraint violation and the ADMM
    iterations of all QPs.
    """
    options = options or DEFAULT_OPTIONS
    weights = np.asarray(weights, dtype=float)
    n = task.n_nodes
    prob = build_problem(task.arm, n, weights.shape[0], options)
    cold = _to_shooting(task, *(initial_guess(task) if guess is None else rest_to_rest_knots(task, guess)))
    warm = warm_start.warm if warm_start is not None else None
    warm_used = bool(warm and warm.get("backend") == "crocoddyl" and warm.get("task") == _task_key(task))
    if warm_used:
        xs, us = _to_shooting(
            task, np.asarray(warm_start.q), np.asarray(warm_start.qd), np.asarray(warm_start.tau)
        )
    else:
        xs, us = cold
    # CSQP is not scale-invariant (its merit penalty, ADMM penalty and QP tolerances are absolute): solve with
    # the weights scaled so that the cold guess costs ``objective_scale``, as the CasADi backend normalises its
    # objective. The minimiser is the same; the reported cost is that of the unscaled weights.
    scale, j0 = weight_scale(task, weights, options, cold)
    # the tolerance depends on the task and the weights only (the cold guess's cost), not on the warm start
    tol = options.termination_tolerance * j0 * scale / n
    # The joint limits and the speed bound are inactive on almost every reach, but each of their 400 rows slows
    # CSQP's ADMM: with screen_bounds, solve without them first. A solution that meets them all is a KKT point of
    # the full problem too (their multipliers are zero); one that breaks one is solved again with every bound,
    # warm from there, and a failed screened solve again from the same start.
    screened = options.screen_bounds
    # line_search_growth holds back the steps of a cold first attempt only; warm starts and every retry use
    # CSQP's own line search
    retry = replace(options, line_search_growth=0.0)
    ok, X, U, monitor, iterations, elapsed = _attempt(
        prob, task, weights * scale, xs, us, tol, retry if warm_used else options, running_bounds=not screened)
    attempts = 1
    if screened and not (ok and _bound_violation(task, X) <= options.feasibility_tolerance):
        start = (list(X), list(U)) if ok else (xs, us)
        ok, X, U, monitor, it1, el1 = _attempt(prob, task, weights * scale, *start, tol, retry)
        iterations, elapsed, attempts = iterations + it1, elapsed + el1, 2
    if not ok and options.fallback_exact_hessian and np.any(weights[:, _J_ENERGY] > 0):
        # the Gauss-Newton model of the energy can make the SQP cycle: solve again, cold, with its full Hessian
        fallback = replace(retry, energy_exact_hessian=True, fallback_exact_hessian=False)
        prob2 = build_problem(task.arm, n, weights.shape[0], fallback)
        ok, X, U, monitor, it2, el2 = _attempt(prob2, task, weights * scale, *cold, tol, fallback)
        iterations, elapsed, attempts = iterations + it2, elapsed + el2, attempts + 1
    if not ok and options.fallback_smoothing_factor > 0 and np.any(weights[:, _J_ENERGY] > 0):
        # continuation in the energy's smoothing: the kink of |q̇ᵀτ| can stall CSQP (KKT stuck at ~0.1 on some
        # learned weights); solve with a smoother energy first, then at ε from that solution
        smooth = replace(retry, energy_smoothing=options.energy_smoothing * options.fallback_smoothing_factor,
                         fallback_exact_hessian=False, fallback_smoothing_factor=0.0)
        prob3 = build_problem(task.arm, n, weights.shape[0], smooth)
        ok3, X3, U3, _, it3, el3 = _attempt(prob3, task, weights * scale, *cold, tol, smooth)
        iterations, elapsed, attempts = iterations + it3, elapsed + el3, attempts + 1
        if ok3:
            ok, X, U, monitor, it4, el4 = _attempt(prob, task, weights * scale, list(X3), list(U3), tol, retry)
            iterations, elapsed, attempts = iterations + it4, elapsed + el4, attempts + 1
    kkt, _, gap, cons, _ = monitor.history[-1] if monitor.history else (math.nan,) * 5
    qp_iters = sum(h[4] for h in monitor.history)
    q, qd, tau = X[:, :2], X[:, 2:4], U
    finite = bool(np.all(np.isfinite(X)) and np.all(np.isfinite(U)))
    cost = trajectory_cost(task.arm, q, qd, tau, task.dt, weights) if finite else float("nan")
    status = (
        f"{monitor.reason if ok else 'not converged'} (KKT {kkt:.2e} for a tolerance of {tol:.1e}, gaps {gap:.1e}, "
        f"constraints {cons:.1e}, {qp_iters} QP iterations)"
    )
    return DocSolution(
        t=task.t,
        q=q.copy(),
        qd=qd.copy(),
        tau=tau.copy(),
        cost=cost,
        converged=ok and finite,
        iterations=iterations,
        solve_time=elapsed,
        status=status,
        backend="crocoddyl",
        attempts=attempts,
        warm={"backend": "crocoddyl", "task": _task_key(task)},
    )
