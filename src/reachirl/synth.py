"""Virtual subjects on Berret et al. 2011's protocol, with known (ground-truth) time-varying cost weights.

A virtual subject is an :class:`~reachirl.arm.ArmModel` drawn from Berret's population. Each of its reaches
is the DOC solution (:func:`reachirl.solve_doc`) of the reach from one of Berret's five initial postures to
a vertical bar, under the subject's true weights jittered for that trial. The reaches are then "recorded":
markers at 100 Hz placed by the arm's kinematics, in a lab frame, with noise and rest before and after, and
written as TRC, C3D or MOT files with a manifest, a subject-info CSV and ``truth.json``.

**Population** (Berret et al. 2011, PLoS Comput Biol 7(10) e1002183): height 1.76 ± 0.06 m, mass 69.9 ± 8.4 kg,
16 of 20 male. Each subject is male with probability 0.8; height and mass are drawn around sex-specific means
chosen so that the mixture has Berret's mean (men +2 cm / +2.1 kg, women −8 cm / −8.4 kg, within-sex SD 5 cm /
7.5 kg, clipped at ±2.5 SD). Segment lengths are Dumas 2007's mean lengths scaled by height over the table's
reference stature, each times ``exp(N(0, 0.03))`` (about 3 % individual variation).

**Initial postures.** Berret gives them as ``[elbow; shoulder]`` in degrees: P1 [0; 90], P2 [−90; 90], P3
[−120; 120], P4 [−90; 30], P5 [−80; 140]. We read both angles as measured from the *forward horizontal* in a
frame seen from the subject's other side (clockwise in reachirl's x-forward/y-up frame), so ``q1 =
−shoulder`` and ``q2 = −elbow``: a negative Berret elbow angle is then flexion, and 90° at the shoulder is
the arm hanging down. This is the only simple reading under which all five are sensible starts for a reach
to a bar at 85–95 % of arm length (see :func:`berret_to_model` and ``docs/figures/berret_postures.png``):

* P1 arm hanging straight down; P2 upper arm down, forearm horizontal forward (the classic 90° elbow); P3
  upper arm 30° behind the vertical, forearm horizontal forward; P4 upper arm 30° below the horizontal
  forward, forearm 60° above it; P5 upper arm 50° behind the vertical, forearm pointing down-forward (hand
  beside the hip).
* Every fingertip starts short of the bar (x ≤ 0.5 m against a bar at ≥ 0.6 m).
* The other common reading (shoulder from the downward vertical) makes P1 a straight horizontal
  arm with the fingertip at x = L, beyond the bar (physically through it), which cannot be a start posture.
* It matches the seed paper's remark that P3 and P5 need "more activity in joint space" for a small
  fingertip motion: they are the two postures with the upper arm behind the trunk.

**Ground-truth weights** (8 windows): ``ω_{s,j} = RELATIVE_IMPORTANCE[s, j] / FEATURE_SCALE[j]``.
``FEATURE_SCALE`` is the typical size of each feature per window (its mean over windows and postures on
reference reaches; see :func:`typical_feature_scales`), so ``RELATIVE_IMPORTANCE`` says how much each cost
matters in each window on a common footing. In the spirit of the seed's findings, joint acceleration
dominates the first and the last windows and energy, torque change, torque and geodesic matter mid-movement;
the deceleration phase is smoother than the acceleration phase, which moves the peak speed earlier (Berret:
0.42 of the movement).

**Trial-to-trial variability:** each weight times ``exp(N(0, 0.2))``, initial joint angles + ``N(0, 3°)``,
duration from Berret's mean ± SD per posture. A trial whose DOC fails is redrawn (and counted).

**Recording:** the DOC horizon is ``duration / 0.92`` so the 5 %-of-peak-speed movement time matches
Berret's duration. Markers ``SHO`` (acromion, the shoulder centre), ``ELB`` (elbow), ``WRI`` (wrist centre:
the forearm length along segment 2) and ``FTP`` (fingertip) at 100 Hz, in a lab frame with Z up (as Vicon)
and the movement plane rotated 2–5° about Z; the shoulder sits at a per-subject lab position (± a few mm per
trial). Gaussian noise of 1–2 mm SD (per subject) on every coordinate; 0.3–0.6 s of still posture before and
after the reach. C3D files keep the lab axes (Z up); TRC files use OpenSim's axes (Y up:
``(X, Y, Z)_trc = (X, Z, −Y)_lab``), so each format follows its own standard. MOT files hold ``q1``, ``q2`` in
degrees (reachirl's convention) with 0.2° noise. The preprocess command reads the markers with
``--markers shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP``.

Randomness: every draw derives from ``numpy.random.SeedSequence(seed, spawn_key=...)`` keyed by (subject) or
(subject, posture, trial), so files do not depend on how trials are scheduled over processes.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import hashlib
import io
import json
import logging
import multiprocessing
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from .arm import _REFERENCE_HEIGHT_M, DUMAS_2007, ArmModel
from .data.trial import Trial, trial_from_knots
from .data.writers import write_c3d, write_mot, write_trc
from .doc import ReachingTask, solve_doc
from .features import FEATURES, feature_rates, window_index
from .io import atomic_write_json, atomic_write_text, cache_root, to_jsonable

__all__ = [
    "BERRET_DURATIONS_S",
    "BERRET_HUMAN_LIKENESS",
    "BERRET_POSTURES_DEG",
    "FEATURE_SCALE",
    "FORMATS",
    "GENERATOR_VERSION",
    "MARKERS",
    "POSTURES",
    "RELATIVE_IMPORTANCE",
    "SynthConfig",
    "SynthResult",
    "SynthSubject",
    "SynthTrial",
    "berret_to_model",
    "builtin_dataset_dir",
    "cache_root",
    "draw_subject",
    "format_human_likeness",
    "generate",
    "human_likeness",
    "nominal_weights",
    "simulate_trial",
    "typical_feature_scales",
]

log = logging.getLogger(__name__)

GENERATOR_VERSION = 5  # bump whenever the generated files change for the same seed
FORMATS = ("trc", "c3d", "mot")
POSTURES = ("P1", "P2", "P3", "P4", "P5")
# Berret 2011: initial postures as (elbow, shoulder) in degrees, and movement durations (mean, SD) in seconds.
BERRET_POSTURES_DEG: dict[str, tuple[float, float]] = {
    "P1": (0.0, 90.0),
    "P2": (-90.0, 90.0),
    "P3": (-120.0, 120.0),
    "P4": (-90.0, 30.0),
    "P5": (-80.0, 140.0),
}
BERRET_DURATIONS_S: dict[str, tuple[float, float]] = {
    "P1": (0.71, 0.08),
    "P2": (0.71, 0.08),
    "P3": (0.78, 0.08),
    "P4": (0.74, 0.09),
    "P5": (0.70, 0.07),
}
BERRET_HUMAN_LIKENESS = {"peak_to_mean_speed": 1.97, "time_to_peak": 0.42}
MARKERS = ("SHO", "ELB", "WRI", "FTP")
N_WINDOWS = 8
# 5 %-of-peak-speed movement time / DOC horizon, measured on the nominal reaches (see human_likeness).
MOVEMENT_FRACTION = 0.92

# Relative importance of each cost per window (rows: 8 equal windows of the reach; columns: FEATURES order).
RELATIVE_IMPORTANCE = np.array(
    [
        # cart_vel energy geodesic joint_acc torque_chg joint_vel torque
        [0.0, 0.000, 0.00, 1.000, 0.000, 0.0, 0.000],
        [0.0, 0.010, 0.00, 0.200, 0.005, 0.0, 0.005],
        [0.0, 0.025, 0.00, 0.050, 0.015, 0.0, 0.010],
        [0.0, 0.025, 0.15, 0.025, 0.015, 0.0, 0.010],
        [0.0, 0.025, 0.30, 0.025, 0.015, 0.0, 0.010],
        [0.0, 0.025, 0.60, 0.050, 0.015, 0.0, 0.010],
        [0.0, 0.010, 0.30, 0.200, 0.005, 0.0, 0.005],
        [0.0, 0.000, 0.00, 1.000, 0.000, 0.0, 0.000],
    ]
)
# Typical Φ per window and feature (SI units of FEATURE_UNITS), from typical_feature_scales() on the reference
# arm (1.76 m, 69.9 kg, male) under pure joint-acceleration weights, rounded to 2 significant digits.
FEATURE_SCALE = np.array([0.079, 0.45, 0.074, 7.0, 5.4, 0.48, 3.6])

_LOG_WEIGHT_SD = 0.2
_POSTURE_SD_DEG = 3.0
_MAX_RETRIES = 10


def nominal_weights() -> np.ndarray:
    """The nominal true weights, shape ``(8, 7)``: ``RELATIVE_IMPORTANCE / FEATURE_SCALE``."""
    return RELATIVE_IMPORTANCE / FEATURE_SCALE[None, :]


def berret_to_model(elbow_deg: float, shoulder_deg: float) -> np.ndarray:
    """Berret's ``[elbow; shoulder]`` posture (degrees) to reachirl's ``(q1, q2)`` in radians.

    Both of Berret's angles are read as measured from the forward horizontal, clockwise in reachirl's frame:
    ``q1 = −shoulder``, ``q2 = −elbow`` (so 90° at the shoulder hangs down and a negative elbow is flexion).
    """
    return np.deg2rad([-float(shoulder_deg), -float(elbow_deg)])


def posture_q(posture: str) -> np.ndarray:
    if posture not in BERRET_POSTURES_DEG:
        raise ValueError(f"unknown posture {posture!r}; expected one of {POSTURES}")
    return berret_to_model(*BERRET_POSTURES_DEG[posture])


# ---------------------------------------------------------------------- configuration and data
@dataclass(frozen=True)
class SynthConfig:
    """What to generate.

    ``target_fraction`` places the bar at that fraction of arm length (seed 95 %, Berret 85 %).
    """

    n_subjects: int = 2
    n_trials: int = 20
    seed: int = 0
    postures: tuple[str, ...] = POSTURES
    fmt: str = "trc"
    target_fraction: float = 0.95
    rate_hz: float = 100.0
    n_nodes: int = 100
    workers: int = 2

    def __post_init__(self) -> None:
        if int(self.n_subjects) < 1 or int(self.n_trials) < 1:
            raise ValueError(
                f"need at least 1 subject and 1 trial, got {self.n_subjects} and {self.n_trials}"
            )
        if int(self.seed) < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if self.fmt not in FORMATS:
            raise ValueError(f"format must be one of {FORMATS}, got {self.fmt!r}")
        for p in self.postures:
            posture_q(p)
        if not 0.5 <= self.target_fraction < 1.0:
            raise ValueError(f"target_fraction must be in [0.5, 1), got {self.target_fraction}")
        if self.rate_hz <= 0:
            raise ValueError(f"rate_hz must be > 0, got {self.rate_hz}")
        object.__setattr__(self, "postures", tuple(self.postures))


@dataclass(frozen=True)
class SynthSubject:
    """A virtual subject: anthropometrics and how its recordings sit in the lab."""

    subject: str
    sex: str
    height_m: float
    mass_kg: float
    upper_arm_m: float
    forearm_m: float
    hand_m: float
    lab_origin_mm: tuple[float, float, float]  # the shoulder's mean lab position
    plane_rotation_deg: float  # movement plane's rotation about the lab's vertical Z
    noise_mm: float  # marker noise SD

    @property
    def arm(self) -> ArmModel:
        return ArmModel.from_anthropometrics(
            self.height_m, self.mass_kg, self.sex, self.upper_arm_m, self.forearm_m, self.hand_m
        )


@dataclass(frozen=True)
class SynthTrial:
    """One virtual reach: its true weights and DOC solution, and its recording (lab frame, mm)."""

    subject: str
    posture: str
    trial_id: str
    weights: np.ndarray  # (8, 7) true (jittered) weights
    q0: np.ndarray  # (2,) rad
    target_x: float  # m
    horizon_s: float  # DOC horizon
    t_knots: np.ndarray  # (N+1,)
    q_knots: np.ndarray  # (N+1, 2)
    doc_retries: int
    doc_iterations: int
    onset_s: float  # reach start in the recording
    time: np.ndarray = field(repr=False)  # (n_frames,) recording time, s
    q_rec: np.ndarray = field(repr=False)  # (n_frames, 2) true joint angles at the frames, rad
    markers: dict = field(repr=False)  # name -> (n_frames, 3) mm, with noise
    angles_deg: np.ndarray = field(repr=False)  # (n_frames, 2) for MOT output, with noise

    def to_trial(self, arm: ArmModel) -> Trial:
        """The reach as a trial on the DOC's own knots (no recording, no noise)."""
        return trial_from_knots(arm, self.t_knots, self.q_knots, self.target_x, self.subject, self.posture,
                                self.trial_id)


@dataclass(frozen=True)
class SynthResult:
    out_dir: Path
    config: SynthConfig
    subjects: tuple[SynthSubject, ...]
    trials: tuple[SynthTrial, ...]
    doc_failures: int
    elapsed_s: float
    human_likeness: tuple[dict, ...] = ()


def _rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)))


def _clipped_normal(rng: np.random.Generator, mean: float, sd: float, k: float = 2.5) -> float:
    return float(mean + sd * np.clip(rng.standard_normal(), -k, k))


def draw_subject(seed: int, index: int) -> SynthSubject:
    """Subject ``index`` (0-based) of the population of ``seed``; ids are ``S01``, ``S02``, …"""
    rng = _rng(seed, 0, index)
    sex = "M" if rng.random() < 0.8 else "F"
    dh, dm = (0.02, 2.1) if sex == "M" else (-0.08, -8.4)
    height = _clipped_normal(rng, 1.76 + dh, 0.05)
    mass = _clipped_normal(rng, 69.9 + dm, 7.5)
    scale = height / _REFERENCE_HEIGHT_M[sex]
    lengths = [
        DUMAS_2007[sex][seg][3] * scale * float(np.exp(0.03 * rng.standard_normal()))
        for seg in ("upper_arm", "forearm", "hand")
    ]
    origin = (
        300.0 + 20 * rng.standard_normal(),
        600.0 + 20 * rng.standard_normal(),
        1050.0 + 30 * rng.standard_normal(),
    )
    rotation = float(rng.choice([-1.0, 1.0]) * rng.uniform(2.0, 5.0))
    noise = float(rng.uniform(1.0, 2.0))
    return SynthSubject(
        subject=f"S{index + 1:02d}",
        sex=sex,
        height_m=round(height, 4),
        mass_kg=round(mass, 2),
        upper_arm_m=round(lengths[0], 4),
        forearm_m=round(lengths[1], 4),
        hand_m=round(lengths[2], 4),
        lab_origin_mm=tuple(round(v, 2) for v in origin),
        plane_rotation_deg=round(rotation, 3),
        noise_mm=round(noise, 3),
    )


# ---------------------------------------------------------------------- one trial
def _draw_trial_inputs(rng: np.random.Generator, posture: str):
    w = nominal_weights() * np.exp(_LOG_WEIGHT_SD * rng.standard_normal((N_WINDOWS, len(FEATURES))))
    q0 = posture_q(posture) + np.deg2rad(_POSTURE_SD_DEG) * np.clip(rng.standard_normal(2), -2.5, 2.5)
    mean, sd = BERRET_DURATIONS_S[posture]
    duration = _clipped_normal(rng, mean, sd)
    return w, q0, duration


def simulate_trial(
    subject: SynthSubject,
    posture: str,
    trial_index: int,
    config: SynthConfig,
) -> SynthTrial:
    """Draw, solve and record one reach. Deterministic in ``(config.seed, subject, posture, trial_index)``.

    Each reach is solved cold (a neighbouring reach's multipliers are a poor warm start); a trial whose DOC
    fails is redrawn, and the failure counted in ``doc_retries``.
    """
    s_idx = int(subject.subject[1:]) - 1
    p_idx = POSTURES.index(posture)
    rng = _rng(config.seed, 1, s_idx, p_idx, trial_index)
    arm = subject.arm
    target = config.target_fraction * arm.length
    retries = 0
    while True:
        w, q0, duration = _draw_trial_inputs(rng, posture)
        probe = ReachingTask(arm, np.zeros(2), target, 1.0, n_nodes=config.n_nodes)
        q0 = np.clip(q0, probe.q_lower + np.deg2rad(1.0), probe.q_upper - np.deg2rad(1.0))
        q0[1] = max(q0[1], 0.0)  # a straight elbow at most
        task = ReachingTask(arm, q0, target, duration / MOVEMENT_FRACTION, n_nodes=config.n_nodes)
        sol = solve_doc(task, w)
        if sol.converged:
            break
        retries += 1
        log.warning(
            "DOC failed for %s %s trial %d (%s); redrawing",
            subject.subject,
            posture,
            trial_index + 1,
            sol.status,
        )
        if retries > _MAX_RETRIES:
            raise RuntimeError(
                f"DOC failed {retries} times for {subject.subject} {posture} trial {trial_index + 1}"
            )
    rec = _record(subject, arm, sol.t, sol.q, config, _rng(config.seed, 2, s_idx, p_idx, trial_index))
    return SynthTrial(
        subject=subject.subject,
        posture=posture,
        trial_id=f"T{trial_index + 1:02d}",
        weights=w,
        q0=q0,
        target_x=float(target),
        horizon_s=float(task.duration),
        t_knots=sol.t,
        q_knots=sol.q,
        doc_retries=retries,
        doc_iterations=int(sol.iterations),
        **rec,
    )


def _reach_spline(t_knots: np.ndarray, q_knots: np.ndarray) -> CubicSpline:
    """A C² joint path through the DOC knots, at rest at both ends."""
    return CubicSpline(t_knots, q_knots, axis=0, bc_type="clamped")


def _record(subject: SynthSubject, arm: ArmModel, t_knots, q_knots, config: SynthConfig, rng) -> dict:
    rest_before, rest_after = rng.uniform(0.3, 0.6, size=2)
    horizon = float(t_knots[-1])
    n_frames = int(np.floor((rest_before + horizon + rest_after) * config.rate_hz)) + 1
    t = np.arange(n_frames) / config.rate_hz
    s = np.clip(t - rest_before, 0.0, horizon)
    q = _reach_spline(t_knots, q_knots)(s)
    q12 = q[:, 0] + q[:, 1]
    elbow = arm.elbow(q)
    wrist = elbow + subject.forearm_m * np.column_stack([np.cos(q12), np.sin(q12)])
    planar = {"SHO": np.zeros_like(elbow), "ELB": elbow, "WRI": wrist, "FTP": arm.fk(q)}
    psi = np.deg2rad(subject.plane_rotation_deg)
    forward = np.array([np.cos(psi), np.sin(psi), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    origin = np.asarray(subject.lab_origin_mm) + 3.0 * rng.standard_normal(3)  # re-seated between trials
    markers = {}
    for name in MARKERS:
        p = planar[name] * 1000.0
        lab = origin + p[:, :1] * forward + p[:, 1:] * up
        markers[name] = lab + subject.noise_mm * rng.standard_normal(lab.shape)
    angles = np.rad2deg(q) + 0.2 * rng.standard_normal(q.shape)
    return {"onset_s": float(rest_before), "time": t, "q_rec": q, "markers": markers, "angles_deg": angles}


def to_opensim_axes(markers: dict) -> dict:
    """Lab (Vicon: X, Y horizontal, Z up) to OpenSim's TRC axes (Y up): ``(X, Y, Z) -> (X, Z, −Y)``."""
    return {n: np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]) for n, p in markers.items()}


def _simulate_group(subject: SynthSubject, posture: str, config: SynthConfig) -> list[SynthTrial]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    return [simulate_trial(subject, posture, k, config) for k in range(config.n_trials)]


def knot_trials(n_trials: int, posture: str = "P2", seed: int = 0, n_nodes: int = 100,
                subject_index: int = 0) -> list[Trial]:
    """``n_trials`` reaches of one virtual subject from ``posture``, in memory, on the DOC's own knots.

    The ground truth is :func:`nominal_weights` (each trial jittered around it). For benchmarks and tests that
    need no files; :func:`generate` records the same reaches as marker files.
    """
    config = SynthConfig(n_subjects=subject_index + 1, n_trials=n_trials, seed=seed, postures=(posture,),
                         n_nodes=n_nodes)
    subject = draw_subject(seed, subject_index)
    return [simulate_trial(subject, posture, i, config).to_trial(subject.arm) for i in range(n_trials)]


# ---------------------------------------------------------------------- human-likeness
def _reach_kinematics(arm: ArmModel, t_knots, q_knots, rate: float = 1000.0):
    spline = _reach_spline(t_knots, q_knots)
    t = np.arange(0.0, t_knots[-1], 1.0 / rate)
    q, qd = spline(t), spline(t, 1)
    p = arm.fk(q)
    v = arm.fingertip_speed(q, qd)
    return t, p, v


def reach_metrics(arm: ArmModel, t_knots: np.ndarray, q_knots: np.ndarray, threshold: float = 0.05) -> dict:
    """Berret's fingertip measures of one reach, between the crossings of ``threshold`` × peak speed.

    Returns ``duration_s``, ``peak_to_mean_speed``, ``time_to_peak`` (fraction of the movement),
    ``path_length_m``, ``peak_speed_m_s`` and ``straightness`` (path length / straight-line distance).
    """
    t, p, v = _reach_kinematics(arm, t_knots, q_knots)
    k_peak = int(np.argmax(v))
    above = v >= threshold * v[k_peak]
    on = k_peak - int(np.argmin(above[k_peak::-1])) + 1 if not above[: k_peak + 1].all() else 0
    off = k_peak + int(np.argmin(above[k_peak:])) - 1 if not above[k_peak:].all() else len(v) - 1
    dt = t[1] - t[0]
    seg = v[on : off + 1]
    path = float(np.trapezoid(seg, dx=dt))
    duration = (off - on) * dt
    chord = float(np.linalg.norm(p[off] - p[on]))
    return {
        "duration_s": duration,
        "peak_to_mean_speed": float(v[k_peak] / (path / duration)),
        "time_to_peak": (k_peak - on) * dt / duration,
        "path_length_m": path,
        "peak_speed_m_s": float(v[k_peak]),
        "straightness": path / chord if chord > 0 else float("nan"),
    }


def human_likeness(trials: Sequence[SynthTrial], subjects: Sequence[SynthSubject]) -> list[dict]:
    """Per-posture fingertip measures (mean and SD over trials) next to Berret's, plus an ``ALL`` row.

    Measures (:func:`reach_metrics`): movement duration, peak/mean speed (Berret 1.97), relative time to peak
    speed (Berret 0.42), path length and straightness. Berret's per-posture durations are in
    ``berret_duration_s``.
    """
    arms = {s.subject: s.arm for s in subjects}
    per: dict[str, list[dict]] = {}
    for tr in trials:
        per.setdefault(tr.posture, []).append(reach_metrics(arms[tr.subject], tr.t_knots, tr.q_knots))
    rows = []
    for posture in [*sorted(per), "ALL"]:
        ms = [m for p in sorted(per) for m in per[p]] if posture == "ALL" else per[posture]
        row: dict = {"posture": posture, "n": len(ms)}
        for key in ("duration_s", "peak_to_mean_speed", "time_to_peak", "path_length_m", "straightness"):
            vals = np.array([m[key] for m in ms])
            row[key] = float(vals.mean())
            row[key + "_sd"] = float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
        if posture in BERRET_DURATIONS_S:
            row["berret_duration_s"] = BERRET_DURATIONS_S[posture][0]
        else:
            row["berret_duration_s"] = float(np.mean([BERRET_DURATIONS_S[p][0] for p in sorted(per)]))
        row["berret_peak_to_mean_speed"] = BERRET_HUMAN_LIKENESS["peak_to_mean_speed"]
        row["berret_time_to_peak"] = BERRET_HUMAN_LIKENESS["time_to_peak"]
        rows.append(row)
    return rows


def format_human_likeness(rows: Sequence[dict]) -> tuple[list[str], list[list[str]]]:
    """Header and cells of the compact human-likeness table (``mean±SD``, Berret's value in brackets)."""
    header = [
        "posture",
        "n",
        "duration s [Berret]",
        "peak/mean [1.97]",
        "t_peak [0.42]",
        "path m",
        "path/chord",
    ]
    cells = []
    for r in rows:
        cells.append(
            [
                str(r["posture"]),
                str(r["n"]),
                f"{r['duration_s']:.3f}±{r['duration_s_sd']:.3f} [{r['berret_duration_s']:.2f}]",
                f"{r['peak_to_mean_speed']:.2f}±{r['peak_to_mean_speed_sd']:.2f}",
                f"{r['time_to_peak']:.3f}±{r['time_to_peak_sd']:.3f}",
                f"{r['path_length_m']:.3f}±{r['path_length_m_sd']:.3f}",
                f"{r['straightness']:.3f}±{r['straightness_sd']:.3f}",
            ]
        )
    return header, cells


# ---------------------------------------------------------------------- feature scales (documentation)
def typical_feature_scales(n_nodes: int = 100) -> np.ndarray:
    """Mean Φ per window and feature over the five postures' reaches of the reference arm under pure
    joint-acceleration weights (the origin of :data:`FEATURE_SCALE`), shape ``(7,)``.

    The torque change of the onset interval (the jump from the gravity torque at rest) is left out: a reach
    under pure joint-acceleration weights starts at full acceleration, so that one jump (×28 the rest of the
    reach) says how little this reference penalises it, not how large torque changes typically are."""
    arm = ArmModel.from_anthropometrics(1.76, 69.9, "M")
    w = np.zeros((N_WINDOWS, len(FEATURES)))
    w[:, FEATURES.index("joint_acceleration")] = 1.0
    out = []
    for p in POSTURES:
        task = ReachingTask(
            arm,
            posture_q(p),
            0.95 * arm.length,
            BERRET_DURATIONS_S[p][0] / MOVEMENT_FRACTION,
            n_nodes=n_nodes,
        )
        sol = solve_doc(task, w)
        rates = feature_rates(arm, sol.q, sol.qd, sol.tau, task.dt)
        rates[0, FEATURES.index("torque_change")] = 0.0
        phi = np.zeros((N_WINDOWS, len(FEATURES)))
        np.add.at(phi, window_index(task.n_nodes, N_WINDOWS), rates * task.dt)
        out.append(phi.mean(axis=0))
    return np.mean(out, axis=0)


# ---------------------------------------------------------------------- the whole data set
def _csv_text(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def _file_name(tr: SynthTrial, fmt: str) -> str:
    return f"{tr.subject}_{tr.posture}_{tr.trial_id}.{fmt}"


def _run_groups(subjects, config: SynthConfig) -> list[SynthTrial]:
    groups = [(s, p) for s in subjects for p in config.postures]
    workers = max(1, int(config.workers))
    if multiprocessing.current_process().daemon:
        workers = 1  # a daemonic process (e.g. a pool worker) may not have children
    if workers == 1 or len(groups) == 1:
        return [tr for s, p in groups for tr in _simulate_group(s, p, config)]
    # fork is cheap and works from unguarded scripts; never fork a process that runs other threads
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context(
        "fork" if "fork" in methods and threading.active_count() == 1 else "spawn"
    )
    ex = cf.ProcessPoolExecutor(max_workers=min(workers, len(groups)), mp_context=ctx, initializer=_worker_signals)
    try:
        futures = [ex.submit(_simulate_group, s, p, config) for s, p in groups]
        trials = [tr for f in futures for tr in f.result()]
    except BaseException:  # Ctrl-C, SIGTERM or an error: end the workers now, not after their groups
        procs = list(getattr(ex, "_processes", {}).values())  # no public API for the worker processes
        ex.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=2.0)
            if proc.is_alive():
                proc.kill()
        raise
    ex.shutdown(wait=True)
    return trials


def _worker_signals() -> None:
    """A generation worker: Ctrl-C is the parent's business (it ends the workers), SIGTERM ends it at once."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def generate(out_dir: str | Path, config: SynthConfig | None = None) -> SynthResult:
    """Generate the virtual data set of ``config`` into ``out_dir`` (created if needed).

    Writes one file per trial (``S01_P1_T01.trc`` …), ``manifest.csv`` (``file,subject,posture,side``),
    ``subjects.csv`` (``subject,sex,height_m,mass_kg,upper_arm_m,forearm_m,hand_m``), ``truth.json`` and
    ``human_likeness.csv``. The same config gives byte-identical files.
    """
    config = config or SynthConfig()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    subjects = tuple(draw_subject(config.seed, i) for i in range(config.n_subjects))
    trials = _run_groups(subjects, config)
    failures = sum(tr.doc_retries for tr in trials)
    manifest = []
    for tr in trials:
        name = _file_name(tr, config.fmt)
        if config.fmt == "trc":
            write_trc(out_dir / name, tr.time, to_opensim_axes(tr.markers), units="mm", rate=config.rate_hz)
        elif config.fmt == "c3d":
            write_c3d(out_dir / name, tr.time, tr.markers, units="mm", rate=config.rate_hz)
        else:
            write_mot(out_dir / name, tr.time, tr.angles_deg, columns=("q1", "q2"))
        manifest.append([name, tr.subject, tr.posture, "right"])
    atomic_write_text(out_dir / "manifest.csv", _csv_text(("file", "subject", "posture", "side"), manifest))
    atomic_write_text(
        out_dir / "subjects.csv",
        _csv_text(
            ("subject", "sex", "height_m", "mass_kg", "upper_arm_m", "forearm_m", "hand_m"),
            [
                [s.subject, s.sex, s.height_m, s.mass_kg, s.upper_arm_m, s.forearm_m, s.hand_m]
                for s in subjects
            ],
        ),
    )
    hl = human_likeness(trials, subjects)
    keys = list(hl[0])
    atomic_write_text(
        out_dir / "human_likeness.csv",
        _csv_text(keys, [[f"{r[k]:.6g}" if isinstance(r[k], float) else r[k] for k in keys] for r in hl]),
    )
    atomic_write_json(out_dir / "truth.json", _truth(config, subjects, trials, failures, hl))
    elapsed = time.perf_counter() - t0
    log.info(
        "generated %d trials of %d subjects in %.1f s (%d DOC failures redrawn)",
        len(trials),
        len(subjects),
        elapsed,
        failures,
    )
    return SynthResult(out_dir, config, subjects, tuple(trials), failures, elapsed, tuple(hl))


def _truth(config, subjects, trials, failures, hl) -> dict:
    subj = {}
    for s in subjects:
        d = asdict(s)
        d["arm"] = s.arm.to_dict()
        d["target_x_m"] = config.target_fraction * s.arm.length
        d["trials"] = {}
        subj[s.subject] = d
    for tr in trials:
        subj[tr.subject]["trials"].setdefault(tr.posture, []).append(
            {
                "trial_id": tr.trial_id,
                "file": _file_name(tr, config.fmt),
                "weights": tr.weights,
                "q0_deg": np.rad2deg(tr.q0),
                "horizon_s": tr.horizon_s,
                "onset_s": tr.onset_s,
                "offset_s": tr.onset_s + tr.horizon_s,
                "doc_retries": tr.doc_retries,
                "doc_iterations": tr.doc_iterations,
            }
        )
    return {
        "generator": "reachirl.synth",
        "version": GENERATOR_VERSION,
        "config": {k: v for k, v in asdict(config).items() if k != "workers"},
        "features": list(FEATURES),
        "n_windows": N_WINDOWS,
        "markers": {"shoulder": "SHO", "elbow": "ELB", "wrist": "WRI", "fingertip": "FTP"},
        "units": {
            "markers": "mm",
            "axes": "C3D: lab, Z up; TRC: OpenSim, Y up ((X, Z, -Y) of the lab); movement plane rotated "
            "about the vertical",
            "mot": "degrees, q1 q2 in reachirl's convention",
            "weights": "SI (features are raw SI quantities)",
        },
        "postures": {
            p: {
                "berret_elbow_deg": e,
                "berret_shoulder_deg": sh,
                "q_deg": np.rad2deg(posture_q(p)),
                "berret_duration_s": BERRET_DURATIONS_S[p],
            }
            for p, (e, sh) in BERRET_POSTURES_DEG.items()
        },
        "posture_convention": "q1 = -shoulder, q2 = -elbow (Berret's angles from the forward horizontal, "
        "clockwise in reachirl's x-forward/y-up frame)",
        "truth": {
            "definition": "weights = relative_importance / feature_scale, per window (rows) and feature "
            "(columns)",
            "relative_importance": RELATIVE_IMPORTANCE,
            "feature_scale": FEATURE_SCALE,
            "nominal_weights": nominal_weights(),
            "jitter": {
                "log_weight_sd": _LOG_WEIGHT_SD,
                "posture_sd_deg": _POSTURE_SD_DEG,
                "duration": "Berret's SD per posture",
                "movement_fraction": MOVEMENT_FRACTION,
            },
        },
        "subjects": subj,
        "doc_failures": failures,
        "human_likeness": hl,
    }


# ---------------------------------------------------------------------- the built-in data set (cached)
def _builtin_config(seed: int) -> SynthConfig:
    return SynthConfig(n_subjects=2, n_trials=20, seed=seed, fmt="trc", workers=2)


def _cache_key(config: SynthConfig) -> str:
    payload = json.dumps(
        to_jsonable(
            {
                "v": GENERATOR_VERSION,
                "config": asdict(config) | {"workers": 0},
                "ri": RELATIVE_IMPORTANCE,
                "fs": FEATURE_SCALE,
            }
        ),
        sort_keys=True,
    )
    return f"synth-v{GENERATOR_VERSION}-seed{config.seed}-{hashlib.sha256(payload.encode()).hexdigest()[:10]}"


def builtin_dataset_dir(seed: int = 0, n_subjects: int = 2) -> Path:
    """The built-in data set (2 subjects × 5 postures × 20 trials, TRC), generated on first use and cached.

    ``n_subjects`` draws that many subjects from the same population (``reachirl reproduce --subjects N``;
    20 is Berret 2011's full design). Subjects and trials are drawn per index, so subject ``S01`` and its trials
    are the same for every ``n_subjects``.

    Returns the folder with the TRC files, ``manifest.csv``, ``subjects.csv`` and ``truth.json``. It is built
    in a temporary folder and renamed into place, so a half-written cache is never used.
    """
    config = _builtin_config(int(seed))
    if int(n_subjects) != config.n_subjects:
        config = replace(config, n_subjects=int(n_subjects))
    root = cache_root()
    final = root / _cache_key(config)
    if final.is_dir() and (final / "truth.json").is_file():
        return final
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".tmp-synth-", dir=root))
    try:
        log.info("generating the built-in data set (seed %d) into %s", seed, final)
        generate(tmp, config)
        try:
            os.rename(tmp, final)
        except OSError:
            if not (final / "truth.json").is_file():  # not a concurrent winner: a real error
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


# ---------------------------------------------------------------------- the posture figure
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
    fig.suptitle(
        f"Berret 2011 initial postures [elbow; shoulder] (deg); arm L = {arm.length:.2f} m, shoulder at 0"
    )
    return fig
