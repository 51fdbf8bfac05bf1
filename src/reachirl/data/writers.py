"""Writers of motion-capture files in formats reachirl reads: TRC and C3D (markers), MOT (joint angles).

Every writer is deterministic (fixed number formatting, no timestamps: the same arrays give the same bytes)
and atomic (a temporary file beside the target, then a rename), so a half-written file never appears.

* **TRC** — OpenSim's marker format (``PathFileType 4 (X/Y/Z)``): a 5-line header, the ``Frame#``/``Time``
  columns, then X/Y/Z per marker, tab separated. Units are written in the header (``mm`` by default) and the
  coordinates are given with 3 decimals (1 µm).
* **MOT** — OpenSim's storage format (``version=1``, ``nRows``, ``nColumns``, ``inDegrees=yes``,
  ``endheader``) with columns ``time q1 q2`` (degrees, in reachirl's angle convention unless other names are
  given).
* **C3D** — written with ezc3d: POINT data in ``mm`` with ``POINT:LABELS``, ``POINT:RATE`` and
  ``POINT:UNITS``.

:func:`read_trc_simple` and :func:`read_mot_simple` are minimal parsers of exactly what these writers
produce (for round-trip tests and the human-likeness check); reachirl's general readers live in
:mod:`reachirl.data.readers`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..io import atomic_path, atomic_write_text

__all__ = ["read_mot_simple", "read_trc_simple", "write_c3d", "write_mot", "write_trc"]


def _check_markers(time: np.ndarray, markers: Mapping[str, np.ndarray]) -> tuple[np.ndarray, list[str], np.ndarray]:
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size < 2 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise ValueError("time must hold at least 2 finite, strictly increasing samples")
    if not markers:
        raise ValueError("no markers to write")
    names = [str(n) for n in markers]
    for n in names:
        if not n or any(c.isspace() for c in n):
            raise ValueError(f"marker names must be non-empty without whitespace, got {n!r}")
    data = []
    for n, a in markers.items():
        a = np.asarray(a, dtype=float)
        if a.shape != (t.size, 3):
            raise ValueError(f"marker {n!r} must have shape ({t.size}, 3), got {a.shape}")
        data.append(a)
    return t, names, np.stack(data, axis=1)  # (n_frames, n_markers, 3)


def _rate(t: np.ndarray, rate: float | None) -> float:
    if rate is not None:
        return float(rate)
    return float(round(1.0 / np.median(np.diff(t)), 6))


def _fmt(v: float, decimals: int) -> str:
    """Fixed-point text with no negative zero (``-0.000`` would differ from ``0.000`` for equal data)."""
    s = f"{v:.{decimals}f}"
    return s[1:] if s.startswith("-") and float(s) == 0.0 else s


_NEGATIVE_ZERO = re.compile(r"(?<![^\t\n])-(?=0(?:\.0*)?(?:[\t\n]|\Z))")


def _fixed_lines(a: np.ndarray, decimals: Sequence[int]) -> str:
    """The rows of ``a (n, k)`` as tab-separated lines (no trailing newline), column ``j`` with ``decimals[j]``
    fixed decimals: the text of :func:`_fmt` cell by cell, formatted in one operation."""
    a = np.asarray(a, dtype=float)
    if a.shape[0] == 0:
        return ""
    row = "\t".join(f"%.{int(d)}f" for d in decimals)
    text = "\n".join([row] * a.shape[0]) % tuple(a.ravel().tolist())
    # a negative number prints as -0.00… only if it is within 10^-decimals of zero
    near = np.signbit(a) & (np.abs(a) <= 10.0 ** -np.asarray(decimals, dtype=float))
    return _NEGATIVE_ZERO.sub("", text) if near.any() else text


def write_trc(
    path: str | Path,
    time: np.ndarray,
    markers: Mapping[str, np.ndarray],
    units: str = "mm",
    rate: float | None = None,
    decimals: int = 3,
) -> Path:
    """Write markers (``name -> (n_frames, 3)`` in ``units``) as an OpenSim TRC file; returns the path.

    NaN coordinates (a gap) are written as empty fields, as Vicon and OpenSim do.
    """
    path = Path(path)
    t, names, data = _check_markers(time, markers)
    rate = _rate(t, rate)
    n_frames, n_markers = data.shape[0], data.shape[1]
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.2f}\t{rate:.2f}\t{n_frames}\t{n_markers}\t{units}\t{rate:.2f}\t1\t{n_frames}",
        "Frame#\tTime\t" + "\t".join(f"{n}\t\t" for n in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, n_markers + 1)),
        "",
    ]
    flat = np.round(data.reshape(n_frames, -1), decimals) + 0.0  # + 0.0: no "-0.000"
    times = np.round(t, 5) + 0.0
    row_fmt = "%d\t%.5f\t" + "\t".join([f"%.{decimals}f"] * flat.shape[1])
    for k in range(n_frames):
        if np.all(np.isfinite(flat[k])):
            lines.append(row_fmt % (k + 1, times[k], *flat[k]))
        else:  # a gap: empty fields
            vals = ["" if not np.isfinite(v) else f"{v:.{decimals}f}" for v in flat[k]]
            lines.append(f"{k + 1}\t{times[k]:.5f}\t" + "\t".join(vals))
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def write_mot(
    path: str | Path,
    time: np.ndarray,
    angles_deg: np.ndarray,
    columns: Sequence[str] = ("q1", "q2"),
    decimals: int = 6,
    *,
    durable: bool = True,
) -> Path:
    """Write joint angles in degrees, ``(n, n_columns)``, as an OpenSim ``.mot`` file (``inDegrees=yes``);
    ``durable``: synced to the disk (:func:`reachirl.io.atomic_path`)."""
    path = Path(path)
    t = np.asarray(time, dtype=float).reshape(-1)
    a = np.asarray(angles_deg, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.shape != (t.size, len(columns)):
        raise ValueError(f"angles must have shape ({t.size}, {len(columns)}), got {a.shape}")
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("time must hold at least 2 strictly increasing samples")
    lines = [
        path.name,
        "version=1",
        f"nRows={t.size}",
        f"nColumns={len(columns) + 1}",
        "inDegrees=yes",
        "endheader",
        "\t".join(["time", *columns]),
    ]
    lines.append(_fixed_lines(np.column_stack([t, a]), [8, *[decimals] * a.shape[1]]))
    atomic_write_text(path, "\n".join(lines) + "\n", durable=durable)
    return path


def write_c3d(
    path: str | Path,
    time: np.ndarray,
    markers: Mapping[str, np.ndarray],
    units: str = "mm",
    rate: float | None = None,
) -> Path:
    """Write markers (``name -> (n_frames, 3)`` in ``units``) as a C3D file with ezc3d (POINT data only)."""
    import ezc3d

    path = Path(path)
    t, names, data = _check_markers(time, markers)
    rate = _rate(t, rate)
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = [units]
    pts = np.ones((4, len(names), t.size))
    pts[:3] = np.transpose(data, (2, 1, 0))
    c3d["data"]["points"] = pts
    with atomic_path(path, suffix=".c3d") as tmp:
        c3d.write(str(tmp))
    return path


# ---------------------------------------------------------------------- minimal readers (round trips, checks)
def read_trc_simple(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]:
    """Read a TRC written by :func:`write_trc`: ``(time, {name: (n, 3)}, header)``; empty fields are NaN."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t"), strict=False))
    names = [n for n in lines[3].split("\t")[2:] if n]
    rows = []
    for line in lines[5:]:
        if not line.strip():
            continue
        f = line.split("\t")
        f += [""] * (2 + 3 * len(names) - len(f))
        rows.append([float(v) if v.strip() else np.nan for v in f[: 2 + 3 * len(names)]])
    arr = np.array(rows, dtype=float)
    return arr[:, 1], {n: arr[:, 2 + 3 * i : 5 + 3 * i] for i, n in enumerate(names)}, header


def read_mot_simple(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]:
    """Read a MOT file written by :func:`write_mot`: ``(time, {column: (n,)}, header)``."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    header = dict(line.split("=", 1) for line in lines[:end] if "=" in line)
    cols = lines[end + 1].split("\t")
    arr = np.array([[float(v) for v in line.split("\t")] for line in lines[end + 2 :] if line.strip()])
    return arr[:, 0], {c: arr[:, i] for i, c in enumerate(cols) if i > 0}, header
