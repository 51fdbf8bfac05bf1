"""DOC backends side by side: CasADi/IPOPT against Pinocchio/Crocoddyl/CSQP on the same problems, in the same
run.

Problems: the 5 start postures (P1 (−60°, 90°), P2 (0°, 90°), P3 (30°, 120°), P4 (−60°, 60°), P5 (50°, 80°))
of a 1.76 m, 70 kg male arm, bar at 0.95 L, durations 0.6–0.8 s, N = 100 knots, 1 and 8 windows, random
weights (log-uniform factors 0.3–3 over 1/Φ typical sizes). Figures: median cold solve time and iterations,
median warm solve time and iterations after a ~10 % weight change (warm-started from the previous solution),
the same changed problems solved cold (``cold2``, to tell what the warm start saves), CPU times
(``time.process_time`` around ``solve_doc``, so on a loaded 2-core machine they are steadier than the wall-clock
``solve_time``; medians over the problems of the median over repeats), the agreement of the two backends (q
RMSE in degrees, relative cost difference under ``features.trajectory_cost``), and where the Crocoddyl
backend's time goes (Python knot model vs the C++ model inside it vs the rest, i.e. CSQP's QPs).
"""

from __future__ import annotations

import time

import numpy as np

from reachirl import ArmModel, ReachingTask, solve_doc
from reachirl.features import N_FEATURES

POSTURES_DEG = [(-60.0, 90.0), (0.0, 90.0), (30.0, 120.0), (-60.0, 60.0), (50.0, 80.0)]
PHI_SCALE = np.array([0.5, 3.0, 0.3, 60.0, 100.0, 3.0, 40.0])
BACKENDS = ("casadi", "crocoddyl")


def problems(seed: int = 0, windows=(1, 8), n_nodes: int = 100):
    arm = ArmModel.from_anthropometrics(1.76, 70.0, "M")
    rng = np.random.default_rng(seed)
    out = []
    for p in POSTURES_DEG:
        for nw in windows:
            task = ReachingTask(arm, np.deg2rad(p), 0.95 * arm.length, rng.uniform(0.6, 0.8), n_nodes)
            w = np.exp(rng.uniform(np.log(0.3), np.log(3.0), (nw, N_FEATURES))) / PHI_SCALE
            w2 = w * np.exp(rng.normal(0.0, 0.1, w.shape))
            out.append((task, w, w2))
    return out


def _median(x):
    return float(np.median(x)) if len(x) else float("nan")


def _profile_crocoddyl(task, w, n_calls: int = 2000) -> dict:
    """Per-knot cost of the Python knot model and of the C++ integrated model inside it (µs per call)."""
    from reachirl.doc import crocoddyl as cb

    prob = cb.build_problem(task.arm, task.n_nodes, w.shape[0])
    prob.update(task, w)
    m = prob.running[task.n_nodes // 2]
    d = m.createData()
    x = np.r_[task.q0, 0.5, -0.3, 1.0, 0.5]
    u = np.array([2.0, 1.0])
    timings = {}
    for name, f in (
        ("knot_calc_us", lambda: m.calc(d, x, u)),
        ("knot_calcdiff_us", lambda: m.calcDiff(d, x, u)),
        ("inner_calc_us", lambda: m.inner.calc(d.inner, x[:4], u)),
        ("inner_calcdiff_us", lambda: m.inner.calcDiff(d.inner, x[:4], u)),
    ):
        t0 = time.perf_counter()
        for _ in range(n_calls):
            f()
        timings[name] = 1e6 * (time.perf_counter() - t0) / n_calls
    xs, us = cb._to_shooting(task, *cb.initial_guess(task))
    t0 = time.perf_counter()
    for _ in range(20):
        prob.problem.calc(xs, us)
        prob.problem.calcDiff(xs, us)
    timings["problem_calc_calcdiff_ms"] = 1e3 * (time.perf_counter() - t0) / 20
    return timings


def run(n_repeats: int = 3, seed: int = 0, windows=(1, 8)) -> dict:
    """Time both backends on the same problems; returns a JSON-able dict of figures."""
    probs = problems(seed, windows)
    keys = ("cold_s", "cold_iter", "warm_s", "warm_iter", "cold_cpu_s", "warm_cpu_s", "cold2_cpu_s", "cold2_iter")
    per = {b: {**{k: [] for k in keys}, "converged": 0, "warm_converged": 0} for b in BACKENDS}
    rmse, dcost, rows = [], [], []
    for task, w, w2 in probs:
        sols = {}
        for b in BACKENDS:
            times, warm_times, cpu, warm_cpu, cold2_cpu = [], [], [], [], []
            for _ in range(n_repeats):
                c0 = time.process_time()
                s = solve_doc(task, w, backend=b)
                c1 = time.process_time()
                sw = solve_doc(task, w2, backend=b, warm_start=s)
                c2 = time.process_time()
                s2 = solve_doc(task, w2, backend=b)
                c3 = time.process_time()
                times.append(s.solve_time)
                warm_times.append(sw.solve_time)
                cpu.append(c1 - c0)
                warm_cpu.append(c2 - c1)
                cold2_cpu.append(c3 - c2)
            sols[b] = s
            per[b]["cold_s"].append(_median(times))
            per[b]["cold_iter"].append(s.iterations)
            per[b]["warm_s"].append(_median(warm_times))
            per[b]["warm_iter"].append(sw.iterations)
            per[b]["cold_cpu_s"].append(_median(cpu))
            per[b]["warm_cpu_s"].append(_median(warm_cpu))
            per[b]["cold2_cpu_s"].append(_median(cold2_cpu))
            per[b]["cold2_iter"].append(s2.iterations)
            per[b]["converged"] += int(s.converged)
            per[b]["warm_converged"] += int(sw.converged)
        a, c = sols["casadi"], sols["crocoddyl"]
        r = float(np.rad2deg(np.sqrt(np.mean((a.q - c.q) ** 2))))
        dc = float(100.0 * (c.cost - a.cost) / a.cost)
        rmse.append(r)
        dcost.append(dc)
        rows.append(
            {
                "q0_deg": np.rad2deg(task.q0).round(1).tolist(),
                "n_windows": int(w.shape[0]),
                "duration_s": task.duration,
                "q_rmse_deg": r,
                "cost_diff_pct": dc,
                "casadi_cold_s": per["casadi"]["cold_s"][-1],
                "crocoddyl_cold_s": per["crocoddyl"]["cold_s"][-1],
                "casadi_iter": a.iterations,
                "crocoddyl_iter": c.iterations,
                "crocoddyl_status": c.status,
            }
        )
    summary = {}
    for b in BACKENDS:
        p = per[b]
        summary[b] = {
            "cold_median_s": _median(p["cold_s"]),
            "cold_median_iterations": _median(p["cold_iter"]),
            "warm_median_s": _median(p["warm_s"]),
            "warm_median_iterations": _median(p["warm_iter"]),
            "cold_cpu_median_s": _median(p["cold_cpu_s"]),
            "warm_cpu_median_s": _median(p["warm_cpu_s"]),
            "cold2_cpu_median_s": _median(p["cold2_cpu_s"]),
            "cold2_median_iterations": _median(p["cold2_iter"]),
            "warm_faster_than_cold2": f"{np.sum(np.less(p['warm_cpu_s'], p['cold2_cpu_s']))}/{len(probs)}",
            "converged": f"{p['converged']}/{len(probs)}",
            "warm_converged": f"{p['warm_converged']}/{len(probs)}",
        }
    summary["agreement"] = {
        "q_rmse_deg_median": _median(rmse),
        "q_rmse_deg_max": float(np.max(rmse)),
        "cost_diff_pct_median": _median(np.abs(dcost)),
        "cost_diff_pct_max_abs": float(np.max(np.abs(dcost))),
    }
    summary["ratio_cold_crocoddyl_over_casadi"] = (
        summary["crocoddyl"]["cold_median_s"] / summary["casadi"]["cold_median_s"]
    )
    summary["ratio_cold_cpu_crocoddyl_over_casadi"] = (
        summary["crocoddyl"]["cold_cpu_median_s"] / summary["casadi"]["cold_cpu_median_s"]
    )
    summary["crocoddyl_profile"] = _profile_crocoddyl(probs[0][0], probs[0][1])
    summary["problems"] = rows
    summary["setup"] = {
        "n_problems": len(probs),
        "n_repeats": n_repeats,
        "n_nodes": 100,
        "windows": list(windows),
    }
    return summary


if __name__ == "__main__":
    import json

    print(json.dumps({k: v for k, v in run().items() if k != "problems"}, indent=2))
