"""The solver policy of the Crocoddyl backend: CSQP's stopping test, the cold start, the retries."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import crocoddyl  # noqa: F401  (before mim_solvers)
import mim_solvers
import numpy as np

from ...errors import interrupt_pending, solver_interrupts
from ...features import euler_knots, trajectory_cost
from ..task import DocSolution, ReachingTask, check_warm_start_knots, min_jerk, rest_to_rest_knots, warm_start_key
from .knots import _J_ENERGY
from .options import DEFAULT_OPTIONS, CsqpOptions
from .problem import ReachingProblem, build_problem


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
            if self._n_acceptable >= o.acceptable_iter and max(costs) - min(costs) <= o.acceptable_cost_change * abs(
                cost
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


def weight_scale(
    task: ReachingTask, weights: np.ndarray, options: CsqpOptions | None = None, cold=None
) -> tuple[float, float]:
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


def _attempt(
    prob: ReachingProblem,
    task: ReachingTask,
    weights: np.ndarray,
    xs,
    us,
    tol: float,
    options: CsqpOptions,
    running_bounds: bool = True,
):
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
    another task on the same knots (or of another backend) is ignored and one on another number of knots raises
    a ``ValueError``, as :func:`reachirl.doc.solve_doc` documents (warm-start timings: ``reachirl bench
    backends``).
    ``status`` reports the last KKT residual, the gaps' max-norm, the summed constraint violation and the ADMM
    iterations of all QPs.
    """
    check_warm_start_knots(task, warm_start)
    options = options or DEFAULT_OPTIONS
    weights = np.asarray(weights, dtype=float)
    n = task.n_nodes
    prob = build_problem(task.arm, n, weights.shape[0], options)
    cold = _to_shooting(task, *(initial_guess(task) if guess is None else rest_to_rest_knots(task, guess)))
    warm = warm_start.warm if warm_start is not None else None
    warm_used = bool(warm and warm.get("backend") == "crocoddyl" and warm.get("task") == warm_start_key(task))
    if warm_used:
        xs, us = _to_shooting(task, np.asarray(warm_start.q), np.asarray(warm_start.qd), np.asarray(warm_start.tau))
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
        prob, task, weights * scale, xs, us, tol, retry if warm_used else options, running_bounds=not screened
    )
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
        smooth = replace(
            retry,
            energy_smoothing=options.energy_smoothing * options.fallback_smoothing_factor,
            fallback_exact_hessian=False,
            fallback_smoothing_factor=0.0,
        )
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
        warm={"backend": "crocoddyl", "task": warm_start_key(task)},
    )
