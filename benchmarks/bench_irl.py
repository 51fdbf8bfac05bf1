"""IRL benchmark: MO-IRL against MaxEnt, bilevel and KKT IOC on virtual subjects with known weights.

One virtual subject (:mod:`reachirl.virtual`, Berret's protocol, seed-paper-like true weights with 8
windows: joint acceleration at onset and termination, geodesic/energy/torque mid-movement), one posture, 10
training and 10 cross-validation reaches (each under the truth jittered by ``exp(N(0, 0.2))``, with its own
start and duration). For each method and 1 and 8 windows:

* training and CV RMSE of q (degrees; :func:`reachirl.doc.evaluation.evaluate_trials`, each reach predicted
  from its own start);
* truth agreement: RMSE (degrees) between the learned weights' predictions and the nominal true weights'
  predictions on the CV tasks (how well the *cost* was recovered, regardless of trial-to-trial jitter);
* DOC solves, wall and CPU time of the fit, iterations, DOC failures.

A reference DOC (cold, 100 knots, true weights, on the training reaches' mean task) is timed in the same
run so the fit times can be read as ratios on a shared, noisy machine. The full run also sweeps MO-IRL's
options (8 windows), measures KKT and MO-IRL under angle noise, and times the protocol's own 8-window fits
(:func:`protocol_fit_cpu`: ``make run``'s reaches, which are cut and observed, on CasADi's virtual machine and
compiled). ``run(quick=True)`` uses 5 + 5 reaches, a smaller bilevel budget and skips all three.

Bilevel runs to convergence or to 20× MO-IRL's DOC solves (at least 200), whichever comes first; the table
gives each method's budget and stop reason. A † marks a fit that never left its initial weights.
"""

from __future__ import annotations

import json
import logging
import os
import platform
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from reachirl import ReachingTask, solve_doc
from reachirl.data.trial import Trial
from reachirl.doc.evaluation import evaluate_trials, rmse_deg, summarise
from reachirl.io import atomic_write_text
from reachirl.irl.methods import make_estimator
from reachirl.irl.moirl import demonstration_states, mean_task
from reachirl.irl.objective import merit
from reachirl.irl.options import FIELDS as OPTION_FIELDS

log = logging.getLogger(__name__)

N_NODES = 100
POSTURE = "P2"


# ---------------------------------------------------------------------- virtual demonstrations
def virtual_subject(n_trials: int, posture: str = POSTURE, seed: int = 0, n_nodes: int = N_NODES):
    """``(trials, truth (8, 7), source)``: ``n_trials`` reaches of one virtual subject from ``posture``.

    The demonstrations are the DOC's knots themselves (no recording noise), on the same discretisation as the
    fits; the truth is the synth module's nominal weights.
    """
    from reachirl import virtual as synth

    return synth.knot_trials(n_trials, posture, seed, n_nodes), synth.nominal_weights(), "reachirl.virtual"


# ---------------------------------------------------------------------- measuring one fit
def _rmse_summary(weights: np.ndarray, trials) -> dict:
    errs = evaluate_trials(weights, trials, n_nodes=N_NODES)
    s = summarise(errs)
    return {
        "mean": s["rmse_deg"]["q"]["mean"],
        "std": s["rmse_deg"]["q"]["std"],
        "failures": s["doc_failures"],
        "predictions": [e.prediction for e in errs],
    }


def _agreement(pred: list, truth_pred: list) -> float:
    """Mean over tasks of the RMSE (deg) between two predictions of q."""
    return float(np.mean([rmse_deg(a.q, b.q)[2] for a, b in zip(pred, truth_pred, strict=True)]))


def with_angle_noise(trial: Trial, sd_deg: float, rng: np.random.Generator) -> Trial:
    """The trial with Gaussian noise on its joint angles (velocities, accelerations, torques re-derived)."""
    q = trial.q + np.deg2rad(sd_deg) * rng.standard_normal(trial.q.shape)
    dt = np.diff(trial.t)[:, None]
    qd = np.vstack([np.zeros(2), np.diff(q, axis=0) / dt])
    qdd = np.vstack([np.diff(qd, axis=0) / dt, np.zeros((1, 2))])
    return replace(trial, q=q, qd=qd, qdd=qdd, tau=trial.arm.inverse_dynamics(q, qd, qdd), x0=None)


def _budget(kw: dict):
    """A method's budget as the table states it: DOC solves, iterations, or one solve (KKT)."""
    if "max_evals" in kw:
        return int(kw["max_evals"])
    return f"{kw['max_iter']} iterations" if "max_iter" in kw else "one solve"


def _mark(row: dict) -> str:
    return " †" if row.get("flag") == "w0" else ""


def _fit_and_score(method: str, n_windows: int, train, cv, truth_cv_pred, **kw) -> tuple[dict, object]:
    est = make_estimator(method, n_windows, n_nodes=N_NODES, **kw)
    t0, c0 = time.perf_counter(), time.process_time()
    est.fit(train)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    tr = _rmse_summary(est.weights_, train)
    cvs = _rmse_summary(est.weights_, cv)
    row = {
        "method": method,
        "label": method + "".join(f"/{v}" for k, v in kw.items() if k == "pooling"),
        "n_windows": n_windows,
        "options": {k: v for k, v in kw.items()},
        "train_rmse_deg": tr["mean"],
        "train_rmse_sd": tr["std"],
        "cv_rmse_deg": cvs["mean"],
        "cv_rmse_sd": cvs["std"],
        "truth_agreement_deg": _agreement(cvs["predictions"], truth_cv_pred),
        "doc_solves": int(est.n_doc_solves_),
        "doc_failures": int(getattr(est, "n_doc_failures_", 0)),
        "fit_time_s": wall,
        "fit_cpu_s": cpu,
        "iterations": int(est.n_iter_),
        "merit": float(getattr(est, "merit_", np.nan)),
        "stop_reason": str(getattr(est, "stop_reason_", "")),
        "budget": _budget(kw),
        "flag": getattr(est, "flag_", None),
        "eval_failures": tr["failures"] + cvs["failures"],
        "weights": np.asarray(est.weights_).tolist(),
    }
    return row, est


def _merit_curve(est) -> list[tuple[int, float]]:
    """(cumulative DOC solves, best merit so far) along a fit's history."""
    out, best = [], np.inf
    for i, h in enumerate(est.history_):
        solves = h.get("doc_solves", i + 1)
        best = min(best, h["merit"])
        out.append((int(solves), float(best)))
    return out


def _solves_to_reach(curve: list[tuple[int, float]], level: float) -> int | None:
    for solves, m in curve:
        if m <= level:
            return solves
    return None


def _reference_doc_time(task: ReachingTask, weights: np.ndarray, repeats: int = 5) -> tuple[float, float]:
    """Median wall and CPU time of a cold DOC under ``weights`` (after one untimed solve that builds the
    NLP)."""
    solve_doc(task, weights)
    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        solve_doc(task, weights)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return float(np.median(walls)), float(np.median(cpus))


def protocol_fit_cpu(seed: int = 0, sections: int = 8, repeats: int = 3) -> dict:
    """CPU time of the protocol's own MO-IRL fits (``make run``'s: built-in virtual subjects, 10 training
    reaches cut from their recordings, observed, normalised merit), one per posture, on CasADi's virtual
    machine and with the compiled solvers of :mod:`reachirl.doc.compiled` (compiled first if not cached), with
    a cold reference DOC timed the same way; the weights must be the same both ways.

    Each fit runs ``repeats`` times and counts with its least CPU time (as ``timeit`` advises: on a shared
    machine the other tenants only ever add time; on this one a fit's CPU time varied by up to 30 % from run
    to run); every repeat must give the same weights, and ``fit_cpu_runs_s`` keeps all the times."""
    from reachirl.doc.compiled import setting as compile_mode
    from reachirl.experiments import datasets
    from reachirl.experiments.protocol import (
        ProtocolConfig,
        make_estimator,
        make_units,
        resolve_postures,
        split_trials,
    )

    config = ProtocolConfig(sections=(sections,), uncertainty=0)
    trials = list(datasets.load(None, seed=seed).trials)
    units = make_units(resolve_postures(trials, config), config)
    train = {u.posture: list(split_trials(trials, u.posture, config).train) for u in units}
    first = train[units[0].posture]
    out: dict = {"sections": sections, "n_train": len(first), "postures": [u.posture for u in units]}
    weights = {}
    for mode in ("off", "on"):
        with compile_mode(mode):
            make_estimator(units[0]).fit(first)  # builds the NLP (and loads or compiles the solvers)
            _, ref_cpu = _reference_doc_time(mean_task(first, N_NODES), np.full((sections, 7), 1.0))
            runs, solves = [[] for _ in units], {}
            for _ in range(repeats):
                for u, times in zip(units, runs, strict=True):
                    est = make_estimator(u)
                    c0 = time.process_time()
                    est.fit(train[u.posture])
                    times.append(time.process_time() - c0)
                    solves.setdefault(u.posture, int(est.n_doc_solves_))
                    weights.setdefault(u.posture, []).append(est.weights_)
            cpus = [min(times) for times in runs]
            solves = list(solves.values())
        key = "vm" if mode == "off" else "compiled"
        out[key] = {
            "fit_cpu_s": cpus,
            "fit_cpu_median_s": float(np.median(cpus)),
            "fit_cpu_runs_s": runs,
            "repeats": repeats,
            "doc_solves": solves,
            "reference_doc_cpu_s": ref_cpu,
            "fit_in_reference_docs": float(np.median(cpus)) / ref_cpu,
        }
    out["same_weights"] = all(np.array_equal(w[0], b) for w in weights.values() for b in w[1:])
    with compile_mode("on"):  # the same fits with weight samples (reachirl fit --uncertainty): their own CPU
        unc = []
        for u in units:
            est = make_estimator(u)
            est.set_params(uncertainty=40)
            c0 = time.process_time()
            est.fit(train[u.posture])
            unc.append(time.process_time() - c0)
    out["uncertainty"] = {
        "fit_cpu_s": unc,
        "ratio_to_plain_fit": [a / b for a, b in zip(unc, out["compiled"]["fit_cpu_s"], strict=True)],
    }
    out["compiled_vs_vm"] = out["compiled"]["fit_cpu_median_s"] / out["vm"]["fit_cpu_median_s"]
    return out


# ---------------------------------------------------------------------- the benchmark
def run(quick: bool = False, out_dir=None, seed: int = 0) -> dict:
    """Run the IRL benchmark; returns the results and, with ``out_dir``, writes ``bench_irl.json`` and
    ``bench_irl.md`` there."""
    n_train, n_cv = (5, 5) if quick else (10, 10)
    bilevel_factor = 3 if quick else 20  # bilevel's budget: this many times MO-IRL's DOC solves (at least 200)
    t_start = time.perf_counter()
    trials, truth, source = virtual_subject(n_train + n_cv, seed=seed)
    train, cv = trials[:n_train], trials[n_train:]
    task0 = mean_task(train, N_NODES)
    ref_doc, ref_doc_cpu = _reference_doc_time(task0, truth)

    truth_train = _rmse_summary(truth, train)
    truth_cv = _rmse_summary(truth, cv)
    x_demos = demonstration_states(train, N_NODES)
    truth_merit = merit(x_demos, solve_doc(task0, truth).state)

    rows, curves = [], {}
    methods = [
        ("moirl", {"max_iter": 50}),
        ("maxent", {"max_iter": 50}),
        ("bilevel", None),  # run to convergence, or to bilevel_factor × MO-IRL's solves
        ("kkt", {}),
        ("kkt", {"pooling": "per_demo"}),
    ]
    for n_windows in (1, 8):
        mo_solves = None
        for method, kw in methods:
            if kw is None:
                kw = {"max_evals": max(200, bilevel_factor * mo_solves)}
            row, est = _fit_and_score(method, n_windows, train, cv, truth_cv["predictions"], **kw)
            if method == "moirl":
                mo_solves = row["doc_solves"]
            rows.append(row)
            if method != "kkt":
                curves[f"{method}/{n_windows}"] = _merit_curve(est)
            log.info(
                "%s/%d: train %.2f cv %.2f truth %.2f solves %d time %.2fs",
                method,
                n_windows,
                row["train_rmse_deg"],
                row["cv_rmse_deg"],
                row["truth_agreement_deg"],
                row["doc_solves"],
                row["fit_time_s"],
            )

    options = []
    if not quick:
        variants = [
            {},
            {"scaling": None},
            {"beta": 1.0},
            {"max_ratio": 3.0},
            {"merit": "state"},
            {"smoothness": "cv"},
            {"feature_cutoff": 6.0},
            {"rollout": "per_demo"},
            {"memory": None},
            {"acceptance": "either"},
            {"n_suffixes": 5},
        ]
        for v in variants:  # MOIRL's own parameters, or Options fields through `experimental`
            kw = {k: x for k, x in v.items() if k not in OPTION_FIELDS}
            if set(v) - set(kw):
                kw["experimental"] = {k: x for k, x in v.items() if k in OPTION_FIELDS}
            row, _ = _fit_and_score("moirl", 8, train, cv, truth_cv["predictions"], max_iter=50, **kw)
            row["variant"] = ", ".join(f"{k}={v[k]!r}" for k in v) or "default"
            options.append(row)

    extra = {}
    if not quick:  # angle noise on the training reaches (evaluated against the clean ones)
        rng = np.random.default_rng(seed)
        for sd in (0.1, 1.0):
            noisy = [with_angle_noise(t, sd, rng) for t in train]
            for method, kw in (("kkt", {}), ("kkt", {"pooling": "per_demo"}), ("moirl", {"max_iter": 50})):
                est = make_estimator(method, 8, n_nodes=N_NODES, **kw).fit(noisy)
                extra[f"noise_{sd}deg/{method}{'/per_demo' if kw.get('pooling') else ''}/8w"] = {
                    "train_rmse_deg_vs_clean": _rmse_summary(est.weights_, train)["mean"],
                    "doc_solves": int(est.n_doc_solves_),
                }
    protocol_fits = None if quick else protocol_fit_cpu(seed)
    targets = _targets(rows, curves, ref_doc)
    if protocol_fits is not None:  # target: an 8-window fit of 10 recorded reaches takes at most 1 s of CPU
        median = protocol_fits["compiled"]["fit_cpu_median_s"]
        targets["protocol_fit_le_1s_cpu"] = {
            "median_cpu_s": median,
            "per_posture_cpu_s": protocol_fits["compiled"]["fit_cpu_s"],
            "met": median <= 1.0,
        }
        ratios = protocol_fits["uncertainty"]["ratio_to_plain_fit"]
        targets["uncertainty_le_10x_fit_cpu"] = {"ratio_per_posture": ratios, "met": max(ratios) <= 10.0}
    result = {
        "benchmark": "irl",
        "quick": quick,
        "seed": seed,
        "data": {
            "source": source,
            "posture": POSTURE,
            "n_train": n_train,
            "n_cv": n_cv,
            "n_nodes": N_NODES,
            "truth_weights": np.asarray(truth).tolist(),
        },
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        },
        "reference_doc_s": ref_doc,
        "reference_doc_cpu_s": ref_doc_cpu,
        "extra": extra,
        "truth": {
            "train_rmse_deg": truth_train["mean"],
            "cv_rmse_deg": truth_cv["mean"],
            "merit": truth_merit,
        },
        "rows": rows,
        "merit_curves": curves,
        "moirl_options": options,
        "protocol_fits": protocol_fits,
        "targets": targets,
        "elapsed_s": time.perf_counter() - t_start,
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "bench_irl.json", json.dumps(result, indent=2, default=_json_default))
        atomic_write_text(out / "bench_irl.md", markdown(result))
    return result


def _targets(rows: list[dict], curves: dict, ref_doc: float) -> dict:
    by = {(r["label"], r["n_windows"]): r for r in rows}
    mo8, mo1, bi8 = by[("moirl", 8)], by[("moirl", 1)], by[("bilevel", 8)]
    out = {
        "moirl8_fit_le_5s": {
            "value_s": mo8["fit_time_s"],
            "cpu_s": mo8["fit_cpu_s"],
            "in_reference_doc_walls": mo8["fit_time_s"] / ref_doc,
            "met": mo8["fit_time_s"] <= 5.0,
            "met_on_cpu_time": mo8["fit_cpu_s"] <= 5.0,
        },
        "moirl8_train_rmse_le_2deg": {
            "value_deg": mo8["train_rmse_deg"],
            "met": mo8["train_rmse_deg"] <= 2.0,
        },
        "8_windows_beat_1": {
            "train_1": mo1["train_rmse_deg"],
            "train_8": mo8["train_rmse_deg"],
            "cv_1": mo1["cv_rmse_deg"],
            "cv_8": mo8["cv_rmse_deg"],
            "met": mo8["cv_rmse_deg"] < mo1["cv_rmse_deg"],
        },
    }
    for nw in (1, 8):
        mo, bi = by[("moirl", nw)], by[("bilevel", nw)]
        mo_curve, bi_curve = curves[f"moirl/{nw}"], curves[f"bilevel/{nw}"]
        mo_final = mo_curve[-1][1]
        bi_final = bi_curve[-1][1]
        # DOC solves each needs to reach the other's final training merit (the common objective)
        bi_to_mo = _solves_to_reach(bi_curve, mo_final)
        mo_to_bi = _solves_to_reach(mo_curve, bi_final)
        out[f"solves_{nw}w"] = {
            "moirl_solves": mo["doc_solves"],
            "bilevel_solves": bi["doc_solves"],
            "moirl_final_merit": mo_final,
            "bilevel_final_merit": bi_final,
            "bilevel_solves_to_reach_moirl_merit": bi_to_mo,
            "moirl_solves_to_reach_bilevel_merit": mo_to_bi,
            "moirl_train_rmse": mo["train_rmse_deg"],
            "bilevel_train_rmse": bi["train_rmse_deg"],
        }
    s8 = out["solves_8w"]
    reached = s8["moirl_solves_to_reach_bilevel_merit"]
    for nw in (1, 8):
        mo, bi = by[("moirl", nw)], by[("bilevel", nw)]
        out[f"moirl_within_5pct_of_converged_bilevel_{nw}w"] = {
            "moirl_train_rmse": mo["train_rmse_deg"],
            "bilevel_train_rmse": bi["train_rmse_deg"],
            "moirl_solves": mo["doc_solves"],
            "bilevel_solves": bi["doc_solves"],
            "bilevel_stop": bi["stop_reason"],
            "met": mo["train_rmse_deg"] <= 1.05 * bi["train_rmse_deg"] and 10 * mo["doc_solves"] <= bi["doc_solves"],
        }
    out["moirl_10x_fewer_solves_than_bilevel"] = {
        "met": reached is not None
        and 10 * reached <= bi8["doc_solves"]
        and mo8["train_rmse_deg"] <= bi8["train_rmse_deg"] + 1e-9,
        "moirl_solves_to_bilevel_merit": reached,
        "bilevel_solves": bi8["doc_solves"],
    }
    return out


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(type(o).__name__)


def markdown(result: dict) -> str:
    """The benchmark's Markdown report: the methods × windows table, the MO-IRL option sweep, the targets."""
    lines = [
        f"# IRL benchmark ({'quick' if result['quick'] else 'full'})",
        "",
        f"Virtual subject ({result['data']['source']}), posture {result['data']['posture']}, "
        f"{result['data']['n_train']} training + {result['data']['n_cv']} CV reaches, "
        f"{result['data']['n_nodes']} knots. Reference DOC (cold, true weights, mean task): "
        f"{result['reference_doc_s'] * 1e3:.0f} ms wall, {result['reference_doc_cpu_s'] * 1e3:.0f} ms CPU. "
        f"True weights: train RMSE {result['truth']['train_rmse_deg']:.2f}°, "
        f"CV RMSE {result['truth']['cv_rmse_deg']:.2f}° (the floor set by trial-to-trial jitter).",
        "",
        "| method | windows | train RMSE (°) | CV RMSE (°) | truth agreement (°) | DOC solves | budget | stop "
        "| fit time (s) | fit CPU (s) | fit CPU / ref DOC CPU | iterations |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ref = result["reference_doc_cpu_s"]
    for r in result["rows"]:
        lines.append(
            f"| {r['label']} | {r['n_windows']} | {r['train_rmse_deg']:.2f} ± {r['train_rmse_sd']:.2f} "
            f"| {r['cv_rmse_deg']:.2f} ± {r['cv_rmse_sd']:.2f} | {r['truth_agreement_deg']:.2f} "
            f"| {r['doc_solves']} | {r['budget']} | {r['stop_reason'] or '—'}{_mark(r)} "
            f"| {r['fit_time_s']:.2f} | {r['fit_cpu_s']:.2f} | {r['fit_cpu_s'] / ref:.0f} | {r['iterations']} |"
        )
    if result["moirl_options"]:
        lines += [
            "",
            "MO-IRL options (8 windows):",
            "",
            "| variant | train RMSE (°) | CV RMSE (°) | truth agreement (°) | DOC solves | fit time (s) "
            "| fit CPU (s) | iterations | stop |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in result["moirl_options"]:
            lines.append(
                f"| {r['variant']} | {r['train_rmse_deg']:.2f} | {r['cv_rmse_deg']:.2f} "
                f"| {r['truth_agreement_deg']:.2f} | {r['doc_solves']} | {r['fit_time_s']:.2f} "
                f"| {r['fit_cpu_s']:.2f} | {r['iterations']} | {r['stop_reason']} |"
            )
    pf = result.get("protocol_fits")
    if pf:
        lines += [
            "",
            f"The protocol's own fits (`make run`'s reaches, {pf['sections']} sections, {pf['n_train']} training "
            f"reaches cut from their recordings and observed), CPU seconds per posture ({', '.join(pf['postures'])}), "
            f"each the least of {pf['compiled'].get('repeats', 1)} runs (every run gave the same weights: "
            f"{pf['same_weights']}):",
            "",
            "| solver | fit CPU (s) | median | DOC solves | median / ref DOC CPU |",
            "|---|---|---|---|---|",
        ]
        for key, label in (("vm", "CasADi virtual machine"), ("compiled", "compiled (`reachirl.doc.compiled`)")):
            r = pf[key]
            lines.append(
                f"| {label} | {', '.join(f'{c:.2f}' for c in r['fit_cpu_s'])} | {r['fit_cpu_median_s']:.2f} "
                f"| {', '.join(map(str, r['doc_solves']))} | {r['fit_in_reference_docs']:.0f} |"
            )
        lines += ["", f"Compiled / VM: {pf['compiled_vs_vm']:.2f}; the same weights both ways: {pf['same_weights']}."]
    for name, e in result.get("extra", {}).items():
        shown = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in e.items()}
        lines += ["", f"`{name}`: {shown}"]
    lines += ["", "Targets:", ""]
    for name, t in result["targets"].items():
        shown = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in t.items()}
        lines.append(f"- `{name}`: {shown}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # pragma: no cover
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO)
    res = run(quick=args.quick, out_dir=args.out)
    print(markdown(res))
