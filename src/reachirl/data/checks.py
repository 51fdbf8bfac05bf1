"""Physical consistency at the door: the checks that a trial, a subject's measured arm, a model's fields and PD
gains make sense for a human reach, before any solve.

Each check raises :class:`~reachirl.errors.InputError` with one line naming the file, the field and the range
that was expected, which the command line turns into exit code 2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..arm import DEFAULT_Q_LOWER, DEFAULT_Q_UPPER
from ..errors import InputError
from ..validation import brief, check_arm, check_duration

__all__ = [
    "ELBOW_HYPEREXTENSION_DEG",
    "LENGTH_TOLERANCE",
    "MIN_REACH_RANGE",
    "TARGET_GAP",
    "check_model_rollout",
    "check_segment_lengths",
    "check_start_and_target",
    "check_trial_meta",
    "check_trial_moves",
    "check_trial_physics",
    "check_trial_posture",
    "pd_gain_limits",
]

#: subject-info segment lengths may differ from the markers' measured ones by this fraction at most (joint
#: centres from markers and tape measures of the segments agree within ~10 %; 20 % apart is another arm)
LENGTH_TOLERANCE = 0.20

#: the least range of the fingertip (the diagonal of the box it moves in, low-passed at MIN_SEGMENT_CUTOFF_HZ) in a
#: record, as a fraction of its median distance from the shoulder: a reach moves it by tens of centimetres (the
#: virtual subjects' bars lie at least 0.1 arm lengths beyond the start), a hand at rest by millimetres of drift and
#: noise (3 mm of marker noise at 100 Hz ranges over about 8 mm at 3 Hz)
MIN_REACH_RANGE = 0.05

#: the largest gap between a trial's ``target_x`` and its fingertip's x at offset, as a fraction of the arm's length:
#: the target is where the reach ends, measured on the markers (recordings cut at 5 % of peak speed end 2-3 % of an
#: arm's length short of it; UE-ADL's at most 2.3 %), while the arm's segments may be the subject-info file's, up to
#: LENGTH_TOLERANCE (20 %) from the markers'; further apart, the target belongs to another reach or another unit
TARGET_GAP = 0.30

#: degrees: how far past straight (0°) a human elbow hyperextends: typically up to 10-15°, and joint centres from
#: markers add a few degrees. An elbow alone beyond the model's lower limit (-5°) by no more than this is a real
#: hyperextended posture, said as such; further, or with the shoulder out too, it is a mirrored or backwards recording
ELBOW_HYPEREXTENSION_DEG = 20.0


def _deg(v: float) -> str:
    return f"{np.degrees(v):.1f}°"


def check_start_and_target(trial, path: object, where: str | None = None) -> None:
    """The target lies in front of the shoulder within the arm's reach, ``0 < target_x <= l1 + l2``, where the reach
    ends (the fingertip's x at offset within :data:`TARGET_GAP` of the arm's length of it), and the start
    velocities are within the DOC's speed bound ``|q̇0| <= qd_max`` (rad/s)."""
    from ..arm import DEFAULT_QD_MAX

    length = trial.arm.length
    tx = float(trial.target_x)
    if not 0.0 < tx <= length:
        raise InputError(
            f"field 'target_x' = {tx:.4g} m is outside the arm's reach (0, {length:.3f}] m (in front of the "
            "shoulder, at most l1 + l2 away)",
            path,
            where,
        )
    end_x = float(trial.arm.fk(trial.q[-1])[0])
    if abs(end_x - tx) > TARGET_GAP * length:
        raise InputError(
            f"field 'target_x' = {tx:.4g} m is {abs(end_x - tx):.3f} m from where the reach ends (the fingertip at "
            f"x = {end_x:.3f} m at offset; at most {TARGET_GAP:.0%} of the arm's {length:.3f} m): the target is "
            "the fingertip's x at offset",
            path,
            where,
        )
    qd_max = np.asarray(DEFAULT_QD_MAX, dtype=float)
    qd0 = np.asarray(trial.x0[2:], dtype=float)
    for j in range(2):
        if not abs(qd0[j]) <= qd_max[j]:
            raise InputError(
                f"field 'x0': the start velocity q̇{j + 1} = {qd0[j]:.4g} rad/s is outside [{-qd_max[j]:g}, "
                f"{qd_max[j]:g}] rad/s, the DOC's speed bound",
                path,
                where,
            )


def check_trial_moves(trial, where: str | None = None) -> None:
    """The fingertip moves: it ranges over at least :data:`MIN_REACH_RANGE` of its median distance from the
    shoulder, as preprocessing asks of a recording. A trial at rest has no reach to learn from (its features are
    zero and its spread, which normalises the merit, too)."""
    tip = trial.arm.fk(trial.q)
    extent = float(np.linalg.norm(np.ptp(tip, axis=0)))
    distance = float(np.median(np.linalg.norm(tip, axis=1)))
    if extent < MIN_REACH_RANGE * distance:
        raise InputError(
            f"no movement: the fingertip ranges over {extent * 1000:.0f} mm, less than {MIN_REACH_RANGE:.0%} of its "
            f"distance from the shoulder ({distance * 1000:.0f} mm): a trial at rest has no reach to learn from",
            None,
            where,
        )


def _first_outside(q: np.ndarray, tol: float) -> int | None:
    """The first sample of ``q`` ``(n, 2)`` outside the joint limits (beyond ``tol`` rad), or None."""
    lo, hi = np.asarray(DEFAULT_Q_LOWER), np.asarray(DEFAULT_Q_UPPER)
    bad = np.flatnonzero(np.any((q < lo - tol) | (q > hi + tol), axis=1))
    return int(bad[0]) if bad.size else None


def _hyperextension(q: np.ndarray, tol: float) -> tuple[int, int, int] | None:
    """``(first, last, deepest)``: the samples of ``q`` ``(n, 2)`` where the elbow is beyond its lower limit (by
    more than ``tol`` rad), when it alone leaves the joint limits and by no more than a human elbow hyperextends
    (:data:`ELBOW_HYPEREXTENSION_DEG`); None otherwise."""
    lo, hi = np.asarray(DEFAULT_Q_LOWER), np.asarray(DEFAULT_Q_UPPER)
    below = q[:, 1] < lo[1] - tol
    others = (q[:, 0] < lo[0] - tol) | (q[:, 0] > hi[0] + tol) | (q[:, 1] > hi[1] + tol)
    if not below.any() or others.any() or q[:, 1].min() < -math.radians(ELBOW_HYPEREXTENSION_DEG):
        return None
    k = np.flatnonzero(below)
    return int(k[0]), int(k[-1]), int(np.argmin(q[:, 1]))


def _hyperextension_text(trial, span: tuple[int, int, int]) -> str:
    """What a hyperextended elbow (:func:`_hyperextension`) is, where, and that the DOC cannot plan it."""
    first, last, deepest = span
    lo = DEFAULT_Q_LOWER[1]
    q2 = float(trial.q[deepest, 1])
    return (
        f"the elbow is hyperextended to {_deg(q2)}, {np.degrees(lo - q2):.1f}° beyond the model's limit of "
        f"{_deg(lo)}, at samples {first}-{last} of the reach ({trial.t[first]:.3f}-{trial.t[last]:.3f} s after "
        f"onset): a real posture, but the DOC's joint limits ({_limits_text()}) cannot reproduce it; leave this "
        "trial out"
    )


def _limits_text() -> str:
    """The model's joint limits, in degrees."""
    lo, hi = DEFAULT_Q_LOWER, DEFAULT_Q_UPPER
    return f"q1 in [{_deg(lo[0])}, {_deg(hi[0])}], q2 in [{_deg(lo[1])}, {_deg(hi[1])}]"


def check_trial_posture(trial, path: object, where: str | None = None) -> None:
    """After preprocessing a recording: the reach starts inside the joint limits, stays within them, and ends
    in front of the shoulder. A mirrored recording (a left arm read as a right one) bends the elbow backwards
    and a backwards one starts at the bar: the message says so, here where ``--side`` or ``--markers`` can fix
    it, and not later in ``fit``."""
    span = _hyperextension(trial.q, 1e-9)
    if span is not None:  # an arm at its length, not a mirrored one: said as such
        raise InputError(_hyperextension_text(trial, span), path, where)
    limits = _limits_text()
    hint = (
        "a mirrored or backwards recording? (a left arm needs --side left or the manifest's side column; "
        "check --markers, --up-axis and --forward-axis)"
    )
    q0 = trial.q[0]
    if _first_outside(q0[None], 1e-9) is not None:
        raise InputError(
            f"the start posture q0 = ({_deg(q0[0])}, {_deg(q0[1])}) lies outside the joint limits {limits}: {hint}",
            path,
            where,
        )
    k = _first_outside(trial.q, 1e-9)
    if k is not None:
        q = trial.q[k]
        raise InputError(
            f"the reach leaves the joint limits {limits} at {trial.t[k]:.3f} s after onset "
            f"(q = ({_deg(q[0])}, {_deg(q[1])})): {hint}",
            path,
            where,
        )
    if not trial.target_x > 0.0:
        raise InputError(
            f"the reach ends {trial.target_x:.3f} m behind the shoulder (fingertip x at offset), "
            f"expected a target in front: {hint}",
            path,
            where,
        )


def check_segment_lengths(
    info_lengths: Mapping[str, float | None], measured: Mapping[str, float], path: object, subject: str = ""
) -> None:
    """Segment lengths of the subject info (``upper_arm_m``, ``forearm_m``, ``hand_m``; ``None``: not given)
    against the markers' measured ones (:func:`reachirl.data.kinematics.estimate_lengths`): more than
    :data:`LENGTH_TOLERANCE` apart, the planned reach would miss the recorded target."""
    ua, fa, hand = (info_lengths.get(k) for k in ("upper_arm_m", "forearm_m", "hand_m"))
    pairs = [("upper_arm_m", ua, "upper_arm", "shoulder to elbow")]
    if fa is not None and hand is not None:
        pairs.append(("forearm_m + hand_m", fa + hand, "elbow_fingertip", "elbow to fingertip"))
    elif fa is not None and hand is None:
        pairs.append(("forearm_m", fa, "forearm", "elbow to wrist"))
    who = f"subject {subject}: " if subject else ""
    for field, given, key, span in pairs:
        m = measured.get(key)
        if given is None or m is None or not np.isfinite(m) or m <= 0:
            continue
        apart = abs(given - m) / m
        if apart > LENGTH_TOLERANCE:
            raise InputError(
                f"{who}subject-info {field} = {given:.3f} m but the markers measure {m:.3f} m from {span} "
                f"({100 * apart:.0f} % apart; at most {100 * LENGTH_TOLERANCE:.0f} % allowed): check the "
                "subject info or the marker map",
                path,
            )


def check_model_rollout(model, path: object) -> None:
    """A model's ``info.rollout_q`` (the fit's own reach, ``evaluate``'s cold start) lies within the joint
    limits."""
    from ..arm import DEFAULT_Q_LOWER, DEFAULT_Q_UPPER

    rollout = model.info.get("rollout_q") if isinstance(model.info, Mapping) else None
    if rollout is None:
        return
    r = np.asarray(rollout, dtype=float)
    lo, hi = np.asarray(DEFAULT_Q_LOWER), np.asarray(DEFAULT_Q_UPPER)
    bad = np.argwhere(~((r >= lo - 1e-6) & (r <= hi + 1e-6)))
    if bad.size:
        i, j = (int(v) for v in bad[0])
        raise InputError(
            f"field 'info.rollout_q', row {i}: q{j + 1} = {r[i, j]:.4g} rad is outside the joint limits "
            f"[{lo[j]:.4g}, {hi[j]:.4g}] rad",
            path,
        )


def pd_gain_limits(trials, n_nodes: int, substeps: int, stretch: float = 1.0) -> tuple[float, float, float, float]:
    """``(kp_max, kd_max, h, inertia)``: the largest PD gains that MuJoCo's explicit step ``h`` (the longest of
    the trials' ``stretch · duration / (n_nodes · substeps)``, s: the reach played lasts at most ``stretch`` times
    the trial) integrates stably on the lightest of the trials' arms, whose smallest mass-matrix eigenvalue over
    the elbow's range is ``inertia`` (kg·m²): ``kd · h / I <= 1`` and ``kp · h² / I <= 1`` (half and a quarter
    of the undamped stability limits; the longest step is the least stable)."""
    from ..arm import DEFAULT_Q_LOWER, DEFAULT_Q_UPPER

    h = float(stretch) * max(tr.duration for tr in trials) / (int(n_nodes) * int(substeps))
    q2 = np.linspace(DEFAULT_Q_LOWER[1], DEFAULT_Q_UPPER[1], 33)
    inertia = min(float(np.linalg.eigvalsh(tr.arm.mass_matrix(np.array([0.0, a])))[0]) for tr in trials for a in q2)
    return inertia / h**2, inertia / h, h, inertia


# ---------------------------------------------------------------------- a trials file's entries
_META_TYPES = {"subject": str, "posture": str, "trial_id": str, "side": str, "source": str}


def check_trial_meta(m, i: int, path) -> None:
    """One trial's entry in a trials file's ``meta.json``. (Each message is made only for an entry that fails: a
    study's file holds thousands.)"""
    where = f"trial {i}"
    if not isinstance(m, dict):
        raise InputError(f"{where}: expected an object, found {brief(m)}", path)
    for key in ("subject", "posture", "trial_id", "target_x", "arm"):
        if key not in m:
            raise InputError(f"{where}: field '{key}' is missing", path)
    for key, typ in _META_TYPES.items():
        if key in m and not (isinstance(m[key], typ | int) and not isinstance(m[key], bool)):
            raise InputError(f"{where}: field '{key}' must be a string, found {brief(m[key])}", path)
    tx = m["target_x"]
    if not (isinstance(tx, int | float) and not isinstance(tx, bool) and math.isfinite(tx)):
        raise InputError(f"{where}: field 'target_x' must be a finite number (m), found {brief(tx)}", path)
    th = m.get("onset_threshold")
    if not (th is None or (isinstance(th, int | float) and not isinstance(th, bool) and 0.0 < th < 1.0)):
        raise InputError(
            f"{where}: field 'onset_threshold' must be null or a fraction in (0, 1), found {brief(th)}", path
        )
    arm = m["arm"]
    if not isinstance(arm, dict):
        raise InputError(f"{where}: field 'arm' must be an object, found {brief(arm)}", path)
    for k, v in arm.items():
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)):
            raise InputError(f"{where}: field 'arm.{k}' must be a finite number, found {brief(v)}", path)


def check_trial_physics(trial, i: int, path) -> None:
    """A loaded trial can be planned by the DOC: a human-sized arm, a reach's duration, a start inside the joint
    limits, the start state ``x0`` the trial's first sample, and a reach that stays within the joint limits (as
    preprocessing guarantees: a trial edited since, or in degrees, would be predicted as if it were a reach)."""
    where = f"trial {i} ({trial.id})"
    try:
        check_arm(trial.arm, where)
        check_duration(trial.duration, where)
    except InputError as e:
        raise InputError(e.reason, path, where) from None
    q0 = trial.x0[:2]
    span = _hyperextension(trial.q, 1e-6)
    if span is not None and np.allclose(q0, trial.q[0], rtol=0.0, atol=1e-6):  # an arm at its length
        raise InputError(_hyperextension_text(trial, span), path, where)
    if _first_outside(q0[None], 1e-9) is not None:
        raise InputError(
            f"the start q0 = ({_deg(q0[0])}, {_deg(q0[1])}) lies outside the joint limits {_limits_text()}", path, where
        )
    gap = float(np.max(np.abs(q0 - trial.q[0])))
    if gap > 1e-6:
        raise InputError(
            f"the start state x0 lies {np.rad2deg(gap):.3g}° from the trial's first sample q[0]: an edited file?",
            path,
            where,
        )
    k = _first_outside(trial.q, 1e-6)
    if k is not None:
        q = trial.q[k]
        raise InputError(
            f"the reach leaves the joint limits {_limits_text()} at sample {k} (q = ({_deg(q[0])}, {_deg(q[1])})): "
            f"angles in degrees, or an edited file?",
            path,
            where,
        )
