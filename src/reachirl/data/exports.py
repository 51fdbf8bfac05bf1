"""Trajectories to files a researcher can take away: one CSV and one OpenSim motion file (MOT) per trial.

* ``<name>.csv`` — comma separated, one row per sample, a ``time_s`` column, then for each of ``demo`` (the
  recorded reach) and ``pred`` (the DOC prediction) when present: ``q1_rad q2_rad qd1_rad_s qd2_rad_s
  tau1_Nm tau2_Nm`` in SI, then the same angles and velocities in degrees (``q1_deg``, ``qd1_deg_s`` ...).
  Torques of the DOC act on an interval: ``tau`` at row ``k`` is the torque on ``[t_k, t_k+1)`` and the last
  row leaves it empty (:data:`CSV_COLUMNS` lists every column). An empty field is a missing value.
* ``<name>.mot`` — OpenSim's motion format (``inDegrees=yes``, ``endheader``, then ``time`` and two
  coordinates) of the predicted angles (or, with no prediction, the recorded ones), under the coordinate
  names of OpenSim's ``arm26`` model: ``r_shoulder_elev = q1 + 90°`` (0 with the arm hanging, positive
  forward) and ``r_elbow_flex = q2`` (``l_`` for a left arm). :func:`reachirl.data.readers.read_mot` reads it
  back into reachirl's convention.
* ``index.csv`` — which file holds which trial: ``id,file,set,converged``. A prediction whose DOC did not
  converge is no prediction: it is left out (no ``.csv``, no ``.mot``) and listed with an empty ``file`` and
  ``converged`` ``false``; ``converged`` is ``true`` for the others, and empty in an export without predictions.
  An export of an earlier version, whose index has no ``converged`` column, is recognised as one all the same.

Trial ids contain slashes (``subject/posture/side/trial``); :func:`safe_name` turns them into file names.
Every file is written atomically.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io import atomic_write_text, csv_column, remove_temporaries
from .writers import write_mot

__all__ = [
    "CSV_COLUMNS",
    "MOT_COLUMNS",
    "TrajectoryExport",
    "earlier_names",
    "export_trajectories",
    "listed_names",
    "opensim_coordinates",
    "remove_export",
    "safe_name",
    "trajectory_csv",
]

_SI = ("q1_rad", "q2_rad", "qd1_rad_s", "qd2_rad_s", "tau1_Nm", "tau2_Nm")
_DEG = ("q1_deg", "q2_deg", "qd1_deg_s", "qd2_deg_s")
CSV_COLUMNS = ("time_s", *(f"{w}_{c}" for w in ("demo", "pred") for c in (*_SI, *_DEG)))
"""Every column of a trajectory CSV, in order, when it holds both the demonstration and the prediction."""
MOT_COLUMNS = {"right": ("r_shoulder_elev", "r_elbow_flex"), "left": ("l_shoulder_elev", "l_elbow_flex")}
SHOULDER_OFFSET_DEG = 90.0  # r_shoulder_elev = q1 + 90°


@dataclass(frozen=True)
class TrajectoryExport:
    """One trial to export. ``demo`` and ``pred`` map ``"q"``, ``"qd"`` (``(n, 2)``, rad, rad/s) and optionally
    ``"tau"`` (``(n, 2)`` or ``(n - 1, 2)`` per interval, N·m) on the samples ``t (n,)`` (s). ``converged``:
    whether the DOC of ``pred`` converged (``None``: no prediction); one that did not is listed in the index and
    written to no file."""

    id: str
    t: np.ndarray
    demo: Mapping[str, np.ndarray] | None = None
    pred: Mapping[str, np.ndarray] | None = None
    side: str = "right"
    set: str = ""
    converged: bool | None = None


def safe_name(trial_id: str) -> str:
    """A portable file name for a trial id: ``S01/P2/right/T03`` → ``S01_P2_right_T03``.

    Characters other than letters, digits, ``.``, ``-`` and ``_`` become ``-``; no leading dot.
    """
    parts = [re.sub(r"[^A-Za-z0-9._-]", "-", p) for p in str(trial_id).split("/")]
    name = "_".join(p for p in parts if p).lstrip(".")
    return name or "trial"


def opensim_coordinates(q: np.ndarray, side: str = "right") -> tuple[tuple[str, str], np.ndarray]:
    """``q (n, 2)`` in rad (reachirl's convention) → (arm26 coordinate names, angles in degrees)."""
    deg = np.rad2deg(np.asarray(q, dtype=float)).copy()
    deg[:, 0] += SHOULDER_OFFSET_DEG
    return MOT_COLUMNS[side], deg


def _columns(n: int, arrays: Mapping[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    q = np.asarray(arrays["q"], dtype=float)
    qd = np.asarray(arrays["qd"], dtype=float)
    tau = arrays.get("tau")
    tau = np.full((n, 2), np.nan) if tau is None else np.asarray(tau, dtype=float)
    if tau.shape == (n - 1, 2):  # per interval: nothing on the last knot
        tau = np.vstack([tau, np.full((1, 2), np.nan)])
    for name, a in (("q", q), ("qd", qd), ("tau", tau)):
        if a.shape != (n, 2):
            raise ValueError(f"{prefix} {name} has shape {a.shape}, expected ({n}, 2)")
    si = (q[:, 0], q[:, 1], qd[:, 0], qd[:, 1], tau[:, 0], tau[:, 1])
    deg = (*np.rad2deg(q).T, *np.rad2deg(qd).T)
    for name, col in zip((*_SI, *_DEG), (*si, *deg), strict=True):
        out[f"{prefix}_{name}"] = col
    return out


def trajectory_csv(t: np.ndarray, demo: Mapping | None = None, pred: Mapping | None = None) -> str:
    """The CSV text of one trial (see the module docstring); ``demo`` and/or ``pred`` must be given."""
    t = np.asarray(t, dtype=float).reshape(-1)
    if demo is None and pred is None:
        raise ValueError("nothing to export: give demo and/or pred")
    cols = {"time_s": t}
    for prefix, arrays in (("demo", demo), ("pred", pred)):
        if arrays is not None:
            cols |= _columns(t.size, arrays, prefix)
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(cols)
    return buf.getvalue() + _number_lines(np.column_stack(list(cols.values())))


def _number_lines(data: np.ndarray) -> str:
    """The rows of ``data (n, k)``, k > 1, as CSV lines: each number ``%.9g``, a non-finite one an empty field
    (what ``csv.writer`` writes for those strings); the finite rows formatted in one operation."""
    n, k = data.shape
    if n == 0:
        return ""
    finite = np.isfinite(data)
    whole = finite.all(axis=1)
    row = ",".join(["%.9g"] * k)
    text = "\n".join([row] * n) % tuple(np.where(finite, data, 0.0).ravel().tolist())
    if whole.all():
        return text + "\n"
    lines = text.split("\n")
    for i in np.flatnonzero(~whole):
        lines[i] = ",".join(f"{v:.9g}" if np.isfinite(v) else "" for v in data[i].tolist())
    return "\n".join(lines) + "\n"


INDEX_COLUMNS = ("id", "file", "set", "converged")
"""The header of an export's ``index.csv``."""
EARLIER_INDEX_COLUMNS = ("id", "file", "set")
"""The header of an ``index.csv`` written before the ``converged`` column: still an export's."""


def is_export(folder: str | Path) -> bool:
    """Whether ``folder`` holds an export of :func:`export_trajectories` (its ``index.csv`` has
    :data:`INDEX_COLUMNS`, or :data:`EARLIER_INDEX_COLUMNS`)."""
    try:
        with open(Path(folder) / "index.csv", encoding="utf-8") as fh:
            return fh.readline().strip() in {",".join(INDEX_COLUMNS), ",".join(EARLIER_INDEX_COLUMNS)}
    except (OSError, UnicodeDecodeError):
        return False


def listed_names(out: str | Path) -> set[str]:
    """The file names (no suffix) an earlier export's ``index.csv`` in ``out`` lists: names this module made,
    never a path."""
    out = Path(out)
    return {n for n in csv_column(out / "index.csv", "file") if n == safe_name(n) and n != "index"}


def _remove(out: Path, names) -> None:
    for name in names:
        for suffix in (".csv", ".mot"):
            (out / f"{name}{suffix}").unlink(missing_ok=True)


def export_trajectories(out_dir: str | Path, items: Iterable[TrajectoryExport], mot: bool = True) -> Path:
    """Write ``<safe id>.csv`` (and ``.mot``) per item and ``index.csv`` under ``out_dir``; returns the index.

    An item whose prediction did not converge (``converged=False``) gets no file: the index lists it with an empty
    ``file`` and ``converged`` ``false`` (see the module docstring). Two ids that map to one file name get ``-2``,
    ``-3`` ... appended. The files an earlier export listed in ``out_dir``'s ``index.csv`` and this one does not
    write (a failed prediction's among them) are removed, so that the folder holds what its index says (a user's
    other files stay), and so are the temporaries a killed export left. The earlier ``index.csv``
    goes first and the new one is written last, so an interrupted export leaves a folder without an index, never
    an index over a mix of two exports; it leaves its :data:`PENDING` list instead, of the earlier export's files
    and those it wrote, which the next export removes where it does not write them again. The index and the
    folder are synced to the disk; the trajectory files, derived and many, are not one by one
    (:func:`reachirl.io.atomic_path`, ``durable=False``): a crash of the system itself (not of reachirl) soon after
    an export may leave one of them short; exporting again rewrites it.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    earlier = earlier_names(out)
    pending = out / PENDING
    atomic_write_text(pending, "".join(f"{n}\n" for n in sorted(earlier)), durable=False)  # before the index goes
    (out / "index.csv").unlink(missing_ok=True)
    remove_temporaries(out)  # what the atomic writes of a killed export left
    used: set[str] = set()
    index = [INDEX_COLUMNS]
    with open(pending, "a", encoding="utf-8") as listed:  # each name before its files: an interrupt from then on
        # leaves it to the next export to remove
        for it in items:
            if it.converged is False:  # a failed DOC is no prediction: listed, not written (nor its name taken)
                index.append((it.id, "", it.set, "false"))
                continue
            base = safe_name(it.id)
            name, k = base, 1
            while name in used:
                k += 1
                name = f"{base}-{k}"
            used.add(name)
            listed.write(f"{name}\n")
            listed.flush()
            # not synced one by one (a millisecond each, over a second for a run's ~1,200): see the docstring
            atomic_write_text(out / f"{name}.csv", trajectory_csv(it.t, it.demo, it.pred), durable=False)
            if mot:
                src = it.pred if it.pred is not None else it.demo
                cols, deg = opensim_coordinates(src["q"], it.side)
                write_mot(out / f"{name}.mot", it.t, deg, columns=cols, durable=False)
            index.append((it.id, name, it.set, "" if it.converged is None else "true"))
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(index)
    atomic_write_text(out / "index.csv", buf.getvalue())
    _remove(out, earlier - used)
    pending.unlink(missing_ok=True)
    return out / "index.csv"


PENDING = ".export-pending"
"""An export's hidden list, while it writes, of the files the earlier export listed and those it wrote so far:
an export interrupted after removing the earlier index leaves it, and the next export removes what it names and
does not write again (as it removes an earlier index's files)."""


def earlier_names(out: str | Path) -> set[str]:
    """The files (no suffix) an earlier export in ``out`` wrote: those its ``index.csv`` lists, and those an
    interrupted export's :data:`PENDING` list names; what a new export removes where it does not write them."""
    return listed_names(out) | _pending_names(Path(out))


def _pending_names(out: Path) -> set[str]:
    """The names an interrupted export's :data:`PENDING` list holds (names this module made, never a path)."""
    try:
        lines = (out / PENDING).read_text(encoding="utf-8").split()
    except (OSError, UnicodeDecodeError):
        return set()
    return {n for n in lines if n == safe_name(n) and n != "index"}


def remove_export(out_dir: str | Path) -> None:
    """Remove what :func:`export_trajectories` wrote into ``out_dir``: the files its ``index.csv`` lists, the
    index, the temporaries of a killed export, and the folder once empty; a user's other files stay."""
    out = Path(out_dir)
    _remove(out, earlier_names(out))
    (out / "index.csv").unlink(missing_ok=True)
    (out / PENDING).unlink(missing_ok=True)
    remove_temporaries(out)
    if not any(out.iterdir()):
        out.rmdir()
