"""The CSQP settings of the Crocoddyl backend."""

from __future__ import annotations

from dataclasses import dataclass


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
    * ``compiled_knots``: the knots' ``calc`` and ``calcDiff`` run compiled (:mod:`reachirl.doc.crocoddyl.native`;
      the same arithmetic, bit-identical results), or in Python (:class:`KnotModel`) when false or where the
      compiled knot cannot be built.
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
    compiled_knots: bool = True  # the knots in C++ (native.py) where they build; False: the Python knots


DEFAULT_OPTIONS = CsqpOptions()
