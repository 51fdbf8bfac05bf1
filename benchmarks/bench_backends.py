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
backend's time goes (:func:`_profile_crocoddyl`, one cold solve; :func:`_warm_breakdown`, every warm solve, with
the ratio the warm solves would have if the knot models cost nothing), and the compiled knots against the Python
ones on the same solves (:func:`_python_knots`).

``learned_weights``: the same comparison on the weights real fits produce (:func:`learned_sweep`, from
``benchmarks/learned_weights.json``, made by ``benchmarks/learned_weights.py``): both convergence rates,
Crocoddyl's rate where CasADi converged, and the agreement where both converged (every 5th prediction by
default; ``learned_stride=1`` for all of them).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import replace

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


def _time(f, n: int) -> float:
    f()
    t0 = time.perf_counter()
    for _ in range(n):
        f()
    return (time.perf_counter() - t0) / n


def _profile_crocoddyl(task, w, n_calls: int = 2000) -> dict:
    """Where a Crocoddyl solve's time goes, measured piece by piece in this run.

    Per knot (µs per call): the compiled knot as CSQP calls it (``knot_*``: the whole problem's calc or calcDiff
    from C++, over the knots), the Python knot called from Python (``python_knot_*``), the C++
    ``IntegratedActionModelEuler`` inside both with the five built-in features (``inner_*``), the custom terms'
    arithmetic (energy, torque change) in Python scalars, an empty Python action model (the floor of any Python
    knot: the C++ → Python call), and a CasADi ``Function`` of the custom terms called from Python. Per solve
    (ms, the compiled knots): the SQP iterations × the calcDiff of the 100 knots, the rollouts × their calc (one
    per SQP iteration and one per line-search try, counted in the Python knots' identical solve), and CSQP's
    ADMM iterations (× the time of one, from ``computeDirection``, with the bounds the solve had), against the
    measured solve time; the rest is the monitor callback, the line search's and the QPs' other work, and
    bookkeeping.
    """
    import math

    import casadi as ca
    import crocoddyl

    from reachirl.doc import crocoddyl as cb

    scale = cb.weight_scale(task, w)[0]
    prob = cb.build_problem(task.arm, task.n_nodes, w.shape[0])
    prob.update(task, w * scale)
    python = cb.build_problem(task.arm, task.n_nodes, w.shape[0], replace(cb.DEFAULT_OPTIONS, compiled_knots=False))
    python.update(task, w * scale)
    pm = python.running[task.n_nodes // 2]
    pd = pm.createData()
    x = np.r_[task.q0, 0.5, -0.3, 1.0, 0.5]
    u = np.array([2.0, 1.0])
    xs0, us0 = [x] * (task.n_nodes + 1), [u] * task.n_nodes
    out = {
        "python_knot_calc_us": 1e6 * _time(lambda: pm.calc(pd, x, u), n_calls),
        "python_knot_calcdiff_us": 1e6 * _time(lambda: pm.calcDiff(pd, x, u), n_calls),
        "inner_calc_us": 1e6 * _time(lambda: pm.inner.calc(pd.inner, x[:4], u), n_calls),
        "inner_calcdiff_us": 1e6 * _time(lambda: pm.inner.calcDiff(pd.inner, x[:4], u), n_calls),
        # the compiled knots as CSQP calls them (from C++, the whole problem), per knot
        "knot_calc_us": 1e6 * _time(lambda: prob.problem.calc(xs0, us0), 50) / task.n_nodes,
        "knot_calcdiff_us": 1e6 * _time(lambda: prob.problem.calcDiff(xs0, us0), 50) / task.n_nodes,
    }

    def custom_terms():
        _, _, v0, v1, p0, p1 = x.tolist()
        u0, u1 = u.tolist()
        r = v0 * u0 + v1 * u1
        s = math.sqrt(r * r + 1e-6)
        return r / s, 1e-6 / (s * s * s), u0 - p0, u1 - p1

    out["custom_terms_python_us"] = 1e6 * _time(custom_terms, n_calls)

    class Empty(crocoddyl.ActionModelAbstract):
        def __init__(self):
            crocoddyl.ActionModelAbstract.__init__(self, crocoddyl.StateVector(6), 2, 1)

        def calc(self, data, x, u=None):
            pass

        def calcDiff(self, data, x, u=None):  # noqa: N802
            pass

    e = Empty()
    empty = crocoddyl.ShootingProblem(np.zeros(6), [e] * task.n_nodes, e)
    out["empty_python_knot_calc_plus_calcdiff_us"] = (
        1e6 * _time(lambda: (empty.calc(xs0, us0), empty.calcDiff(xs0, us0)), 50) / task.n_nodes
    )
    xs_, us_, ps_ = ca.SX.sym("x", 6), ca.SX.sym("u", 2), ca.SX.sym("p", 3)
    r = ca.dot(xs_[2:4], us_)
    c = ps_[0] * (ca.sqrt(r * r + ps_[2] ** 2) - ps_[2]) + ps_[1] * ca.sumsqr(us_ - xs_[4:6])
    z = ca.vertcat(xs_, us_)
    f = ca.Function("custom", [xs_, us_, ps_], [c, ca.gradient(c, z), ca.hessian(c, z)[0]])
    pn = np.array([0.01, 10.0, 1e-3])
    out["custom_terms_casadi_function_us"] = 1e6 * _time(lambda: f(x, u, pn), max(n_calls // 10, 10))

    # one solve, then its pieces at its solution
    sol = _croc_solve(task, w)
    iters = sol.iterations
    qp_iters = int(sol.status.split(" QP iterations")[0].rsplit(", ", 1)[-1]) if "QP iter" in sol.status else 0
    # the same solve again with the Python knots (the same iterates), counting the rollouts
    with _counting_rollouts() as rollouts:
        again = _croc_solve(task, w, compiled=False)
    assert again.iterations == iters
    xs, us = cb.solver._to_shooting(task, sol.q, sol.qd, sol.tau)
    # the ADMM iterations are timed with the bounds the solve had (the running ones screened out, by default)
    prob.update(task, w * scale, running_bounds=not (cb.DEFAULT_OPTIONS.screen_bounds and sol.attempts == 1))
    t_calc = _time(lambda: prob.problem.calc(xs, us), 20)
    t_diff = _time(lambda: prob.problem.calcDiff(xs, us), 20)

    def one_sqp_iteration(n_qp):  # calcDiff, one QP of exactly n_qp ADMM iterations, the line search
        solver = prob.make_solver(-1.0, 0.0)
        solver.max_qp_iters = n_qp
        solver.solve(list(xs), list(us), 1, False)

    t_qp = (_time(lambda: one_sqp_iteration(225), 5) - _time(lambda: one_sqp_iteration(25), 5)) / 200
    total = sol.solve_time
    pieces = {
        "knot_models_calcdiff_ms": 1e3 * iters * t_diff,
        "knot_models_calc_ms": 1e3 * rollouts[0] * t_calc,  # each SQP iteration's and each line-search try's
        "admm_ms": 1e3 * qp_iters * t_qp,
    }
    pieces["rest_ms"] = 1e3 * total - sum(pieces.values())
    python_share = 1.0 - (out["inner_calc_us"] + out["inner_calcdiff_us"]) / (
        out["python_knot_calc_us"] + out["python_knot_calcdiff_us"]
    )
    out.update(
        {
            "problem_calc_ms": 1e3 * t_calc,
            "problem_calcdiff_ms": 1e3 * t_diff,
            "admm_iteration_us": 1e6 * t_qp,
            "solve": {
                "time_ms": 1e3 * total,
                "sqp_iterations": iters,
                "rollouts": rollouts[0],
                "admm_iterations": qp_iters,
                "attempts": sol.attempts,
                **pieces,
            },
            "python_share_of_knot_time": python_share,
        }
    )
    return out


def _croc_solve(task, w, warm_start=None, compiled: bool = True):
    """A Crocoddyl solve as ``solve_doc`` makes it (weights over their largest), with the compiled knots or the
    Python ones."""
    from reachirl.doc import crocoddyl as cb

    options = replace(cb.DEFAULT_OPTIONS, compiled_knots=compiled)
    return cb.solve(task, w / np.max(w), warm_start=warm_start, options=options)


@contextlib.contextmanager
def _counting_rollouts():
    """Count the rollouts of the Python knots' Crocoddyl solves meanwhile (one per SQP iteration and one per
    line-search try: the terminal knot's calc runs once per rollout); yields a one-element list holding the
    count. The compiled knots' solves make the same iterates (bit-identical knots), so the same rollouts."""
    from reachirl.doc import crocoddyl as cb

    count = [0]
    calc = cb.KnotModel.calc

    def counting_calc(self, data, x, u=None):
        count[0] += self.terminal
        return calc(self, data, x, u)

    cb.KnotModel.calc = counting_calc
    try:
        yield count
    finally:
        cb.KnotModel.calc = calc


def _warm_one(task, w, w2) -> tuple[float, int, int, int, float]:
    """One warm solve of the default (compiled) knots (cold at ``w``, then warm at ``w2``): its CPU time, SQP
    iterations, rollouts (counted on the Python knots' identical solve), ADMM iterations and knot models' time
    (s)."""
    from reachirl.doc import crocoddyl as cb

    cold = _croc_solve(task, w)
    c0 = time.process_time()
    warm = _croc_solve(task, w2, warm_start=cold)
    cpu = time.process_time() - c0
    python_cold = _croc_solve(task, w, compiled=False)
    with _counting_rollouts() as rollouts:
        again = _croc_solve(task, w2, warm_start=python_cold, compiled=False)
    if again.iterations != warm.iterations or not np.array_equal(again.q, warm.q):
        raise AssertionError("the Python and compiled knots' warm solves differ")
    qp_iters = int(warm.status.split(" QP iterations")[0].rsplit(", ", 1)[-1]) if "QP iter" in warm.status else 0
    prob = cb.build_problem(task.arm, task.n_nodes, w2.shape[0])
    prob.update(task, w2 / np.max(w2) * cb.weight_scale(task, w2 / np.max(w2))[0])
    xs, us = cb.solver._to_shooting(task, warm.q, warm.qd, warm.tau)
    knots = rollouts[0] * _time(lambda: prob.problem.calc(xs, us), 20) + warm.iterations * _time(
        lambda: prob.problem.calcDiff(xs, us), 20
    )
    return cpu, warm.iterations, rollouts[0], qp_iters, min(knots, cpu)


def _warm_breakdown(probs, casadi_warm_cpu_median_s: float) -> dict:
    """Where Crocoddyl's warm solves' time goes, and what faster knot models could give at most.

    Each problem's warm solve (from the cold solution at ``w`` to ``w2``, as in :func:`_run`) is repeated with its
    rollouts counted; its knot models' time is the rollouts × one ``problem.calc`` plus the SQP iterations × one
    ``problem.calcDiff`` at its solution (the C++ shooting problem around the Python knots included). Figures
    (medians over the problems): the warm solve's CPU time, SQP iterations, rollouts and ADMM iterations, the
    knots' share of the time, and ``without_knots_vs_casadi_warm``: the warm solve's time less its knots' time
    against CasADi's warm median, a bound no knot model (Python, vectorised or C++) can beat.
    """
    rows = [_warm_one(task, w, w2) for task, w, w2 in probs]
    cpu, iters, rolls, qps, knots = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    return {
        "warm_cpu_median_ms": 1e3 * _median(cpu),
        "sqp_iterations_median": _median(iters),
        "rollouts_median": _median(rolls),
        "admm_iterations_median": _median(qps),
        "knots_share_of_time": float(knots.sum() / cpu.sum()),
        "without_knots_vs_casadi_warm": _median(cpu - knots) / casadi_warm_cpu_median_s,
    }


def _python_knots(probs) -> dict:
    """The Crocoddyl solves of :func:`_run` (cold at ``w``, warm at ``w2``) with the Python knots and with the
    compiled ones, interleaved: the CPU medians of each, the compiled over the Python, and how many problems'
    solves were identical (the two knots compute the same numbers, so their solves must be)."""
    cpu = {False: ([], []), True: ([], [])}
    same = 0
    for task, w, w2 in probs:
        sols = {}
        for compiled in (False, True):
            c0 = time.process_time()
            s = _croc_solve(task, w, compiled=compiled)
            c1 = time.process_time()
            sw = _croc_solve(task, w2, warm_start=s, compiled=compiled)
            c2 = time.process_time()
            cpu[compiled][0].append(c1 - c0)
            cpu[compiled][1].append(c2 - c1)
            sols[compiled] = (s, sw)
        same += int(all(np.array_equal(a.q, b.q) for a, b in zip(sols[False], sols[True], strict=True)))
    (pc, pw), (cc, cw) = cpu[False], cpu[True]
    return {
        "python_cold_cpu_median_s": _median(pc),
        "python_warm_cpu_median_s": _median(pw),
        "compiled_cold_cpu_median_s": _median(cc),
        "compiled_warm_cpu_median_s": _median(cw),
        "compiled_over_python_cold": _median(cc) / _median(pc),
        "compiled_over_python_warm": _median(cw) / _median(pw),
        "identical": f"{same}/{len(probs)}",
    }


def learned_sweep(stride: int = 1, path=None) -> dict:
    """Both backends on the weights that fits really produce (``benchmarks/learned_weights.json``: MO-IRL,
    MaxEnt and bilevel at 1/6/8 windows on the built-in virtual subjects and the UE-ADL sample), predicting
    every trial of each fit's split (every ``stride``-th with ``stride > 1``), each from a cold start.

    Reports both convergence rates, Crocoddyl's rate on the predictions where CasADi converged, and where both
    converged the q RMSE between them (degrees) and the relative cost difference; a failure is counted, never
    averaged in.
    """
    import importlib.util
    from pathlib import Path

    here = Path(__file__).resolve().parent
    spec = importlib.util.spec_from_file_location("reachirl_learned_weights", here / "learned_weights.py")
    lw = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(lw)
    fits = lw.load(path or here / "learned_weights.json")
    rows, i = [], 0
    for f in fits:
        w = np.array(f["weights"])
        for set_name, trials in f["trials"].items():
            for d in trials:
                i += 1
                if (i - 1) % stride:
                    continue
                task = lw.to_task(d)
                a = solve_doc(task, w, backend="casadi")
                c = solve_doc(task, w, backend="crocoddyl")
                rows.append(
                    {
                        "fit": f"{f['source']}/{f['method']}/{f['posture']}/s{f['sections']}",
                        "set": set_name,
                        "trial": d["id"],
                        "casadi_converged": bool(a.converged),
                        "crocoddyl_converged": bool(c.converged),
                        "q_rmse_deg": float(np.rad2deg(np.sqrt(np.mean((a.q - c.q) ** 2)))),
                        "cost_diff_pct": float(100.0 * (c.cost - a.cost) / a.cost),
                        "casadi_s": a.solve_time,
                        "crocoddyl_s": c.solve_time,
                        "crocoddyl_iterations": c.iterations,
                        "crocoddyl_status": c.status,
                    }
                )
    both = [r for r in rows if r["casadi_converged"] and r["crocoddyl_converged"]]
    n_ca = sum(r["casadi_converged"] for r in rows)
    rm = [r["q_rmse_deg"] for r in both]
    dc = [abs(r["cost_diff_pct"]) for r in both]
    return {
        "n_fits": len(fits),
        "n_predictions": len(rows),
        "casadi_converged": n_ca,
        "crocoddyl_converged": sum(r["crocoddyl_converged"] for r in rows),
        "crocoddyl_rate_where_casadi_converged": len(both) / n_ca if n_ca else float("nan"),
        "both_converged": len(both),
        "q_rmse_deg_median": _median(rm),
        "q_rmse_deg_max": float(np.max(rm)) if rm else float("nan"),
        "q_rmse_over_0.1deg": int(sum(v > 0.1 for v in rm)),
        "cost_diff_pct_median_abs": _median(dc),
        "cost_diff_pct_max_abs": float(np.max(dc)) if dc else float("nan"),
        "cost_diff_over_0.1pct": int(sum(v > 0.1 for v in dc)),
        "casadi_median_s": _median([r["casadi_s"] for r in rows]),
        "crocoddyl_median_s": _median([r["crocoddyl_s"] for r in rows]),
        "failures": [r for r in rows if r["casadi_converged"] != r["crocoddyl_converged"]],
        "disagreements": [r for r in both if r["q_rmse_deg"] > 0.1 or abs(r["cost_diff_pct"]) > 0.1],
    }


def run(n_repeats: int = 3, seed: int = 0, windows=(1, 8), learned_stride: int = 5) -> dict:
    """Time both backends on the same problems; returns a JSON-able dict of figures. CasADi runs on its
    virtual machine (``REACHIRL_COMPILE=off``), whatever the cache holds, so the ratios compare like with like
    across machines (``bench doc`` reports the compiled solver's own figure)."""
    from reachirl.doc.compiled import setting

    with setting("off"):
        return _run(n_repeats, seed, windows, learned_stride)


def _run(n_repeats: int, seed: int, windows, learned_stride: int) -> dict:
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
    summary["crocoddyl_warm"] = _warm_breakdown(probs, summary["casadi"]["warm_cpu_median_s"])
    summary["crocoddyl_python_knots"] = _python_knots(probs)
    summary["problems"] = rows
    summary["learned_weights"] = learned_sweep(learned_stride)
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
