"""Inter-subject validation over every ordered pair of subjects (``reachirl reproduce --iscv all-pairs``).

With ``ProtocolConfig(iscv="all-pairs")`` the protocol learns, per posture and section count, from **every**
subject in turn (the same number of training trials, chosen with the same seeded rule) and predicts every trial
of that posture of every other subject (``n_iscv`` trials *per test subject*). The units learned from the
protocol's own training subject are the main table's; the others are extra units (key suffix ``-t<subject>``)
that keep their per-trial RMSEs only (no prediction arrays).

:func:`pair_rows` turns the units into the subject × subject RMSE matrix: one row per (method, posture,
sections, train_subject, test_subject) with the RMSE of q (mean, population SD, n over the test subject's
trials). The diagonal (train_subject = test_subject) is the training subject's own CV set. Posture ``ALL`` pools
every posture's trials. :func:`write_pairs` writes ``iscv_pairs.csv`` and returns the figures for the report's
figure workers to draw: one heatmap per method and section count (``figures/iscv_pairs_<method>_s<n>.png``) and
``figures/iscv_vs_cv_<method>.png``: does a subject's own CV RMSE predict how well its weights transfer to the
others (Spearman ρ)?
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..data.trial import Trial
from ..errors import InputError
from ..io import atomic_write_text
from .names import sections_text

__all__ = [
    "ALL",
    "COLUMNS",
    "pair_matrix",
    "pair_rows",
    "pair_splits",
    "pair_training_subjects",
    "plot_iscv_vs_cv",
    "plot_pair_matrices",
    "plot_pair_matrix",
    "transfer_summary",
    "write_pairs",
]

log = logging.getLogger(__name__)

ALL = "ALL"
COLUMNS = (
    "method",
    "posture",
    "sections",
    "train_subject",
    "test_subject",
    "rmse_q_mean_deg",
    "rmse_q_sd_deg",
    "n",
    "doc_failures",
)


def pair_training_subjects(trials: Sequence[Trial], config) -> list[str]:
    """The subjects the all-pairs units learn from besides the protocol's training subject (none unless
    ``config.iscv == "all-pairs"``)."""
    from .protocol import resolve_train_subject

    if config.iscv != "all-pairs":
        return []
    main = resolve_train_subject(trials, config)
    return [s for s in sorted({t.subject for t in trials}) if s != main]


def pair_splits(trials: Sequence[Trial], postures: Sequence[str], config) -> dict:
    """``{(posture, subject): Split}`` for every extra training subject; a (posture, subject) without training
    trials (e.g. no right-arm reach with ``cv="other-side"``) is left out with a log message."""
    from .protocol import split_trials

    out = {}
    for s in pair_training_subjects(trials, config):
        for p in postures:
            try:
                out[(p, s)] = split_trials(trials, p, replace(config, train_subject=s))
            except InputError as e:
                log.info("all-pairs: no unit for subject %s, posture %s (%s)", s, p, e)
    return out


def _stats(v: list[float]) -> tuple[float, float, int]:
    """Mean, population SD and number of ``v``; NaN for both with no value (every prediction failed)."""
    a = np.asarray(v, dtype=float)
    return (float(a.mean()), float(a.std()), int(a.size)) if a.size else (float("nan"), float("nan"), 0)


def pair_rows(run) -> list[dict]:
    """The all-pairs matrix of ``run`` (:class:`~reachirl.experiments.results.RunResult`) as rows (see the
    module docstring), in a fixed order: methods as run, postures as run then ``ALL``, sections, subjects."""
    subject_of = {t.id: t.subject for t in run.dataset.trials}
    methods, postures = list(run.config.methods), list(run.postures)
    cells: dict[tuple, list[float]] = {}
    failures: dict[tuple, int] = {}
    for r in [*run.results.values(), *run.pairs.values()]:
        u = r["unit"]
        train = u.get("train_subject") or run.train_subject
        for set_name in ("cv", "iscv"):
            for e in r["sets"][set_name]["trials"]:
                test = train if set_name == "cv" else subject_of.get(e["id"])
                if test is None:
                    continue
                for p in (u["posture"], ALL):  # a prediction whose DOC failed is counted, not averaged in
                    key = (u["method"], p, int(u["sections"]), train, test)
                    cells.setdefault(key, [])
                    failures[key] = failures.get(key, 0) + (not e.get("converged", True))
                    if e.get("converged", True):
                        cells[key].append(float(e["rmse_deg"]["q"]))
    order = {p: i for i, p in enumerate([*postures, ALL])}
    morder = {m: i for i, m in enumerate(methods)}
    rows = []
    for k in sorted(cells, key=lambda k: (morder.get(k[0], 99), order.get(k[1], 99), k[2], k[3], k[4])):
        mean, sd, n = _stats(cells[k])
        rows.append(dict(zip(COLUMNS, (*k, mean, sd, n, failures[k]), strict=True)))
    return rows


def to_csv(rows: Sequence[dict]) -> str:
    lines = [",".join(COLUMNS)]
    for r in rows:
        lines.append(
            ",".join(
                [
                    r["method"],
                    r["posture"],
                    str(r["sections"]),
                    r["train_subject"],
                    r["test_subject"],
                    _number(r["rmse_q_mean_deg"]),
                    _number(r["rmse_q_sd_deg"]),
                    str(r["n"]),
                    str(r["doc_failures"]),
                ]
            )
        )
    return "\n".join(lines) + "\n"


def _number(x: float) -> str:
    """A CSV cell: 4 decimals, empty where no prediction converged (``doc_failures`` says how many failed)."""
    return f"{x:.4f}" if np.isfinite(x) else ""


def pair_matrix(rows: Sequence[dict], method: str, posture: str, sections: int) -> tuple[list[str], np.ndarray]:
    """``(subjects, M)`` with ``M[i, j]`` the mean RMSE of q (deg) of subject j's trials predicted with subject
    i's weights (NaN where no unit)."""
    sel = [r for r in rows if r["method"] == method and r["posture"] == posture and r["sections"] == sections]
    subjects = sorted({r["train_subject"] for r in sel} | {r["test_subject"] for r in sel})
    idx = {s: i for i, s in enumerate(subjects)}
    m = np.full((len(subjects), len(subjects)), np.nan)
    for r in sel:
        m[idx[r["train_subject"]], idx[r["test_subject"]]] = r["rmse_q_mean_deg"]
    return subjects, m


def transfer_summary(rows: Sequence[dict], method: str, postures: Sequence[str], sections: int) -> dict:
    """Per (training subject, posture): its own CV RMSE against the mean RMSE of its weights on the other
    subjects; ``{"cv", "iscv", "spearman_rho", "spearman_p", "n"}`` (ρ over the points; ``None`` if < 3)."""
    from scipy.stats import spearmanr

    cv, iscv, cv_c, iscv_c = [], [], [], []
    for p in postures:
        subjects, m = pair_matrix(rows, method, p, sections)
        a, b = [], []
        for i in range(len(subjects)):
            off = np.delete(m[i], i)
            if np.isfinite(m[i, i]) and np.isfinite(off).any():
                a.append(float(m[i, i]))
                b.append(float(np.nanmean(off)))
        cv += a
        iscv += b
        if len(a) > 1:  # centred per posture: the subjects' differences, not the postures' difficulty
            cv_c += list(np.asarray(a) - np.mean(a))
            iscv_c += list(np.asarray(b) - np.mean(b))

    def rho(x, y):
        if len(x) >= 3 and np.ptp(x) > 0 and np.ptp(y) > 0:
            res = spearmanr(x, y)
            return float(res.statistic), float(res.pvalue)
        return None, None

    r, p_val = rho(cv, iscv)
    rc, pc = rho(cv_c, iscv_c)
    return {
        "cv": cv,
        "iscv": iscv,
        "spearman_rho": r,
        "spearman_p": p_val,
        "n": len(cv),
        "within_posture_rho": rc,
        "within_posture_p": pc,
    }


# ---------------------------------------------------------------------- figures
_COLOUR_LABEL = "RMSE of q (deg)"


def plot_pair_matrix(
    subjects: Sequence[str],
    matrix: np.ndarray,
    ax=None,
    title: str = "",
    vmax=None,
    annotate: bool | None = None,
    colorbar: bool = True,
):
    """A train × test subject heatmap of the RMSE of q (deg); the diagonal (CV) is outlined. ``colorbar``: its
    colour bar beside it (not when several heatmaps share one)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(subjects)
    if ax is None:
        fig, ax = plt.subplots(figsize=(1.2 + 0.45 * max(n, 4), 1.0 + 0.4 * max(n, 4)))
    fig = ax.figure
    im = ax.imshow(
        matrix, cmap="magma_r", vmin=0, vmax=vmax if vmax is not None else np.nanmax(matrix), interpolation="nearest"
    )
    ax.set_xticks(range(n))
    ax.set_yticks(range(n))
    fs = 8 if n <= 8 else 5
    ax.set_xticklabels(subjects, rotation=90, fontsize=fs)
    ax.set_yticklabels(subjects, fontsize=fs)
    ax.set_xlabel("test subject")
    ax.set_ylabel("weights learned on")
    for i in range(n):
        ax.add_patch(matplotlib.patches.Rectangle((i - 0.5, i - 0.5), 1, 1, fill=False, lw=1.2, ec="tab:cyan"))
    if annotate if annotate is not None else n <= 8:
        for i in range(n):
            for j in range(n):
                if np.isfinite(matrix[i, j]):
                    r, g, b, _ = im.cmap(im.norm(matrix[i, j]))
                    dark = 0.299 * r + 0.587 * g + 0.114 * b < 0.5  # white on dark cells, black on light ones
                    ax.text(
                        j,
                        i,
                        f"{matrix[i, j]:.1f}",
                        ha="center",
                        va="center",
                        fontsize=7,
                        color="white" if dark else "black",
                    )
    ax.set_title(title, fontsize=9)
    if colorbar:
        fig.colorbar(im, ax=ax, shrink=0.8, label=_COLOUR_LABEL)
    return fig


def plot_iscv_vs_cv(
    rows: Sequence[dict], method: str, postures: Sequence[str], sections: Sequence[int], axes=None, title: str = ""
):
    """Left: the distribution of CV (diagonal) and ISCV (off-diagonal) pair RMSEs per section count. Right: each
    training subject's CV RMSE against the mean RMSE of its weights on the other subjects (one point per
    subject and posture), with Spearman ρ per section count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    fig = axes[0].figure
    data, labels = [], []
    for n in sections:
        diag = [
            r["rmse_q_mean_deg"]
            for r in rows
            if r["method"] == method
            and r["posture"] in postures
            and r["sections"] == n
            and r["train_subject"] == r["test_subject"]
            and r["n"]
        ]
        off = [
            r["rmse_q_mean_deg"]
            for r in rows
            if r["method"] == method
            and r["posture"] in postures
            and r["sections"] == n
            and r["train_subject"] != r["test_subject"]
            and r["n"]
        ]
        data += [diag, off]
        labels += [f"CV\n{sections_text(n)}", f"ISCV\n{sections_text(n)}"]
    keep = [i for i, d in enumerate(data) if d]
    axes[0].boxplot([data[i] for i in keep], tick_labels=[labels[i] for i in keep])
    axes[0].set_ylabel("RMSE of q (deg), per subject pair and posture")
    axes[0].set_title("CV (own trials) vs ISCV (other subjects)", fontsize=9)
    for k, n in enumerate(sections):
        s = transfer_summary(rows, method, postures, n)
        rho = "n/a" if s["spearman_rho"] is None else f"{s['spearman_rho']:.2f}"
        axes[1].scatter(s["cv"], s["iscv"], s=18, color=f"C{k}", label=f"{sections_text(n)} (ρ = {rho}, n = {s['n']})")
    lim = axes[1].get_xlim()[1], axes[1].get_ylim()[1]
    top = max(lim)
    axes[1].plot([0, top], [0, top], color="0.7", lw=0.8, ls="--")
    axes[1].set_xlabel("training subject's own CV RMSE (deg)")
    axes[1].set_ylabel("mean RMSE of its weights on the others (deg)")
    axes[1].legend(fontsize=8)
    axes[1].set_title("does a subject's CV predict how its weights transfer?", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_pair_matrices(matrices: dict, vmax: float, title: str = ""):
    """One train × test heatmap (:func:`plot_pair_matrix`) per panel of ``matrices`` (``{panel: (subjects,
    matrix)}``: a posture, or ALL), side by side on one colour scale up to ``vmax``, with one colour bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(matrices)
    fig, axes = plt.subplots(
        1, n + 1, figsize=(3.6 * n + 0.9, 3.8), squeeze=False, gridspec_kw={"width_ratios": [1] * n + [0.06]}
    )
    for ax, (p, (subjects, mat)) in zip(axes[0, :n], matrices.items(), strict=True):
        plot_pair_matrix(subjects, mat, ax=ax, title=f"{p}", vmax=vmax, colorbar=False)
        if ax is not axes[0, 0]:
            ax.set_ylabel("")
    fig.colorbar(axes[0, 0].images[0], cax=axes[0, -1], label=_COLOUR_LABEL)  # one scale for every panel
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def write_pairs(run, fig_dir: Path | None = None) -> dict:
    """Write ``iscv_pairs.csv`` of ``run``; return it with the all-pairs figures as jobs for the caller to draw
    beside the run's other figures (:func:`reachirl.experiments.rendering.drawing`): ``{"rows", "jobs": [FigureJob],
    "figures": {name: {caption}}, "markdown": [lines for report.md]}``."""
    from .rendering import FigureJob

    out = Path(run.out_dir)
    fig_dir = fig_dir or out / "figures"
    head = ["## All-pairs inter-subject validation (`iscv_pairs.csv`)", ""]
    n_subjects = len(run.dataset.subjects)
    if n_subjects < 2:  # no pair to learn on one subject and predict another
        note = f"Not run: it needs at least two subjects, and this data has {n_subjects}."
        return {"rows": [], "jobs": [], "figures": {}, "markdown": [*head, note, ""]}
    rows = pair_rows(run)
    atomic_write_text(out / "iscv_pairs.csv", to_csv(rows))
    methods, postures, sections = list(run.config.methods), list(run.postures), list(run.config.sections)
    jobs: list[FigureJob] = []
    figs: dict[str, dict] = {}
    md = list(head)
    failed = sum(r["doc_failures"] for r in rows if r["posture"] != ALL)
    if failed:
        md += [
            f"**{failed} prediction(s) failed** (the DOC did not converge): counted in `iscv_pairs.csv`'s "
            "`doc_failures`, not averaged into its means; a cell where every prediction failed has no mean.",
            "",
        ]
    for m in methods:
        for n in sections:
            panels = [*postures, ALL] if len(postures) > 1 else postures
            mats = {p: pair_matrix(rows, m, p, n) for p in panels}
            if not any(mat.size for _, mat in mats.values()):
                continue
            vmax = max(float(np.nanmax(mat)) for _, mat in mats.values() if mat.size)
            name = f"iscv_pairs_{m}_s{n}.png"
            title = (
                f"{m}, {n} section(s): RMSE of q (deg), weights of row subject on column subject's trials "
                "(diagonal: own CV)"
            )
            jobs.append(
                FigureJob(
                    f"{__name__}:plot_pair_matrices",
                    {"matrices": mats, "vmax": vmax, "title": title},
                    (fig_dir / name,),
                )
            )
            figs[name] = {
                "caption": f"All-pairs ISCV, {m}, {n} section(s): subject × subject matrix of the RMSE "
                f"of q per posture{' and pooled (ALL)' if len(panels) > 1 else ''}; row = "
                "the subject the weights were learned on, column = the subject predicted; "
                "the outlined diagonal is the training subject's own CV."
            }
        name = f"iscv_vs_cv_{m}.png"
        title = f"{m}: CV against ISCV over all subject pairs"
        kwargs = {"rows": rows, "method": m, "postures": postures, "sections": sections, "title": title}
        jobs.append(FigureJob(f"{__name__}:plot_iscv_vs_cv", kwargs, (fig_dir / name,)))
        figs[name] = {
            "caption": f"{m}: distribution of CV and all-pairs ISCV RMSEs, and each training subject's "
            "CV against the mean RMSE of its weights on the other subjects (Spearman ρ)."
        }
        md += [
            f"### {m}",
            "",
            "| sections | CV (diagonal) mean | ISCV (off-diagonal) mean | ISCV/CV | "
            "best donor (lowest mean ISCV, ALL) | worst donor | Spearman ρ (CV vs transfer) | ρ within postures |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for n in sections:
            sel = [r for r in rows if r["method"] == m and r["sections"] == n and r["posture"] != ALL and r["n"]]
            diag = [r["rmse_q_mean_deg"] for r in sel if r["train_subject"] == r["test_subject"]]
            off = [r["rmse_q_mean_deg"] for r in sel if r["train_subject"] != r["test_subject"]]
            if not off:
                continue
            subjects, mat = pair_matrix(rows, m, ALL if len(postures) > 1 else postures[0], n)
            donors = {
                s: float(np.nanmean(np.delete(mat[i], i)))
                for i, s in enumerate(subjects)
                if np.isfinite(np.delete(mat[i], i)).any()
            }
            best = min(donors, key=donors.get)
            worst = max(donors, key=donors.get)
            ts = transfer_summary(rows, m, postures, n)
            rho = "—" if ts["spearman_rho"] is None else f"{ts['spearman_rho']:.2f} (p = {ts['spearman_p']:.2g})"
            rho_c = (
                "—"
                if ts["within_posture_rho"] is None
                else f"{ts['within_posture_rho']:.2f} (p = {ts['within_posture_p']:.2g})"
            )
            cvm = f"{np.mean(diag):.2f}°" if diag else "—"
            ratio = f"{np.mean(off) / np.mean(diag):.2f}" if diag else "—"
            md.append(
                f"| {n} | {cvm} | {np.mean(off):.2f}° | {ratio} | {best} ({donors[best]:.2f}°) | "
                f"{worst} ({donors[worst]:.2f}°) | {rho} | {rho_c} |"
            )
        md.append("")
    md += [
        "Means are over (train, test, posture) cells of the per-pair mean RMSE of q. ρ: Spearman correlation, "
        "over (training subject, posture), of the subject's own CV RMSE with the mean RMSE of its weights on "
        "the others; within postures: both centred on their posture's mean first (subject differences only, "
        "not posture difficulty). The matrices are in "
        "`iscv_pairs.csv` and the figures `iscv_pairs_*.png`, `iscv_vs_cv_*.png`.",
        "",
    ]
    return {"rows": rows, "jobs": jobs, "figures": figs, "markdown": md}
