"""Readers for motion-capture files. Each one validates what it reads and raises :class:`InputError` naming
the file, the line (or frame) and the problem.

Marker files (TRC, C3D, Vicon Nexus "Trajectories" CSV) give a :class:`MarkerData`: positions in **metres**,
in the lab frame of the file. Joint-angle files (OpenSim MOT, plain CSV) give an :class:`AngleData`: ``q (n,
2)`` in **radians** in the model convention (q1 the upper arm from +x forward, CCW positive; q2 the elbow
flexion, 0 straight).

Units, per format:

* TRC: the header's ``Units`` field (``mm``, ``cm`` or ``m``).
* C3D: the ``POINT:UNITS`` parameter (``mm`` when absent, as in the standard).
* Vicon CSV: line 5 (``mm`` for every coordinate in a Nexus export; ``m``/``cm`` also accepted).
* MOT: ``inDegrees=yes|no`` in the header (``yes`` when absent, OpenSim's default).
* CSV angles: columns ``time,q1,q2``. The units are **radians** unless the header says otherwise, either by
  column suffixes (``q1_deg,q2_deg`` or ``q1_rad,q2_rad``) or by a comment line ``# units: deg`` (or ``rad``)
  before the header. ``time`` is in seconds.

:func:`read_subject_info` reads the subject-info CSV (``subject,sex,height_m,mass_kg`` and optionally
``upper_arm_m,forearm_m,hand_m``) and also accepts the UE-ADL ``subjects.csv`` directly
(``subject,age,sex,height_m,mass_kg,...,right_upper_arm_mm,...``); see its docstring.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
import re
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..arm import SEGMENT_COLUMNS, anthropometry_problem, bmi_note, bmi_problem, sex_key
from ..errors import InputError
from ..io import read_text

__all__ = [
    "ANGLE_FORMATS",
    "FORMATS",
    "AngleData",
    "MarkerData",
    "SubjectInfo",
    "detect_format",
    "read_angles_csv",
    "read_c3d",
    "read_file",
    "read_manifest",
    "read_markers",
    "read_mot",
    "read_subject_info",
    "read_trc",
    "read_vicon_csv",
]

FORMATS = ("trc", "c3d", "vicon-csv", "mot", "csv")
#: the formats of :data:`FORMATS` that hold joint angles, not markers
ANGLE_FORMATS = ("mot", "csv")
VICON_BLOCKS = ("Trajectories", "Devices", "Joints", "Model Outputs", "Segments")  # a Nexus CSV export's blocks
_UNIT_SCALE = {
    "mm": 1e-3,
    "millimeter": 1e-3,
    "millimetre": 1e-3,
    "millimeters": 1e-3,
    "millimetres": 1e-3,
    "cm": 1e-2,
    "centimeter": 1e-2,
    "centimetre": 1e-2,
    "centimeters": 1e-2,
    "centimetres": 1e-2,
    "m": 1.0,
    "meter": 1.0,
    "metre": 1.0,
    "meters": 1.0,
    "metres": 1.0,
}


# ---------------------------------------------------------------------- data
@dataclass(frozen=True)
class MarkerData:
    """Marker trajectories: ``markers[name]`` is ``(n, 3)`` in metres (NaN where unseen), sampled at ``rate``
    Hz. A point exactly at the lab's origin (0, 0, 0) is unseen, in every format: how C3D writers and Vicon's and
    other exports mark a marker they lost.

    ``t`` is the time of each frame in seconds; ``up`` is the lab axis opposite gravity in the file's
    convention (``"+z"`` for Vicon and C3D, ``"+y"`` for OpenSim TRC), used when the caller does not say.
    ``labelled_subjects``: the subject names Vicon put before the marker names (``"ADL001:RSHO1"``), if any.
    """

    rate: float
    markers: Mapping[str, np.ndarray]
    source: str = ""
    t: np.ndarray = field(default=None)  # type: ignore[assignment]
    up: str = "+z"
    labelled_subjects: tuple[str, ...] = ()
    up_declared: bool = False  # ``up`` is the file's own statement (C3D's POINT:Y_SCREEN), not its format's convention

    def __post_init__(self) -> None:
        where = self.source or None
        if not (np.isfinite(self.rate) and self.rate > 0):
            raise InputError(f"sampling rate must be a positive number, got {self.rate}", where)
        if not self.markers:
            raise InputError("no markers", where)
        n = None
        clean: dict[str, np.ndarray] = {}
        for name, a in self.markers.items():
            a = np.array(a, dtype=float)
            if a.ndim != 2 or a.shape[1] != 3:
                raise InputError(f"marker {name!r} has shape {a.shape}, expected (n, 3)", where)
            a[np.all(a == 0.0, axis=1)] = np.nan  # exactly at the lab's origin: how exports mark an unseen marker
            if n is None:
                n = a.shape[0]
            elif a.shape[0] != n:
                raise InputError(f"marker {name!r} has {a.shape[0]} frames, others have {n}", where)
            far = np.abs(a) > MAX_MARKER_COORDINATE  # NaN (unseen) is not far; inf is
            if np.any(far):
                k = int(np.flatnonzero(np.any(far, axis=1))[0])
                dist = float(np.abs(a[k]).max())
                # a lab-sized distance times 1000: millimetres declared (or taken) as metres
                why = "millimetres declared as metres? (the file's units)" if dist <= 1e3 * 30.0 else "a corrupt value?"
                raise InputError(
                    f"marker {name!r} is {dist:.3g} m from the lab's origin, beyond any lab "
                    f"({MAX_MARKER_COORDINATE:.0f} m): {why}",
                    where,
                    f"frame {k + 1}",
                )
            a.setflags(write=False)
            clean[str(name)] = a
        object.__setattr__(self, "markers", clean)
        t = np.arange(n) / float(self.rate) if self.t is None else np.asarray(self.t, dtype=float).reshape(-1)
        if t.shape != (n,):
            raise InputError(f"time has {t.shape[0]} samples, markers have {n}", where)
        if n >= 2 and (not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0)):
            k = int(np.flatnonzero(~(np.diff(t) > 0))[0]) + 1 if np.any(~(np.diff(t) > 0)) else 0
            raise InputError("time is not strictly increasing", where, f"frame {k + 1}")
        _check_even_steps(t, where)
        t = t.copy()
        t.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "rate", float(self.rate))

    @property
    def n_frames(self) -> int:
        return int(self.t.shape[0])

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.markers)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.markers[name]


MAX_MARKER_COORDINATE = 1000.0  # m: no motion-capture volume is larger
UNEVEN_STEP = 0.25  # a time step this far from the recording's median one (as a fraction) is not a sampling of it


def _check_even_steps(t: np.ndarray, where) -> None:
    """Refuse marker times ``t`` (increasing) whose steps are not even: one more than :data:`UNEVEN_STEP` away from
    their median is a frame missing (a row deleted, the frames numbered again) or a Time column that jitters, which
    the filters and derivatives, made for even sampling, would turn into wrong speeds and torques (a row left out
    at the peak speed gave 62 N·m for 10). Time written with few decimals (3 at 120 Hz: steps of 8 and 9 ms) passes.
    (Joint angles are resampled at their own times instead: :func:`reachirl.data.preprocess.angles_to_trial`.)
    The :class:`~reachirl.errors.InputError` names the frame after the step."""
    if t.shape[0] < 3:
        return
    steps = np.diff(t)
    step = float(np.median(steps))
    off = np.flatnonzero(np.abs(steps / step - 1.0) > UNEVEN_STEP)
    if off.size:
        k = int(off[0])
        ratio = steps[k] / step
        why = "frames missing" if ratio > 1.5 and abs(ratio - round(ratio)) <= UNEVEN_STEP else "an uneven Time column"
        raise InputError(
            f"the time steps {steps[k]:.4g} s from frame {k + 1} to {k + 2}, where the recording's steps are "
            f"{step:.4g} s ({why}?): the filters need even sampling",
            where,
            f"frame {k + 2}",
        )


MAX_JOINT_SPEED = 100.0  # rad/s (~5700°/s): human joints peak near 20-30 rad/s, in throwing


@dataclass(frozen=True)
class AngleData:
    """Joint angles ``q (n, 2)`` in radians (model convention) at times ``t (n,)`` in seconds; ``side``: the arm
    the file's columns name (``r_shoulder_elev``: right), ``None`` when they name none."""

    t: np.ndarray
    q: np.ndarray
    source: str = ""
    side: str | None = None  # the arm the file's angle columns name (r_/l_ prefix, OpenSim's), or None

    def __post_init__(self) -> None:
        where = self.source or None
        t = np.asarray(self.t, dtype=float).reshape(-1)
        q = np.asarray(self.q, dtype=float)
        if q.shape != (t.shape[0], 2):
            raise InputError(f"q has shape {q.shape}, expected ({t.shape[0]}, 2)", where)
        if t.shape[0] < 2:
            raise InputError(f"need at least 2 samples, got {t.shape[0]}", where)
        bad = np.flatnonzero(~(np.diff(t) > 0))
        if bad.size:
            raise InputError(
                f"time is not strictly increasing ({t[bad[0]]} then {t[bad[0] + 1]})",
                where,
                f"sample {bad[0] + 2}",
            )
        if not np.all(np.isfinite(q)):
            k = int(np.flatnonzero(~np.all(np.isfinite(q), axis=1))[0])
            raise InputError("angles contain NaN or infinite values", where, f"sample {k + 1}")
        if np.any(np.abs(q) > 2 * np.pi + 1e-9):
            raise InputError(
                f"angles reach {np.degrees(np.abs(q).max()):.0f}° after unit conversion, beyond one turn: "
                "are degrees declared as radians?",
                where,
            )
        # An angle that jumps by about a turn between two samples has wrapped (359° is -1°): unwrap it. A jump
        # faster than any arm moves after that is a glitch in the file, not a reach.
        wrapped = np.flatnonzero(np.any(np.abs(np.diff(q, axis=0)) > np.pi, axis=1))
        if wrapped.size:
            logging.getLogger(__name__).warning(
                "%s: angles wrap around a full turn at sample %d; unwrapped", where or "angles", wrapped[0] + 2
            )
            q = np.unwrap(q, axis=0)
        speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
        if np.any(speed > MAX_JOINT_SPEED):
            k, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
            raise InputError(
                f"q{j + 1} jumps by {np.degrees(abs(q[k + 1, j] - q[k, j])):.0f}° in one sample "
                f"({speed[k, j]:.0f} rad/s, more than any arm's {MAX_JOINT_SPEED:.0f} rad/s): a glitch in the file?",
                where,
                f"sample {k + 2}",
            )
        for a in (t, q):
            a.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "q", q)

    @property
    def rate(self) -> float:
        return float(1.0 / np.median(np.diff(self.t)))


# ---------------------------------------------------------------------- helpers
def _float(cell: str, path: Path, line: int, col: str, allow_empty: bool = False) -> float:
    cell = cell.strip()
    if cell == "" and allow_empty:
        return math.nan
    try:
        v = float(cell)
    except ValueError:
        raise InputError(f"non-numeric cell {cell!r} in column {col}", path, f"line {line}") from None
    if not math.isfinite(v) and not allow_empty:
        raise InputError(f"non-finite value {cell!r} in column {col}", path, f"line {line}")
    return v


def _unit_scale(unit: str, path: Path, where: str) -> float:
    key = unit.strip().lower()
    if key not in _UNIT_SCALE:
        raise InputError(f"unknown length unit {unit!r}, expected mm, cm or m", path, where)
    return _UNIT_SCALE[key]


# ---------------------------------------------------------------------- header row counts
#: rows (frames, samples) a recording may declare: 10⁷ is 2.8 h at 1 kHz, more than any reach's recording
MAX_ROWS = 10_000_000


def _declared_rows(text: str | None, field: str, path: Path, where: str) -> int | None:
    """A header's row count (``NumFrames``, ``nRows``) as an int in ``[1, MAX_ROWS]``; ``None`` if absent."""
    if text is None or text.strip() == "":
        return None
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"header field {field}={text.strip()[:40]!r} is not a number of rows", path, where) from None
    if not (math.isfinite(v) and v == int(v) and 1 <= v <= MAX_ROWS):
        raise InputError(f"header field {field}={text.strip()[:40]} is not a row count in [1, {MAX_ROWS}]", path, where)
    return int(v)


def _check_row_count(n: int, declared: int | None, field: str, what: str, path: Path, last_line: int) -> None:
    """The rows present match the header's count: fewer is a truncated file, more a header that lies."""
    if declared is None or n == declared:
        return
    if n < declared:
        raise InputError(
            f"truncated file: the header says {field}={declared}, the file ends after {n} {what}",
            path,
            f"line {last_line}",
        )
    raise InputError(f"the header says {field}={declared} but the file holds {n} {what}", path, f"line {last_line}")


# ---------------------------------------------------------------------- TRC
def read_trc(path: str | Path) -> MarkerData:
    """Read an OpenSim TRC marker file (tab-separated; ``Units`` from the header line; Y up by convention)."""
    path = Path(path)
    lines = read_text(path).splitlines()
    if not lines[0].startswith("PathFileType"):
        raise InputError("not a TRC file (line 1 should start with 'PathFileType')", path, "line 1")
    if len(lines) < 5:
        raise InputError("truncated header: a TRC file needs 5 header lines", path)
    keys = lines[1].split("\t")
    vals = lines[2].split("\t")
    if len(vals) < len(keys):
        raise InputError(f"header line 3 has {len(vals)} fields, line 2 names {len(keys)}", path, "line 3")
    hdr = {k.strip(): v.strip() for k, v in zip(keys, vals, strict=False)}
    for k in ("DataRate", "NumMarkers", "Units"):
        if k not in hdr:
            raise InputError(f"header lacks the {k!r} field", path, "line 2")
    rate = _float(hdr["DataRate"], path, 3, "DataRate")
    scale = _unit_scale(hdr["Units"], path, "line 3")
    name_cells = lines[3].split("\t")
    if len(name_cells) < 2 or name_cells[0].strip() not in ("Frame#", "Frame"):
        raise InputError("line 4 should start with 'Frame#\\tTime'", path, "line 4")
    names = [c.strip() for c in name_cells[2::3]]
    names = [n for n in names if n]
    n_markers = int(_float(hdr["NumMarkers"], path, 3, "NumMarkers"))
    if len(names) != n_markers:
        raise InputError(f"line 4 names {len(names)} markers, the header says NumMarkers={n_markers}", path, "line 4")
    if len(set(names)) != len(names):
        raise InputError("duplicate marker names", path, "line 4")
    n_cols = 2 + 3 * n_markers
    declared = _declared_rows(hdr.get("NumFrames"), "NumFrames", path, "line 3")
    rows, times = [], []
    first_frame, last_line = None, 5
    for i, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split("\t")
        if len(cells) < n_cols:
            # trailing markers unseen may be written as empty cells or left off; OpenSim writes them empty
            raise InputError(f"truncated row: {len(cells)} fields, expected {n_cols}", path, f"line {i}")
        frame = _float(cells[0], path, i, "Frame#")
        if first_frame is None:
            first_frame = frame
        elif frame != first_frame + len(rows):
            raise InputError(
                f"frame number {cells[0].strip()} where {first_frame + len(rows):g} was expected (a "
                "frame missing, repeated or out of order)",
                path,
                f"line {i}",
            )
        last_line = i
        times.append(_float(cells[1], path, i, "Time"))
        try:  # the common row: every cell a number or empty
            rows.append([float(c) if c else math.nan for c in cells[2:n_cols]])
        except ValueError:  # a blank or non-numeric cell: read cell by cell, naming the one at fault
            rows.append(
                [
                    _float(c, path, i, names[(j - 2) // 3], allow_empty=True)
                    for j, c in enumerate(cells[2:n_cols], start=2)
                ]
            )
    if not rows:
        raise InputError("no data rows after the header", path)
    _check_row_count(len(rows), declared, "NumFrames", "frames", path, last_line)
    if rate > 0 and len(times) > 1:
        step = float(np.median(np.diff(times)))
        if not abs(step * rate - 1.0) <= 0.02:
            raise InputError(
                f"the Time column steps {step:.6g} s but the header's DataRate={hdr['DataRate']} Hz "
                f"means {1.0 / rate:.6g} s",
                path,
                "line 3",
            )
    a = np.asarray(rows) * scale
    markers = {n: a[:, 3 * k : 3 * k + 3] for k, n in enumerate(names)}
    return MarkerData(rate=rate, markers=markers, source=str(path), t=np.asarray(times), up="+y")


# ---------------------------------------------------------------------- C3D
def _vicon_label(label: str) -> tuple[str, str]:
    """Vicon's ``"Subject:Marker"`` as ``(subject, marker)``; ``("", label)`` without a subject."""
    subject, sep, name = label.partition(":")
    return (subject, name) if sep else ("", label)


def read_c3d(path: str | Path) -> MarkerData:
    """Read the 3-D points of a C3D file with ``ezc3d`` (``POINT:UNITS``; residual < 0, NaN or exactly (0, 0, 0)
    → unseen; up: ``POINT:Y_SCREEN``, else Z). A ``Subject:`` prefix is dropped from the labels, as from a Vicon
    CSV's names."""
    from ..validation import check_file_size

    path = Path(path)
    check_file_size(path)  # a regular file (not /dev/zero) of sane size
    if path.stat().st_size == 0:
        raise InputError("file is empty", path)
    _check_c3d_parameters(path)  # ezc3d crashes the process (a segfault) on some damaged parameter sections
    import ezc3d

    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises RuntimeError/IOError with C++ messages
        raise InputError(f"not a readable C3D file ({str(e).strip() or type(e).__name__})", path) from None
    try:
        point = c["parameters"]["POINT"]
        labels = [str(s).strip() for s in point["LABELS"]["value"]]
        rate = float(np.ravel(point["RATE"]["value"])[0])
        units = point["UNITS"]["value"] if "UNITS" in point else ["mm"]
        unit = str(units[0]).strip() if len(units) else "mm"
        screen = point["Y_SCREEN"]["value"] if "Y_SCREEN" in point else []
        y_screen = str(screen[0]).strip().upper() if len(screen) else ""
        pts = np.asarray(c["data"]["points"], dtype=float)  # (4, n_markers, n_frames)
        resid = c["data"]["meta_points"]["residuals"] if "meta_points" in c["data"] else None
    except (KeyError, IndexError, TypeError, ValueError) as e:
        raise InputError(f"C3D file lacks POINT parameters ({e})", path) from None
    if pts.ndim != 3 or pts.shape[1] == 0:
        raise InputError("C3D file holds no 3-D points", path)
    if pts.shape[2] == 0:
        raise InputError("C3D file holds no frames", path)
    declared = _c3d_declared_frames(path)
    if declared is not None and declared > pts.shape[2]:
        # ezc3d reads what is there and says nothing: a cut-off file would give a cut-off reach
        raise InputError(
            f"truncated C3D file: the header declares {declared} frames, the file holds {pts.shape[2]}",
            path,
        )
    if len(labels) < pts.shape[1]:
        labels += [f"M{k + 1:03d}" for k in range(len(labels), pts.shape[1])]
    if len(set(labels[: pts.shape[1]])) != pts.shape[1]:
        raise InputError("duplicate point labels", path)
    # Vicon writes "Subject:Marker" labels; the name alone, as the Vicon CSV reader gives it, unless that makes two
    # markers one (several subjects in one file)
    split = [_vicon_label(s) for s in labels[: pts.shape[1]]]
    bare = [name for _, name in split]
    prefixes = tuple(sorted({subject for subject, _ in split if subject}))
    if len(set(bare)) == len(bare):
        labels = bare
    else:  # a stray marker or two of another subject: the recorded subject's markers by their bare names
        counts = Counter(subject for subject, _ in split if subject).most_common()
        others = sum(c for _, c in counts[1:])
        if counts and others <= 2 and counts[0][1] > 2 * others:  # clearly the subject recorded, else refused
            own = counts[0][0]
            named = [name if s == own else label for (s, name), label in zip(split, labels[: len(split)], strict=True)]
            if len(set(named)) == len(named):
                labels = named
    scale = _unit_scale(unit, path, "POINT:UNITS")
    xyz = pts[:3].transpose(2, 1, 0) * scale  # (n_frames, n_markers, 3)
    if resid is not None:
        r = np.asarray(resid, dtype=float).reshape(-1, pts.shape[1], pts.shape[2])[0].T
        xyz[r < 0] = np.nan
    markers = {labels[k]: xyz[:, k, :] for k in range(pts.shape[1])}
    # POINT:Y_SCREEN is the lab axis drawn upwards (Vicon writes +Z; OptiTrack Motive, Y up, +Y)
    declared = y_screen in ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
    return MarkerData(
        rate=rate,
        markers=markers,
        source=str(path),
        up=y_screen.lower() if declared else "+z",
        labelled_subjects=prefixes,
        up_declared=declared,
    )


def _check_c3d_parameters(path: Path) -> None:
    """Refuse a C3D file whose parameter section :func:`_c3d_parameter_problem` finds damaged, before ``ezc3d``
    reads it (the file is mapped: only the pages the walk reads are read)."""
    import mmap

    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
        problem = _c3d_parameter_problem(data)
    if problem is not None:
        raise InputError(f"not a readable C3D file (damaged parameter section: {problem})", path)


def _c3d_parameter_problem(data) -> str | None:
    """Walk the C3D parameter section's records (the C3D specification: each group or parameter record is a
    name, a signed pointer to the next record and, for a parameter, its type, dimensions and data): what is
    wrong with a record that points outside the file or holds an impossible type or size, or ``None``."""
    import struct

    if len(data) < 512 or data[1] != 0x50:
        return None  # not a C3D header: ezc3d says so itself
    start = (data[0] - 1) * 512
    if data[0] < 1 or start + 4 > len(data):
        return f"its first block {data[0]} lies outside the file"
    processor = data[start + 3] - 83  # 1 Intel, 2 DEC, 3 MIPS
    if processor not in (1, 2, 3):
        return f"unknown processor type {data[start + 3]}"
    order = ">" if processor == 3 else "<"
    end = len(data)  # not the section's declared block count, which some writers get wrong
    pos = start + 4
    for _ in range(100_000):
        if pos + 2 > end:
            return "a record runs past its end"
        n_chars, ident = struct.unpack_from("bb", data, pos)
        if n_chars == 0 or ident == 0:
            return None  # the last record
        name_end = pos + 2 + abs(n_chars)
        if name_end + 2 > end:
            return "a record's name runs past its end"
        (offset,) = struct.unpack_from(order + "h", data, name_end)
        if ident > 0:  # a parameter: its type, dimensions and data must fit
            q = name_end + 2
            if q + 2 > end:
                return "a parameter runs past its end"
            kind, n_dims = struct.unpack_from("bB", data, q)
            if kind not in (-1, 1, 2, 4) or n_dims > 7 or q + 2 + n_dims > end:
                return f"a parameter of type {kind} with {n_dims} dimensions"
            size = abs(kind) * math.prod(data[q + 2 : q + 2 + n_dims])
            if q + 2 + n_dims + size > end:
                return "a parameter's data runs past its end"
        if offset == 0:
            return None  # the last record
        nxt = name_end + offset
        if offset < 0 or nxt <= pos or nxt > end:
            return f"the record at byte {pos} points to byte {nxt}"
        pos = nxt
    return "too many records"


def _c3d_declared_frames(path: Path) -> int | None:
    """Frames declared by a C3D header (words 4 and 5: first and last frame), or ``None`` when unknown. 16-bit
    frame numbers saturate at 65535 in long files: a last frame of 65535 declares at least that many frames."""
    import struct

    try:
        with open(path, "rb") as fh:
            head = fh.read(10)
    except OSError:
        return None
    if len(head) < 10 or head[1] != 0x50:
        return None
    counts = []
    for order in "<>":  # Intel/DEC headers are little-endian, MIPS big-endian
        first, last = struct.unpack(order + "HH", head[6:10])
        if 1 <= first <= last <= 65535:  # a last frame of 65535 may be saturated: then a lower bound
            counts.append(last - first + 1)
    return min(counts) if counts else None


# ---------------------------------------------------------------------- Vicon Nexus CSV
def read_vicon_csv(path: str | Path) -> MarkerData:
    """Read a Vicon Nexus "Trajectories" CSV export (UE-ADL's format).

    The ``Trajectories`` block: its line ``Trajectories``, then the rate, the marker names (``Subject:Marker``,
    one per X/Y/Z triplet), ``Frame,Sub Frame,X,Y,Z,...``, the units, and data until a blank line. Other blocks
    (``Devices``, ``Joints``, ``Model Outputs``, ``Segments``, which Nexus writes before it when they are
    exported too) may come before or after it. Empty cells are unseen markers (NaN), and so are the frames whose
    rows are missing (the ``Frame`` column skips them): gap filling then treats both alike. The ``Subject:``
    prefix is dropped from the names.
    """
    path = Path(path)
    text = read_text(path)
    lines = text.splitlines()
    starts = [i for i, line in enumerate(lines) if i == 0 or not lines[i - 1].strip(", \t")]  # a block's first line
    blocks = [lines[i].split(",")[0].strip() for i in starts if lines[i].strip(", \t")]
    if "Trajectories" not in blocks:
        if lines[0].split(",")[0].strip() in VICON_BLOCKS:
            raise InputError(f"no 'Trajectories' block (the file's blocks: {', '.join(blocks)})", path)
        raise InputError("not a Vicon 'Trajectories' CSV (line 1 should be 'Trajectories')", path, "line 1")
    top = next(i for i in starts if lines[i].split(",")[0].strip() == "Trajectories")  # line top + 1
    lines = lines[top:]
    if len(lines) < 5:
        raise InputError("truncated header: expected 5 header lines (Trajectories, rate, names, X/Y/Z, units)", path)
    try:  # Vicon writes the frame rate alone on the line after "Trajectories"
        rate = float(lines[1].split(",")[0])
    except ValueError:
        raise InputError(
            f"expected the frame rate in Hz (a number alone on the line after 'Trajectories'), found {lines[1][:40]!r}",
            path,
            f"line {top + 2}",
        ) from None
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"sampling rate must be a positive number, got {rate:g}", path, f"line {top + 2}")
    names_row = next(csv.reader([lines[2]]))
    axes_row = next(csv.reader([lines[3]]))
    units_row = next(csv.reader([lines[4]]))
    if len(axes_row) < 2 or axes_row[0].strip() != "Frame":
        raise InputError(f"line {top + 4} should start with 'Frame,Sub Frame'", path, f"line {top + 4}")
    cols: dict[str, int] = {}
    prefixes: set[str] = set()
    for j, cell in enumerate(names_row):
        name = cell.strip()
        if not name:
            continue
        subject, name = _vicon_label(name)
        if subject:
            prefixes.add(subject)
        if name in cols:
            raise InputError(f"duplicate marker name {name!r}", path, f"line {top + 3}")
        if j + 2 >= len(axes_row) or [a.strip() for a in axes_row[j : j + 3]] != ["X", "Y", "Z"]:
            raise InputError(f"marker {name!r} is not followed by X,Y,Z columns", path, f"line {top + 4}")
        cols[name] = j
    if not cols:
        raise InputError("no marker names", path, f"line {top + 3}")
    n_cols = max(cols.values()) + 3
    unit = None
    for j in cols.values():
        for u in units_row[j : j + 3]:
            u = u.strip()
            if unit is None:
                unit = u
            elif u != unit:
                raise InputError(f"mixed units {unit!r} and {u!r}", path, f"line {top + 5}")
    scale = _unit_scale(unit or "", path, f"line {top + 5}")
    rows, frames = [], []
    for i, line in enumerate(lines[5:], start=top + 6):
        if not line.strip(", \t"):
            break  # end of the Trajectories block
        cells = line.split(",")
        if len(cells) < n_cols:
            raise InputError(f"truncated row: {len(cells)} fields, expected {n_cols}", path, f"line {i}")
        if any(c.strip() for c in cells[n_cols:]):  # each cell would be read in its neighbour's column
            raise InputError(
                f"{len(cells)} fields, more than the {n_cols} the header names: decimal commas (129,56 for 129.56), "
                "or a column without its marker name?",
                path,
                f"line {i}",
            )
        frames.append(_float(cells[0], path, i, "Frame"))
        rows.append([_float(c, path, i, _col_name(cols, j), allow_empty=True) for j, c in enumerate(cells[:n_cols])])
    if not rows:
        raise InputError("no data rows after the header", path)
    frames_a = np.asarray(frames)
    bad = np.flatnonzero(~(np.diff(frames_a) > 0))
    if bad.size:
        raise InputError(
            f"frame numbers not increasing ({frames_a[bad[0]]:g} then {frames_a[bad[0] + 1]:g})",
            path,
            f"line {top + bad[0] + 7}",
        )
    if np.any(frames_a != np.round(frames_a)):
        k = int(np.flatnonzero(frames_a != np.round(frames_a))[0])
        raise InputError(f"frame number {frames_a[k]:g} is not a whole number", path, f"line {top + k + 6}")
    index = (frames_a - frames_a[0]).astype(np.int64)
    if index[-1] + 1 > 2 * len(rows) + 1000:  # not dropped rows: a corrupt frame number
        k = int(np.argmax(np.diff(index)))  # the largest jump
        raise InputError(
            f"frame numbers jump from {frames_a[k]:g} to {frames_a[k + 1]:g}: a corrupt frame number?",
            path,
            f"line {top + k + 7}",
        )
    a = np.full((int(index[-1]) + 1, len(rows[0])), np.nan)
    a[index] = np.asarray(rows) * scale  # a frame whose row is missing stays unseen (NaN)
    markers = {n: a[:, j : j + 3] for n, j in cols.items()}
    t = np.arange(a.shape[0]) / rate
    return MarkerData(
        rate=rate, markers=markers, source=str(path), t=t, up="+z", labelled_subjects=tuple(sorted(prefixes))
    )


def _col_name(cols: dict[str, int], j: int) -> str:
    if j == 0:
        return "Frame"
    if j == 1:
        return "Sub Frame"
    for n, k in cols.items():
        if k <= j < k + 3:
            return f"{n}.{'XYZ'[j - k]}"
    return str(j + 1)


# ---------------------------------------------------------------------- angles: MOT, CSV
_Q_ALIASES = {
    "q1": ("q1", "shoulder", "shoulder_flex", "q_shoulder", "r_shoulder_elev", "l_shoulder_elev", "demo_q1"),
    "q2": ("q2", "elbow", "elbow_flex", "q_elbow", "r_elbow_flex", "l_elbow_flex", "demo_q2"),
}
_TIME_ALIASES = ("time", "time_s")  # time_s: reachirl's own exports (reachirl.data.exports), read back
# OpenSim arm26's shoulder elevation is 0 with the arm hanging: q1 = r_shoulder_elev - 90° (reachirl.data.exports)
_Q1_OFFSET_RAD = {"r_shoulder_elev": -np.pi / 2, "l_shoulder_elev": -np.pi / 2}


def _angle_name(column: str) -> str:
    """A column's angle, without its unit suffix: ``demo_q1_deg`` and ``demo_q1_rad`` are ``demo_q1``."""
    return re.sub(r"_(deg|rad)$", "", column.strip().lower())


def _q1_offset(name: str) -> float:
    return _Q1_OFFSET_RAD.get(_angle_name(name), 0.0)


_SIDE_PREFIX = {"right": "r_", "left": "l_"}


def _find_q_columns(header: list[str], path: Path, line: int, side: str | None = None) -> tuple[int, int, int]:
    """The time, q1 and q2 columns. A file of both arms' angles (``r_shoulder_elev`` and ``l_shoulder_elev``, as
    OpenSim writes them) gives the ``side`` arm's (``"right"``/``"left"``); without a side it is refused."""
    low = [h.strip().lower() for h in header]
    time = next((k for k, h in enumerate(low) if h in _TIME_ALIASES), None)
    if time is None:
        if {"file", "subject"} <= set(low):  # preprocess's manifest given among the recordings
            raise InputError(
                f"a manifest (columns: {', '.join(header)}), not a recording: give it as --manifest, or give the "
                "folder that holds it",
                path,
            )
        raise InputError(f"no 'time' column (columns: {', '.join(header)})", path, f"line {line}")
    idx = []
    for q in ("q1", "q2"):
        found = [k for k, h in enumerate(low) if _angle_name(h) in _Q_ALIASES[q]]
        if not found:
            raise InputError(f"no '{q}' column (columns: {', '.join(header)})", path, f"line {line}")
        # one angle in two units (reachirl's exports: demo_q1_rad, demo_q1_deg) is one column; two angles
        # (r_shoulder_elev and l_shoulder_elev: both arms) are not, and the first would be taken silently
        bases = list(dict.fromkeys(_angle_name(low[k]) for k in found))
        if len(bases) > 1 and side in _SIDE_PREFIX:  # both arms' columns: the side's
            sided = [k for k in found if low[k].startswith(_SIDE_PREFIX[side])]
            if len({_angle_name(low[k]) for k in sided}) == 1:
                found, bases = sided, bases[:1]
        if len(bases) > 1:
            names = " and ".join(header[k].strip() for k in found)
            raise InputError(
                f"columns {names} all give {q}: which one is the reach is ambiguous (give the arm: --side or "
                "the manifest's side column, for a file of both arms' angles)",
                path,
                f"line {line}",
            )
        idx.append(found[0])
    return time, idx[0], idx[1]


def _columns_side(header: list[str], i1: int, i2: int) -> str | None:
    """The arm both angle columns name by their prefix (``l_shoulder_elev``, ``l_elbow_flex``: left), or None."""
    names = [header[k].strip().lower() for k in (i1, i2)]
    return next((s for s, pre in _SIDE_PREFIX.items() if all(n.startswith(pre) for n in names)), None)


def _angle_rows(lines: list[str], start: int, sep: str | None, n_min: int, path: Path, names: list[str]):
    rows = []
    for i, line in enumerate(lines[start:], start=start + 1):
        if not line.strip():
            continue
        cells = line.split(sep) if sep else line.split()
        if len(cells) < n_min:
            raise InputError(f"truncated row: {len(cells)} fields, expected {n_min}", path, f"line {i}")
        rows.append(
            [_float(c, path, i, names[j] if j < len(names) else str(j + 1)) for j, c in enumerate(cells[:n_min])]
        )
    if not rows:
        raise InputError("no data rows after the header", path)
    return np.asarray(rows)


def _radians(q_deg: np.ndarray, path: Path, declared: str) -> np.ndarray:
    """``q_deg`` ``(n, 2)`` (the file's q1, q2, in degrees as ``declared``) in radians; refused when every value
    lies within ±π, as a reach's angles do in radians and never in degrees (the arm straight and horizontal all
    along: no reach): radians declared, or taken by default, as degrees."""
    if np.all(np.abs(q_deg) <= np.pi):
        raise InputError(
            f"every q1 and q2 lies within ±{np.pi:.2f}, read as degrees ({declared}): that is a reach in radians, "
            "not in degrees; are radians declared as degrees?",
            path,
        )
    return np.radians(q_deg)


def read_mot(path: str | Path, side: str | None = None) -> AngleData:
    """Read an OpenSim MOT/STO motion file: ``inDegrees=yes|no`` in the header, then ``endheader``, then a
    ``time q1 q2 ...`` header row (tab- or space-separated). Column names: ``q1``/``q2`` (or
    ``shoulder``/``elbow``)
    in the model convention."""
    path = Path(path)
    lines = read_text(path).splitlines()
    end = next((k for k, ln in enumerate(lines) if ln.strip().lower() == "endheader"), None)
    if end is None:
        raise InputError("not a MOT file (no 'endheader' line)", path)
    in_degrees, said_degrees = True, False
    declared = n_columns = None
    for k, ln in enumerate(lines[:end]):
        key = ln.split("=", 1)[0].strip().lower()
        if key == "indegrees":
            val = ln.split("=", 1)[-1].strip().lower()
            if val not in ("yes", "no"):
                raise InputError(f"inDegrees must be yes or no, got {val!r}", path, f"line {k + 1}")
            in_degrees = said_degrees = val == "yes"
        elif key in ("nrows", "datarows") and "=" in ln:
            declared = _declared_rows(ln.split("=", 1)[1], ln.split("=", 1)[0].strip(), path, f"line {k + 1}")
        elif key in ("ncolumns", "datacolumns") and "=" in ln:
            n_columns = (_declared_rows(ln.split("=", 1)[1], ln.split("=", 1)[0].strip(), path, f"line {k + 1}"), k + 1)
    hdr_k = next((k for k in range(end + 1, len(lines)) if lines[k].strip()), None)
    if hdr_k is None:
        raise InputError("no column header after 'endheader'", path)
    sep = "\t" if "\t" in lines[hdr_k] else None
    header = lines[hdr_k].split(sep) if sep else lines[hdr_k].split()
    if n_columns is not None and n_columns[0] != len(header):
        raise InputError(
            f"the header says nColumns={n_columns[0]} but the column header names {len(header)}",
            path,
            f"line {n_columns[1]}",
        )
    it, i1, i2 = _find_q_columns(header, path, hdr_k + 1, side)
    a = _angle_rows(lines, hdr_k + 1, sep, max(it, i1, i2) + 1, path, header)
    last_line = max(k for k in range(hdr_k, len(lines)) if lines[k].strip()) + 1
    _check_row_count(a.shape[0], declared, "nRows", "rows", path, last_line)
    if in_degrees:
        q = _radians(a[:, [i1, i2]], path, "inDegrees=yes" if said_degrees else "no inDegrees line: OpenSim's default")
    else:
        q = a[:, [i1, i2]]
    q[:, 0] += _q1_offset(header[i1])
    return AngleData(t=a[:, it], q=q, source=str(path), side=_columns_side(header, i1, i2))


def read_angles_csv(path: str | Path, side: str | None = None) -> AngleData:
    """Read a ``time,q1,q2`` CSV (radians unless ``_deg`` suffixes or a ``# units: deg`` line say degrees)."""
    path = Path(path)
    lines = read_text(path).splitlines()
    units, declared_by = None, ""
    k = 0
    while k < len(lines) and (lines[k].lstrip().startswith("#") or not lines[k].strip()):
        m = re.match(r"#\s*units?\s*[:=]\s*(\w+)", lines[k].strip(), re.IGNORECASE)
        if m:
            u = m.group(1).lower()
            if u not in ("deg", "degree", "degrees", "rad", "radian", "radians"):
                raise InputError(f"unknown angle unit {m.group(1)!r}, expected deg or rad", path, f"line {k + 1}")
            units = "deg" if u.startswith("deg") else "rad"
            declared_by = f"line {k + 1}: {lines[k].strip()}"
        k += 1
    if k >= len(lines):
        raise InputError("no header row", path)
    header = next(csv.reader([lines[k]]))
    it, i1, i2 = _find_q_columns(header, path, k + 1, side)
    suffixes = {re.search(r"_(deg|rad)$", header[i].strip().lower()) for i in (i1, i2)}
    sfx = {m.group(1) for m in suffixes if m}
    if len(sfx) > 1:
        raise InputError("q1 and q2 columns declare different units", path, f"line {k + 1}")
    if sfx:
        col_unit = sfx.pop()
        if units is not None and units != col_unit:
            raise InputError(f"'# units: {units}' contradicts the column suffix _{col_unit}", path, f"line {k + 1}")
        units, declared_by = col_unit, f"the columns' suffix _{col_unit}"
    a = _angle_rows(lines, k + 1, ",", max(it, i1, i2) + 1, path, header)
    q = _radians(a[:, [i1, i2]], path, declared_by) if units == "deg" else a[:, [i1, i2]]
    q[:, 0] += _q1_offset(header[i1])
    return AngleData(t=a[:, it], q=q, source=str(path), side=_columns_side(header, i1, i2))


# ---------------------------------------------------------------------- dispatch
def detect_format(path: str | Path) -> str:
    """The format of ``path`` from its extension, and for ``.csv`` from its first line."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".trc":
        return "trc"
    if ext == ".c3d":
        return "c3d"
    if ext in (".mot", ".sto"):
        return "mot"
    if ext in (".csv", ".txt"):
        first = read_text(path).lstrip().split("\n", 1)[0]
        return "vicon-csv" if first.split(",")[0].strip() in VICON_BLOCKS else "csv"
    raise InputError(f"cannot tell the format from the extension {ext!r}; give --format {'|'.join(FORMATS)}", path)


def read_file(path: str | Path, fmt: str = "auto", side: str | None = None) -> MarkerData | AngleData:
    """Read any supported file: markers (:class:`MarkerData`) or joint angles (:class:`AngleData`; ``side``: the
    arm whose angles a file of both arms' holds is read)."""
    fmt = detect_format(path) if fmt in ("auto", None) else fmt
    readers = {
        "trc": read_trc,
        "c3d": read_c3d,
        "vicon-csv": read_vicon_csv,
        "mot": read_mot,
        "csv": read_angles_csv,
    }
    if fmt not in readers:
        raise InputError(f"unknown format {fmt!r}, expected one of auto, {', '.join(FORMATS)}", path)
    return readers[fmt](path, side) if fmt in ANGLE_FORMATS else readers[fmt](path)


def read_markers(path: str | Path, fmt: str = "auto") -> MarkerData:
    """Read a marker file; joint-angle files are refused with a clear message."""
    data = read_file(path, fmt)
    if not isinstance(data, MarkerData):
        raise InputError("holds joint angles, expected marker trajectories", path)
    return data


# ---------------------------------------------------------------------- subject info and manifest
@dataclass(frozen=True)
class SubjectInfo:
    """One subject's anthropometrics. Lengths in metres; ``None`` means "estimate from the markers".

    ``left_*`` lengths, when given, apply to the left arm instead of the plain ones.
    """

    subject: str
    sex: str
    height_m: float
    mass_kg: float
    upper_arm_m: float | None = None
    forearm_m: float | None = None
    hand_m: float | None = None
    left_upper_arm_m: float | None = None
    left_forearm_m: float | None = None

    def lengths(self, side: str) -> tuple[float | None, float | None, float | None]:
        """``(upper_arm_m, forearm_m, hand_m)`` for the ``side`` arm."""
        if side == "left":
            return (
                self.left_upper_arm_m or self.upper_arm_m,
                self.left_forearm_m or self.forearm_m,
                self.hand_m,
            )
        return self.upper_arm_m, self.forearm_m, self.hand_m


def _csv_dicts(
    path: Path, required: tuple[str, ...], optional: tuple[str, ...] = ()
) -> list[tuple[int, dict[str, str]]]:
    """The rows of the CSV at ``path`` as ``(line, {column: cell})``; ``required`` columns must be there, and a
    column read (``required`` or ``optional``) must not be named twice."""
    text = read_text(path)
    reader = csv.DictReader(io.StringIO(text))
    try:
        return _csv_rows(path, reader, required, optional)
    except csv.Error as e:  # e.g. a stray carriage return inside a field
        raise InputError(f"not a readable CSV ({e})", path, f"line {reader.line_num}") from None


def _csv_rows(
    path: Path, reader: csv.DictReader, required: tuple[str, ...], optional: tuple[str, ...] = ()
) -> list[tuple[int, dict[str, str]]]:
    fields_ = [f.strip() for f in (reader.fieldnames or [])]
    reader.fieldnames = fields_
    # a column read named twice: csv.DictReader would keep the last one and drop the others, silently (a column
    # the reader ignores, such as a spreadsheet's second "notes", may repeat)
    twice = sorted({f for f in (*required, *optional) if fields_.count(f) > 1})
    if twice:
        raise InputError(
            f"column(s) {', '.join(twice)} appear more than once in the header; which one holds the value is ambiguous",
            path,
            "line 1",
        )
    missing = [c for c in required if c not in fields_]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)} (has: {', '.join(fields_)})", path, "line 1")
    rows = []
    for row in reader:
        if None in row:
            raise InputError(f"row has more fields than the header ({len(fields_)})", path, f"line {reader.line_num}")
        if all(not (v or "").strip() for v in row.values()):
            continue
        if any(row.get(c) is None for c in required):
            raise InputError(
                f"truncated row: fewer fields than the header's {len(fields_)}",
                path,
                f"line {reader.line_num}",
            )
        rows.append((reader.line_num, {k: (v or "").strip() for k, v in row.items()}))
    if not rows:
        raise InputError("no data rows after the header", path)
    return rows


def _check_anthropometry(subject: str, column: str, value: float, path: Path, where: str) -> None:
    """A subject's ``column`` in its range, else an :class:`InputError` naming the subject and the unit the value
    was likely written in (a mass in grams, a height in cm), in the words ArmModel.from_anthropometrics says them."""
    problem = anthropometry_problem(column, value)
    if problem is not None:
        raise InputError(f"subject {subject}: {problem}", path, where)


def read_subject_info(path: str | Path) -> dict[str, SubjectInfo]:
    """Read subject anthropometrics, keyed by subject id.

    Two layouts are accepted:

    * reachirl's: ``subject,sex,height_m,mass_kg`` and optional ``upper_arm_m,forearm_m,hand_m`` (metres; an
      empty cell means "estimate from the markers");
    * UE-ADL's ``subjects.csv`` as shipped (``subject,age,sex,height_m,mass_kg,handedness_score,
      left_upper_arm_mm,left_lower_arm_mm,right_upper_arm_mm,right_lower_arm_mm,...``). Only sex, height and
      mass are taken: the examiners' tape lengths (acromion to olecranon, etc.) are not the joint-centre
      distances the planar model needs, so segment lengths come from the markers (on ADL001 the tape says 325
      mm for the upper arm, the joint centres 284 mm). :func:`reachirl.data.ue_adl.convert_subjects` writes
      them in reachirl's layout if you want to keep them.
    """
    path = Path(path)
    rows = _csv_dicts(path, ("subject", "sex", "height_m", "mass_kg"), ("upper_arm_m", "forearm_m", "hand_m"))
    out: dict[str, SubjectInfo] = {}
    for line, r in rows:
        where = f"line {line}"
        sid = r["subject"]
        if not sid:
            raise InputError("empty subject id", path, where)
        sex = sex_key(r["sex"])
        if sex is None:
            raise InputError(f"sex must be M or F (or male, female), got {r['sex']!r}", path, where)
        h = _float(r["height_m"], path, line, "height_m")
        m = _float(r["mass_kg"], path, line, "mass_kg")
        _check_anthropometry(sid, "height_m", h, path, where)
        _check_anthropometry(sid, "mass_kg", m, path, where)
        problem = bmi_problem(h, m)  # a mass in pounds, each column in its range
        if problem is not None:
            raise InputError(f"subject {sid}: {problem}", path, where)
        note = bmi_note(h, m)
        if note is not None:
            logging.getLogger(__name__).warning("%s: %s: subject %s: %s", path, where, sid, note)
        lengths = {}
        for c in SEGMENT_COLUMNS:
            if r.get(c, ""):
                lengths[c] = _float(r[c], path, line, c)
                _check_anthropometry(sid, c, lengths[c], path, where)
        if sid in out:
            raise InputError(f"subject {sid!r} appears twice", path, where)
        out[sid] = SubjectInfo(subject=sid, sex=sex, height_m=h, mass_kg=m, **lengths)
    return out


@dataclass(frozen=True)
class ManifestEntry:
    file: Path
    subject: str
    posture: str
    side: str | None = None
    static: Path | None = None


def read_manifest(path: str | Path) -> list[ManifestEntry]:
    """Read a manifest CSV ``file,subject,posture`` (+ optional ``side``, ``static``); paths are relative to
    the
    manifest's folder."""
    path = Path(path)
    rows = _csv_dicts(path, ("file", "subject", "posture"), ("side", "static"))
    out = []
    seen: dict[str, int] = {}
    for line, r in rows:
        if not r["file"]:
            raise InputError("empty file name", path, f"line {line}")
        key = os.path.normpath(r["file"])
        if key in seen:  # the same recording twice would be one reach counted twice
            raise InputError(f"file {r['file']!r} is listed twice (lines {seen[key]} and {line})", path, f"line {line}")
        seen[key] = line
        side = r.get("side", "").lower() or None
        if side is not None and side not in ("right", "left", "r", "l"):
            raise InputError(f"side must be right or left, got {r['side']!r}", path, f"line {line}")
        if side in ("r", "l"):
            side = {"r": "right", "l": "left"}[side]
        static = r.get("static", "")
        out.append(
            ManifestEntry(
                file=path.parent / r["file"],
                subject=r["subject"] or Path(r["file"]).stem,
                posture=r["posture"] or "default",
                side=side,
                static=(path.parent / static) if static else None,
            )
        )
    return out
