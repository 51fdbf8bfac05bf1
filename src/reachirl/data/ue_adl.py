"""The UE-ADL forward-reach data (Vicon, 100 Hz; Mia Huang, San Francisco State University, 2021, MIT
licence): file naming, subject info, and the check of our planar angles against the authors' own joint angles.

Layout of a UE-ADL folder: ``<root>/subjects.csv`` and ``<root>/ADLxxx/ADLxxxF{R,L}{1..5}.csv`` (reaches),
``ADLxxx_static.csv`` (static calibration trial) and ``ADLxxxF{R,L}{n}angles.csv`` (the authors' angles, in
degrees, only between their onset and offset at a 3 % fingertip-velocity threshold). A one-subject sample
ships in :data:`SAMPLE_DIR` (ADL001).

The authors' angles are an *independent* reference, not ground truth for the planar model. Over the 8 subjects
× 2 arms × 5 reaches of the database (``examples/ue_adl_agreement.py --root ...``), with the defaults:

* **elbow**: r = 0.995 (worst trial 0.89), offset ours − theirs = +24° (+27° with ``distal="wrist"``), range
  57° against their 66°. Our q2 is the angle between the GTH→elbow-centre and elbow→fingertip (or wrist
  centre) lines; in 3-D that angle equals our planar q2 within ~1-2°, so the offset is not the projection. It
  comes from the segment definitions: GTH (greater tubercle) sits anterior-lateral on the humeral head, not at
  the glenohumeral centre, so the line GTH→elbow is tilted from the humerus' long axis, and the authors' elbow
  reads ~0° at full reach where our lines still make ~30°.
* **shoulder**: r = 0.99-1.00 for 7 subjects, offset −35° to −55°, not the −90° the conventions alone give (q1
  is from the horizontal, their flexion from the vertical): at rest, with the upper arm hanging (q1 ≈ −90°),
  their flexion already reads about −35°, because theirs is a thorax-relative Euler angle (after −15° to −30°
  of horizontal abduction) and not the gravity-referenced elevation of the planar model. Their range is also
  smaller (36° against 44°).
* **ADL009** faced −Y in the lab throughout (static and reaches), unlike the others (+Y). Our pipeline takes
  the forward axis from the fingertip's motion, so nothing changes for us; the authors' shoulder flexion of
  that subject has the opposite sign (r = −0.999 on both arms), which pulls the pooled shoulder r down to
  0.75.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_write_text, read_text
from .markersets import load_markerset
from .preprocess import PreprocessOptions, reconstruct_markers
from .readers import SubjectInfo, read_subject_info, read_vicon_csv

__all__ = [
    "SAMPLE_DIR",
    "AgreementRow",
    "agreement",
    "agreement_markdown",
    "convert_subjects",
    "find_static",
    "parse_trial_name",
    "reach_files",
    "read_authors_angles",
]

SAMPLE_DIR = Path(__file__).parent / "ue_adl_sample"
_NAME = re.compile(r"^(?P<subject>[A-Za-z]+\d+)F(?P<side>[RL])(?P<n>\d+)$")


def parse_trial_name(path: str | Path) -> tuple[str, str, str] | None:
    """``ADL001FR3.csv`` → ``("ADL001", "right", "FR3")``; ``None`` for a name not in UE-ADL's pattern."""
    m = _NAME.match(Path(path).stem)
    if not m:
        return None
    return m["subject"], "right" if m["side"] == "R" else "left", f"F{m['side']}{m['n']}"


def find_static(path: str | Path, subject: str, pattern: str = "{subject}_static.csv") -> Path | None:
    """The static trial beside ``path`` (``<subject>_static.csv``; for a reach in another format, such as C3D, a
    static in that format is taken first: ``<subject>_static.c3d``), or ``None``."""
    p = Path(path).parent / pattern.format(subject=subject)
    same_format = p.with_suffix(Path(path).suffix)
    return next((c for c in (same_format, p) if c.is_file()), None)


def reach_files(root: str | Path) -> list[Path]:
    """Every reach file (``*F[RL]<n>.csv``) under ``root``, sorted."""
    root = Path(root)
    if not root.is_dir():
        raise InputError("not a folder", root)
    return sorted(p for p in root.rglob("*.csv") if parse_trial_name(p))


def convert_subjects(src: str | Path, dst: str | Path, with_lengths: bool = False) -> Path:
    """Write UE-ADL's ``subjects.csv`` as a reachirl subject-info CSV (``subject,sex,height_m,mass_kg``).

    With ``with_lengths``, the examiners' tape lengths go to ``upper_arm_m`` and ``forearm_m`` (right arm; the
    mean of both arms would hide asymmetry, so left lengths are not kept). They are not joint-centre
    distances: by default the lengths come from the markers instead. ``reachirl preprocess --subject-info``
    also reads UE-ADL's file directly (sex, height and mass only).
    """
    src = Path(src)
    info = read_subject_info(src)
    raw = {}
    if with_lengths:
        reader = csv.DictReader(read_text(src).splitlines())
        for row in reader:
            raw[row["subject"].strip()] = row
    lines = ["subject,sex,height_m,mass_kg" + (",upper_arm_m,forearm_m" if with_lengths else "")]
    for sid, s in info.items():
        line = f"{sid},{s.sex},{s.height_m:g},{s.mass_kg:g}"
        if with_lengths:
            try:
                ua = float(raw[sid]["right_upper_arm_mm"]) / 1000
                fa = float(raw[sid]["right_lower_arm_mm"]) / 1000
            except (KeyError, ValueError):
                raise InputError(f"subject {sid}: no right_upper_arm_mm/right_lower_arm_mm", src) from None
            line += f",{ua:g},{fa:g}"
        lines.append(line)
    atomic_write_text(dst, "\n".join(lines) + "\n")
    return Path(dst)


def read_authors_angles(path: str | Path) -> dict[str, np.ndarray]:
    """The authors' angles file: ``{"finger_velocity", "shoulder_flexion", "elbow_flexion", ...}`` in
    degrees."""
    path = Path(path)
    lines = [ln for ln in read_text(path).splitlines() if ln.strip()]
    header = [h.strip() for h in lines[0].split(",")]
    keys = {
        "Finger Velocity": "finger_velocity",
        "Shoulder flexion-extension": "shoulder_flexion",
        "elbow flexion-extension": "elbow_flexion",
        "Shoulder horiz abd-adduction": "shoulder_horizontal",
        "Shoulder internal-external rotation": "shoulder_rotation",
    }
    missing = [k for k in keys if k not in header]
    if missing:
        raise InputError(f"missing column(s) {missing}", path, "line 1")
    if len(lines) < 5:
        raise InputError("fewer than 4 data rows", path)
    rows = []
    for i, ln in enumerate(lines[1:], start=2):
        cells = ln.split(",")
        if len(cells) < len(header):
            raise InputError(f"truncated row: {len(cells)} fields, expected {len(header)}", path, f"line {i}")
        try:
            rows.append([float(c) for c in cells[: len(header)]])
        except ValueError:
            raise InputError("non-numeric cell", path, f"line {i}") from None
    a = np.asarray(rows)
    return {v: a[:, header.index(k)] for k, v in keys.items()}


@dataclass(frozen=True)
class AgreementRow:
    """Agreement of our angles with the authors' on one group of trials (degrees; ``r`` is Pearson's).

    ``*_r`` is the mean over trials of the per-trial correlation of the time-normalised curves, ``*_r_min``
    the worst trial, ``*_offset_deg`` the mean of (ours − theirs) and ``*_range_deg`` the mean per-trial range
    of ours and theirs.
    """

    subject: str
    side: str
    n_trials: int
    shoulder_r: float
    shoulder_r_min: float
    shoulder_offset_deg: float
    elbow_r: float
    elbow_r_min: float
    elbow_offset_deg: float
    shoulder_range_deg: tuple[float, float]
    elbow_range_deg: tuple[float, float]


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    if np.std(a) < 1e-12 or np.std(b) < 1e-12:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def _normalise(x: np.ndarray, n: int) -> np.ndarray:
    return np.interp(np.linspace(0, 1, n), np.linspace(0, 1, x.shape[0]), x)


def agreement(
    root: str | Path = SAMPLE_DIR,
    options: PreprocessOptions | None = None,
    n_points: int = 101,
    subjects_csv: str | Path | None = None,
) -> tuple[list[AgreementRow], list[dict]]:
    """Run every reach under ``root`` through the pipeline and compare with the authors' angles.

    Each reach is cut at *our* onset/offset with the authors' 3 % threshold (``options.onset_threshold`` is
    replaced by 0.03), and both curves are time-normalised to ``n_points``. Returns the rows per subject and
    side, plus an ``"ALL"`` row per side and overall, and the per-trial records.
    """
    root = Path(root)
    options = replace(options or PreprocessOptions(), onset_threshold=0.03)
    subjects_csv = Path(subjects_csv) if subjects_csv else root / "subjects.csv"
    info: dict[str, SubjectInfo] = read_subject_info(subjects_csv) if subjects_csv.is_file() else {}
    mset = load_markerset("ue-adl")
    statics: dict[Path, object] = {}
    per_trial = []
    for f in reach_files(root):
        subject, side, tid = parse_trial_name(f)  # type: ignore[misc]
        ang_path = f.with_name(f"{f.stem}angles.csv")
        static_path = find_static(f, subject)
        if not ang_path.is_file() or static_path is None:
            continue
        if static_path not in statics:
            statics[static_path] = read_vicon_csv(static_path)
        rec = reconstruct_markers(
            read_vicon_csv(f),
            mset,
            side=side,
            static=statics[static_path],
            subject_info=info.get(subject),
            options=options,
        )
        theirs = read_authors_angles(ang_path)
        sl = slice(rec.onset, rec.offset + 1)
        ours = np.degrees(rec.q[sl])
        s_o, e_o = _normalise(ours[:, 0], n_points), _normalise(ours[:, 1], n_points)
        s_t, e_t = (
            _normalise(theirs["shoulder_flexion"], n_points),
            _normalise(theirs["elbow_flexion"], n_points),
        )
        per_trial.append(
            {
                "subject": subject,
                "side": side,
                "trial": tid,
                "frames_ours": int(rec.offset - rec.onset + 1),
                "frames_theirs": int(theirs["elbow_flexion"].shape[0]),
                "shoulder_r": _corr(s_o, s_t),
                "shoulder_offset_deg": float(np.mean(s_o - s_t)),
                "elbow_r": _corr(e_o, e_t),
                "elbow_offset_deg": float(np.mean(e_o - e_t)),
                "shoulder_range_deg": (float(np.ptp(s_o)), float(np.ptp(s_t))),
                "elbow_range_deg": (float(np.ptp(e_o)), float(np.ptp(e_t))),
                "forearm_mm": rec.lengths.get("forearm", math.nan) * 1000,
                "forearm_sd_mm": rec.lengths.get("forearm_sd", math.nan) * 1000,
            }
        )
    if not per_trial:
        raise InputError("no reach with its angles and static files found", root)

    def row(subject: str, side: str, recs: list[dict]) -> AgreementRow:
        def m(k):
            return float(np.nanmean([r[k] for r in recs]))

        def mn(k):
            return float(np.nanmin([r[k] for r in recs]))

        def rng(k):
            return (float(np.mean([r[k][0] for r in recs])), float(np.mean([r[k][1] for r in recs])))

        return AgreementRow(
            subject,
            side,
            len(recs),
            m("shoulder_r"),
            mn("shoulder_r"),
            m("shoulder_offset_deg"),
            m("elbow_r"),
            mn("elbow_r"),
            m("elbow_offset_deg"),
            rng("shoulder_range_deg"),
            rng("elbow_range_deg"),
        )

    rows = []
    groups = sorted({(r["subject"], r["side"]) for r in per_trial}, key=lambda g: (g[0], g[1] != "right"))
    for subject, side in groups:
        rows.append(row(subject, side, [r for r in per_trial if (r["subject"], r["side"]) == (subject, side)]))
    for side in ("right", "left"):
        recs = [r for r in per_trial if r["side"] == side]
        if recs:
            rows.append(row("ALL", side, recs))
    rows.append(row("ALL", "both", per_trial))
    return rows, per_trial


def agreement_markdown(rows: list[AgreementRow]) -> str:
    """The agreement table in Markdown (degrees)."""
    out = [
        "| subject | side | trials | shoulder r (min) | shoulder offset ° | shoulder range ours/theirs ° "
        "| elbow r (min) | elbow offset ° | elbow range ours/theirs ° |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(
            f"| {r.subject} | {r.side} | {r.n_trials} | {r.shoulder_r:.3f} ({r.shoulder_r_min:.3f}) | "
            f"{r.shoulder_offset_deg:+.1f} | {r.shoulder_range_deg[0]:.0f}/{r.shoulder_range_deg[1]:.0f} | "
            f"{r.elbow_r:.3f} ({r.elbow_r_min:.3f}) | {r.elbow_offset_deg:+.1f} | "
            f"{r.elbow_range_deg[0]:.0f}/{r.elbow_range_deg[1]:.0f} |"
        )
    return "\n".join(out)
