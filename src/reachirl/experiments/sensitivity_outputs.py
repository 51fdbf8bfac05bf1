"""The outputs of ``reachirl sensitivity`` (:mod:`reachirl.experiments.sensitivity`): ``sensitivity.csv``,
``sensitivity.md``, ``identifiability.json`` and a figure per posture."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..features import FEATURES, N_FEATURES
from ..io import atomic_write_json, atomic_write_text
from .sensitivity import ALL, COLUMNS, SETS, reading

__all__ = ["plot_sensitivity", "remove_outputs", "to_csv", "write_sensitivity"]


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if not np.isfinite(v) else f"{v:.4f}"
    return str(v)


def to_csv(rows: Sequence[dict]) -> str:
    return "\n".join([",".join(COLUMNS), *(",".join(_fmt(r[c]) for c in COLUMNS) for r in rows)]) + "\n"


def plot_sensitivity(rows: Sequence[dict], posture: str, axes=None, title: str = "", percent: float | None = None):
    """Three panels for ``posture``: occlusion of each feature and freezing of each window (RMSE change on the
    held-out set with its 95 % interval, and on the training set), and the path change under ±``percent`` % of
    each weight (window × feature; the title names the percentage when given)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .figures import SHORT

    sel = [r for r in rows if r["posture"] == posture]
    kinds = ("occlude_feature", "freeze_window", "sensitivity")
    if axes is None:  # a panel per analysis that was run (--no-occlusion: the sensitivity alone)
        shown = [k for k in kinds if any(r["analysis"] == k for r in sel)] or ["sensitivity"]
        fig, grid = plt.subplots(1, len(shown), figsize=(5 * len(shown), 4.2), squeeze=False)
        panel = dict(zip(shown, grid[0], strict=True))
    else:
        panel = dict(zip(kinds, axes, strict=True))
    fig = next(iter(panel.values())).figure
    for kind, label in (("occlude_feature", "feature removed"), ("freeze_window", "window frozen at ω₀")):
        ax = panel.get(kind)
        if ax is None:
            continue
        rs = [r for r in sel if r["analysis"] == kind]
        if not rs:
            ax.set_axis_off()
            continue
        x = np.arange(len(rs))
        has_ci = False
        for k, (s, c) in enumerate((("train", "tab:gray"), ("cv", "tab:blue"), ("iscv", "tab:orange"))):
            m = np.array([np.nan if r[f"{s}_delta_deg"] is None else r[f"{s}_delta_deg"] for r in rs], float)
            if not np.isfinite(m).any():
                continue
            lo = np.array([r[f"{s}_ci_lo"] for r in rs], float)
            hi = np.array([r[f"{s}_ci_hi"] for r in rs], float)
            has_ci |= bool(np.isfinite(lo).any())
            ax.bar(
                x + (k - 1) * 0.27,
                m,
                0.27,
                color=c,
                label=s.upper() if s != "train" else "training",
                yerr=np.vstack([m - lo, hi - m]),
                capsize=2,
                error_kw={"lw": 0.8},
            )
        ax.axhline(0, color="k", lw=0.6)
        names = [SHORT.get(r["feature"], r["feature"]) if kind == "occlude_feature" else f"w{r['window']}" for r in rs]
        ax.set_xticks(x)
        ax.set_xticklabels(
            names,
            rotation=45 if kind == "occlude_feature" else 0,
            ha="right" if kind == "occlude_feature" else "center",
            fontsize=8,
        )
        ax.set_ylabel("RMSE change of q (deg), refit − full fit")
        ax.set_title(f"occlusion: {label}", fontsize=9)
        ax.legend(fontsize=7)
        if not has_ci:  # bars without whiskers would read as intervals too narrow to draw
            ax.text(
                0.02,
                0.02,
                "no 95 % intervals: fewer than 5 trials in every set",
                transform=ax.transAxes,
                fontsize=7,
                va="bottom",
            )
    rs = [r for r in sel if r["analysis"] == "sensitivity"]
    ax = panel.get("sensitivity")
    if rs and ax is not None:
        n_w = max(int(r["window"]) for r in rs)
        m = np.full((n_w, N_FEATURES), np.nan)
        for r in rs:
            if r["path_change_deg"] is not None:  # None: every prediction's DOC failed (blank)
                m[int(r["window"]) - 1, FEATURES.index(r["feature"])] = r["path_change_deg"]
        im = ax.imshow(
            m.T, aspect="auto", cmap="viridis", interpolation="nearest", extent=(0.5, n_w + 0.5, N_FEATURES - 0.5, -0.5)
        )
        ax.set_yticks(range(N_FEATURES))
        ax.set_yticklabels([SHORT[f] for f in FEATURES], fontsize=8)
        ax.set_xticks(range(1, n_w + 1))
        ax.set_xlabel("window")
        x_pc = "x" if percent is None else f"{percent:g}"
        ax.set_title(f"sensitivity: path change under ±{x_pc} % of each weight (deg)", fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.8)
    elif ax is not None:
        ax.set_axis_off()
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _markdown(out: dict) -> list[str]:
    cfg, rows = out["config"], out["rows"]
    post = ALL if any(r["posture"] == ALL for r in rows) else cfg["postures"][0]
    lines = [
        f"# reachirl sensitivity: {cfg['method']}, {cfg['sections']} section(s), postures {', '.join(cfg['postures'])}",
        "",
    ]
    occ = sorted(
        [r for r in rows if r["posture"] == post and r["analysis"] == "occlude_feature"],
        key=lambda r: (
            -(
                r["cv_delta_deg"]
                if r["cv_delta_deg"] is not None and np.isfinite(r["cv_delta_deg"])
                else r["train_delta_deg"] or 0.0
            )
        ),
    )
    if occ or any(r["analysis"] == "freeze_window" for r in rows):
        lines += [
            "Δ: RMSE of q of the refit minus the full fit's, mean over trials. 95 % CI: the paired differences "
            "resampled over the trials, given the two fits (each held as it is): whether these fits predict these "
            "trials differently, not how uncertain their weights are. A trial whose prediction's DOC failed in either "
            "fit is left out of its set's Δ and counted beside it. A verdict is taken on the CV trials, else the ISCV "
            "trials, else the training trials (a set of fewer than 5 has no interval) and names its set: "
            "`needed (train)` is in-sample evidence, not held-out."
            + (
                f" {ALL} pools every posture's trials, which share their posture's fits, as if independent: its "
                "interval is narrower than the postures' fits warrant, and each verdict is followed by the "
                "postures' own verdicts."
                if post == ALL
                else ""
            ),
            "",
        ]
    if occ:
        lines += [
            f"## Which costs the data needs (posture {post}; refit without each feature)",
            "",
            "| feature | mean cost share | Δ training (deg) [95 % CI] | Δ CV (deg) [95 % CI] | "
            "Δ ISCV (deg) [95 % CI] | verdict |",
            "|---|---|---|---|---|---|",
        ]
        lines += [f"| {r['feature']} | {_share(r)} | {_verdict_cells(rows, r)}" for r in occ]
        lines.append("")
    fr = [r for r in rows if r["posture"] == post and r["analysis"] == "freeze_window"]
    if fr:
        lines += [
            f"## Which windows need learning (posture {post}; window frozen at ω₀)",
            "",
            "| window | Δ training (deg) [95 % CI] | Δ CV (deg) [95 % CI] | Δ ISCV (deg) [95 % CI] | verdict |",
            "|---|---|---|---|---|",
        ]
        lines += [f"| {r['window']} | {_verdict_cells(rows, r)}" for r in fr]
        lines.append("")
    sens = [r for r in rows if r["posture"] == post and r["analysis"] == "sensitivity"]
    if sens:
        top = sorted(sens, key=lambda r: -(r["path_change_deg"] if r["path_change_deg"] is not None else -np.inf))[:5]
        lines += [
            f"## Most sensitive weights (±{cfg['percent']:g} %, posture {post})",
            "",
            "| window | feature | cost share | path change (deg) | Δ RMSE + (deg) | Δ RMSE − (deg) |",
            "|---|---|---|---|---|---|",
        ]
        for r in top:
            lines.append(
                f"| {r['window']} | {r['feature']} | {_share(r)} | {_num(r['path_change_deg'], '.3f')} | "
                f"{_num(r['plus_delta_deg'], '+.3f')} | {_num(r['minus_delta_deg'], '+.3f')}{_failures(r, 'train')} |"
            )
        failed = sum(r["train_doc_failures"] or 0 for r in sens)
        if failed:
            lines += [
                "",
                "A training trial whose prediction's DOC failed, at the full fit's weights or a changed one, is left "
                f"out of that weight's figures and counted beside them: {failed} left out across the {len(sens)} "
                "weights' rows (`train_doc_failures` in sensitivity.csv).",
            ]
        lines.append("")
    lines += ["## What the training data determines", ""]
    for p, d in out["identifiability"].items():
        det = d.get("determination")
        head = f"- **{p}** ({d['key']}{', flag ' + d['flag'] if d.get('flag') else ''}): "
        effects = (
            f"weights with nearly collinear effects on the path (|cos| ≥ 0.9, per window): "
            f"{_effects(d.get('effect_collinearity') or [])}."
        )
        if det is None:  # the ±x % changes still ran, and their effects are compared
            lines.append(
                head + "which weight directions the training data determines is not computed for this method "
                "(only MO-IRL and MaxEnt fit from rollouts); " + effects
            )
            continue
        lines.append(
            head + f"{det['n_determined']} of {det['n_directions']} weight directions determined "
            f"(most determined: {det['determined'][0] if det['determined'] else 'none'}; least: "
            f"{det['undetermined'][-1] if det['undetermined'] else 'none'}); " + effects
        )
    lines.append("")
    return lines


def _verdict_cells(rows: Sequence[dict], row: dict) -> str:
    """A refit's last cells in the report: its paired Δ with the 95 % interval per set, then its verdict (taken on
    CV where it has an interval; the other held-out set's own reading added where it differs: a few CV trials, as
    on UE-ADL, can read otherwise than many ISCV ones), then, for ``ALL``, the postures' own."""
    return (
        " | ".join(_ci(row, s) for s in SETS)
        + f" | {row['verdict']}{_other_held_out(row)}{_postures_verdicts(rows, row)} |"
    )


def _other_held_out(row: dict) -> str:
    """``"; iscv: not needed"`` where the held-out set the verdict was not taken on reads otherwise."""
    verdict = row.get("verdict") or ""
    for used, other in (("cv", "iscv"), ("iscv", "cv")):
        if verdict.endswith(f"({used})"):
            said = reading(row, other)
            if said is not None and not verdict.startswith(said + " "):
                return f"; {other}: {said}"
    return ""


def _postures_verdicts(rows: Sequence[dict], row: dict) -> str:
    """For a row of posture ``ALL``: the verdicts of the same occlusion in each posture, counted (the pooled
    interval holds each posture's fits as they are; the postures are the fits); nothing for a posture's row."""
    if row["posture"] != ALL:
        return ""
    same = [
        r
        for r in rows
        if r["posture"] != ALL
        and r["analysis"] == row["analysis"]
        and r["feature"] == row["feature"]
        and r["window"] == row["window"]
    ]
    counts: dict[str, int] = {}
    for r in same:
        word = (r["verdict"] or "no verdict").split(" (")[0]
        counts[word] = counts.get(word, 0) + 1
    return "; postures: " + ", ".join(f"{w} {n}" for w, n in sorted(counts.items(), key=lambda kv: -kv[1]))


def _share(row: dict) -> str:
    """A row's cost share as the report prints it: marked where the fit's weight samples do not determine it."""
    mark = {True: "", False: " (undetermined)", None: " (no samples)"}[row.get("cost_share_determined")]
    return f"{row['cost_share']:.2f}{mark}"


def _effects(items: list[dict]) -> str:
    if not items:
        return "none (or no sensitivity run)"
    count: dict[tuple, list] = {}
    for e in items:
        count.setdefault(tuple(e["features"]), []).append(e["window"])
    top = sorted(count.items(), key=lambda kv: -len(kv[1]))[:4]
    said = ", ".join(f"{a}–{b} (window{'s' if len(w) > 1 else ''} {', '.join(map(str, w))})" for (a, b), w in top)
    if len(count) > len(top):  # said, not left out silently: the reader would take these for all of them
        said += (
            f"; these are the {len(top)} in most windows of {len(count)} such pairs ({len(items)} with their "
            "windows: every one in identifiability.json's `effect_collinearity`)"
        )
    return said


def _ci(r, s) -> str:
    m = r[f"{s}_delta_deg"]
    if m is None or not np.isfinite(m):
        return "—" + _failures(r, s)
    lo, hi = r[f"{s}_ci_lo"], r[f"{s}_ci_hi"]
    if lo is None or not np.isfinite(lo):
        return f"{m:+.3f} [too few trials]" + _failures(r, s)
    return f"{m:+.3f} [{lo:+.3f}, {hi:+.3f}]" + _failures(r, s)


def _failures(r, s) -> str:
    """The trials of set ``s`` a row leaves out because a prediction's DOC failed, as the report says it (nothing
    when none did): a solver failure is counted, never averaged in."""
    n = r.get(f"{s}_doc_failures") or 0
    return f" ({n} DOC failure{'s' if n != 1 else ''} left out)" if n else ""


def _num(v, fmt: str) -> str:
    return "—" if v is None or not np.isfinite(v) else format(v, fmt)


#: the files an analysis writes at the top of its folder (identifiability.json first: :func:`write_sensitivity`)
OUTPUT_FILES = ("identifiability.json", "sensitivity.md", "sensitivity.csv")


def is_analysis(out_dir: str | Path) -> bool:
    """Whether ``out_dir`` holds an earlier analysis: an ``identifiability.json`` as :func:`write_sensitivity`
    writes it (written before the others, so an analysis stopped while writing them has it)."""
    try:
        d = json.loads((Path(out_dir) / "identifiability.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(d, dict) and {"config", "units", "postures"} <= d.keys()


def remove_outputs(out_dir: str | Path) -> None:
    """Remove an earlier analysis's outputs from ``out_dir`` (its checkpoints stay, to be reused), so that a rerun
    stopped early never leaves them looking like its own."""
    out_dir = Path(out_dir)
    for name in OUTPUT_FILES:
        (out_dir / name).unlink(missing_ok=True)
    for fig in sorted((out_dir / "figures").glob("sensitivity_*.png")) if (out_dir / "figures").is_dir() else ():
        fig.unlink(missing_ok=True)


def write_sensitivity(out: dict, out_dir: str | Path) -> list[Path]:
    """``figures/sensitivity_<posture>.png``, ``identifiability.json``, ``sensitivity.md`` and, last (so that a
    folder without it is unfinished), ``sensitivity.csv`` under ``out_dir``; returns the paths."""
    from .figures import save

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for p in sorted({r["posture"] for r in out["rows"]}):
        fig = plot_sensitivity(
            out["rows"],
            p,
            title=f"{out['config']['method']}, {out['config']['sections']} section(s), posture {p}",
            percent=out["config"].get("percent"),
        )
        path = out_dir / "figures" / f"sensitivity_{p}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        save(fig, path)
        paths.append(path)
    ident, md, csv = out_dir / "identifiability.json", out_dir / "sensitivity.md", out_dir / "sensitivity.csv"
    atomic_write_json(ident, {"config": out["config"], "units": out["units"], "postures": out["identifiability"]})
    atomic_write_text(md, "\n".join(_markdown(out)))
    atomic_write_text(csv, to_csv(out["rows"]))
    return [csv, md, ident, *paths]
