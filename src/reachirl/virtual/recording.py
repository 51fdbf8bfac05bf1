"""Recording a virtual subject's reaches: each reach solved as a DOC, then recorded as markers in a lab."""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from ..arm import ArmModel
from ..data.trial import Trial, trial_from_knots
from ..doc import ReachingTask, solve_doc
from ..doc.observation import observe
from ..features import FEATURES
from .population import (
    _MAX_RETRIES,
    BERRET_DURATIONS_S,
    MOVEMENT_FRACTION,
    POSTURES,
    SynthSubject,
    _draw_trial_inputs,
    _rng,
    draw_subject,
    nominal_weights,
    posture_q,
)

log = logging.getLogger(__name__)

FORMATS = ("trc", "c3d", "mot")
MARKERS = ("SHO", "ELB", "WRI", "FTP")


MAX_TRUTH_WINDOWS = 20
"""The most time windows a virtual subject's true cost may have."""


def check_relative_importance(ri) -> tuple[tuple[float, ...], ...]:
    """``ri`` as a tuple of rows, after checking it is a true cost: 1 to :data:`MAX_TRUTH_WINDOWS` rows (time
    windows) of 7 finite values ≥ 0 (FEATURES order), each row with a positive sum. Raises ``ValueError``."""
    a = np.asarray(ri, dtype=float)
    if a.ndim != 2 or a.shape[1] != len(FEATURES) or not 1 <= a.shape[0] <= MAX_TRUTH_WINDOWS:
        raise ValueError(
            f"relative importance must be 1 to {MAX_TRUTH_WINDOWS} windows × {len(FEATURES)} features, "
            f"got shape {a.shape}"
        )
    bad = np.argwhere(~np.isfinite(a) | (a < 0))
    if bad.size:
        w, j = (int(i) for i in bad[0])
        raise ValueError(f"relative importance must be finite and >= 0: window {w + 1}, {FEATURES[j]}, is {a[w, j]:g}")
    empty = [i + 1 for i, row in enumerate(a) if row.sum() <= 0]
    if empty:
        raise ValueError(f"relative importance: window {empty[0]} weighs no feature (its row sums to 0)")
    return tuple(tuple(float(v) for v in row) for row in a)


MIN_REACH_FRACTION = 0.1
"""The least distance, as a fraction of the arm's length, from a posture's start fingertip to the bar."""


def start_fraction(posture: str) -> float:
    """How far forward the fingertip starts in ``posture``, as a fraction of the arm's length (Dumas' segment
    ratio, the same for every virtual subject up to their anthropometric jitter)."""
    arm = ArmModel.from_anthropometrics(1.76, 70.0, "M")
    return float(arm.fk(posture_q(posture))[0] / arm.length)


@dataclass(frozen=True)
class SynthConfig:
    """What to generate.

    ``target_fraction`` places the bar at that fraction of arm length (seed 95 %, Berret 85 %).
    ``relative_importance`` (windows × 7, FEATURES order; default :data:`RELATIVE_IMPORTANCE`, the paper's
    pattern over 8 windows) is the true cost: how much each feature weighs in each equal time window, the
    weights being ``relative_importance / FEATURE_SCALE`` (:func:`nominal_weights`).
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
    relative_importance: tuple[tuple[float, ...], ...] | None = None

    def __post_init__(self) -> None:
        if self.relative_importance is not None:
            object.__setattr__(self, "relative_importance", check_relative_importance(self.relative_importance))
        # a posture named twice is recorded once: twice would write each file once but list it twice
        object.__setattr__(self, "postures", tuple(dict.fromkeys(self.postures)))
        if int(self.n_subjects) < 1 or int(self.n_trials) < 1:
            raise ValueError(f"need at least 1 subject and 1 trial, got {self.n_subjects} and {self.n_trials}")
        if int(self.seed) < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if self.fmt not in FORMATS:
            raise ValueError(f"format must be one of {FORMATS}, got {self.fmt!r}")
        for p in self.postures:
            posture_q(p)
        if not 0.5 <= self.target_fraction < 1.0:
            raise ValueError(f"target_fraction must be in [0.5, 1), got {self.target_fraction}")
        short = {p: f for p in self.postures if (f := start_fraction(p)) > self.target_fraction - MIN_REACH_FRACTION}
        if short:
            starts = ", ".join(f"{p} at {f:.2f}" for p, f in short.items())
            least = math.ceil(100 * (max(short.values()) + MIN_REACH_FRACTION)) / 100
            raise ValueError(
                f"target_fraction {self.target_fraction:g} puts the bar behind, or within {MIN_REACH_FRACTION:g} arm "
                f"lengths of, the fingertip's start ({starts} of the arm's length): those reaches would go "
                f"backwards or barely move; use at least {least:.2f}, or leave "
                "those postures out"
            )
        if self.rate_hz <= 0:
            raise ValueError(f"rate_hz must be > 0, got {self.rate_hz}")


@dataclass(frozen=True)
class SynthTrial:
    """One virtual reach: its true weights and DOC solution, and its recording (lab frame, mm)."""

    subject: str
    posture: str
    trial_id: str
    weights: np.ndarray  # (windows, 7) true (jittered) weights
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
        return trial_from_knots(
            arm, self.t_knots, self.q_knots, self.target_x, self.subject, self.posture, self.trial_id
        )


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
    nominal = nominal_weights(config.relative_importance)
    retries = 0
    while True:
        w, q0, duration = _draw_trial_inputs(rng, posture, nominal)
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
            raise RuntimeError(f"DOC failed {retries} times for {subject.subject} {posture} trial {trial_index + 1}")
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


def _reach_spline(t_knots: np.ndarray, q_knots: np.ndarray):
    """A C² joint path through the DOC knots, at rest at both ends."""
    # imported here: scipy.interpolate imports scipy.optimize, which the command's own process never needs
    from scipy.interpolate import CubicSpline

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


def knot_trials(
    n_trials: int, posture: str = "P2", seed: int = 0, n_nodes: int = 100, subject_index: int = 0
) -> list[Trial]:
    """``n_trials`` reaches of one virtual subject from ``posture``, in memory, on the DOC's own knots.

    The ground truth is :func:`nominal_weights` (each trial jittered around it), the paper's pattern. For
    benchmarks and tests that need no files; :func:`generate` records the same reaches as marker files.
    """
    config = SynthConfig(
        n_subjects=subject_index + 1, n_trials=n_trials, seed=seed, postures=(posture,), n_nodes=n_nodes
    )
    subject = draw_subject(seed, subject_index)
    return [simulate_trial(subject, posture, i, config).to_trial(subject.arm) for i in range(n_trials)]


def one_cost_trials(
    n_reaches: int,
    seed: int = 0,
    weights: np.ndarray | None = None,
    jitter: float = 0.0,
    threshold: float | None = None,
    postures: tuple[str, ...] = POSTURES,
) -> tuple[list[Trial], np.ndarray]:
    """``(trials, true weights)``: ``n_reaches`` reaches from each of ``postures`` by the seed's first virtual
    subject, each the DOC's own solution under one cost (default :func:`nominal_weights`, the paper's pattern), in
    memory and without recording noise: the start jittered by 3°, the bar at 0.95 of the arm's length, Berret's
    mean duration. ``jitter``: each reach's weights drawn around the cost (a log-normal factor of that SD), the
    truth being their mean. ``threshold``: each reach cut where its fingertip speed crosses that fraction of its
    peak, as a recording is (``Trial.onset_threshold``); ``None``: whole. A reach whose DOC fails raises
    ``RuntimeError``. For benchmarks and tests of what the data can determine."""
    rng = np.random.default_rng(seed)
    arm = draw_subject(seed, 0).arm
    cost = nominal_weights() if weights is None else np.asarray(weights, dtype=float)
    trials, ws = [], []
    for p in postures:
        for k in range(n_reaches):
            q0 = posture_q(p) + np.deg2rad(3.0) * rng.standard_normal(2)
            q0[1] = max(q0[1], 0.0)  # a straight elbow at most
            task = ReachingTask(arm, q0, 0.95 * arm.length, BERRET_DURATIONS_S[p][0] / MOVEMENT_FRACTION)
            w = cost * np.exp(jitter * rng.standard_normal(cost.shape)) if jitter else cost
            sol = solve_doc(task, w)
            if not sol.converged:
                raise RuntimeError(f"the DOC of reach {k + 1} from {p} did not converge")
            trial = observe(sol, task, threshold, name=f"{p}T{k + 1}")
            trials.append(replace(trial, subject="V", posture=p, trial_id=f"{p}T{k + 1}", onset_threshold=threshold))
            ws.append(w)
    return trials, np.mean(ws, axis=0)
