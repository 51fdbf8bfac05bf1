"""DOC benchmark: reachirl's CasADi backend against a plain formulation of the same problem, in the same run.

The plain baseline is the problem as one would first write it: multiple shooting in CasADi SX with states
``(q, q̇)`` and torques ``τ`` as decision variables, forward dynamics ``M⁻¹(τ − b)`` in the Euler step, the
same seven features, the same slack form of the energy term, the same constraints, and IPOPT with its default
options.

Figures (N = 100 knots, 8 windows, all seven features): median cold and warm solve times over 20 problems
(5 postures × 4 weight draws), as CPU time (``time.process_time`` around the whole call; the machine may be
shared, so prefer these and ``ratios_cpu``) and wall time, iteration counts, the convergence rate over a
135-problem sweep, and the ratios. These run on CasADi's virtual machine (``REACHIRL_COMPILE=off``), whatever
the cache holds; ``compiled`` times the same cold and warm solves with the compiled solvers of
:mod:`reachirl.doc.compiled` (compiling them first if they are not cached, and saying how long that took) and
checks that their solutions are bit-identical. There too, the warm solves once more by exact Newton from the
previous solution (:mod:`reachirl.doc.newton`, as MO-IRL's ``warm_newton`` does): its CPU time, how often it
answered, its largest difference from fatrop's warm answer, and both warm solves against the plain warm solve.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.doc.casadi import guess_knots
from reachirl.doc.compiled import setting as compile_mode
from reachirl.doc.symbolic import fingertip, inverse_dynamics, mass_matrix
from reachirl.errors import solver_interrupts
from reachirl.features import N_FEATURES, trajectory_cost, window_index

POSTURES_DEG = [(-60.0, 90.0), (0.0, 90.0), (30.0, 120.0), (-60.0, 60.0), (50.0, 80.0)]
FEATURE_SCALE = np.array([0.6, 1.5, 0.3, 300.0, 3000.0, 3.0, 10.0])


def random_weights(rng: np.random.Generator, n_windows: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(1e-2), np.log(1.0), size=(n_windows, N_FEATURES))) / FEATURE_SCALE


class PlainDoc:
    """The straightforward formulation, IPOPT defaults (printing off)."""

    def __init__(self, task: ReachingTask, n_windows: int):
        n, arm = task.n_nodes, task.arm
        a = [arm.l1, arm.l2, arm.m1, arm.m2, arm.c1, arm.c2, arm.i1, arm.i2, arm.gravity]
        dt = task.dt
        w = ca.SX.sym("w", n_windows * N_FEATURES)
        X = ca.SX.sym("X", 4, n + 1)
        U = ca.SX.sym("U", 2, n)
        Sp, Sm = ca.SX.sym("Sp", n), ca.SX.sym("Sm", n)
        win = window_index(n, n_windows)
        g, obj = [X[:, 0] - ca.vertcat(task.q0, 0, 0)], 0
        tau_rest = ca.DM(arm.gravity_torque(task.q0))  # held at rest before the reach
        for k in range(n):
            q, qd, tau = X[:2, k], X[2:, k], U[:, k]
            M = mass_matrix(a, q)
            bias = inverse_dynamics(a, q, qd, ca.SX.zeros(2))
            qdd = ca.solve(M, tau - bias)
            qd_next = qd + dt * qdd
            g.append(X[2:, k + 1] - qd_next)
            g.append(X[:2, k + 1] - (q + dt * qd_next))
            jac = ca.jacobian(fingertip(a, q), q)
            wk = w[win[k] * N_FEATURES : (win[k] + 1) * N_FEATURES]
            rates = [
                ca.sumsqr(jac @ qd),
                Sp[k] + Sm[k],
                ca.bilin(M, qd, qd),
                ca.sumsqr(qdd),
                ca.sumsqr((tau - (U[:, k - 1] if k > 0 else tau_rest)) / dt),
                ca.sumsqr(qd),
                ca.sumsqr(tau),
            ]
            obj += dt * sum(wk[j] * rates[j] for j in range(N_FEATURES))
            g.append(ca.dot(qd, tau) - Sp[k] + Sm[k])
        g.append(X[2:, n])
        g.append(fingertip(a, X[:2, n])[0] - task.target_x)
        self.n_eq = int(ca.vertcat(*g).numel())
        z = ca.vertcat(ca.vec(X), ca.vec(U), Sp, Sm)
        self.solver = ca.nlpsol(
            "plain",
            "ipopt",
            {"x": z, "p": w, "f": obj, "g": ca.vertcat(*g)},
            {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"},
        )
        inf = np.inf
        lbx_X = np.tile(np.r_[task.q_lower, -task.qd_max][:, None], (1, n + 1)).T.reshape(-1)
        ubx_X = np.tile(np.r_[task.q_upper, task.qd_max][:, None], (1, n + 1)).T.reshape(-1)
        self.lbx = np.r_[lbx_X, np.full(2 * n, -inf), np.zeros(2 * n)]
        self.ubx = np.r_[ubx_X, np.full(2 * n, inf), np.full(2 * n, inf)]
        self.task, self.n = task, n

    def x0(self) -> np.ndarray:
        """Linear interpolation of the cold guess's end posture, zero velocities and torques."""
        n, task = self.n, self.task
        q_end = guess_knots(task)[-1]
        s = np.linspace(0, 1, n + 1)[:, None]
        q = task.q0 + s * (q_end - task.q0)
        X = np.hstack([q, np.zeros((n + 1, 2))])
        return np.r_[X.reshape(-1), np.zeros(2 * n), np.zeros(2 * n)]

    def solve(self, weights: np.ndarray, x0: np.ndarray | None = None) -> dict:
        c0, t0 = time.process_time(), time.perf_counter()
        with solver_interrupts():  # Ctrl-C/SIGTERM stop the baseline too, and are raised here
            out = self.solver(
                x0=self.x0() if x0 is None else x0, p=weights.reshape(-1), lbx=self.lbx, ubx=self.ubx, lbg=0, ubg=0
            )
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        st = self.solver.stats()
        z = np.asarray(out["x"]).reshape(-1)
        n = self.n
        X = z[: 4 * (n + 1)].reshape(n + 1, 4)
        tau = z[4 * (n + 1) : 4 * (n + 1) + 2 * n].reshape(n, 2)
        return {
            "time": elapsed,
            "cpu": cpu,
            "iterations": int(st["iter_count"]),
            "converged": bool(st["success"]),
            "x": z,
            "q": X[:, :2],
            "qd": X[:, 2:],
            "tau": tau,
        }


def compiled_figures(problems, reference, reference_warm) -> dict:
    """The cold and warm solves of ``problems`` again with the compiled solvers; ``reference`` and
    ``reference_warm`` hold the VM's solutions."""
    with compile_mode("on"):
        t0 = time.perf_counter()
        cold = solve_doc(problems[0][0], problems[0][1])  # compiles the cold solver here unless cached
        compile_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        solve_doc(problems[0][0], problems[0][2], warm_start=cold)  # and the warm one
        compile_warm_s = time.perf_counter() - t0
        solve_doc(problems[0][0], problems[0][2], warm_start=cold, newton=True)  # Newton's stage map, compiled
        cpu, cpu_warm, cpu_newton, identical, answered, newton_diff = [], [], [], 0, 0, []
        for (task, w, w2), ref, ref_warm in zip(problems, reference, reference_warm, strict=True):
            c0 = time.process_time()
            sol = solve_doc(task, w)
            c1 = time.process_time()
            warm = solve_doc(task, w2, warm_start=sol)
            c2 = time.process_time()
            newton = solve_doc(task, w2, warm_start=sol, newton=True)  # as MO-IRL's warm_newton
            c3 = time.process_time()
            cpu.append(c1 - c0)
            cpu_warm.append(c2 - c1)
            cpu_newton.append(c3 - c2)
            identical += bool(np.array_equal(sol.q, ref.q) and sol.cost == ref.cost)
            identical += bool(np.array_equal(warm.q, ref_warm.q) and warm.cost == ref_warm.cost)
            answered += newton.status.startswith("newton")
            newton_diff.append(float(np.rad2deg(np.max(np.abs(newton.q - warm.q)))))
    return {
        "cold_cpu_median_s": float(np.median(cpu)),
        "warm_cpu_median_s": float(np.median(cpu_warm)),
        "first_solve_s": compile_s,
        "first_warm_solve_s": compile_warm_s,
        "bit_identical": f"{identical}/{2 * len(problems)}",
        "warm_newton": {  # the same warm solves by exact Newton (fatrop where Newton cannot vouch for its answer)
            "cpu_median_s": float(np.median(cpu_newton)),
            "newton_answered": f"{answered}/{len(problems)}",
            "max_diff_from_fatrop_warm_deg": max(newton_diff),
        },
    }


def run(n_repeats: int = 20, sweep: bool = True, seed: int = 0) -> dict:
    """Time both formulations on the same problems; returns the figures and their ratios."""
    with compile_mode("off"):
        out = _run(n_repeats, sweep, seed)
    return out


def _run(n_repeats: int, sweep: bool, seed: int) -> dict:
    arm = ArmModel.from_anthropometrics(1.76, 70.0, "M")
    rng = np.random.default_rng(seed)
    n_windows, n_nodes = 8, 100
    problems = []
    for i in range(n_repeats):
        task = ReachingTask(
            arm, np.deg2rad(POSTURES_DEG[i % 5]), 0.9 * arm.length, rng.uniform(0.65, 0.8), n_nodes=n_nodes
        )
        w = random_weights(rng, n_windows)
        problems.append((task, w, w * np.exp(0.1 * rng.normal(size=w.shape))))  # warm: a 10 % weight change

    solve_doc(problems[0][0], problems[0][1])  # build (and cache) the NLP outside the timings
    keys = ("cold", "warm", "cold_cpu", "warm_cpu", "cold_it", "warm_it")
    ours = {**{k: [] for k in keys}, "ok": 0, "n": 0}
    plain = {**{k: [] for k in keys}, "ok": 0, "n": 0}
    agree_deg, agree_cost, colds, warms = [], [], [], []
    for task, w, w2 in problems:
        c0 = time.process_time()
        cold = solve_doc(task, w)
        colds.append(cold)
        c1 = time.process_time()
        warm = solve_doc(task, w2, warm_start=cold)
        c2 = time.process_time()
        warms.append(warm)
        ours["cold"].append(cold.solve_time)
        ours["warm"].append(warm.solve_time)
        ours["cold_cpu"].append(c1 - c0)  # the whole solve_doc call: initial guess, solver, post-processing
        ours["warm_cpu"].append(c2 - c1)
        ours["cold_it"].append(cold.iterations)
        ours["warm_it"].append(warm.iterations)
        ours["ok"] += cold.converged + warm.converged
        ours["n"] += 2
        pd = PlainDoc(task, n_windows)
        pc = pd.solve(w)
        pw = pd.solve(w2, x0=pc["x"])  # plain warm start: the previous primal solution
        plain["cold"].append(pc["time"])
        plain["warm"].append(pw["time"])
        plain["cold_cpu"].append(pc["cpu"])
        plain["warm_cpu"].append(pw["cpu"])
        plain["cold_it"].append(pc["iterations"])
        plain["warm_it"].append(pw["iterations"])
        plain["ok"] += pc["converged"] + pw["converged"]
        plain["n"] += 2
        if pc["converged"]:
            agree_deg.append(float(np.rad2deg(np.sqrt(np.mean((pc["q"] - cold.q) ** 2)))))
            c_plain = trajectory_cost(arm, pc["q"], pc["qd"], pc["tau"], task.dt, w)
            agree_cost.append(abs(c_plain - cold.cost) / cold.cost)

    def med(v):
        return float(np.median(v))

    def fig(d):
        return {
            "cold_cpu_median_s": med(d["cold_cpu"]),
            "warm_cpu_median_s": med(d["warm_cpu"]),
            "cold_median_s": med(d["cold"]),
            "warm_median_s": med(d["warm"]),
            "cold_iterations_median": med(d["cold_it"]),
            "warm_iterations_median": med(d["warm_it"]),
            "converged": f"{d['ok']}/{d['n']}",
        }

    out = {
        "problem": {"n_nodes": n_nodes, "n_windows": n_windows, "features": 7, "n_problems": n_repeats},
        "reachirl": fig(ours),
        "plain_baseline": fig(plain),
        "agreement": {
            "q_rmse_deg_max": max(agree_deg) if agree_deg else None,
            "cost_rel_diff_max": max(agree_cost) if agree_cost else None,
        },
    }
    r, b = out["reachirl"], out["plain_baseline"]
    out["ratios_cpu"] = {
        "warm_vs_plain_cold": r["warm_cpu_median_s"] / b["cold_cpu_median_s"],
        "warm_vs_plain_warm": r["warm_cpu_median_s"] / b["warm_cpu_median_s"],
        "cold_vs_plain_cold": r["cold_cpu_median_s"] / b["cold_cpu_median_s"],
    }
    out["ratios"] = {  # wall time: noisy on a loaded machine, prefer ratios_cpu
        "warm_vs_plain_cold": r["warm_median_s"] / b["cold_median_s"],
        "warm_vs_plain_warm": r["warm_median_s"] / b["warm_median_s"],
        "cold_vs_plain_cold": r["cold_median_s"] / b["cold_median_s"],
    }
    out["compiled"] = compiled_figures(problems, colds, warms)
    out["compiled"]["cold_cpu_vs_vm"] = out["compiled"]["cold_cpu_median_s"] / r["cold_cpu_median_s"]
    out["compiled"]["warm_cpu_vs_vm"] = out["compiled"]["warm_cpu_median_s"] / r["warm_cpu_median_s"]
    # the solves reachirl runs (compiled) against the plain reference's warm solve: fatrop's warm solve and exact
    # Newton's (the fits' warm solves, ``warm_newton``, and the predictions' solver)
    c, plain_warm = out["compiled"], b["warm_cpu_median_s"]
    c["warm_cpu_vs_plain_warm"] = c["warm_cpu_median_s"] / plain_warm
    c["warm_newton"]["cpu_vs_plain_warm"] = c["warm_newton"]["cpu_median_s"] / plain_warm
    if sweep:
        out["convergence_sweep"] = convergence_sweep(arm, seed)
    return out


def convergence_sweep(arm: ArmModel, seed: int = 0) -> dict:
    """5 postures × 3 durations × 1/6/8 windows × 3 weight draws = 135 cold solves."""
    rng = np.random.default_rng(seed + 1)
    ok, its, times, cpus = 0, [], [], []
    n = 0
    for posture in POSTURES_DEG:
        for duration in (0.6, 0.72, 0.85):
            for n_windows in (1, 6, 8):
                for _ in range(3):
                    task = ReachingTask(arm, np.deg2rad(posture), 0.9 * arm.length, duration)
                    w = random_weights(rng, n_windows)
                    c0 = time.process_time()
                    sol = solve_doc(task, w)
                    cpus.append(time.process_time() - c0)
                    ok += sol.converged
                    its.append(sol.iterations)
                    times.append(sol.solve_time)
                    n += 1
    return {
        "n_problems": n,
        "converged": ok,
        "rate": ok / n,
        "iterations_median": float(np.median(its)),
        "iterations_max": int(max(its)),
        "solve_time_median_s": float(np.median(times)),
        "cpu_median_s": float(np.median(cpus)),
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
