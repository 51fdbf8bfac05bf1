"""The "Measured" section of ``docs/benchmarks.md``, generated from the files ``make run`` and ``make bench`` write.

    .venv/bin/python benchmarks/measured.py [--results results/results.json] [--bench bench.json] [--check]

(``make measured`` runs ``make run``, ``make bench`` and then this.) It keeps the numbers it quotes in
``docs/measured.json`` (a snapshot: the protocol table of ``make run``, the benchmark figures of ``make bench``,
the machine and the wall times seen) and rewrites ``docs/benchmarks.md`` between ``<!-- measured:begin -->`` and
``<!-- measured:end -->`` from that snapshot. Without ``--results`` or ``--bench`` it only re-renders the snapshot
(``make docs``). Parts whose file is not given keep their previous snapshot.
Benchmark suites missing from the bench file keep theirs too (one machine label covers them all).
Times are given as ranges over the runs recorded and as ratios to a baseline timed in the same run, with the
machine named, since a shared machine's absolute times vary. ``tests/test_readme_measured.py`` fails when the
page differs from the snapshot, or when ``results/results.json`` holds other numbers than the snapshot.
``--check`` only compares (exit 1 on a difference).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "benchmarks.md"
SNAPSHOT = ROOT / "docs" / "measured.json"
BEGIN, END = "<!-- measured:begin -->", "<!-- measured:end -->"
SETS = (("train", "Training"), ("cv", "CV"), ("iscv", "ISCV"))
MAX_TIMES = 10  # wall times kept per machine


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    system = f"{platform.system()} {platform.release()}"
    return f"{cpu}, {os.cpu_count()} cores, {system}, Python {platform.python_version()}"


def protocol_numbers(results: dict) -> dict:
    """The ALL-postures RMSE of q per section count and set, as the page quotes them (2 decimals)."""
    main = results["protocol"]["methods"][0]
    rows = {}
    for row in results["headline"][main]:
        rows[str(row["sections"])] = {s: round(row[s]["mean"], 2) for s, _ in SETS if row.get(s)}
    return {
        "method": main,
        "postures": results["protocol"]["postures_run"],
        "n_nodes": results["protocol"]["n_nodes"],
        "split_sizes": results["split_sizes"],
        "all_q_rmse_deg": rows,
        "data_fingerprint": results["data"]["fingerprint"],
        "code_fingerprint": results["run"]["code_fingerprints"].get(main),
    }


def bench_numbers(bench: dict) -> dict:
    """The benchmark figures the page quotes, from ``bench.json`` (each suite optional)."""
    out: dict = {}
    doc = bench.get("doc")
    if doc:
        r, b = doc["reachirl"], doc["plain_baseline"]
        out["doc"] = {
            "cold_cpu_ms": round(1e3 * r["cold_cpu_median_s"], 1),
            "warm_cpu_ms": round(1e3 * r["warm_cpu_median_s"], 1),
            "cold_iterations": r["cold_iterations_median"],
            "warm_iterations": r["warm_iterations_median"],
            "plain_cold_cpu_ms": round(1e3 * b["cold_cpu_median_s"], 1),
            "plain_warm_cpu_ms": round(1e3 * b["warm_cpu_median_s"], 1),
            "converged": r["converged"],
            "ratios_cpu": {k: round(v, 2) for k, v in doc.get("ratios_cpu", {}).items()},
            "agreement_q_deg": doc["agreement"]["q_rmse_deg_max"],
            "agreement_cost": doc["agreement"]["cost_rel_diff_max"],
            "compiled_cold_cpu_ms": (
                round(1e3 * doc["compiled"]["cold_cpu_median_s"], 1) if doc.get("compiled") else None
            ),
            "compiled_warm_cpu_ms": (
                round(1e3 * doc["compiled"]["warm_cpu_median_s"], 1)
                if doc.get("compiled", {}).get("warm_cpu_median_s")
                else None
            ),
            "compiled_bit_identical": doc["compiled"]["bit_identical"] if doc.get("compiled") else None,
            "compiled_warm_vs_plain_warm": (
                round(doc["compiled"]["warm_cpu_vs_plain_warm"], 2)
                if doc.get("compiled", {}).get("warm_cpu_vs_plain_warm")
                else None
            ),
            "newton_warm": (
                {
                    "cpu_ms": round(1e3 * doc["compiled"]["warm_newton"]["cpu_median_s"], 1),
                    "vs_plain_warm": round(doc["compiled"]["warm_newton"]["cpu_vs_plain_warm"], 2),
                    "answered": doc["compiled"]["warm_newton"]["newton_answered"],
                    "max_diff_deg": float(f"{doc['compiled']['warm_newton']['max_diff_from_fatrop_warm_deg']:.2g}"),
                }
                if doc.get("compiled", {}).get("warm_newton")
                else None
            ),
            "sweep_converged": (
                f"{doc['convergence_sweep']['converged']}/{doc['convergence_sweep']['n_problems']}"
                if doc.get("convergence_sweep")
                else None
            ),
        }
    pr = bench.get("predict")
    if pr:
        out["predict"] = {
            "n_predictions": pr["n_predictions"],
            "newton_cpu_ms_median": round(pr["cpu_ms_newton"]["median"], 2),
            "fatrop_cpu_ms_median": round(pr["cpu_ms_fatrop"]["median"], 2),
            "ratio_cpu_median": round(pr["ratio_cpu_median"], 2),
            "ratio_cpu_total": round(pr["ratio_cpu_total"], 2),
            "newton_answered": pr["newton_answered"],
            "iterations_median": pr["newton_iterations_median"],
            "converged": pr["converged"]["newton_path"],
            "max_diff_deg": round(pr["max_diff_deg"], 4),
            "newton_from_optimum_deg": float(f"{pr['max_from_optimum_deg']['newton']:.2g}"),
            "fatrop_from_optimum_deg": round(pr["max_from_optimum_deg"]["fatrop"], 4),
        }
        if pr.get("compiled_lu"):  # Newton's compiled banded LU against LAPACK's, in the same run
            out["predict"] |= {
                "lapack_lu_cpu_ms_median": round(pr["cpu_ms_lapack_lu"]["median"], 2),
                "ratio_lu_cpu_median": round(pr["ratio_lu_cpu_median"], 2),
                "lu_same_answers": pr["lu_same_answers"],
            }
    ck = bench.get("checks")
    if ck:
        cost = ck["cost_vs_fatrop"]
        out["checks"] = {
            "n_solves": ck["n_solves"],
            "default_cpu_ms_median": round(ck["cpu_ms_default"]["median"], 1),
            "default_cpu_ms_mean": round(ck["cpu_ms_default"]["mean"], 1),
            "fatrop_cpu_ms_median": round(ck["cpu_ms_fatrop"]["median"], 1),
            "fatrop_cpu_ms_mean": round(ck["cpu_ms_fatrop"]["mean"], 1),
            "ratio_cpu_total": round(ck["ratio_cpu_total"], 2),
            "answered_by": ck["answered_by"],
            "not_converged": ck["not_converged"],
            "diff_deg_median": float(f"{ck['diff_deg']['median']:.2g}"),
            "diff_deg_p90": float(f"{ck['diff_deg']['p90']:.2g}"),
            "cost_higher": cost["higher_by_more_than_1e-6"],
            "cost_lower": cost["lower_by_more_than_1e-6"],
            "largest_rise_pct": float(f"{100 * cost['largest_rise']:.2g}"),
            "largest_fall_pct": float(f"{100 * cost['largest_fall']:.2g}"),
        }
    bk = bench.get("backends")
    if bk and "casadi" in bk and "crocoddyl" in bk:
        a, c = bk["casadi"], bk["crocoddyl"]
        out["backends"] = {
            "crocoddyl_vs_casadi_cold_cpu": round(c["cold_cpu_median_s"] / a["cold_cpu_median_s"], 1),
            "crocoddyl_vs_casadi_warm_cpu": round(c["warm_cpu_median_s"] / a["warm_cpu_median_s"], 1),
            "crocoddyl_converged": c["converged"],
            "agreement_q_deg_max": round(bk["agreement"]["q_rmse_deg_max"], 3),
            "agreement_cost_pct_max": float(f"{bk['agreement']['cost_diff_pct_max_abs']:.2g}"),  # 2 significant
        }
        pk = bk.get("crocoddyl_python_knots")
        if pk:
            out["backends"]["python_knots"] = {
                "compiled_over_python_cold": round(pk["compiled_over_python_cold"], 2),
                "compiled_over_python_warm": round(pk["compiled_over_python_warm"], 2),
                "identical": pk["identical"],
            }
        cw = bk.get("crocoddyl_warm")
        if cw:
            out["backends"]["warm"] = {
                "sqp_iterations_median": cw["sqp_iterations_median"],
                "rollouts_median": cw["rollouts_median"],
                "knots_share_of_time": round(cw["knots_share_of_time"], 2),
                "without_knots_vs_casadi_warm": round(cw["without_knots_vs_casadi_warm"], 1),
            }
    return out


def _range(times: list[float]) -> str:
    lo, hi = min(times), max(times)
    fmt = lambda s: f"{s / 60:.1f} min" if s >= 90 else f"{s:.0f} s"  # noqa: E731
    return fmt(lo) if len(times) == 1 or abs(hi - lo) < 1 else f"{fmt(lo)}–{fmt(hi)}"


def render(snap: dict) -> str:
    """The Measured section between the markers, from the snapshot alone."""
    lines = [
        BEGIN,
        "<!-- generated by benchmarks/measured.py from docs/measured.json: do not edit by hand; "
        "regenerate with `make measured` -->",
        "",
    ]
    p = snap.get("protocol")
    if p:
        sizes = p["split_sizes"]
        per = {s: "/".join(sorted({str(v) for v in sizes[s].values()})) for s, _ in SETS}
        lines += [
            f"- **Protocol** (`make run`: built-in virtual subjects, {p['n_nodes']} knots, postures "
            f"{', '.join(p['postures'])}, {p['method']}; RMSE of q in degrees, ALL postures; trials per posture "
            f"{', '.join(f'{lab} {per[s]}' for s, lab in SETS)}):",
            "",
            "  | sections | " + " | ".join(lab for _, lab in SETS) + " |",
            "  |---|" + "---|" * len(SETS),
        ]
        for n, row in p["all_q_rmse_deg"].items():
            lines.append(f"  | {n} | " + " | ".join(f"{row[s]:.2f}°" if s in row else "—" for s, _ in SETS) + " |")
        lines.append("")
        lines.append("  The run is deterministic: rerunning the same code with the same seed gives the same numbers.")
        for m, times in (snap.get("run_wall_s") or {}).items():
            lines.append(
                f"  Wall time of `make run` (first-time data generation included when it happened): "
                f"{_range(times)} over {len(times)} run(s) on {m}."
            )
        lines.append("")
    d = (snap.get("bench") or {}).get("doc")
    if d:
        ratios = d["ratios_cpu"]
        lines += [
            f"- **DOC** (`make bench`, on {snap['bench_machine']}; N = 100, 8 windows, all seven features, CPU "
            "medians):",
            "",
            "  | | cold | warm (10 % weight change) |",
            "  |---|---|---|",
            f"  | reachirl | {d['cold_cpu_ms']} ms, {d['cold_iterations']:g} iterations | {d['warm_cpu_ms']} ms, "
            f"{d['warm_iterations']:g} iterations |",
            f"  | plain CasADi/IPOPT baseline | {d['plain_cold_cpu_ms']} ms | {d['plain_warm_cpu_ms']} ms |",
            "",
            "  Ratios (same run, so comparable across machines): "
            + ", ".join(f"{k.replace('_vs_', ' / ').replace('_', ' ')} {v:.2f}" for k, v in ratios.items())
            + f". Converged: {d['converged']}"
            + (f"; sweep {d['sweep_converged']}" if d.get("sweep_converged") else "")
            + f". Agreement with the plain formulation: q within {d['agreement_q_deg']:.2g}°, cost within "
            f"{d['agreement_cost']:.2g}.",
            "",
        ]
        if d.get("compiled_cold_cpu_ms") is not None:
            warm = f", {d['compiled_warm_cpu_ms']} ms warm" if d.get("compiled_warm_cpu_ms") is not None else ""
            ratio = (
                f" (warm / plain warm {d['compiled_warm_vs_plain_warm']:.2f})"
                if d.get("compiled_warm_vs_plain_warm") is not None
                else ""
            )
            lines += [
                f"  The compiled solvers (`reachirl.doc.compiled`): {d['compiled_cold_cpu_ms']} ms cold{warm}{ratio}, "
                f"solutions bit-identical on {d['compiled_bit_identical']} solves.",
                "",
            ]
            nw = d.get("newton_warm")
            if nw:
                lines += [
                    f"  The same warm solves as MO-IRL makes them, by exact Newton from the previous solution "
                    f"(`warm_newton`, on by default): {nw['cpu_ms']} ms (warm / plain warm {nw['vs_plain_warm']:.2f}); "
                    f"Newton answered {nw['answered']}, fatrop the rest; at most {nw['max_diff_deg']}° from "
                    "fatrop's warm answer.",
                    "",
                ]
    pr = (snap.get("bench") or {}).get("predict")
    if pr:
        lines += [
            f"- **Predictions** (`reachirl bench predict`, same machine; {pr['n_predictions']} predictions of the "
            "built-in data by its 8-section protocol fits, from each fit's moved rollout, CPU): exact Newton "
            f"{pr['newton_cpu_ms_median']} ms median against {pr['fatrop_cpu_ms_median']} ms for fatrop from the "
            f"same start (ratio {pr['ratio_cpu_median']:.2f}; all of them {pr['ratio_cpu_total']:.2f}). Newton "
            f"answered {pr['newton_answered']}/{pr['n_predictions']} ({pr['iterations_median']:g} steps median), "
            f"every prediction converged; the two answers differ by at most {pr['max_diff_deg']}°, fatrop's "
            f"tolerance: from the optimum (Newton rerun from fatrop's answer) fatrop lies up to "
            f"{pr['fatrop_from_optimum_deg']}° away, Newton {pr['newton_from_optimum_deg']}°."
            + (
                f" With LAPACK's `dgbsv` for Newton's banded LU instead of its compiled twin (`reachirl.doc.banded`), "
                f"interleaved: {pr['lapack_lu_cpu_ms_median']} ms (compiled / LAPACK {pr['ratio_lu_cpu_median']:.2f}); "
                f"{pr['lu_same_answers']} of the {pr['n_predictions']} predictions the same to the last bit."
                if "ratio_lu_cpu_median" in pr
                else ""
            ),
            "",
        ]
    ck = (snap.get("bench") or {}).get("checks")
    if ck:
        by = ", ".join(f"{k} {v}" for k, v in sorted(ck["answered_by"].items(), key=lambda kv: -kv[1]))
        lines += [
            f"- **The uncertainty's checked samples** (`reachirl bench checks`, same machine; {ck['n_solves']} "
            "re-solves of the built-in data's 8-section protocol fits under their first weight samples, warm from "
            "the fits' solutions, CPU): by their path (exact Newton, then the interior point on the knots, then "
            f"fatrop) {ck['default_cpu_ms_median']} ms median "
            f"({ck['default_cpu_ms_mean']} ms mean) against {ck['fatrop_cpu_ms_median']} ms "
            f"({ck['fatrop_cpu_ms_mean']} ms) for fatrop from the same start, {ck['ratio_cpu_total']:.2f} of its "
            f"total. Answered by: {by}. Not converged: {ck['not_converged']['default_path']} on their path, "
            f"{ck['not_converged']['fatrop_path']} on fatrop's. The answers lie {ck['diff_deg_median']}° apart "
            f"(median; 90th percentile {ck['diff_deg_p90']}°); their path's cost is lower than fatrop's by "
            f"more than 1e-6 on {ck['cost_lower']} (up to {-ck['largest_fall_pct']} %), higher on "
            f"{ck['cost_higher']} (at most {ck['largest_rise_pct']} %; another local optimum).",
            "",
        ]
    b = (snap.get("bench") or {}).get("backends")
    if b:
        lines += [
            f"- **Crocoddyl/CSQP** against CasADi (`make bench`, same run): {b['crocoddyl_vs_casadi_cold_cpu']}× "
            f"the cold CPU time, {b['crocoddyl_vs_casadi_warm_cpu']}× the warm; converged "
            f"{b['crocoddyl_converged']}; agreement within {b['agreement_q_deg_max']}° RMSE of q and "
            f"{b['agreement_cost_pct_max']} % of the cost."
            + (
                f" Its warm solves take {b['warm']['sqp_iterations_median']:g} SQP iterations and "
                f"{b['warm']['rollouts_median']:g} rollouts (medians); the knot models are "
                f"{100 * b['warm']['knots_share_of_time']:.0f} % of their time; without that time, the warm "
                f"solve would take {b['warm']['without_knots_vs_casadi_warm']}× CasADi's."
                if b.get("warm")
                else ""
            )
            + (
                f" Its knot models are compiled: the same solves ({b['python_knots']['identical']} identical) take "
                f"{b['python_knots']['compiled_over_python_cold']}× (cold) and "
                f"{b['python_knots']['compiled_over_python_warm']}× (warm) the CPU time of the same knots in Python."
                if b.get("python_knots")
                else ""
            ),
            "",
        ]
    lines.append(END)
    return "\n".join(lines)


def measured_block(text: str) -> str:
    i, j = text.find(BEGIN), text.find(END)
    if i < 0 or j < 0:
        raise SystemExit(f"{PAGE}: no {BEGIN} ... {END} block")
    return text[i : j + len(END)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, help="results.json written by `make run` (default: keep the snapshot)")
    ap.add_argument("--bench", type=Path, help="bench.json written by `make bench` (default: keep the snapshot)")
    ap.add_argument("--check", action="store_true", help="compare only; exit 1 when the page differs")
    args = ap.parse_args(argv)
    snap = json.loads(SNAPSHOT.read_text(encoding="utf-8")) if SNAPSHOT.is_file() else {}
    if args.results:
        res = json.loads(args.results.read_text(encoding="utf-8"))
        snap["protocol"] = protocol_numbers(res)
        if not res["run"]["reused"]:  # a resumed run's time says nothing about a full one
            times = snap.setdefault("run_wall_s", {}).setdefault(machine(), [])
            times.append(round(res["timing"]["total_s"], 1))
            del times[:-MAX_TIMES]
    if args.bench:
        # suites the file does not hold (``reachirl bench backends --out F``) keep their previous snapshot
        snap["bench"] = {**snap.get("bench", {}), **bench_numbers(json.loads(args.bench.read_text(encoding="utf-8")))}
        snap["bench_machine"] = machine()
    text = PAGE.read_text(encoding="utf-8")
    new = text.replace(measured_block(text), render(snap))
    if args.check:
        if new != text:
            print(
                "docs/benchmarks.md's Measured section differs from docs/measured.json; run `make docs`",
                file=sys.stderr,
            )
            return 1
        return 0
    SNAPSHOT.write_text(json.dumps(snap, indent=2) + "\n", encoding="utf-8")
    PAGE.write_text(new, encoding="utf-8")
    print(f"wrote {SNAPSHOT} and the Measured section of {PAGE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
