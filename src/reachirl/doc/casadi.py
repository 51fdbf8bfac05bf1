"""CasADi + IPOPT backend of the reaching DOC.

Formulation (exactly the problem of :mod:`reachirl.doc.task`, written in fewer variables):

* The arm is fully actuated, so the semi-implicit Euler trajectory is determined by the joint positions at the
  knots: ``q̇_k = (q_k − q_{k−1}) / dt``, ``q̈_k = (q̇_{k+1} − q̇_k) / dt`` and ``τ_k = M(q_k) q̈_k + b(q_k, q̇_k)``
  (inverse dynamics, which is the exact inverse of the Euler step with ``q̈_k = M⁻¹(τ_k − b)``). The decision
  variables are ``q_1 … q_{N−1}``; ``q̇_0 = 0`` and ``q̇_N = 0`` are imposed by ``q_{−1} = q_0`` and
  ``q_N = q_{N−1}``. Joint limits are variable bounds and the speed bound is a linear constraint.
* The energy term ``|q̇_kᵀτ_k|`` uses the exact slack form ``q̇_kᵀτ_k = s⁺_k − s⁻_k``, ``s± ≥ 0`` (a smoothed
  absolute value made IPOPT stall). On interval 0, ``q̇_0 = 0`` makes it zero, so it has no slack.
* The arm's parameters, ``q0``, the target, ``dt`` and the weights are NLP *parameters*: one NLP is built per
  ``(N, n_windows)`` shape and reused for every arm, task and weight.
* Variables are ordered knot by knot so the KKT matrix is banded.
"""

from __future__ import annotations

import functools
import threading
import time

import casadi as ca
import numpy as np

from ..features import N_FEATURES, trajectory_cost, window_index
from .task import DocSolution, ReachingTask

__all__ = ["IPOPT_OPTIONS", "build_nlp", "initial_guess", "solve"]

# Tuned on 40 random problems (5 postures, 1/6/8 windows, log-uniform weights; see benchmarks/bench_doc.py):
# * the objective is normalised by the initial guess's cost (an NLP parameter) and IPOPT's gradient scaling is
#   capped at 1, which took convergence from 75 % to 100 %;
# * tol 1e-6 on that order-one objective, with feasibility kept at 1e-9; q then agrees with a tol = 1e-10 solve
#   to 0.02 deg. Tighter tolerances stall on "Search_Direction_Becomes_Too_Small" at the same point;
# * the adaptive barrier halves the iterations of the monotone one.
IPOPT_OPTIONS: dict = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "ipopt.tol": 1e-6,
    "ipopt.acceptable_tol": 1e-5,
    "ipopt.acceptable_iter": 3,
    "ipopt.constr_viol_tol": 1e-9,
    "ipopt.max_iter": 1000,
    "ipopt.mu_strategy": "adaptive",
    "ipopt.nlp_scaling_max_gradient": 1.0,
    "ipopt.linear_solver": "mumps",
}
WARM_OPTIONS: dict = {
    "ipopt.max_iter": 100,  # a warm start that has not converged by then is worse than a cold one
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-6,
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
}
_ARM_FIELDS = ("l1", "l2", "m1", "m2", "c1", "c2", "i1", "i2", "gravity")


def _inverse_dynamics(arm, q, qd, qdd):
    """Closed-form ``τ = M q̈ + C q̇ + g`` on CasADi symbols (the same equations as ArmModel)."""
    l1, l2, m1, m2, c1, c2, i1, i2, g = arm
    cq2, sq2 = ca.cos(q[1]), ca.sin(q[1])
    a = i1 + i2 + m1 * c1**2 + m2 * (l1**2 + c2**2)
    b = m2 * l1 * c2
    d = i2 + m2 * c2**2
    h = b * sq2
    g2 = g * m2 * c2 * ca.cos(q[0] + q[1])
    g1 = g * (m1 * c1 + m2 * l1) * ca.cos(q[0]) + g2
    tau1 = (a + 2 * b * cq2) * qdd[0] + (d + b * cq2) * qdd[1] - h * (2 * qd[0] * qd[1] + qd[1] ** 2) + g1
    tau2 = (d + b * cq2) * qdd[0] + d * qdd[1] + h * qd[0] ** 2 + g2
    return ca.vertcat(tau1, tau2)


def _mass_matrix(arm, q):
    l1, l2, m1, m2, c1, c2, i1, i2, g = arm
    cq2 = ca.cos(q[1])
    a = i1 + i2 + m1 * c1**2 + m2 * (l1**2 + c2**2)
    b = m2 * l1 * c2
    d = i2 + m2 * c2**2
    return ca.vertcat(ca.horzcat(a + 2 * b * cq2, d + b * cq2), ca.horzcat(d + b * cq2, d))


def _fingertip(arm, q):
    l1, l2 = arm[0], arm[1]
    return ca.vertcat(
        l1 * ca.cos(q[0]) + l2 * ca.cos(q[0] + q[1]), l1 * ca.sin(q[0]) + l2 * ca.sin(q[0] + q[1])
    )


class _Nlp:
    """One NLP of a given shape, with a cold and a warm IPOPT instance."""

    def __init__(self, n: int, n_windows: int, options: dict | None = None):
        self.n, self.n_windows = n, n_windows
        arm = ca.SX.sym("arm", len(_ARM_FIELDS))
        q0 = ca.SX.sym("q0", 2)
        target = ca.SX.sym("target")
        dt = ca.SX.sym("dt")
        fscale = ca.SX.sym("fscale")  # objective normalisation: 1 / (cost of the initial guess)
        w = ca.SX.sym("w", n_windows * N_FEATURES)  # row-major (window, feature)
        arm_l = [arm[i] for i in range(len(_ARM_FIELDS))]

        # decision variables, knot by knot: q_k (2), then s⁺_k, s⁻_k for k = 1..N-1
        z_blocks, qs, sp, sm = [], [q0], [None], [None]
        for k in range(1, n):
            qk = ca.SX.sym(f"q{k}", 2)
            spk, smk = ca.SX.sym(f"sp{k}"), ca.SX.sym(f"sm{k}")
            z_blocks += [qk, spk, smk]
            qs.append(qk)
            sp.append(spk)
            sm.append(smk)
        qs.append(qs[-1])  # q_N = q_{N-1}  ⇔  q̇_N = 0
        z = ca.vertcat(*z_blocks)

        win = window_index(n, n_windows)
        qd = [ca.SX.zeros(2)] + [(qs[k] - qs[k - 1]) / dt for k in range(1, n + 1)]  # q̇_0 = 0
        obj = 0
        g, lbg, ubg = [], [], []
        tau_prev = None
        for k in range(n):
            qdd = (qd[k + 1] - qd[k]) / dt
            tau = _inverse_dynamics(arm_l, qs[k], qd[k], qdd)
            wk = w[win[k] * N_FEATURES : (win[k] + 1) * N_FEATURES]
            l1, l2 = arm_l[0], arm_l[1]
            q1, q12 = qs[k][0], qs[k][0] + qs[k][1]
            jac = ca.vertcat(
                ca.horzcat(-l1 * ca.sin(q1) - l2 * ca.sin(q12), -l2 * ca.sin(q12)),
                ca.horzcat(l1 * ca.cos(q1) + l2 * ca.cos(q12), l2 * ca.cos(q12)),
            )
            pdot = jac @ qd[k]
            rates = [
                ca.sumsqr(pdot),
                (sp[k] + sm[k]) if k > 0 else 0,
                ca.bilin(_mass_matrix(arm_l, qs[k]), qd[k], qd[k]),
                ca.sumsqr(qdd),
                ca.sumsqr((tau - tau_prev) / dt) if k > 0 else 0,
                ca.sumsqr(qd[k]),
                ca.sumsqr(tau),
            ]
            obj += dt * sum(wk[j] * rates[j] for j in range(N_FEATURES))
            tau_prev = tau
            if k > 0:
                g += [ca.dot(qd[k], tau) - sp[k] + sm[k], qd[k]]
                lbg += [0.0, -np.inf, -np.inf]
                ubg += [0.0, np.inf, np.inf]
        g.append(_fingertip(arm_l, qs[n])[0] - target)
        lbg.append(0.0)
        ubg.append(0.0)
        self.n_z = z.numel()
        self.p = ca.vertcat(arm, q0, target, dt, fscale, w)
        self.nlp = {"x": z, "p": self.p, "f": fscale * obj, "g": ca.vertcat(*g)}
        self.lbg_template = np.array(lbg, dtype=float)
        self.ubg_template = np.array(ubg, dtype=float)
        self.speed_rows = np.array(
            [1 + 3 * (k - 1) + j for k in range(1, n) for j in range(2)], dtype=int
        )  # rows of g holding q̇_k
        self.objective = ca.Function("objective", [z, self.p], [self.nlp["f"]])
        opts = dict(IPOPT_OPTIONS)
        opts.update(options or {})
        self.cold = ca.nlpsol("doc_cold", "ipopt", self.nlp, opts)
        self.warm = ca.nlpsol("doc_warm", "ipopt", self.nlp, {**opts, **WARM_OPTIONS})
        self.lock = threading.Lock()

    def params(self, task: ReachingTask, weights: np.ndarray, fscale: float) -> np.ndarray:
        a = task.arm
        return np.concatenate(
            [[getattr(a, f) for f in _ARM_FIELDS], task.q0, [task.target_x, task.dt, fscale], weights.reshape(-1)]
        )

    def bounds(self, task: ReachingTask) -> tuple[np.ndarray, ...]:
        lbx = np.tile(np.r_[task.q_lower, 0.0, 0.0], self.n - 1)
        ubx = np.tile(np.r_[task.q_upper, np.inf, np.inf], self.n - 1)
        lbg, ubg = self.lbg_template.copy(), self.ubg_template.copy()
        lbg[self.speed_rows] = np.tile(-task.qd_max, self.n - 1)
        ubg[self.speed_rows] = np.tile(task.qd_max, self.n - 1)
        return lbx, ubx, lbg, ubg


@functools.lru_cache(maxsize=16)
def build_nlp(n: int, n_windows: int) -> _Nlp:
    """The cached NLP of shape ``(n, n_windows)``."""
    return _Nlp(n, n_windows)


def _min_jerk(s: np.ndarray) -> np.ndarray:
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def initial_guess(task: ReachingTask) -> np.ndarray:
    """A cold start: a minimum-jerk joint path from ``q0`` to a posture with the fingertip on the bar.

    The end posture keeps the fingertip's starting height where it is reachable (within 98 % of the arm's reach).
    """
    arm, n = task.arm, task.n_nodes
    y0 = float(arm.fk(task.q0)[1])
    r_max = 0.98 * arm.length
    y_lim = np.sqrt(max(r_max**2 - task.target_x**2, 0.0))
    qf = arm.ik(np.array([task.target_x, np.clip(y0, -y_lim, y_lim)]))
    qf = np.clip(qf, task.q_lower + 1e-3, task.q_upper - 1e-3)
    s = _min_jerk(np.linspace(0.0, 1.0, n + 1))[:, None]
    q = task.q0 + s * (qf - task.q0)
    return _pack(task, q)


def _pack(task: ReachingTask, q: np.ndarray) -> np.ndarray:
    """Decision vector from a knot trajectory ``q (N+1, 2)``, slacks from its energy rates."""
    arm, dt, n = task.arm, task.dt, task.n_nodes
    q = q.copy()
    q[-1] = q[-2]
    qd = np.vstack([np.zeros(2), np.diff(q, axis=0) / dt])
    tau = arm.inverse_dynamics(q[:-1], qd[:-1], np.diff(qd, axis=0) / dt)
    e = np.sum(qd[:-1] * tau, axis=1)
    z = np.column_stack([q[1:n], np.maximum(e[1:], 0.0), np.maximum(-e[1:], 0.0)])
    return z.reshape(-1)


def _exact_slacks(task: ReachingTask, z: np.ndarray) -> np.ndarray:
    """Set ``s± = max(±q̇ᵀτ, 0)``: the interior point leaves both slightly positive (≈ barrier parameter)."""
    q, qd, tau = _unpack(task, z)
    e = np.sum(qd[1:-1] * tau[1:], axis=1)
    z = z.reshape(task.n_nodes - 1, 4).copy()
    z[:, 2], z[:, 3] = np.maximum(e, 0.0), np.maximum(-e, 0.0)
    return z.reshape(-1)


def _unpack(task: ReachingTask, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n, dt = task.n_nodes, task.dt
    inner = np.asarray(z).reshape(n - 1, 4)[:, :2]
    q = np.vstack([task.q0, inner, inner[-1:]])
    qd = np.vstack([np.zeros(2), np.diff(q, axis=0) / dt])
    tau = task.arm.inverse_dynamics(q[:-1], qd[:-1], np.diff(qd, axis=0) / dt)
    return q, qd, tau


def _task_key(task: ReachingTask) -> tuple:
    """What must match for a warm start: everything in the task but the weights."""
    return (task.n_nodes, task.arm, tuple(task.q0), task.target_x, task.duration, tuple(task.q_lower),
            tuple(task.q_upper), tuple(task.qd_max))


def _objective_scale(task: ReachingTask, weights: np.ndarray, z: np.ndarray) -> float:
    """``1 / cost`` of the starting point, so that IPOPT sees an objective of order one."""
    q, qd, tau = _unpack(task, z)
    cost = trajectory_cost(task.arm, q, qd, tau, task.dt, weights)
    return 1.0 / max(cost, 1e-8)


def _run(nlp: _Nlp, solver, args: dict) -> tuple[dict, dict, float]:
    with nlp.lock:  # an nlpsol instance is not re-entrant
        t0 = time.perf_counter()
        out = solver(**args)
        elapsed = time.perf_counter() - t0
        stats = solver.stats()
    return out, stats, elapsed


def _converged(stats: dict, z: np.ndarray) -> bool:
    status = str(stats.get("return_status", ""))
    ok = bool(stats.get("success", False)) or status == "Solved_To_Acceptable_Level"
    return ok and bool(np.all(np.isfinite(z)))


def solve(
    task: ReachingTask, weights: np.ndarray, warm_start: DocSolution | None = None, retry_cold: bool = True
) -> DocSolution:
    """Solve the DOC; warm from ``warm_start`` when it is the same task, cold otherwise, and cold again when the
    warm attempt fails and ``retry_cold``.

    ``iterations`` and ``solve_time`` count every attempt.
    """
    nlp = build_nlp(task.n_nodes, weights.shape[0])
    lbx, ubx, lbg, ubg = nlp.bounds(task)
    bounds = {"lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
    warm = warm_start.warm if warm_start is not None else None
    key = _task_key(task)
    iterations, elapsed = 0, 0.0
    out = stats = None
    if warm is not None and warm.get("backend") == "casadi" and warm.get("task") == key:
        # the same reach under new weights (MO-IRL's line search): reuse primal and dual variables and the scale
        fscale = warm["fscale"]
        args = {**bounds, "x0": np.clip(warm["x"], lbx, ubx), "lam_x0": warm["lam_x"], "lam_g0": warm["lam_g"],
                "p": nlp.params(task, weights, fscale)}
        out, stats, elapsed = _run(nlp, nlp.warm, args)
        iterations = int(stats.get("iter_count", 0))
    if out is None or (retry_cold and not _converged(stats, np.asarray(out["x"]))):
        # cold: a neighbouring reach's multipliers mislead IPOPT (10x more iterations measured), and so does a
        # warm start after a large change of weights
        x0 = np.clip(initial_guess(task), lbx, ubx)
        fscale = _objective_scale(task, weights, x0)
        args = {**bounds, "x0": x0, "p": nlp.params(task, weights, fscale)}
        out, stats, t_cold = _run(nlp, nlp.cold, args)
        iterations += int(stats.get("iter_count", 0))
        elapsed += t_cold
    z = _exact_slacks(task, np.asarray(out["x"]).reshape(-1))
    q, qd, tau = _unpack(task, z)
    return DocSolution(
        t=task.t,
        q=q,
        qd=qd,
        tau=tau,
        cost=float(nlp.objective(z, args["p"])) / fscale,
        converged=_converged(stats, z),
        iterations=iterations,
        solve_time=elapsed,
        status=str(stats.get("return_status", "")),
        backend="casadi",
        warm={
            "backend": "casadi",
            "task": key,
            "fscale": fscale,
            "x": z,
            "lam_x": np.asarray(out["lam_x"]).reshape(-1),
            "lam_g": np.asarray(out["lam_g"]).reshape(-1),
        },
    )
