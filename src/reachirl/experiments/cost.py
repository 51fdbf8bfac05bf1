"""What a run says about the learned cost: each unit's model, what the training data determines, the weights'
uncertainty, the paper's claim tested at that uncertainty, and leave-one-posture-out transfer."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..io import atomic_write_text
from ..irl.model import LearnedModel, save_model
from ..irl.uncertainty import PRIOR_LOG_SD, UNDETERMINED_WIDTH, claim_verdict, mean_width, prior_gives_verdict

__all__ = [
    "claim_verdict",
    "cost_section",
    "uncertainty_summary",
    "write_model",
    "write_models",
    "write_posture_transfer",
]


def write_models(run, skip=frozenset()) -> list[Path]:
    """``RUN_DIR/models/<unit key>.json``: each unit's model as ``reachirl fit`` writes it, for ``evaluate``,
    ``plot`` and ``simulate`` (but those of the units in ``skip``, already written by :func:`write_model`)."""
    every = {**run.results, **run.pairs, **run.transfer}
    return [write_model(run.out_dir, key, r) for key, r in sorted(every.items()) if key not in skip]


def write_model(out_dir, key: str, r: dict) -> Path:
    """``out_dir/models/<key>.json``: the model of the unit ``key`` (its result ``r``), as ``reachirl fit`` writes
    it."""
    info = dict(r.get("model_info") or {"method": r["unit"]["method"]})
    # the fit's whole history as `reachirl fit` keeps it (a unit checkpointed before it was kept: the result's
    # short one)
    info.setdefault("history", r.get("history", []))
    # as the checkpoint's model_info has them (one written before it did: from the unit); "run" is this run's
    # folder, where the checkpoint may name the one it was computed in (a folder moved since)
    info.update({"unit": key, "backend": r["unit"]["backend"], "run": str(Path(out_dir).resolve())})
    model = LearnedModel(
        weights=np.asarray(r["weights"], dtype=float),
        n_nodes=int(r["unit"]["n_nodes"]),
        method=r["unit"]["method"],
        info=info,
        uncertainty=r.get("uncertainty"),
    )
    return save_model(Path(out_dir) / "models" / f"{key}.json", model)


def uncertainty_summary(unc: dict | None) -> dict | None:
    """A unit's ``uncertainty`` for results.json: its method, intervals, what the data determines, the check and
    the claim's verdict (the samples themselves are in the unit's model, ``models/<key>.json``)."""
    if not unc:
        return None
    keep = ("method", "n_samples", "share_intervals", "determination", "prior", "checked")
    return {k: unc[k] for k in keep if k in unc} | {"claim": _claim(unc)}


def _claim(unc: dict) -> dict:
    """The claim's verdict over the posterior's interval draws (a model written before they were recorded: over
    its weight samples)."""
    return unc.get("claim") or claim_verdict(np.asarray(unc["share_samples"]))


def _no_samples(run) -> str:
    """Why no fit of the run has weight samples, and what to rerun with."""
    from ..irl.methods import builds_on_moirl

    config = getattr(run, "config", None)
    methods = list(getattr(config, "methods", ()) or ())
    sampled = [m for m in methods if builds_on_moirl(m)]
    if methods and not sampled:  # --uncertainty was in force, but only MO-IRL and MaxEnt fits draw samples
        return (
            f"No fit of this run has weight samples: they are drawn for moirl and maxent fits only, and this run's "
            f"method{'s' if len(methods) > 1 else ''} ({', '.join(methods)}) "
            f"{'have' if len(methods) > 1 else 'has'} none; add moirl (`--method moirl {' '.join(methods)}`) "
            "to quote a share."
        )
    if config is not None and getattr(config, "uncertainty", 0):
        return (
            "No fit of this run has weight samples, though they were asked for (`uncertainty = "
            f"{config.uncertainty}`): the fits' `warnings` in results.json say why."
        )
    return "No fit of this run has weight samples: rerun with `--uncertainty` to quote a share."


def _truth_coverage(unc: dict, true_shares: np.ndarray) -> float:
    """The fraction of the true shares inside the fit's intervals (within 0.005, the shares' printed precision)."""
    lo, hi = np.asarray(unc["share_intervals"]["low"]), np.asarray(unc["share_intervals"]["high"])
    return float(np.mean((true_shares >= lo - 0.005) & (true_shares <= hi + 0.005)))


def cost_section(run, true_shares: dict | None = None, truth_metrics: dict | None = None) -> list[str]:
    """``report.md``'s section on the learned cost: per MO-IRL fit with weight samples, the determined weight
    directions in words, the share intervals (how many are undetermined), the claim's verdict and, on virtual
    subjects (``true_shares`` by posture), how often the intervals contain the truth's shares and whether the
    training reaches tell the truth's cost from the fit's (``truth_metrics`` by posture, of
    :func:`~reachirl.experiments.analysis.truth_comparison`, for the sentence that sums it up)."""
    lines = [
        "## What the data determines about the cost",
        "",
        "The learned weights are one cost among several that explain the training reaches equally well: "
        "quote a cost share only where its interval is narrow. For each fit with weight samples "
        "(`--uncertainty`, on by default): the weight directions the training data determines (moving the "
        "log-weights along one by log 2 raises the merit by more than the demonstrations can tell from noise) "
        "and the most determined one in words; the share of cost shares whose 95 % interval is wider than "
        f"{UNDETERMINED_WIDTH} or does not contain the fit's own share (undetermined, not a finding; the figures "
        "hatch them); and the paper's claim, joint acceleration's share "
        "higher at onset and end than mid-reach, over the posterior's draws (supported in at least 97.5 % of them, "
        "contradicted in at most 2.5 %, undetermined otherwise; a verdict the prior alone gives too is said to be "
        "the prior's, not a finding). The samples are the Gauss-Newton posterior "
        f"of the log-weights with a prior of a factor {np.exp(PRIOR_LOG_SD):.0f} around ω₀ (equal shares of each "
        "window's demonstrated cost), wide enough to "
        "rule out no share (`docs/method.md`). Beside each fit's mean interval width and claim fraction, the same "
        "under the prior alone, without the data: where they are close, the intervals are the prior's and the "
        "data says little about the cost"
        + (
            "; the intervals containing the truth's shares shows that they are honest, not that the data "
            "determines them (the prior alone contains them too). 'Truth's shares inside' compares the truth's "
            "shares on the truth's own reach with the intervals on the fit's reach (the posture's reach under each "
            "cost: the report quotes each cost's shares on its own reach). 'Truth against the fit' re-solves "
            "the training rollouts under the truth's weights and applies the samples' test both ways, with the "
            "merit's rise under the truth: 'as good' means the training reaches cannot tell the truth's cost from "
            "the learned one, however far apart their shares are, so no fit of these reaches could say which of the "
            "two is the subject's; 'better', that the fit stopped short of a cost the data prefers."
            if true_shares
            else "."
        )
        + " The posterior is a local (Gauss-Newton) model at the fit: a few weight samples are solved by the DOC "
        "again, and 'samples as good as the fit' counts those whose reaches the demonstrations cannot tell from "
        "the fit's (a rise of their merit within the merit noise, or not significant in a one-sided paired t-test, "
        "5 %), with the range of their merit's rise over the fit's in units of "
        "the merit noise (the rise the demonstrations can tell from noise; under 1, none they can tell); few or "
        "none means the samples are costs the local model does not rule out, not costs shown to explain the "
        "reaches equally well.",
        "",
    ]
    rows = [r for r in run.results.values() if r.get("uncertainty")]
    if not rows:
        return [*lines, _no_samples(run), "", *window_sentence(run.results)]
    lines += [
        "| unit | determined directions | shares undetermined | mean width (prior alone) | claim (prior alone) | "
        "most determined direction | samples as good as the fit |"
        + (" truth's shares inside | truth against the fit |" if true_shares else ""),
        "|---|---|---|---|---|---|---|" + ("---|---|" if true_shares else ""),
    ]
    for r in sorted(rows, key=lambda r: r["key"]):
        u = r["uncertainty"]
        det = u["determination"]
        iv = u["share_intervals"]
        und = 1.0 - float(np.mean(iv["determined"]))
        width = mean_width(iv)
        prior = u.get("prior") or {}
        claim = _claim(u)
        frac = "" if claim["fraction"] is None else f" ({100 * claim['fraction']:.0f} % of draws"
        if frac:
            p0 = prior.get("claim_fraction")
            frac += "" if p0 is None else f"; {100 * p0:.0f} %"
            # the prior alone gives the verdict too (many windows: 'contradicted' with nothing determined)
            frac += "; the prior's verdict too, not a finding)" if prior_gives_verdict(claim, prior) else ")"
        w0 = prior.get("mean_width")
        top = det["determined"][0] if det["determined"] else "none"
        row = (
            f"| {r['key']} | {det['n_determined']} of {det['n_directions']} | {100 * und:.0f} % | "
            f"{'-' if width is None else f'{width:.2f}'}{'' if w0 is None else f' ({w0:.2f})'} | "
            f"{claim['verdict']}{frac} | {top} | "
            f"{_checked(u.get('checked'))} |"
        )
        p = r["unit"]["posture"]
        if true_shares:
            ts = true_shares.get(p)
            if ts is not None and np.shape(ts) == np.shape(iv["low"]):
                row += f" {100 * _truth_coverage(u, np.asarray(ts)):.0f} % |"
            else:
                row += " — |"
            m = (truth_metrics or {}).get(p) or {}  # truth_comparison's: for the truth's section count only
            row += (
                f" {_versus(m.get('truth_versus_fit') if m.get('sections') == r['unit'].get('sections') else None)} |"
            )
        lines.append(row)
    lines.append("")
    return lines + window_sentence(run.results) + _truth_sentence(truth_metrics)


def window_sentence(results: dict) -> list[str]:
    """Where the fits' windows lie on the recorded reaches: each section count's mean edges (MODEL.json
    ``info.window_edges``, 0 at the recorded onset, 1 at the offset) over the units that record them."""
    by: dict[int, list] = {}
    for r in results.values():
        edges = (r.get("model_info") or {}).get("window_edges")
        if edges is not None and len(edges) > 2:
            by.setdefault(len(edges) - 1, []).append(edges)
    if not by:
        return []
    said = "; ".join(
        f"{n} windows: " + ", ".join(f"{e:.2f}" for e in np.mean(by[n], axis=0)) + f" (mean over {len(by[n])} fits)"
        for n in sorted(by)
    )
    return [
        "Windows: the weights act on equal windows of the rest-to-rest DOC, and the shares are those windows' own. "
        "On the recorded reach (0 at its onset, 1 at its offset, the speed's crossings of the threshold) their "
        f"edges lie at {said}: the first window begins before the recorded onset, the last ends after the offset.",
        "",
    ]


def _truth_sentence(metrics: dict | None) -> list[str]:
    """On virtual subjects: on how many fits the training reaches cannot tell the truth's cost from the learned
    one (and how far apart the two costs' shares are there), and on how many they prefer the truth."""
    rows = [(m["truth_versus_fit"], m["mean_total_variation"]) for m in (metrics or {}).values()]
    rows = [(v, tv) for v, tv in rows if v and v.get("converged")]
    if not rows:
        return []
    same = [tv for v, tv in rows if v["verdict"] == "as good"]
    better = sum(v["verdict"] == "better" for v, _ in rows)
    sections = next(iter(metrics.values()))["sections"]
    text = (
        f"The truth's cost explains the training reaches as well as the learned one on {len(same)} of {len(rows)} "
        f"{sections}-section fits (the demonstrations cannot tell the two apart)"
    )
    if same:
        text += (
            f", though the two costs' shares lie {min(same):.2f}-{max(same):.2f} apart there (mean total "
            "variation per window, 1 = disjoint): the merit of these reaches cannot prefer the truth's shares to the "
            "fit's"
        )
    if better:
        text += f"; on {better} the data prefers the truth's cost, and the fit stopped short of it"
    return [text + ".", ""]


def _versus(record: dict | None) -> str:
    """Whether the training reaches tell the truth's cost from the fit's, and the merit's rise under it."""
    if not record:
        return "—"
    if not record.get("converged"):
        return "— (DOC failed)"
    return f"{record['verdict']} ({_times(record['rise_over_noise'])} noise)"


def _times(x: float) -> str:
    """A merit rise in units of the merit noise, e.g. "0.3×", "−0.8×", "52×"."""
    return f"{x:.2g}×".replace("-", "−") if abs(x) < 10 else f"{x:.0f}×".replace("-", "−")


def _checked(checked: dict | None) -> str:
    """How many of the weight samples re-solved by the DOC the demonstrations cannot tell from the fit."""
    failed = f" ({checked['failed']} DOC failed)" if checked and checked.get("failed") else ""
    if not checked or not checked.get("solved"):
        return f"—{failed}"
    rises = checked.get("rise_over_noise") or []  # absent from the records of earlier versions
    spread = ""
    if rises:
        lo, hi = min(rises), max(rises)
        spread = (
            f" (rise {_times(lo)} noise)" if _times(lo) == _times(hi) else f" (rise {_times(lo)}-{_times(hi)} noise)"
        )
    return f"{checked['indistinguishable']} of {checked['solved']}{spread}{failed}"


def write_posture_transfer(run) -> list[str]:
    """``posture_transfer.csv`` (method, sections, held_out_posture, RMSE of q as mean, SD, n for the training
    subject's trials of the held-out posture, then iscv_mean, iscv_sd, iscv_n for the other subjects') and the
    report's lines; nothing without ``--posture-transfer``."""
    if not run.transfer:
        if getattr(run.config, "posture_transfer", False):
            return [
                "## Posture transfer (leave one posture out)",
                "",
                f"Not run: it needs at least two postures, and this run has {len(run.postures)}.",
                "",
            ]
        return []
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            "method",
            "sections",
            "held_out_posture",
            "mean",
            "sd",
            "n",
            "iscv_mean",
            "iscv_sd",
            "iscv_n",
            "per_posture_fit_mean",
        ]
    )
    lines = [
        "## Posture transfer (leave one posture out)",
        "",
        f"One cost learned on the training trials of every other posture ({_rollout_words(run.transfer)}), predicting "
        "the held-out posture's reaches of the training subject and of the other subjects, beside the fit of "
        "that posture's own training trials (the main table's CV and training trials).",
        "",
        "| method | sections | held-out posture | RMSE of q, same subject (deg) | other subjects (deg) | "
        "per-posture fit, same trials (deg) |",
        "|---|---|---|---|---|---|",
    ]

    def stats(trials):
        v = [t["rmse_deg"]["q"] for t in trials if t.get("converged", True)]
        return (float(np.mean(v)), float(np.std(v)), len(v)) if v else (None, None, 0)

    for _key, r in sorted(run.transfer.items()):
        u = r["unit"]
        own = stats(r["sets"]["cv"]["trials"])
        iscv = stats(r["sets"]["iscv"]["trials"])
        main = next(
            (
                m
                for m in run.results.values()
                if m["unit"]["method"] == u["method"]
                and m["unit"]["posture"] == u["held_out_posture"]
                and m["unit"]["sections"] == u["sections"]
            ),
            None,
        )
        base = stats([*main["sets"]["train"]["trials"], *main["sets"]["cv"]["trials"]]) if main else (None, None, 0)
        w.writerow(
            [
                u["method"],
                u["sections"],
                u["held_out_posture"],
                *_fmt_row(own),
                *_fmt_row(iscv),
                "" if base[0] is None else f"{base[0]:.4f}",
            ]
        )

        def cell(s):
            return "—" if s[0] is None else f"{s[0]:.2f} ± {s[1]:.2f} (n = {s[2]})"

        lines.append(
            f"| {u['method']} | {u['sections']} | {u['held_out_posture']} | {cell(own)} | {cell(iscv)} | {cell(base)} |"
        )
    atomic_write_text(Path(run.out_dir) / "posture_transfer.csv", buf.getvalue())
    return [*lines, ""]


def _rollout_words(units: dict) -> str:
    """How the posture-transfer fits rolled out their training tasks, in words (from their recorded options)."""
    from .protocol import estimator_kwargs

    words = {
        "per_task": "one rollout per posture",
        "per_demo": "one rollout per demonstration",
        "mean": "one rollout for every posture's trials together",
    }
    opts = [estimator_kwargs(r["unit"].get("estimator_options") or ()) for r in units.values()]
    kinds = {str(o["rollout"]) for o in opts if "rollout" in o}  # the baselines have no rollout option
    said = "; ".join(words.get(k, f"rollout {k}") for k in sorted(kinds))
    # beside MO-IRL's, a baseline's fits (KKT: no rollout; bilevel: one from the mean task) are not those words
    pairs = zip(units.values(), opts, strict=True)
    others = sorted({str(r["unit"].get("method", "baseline")) for r, o in pairs if "rollout" not in o})
    if said and others:
        return f"{said}; {', '.join(others)}: {'each its' if len(others) > 1 else 'its'} own way"
    return said or "each method's own way"


def _fmt_row(s) -> list:
    return ["", "", 0] if s[0] is None else [f"{s[0]:.4f}", f"{s[1]:.4f}", s[2]]
