"""The posture figure: Berret's five initial postures under the chosen reading and the rejected one."""

from __future__ import annotations

import numpy as np

from ..arm import ArmModel
from .population import BERRET_POSTURES_DEG, berret_to_model


def _downward_vertical_reading(elbow_deg: float, shoulder_deg: float) -> np.ndarray:
    """The other reading (rejected): shoulder from the downward vertical, elbow < 0 = flexion."""
    return np.deg2rad([float(shoulder_deg) - 90.0, -float(elbow_deg)])


def plot_postures(arm: ArmModel | None = None, target_fraction: float = 0.95, axes=None):
    """Stick figures of P1–P5 with the bar, under the chosen reading (left) and the rejected one (right).

    Returns the matplotlib figure; nothing is shown.
    """
    import matplotlib.pyplot as plt

    arm = arm or ArmModel.from_anthropometrics(1.76, 69.9, "M")
    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(11, 5.5), constrained_layout=True)
    else:
        fig = axes[0].figure
    readings = (
        (
            "chosen: q1 = −shoulder, q2 = −elbow\n(angles from the forward horizontal, clockwise)",
            berret_to_model,
        ),
        (
            "rejected: shoulder from the downward vertical,\nnegative elbow = flexion",
            _downward_vertical_reading,
        ),
    )
    colors = plt.get_cmap("tab10").colors
    for ax, (title, reading) in zip(axes, readings, strict=True):
        for i, (p, (e, sh)) in enumerate(BERRET_POSTURES_DEG.items()):
            q = reading(e, sh)
            pts = np.vstack([[0.0, 0.0], arm.elbow(q), arm.fk(q)])
            qd = np.rad2deg(q) + 0.0  # no "-0°"
            ax.plot(
                pts[:, 0],
                pts[:, 1],
                "-o",
                color=colors[i],
                lw=2.5,
                ms=4,
                label=f"{p} [{e:g}; {sh:g}]  q=({qd[0]:.0f}°, {qd[1]:.0f}°)",
            )
            ax.annotate(p, pts[-1], textcoords="offset points", xytext=(4, 4), color=colors[i], fontsize=9)
        for frac, style in ((target_fraction, "-"), (0.85, ":")):
            ax.axvline(
                frac * arm.length,
                color="k",
                ls=style,
                lw=1.5 if style == "-" else 1.0,
                label=f"bar at {frac:.0%} of L" + (" (Berret)" if frac == 0.85 else ""),
            )
        ax.plot(0, 0, "ks", ms=8)
        ax.set_aspect("equal")
        ax.set_xlim(-0.6, 0.95)
        ax.set_ylim(-0.85, 0.85)
        ax.grid(alpha=0.3)
        ax.set_xlabel("x forward (m)")
        ax.set_ylabel("y up (m)")
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7.5, loc="upper left")
    fig.suptitle(f"Berret 2011 initial postures [elbow; shoulder] (deg); arm L = {arm.length:.2f} m, shoulder at 0")
    return fig
