"""Synthetic reaches with known joint angles, and small writers of standard marker files, for the data
tests."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from reachirl.arm import ArmModel

SAMPLE = Path(__file__).resolve().parents[2] / "src" / "reachirl" / "data" / "ue_adl_sample"
MAP = "shoulder=SH,elbow=EL,wrist=WR,fingertip=FT"


def min_jerk_q(q0, qf, duration=0.8, rest=0.5, rate=100.0):
    """A joint-space minimum-jerk reach with ``rest`` seconds of stillness before and after."""
    n = round((2 * rest + duration) * rate) + 1
    t = np.arange(n) / rate
    s = np.clip((t - rest) / duration, 0, 1)
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    q0, qf = np.asarray(q0, float), np.asarray(qf, float)
    return t, q0 + (qf - q0) * s[:, None]


def lab_markers(arm: ArmModel, q, yaw_deg=10.0, shoulder=(0.15, 0.2, 1.1), side="right", wrist_frac=0.6):
    """3-D markers (metres, Z up, forward ≈ +Y turned by ``yaw_deg``) of the planar arm at angles ``q``.

    A left arm is the right one reflected across the lab's X = 0 plane.
    """
    el, ft = arm.elbow(q), arm.fk(q)
    wr = el + wrist_frac * (ft - el)
    yaw = np.radians(yaw_deg)
    fwd, up = np.array([np.sin(yaw), np.cos(yaw), 0.0]), np.array([0.0, 0.0, 1.0])
    sh = np.broadcast_to(np.asarray(shoulder, float), (len(q), 3))
    out = {"SH": sh.copy()}
    for name, p in (("EL", el), ("WR", wr), ("FT", ft)):
        out[name] = sh + p[:, :1] * fwd + p[:, 1:] * up
    if side == "left":
        for v in out.values():
            v[:, 0] *= -1
    return out


def trc_text(markers: dict, rate=100.0, units="mm", up="z"):
    """An OpenSim TRC file. With ``up="y"`` the lab's Z-up data are rotated into OpenSim's Y-up convention."""
    names = list(markers)
    n = len(next(iter(markers.values())))
    scale = {"mm": 1000.0, "m": 1.0, "cm": 100.0}[units]
    lines = [
        "PathFileType\t4\t(X/Y/Z)\tsynthetic.trc",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:g}\t{rate:g}\t{n}\t{len(names)}\t{units}\t{rate:g}\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{m}\t\t" for m in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(names))),
        "",
    ]
    for i in range(n):
        cells = [str(i + 1), f"{i / rate:.5f}"]
        for m in names:
            x, y, z = markers[m][i] * scale
            if up == "y":
                x, y, z = x, z, -y
            cells += ["" if np.isnan(v) else f"{v:.6f}" for v in (x, y, z)]
        lines.append("\t".join(cells))
    return "\n".join(lines) + "\n"


def vicon_text(markers: dict, rate=100.0, subject="SUBJ", units="mm"):
    """A Vicon Nexus 'Trajectories' CSV export (with the UTF-8 BOM)."""
    names = list(markers)
    n = len(next(iter(markers.values())))
    scale = {"mm": 1000.0, "m": 1.0}[units]
    lines = [
        "\ufeffTrajectories",
        f"{rate:g}",
        ",," + ",".join(f"{subject}:{m},," for m in names),
        "Frame,Sub Frame," + ",".join("X,Y,Z" for _ in names),
        ",," + ",".join(f"{units}" for _ in range(3 * len(names))),
    ]
    for i in range(n):
        cells = [str(i + 1), "0"]
        for m in names:
            cells += ["" if np.isnan(v) else f"{v * scale:.6f}" for v in markers[m][i]]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="session")
def synth_arm() -> ArmModel:
    return ArmModel.from_anthropometrics(1.76, 70.0, "M", upper_arm_m=0.30, forearm_m=0.26, hand_m=0.18)


@pytest.fixture(scope="session")
def reach(synth_arm):
    """A synthetic reach: ``t``, true ``q`` and its lab markers, right arm."""
    t, q = min_jerk_q([-1.4, 1.6], [-0.6, 0.5])
    return SimpleNamespace(t=t, q=q, markers=lab_markers(synth_arm, q), arm=synth_arm)


@pytest.fixture(scope="session")
def synth():
    return SimpleNamespace(
        min_jerk_q=min_jerk_q,
        lab_markers=lab_markers,
        trc_text=trc_text,
        vicon_text=vicon_text,
        SAMPLE=SAMPLE,
        MAP=MAP,
    )
