"""The figures of ``reproduce`` (matplotlib, Agg). Each function takes ``ax``/``axes=None`` and returns
the figure.

* :func:`plot_prediction` — seed Fig. 2: demonstrations vs predictions, q and q̇ (one posture, one section
  count);
* :func:`plot_weights` — seed Fig. 3: the learned weights per posture and section count, normalised as each
  feature's share of its window's cost on the fit's own reach (``ω_sj Φ_sj / Σ_j ω_sj Φ_sj``), so features
  in different units are comparable, undetermined shares hatched;
* :func:`plot_iscv` — seed Fig. 4: inter-subject predictions for some postures, time normalised;
* :func:`plot_convergence` — the merit of every fit per iteration;
* :func:`plot_truth` — virtual subjects: learned vs true cost shares;
* :func:`plot_methods` — MO-IRL vs the baselines that were run.
"""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ..features import FEATURES
from .names import CONVERGENCE_TITLE, natural_key, sections_text

__all__ = [
    "FIGURE_MARK",
    "is_marked_figure",
    "no_samples_note",
    "plot_convergence",
    "plot_iscv",
    "plot_methods",
    "plot_prediction",
    "plot_truth",
    "plot_weights",
    "save",
]

SHORT = {  # each the feature's name (FEATURES) in words, shortened where it stays unambiguous
    "cartesian_velocity": "Cartesian vel.",
    "energy": "energy",
    "geodesic": "geodesic",
    "joint_acceleration": "joint acc.",
    "torque_change": "torque change",
    "joint_velocity": "joint vel.",
    "joint_torque": "joint torque",
}
JOINT_COLOURS = ("tab:blue", "tab:green")
PRED_COLOUR, DEMO_COLOUR = "tab:blue", "tab:orange"


CAVEAT = (
    "Learned weights are one cost among several that explain the reaches; shares on the fit's own reach; hatched: "
    "undetermined (95 % interval of the share wider than 0.25, or missing the fit's share), not a finding."
)
NO_SAMPLES = (
    "No weight samples (--uncertainty of fit or reproduce): nothing is hatched, and no share here is a finding."
)
PANEL_NO_SAMPLES = "no weight samples:\nnot a finding"


def no_samples_note(method: str | None = None) -> str:
    """The footnote of a weights figure without weight samples, suggesting only what draws them for ``method``'s
    fits: ``--uncertainty`` for MO-IRL and MaxEnt (and when the method is not known), none for bilevel and KKT,
    which refuse it."""
    from ..irl.methods import builds_on_moirl

    if method is None or builds_on_moirl(method):
        return NO_SAMPLES
    return (
        f"No weight samples: {method} draws none (moirl and maxent fits do, with --uncertainty); nothing is hatched, "
        "and no share here is a finding."
    )


TRUTH_CAVEAT = (
    "Learned weights are one cost among several that explain the reaches; both rows' shares on {on}; hatched: "
    "the learned share is undetermined (its 95 % interval, on the fit's own reach, wider than 0.25 or missing the "
    "fit's share there), not a finding."
)


def _panel_undetermined(undetermined: dict | None, key, shape) -> np.ndarray | None:
    """The hatching of one panel: its fit's undetermined shares; every share when the figure has intervals but
    this fit has none (an unhatched panel under the caveat would read as determined); None without any."""
    if not undetermined:
        return None
    u = undetermined.get(key)
    return np.ones(shape, dtype=bool) if u is None else u


def _mark_no_samples(ax, undetermined: dict | None, key) -> None:
    """Say on a panel that its fit has no weight samples, where the figure's other fits have them."""
    if undetermined and key not in undetermined:
        ax.text(
            0.5,
            0.02,
            PANEL_NO_SAMPLES,
            transform=ax.transAxes,
            ha="center",
            va="bottom",
            fontsize=7,
            color="white",
            bbox={"facecolor": "black", "alpha": 0.6, "edgecolor": "none"},
        )


_LIGHT_CELL = 0.45
"""The luminance (0-1) of a heatmap cell above which its hatching is black, not white."""


def _share_heatmap(ax, shares, feature_labels: bool, undetermined=None):
    """Cost shares ``(n_windows, 7)`` as a window × feature heatmap on ``ax``, the ``undetermined`` cells (booleans
    of the same shape) hatched; returns the image."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path
    from matplotlib.transforms import Affine2D

    s = np.asarray(shares)
    im = ax.imshow(
        s.T,
        aspect="auto",
        cmap="viridis",
        vmin=0,
        vmax=1,
        interpolation="nearest",
        extent=(0.5, s.shape[0] + 0.5, len(FEATURES) - 0.5, -0.5),
    )
    cells = [] if undetermined is None else list(zip(*np.nonzero(np.asarray(undetermined, dtype=bool)), strict=True))
    # white hatching on dark cells, black on light ones: white on viridis' bright end (the large shares, the ones a
    # reader would quote) was nearly invisible
    rgb = im.cmap(im.norm(s))[..., :3]
    light = rgb @ np.array([0.2126, 0.7152, 0.0722]) > _LIGHT_CELL
    square = Path.unit_rectangle()
    for colour, group in (("white", [c for c in cells if not light[c]]), ("black", [c for c in cells if light[c]])):
        if group:  # one hatched path of every such cell: a patch per cell drew 2.5 times slower
            path = Path.make_compound_path(
                *(square.transformed(Affine2D().translate(w + 0.5, j - 0.5)) for w, j in group)
            )
            ax.add_patch(PathPatch(path, fill=False, hatch="///", edgecolor=colour, linewidth=0, alpha=0.6))
    ax.set_xticks(range(1, s.shape[0] + 1))
    ax.tick_params(labelsize=9)
    ax.set_yticks(range(len(FEATURES)))
    ax.set_yticklabels([SHORT[f] for f in FEATURES] if feature_labels else [], fontsize=9)
    return im


FIGURE_MARK = "reachirl"
"""What :func:`save` writes into every figure's metadata (a PNG's ``Software`` text chunk, a PDF's ``Creator``), by
which :func:`is_marked_figure` tells reachirl's own figures, which a command may replace, from a user's."""

#: how much of a file :func:`is_marked_figure` reads at most (a PNG's chunks before its image data; of a PDF, 5 kB)
_MARK_BYTES = 64 * 1024


def save(fig, path, close: bool = True) -> None:
    """Write ``fig`` atomically as PNG (200 dpi) or PDF, from ``path``'s suffix, marked as reachirl's
    (:data:`FIGURE_MARK`; no matplotlib version or date, so that a figure is the same bytes each time), and close
    it (unless ``close=False``)."""
    from pathlib import Path

    from ..io import atomic_path

    fmt = Path(path).suffix.lower().lstrip(".") or "png"
    if fmt not in ("png", "pdf"):
        raise ValueError(f"figures are written as .png or .pdf, got {path}")
    meta = (
        {"Software": FIGURE_MARK} if fmt == "png" else {"Creator": FIGURE_MARK, "Producer": None, "CreationDate": None}
    )
    bbox = _tight_png_bbox(fig, 200) if fmt == "png" else "tight"
    with atomic_path(path, suffix=f".{fmt}") as tmp:
        fig.savefig(tmp, dpi=200, bbox_inches=bbox, format=fmt, metadata=meta)
    if close:
        plt.close(fig)


def _tight_png_bbox(fig, dpi: float):
    """The region ``savefig(bbox_inches="tight")`` crops a PNG at ``dpi`` to (the figure's tight box on an Agg
    renderer at that dpi, padded by ``savefig.pad_inches``), found without the layout-only draw of the whole
    figure that matplotlib makes to find it: the same image."""
    before = fig.dpi
    fig.dpi = dpi
    try:
        box = fig.get_tightbbox(fig.canvas.get_renderer())
    finally:
        fig.dpi = before
    pad = plt.rcParams["savefig.pad_inches"]
    return box.padded(pad, pad)


def is_marked_figure(path) -> bool:
    """Whether the file at ``path`` is a PNG or PDF figure that :func:`save` wrote (its metadata holds
    :data:`FIGURE_MARK`); False for anything else, or a file that cannot be read. Reads at most 64 KiB
    (``_MARK_BYTES``): a PNG's chunks before its image data, a PDF's last kB and its information dictionary."""
    import re
    import struct
    from pathlib import Path

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            if path.suffix.lower() == ".png":
                if fh.read(8) != b"\x89PNG\r\n\x1a\n":
                    return False
                left = _MARK_BYTES - 8  # what may still be read after the signature
                for _ in range(64):  # the text chunks come before the image data
                    head = fh.read(8)
                    if len(head) < 8:
                        return False
                    size, kind = struct.unpack(">I4s", head)
                    left -= size + 12  # its length and type, data and CRC
                    if kind in (b"IDAT", b"IEND") or left < 0:
                        return False
                    data = fh.read(size + 4)[:size]  # and its CRC
                    if kind == b"tEXt" and data == b"Software\0" + FIGURE_MARK.encode():
                        return True
                return False
            if path.suffix.lower() != ".pdf" or fh.read(5) != b"%PDF-":
                return False
            fh.seek(0, 2)
            end = fh.tell()
            fh.seek(max(0, end - 1024))
            tail = fh.read()
            m = re.search(rb"/Info (\d+) 0 R.*?startxref\s+(\d+)\s+%%EOF\s*$", tail, re.S)
            if m is None or int(m.group(2)) > end:
                return False
            # the document's information dictionary, the object just before the cross-reference table
            xref = int(m.group(2))
            fh.seek(max(0, xref - 4096))
            before = fh.read(xref - max(0, xref - 4096))
    except OSError:
        return False
    info = re.search(rb"(\d+) 0 obj\s*<<((?:(?!endobj).)*)>>\s*endobj\s*$", before, re.S)
    mark = re.escape(b"/Creator (" + FIGURE_MARK.encode() + b")")
    return info is not None and info.group(1) == m.group(1) and re.search(mark, info.group(2)) is not None


def _grid(axes, nrows, ncols, figsize):
    if axes is None:
        fig, axes = plt.subplots(nrows, ncols, figsize=figsize, squeeze=False)
    else:
        axes = np.asarray(axes, dtype=object).reshape(nrows, ncols)
        fig = axes[0, 0].figure
    return fig, axes


def plot_prediction(arrays: dict, set_name: str = "train", title: str = "", axes=None):
    """Demonstrations (orange, dashed) and DOC predictions (blue, solid) of one set: q1, q2 (top), q̇1, q̇2
    (bottom); the same two colours in every panel, as the legend says. ``{set_name}/t`` are the predictions'
    times; the demonstrations are drawn on ``{set_name}/demo_t``, their own times, when given (a prediction seen as
    recorded lasts longer or shorter than its trial), else on the predictions' (the same normalised time)."""
    fig, axes = _grid(axes, 2, 2, (7.5, 5.0))
    t = arrays[f"{set_name}/t"]
    own = f"{set_name}/demo_t" in arrays  # without their own times the demonstrations are on their predictions'
    t_demo = arrays[f"{set_name}/demo_t"] if own else t
    for j in range(2):
        for row, (kind, unit) in enumerate((("q", "deg"), ("qd", "deg/s"))):
            ax = axes[row, j]
            demo = np.rad2deg(arrays[f"{set_name}/demo_{kind}"][..., j])
            pred = np.rad2deg(arrays[f"{set_name}/pred_{kind}"][..., j])
            for i in range(t.shape[0]):
                ax.plot(
                    t_demo[i],
                    demo[i],
                    "--",
                    color=DEMO_COLOUR,
                    lw=1.2,
                    alpha=0.85,
                    label="demonstration" if i == 0 else None,
                )
                ax.plot(
                    t[i], pred[i], "-", color=PRED_COLOUR, lw=1.2, alpha=0.85, label="prediction" if i == 0 else None
                )
            sym = "q" if kind == "q" else "q̇"
            ax.set_ylabel(f"{sym}{j + 1} ({unit})", fontsize=10)
            ax.tick_params(labelsize=9)
            ax.grid(alpha=0.3)
            if row == 1:
                ax.set_xlabel("time (s)" if own else "prediction's time (s); demonstrations scaled to it", fontsize=9)
    axes[0, 0].legend(loc="best", fontsize=9)
    if not title:
        from .protocol import SET_LABELS

        title = f"{SET_LABELS.get(set_name, set_name)}: demonstrations vs predictions"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _mark_flag(ax, flag: str | None) -> None:
    """Cross out a panel whose fit is flagged (``"w0"``: never left the initial weights; ``"one_step"``)."""
    if not flag:
        return
    text = {"w0": "NOT LEARNED\n(initial weights ω₀)", "one_step": "one step only"}.get(flag, flag)
    ax.text(
        0.5,
        0.5,
        text,
        transform=ax.transAxes,
        ha="center",
        va="center",
        fontsize=8,
        color="white",
        fontweight="bold",
        bbox={"facecolor": "crimson", "alpha": 0.85, "edgecolor": "none"},
    )


def plot_weights(
    shares: dict,
    postures: Sequence[str],
    sections: Sequence[int],
    axes=None,
    title: str = "",
    flags: dict | None = None,
    undetermined: dict | None = None,
    note: str | None = None,
    method: str | None = None,
):
    """``shares[(posture, sections)] = (n_windows, 7)`` cost shares; one heatmap per posture (columns) and
    section count (rows): features on the y axis, windows on the x axis. ``flags[(posture, sections)]`` marks
    fits that never left ω₀ (``"w0"``) or made one step (``"one_step"``); ``undetermined[(posture, sections)]``
    (booleans ``(n_windows, 7)``) hatches the shares whose interval is wide. The caveat is written under it:
    ``note``, by default :data:`CAVEAT` with ``undetermined``, else :func:`no_samples_note` of the fits' ``method``
    (what draws weight samples for it, if anything)."""
    fig, axes = _grid(axes, len(sections), len(postures), (2.4 * len(postures) + 2.2, 2.6 * len(sections) + 0.8))
    im = None
    for r, n in enumerate(sections):
        for c, p in enumerate(postures):
            ax = axes[r, c]
            s = shares.get((p, n))
            if s is None:
                ax.set_axis_off()
                continue
            hatch = _panel_undetermined(undetermined, (p, n), np.shape(s))
            im = _share_heatmap(ax, s, feature_labels=c == 0, undetermined=hatch)
            _mark_no_samples(ax, undetermined, (p, n))
            _mark_flag(ax, (flags or {}).get((p, n)))
            if r == 0:
                ax.set_title(p, fontsize=10)
            if c == 0:
                ax.set_ylabel(sections_text(n), fontsize=10)
            if r == len(sections) - 1:
                ax.set_xlabel("window", fontsize=10)
    if im is not None:
        cb = fig.colorbar(im, ax=axes, shrink=0.8)
        cb.set_label("share of the window's cost", fontsize=10)
        cb.ax.tick_params(labelsize=9)
    fig.suptitle(title or "Learned weights (each feature's share of its window's cost)", fontsize=11)
    note = note or (CAVEAT if undetermined else no_samples_note(method))
    fig.text(0.01, -0.03, note, fontsize=8, va="top", wrap=True)
    return fig


def _curves(ax, x: np.ndarray, ys: np.ndarray, colour, style: str, lw: float, alpha: float) -> None:
    """The curves ``ys (n, len(x))`` over ``x`` on ``ax``, as one line collection (a study's ISCV panel holds
    hundreds of trials)."""
    from matplotlib.collections import LineCollection

    segments = np.stack([np.broadcast_to(x, ys.shape), ys], axis=-1)
    ax.add_collection(LineCollection(segments, colors=colour, linestyles=style, linewidths=lw, alpha=alpha))


def plot_iscv(arrays_by_posture: dict, axes=None, title: str = ""):
    """ISCV trials of each posture (columns): q (top) and q̇ (bottom), measured dashed, predicted solid,
    q1 blue,
    q2 green, over normalised time."""
    postures = list(arrays_by_posture)
    fig, axes = _grid(axes, 2, max(1, len(postures)), (5 * max(1, len(postures)), 6))
    for c, p in enumerate(postures):
        a = arrays_by_posture[p]
        if "iscv/t" not in a:
            axes[0, c].set_axis_off()
            axes[1, c].set_axis_off()
            continue
        n_pts = a["iscv/t"].shape[1]
        s = np.linspace(0, 1, n_pts)
        for row, kind in enumerate(("q", "qd")):
            ax = axes[row, c]
            for j in range(2):
                for who, style, lw, alpha in (("demo", "--", 0.8, 0.5), ("pred", "-", 1.0, 0.8)):
                    _curves(ax, s, np.rad2deg(a[f"iscv/{who}_{kind}"][..., j]), JOINT_COLOURS[j], style, lw, alpha)
            ax.autoscale_view()
            ax.plot([], [], "k--", label="measured")
            ax.plot([], [], "k-", label="predicted")
            ax.set_ylabel("q (deg)" if kind == "q" else "q̇ (deg/s)")
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(f"{p}: ISCV ({a['iscv/t'].shape[0]} trials); q1 blue, q2 green", fontsize=9)
            else:
                ax.set_xlabel("normalised time")
        axes[0, c].legend(loc="best", fontsize=8)
    fig.suptitle(title or "Inter-subject cross-validation")
    fig.tight_layout()
    return fig


class _DecimalLogLabels(matplotlib.ticker.LogFormatterSciNotation):
    """A log axis's labels as plain numbers (0.6, 0.1, 1, 3e-05) on the ticks matplotlib's own formatter labels:
    over the decade or two a merit spans, 0.6 reads more easily than 6 × 10⁻¹, and needs no mathematical text
    (whose parser takes a tenth of a second to build)."""

    def __call__(self, x, pos=None):
        return f"{x:g}" if super().__call__(x, pos) else ""


def plot_convergence(
    histories: dict,
    sections: Sequence[int],
    axes=None,
    title: str = "",
    merit_label: str = "merit m(x)",
    start: str = "the initial weights ω₀",
    x_key: str = "iteration",
):
    """``histories[(posture, sections)] = [{"iteration", "merit", ...}]``: merit (log scale) per iteration.
    ``merit_label`` names the merit and its units on the y axis; ``start`` says what the weights of iteration 0
    are (the x axis). ``x_key="evaluation"``: a direct search's history (bilevel), one point per DOC evaluation
    whose DOC converged."""
    fig, axes = _grid(axes, 1, len(sections), (3.6 * len(sections) + 0.6, 3.2))
    postures = sorted({p for p, _ in histories}, key=natural_key)
    colours = plt.get_cmap("tab10")
    for c, n in enumerate(sections):
        ax = axes[0, c]
        xs: list = []
        for k, p in enumerate(postures):
            h = histories.get((p, n)) or []
            ok = [
                r
                for r in h
                if isinstance(r.get("merit"), int | float)
                and np.isfinite(r["merit"])
                and r.get(x_key) is not None
                and r.get("accepted", True)
            ]  # a baseline's history may lack iterations (bilevel); a failed evaluation has no merit
            it, m = [r[x_key] for r in ok], [r["merit"] for r in ok]
            if it:
                ax.semilogy(it, m, "o-", ms=3, color=colours(k % 10), label=p)
                xs += it
        if xs and max(xs) == min(xs):  # a single iteration: matplotlib spans ±0.05 and ticks fractions over it
            ax.set_xlim(min(xs) - 0.5, min(xs) + 1.5)
        ax.set_title(sections_text(n), fontsize=10)
        ax.tick_params(labelsize=9)
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
        ax.set_xlabel(f"iteration (0: {start})" if x_key == "iteration" else "DOC evaluation", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        if ax.get_yscale() == "log":  # a panel without a history keeps its linear axis
            ax.yaxis.set_major_formatter(_DecimalLogLabels())  # as matplotlib's log scale sets its formatters
            ax.yaxis.set_minor_formatter(_DecimalLogLabels())
        if c == 0:
            ax.set_ylabel(merit_label, fontsize=9)
    if axes[0, 0].get_legend_handles_labels()[0]:  # a one-shot baseline has no iterations to plot
        axes[0, 0].legend(fontsize=8)
    fig.suptitle(title or CONVERGENCE_TITLE)
    fig.tight_layout()
    return fig


def plot_truth(
    learned: dict,
    true: dict,
    axes=None,
    title: str = "",
    flags: dict | None = None,
    undetermined: dict | None = None,
    on: str = "the true weights' own noise-free reach",
):
    """``learned[posture]``, ``true[posture]``: ``(n_windows, 7)`` cost shares, both on the features ``on`` names;
    learned (top) vs true (bottom), postures in natural order (P2 before P10). ``flags[posture]`` marks learned
    panels whose fit never left ω₀ or made one step; ``undetermined[posture]`` hatches the learned shares whose
    interval (on the fit's own reach) is wide."""
    postures = sorted((p for p in learned if p in true), key=natural_key)
    fig, axes = _grid(axes, 2, max(1, len(postures)), (2.5 * max(1, len(postures)) + 1.5, 5.2))
    im = None
    for c, p in enumerate(postures):
        for r, (label, d) in enumerate((("learned", learned), ("true", true))):
            ax = axes[r, c]
            hatch = _panel_undetermined(undetermined, p, np.shape(d[p])) if r == 0 else None
            im = _share_heatmap(ax, d[p], feature_labels=c == 0, undetermined=hatch)
            if r == 0:
                ax.set_title(p, fontsize=9)
                _mark_no_samples(ax, undetermined, p)
                _mark_flag(ax, (flags or {}).get(p))
            if c == 0:
                ax.set_ylabel(label, fontsize=9)
            if r == 1:
                ax.set_xlabel("window", fontsize=8)
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="share of the window's cost")
    fig.suptitle(title or "Virtual subjects: learned vs true weights (cost shares)")
    fig.text(0.01, -0.03, TRUTH_CAVEAT.format(on=on) if undetermined else NO_SAMPLES, fontsize=8, va="top", wrap=True)
    return fig


def plot_methods(headlines: dict, sections: Sequence[int], ax=None, title: str = ""):
    """``headlines[method][set][sections] = {"mean", "std"}`` (ALL postures, q): grouped bars."""
    from .protocol import SET_LABELS, SETS

    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 3.6))
    else:
        fig = ax.figure
    methods = list(headlines)
    labels = [f"{SET_LABELS[s]} · {sections_text(n)}" for s in SETS for n in sections]  # as the tables' columns
    x = np.arange(len(labels))
    width = 0.8 / max(1, len(methods))
    for k, m in enumerate(methods):
        means = [((headlines[m][s].get(n) or {}).get("mean") or np.nan) for s in SETS for n in sections]
        sds = [((headlines[m][s].get(n) or {}).get("std") or 0.0) for s in SETS for n in sections]
        ax.bar(x + (k - (len(methods) - 1) / 2) * width, means, width, yerr=sds, capsize=2, label=m)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("RMSE of q (deg), ALL postures\n(mean ± SD of the tables' ALL row)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    ax.set_title(title or "Methods compared")
    fig.tight_layout()
    return fig
