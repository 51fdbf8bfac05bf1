"""Everything ``reproduce`` writes from its units' results, one function per output:

* :func:`write_tables` — ``table.md`` and ``table.csv``;
* :func:`write_figures` — ``figures/*.png`` (and ``.pdf``), drawn in worker processes
  (:mod:`reachirl.experiments.rendering`; :func:`figure_jobs` says what they draw);
* :func:`write_predictions` — ``predictions/<unit key>/<trial id>.csv`` and ``.mot`` (:mod:`reachirl.data.exports`),
  of the units that :class:`UnitOutputs` did not write as they finished;
* :func:`write_results_json` — ``results.json``;
* :func:`write_report` — ``report.md``.

What they state is computed by :mod:`reachirl.experiments.analysis` (and the method's words by
:mod:`reachirl.experiments.method`); here it is only put into words, tables and figures. :func:`write_outputs`
calls them in turn on the :class:`~reachirl.experiments.results.RunResult` that
:func:`reachirl.experiments.runner.reproduce` returns (the command line calls both), the figures being drawn
meanwhile. Predictions are read back from the units' NPZ checkpoints, so a resumed run writes the same files as an
uninterrupted one.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..features import FEATURES
from ..io import atomic_write_json, atomic_write_text
from ..irl.methods import builds_on_moirl
from ..irl.model import MODEL_FORMAT
from ..irl.provenance import versions
from . import tables as tb
from .analysis import methods_run, prediction_agreement, section_comparisons, truth_comparison
from .cost import uncertainty_summary, write_model
from .method import convergence_text, method_lines, unit_method
from .names import CONVERGENCE_TITLE, backend_text, natural_key, sections_text
from .no_data import annotate_no_data, csv_with_reasons, split_reasons
from .protocol import SET_LABELS, SETS, ProtocolConfig, unit_observes
from .rendering import FigureJob, FigureWorkers, drawing
from .results import RunResult, is_table_unit, load_unit_arrays

__all__ = [
    "RESULTS_FORMAT",
    "UnitOutputs",
    "figure_jobs",
    "is_run_figure",
    "marked_run_figures",
    "prediction_note",
    "weights_caption",
    "write_figures",
    "write_outputs",
    "write_predictions",
    "write_report",
    "write_results_json",
    "write_tables",
    "write_unit_predictions",
]

RESULTS_FORMAT = "reachirl-reproduce/1"
TORQUE_CHANGE, JOINT_ACCELERATION = FEATURES.index("torque_change"), FEATURES.index("joint_acceleration")


def _agreement_note(agreement: dict, n_true: int) -> str:
    def mean(key, s):
        v = [a[s][key] for a in agreement.values() if s in a]
        return f"{np.mean(v):.2f}" if v else "—"

    return (
        f"Virtual subjects, {sections_text(n_true)} (mean over postures, train / CV / ISCV): the fits' predictions lie "
        + " / ".join(mean("learned_vs_true_deg", s) for s in SETS)
        + "° from the true weights' own; the true weights predict the recorded reaches to "
        + " / ".join(mean("true_vs_recorded_deg", s) for s in SETS)
        + "°, the fits to "
        + " / ".join(mean("learned_vs_recorded_deg", s) for s in SETS)
        + "°."
    )


def _count(items) -> dict:
    out: dict = {}
    for i in items:
        out[i] = out.get(i, 0) + 1
    return out


def _pick(options: Sequence, preferred) -> object | None:
    for p in preferred:
        if p in options:
            return p
    return options[0] if options else None


def _fmt(c: dict | None) -> str:
    return "—" if not c or c.get("mean") is None else f"{c['mean']:.2f} ± {c['std']:.2f}"


OBSERVED = (
    "the rest-to-rest DOC from the trial's onset posture to its target, seen between its own crossings of "
    "the onset threshold the trial was cut at, as the reach was recorded (reachirl.doc.observation; a trial "
    "not cut at a threshold: the DOC over its own duration)"
)
WHOLE = "the DOC from the trial's own initial state, target and duration"


def prediction_note(units) -> str:
    """How the units' predictions were made, from their records (``method``, ``estimator_options``): seen as
    the reach was recorded by the units that observe, the DOC over the trial by the others."""
    observing = {u["method"]: unit_observes(u["method"], u.get("estimator_options", ())) for u in units}
    seen = sorted(m for m, o in observing.items() if o)
    whole = sorted(m for m, o in observing.items() if not o)
    if not whole:
        return f"each prediction is {OBSERVED}"
    if not seen:
        return f"each prediction is {WHOLE}"
    return f"the predictions of {', '.join(seen)} are {OBSERVED}; those of {', '.join(whole)}, {WHOLE}"


def _notes(results: dict[str, dict], config: ProtocolConfig) -> tuple[list[str], dict]:
    fit_solves = sum(r["fit"]["doc_solves"] for r in results.values())
    fit_fail = sum(r["fit"]["doc_failures"] for r in results.values())
    ev_solves = sum(r["evaluation"]["doc_solves"] for r in results.values())
    ev_fail = sum(r["evaluation"]["doc_failures"] for r in results.values())
    notes = [
        f"DOC failures: {fit_fail} rollouts of {fit_solves} solves during the fits failed even after their "
        "cold and demonstration-path retries (such a line-search try is rejected); "
        f"{sum(r['fit'].get('doc_recovered', 0) for r in results.values())} tries were rescued by a retry; "
        f"{ev_fail} of {ev_solves} predictions did not converge (counted per cell, left out of the RMSE "
        "statistics).",
        tb.ALL_CONVENTION,
        "Fits ended by: "
        + ", ".join(
            f"{k} {v}"
            for k, v in sorted(_count(r["stop_reason"] or "one-shot (no iterations)" for r in results.values()).items())
        )
        + (
            f" (at most {config.max_iter} iterations per stage; an observed fit's iterations are those of its second"
            " stage, which starts where its whole-rollout first stage ended: MODEL.json `info.first_stage`)."
            if any(builds_on_moirl(m) for m in config.methods)
            else " (KKT solves once; bilevel stops at its own budget of DOC solves, not at --max-iter)."
        ),
        "RMSE in degrees, mean ± population SD over trials; "
        + prediction_note([r["unit"] for r in results.values()])
        + ", compared on normalised time.",
    ]
    flagged = sorted(f"{r['key']} ({r['flag']})" for r in results.values() if r.get("flag"))
    notes.append("Fits flagged: " + (", ".join(flagged) if flagged else "none") + ". " + tb.FLAG_NOTE)
    warned: dict[str, list[str]] = {}  # each warning of the fits (MODEL.json info.warnings) with the units it came from
    for r in sorted(results.values(), key=lambda r: r["key"]):
        for w in r.get("warnings") or []:
            warned.setdefault(str(w), []).append(r["key"])
    if warned:
        notes.append(
            "Fit warnings (also in each model's `info.warnings`): "
            + "; ".join(f"{', '.join(keys)}: {w}" for w, keys in warned.items())
            + "."
        )
    zero = sorted(r["key"] for r in results.values() if not np.any(np.asarray(r["weights"]) > 0))
    if zero:
        notes.append(
            f"Degenerate fits: {', '.join(zero)} learned all-zero weights (the DOC then has no cost and "
            "returns its initial guess, a minimum-jerk path); their rows are reported as they are."
        )
    doc = {"fit_solves": fit_solves, "fit_failures": fit_fail, "predictions": ev_solves, "prediction_failures": ev_fail}
    return notes, doc


def _other_units_notes(run: RunResult) -> list[str]:
    """The notes above count the main table's units only; the all-pairs and posture-transfer units (``run.pairs``,
    ``run.transfer``) are fits too, whose DOC failures, flags and warnings would otherwise be said nowhere: one
    note for each kind run."""
    notes = []
    for units, what in (
        (run.pairs, "all-pairs units (the other training subjects' fits; `iscv_pairs.csv`, not the tables above)"),
        (run.transfer, "posture-transfer units (`posture_transfer.csv`, not the tables above)"),
    ):
        if not units:
            continue
        rs = sorted(units.values(), key=lambda r: r["key"])
        fit_solves = sum(r["fit"]["doc_solves"] for r in rs)
        fit_fail = sum(r["fit"]["doc_failures"] for r in rs)
        ev_solves = sum(r["evaluation"]["doc_solves"] for r in rs)
        ev_fail = sum(r["evaluation"]["doc_failures"] for r in rs)
        flagged = [f"{r['key']} ({r['flag']})" for r in rs if r.get("flag")]
        warned: dict[str, list[str]] = {}
        for r in rs:
            for w in r.get("warnings") or []:
                warned.setdefault(str(w), []).append(r["key"])
        notes.append(
            f"The {len(rs)} {what}: {fit_fail} rollouts of {fit_solves} solves during their fits failed; "
            f"{ev_fail} of {ev_solves} predictions did not converge; fits flagged: "
            + (", ".join(flagged) if flagged else "none")
            + (
                "; fit warnings: " + "; ".join(f"{', '.join(keys)}: {w}" for w, keys in warned.items())
                if warned
                else ""
            )
            + "."
        )
    return notes


def markdown_tables(tables: dict, postures, sections, n_trials: dict) -> list[str]:
    """The Markdown tables of ``table.md`` (and ``report.md``), one per method."""
    methods = list(tables)
    return [
        tb.to_markdown(
            tables[m],
            postures,
            sections,
            n_trials,
            title=f"{m}: RMSE of the joint angles (deg)" if len(methods) > 1 else "",
        )
        for m in methods
    ]


def write_tables(
    out: Path,
    tables: dict,
    postures,
    sections,
    n_trials: dict,
    notes: list[str],
    reasons: dict[str, str] | None = None,
    md_tables: list[str] | None = None,
) -> list[str]:
    """``table.md`` (one table per method, then the notes) and ``table.csv``; returns the Markdown tables
    (``md_tables``: :func:`markdown_tables`, when already made)."""
    md_tables = md_tables or markdown_tables(tables, postures, sections, n_trials)
    atomic_write_text(out / "table.md", "\n".join(md_tables) + "\n" + "\n".join(f"- {n}" for n in notes) + "\n")
    csv = tb.to_csv(tables, postures, sections)
    atomic_write_text(out / "table.csv", csv_with_reasons(csv, reasons) if reasons is not None else csv)
    return md_tables


def hardest_words(tab: dict, postures: Sequence[str], sections: int) -> str:
    """The postures with the highest mean CV RMSE of q at ``sections``, each with its SD over trials, and the next
    one: a ranking of means over the trials of one fit per posture, which no test compares."""
    cell = {p: tab[p]["cv"][sections]["q"] for p in postures}
    ranked = sorted(cell, key=lambda p: cell[p]["mean"], reverse=True)

    def fmt(p):
        sd = cell[p].get("std")
        return f"{p} ({cell[p]['mean']:.2f}{'' if sd is None else f' ± {sd:.2f}'}°)"

    if len(ranked) == 2:
        head = f"Higher mean CV RMSE ({sections_text(sections)}): {fmt(ranked[0])} than {fmt(ranked[1])}"
    else:
        nxt = f", then {fmt(ranked[2])}" if len(ranked) > 2 else ""
        head = f"Highest mean CV RMSE ({sections_text(sections)}): {', '.join(fmt(p) for p in ranked[:2])}{nxt}"
    return (
        f"{head} (mean ± SD over the trials; a ranking of means, not tested: one fit per posture) (the seed's "
        "hardest: P3 and P5)."
    )


def ends_determined_words(results: dict, method: str, truth_metrics: dict) -> str:
    """How many of the learned dominant features' shares at onset and end (first and last windows, per posture of
    the truth comparison) the fits' weight samples determine (``share_intervals.determined``, on the fit's own
    reach), in words: a dominant feature is a finding only where its share is determined."""
    by = {(r["unit"]["posture"], r["unit"]["sections"]): r for r in results.values() if r["unit"]["method"] == method}
    n = n_det = n_missing = 0
    for p, m in truth_metrics.items():
        r = by.get((p, m["sections"]))
        iv = ((r or {}).get("uncertainty") or {}).get("share_intervals")
        for i in (0, -1):
            n += 1
            if iv is None:
                n_missing += 1
                continue
            n_det += bool(iv["determined"][i][FEATURES.index(m["learned_dominant"][i])])
    if n_missing == n:
        return "no weight samples: not a finding"
    words = f"{n_det} of {n} of those shares (posture × first and last window) determined by the data"
    if n_missing:
        words += f", {n_missing} without weight samples"
    return words + ("" if n_det == n else "; the others undetermined: not a finding")


def truth_reach_words(truth_metrics: dict) -> str:
    """Whose features the learned and true shares of the truth comparison are weighed on, in words, from each
    posture's ``shares_on`` (:func:`~reachirl.experiments.analysis.truth_comparison`: the true weights' own
    noise-free reach, or the demonstrations' where that DOC failed)."""
    demos = sorted((p for p, m in truth_metrics.items() if m.get("shares_on") == "demonstrations"), key=natural_key)
    reach = "the true weights' own noise-free reach"
    if not demos:
        return reach
    if len(demos) == len(truth_metrics):
        return "the training demonstrations (the true weights' own reach did not converge)"
    return f"{reach} ({', '.join(demos)}: the training demonstrations', where that reach did not converge)"


def weights_caption(shares: dict, intervals: dict, on_reach: bool = True) -> str:
    """Fig. 3's caption: what it shows and, per section count (a row of panels), how many shares the data
    determines and the largest of those with their 95 % intervals (``shares[(posture, sections)] = (n_windows,
    7)`` cost shares; ``intervals[(posture, sections)]``: the fit's ``share_intervals``, where it has them;
    ``on_reach``: the shares are on the fits' own reaches, else on the demonstrations). An undetermined share is
    never quoted."""
    name = {f: f.replace("_", " ") for f in FEATURES}
    rows = []
    for n in sorted({n for _, n in shares}):
        keys = [k for k in shares if k[1] == n]
        if not all(k in intervals for k in keys):
            rows.append(f"{sections_text(n)}: no weight samples, no share is a finding")
            continue
        found = []
        for p, _ in keys:
            iv = intervals[(p, n)]
            s = np.asarray(shares[(p, n)], dtype=float)
            for w, j in zip(*np.nonzero(np.asarray(iv["determined"], dtype=bool)), strict=True):
                found.append((s[w, j], p, w, j, iv["low"][w][j], iv["high"][w][j]))
        n_cells = sum(np.asarray(shares[k]).size for k in keys)
        top = sorted(found, key=lambda f: -f[0])[:3]
        quoted = "; ".join(
            f"{p} window {w + 1} {name[FEATURES[j]]} {v:.2f} [{lo:.2f}, {hi:.2f}]" for v, p, w, j, lo, hi in top
        )
        rows.append(
            f"{sections_text(n)}: {len(found)} of {n_cells} shares determined"
            + (f", the largest {quoted}" if found else "")
        )
    base = (
        "on the fit's own reach (ω·Φ of the reach the weights predict, normalised per window"
        + (": the shares the 95 % intervals bracket)" if intervals else ")")
        if on_reach
        else "on the training demonstrations (ω·Φ*, normalised per window)"
    )
    hatched = (
        "Hatched: undetermined (interval wider than 0.25, or not containing the fit's share), not a finding. "
        if intervals
        else "Nothing is hatched: the fits shown have no weight samples (`--uncertainty`; MO-IRL and MaxEnt draw "
        "them), so no share is a finding. "
    )
    return (
        "Seed Fig. 3 equivalent: learned weights per posture (columns) and section count (rows), each shown as the "
        f"feature's share of its window's cost {base}. " + hatched + ". ".join(rows) + "."
    )


#: the figures, costliest to draw first (workers take them in this order)
_DRAW_ORDER = (
    "fig3_weights.png",
    "weights_vs_truth.png",
    "convergence.png",
    "fig4_iscv.png",
    "fig2_prediction.png",
    "methods.png",
)


def _job(plot: str, fig_dir: Path, name: str, pdf: bool, **kwargs) -> FigureJob:
    """``figures.<plot>(**kwargs)``, saved as ``fig_dir/name`` (and its PDF first, with ``pdf``)."""
    paths = ((fig_dir / f"{Path(name).stem}.pdf",) if pdf else ()) + (fig_dir / name,)
    return FigureJob(f"{__package__}.figures:{plot}", kwargs, paths)


def figure_jobs(
    run: RunResult, tables: dict, truth: tuple[dict, dict, dict], fig_dir: Path | None = None, pdf: bool = False
) -> tuple[list[FigureJob], dict[str, dict]]:
    """What :func:`write_figures` draws: the jobs (:class:`~reachirl.experiments.rendering.FigureJob`, costliest
    first) and ``{name: {"caption"}}`` in the report's order."""
    out = run.out_dir
    fig_dir = fig_dir or out / "figures"
    results, postures = run.results, run.postures
    sections, methods = list(run.config.sections), list(run.config.methods)
    main = methods[0]
    on = backend_text(run.config.backend)  # the titles name the backend when it is not CasADi (the default)
    figs: dict[str, dict] = {}
    jobs: dict[str, FigureJob] = {}
    by = {(r["unit"]["method"], r["unit"]["posture"], r["unit"]["sections"]): r for r in results.values()}

    def key(m, p, n):
        return by[(m, p, n)]["key"] if (m, p, n) in by else None

    p2 = _pick(postures, ["P2"])
    n8 = _pick(sorted(sections, reverse=True), [8])
    if p2 is not None and key(main, p2, n8):
        arrays = load_unit_arrays(out, key(main, p2, n8))
        if "train/t" in arrays:
            jobs["fig2_prediction.png"] = _job(
                "plot_prediction",
                fig_dir,
                "fig2_prediction.png",
                pdf,
                arrays=arrays,
                set_name="train",
                title=f"{p2}, {sections_text(n8)}: training demonstrations (dashed) vs {main} predictions{on} (solid)",
            )
            figs["fig2_prediction.png"] = {
                "caption": f"Seed Fig. 2 equivalent: posture {p2}, {sections_text(n8)}, "
                "training trials of the training subject, q (top) and q̇ (bottom)."
            }
    shares = {
        (r["unit"]["posture"], r["unit"]["sections"]): r["cost_shares"]
        for r in results.values()
        if r["unit"]["method"] == main
    }
    if shares:
        flags = {
            (r["unit"]["posture"], r["unit"]["sections"]): r.get("flag")
            for r in results.values()
            if r["unit"]["method"] == main
        }
        undetermined = {
            (r["unit"]["posture"], r["unit"]["sections"]): _undetermined(r)
            for r in results.values()
            if r["unit"]["method"] == main and r.get("uncertainty")
        }
        jobs["fig3_weights.png"] = _job(
            "plot_weights",
            fig_dir,
            "fig3_weights.png",
            pdf,
            shares=shares,
            postures=postures,
            sections=sections,
            flags=flags,
            undetermined=undetermined or None,
            method=main,  # without samples, the footnote says what draws them for its fits (bilevel's, KKT's: none)
        )
        intervals = {
            (r["unit"]["posture"], r["unit"]["sections"]): r["uncertainty"]["share_intervals"]
            for r in results.values()
            if r["unit"]["method"] == main and r.get("uncertainty")
        }
        on_reach = all(r.get("cost_shares_on") == "fit_reach" for r in results.values() if r["unit"]["method"] == main)
        figs["fig3_weights.png"] = {"caption": weights_caption(shares, intervals, on_reach)}
    iscv_postures = [p for p in ("P2", "P4") if p in postures] or list(postures[:2])
    iscv_arrays = {}
    for p in iscv_postures:
        k = key(main, p, n8)
        if k:
            a = load_unit_arrays(out, k)
            if "iscv/t" in a:
                iscv_arrays[p] = a
    if iscv_arrays:
        jobs["fig4_iscv.png"] = _job(
            "plot_iscv",
            fig_dir,
            "fig4_iscv.png",
            pdf,
            arrays_by_posture=iscv_arrays,
            title=f"ISCV, {sections_text(n8)}: measured (dashed) vs predicted{on} (solid)",
        )
        figs["fig4_iscv.png"] = {
            "caption": f"Seed Fig. 4 equivalent: ISCV for postures {', '.join(iscv_arrays)} "
            f"({sections_text(n8)}), q (top) and q̇ (bottom) over normalised time."
        }
    hist = {
        (r["unit"]["posture"], r["unit"]["sections"]): r["history"]
        for r in results.values()
        if r["unit"]["method"] == main
    }
    if hist:
        first = next(r["unit"] for r in results.values() if r["unit"]["method"] == main)
        described = unit_method(main, first.get("estimator_options"), first.get("tol"), tasks=1)
        words = convergence_text(described["options"] if described else None)
        jobs["convergence.png"] = _job(
            "plot_convergence",
            fig_dir,
            "convergence.png",
            pdf,
            histories=hist,
            sections=sections,
            title=CONVERGENCE_TITLE + on,
            merit_label=words["merit_label"],
            start=words["start"],
        )
        figs["convergence.png"] = {"caption": words["caption"]}
    learned, true, truth_metrics = truth
    if learned:
        n_true = next(iter(truth_metrics.values()))["sections"]
        truth_flags = {
            r["unit"]["posture"]: r.get("flag")
            for r in results.values()
            if r["unit"]["method"] == main and r["unit"]["sections"] == n_true
        }
        truth_undetermined = {
            r["unit"]["posture"]: _undetermined(r)
            for r in results.values()
            if r["unit"]["method"] == main and r["unit"]["sections"] == n_true and r.get("uncertainty")
        }
        on = truth_reach_words(truth_metrics)
        jobs["weights_vs_truth.png"] = _job(
            "plot_truth",
            fig_dir,
            "weights_vs_truth.png",
            pdf,
            learned=learned,
            true=true,
            title=f"Virtual subjects, {sections_text(n_true)}: learned vs true weights (cost shares)",
            flags=truth_flags,
            undetermined=truth_undetermined or None,
            on=on,
        )
        figs["weights_vs_truth.png"] = {
            "caption": f"Virtual subjects, {sections_text(n_true)}: learned (top) vs true (bottom) cost shares, "
            f"both on the features of {on}; true weights = mean of the "
            "training trials' own (jittered) weights from truth.json. "
            + (
                "The hatching marks the learned shares whose 95 % interval (on the fit's own reach) is wider than "
                "0.25 or misses the fit's share: undetermined by the data, not a finding."
                if truth_undetermined
                else "Nothing is hatched: the fits shown have no weight samples (`--uncertainty`), so no learned "
                "share is a finding."
            )
        }
    if len(methods) > 1:
        heads = {m: {s: {n: tables[m][tb.ALL][s].get(n, {}).get("q") for n in sections} for s in SETS} for m in methods}
        jobs["methods.png"] = _job("plot_methods", fig_dir, "methods.png", pdf, headlines=heads, sections=sections)
        figs["methods.png"] = {
            "caption": "ALL-postures RMSE of q per method, set and section count: bars the mean, error bars ± the SD "
            "of the table's ALL row (its convention: over the postures' means, or a single posture's trials)."
        }
    return [jobs[n] for n in _DRAW_ORDER if n in jobs], figs


def write_figures(
    run: RunResult,
    tables: dict,
    truth: tuple[dict, dict, dict],
    fig_dir: Path | None = None,
    pdf: bool = False,
    workers: int = 1,
) -> dict[str, dict]:
    """``figures/*.png`` (and ``.pdf`` with ``pdf``) under ``run.out_dir`` (or ``fig_dir``), drawn in ``workers``
    processes (:mod:`reachirl.experiments.rendering`); returns ``{name: {"caption"}}``."""
    jobs, figs = figure_jobs(run, tables, truth, fig_dir, pdf)
    with drawing(jobs, workers) as figures:
        pass
    figures.close()
    return figs


def write_predictions(run: RunResult, skip=frozenset()) -> list[Path]:
    """``predictions/<unit key>/<trial id>.csv`` and ``.mot`` for every trial of every set of every unit but those
    in ``skip`` (already written by :func:`write_unit_predictions`). Returns the index files."""
    written = [write_unit_predictions(run.out_dir, k, run.results[k]) for k in sorted(run.results) if k not in skip]
    return [p for p in written if p is not None]


def write_unit_predictions(out_dir, key: str, result: dict) -> Path | None:
    """``out_dir/predictions/<key>/``: the unit's every trial of every set (:func:`reachirl.data.exports.
    export_trajectories`), read from its NPZ checkpoint; a prediction whose DOC did not converge (the unit's
    record of the trial) is left out, listed in the index as such. Returns the index (None: no trials)."""
    from ..data.exports import TrajectoryExport, export_trajectories

    a = load_unit_arrays(out_dir, key)
    items = []
    for s in SETS:
        if f"{s}/ids" not in a:
            continue
        records = ((result.get("sets") or {}).get(s) or {}).get("trials") or ()
        converged = {str(r.get("id")): r.get("converged") for r in records}
        for i, tid in enumerate(a[f"{s}/ids"]):
            items.append(
                TrajectoryExport(
                    id=str(tid),
                    t=a[f"{s}/t"][i].astype(float),
                    side=str(a[f"{s}/sides"][i]),
                    set=s,
                    demo={k: a[f"{s}/demo_{k}"][i].astype(float) for k in ("q", "qd", "tau")},
                    pred={k: a[f"{s}/pred_{k}"][i].astype(float) for k in ("q", "qd", "tau")},
                    converged=converged.get(str(tid)) is not False,
                )
            )
    return export_trajectories(Path(out_dir) / "predictions" / key, items) if items else None


class UnitOutputs:
    """A unit's own outputs, written by the coordinating process as the unit finishes, while the others run: its
    model (:func:`~reachirl.experiments.cost.write_model`) and, for a unit of the table, its predictions
    (:func:`write_unit_predictions`). Given to :func:`write_outputs`, which writes the other units' (those reused
    from checkpoints, and all of them without it)."""

    def __init__(self, out_dir) -> None:
        self.out_dir = Path(out_dir)
        self.written: set[str] = set()
        self.predictions_s = 0.0  # the predictions' part of the time spent here, s

    def __call__(self, key: str, result: dict) -> None:
        write_model(self.out_dir, key, result)
        if is_table_unit(result):
            t0 = time.perf_counter()
            write_unit_predictions(self.out_dir, key, result)
            self.predictions_s += time.perf_counter() - t0
        self.written.add(key)


def write_results_json(
    run: RunResult, tables: dict, figs: dict, truth_metrics: dict, notes: list[str], doc: dict, comparisons: dict
) -> Path:
    """``results.json`` (schema: docs/outputs.md)."""
    config, sections = run.config, list(run.config.sections)
    units = []
    for r in sorted(run.results.values(), key=lambda r: r["key"]):
        units.append(
            {
                k: r.get(k)
                for k in (
                    "key",
                    "unit",
                    "fingerprint",
                    "weights",
                    "cost_shares",
                    "cost_shares_on",
                    "n_iter",
                    "stop_reason",
                    "flag",
                    "warnings",
                    "smoothness",
                    "fit",
                    "evaluation",
                    "history",
                )
            }
            | {
                "sets": {s: {"summary": r["sets"][s]["summary"], "trials": r["sets"][s]["trials"]} for s in SETS},
                "predictions": f"units/{r['key']}.npz",
                "model": f"models/{r['key']}.json",
                "uncertainty": uncertainty_summary(r.get("uncertainty")),
            }
        )
    results_json = {
        "format": RESULTS_FORMAT,
        "data": run.dataset.describe(),
        "protocol": config.to_dict() | {"train_subject": run.train_subject, "postures_run": list(run.postures)},
        "method": methods_run(run),
        "split_sizes": run.split_sizes,
        "tables": tables,
        "headline": {m: tb.headline(tables[m], sections) for m in config.methods},
        "comparisons": comparisons,
        "all_postures_convention": tb.ALL_CONVENTION,
        "seed_table": {
            "source": "seed paper Table II (Berret et al.'s human data, 2 subjects): different data",
            "table": tb.SEED_TABLE,
        },
        "doc": doc,
        "truth_comparison": truth_metrics,
        "figures": {f"figures/{k}": v["caption"] for k, v in figs.items()},
        "units": units,
        "run": run.run_info,
        "timing": run.timing,
        "notes": notes,
    }
    path = run.out_dir / "results.json"
    atomic_write_json(path, annotate_no_data(results_json, split_reasons(config)))
    return path


def write_report(
    run: RunResult,
    tables: dict,
    md_tables: list[str],
    notes: list[str],
    figs: dict,
    truth_metrics: dict,
    comparisons: dict,
    extra_md: Sequence[str] = (),
) -> Path:
    """``report.md`` (``extra_md``: more sections, before "Run")."""
    path = run.out_dir / "report.md"
    atomic_write_text(path, _report_md(run, tables, md_tables, notes, figs, truth_metrics, comparisons, extra_md))
    return path


def _unit_model(path: Path) -> bool:
    """Whether ``path`` is a model a ``reproduce`` run wrote for one of its units (its ``info.unit`` is its
    name): a model file of the user's own (``reachirl fit``) is never one."""
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    info = d.get("info") if isinstance(d, dict) else None
    return isinstance(info, dict) and info.get("unit") == path.stem and d.get("format") == MODEL_FORMAT


#: the files a run writes at the top of its folder besides run.toml (an earlier run's are removed first)
RUN_OUTPUT_FILES = ("results.json", "report.md", "table.md", "table.csv", "iscv_pairs.csv", "posture_transfer.csv")


def is_run_figure(name: str) -> bool:
    """Whether ``name`` is the file of one of a run's figures (``fig2_prediction.png``, ``methods.pdf``,
    ``iscv_pairs_moirl_s8.png`` ...)."""
    import re

    stems = "|".join(re.escape(Path(n).stem) for n in _DRAW_ORDER)
    return re.fullmatch(rf"(?:{stems}|iscv_pairs_.+|iscv_vs_cv_.+)\.(?:png|pdf)", name) is not None


def marked_run_figures(folder: Path, keep=()) -> list[Path]:
    """The files of a run's figures (:func:`is_run_figure`) in ``folder`` that reachirl drew
    (:func:`~reachirl.experiments.figures.is_marked_figure`; never a file of the user's own), but those named in
    ``keep``."""
    keep = set(keep)
    named = [f for f in sorted(Path(folder).iterdir()) if f.name not in keep and is_run_figure(f.name)]
    if not named:  # nothing to read: matplotlib (the figures module's) is not imported
        return []
    from .figures import is_marked_figure

    return [f for f in named if is_marked_figure(f)]


def remove_previous_outputs(out_dir: str | Path, keys: frozenset[str] | set[str] = frozenset()) -> list[Path]:
    """What an earlier run into ``out_dir`` wrote and a run of units ``keys`` will not write again: its tables,
    report and results.json (``iscv_pairs.csv`` and ``posture_transfer.csv`` too), its figures (redrawn; a figure
    this run does not draw, such as the methods' comparison of a run with more methods, would stay beside the new
    ones), the models (those a run wrote for a unit: never a model file of the user's own) and the exports in the
    prediction folders of units not in ``keys`` (a file of the user's own in one stays). The checkpoints
    (``units/``) stay, to be reused. ``reachirl reproduce`` calls it with no keys before its first unit, so that
    an interrupted rerun never leaves an earlier run's results looking finished beside the new run's
    ``run.toml``. Returns what was removed."""
    out = Path(out_dir)
    removed = [out / n for n in RUN_OUTPUT_FILES if (out / n).is_file()]
    if (out / "figures").is_dir():
        removed += [f for f in (out / "figures").iterdir() if f.is_file() and is_run_figure(f.name)]
    if (out / "run.toml").is_file() or (out / "results.json").is_file():  # an earlier run's folder: the figures
        # that `plot RUN --out RUN` drew of it beside its results (reachirl's only)
        removed += marked_run_figures(out)
    if (out / "models").is_dir():
        removed += [f for f in (out / "models").glob("*.json") if f.stem not in keys and _unit_model(f)]
    for f in removed:
        f.unlink(missing_ok=True)
    if (out / "predictions").is_dir():
        from ..data.exports import remove_export

        for d in (out / "predictions").iterdir():
            if d.is_dir() and d.name not in keys and (d / "index.csv").is_file():
                remove_export(d)  # what the export wrote; a file of the user's own in it stays
                removed.append(d)
    return removed


def write_outputs(
    run: RunResult, workers: int = 1, ahead: FigureWorkers | None = None, units: UnitOutputs | None = None
) -> dict:
    """Every output of a finished run (see the module docstring), in turn; the figures are drawn in ``workers``
    processes while the other files are written (``workers`` > 1; :mod:`reachirl.experiments.rendering`; those
    of ``ahead`` when they were started before the run ended). The units' own outputs that ``units`` wrote as
    they finished are not written again.

    ``report.md``, ``results.json`` and last the tables are written at the end, and a previous run's are removed
    first: a folder without ``table.csv`` is a run that has not finished (an interrupted one), never one that looks
    done.

    Returns ``{"tables": {method: table}, "timing": {...}, "notes": [...], "figures": [...], "n_trials"}``.
    """
    t0 = time.perf_counter()
    out, config = run.out_dir, run.config
    remove_previous_outputs(run.out_dir, {*run.results, *run.pairs, *run.transfer})
    postures, sections, methods = run.postures, list(config.sections), list(config.methods)
    results = run.results
    tables = {m: tb.build_table(results, m, postures, sections) for m in methods}
    n_trials = {s: ("/".join(sorted({str(v) for v in run.split_sizes[s].values()})) or "0") for s in SETS}
    notes, doc = _notes(results, config)
    notes += _other_units_notes(run)
    empty = [s for s in SETS if not any(run.split_sizes[s].values())]
    if empty:  # the table shows "—" there; say why
        reasons = split_reasons(config)
        notes.append("— means no data: " + "; ".join(reasons[s] for s in empty) + ".")
    truth = truth_comparison(run.dataset, results, methods[0], postures)
    agreement = prediction_agreement(run, methods[0], postures)
    if agreement:
        notes.append(_agreement_note(agreement, int(run.dataset.truth.get("n_windows", 0))))
        for p, a in agreement.items():
            if p in truth[2]:
                truth[2][p]["predictions"] = a
    t_fig = time.perf_counter()
    jobs, figs = figure_jobs(run, tables, truth)
    pairs_md: list[str] = []
    if run.config.iscv == "all-pairs":  # iscv_pairs.csv now, its figures drawn with the others
        from .pairs import write_pairs

        pairs_out = write_pairs(run)
        jobs = [*pairs_out["jobs"], *jobs]  # the costliest first: a study's heatmaps of every pair
        figs.update(pairs_out["figures"])
        pairs_md = pairs_out["markdown"]
    from .cost import cost_section, write_models, write_posture_transfer

    with drawing(jobs, workers, ahead) as figures:  # drawn in other processes meanwhile (workers > 1)
        skip = frozenset() if units is None else frozenset(units.written)
        write_models(run, skip)
        extra_md: list[str] = cost_section(run, truth[1] or None, truth[2] or None)
        extra_md += write_posture_transfer(run)
        extra_md += pairs_md
        t_pred = time.perf_counter()
        write_predictions(run, skip)
        predictions_s = time.perf_counter() - t_pred + (0.0 if units is None else units.predictions_s)
        comparisons = section_comparisons(run)
        figures.wait()
    fig_time = time.perf_counter() - t_fig
    computed = set(run.run_info.get("computed", []))
    timing = dict(run.timing)
    every = [*results.values(), *run.pairs.values(), *run.transfer.values()]
    timing["fit_s_sum"] = sum(r["fit"]["time_s"] for r in every if r["key"] in computed)
    timing["evaluation_s_sum"] = sum(r["evaluation"]["time_s"] for r in every if r["key"] in computed)
    # the weight samples' part of fit_s_sum (reproduce --uncertainty 0 draws none)
    timing["uncertainty_s_sum"] = sum(
        (r.get("uncertainty") or {}).get("time_s", 0.0) for r in every if r["key"] in computed
    )
    timing["figures_s"] = fig_time
    timing["predictions_s"] = predictions_s
    timing["report_s"] = time.perf_counter() - t0
    timing["total_s"] = sum(timing.get(k, 0.0) for k in ("data_s", "units_wall_s", "report_s"))
    run.timing = timing
    md_tables = markdown_tables(tables, postures, sections, n_trials)
    write_report(run, tables, md_tables, notes, figs, truth[2], comparisons, extra_md)
    write_results_json(run, tables, figs, truth[2], notes, doc, comparisons)
    reasons = split_reasons(config)
    write_tables(out, tables, postures, sections, n_trials, notes, reasons, md_tables)  # last: the run is done
    figures.close()  # the figure workers have ended meanwhile
    return {"tables": tables, "timing": timing, "notes": notes, "figures": sorted(figs), "n_trials": n_trials}


def protocol_line(config: ProtocolConfig, train_subject: str, postures: Sequence[str]) -> str:
    """The report's line saying which trials each set takes (as :func:`~reachirl.experiments.protocol.split_trials`
    chooses them): the arm is named whenever the training takes one arm only (``train_side``, or ``cv =
    "other-side"``, which learns from the right arm unless told otherwise)."""
    arm = config.train_side or ("right" if config.cv == "other-side" else None)
    of_arm = f" ({arm} arm)" if arm else ""
    learn = (
        f"all the trials of subject {train_subject}{of_arm}"
        if config.n_train is None
        else f"{config.n_train} trial(s) of subject {train_subject}{of_arm} chosen at random (seed {config.seed}) "
        "(when a posture has fewer, all of them)"
    )
    if config.cv == "other-side":
        cv = "its other-arm reaches (mirrored)"
    else:
        cv = f"its other {arm}-arm trials (its other arm's are not used)" if arm else "its other trials"
    return (
        f"- **Protocol (seed §II-D):** per posture ({', '.join(postures)}) and section count "
        f"({', '.join(map(str, config.sections))}): learn from {learn}, cross-validate on {cv}, ISCV on the other "
        "subjects' trials of the same posture."
    )


def _no_truth_comparison(truth: dict, sections: Sequence[int]) -> str:
    """Why a run on virtual subjects has no learned-vs-true comparison (nor ``weights_vs_truth.png``): the true cost
    is compared only with fits of as many sections as it has windows."""
    n_true = int(truth.get("n_windows", 0) or 0)
    run_sections = ", ".join(str(n) for n in sorted(sections))
    if n_true and n_true not in sections:
        return (
            f"Not compared: the true cost (truth.json) has {n_true} window{'s' if n_true != 1 else ''} and this "
            f"run's section counts are {run_sections}; the learned and true shares are compared window by window, "
            f"so rerun with `--sections {n_true}` among them for this comparison, `weights_vs_truth.png` and the "
            "truth's shares inside the intervals."
        )
    return (
        "Not compared: no fit of this run's first method could be set beside the true weights (truth.json has none "
        "for its training trials, or their shape is not the fit's)."
    )


def _report_md(run: RunResult, tables, md_tables, notes, figs, truth_metrics, comparisons, extra_md=()) -> str:
    dataset, config, postures = run.dataset, run.config, run.postures
    train_subject, split_sizes, timing, run_info = run.train_subject, run.split_sizes, run.timing, run.run_info
    methods, sections = list(config.methods), list(config.sections)
    main = methods[0]
    tab = tables[main]
    virtual = dataset.truth is not None
    lines = ["# reachirl reproduce: MO-IRL with time-varying weights", ""]
    lines += ["## Setup", ""]
    desc = dataset.describe()
    lines += [
        f"- **Data:** {dataset.source} — {desc['n_trials']} trials, subjects {', '.join(desc['subjects'])}, "
        f"postures {', '.join(desc['postures'])}."
        + (
            " Virtual subjects: reaches generated by the DOC under known time-varying weights (truth.json), "
            "recorded as noisy 100 Hz markers and preprocessed like real data."
            if virtual
            else ""
        ),
        protocol_line(config, train_subject, postures),
        "- **Trials per posture:** "
        + "; ".join(f"{SET_LABELS[s]} " + ", ".join(f"{p}: {split_sizes[s][p]}" for p in postures) for s in SETS)
        + ".",
        f"- **Methods:** {', '.join(methods)}; DOC backend {config.backend}, {config.n_nodes} knots; "
        f"at most {config.max_iter} iterations per stage.",
        *method_lines([r["unit"] for r in run.results.values()]),
        f"- **Provenance:** trials' fingerprint {desc['fingerprint']}; "
        + ", ".join(f"{name} {v}" for name, v in versions().items() if v is not None)
        + ".",
        "",
        "## Results: RMSE of the joint angles (deg), seed Table II layout",
        "",
    ]
    lines += md_tables
    lines += [f"- {n}" for n in notes] + [""]
    lines += [
        "### Headline (ALL postures, q), and the seed's numbers measured on its own subjects",
        "",
        "The seed's columns were **measured on the paper's own subjects** (Berret et al.'s human reaches to a "
        "bar, 2 subjects, 10/10/20 trials), not on the data of this run ("
        + ("virtual subjects" if virtual else dataset.source)
        + (", cross-validated on the other arm" if config.cv == "other-side" else "")
        + "): they are **not comparable** with ours, and are shown only as the paper's own figures.",
        "",
        "| sections | "
        + " | ".join(f"{SET_LABELS[s]} (ours) | {SET_LABELS[s]} (seed's subjects, not comparable)" for s in SETS)
        + " |",
        "|---|" + "---|" * (2 * len(SETS)),
    ]
    for row in tb.headline(tab, sections):
        lines.append(
            f"| {row['sections']} | " + " | ".join(f"{_fmt(row[s])} | {_fmt(row['seed_' + s])}" for s in SETS) + " |"
        )
    lines += [""]
    # what the numbers say
    says = []
    lo, hi = min(sections), max(sections)
    for s, c in comparisons.get(main, {}).items():
        a, b = tab[tb.ALL][s].get(lo, {}).get("q"), tab[tb.ALL][s].get(hi, {}).get("q")
        if not (a and b and a.get("mean") is not None and b.get("mean") is not None):
            continue
        if c["min_p"] >= 0.05:
            test = f"too few postures for a test: p ≥ {c['min_p']:.2g} whatever the data"
        else:
            verdict = (
                "significantly " + ("lower" if c["mean_diff_deg"] < 0 else "higher")
                if c["wilcoxon_p"] < 0.05
                else "no significant difference"
            )
            test = f"{verdict}: Wilcoxon signed-rank p = {c['wilcoxon_p']:.2g} over the postures, one fit each"
        says.append(
            f"{SET_LABELS[s]}: {sections_text(hi)} give {b['mean']:.2f}° against {a['mean']:.2f}° with {lo}, lower in "
            f"{c['n_lower']} of {c['n']} postures (mean paired difference {c['mean_diff_deg']:+.2f}°; {test})."
        )
    per_p = {p: tab[p]["cv"].get(hi, {}).get("q", {}).get("mean") for p in postures}
    per_p = {p: v for p, v in per_p.items() if v is not None}
    if len(per_p) > 1:
        says.append(hardest_words(tab, list(per_p), hi))
    if says:
        lines += ["What they show: " + " ".join(says), ""]
    lines += ["### The seed's Table II (its own human data: not the data above)", "", tb.seed_markdown()]
    lines += ["## Figures", ""]
    for name, f in figs.items():
        lines += [f"### {name}", "", f"![{name}](figures/{name})", "", f["caption"], ""]
    if truth_metrics:
        lines += [
            "## Virtual subjects: learned vs true weights",
            "",
            "Per posture: total-variation distance between learned and true cost shares (0 = same, 1 = "
            "disjoint; mean over windows), correlation of the shares, and how often the dominant "
            "feature of a window agrees. Both sets of weights are weighed on the features of "
            + truth_reach_words(truth_metrics)
            + " (the DOC over the training trials' mean task), not on the recorded reaches', whose noise "
            "inflates joint acceleration and torque change.",
            "",
            "| posture | total variation | correlation | dominant feature agrees |",
            "|---|---|---|---|",
        ]
        for p, m in truth_metrics.items():
            corr = "—" if m["share_correlation"] is None else f"{m['share_correlation']:.2f}"
            lines.append(
                f"| {p} | {m['mean_total_variation']:.2f} | {corr} | {100 * m['dominant_feature_agreement']:.0f} % |"
            )
        lines += [
            "",
            "Features whose effects on the trajectory are nearly alike can trade weight without changing "
            "the reach: Cartesian velocity, geodesic and joint velocity (running rates correlated at "
            "|r| > 0.9 on such reaches; each fit's collinear pairs are in `reachirl sensitivity`'s "
            "identifiability.json), and joint acceleration and joint torque (the torque is the inertia times "
            "the acceleration plus a gravity term that changes slowly within a window). A low RMSE with "
            "imperfect shares is therefore expected: MO-IRL matches trajectories, not weights.",
            "",
        ]
        agree = {p: m["predictions"] for p, m in truth_metrics.items() if m.get("predictions")}
        if agree:
            lines += [
                "Predictions (joint-angle RMSE, degrees, mean over the trials): the fits' against the true "
                "weights' own (learned vs true), and each against the recorded reaches, per set "
                "(train / CV / ISCV).",
                "",
                "| posture | learned vs true | true vs recorded | learned vs recorded |",
                "|---|---|---|---|",
            ]
            for p, a in agree.items():
                cells = [
                    " / ".join(f"{a[s][k]:.2f}" if s in a else "—" for s in SETS)
                    for k in ("learned_vs_true_deg", "true_vs_recorded_deg", "learned_vs_recorded_deg")
                ]
                lines.append(f"| {p} | " + " | ".join(cells) + " |")
            lines += [""]
        lines += [
            "The largest share at movement onset and termination (the first and last windows of the weights), "
            "per posture: the true weights' against the learned point estimates' "
            f"({ends_determined_words(run.results, main, truth_metrics)}).",
            "",
            "| posture | onset: true | onset: learned | end: true | end: learned |",
            "|---|---|---|---|---|",
        ]
        for p, m in truth_metrics.items():
            ends = (m[k][i] for i in (0, -1) for k in ("true_dominant", "learned_dominant"))
            lines.append(f"| {p} | " + " | ".join(ends) + " |")
        lines += [""]
    elif virtual:  # said, not left out: a reader of virtual subjects looks for the truth here
        lines += ["## Virtual subjects: learned vs true weights", "", _no_truth_comparison(dataset.truth, sections), ""]
    lines += list(extra_md)
    lines += [
        "## Run",
        "",
        f"- Units: {run_info.get('n_units')} ({len(run_info.get('computed', []))} computed, "
        f"{len(run_info.get('reused', []))} reused from checkpoints in units/); "
        f"executor: {run_info.get('executor')}.",
        "- Time split (s): " + ", ".join(f"{k} {v:.1f}" for k, v in timing.items()) + ".",
        "  (`fit_s_sum` and `evaluation_s_sum` add the units' own times over the workers, `uncertainty_s_sum` the "
        "weight samples' part of `fit_s_sum`; `units_wall_s` is the wall time of all units; `report_s` includes "
        "`figures_s`.)",
        "- Files: `table.md`, `table.csv`, `results.json` (every unit's weights, history, per-trial RMSE), "
        "`units/*.json` + `units/*.npz` (checkpoints and predictions), `figures/*.png`, "
        "`predictions/<unit>/<trial id>.csv|.mot` (schemas: docs/outputs.md in the source).",
        "",
    ]
    return "\n".join(lines)


def _undetermined(result: dict) -> np.ndarray:
    """The shares of a unit's fit whose 95 % interval is wide (``uncertainty.share_intervals.determined``)."""
    return ~np.asarray(result["uncertainty"]["share_intervals"]["determined"], dtype=bool)
