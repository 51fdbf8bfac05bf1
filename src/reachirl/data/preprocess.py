"""From marker trajectories (or joint angles) to a validated :class:`~reachirl.data.trial.Trial`.

This module runs the steps in order; they live in :mod:`~reachirl.data.kinematics` (joint centres, mirror, plane,
angles, lengths, the arm), :mod:`~reachirl.data.signal` (gaps, filters, derivatives) and
:mod:`~reachirl.data.segmentation` (the stretch kept, onset and offset, another reach).

The steps, in order, each set by :class:`PreprocessOptions` (defaults follow Berret et al. 2011):

1. **Joint centres** from the marker set: a marker, a midpoint of markers, or an anatomical landmark
   calibrated in a static trial and carried by its segment's cluster (:func:`calibrate_static`,
   :func:`cast_reconstruct`: a least-squares rigid fit of the cluster per frame, Kabsch/SVD).
2. **Mirror** a left arm into the right-arm convention (reflect the lab's lateral axis). The planar angles do
   not depend on it, since the plane's axes come from the movement and from gravity, but the 3-D data then
   look like a right arm everywhere.
3. **Gap filling** (:func:`fill_gaps`): a run of at most ``max_gap_frames`` missing frames by a cubic spline
   through the seen frames (the nearest value at the ends of the record); a longer run is an
   :class:`InputError` naming the marker and the frames, unless it lies in the rest before or after the reach
   (a marker occluded while the hand rests): the record is then cut at the gap (:func:`seen_window`), with a
   warning, when the gap is shown to lie in the rest (:func:`_check_window`): the reach begins and ends in
   0.1 s of rest seen right before and after it, the fingertip is in the same place on both sides of the gap,
   and what is kept is a reach (it moves the fingertip by at least a tenth of the shoulder-fingertip distance
   and, after a gap before it, extends the arm).
4. **Units check**: the median shoulder→elbow, elbow→wrist and shoulder→fingertip distances must be body-sized
   (``segment_range_m``); metres declared as mm give absurdly small ones. Then the **glitch check**
   (:func:`check_glitches`): a joint centre faster than any arm, or accelerating beyond any reaching arm over
   10 ms, or repeating the frame before it exactly (every joint, the fingertip moving on both sides: a copy), or a
   fingertip stepping back against its way of travel beyond its noise (frames out of order), or every joint of
   the arm stepping back at once where the hand moves slowly (frames out of order at the start or the end of the
   reach), or a fingertip that leaves its running median by more than 4 mm and its noise (another joint: 10 mm; a
   spike of a few frames, in the rest too), is an :class:`InputError` naming the frame(s).
5. **Zero-lag low-pass** (:func:`lowpass`): Butterworth (``filter_order``, ``cutoff_hz``) by ``sosfiltfilt``,
   so the effective order is doubled and there is no phase lag. 10 Hz, 5th order as Berret.
6. **Onset and offset** (:func:`detect_onset_offset`): where the fingertip speed crosses ``onset_threshold``
   (5 %) of its peak, the first crossings before and after the main peak. With noisy markers that speed is
   taken from the fingertip low-passed harder (``segment_cutoff_hz="auto"``, :func:`segmentation_cutoff`;
   the angles keep ``cutoff_hz``): with 1–2 mm of marker noise the 10 Hz speed carries about 40 mm/s of
   noise, as much as 5 % of a reach's peak, so onset and offset wandered by up to ±8 % of the reach, into the
   rest or into the movement, and the DOC (at rest at both ends) was asked for another reach. Clean
   recordings (UE-ADL: 0.06 mm) keep the 10 Hz speed. ``None`` always uses it, as Berret. A recording that
   also holds the return, faster than the reach, gives the reach: the movement that takes the fingertip away
   from where it rested, not the one that brings it back. Another forward reach in the recording is reported
   (:func:`other_reach`), and the faster one is kept. A record whose fingertip (low-passed at 3 Hz) ranges over
   less than ``MIN_REACH_RANGE`` (5 %) of its distance from the shoulder holds no reach: rest, whose marker noise
   (or a joint-angle file's angle noise) can carry the 10 Hz speed above ``min_peak_speed``.
7. **Sagittal plane** (:func:`sagittal_basis`): ``"pca"`` (default), the principal plane (SVD) of the arm's
   joint centres relative to the shoulder over the movement, as Berret; its up axis is the lab's up (opposite
   gravity) projected on the plane, its forward axis normal to up in the plane, pointing where the fingertip
   moves. When that plane is ill-defined (a flat point cloud: 3rd singular value > ``pca_max_flatness`` × the
   2nd, or more than ``pca_max_tilt_deg`` from vertical: an arm that stays near-horizontal, as in some UE-ADL
   reaches) it falls back, with a log note, to ``"vertical"``: the vertical plane through the fingertip's main
   horizontal direction of travel. ``"axes"`` takes given lab axes. The shoulder, frame by frame, is the
   origin. With ``"pca"`` or ``"vertical"`` the up axis is then checked (:func:`check_up_axis`): a reach's arm lies
   near the vertical plane of the reach or hangs at some moment; a lab axis across the reach given as up fails
   both (the plane turns horizontal and cuts across the arm), and is refused. An up axis given (``--up-axis``) against
   the recording's, the marker set's or the format's own is refused when the upper arm hangs within
   ``MAX_HANG_DEG`` of straight down before the reach with that one and not with the axis given
   (:func:`check_given_up`: the lab's forward axis given as up, which keeps the plane of the reach).
8. **Planar IK**: ``"segments"`` (default): q1 from the shoulder→elbow direction and q2 from the
   elbow→``distal`` direction (fingertip by default: segment 2 of the model is forearm + hand; ``"wrist"`` for
   the anatomical elbow); ``"fingertip"``: Berret's 2-link IK of the fingertip alone (:meth:`ArmModel.ik`).
9. **Segment lengths** (:func:`estimate_lengths`): medians of the 3-D joint-centre distances over every frame of
   the record where both joints are seen (a part cut off at a gap included). l2
   is the elbow→fingertip distance (the hand is lumped with a frozen wrist). Lengths in the subject-info file,
   when given, win; the arm is :meth:`ArmModel.from_anthropometrics` with the subject's sex, height and mass.
10. **Derivatives and torques**: a cubic spline through the filtered angles over the whole record gives q̇ and
    q̈; τ by inverse dynamics on the subject's arm. The trial is then cut to onset→offset (and resampled to
    ``n_samples`` points if asked). ``target_x`` is the measured fingertip x (shoulder frame, sagittal plane)
    at offset.

Nothing here prints; problems are :class:`InputError` with the file and frame, notes go to ``logging``. A record's
warnings wait until it gives a trial (or are held for the caller's own checks, ``held``): a refusal comes alone.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import median_filter

from ..arm import ArmModel
from ..errors import InputError
from .checks import MIN_REACH_RANGE  # the least fingertip range of a reach
from .kinematics import (
    build_arm,
    check_units,
    estimate_lengths,
    joint_positions,
    mirror,
    planar_ik_segments,
    sagittal_basis,
)
from .markersets import MarkerSet, lab_axis, resolve_name
from .options import PreprocessOptions
from .readers import AngleData, MarkerData, SubjectInfo
from .segmentation import (
    MIN_SEGMENT_CUTOFF_HZ,
    SeenWindow,
    detect_onset_offset,
    other_reach,
    seen_window,
    segmentation_speed,
)
from .signal import (
    derivatives,
    fill_gaps,
    filter_padlen,
    gap_message,
    gap_where,
    lowpass,
    seen_frames,
    true_runs,
)
from .trial import Trial

__all__ = [
    "DEFAULT_SUBJECT",
    "MarkerReconstruction",
    "PreprocessOptions",
    "angles_to_trial",
    "check_given_up",
    "check_glitches",
    "check_up_axis",
    "markers_to_trial",
    "reconstruct_markers",
]

log = logging.getLogger(__name__)

#: m/s: a human fingertip peaks near 1-3 m/s in a reach and below 20 m/s in a throw; faster is a glitch
MAX_FINGERTIP_SPEED = 30.0
#: m/s²: a reaching hand's markers peak near 10-30 m/s² (about 3 g); 20 g from one frame to the next is a glitch
MAX_MARKER_ACCELERATION = 200.0

#: a step of the fingertip back against its way of travel (check_glitches) is a frame out of order when it is longer
#: than this many SDs of the recording's step noise (noise alone: at most 4.0 in 1,350 virtual records of three seeds)
#: and than MIN_BACK_STEP_M, while the fingertip travels at least MIN_TRAVEL_SPEED (its path low-passed at
#: MIN_SEGMENT_CUTOFF_HZ): a hand does not move back and forth within a frame, a block of frames put back in time does
BACK_STEP_NOISE_SDS = 6.0
#: m: ... and the least such step: UE-ADL's markers flicker from one frame to the next (at most 1.3 mm back while
#: the fingertip travels, over its 80 reaches)
MIN_BACK_STEP_M = 0.003
#: m/s: ... where the fingertip travels at least this fast (at rest it has no way of travel to step back against)
MIN_TRAVEL_SPEED = 0.05

#: m: the arm's joints (all but the shoulder) that step back against their ways of travel in the same frame, each
#: by more than this (and than COHERENT_BACK_NOISE_SDS of its step noise), are frames out of order (check_glitches):
#: a block of frames put back moves every marker back at once, while a marker's flicker is its own (UE-ADL: at most
#: 0.09 mm at once over its 80 reaches, where each joint alone steps back by up to 1.3 mm, the wrist's cluster 6 mm)
MIN_COHERENT_BACK_M = 0.0005
#: ... SDs of each joint's step noise (as BACK_STEP_NOISE_SDS, for three joints at once)
COHERENT_BACK_NOISE_SDS = 4.0
#: m/s: ... where each joint travels at least this fast (its path low-passed at MIN_SEGMENT_CUTOFF_HZ): at the start
#: and the end of the reach, slower than MIN_TRAVEL_SPEED
MIN_COHERENT_TRAVEL_SPEED = 0.005

#: frames: the fingertip's path against which a spike is measured (check_glitches) is its running median over this
#: many frames: a spike, a swap or a block of frames out of order up to (SPIKE_WINDOW - 1) / 2 frames long leaves it
SPIKE_WINDOW = 11
#: m: the fingertip further than this from its running median is a spike ... (UE-ADL: at most 2.4 mm, over its 80
#: reaches; a hand at rest or slow does not leave its path and come back within a few frames) ...
MIN_SPIKE_M = 0.004
#: ... and than this many times the median distance (the recording's noise: 1-2 mm of it stays below 5 times)
SPIKE_NOISE_MEDIANS = 8.0
#: m: MIN_SPIKE_M for the other joints (shoulder, elbow, wrist), whose centres a cluster of markers carries (a
#: landmark some centimetres off its cluster turns the cluster's noise into more of its own): UE-ADL's leave their
#: running medians by at most 6.3 mm (the wrist; the elbow 6.0, the shoulder 3.7 mm). A block of 2-5 frames of the
#: elbow's cluster off by 10-19 mm, within the acceleration check, moved q2 by 1-3.7° (ADL001FR1; 3 frames 15 mm off
#: where the reach starts: q̈2 by 29 rad/s², beyond its peak over the reach)
MIN_JOINT_SPIKE_M = 0.010

#: m: a frame that repeats the one before it exactly, every joint, is a copy (check_glitches) when the fingertip moves
#: further than this (plus what an arm's acceleration can take off a step) in the frames on both sides: no rounding of
#: the coordinates (at worst to 1 mm) makes a moving marker stand still
MIN_COPY_STEP_M = 0.002

#: s: a record cut at a gap longer than gap filling allows must show this much rest between the gap and the reach
#: (the reach's onset or offset is then seen, not inferred at the gap's edge)
MIN_SEEN_REST_S = 0.1
#: m: how far the fingertip may drift across a gap cut off as rest (a hand at rest drifts by millimetres)
MAX_REST_DRIFT_M = 0.02
#: the least fingertip movement, as a fraction of the shoulder-to-fingertip distance, of a reach seen beside a gap
#: cut off (the virtual subjects' bars lie at least 0.1 arm lengths beyond the start)
MIN_CUT_REACH = 0.1

#: degrees: a segment of a reach's arm stands at most this far out of the vertical plane of the reach ... (see
#: check_up_axis; UE-ADL: at most 34°; a lab axis across the reach given as up: 63-90°)
MAX_OUT_OF_PLANE_DEG = 50.0
#: ... or its upper arm hangs this near straight down at some moment (UE-ADL: within 19°; a lab axis across the reach
#: given as up: 70° or further)
MAX_HANG_DEG = 45.0

#: The subject used when no subject-info is given: Berret et al. 2011's mean subject (male, 1.76 m, 69.9 kg).
DEFAULT_SUBJECT = SubjectInfo(subject="default", sex="M", height_m=1.76, mass_kg=69.9)


# ---------------------------------------------------------------------- markers → trial
@dataclass(frozen=True)
class MarkerReconstruction:
    """Everything computed from one marker file, on every frame of the record (``onset``/``offset``
    inclusive), or of the part of it that a gap in the rest cut off (``first_frame``, :func:`seen_window`)."""

    t: np.ndarray  # (n,) s
    q: np.ndarray  # (n, 2) rad
    qd: np.ndarray
    qdd: np.ndarray
    fingertip: np.ndarray  # (n, 2) planar fingertip, shoulder frame (m)
    speed: np.ndarray  # (n,) 3-D fingertip speed (m/s)
    onset: int
    offset: int
    arm: ArmModel
    lengths: Mapping[str, float]
    basis: np.ndarray  # rows forward, up, normal (lab frame, after mirroring)
    joints: Mapping[str, np.ndarray] = field(repr=False)  # filtered 3-D joint centres (lab frame, mirrored)
    side: str = "right"
    source: str = ""
    first_frame: int = 0  # the record's frame (0-based) at t[0]: > 0 when a long gap in the rest was cut off


def _check_window(
    window: SeenWindow,
    onset: int,
    offset: int,
    seen: np.ndarray,
    positions: Mapping[str, tuple[np.ndarray, str]],
    cut_tip: np.ndarray,
    rate: float,
    max_gap: int,
    src: object,
    held: list[tuple],
) -> None:
    """A record cut at gaps longer than gap filling allows (:func:`seen_window`) gives a trial only when those
    gaps lie in the rest: the reach (``onset``/``offset``, frames of the cut) begins and ends in rest seen
    (every joint, no filled frame) for :data:`MIN_SEEN_REST_S` right before and after it; the fingertip is in
    the same place (within :data:`MAX_REST_DRIFT_M`) on both sides of each gap it is seen beyond; after a gap
    before it, the reach extends the arm (it is not a return); and it moves the fingertip by at least
    :data:`MIN_CUT_REACH` of the shoulder-to-fingertip distance (not a fidget or noise while the reach is
    hidden). Each gap cut off is then reported as a warning (appended to ``held``, :func:`_release`); otherwise the
    gap beside the reach is refused as :func:`fill_gaps` refuses it. ``seen``: the cut's frames where every joint was
    seen; ``cut_tip``: the cut's fingertip, gaps filled."""
    rest = max(1, round(MIN_SEEN_REST_S * rate))
    before = [g for g in window.gaps if g[2] <= window.start]
    after = [g for g in window.gaps if g[1] >= window.stop]
    near_before = max(before, key=lambda g: g[2]) if before else None
    near_after = min(after, key=lambda g: g[1]) if after else None
    tip = positions["fingertip"][0]
    shoulder = positions["shoulder"][0]
    tip_seen = seen_frames(tip)
    distance = np.linalg.norm(tip - shoulder, axis=1)
    on, off = window.start + onset, window.start + offset  # frames of the record
    why = gap = None
    if near_before and (onset < rest or not seen[onset - rest : onset].all()):
        why, gap = f"the reach does not begin in {MIN_SEEN_REST_S:g} s of seen rest after it", near_before
    elif near_after and (offset + rest >= len(seen) or not seen[offset + 1 : offset + 1 + rest].all()):
        why, gap = f"the reach does not end in {MIN_SEEN_REST_S:g} s of seen rest before it", near_after
    if why is None:
        for g in window.gaps:
            i = np.flatnonzero(tip_seen[: g[1]])
            j = np.flatnonzero(tip_seen[g[2] :])
            if i.size and j.size:
                moved = float(np.linalg.norm(tip[g[2] + j[0]] - tip[i[-1]]))
                inside = tip[g[1] : g[2]][tip_seen[g[1] : g[2]]]
                if inside.shape[0] >= 2:
                    moved = max(moved, float(np.linalg.norm(np.ptp(inside, axis=0))))
                if moved > MAX_REST_DRIFT_M:
                    why, gap = f"the fingertip moves {moved * 1000:.0f} mm across it: the hand is not at rest", g
                    break
    if why is None and near_before and np.nanmax(distance[on : off + 1]) <= distance[on]:
        why, gap = "the movement seen after it shortens the arm: a return (a reach extends it)", near_before
    reach = float(np.linalg.norm(cut_tip[offset] - cut_tip[onset]))
    if why is None and not reach >= MIN_CUT_REACH * float(np.nanmedian(distance)):
        why = f"what is seen beside it moves the fingertip only {reach * 1000:.0f} mm: not the reach"
        gap = near_before or near_after
    if why is not None:
        raise InputError(f"{gap_message(gap[0], gap[1], gap[2], max_gap)}, and {why}", src)
    for label, s, e in window.gaps:
        held.append(
            (
                "%s: marker %s is missing %s, in the rest %s the reach; the record is used from frame %d to %d",
                src,
                label,
                gap_where(s, e),
                "before" if e <= window.start else "after",
                window.start + 1,
                window.stop,
            )
        )


def _release(notes: list[tuple], held: list[tuple] | None) -> None:
    """The warnings a trial's preprocessing held back (:meth:`logging.Logger.warning` arguments) once the trial is
    accepted: into the caller's ``held`` list, for it to log once its own checks accept the trial, or logged."""
    if held is not None:
        held.extend(notes)
        return
    for warning in notes:
        log.warning(*warning)


def _fingertip_range(tip: np.ndarray, rate: float, order: int) -> float:
    """The diagonal of the box the fingertip ``(n, 3)`` moves in (m), low-passed at
    :data:`~reachirl.data.segmentation.MIN_SEGMENT_CUTOFF_HZ` (the slowest segmentation speed) when the record
    allows: a reach keeps its extent, noise loses most of its own."""
    if rate > 2.0 * MIN_SEGMENT_CUTOFF_HZ and tip.shape[0] > filter_padlen(order):
        tip = lowpass(tip, rate, MIN_SEGMENT_CUTOFF_HZ, order)
    return float(np.linalg.norm(np.ptp(tip, axis=0)))


def _rest_only(tip: np.ndarray, distance: float, rate: float, order: int, noise: str) -> str | None:
    """The refusal of a record that holds no reach, or ``None``: its fingertip ``tip`` (``(n, d)``, before the
    angles' filter) ranges over less than :data:`MIN_REACH_RANGE` of ``distance``, its median distance from the
    shoulder (m): rest, whose ``noise`` can carry the 10 Hz speed above ``min_peak_speed``."""
    extent = _fingertip_range(tip, rate, order)
    if not extent < MIN_REACH_RANGE * distance:
        return None
    return (
        f"no movement detected: the fingertip ranges over {extent * 1000:.0f} mm, less than {MIN_REACH_RANGE:.0%} "
        f"of its distance from the shoulder ({distance * 1000:.0f} mm): rest and {noise}, not a reach"
    )


def check_up_axis(
    rel: Mapping[str, np.ndarray],
    basis: np.ndarray,
    up: np.ndarray,
    onset: int,
    offset: int,
    t: np.ndarray,
    up_name: str,
    src: object,
) -> None:
    """Refuse an up axis that is not the lab's vertical (a horizontal lab axis given as up), from two cues of
    gravity of which a recording of a reach shows at least one:

    * the arm moves in a vertical plane: the sagittal plane (:func:`sagittal_basis`, which holds ``up`` or, for
      ``"pca"``, its projection) holds each segment (shoulder→elbow, elbow→fingertip) within
      :data:`MAX_OUT_OF_PLANE_DEG` from onset to offset;
    * the arm hangs under gravity at some moment of the record (at rest, before or after the reach): the upper arm
      comes within :data:`MAX_HANG_DEG` of ``-up``.

    With the lab's lateral axis as up the plane of the reach turns horizontal: the vertical fallback plane of
    :func:`sagittal_basis` then cuts across the arm and the hanging arm is horizontal, so both cues fail, and the
    angles were the projections of a segment standing 60-90° out of the plane (elbow flexion swinging over 150°
    while the upper arm stays still). Measured over UE-ADL (80 trials, both arms, each turned to every lab up axis
    and mirrored) and the virtual subjects (200 trials, likewise, left arms by mirroring): with the right up axis a
    segment stands at most 34° out of the plane and the upper arm hangs within 19° of straight down in UE-ADL (the
    virtual subjects' reaches are planar, 0°; from Berret's P4 start the upper arm never comes nearer than 52-66°
    to straight down); with a lateral axis as up, a segment stands 63-90° out of the plane and the upper arm never
    comes within 70°. ``rel``: the joints relative to the shoulder over the record; ``up_name``: the up axis in
    words, for the message. A horizontal axis along the reach (the lab's forward axis as up) turns the reach in its
    own plane and is not caught here: :func:`check_given_up` catches it when the axis was given against the
    recording's, marker set's or format's own up."""
    names = {"elbow": "upper arm", "fingertip": "forearm (elbow to fingertip)"}
    if "elbow" not in rel:
        names = {"fingertip": "arm"}
    worst = None
    start = np.zeros_like(rel["fingertip"])
    for joint, name in names.items():
        seg = (rel[joint] - start)[onset : offset + 1]
        length = np.linalg.norm(seg, axis=1)
        inplane = np.linalg.norm(seg @ basis[:2].T, axis=1)
        inside = np.divide(inplane, length, out=np.ones_like(length), where=length > 0.0)
        k = int(np.argmin(inside))
        angle = float(np.degrees(np.arccos(np.clip(inside[k], 0.0, 1.0))))
        if worst is None or angle > worst[0]:
            worst = (angle, name, k)
        start = rel[joint]
    hang = _hang_deg(rel, up)
    angle, name, k = worst
    if angle > MAX_OUT_OF_PLANE_DEG and hang > MAX_HANG_DEG:
        raise InputError(
            f"with up = {up_name}, the {name} stands {angle:.0f}° out of the vertical plane of the reach "
            f"({t[onset + k] - t[onset]:.2f} s after onset) and the {names.get('elbow', 'arm')} never hangs within "
            f"{MAX_HANG_DEG:g}° of straight down ({hang:.0f}° at best): is the up axis the lab's vertical? (check "
            "--up-axis)",
            src,
        )


def _hang_deg(rel: Mapping[str, np.ndarray], up: np.ndarray) -> float:
    """How near (degrees) the upper arm (shoulder→elbow, else shoulder→fingertip) comes to ``-up`` over the record."""
    first = rel["elbow"] if "elbow" in rel else rel["fingertip"]
    norm = np.linalg.norm(first, axis=1)
    cos_down = np.divide(-(first @ up), norm, out=np.full_like(norm, -1.0), where=norm > 0.0)
    return float(np.degrees(np.arccos(np.clip(np.nanmax(cos_down), -1.0, 1.0))))


def check_given_up(
    rel: Mapping[str, np.ndarray],
    up: np.ndarray,
    up_name: str,
    reference: str,
    reference_source: str,
    onset: int,
    src: object,
    mirrored: np.ndarray | None = None,
) -> None:
    """Refuse an up axis ``up`` (``up_name``, given by ``--up-axis``) that gravity contradicts where the recording,
    its marker set or its format says which lab axis is up (``reference``, from ``reference_source``): before the
    reach, at rest, the upper arm never hangs within :data:`MAX_HANG_DEG` of straight down with the axis given, and
    does with the reference.

    :func:`check_up_axis` cannot see a horizontal lab axis *along* the reach given as up (the lab's forward axis):
    the reach's vertical plane holds the forward axis as well as the up one, so the arm stays in it (UE-ADL: at
    most 34° out of it, as with the right axis), and its other cue, the arm hanging at some moment, is only asked
    for when the arm leaves the plane. Only the joint limits were left: they refused the trials whose forward
    direction came out as the lab's up (the arm at rest then hangs backwards, q1 near ±180°), not those whose
    fingertip sinks a little as it reaches, so that the lab's down came out as forward: the resting arm then reads
    as an upper arm held horizontally forward and the reach as a raise of the arm, within the limits (26 of UE-ADL's
    80 trials with +y, q1 from -15..10° at onset to 29..45°). Measured over UE-ADL before the reach: with the lab's
    up the upper arm hangs within 3-19° of straight down; with its forward axis (+y or -y) as up it comes no nearer
    than 75°. After the reach the arm may be held out at the target (ADL009's upper arm stays 43° from the forward
    axis), so only the rest before it counts. A recording whose arm never hangs (Berret's P4 start) is not refused,
    nor one without a reference up or with the reference given. ``rel``: the joints relative to the shoulder over
    the record, mirrored across the lab axis ``mirrored`` for a left arm; ``onset``: the reach's first frame."""
    ref = lab_axis(reference)
    if float(up @ ref) > 0.999:  # the same axis
        return
    if mirrored is not None:  # a left arm's joints are mirrored across the lab axis ``mirrored``: so is the reference
        ref = ref - 2.0 * float(ref @ mirrored) * mirrored
    before = {k: v[: onset + 1] for k, v in rel.items()}  # at rest before the reach (after it, the arm may be held out)
    given, declared = _hang_deg(before, up), _hang_deg(before, ref)
    if given > MAX_HANG_DEG and declared <= MAX_HANG_DEG:
        name = "upper arm" if "elbow" in rel else "arm"
        raise InputError(
            f"with up = {up_name} (--up-axis), the {name} never hangs within {MAX_HANG_DEG:g}° of straight down before "
            f"the reach ({given:.0f}° at best), and with {reference} ({reference_source}) it hangs within "
            f"{declared:.0f}°: is {up_name} a horizontal lab axis? Give --up-axis {reference}, or leave --up-axis out",
            src,
        )


def check_glitches(
    joints: dict[str, np.ndarray],
    rate: float,
    src: str,
    first_frame: int = 0,
    n_frames: int | None = None,
    order: int = 5,
) -> None:
    """Refuse a joint centre that jumps (the low-pass would smear the jump into the reach): faster than any arm
    moves (:data:`MAX_FINGERTIP_SPEED`), or with an acceleration from one frame to the next that no reaching arm
    has (:data:`MAX_MARKER_ACCELERATION`, or 20× the recording's own median where its noise is larger): a spike,
    a marker frozen and then caught up, or two labels swapped for a few frames. Then frames out of order
    (:func:`_check_back_steps`): a fingertip that steps back against its way of travel; where the hand moves slowly
    (:func:`_check_coherent_back_steps`), every joint of the arm stepping back at once. Then a spike of a few frames
    of the fingertip, and then of the other joints, at any speed (:func:`_check_spikes`). ``first_frame``: the
    record's frame at ``joints``' first row, for the messages; ``n_frames``: the record's frame count (a jump into
    its last frame is named as a file cut short in its last row, a number cut off); ``order``: the low-pass's."""

    def cause(f: int, usual: str) -> str:  # f: the step into row f + 1
        if n_frames is not None and first_frame + f + 2 == n_frames:
            return "the record's last frame: a file cut short in its last row?"
        return usual

    # a frame that repeats the one before it exactly, every joint, while the fingertip moves on both sides of it:
    # cameras never see that (noise alone tells two frames apart), an export that pads a frame rate with copies does,
    # and the copy is a stall mid-reach that the filter smears into its speed and onset
    tip = np.linalg.norm(np.diff(joints["fingertip"], axis=0), axis=1)
    still = np.all([np.all(np.diff(x, axis=0) == 0.0, axis=1) for x in joints.values()], axis=0)
    moving = MIN_COPY_STEP_M + 50.0 / rate**2  # what 50 m/s² (beyond a reaching hand's 10-30) takes off in a frame
    for a, b in true_runs(still):  # steps a … b - 1 are 0: rows a + 1 … b repeat row a
        if a > 0 and b < tip.shape[0] and min(tip[a - 1], tip[b]) > moving:
            first, last = first_frame + a + 2, first_frame + b + 1
            raise InputError(
                f"every joint repeats frame {first - 1} exactly, while the fingertip moves {tip[a - 1] * 1000:.0f} mm "
                f"in the frame before and {tip[b] * 1000:.0f} mm in the frame after: duplicated frames (a frame rate "
                "padded with copies)? Remove them, or blank them to be filled as a gap",
                src,
                f"frame {first}" if first == last else f"frames {first}-{last}",
            )

    for k, x in joints.items():
        step = np.linalg.norm(np.diff(x, axis=0), axis=1)
        if np.nanmax(step, initial=0.0) * rate > MAX_FINGERTIP_SPEED:
            f = int(np.nanargmax(step))
            raise InputError(
                f"the {k} moves {step[f] * 1000:.0f} mm in one frame ({step[f] * rate:.3g} m/s, faster than any "
                f"arm's {MAX_FINGERTIP_SPEED:g} m/s): {cause(f, 'a glitch in the markers?')}",
                src,
                _excursion(x, f, first_frame) or f"frame {first_frame + f + 2}",
            )
        h = max(1, round(0.01 * rate))  # frames in 10 ms: finer, a fast recording's noise (or the kinks of a
        # linear gap fill) would pass for acceleration
        if x.shape[0] < 2 * h + 1:
            continue
        acc = np.linalg.norm(x[2 * h :] - 2.0 * x[h:-h] + x[: -2 * h], axis=1) * (rate / h) ** 2  # m/s², frames h…
        if not np.isfinite(acc).any():
            continue
        limit = max(MAX_MARKER_ACCELERATION, 20.0 * float(np.nanmedian(acc)))
        worst = int(np.nanargmax(acc))
        if acc[worst] > limit:
            f = worst + int(np.nanargmax(step[worst : worst + 2 * h]))  # the largest of the steps it spans
            where = _excursion(x, f, first_frame)
            raise InputError(
                f"the {k} jumps {step[f] * 1000:.0f} mm in one frame (an acceleration of {acc[worst]:.3g} m/s², "
                f"above the limit of {limit:.3g}): "
                + cause(
                    f,
                    "a glitch, a marker frozen and caught up, or two labels swapped? Fix the labels, or blank those "
                    "frames to be filled as a gap",
                ),
                src,
                where or f"frame {first_frame + f + 2}",
            )
    _check_back_steps(joints["fingertip"], rate, src, order, first_frame, cause)
    _check_coherent_back_steps(joints, rate, src, order, first_frame, cause)
    for k in ("fingertip", *(k for k in joints if k != "fingertip")):
        _check_spikes(joints[k], k, MIN_SPIKE_M if k == "fingertip" else MIN_JOINT_SPIKE_M, src, first_frame, cause)


def _excursion(x: np.ndarray, f: int, first_frame: int, reach: int = 10) -> str | None:
    """The frames a jump of ``x`` at step ``f`` (into row ``f + 1``) took off its path, what to blank: where a step
    within ``reach`` frames jumps back (within half its size), the rows between the two jumps (a spike, or labels
    swapped for a few frames); where the rows before the jump repeat one value (a marker frozen, then caught up),
    those rows: ``"frame N"`` or ``"frames N-M"``; None otherwise."""
    jump = x[f + 1] - x[f]
    for g in sorted(range(max(0, f - reach), min(x.shape[0] - 1, f + reach + 1)), key=lambda g: abs(g - f)):
        if g != f and np.linalg.norm(x[g + 1] - x[g] + jump) < 0.5 * np.linalg.norm(jump):
            a, b = first_frame + min(f, g) + 2, first_frame + max(f, g) + 1
            return f"frame {a}" if a == b else f"frames {a}-{b}"
    held = 0
    while f - held >= 1 and np.array_equal(x[f - held], x[f - held - 1]):
        held += 1
    # rows f - held + 1 … f repeat row f - held: a freeze of a few frames (a longer run is the hand at rest, as
    # before a last row cut short)
    if 0 < held <= 2 * reach and f + 2 < x.shape[0]:
        a, b = first_frame + f - held + 2, first_frame + f + 1
        return f"frame {a}" if a == b else f"frames {a}-{b}"
    return None


def _step_noise(x: np.ndarray) -> float:
    """The SD of a step's noise along a direction (m) of a path ``x`` ``(n, 3)``, from the median absolute second
    difference per axis (a robust SD: √6 s for white noise of SD s per axis; a step's noise along a direction is
    √2 s)."""
    second = x[2:] - 2.0 * x[1:-1] + x[:-2]
    sd = np.median(np.abs(second), axis=0) / 0.6745  # per axis, √6 s
    return float(np.sqrt(np.mean(sd**2) / 3.0))  # √2 s


def _back_steps(x: np.ndarray, rate: float, order: int, min_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """``(back, travel)`` of a path ``x`` ``(n, 3)`` per step: how far it steps back against its way of travel (its
    path low-passed at :data:`~reachirl.data.segmentation.MIN_SEGMENT_CUTOFF_HZ`), ``-inf`` where that way moves
    slower than ``min_speed``, and the way's length."""
    way = np.diff(lowpass(x, rate, MIN_SEGMENT_CUTOFF_HZ, order), axis=0)  # the way of travel, per step
    travel = np.linalg.norm(way, axis=1)
    moving = travel * rate >= min_speed
    back = np.where(moving, -np.sum(np.diff(x, axis=0) * way, axis=1) / np.where(moving, travel, 1.0), -np.inf)
    return back, travel


def _check_coherent_back_steps(
    joints: Mapping[str, np.ndarray], rate: float, src: str, order: int, first_frame: int, cause
) -> None:
    """Refuse frames out of order where the hand moves slowly (the start and the end of a reach), which the
    fingertip's own back step (:func:`_check_back_steps`) cannot tell from a marker's flicker: every joint of the arm
    but the shoulder (two at least) steps back against its way of travel in the same frame, each by more than
    :data:`MIN_COHERENT_BACK_M` and :data:`COHERENT_BACK_NOISE_SDS` of its step noise, while each travels at least
    :data:`MIN_COHERENT_TRAVEL_SPEED`. UE-ADL's ADL001FR1 with 2 or 3 frames put back as many frames at the reach's
    start (0.03 m/s) steps back 0.7-1.1 mm at once and its onset came 1-4 frames later (the angles 5° apart at the
    same sample); the 80 clean reaches step back at most 0.09 mm at once."""
    names = [k for k in joints if k != "shoulder"]
    if len(names) < 2 or not rate > 2.0 * MIN_SEGMENT_CUTOFF_HZ:
        return
    if any(joints[k].shape[0] <= filter_padlen(order) or not np.isfinite(joints[k]).all() for k in names):
        return
    backs, limits = [], []
    for k in names:
        backs.append(_back_steps(joints[k], rate, order, MIN_COHERENT_TRAVEL_SPEED)[0])
        limits.append(max(MIN_COHERENT_BACK_M, COHERENT_BACK_NOISE_SDS * _step_noise(joints[k])))
    # each joint's back step as a multiple of its own limit; the least of them is the frame's
    ratio = np.min([b / lim for b, lim in zip(backs, limits, strict=True)], axis=0)
    f = int(np.argmax(ratio))
    if ratio[f] > 1.0:
        steps = ", ".join(f"the {k} {b[f] * 1000:.1f} mm" for k, b in zip(names, backs, strict=True))
        raise InputError(
            f"every joint of the arm steps back against its way of travel in the same frame ({steps}; the recording's "
            f"noise allows {', '.join(f'{lim * 1000:.1f}' for lim in limits)} mm): "
            + cause(
                f,
                "frames out of order (a block of frames put back before its place)? Put them in order, or blank "
                "them to be filled as a gap",
            ),
            src,
            f"frame {first_frame + f + 2}",
        )


#: m: the fingertip placed by a joint-angle file's angles further than this from its running median is a spike of
#: the angles (the virtual subjects' angle files, whose noise is 0.1°: at most 9.3 mm, at the peak speed, where the
#: running median cuts the path's curve; a 20° spike of one sample: 188 mm)
MIN_ANGLE_SPIKE_M = 0.025


def _check_spikes(x: np.ndarray, name: str, least: float, src: str, first_frame: int, cause) -> None:
    """Refuse a joint ``name``'s path ``x`` ``(n, 3)`` that leaves its path for a few frames and comes back: further
    than ``least`` (:data:`MIN_SPIKE_M` for the fingertip, :data:`MIN_JOINT_SPIKE_M` for the others) and
    :data:`SPIKE_NOISE_MEDIANS` times the recording's median from its running median over :data:`SPIKE_WINDOW`
    frames. The speed and acceleration checks see a jump by how fast it is: at 100 Hz a spike
    of up to 10-20 mm, or a block of frames put back while the hand moves slowly (at rest, or starting or ending its
    reach), is within any arm's 200 m/s², and the back-step check asks for 0.05 m/s of travel. Yet such a spike in the
    rest moved the reach's onset by up to 5 frames (0.05 s, the angles up to 4° apart; a block of 5 frames put back at
    the reach's slow start, 6°), since the fingertip's speed sets onset and offset. A real fingertip stays on its
    running median within 2.4 mm (UE-ADL, any speed). The other joints' spikes leave onset and offset as they are,
    but not the angles (:data:`MIN_JOINT_SPIKE_M`)."""
    w = SPIKE_WINDOW
    if x.shape[0] < w or not np.isfinite(x).all():
        return
    off = np.linalg.norm(x - median_filter(x, size=(w, 1), mode="nearest"), axis=1)
    limit = max(least, SPIKE_NOISE_MEDIANS * float(np.median(off)))
    runs = true_runs(off > limit)
    if not runs:
        return
    a, b = max(runs, key=lambda r: float(off[r[0] : r[1]].max()))  # rows a … b - 1
    worst = a + int(np.argmax(off[a:b]))
    first, last = first_frame + a + 1, first_frame + b
    raise InputError(
        f"the {name} leaves its path by {off[worst] * 1000:.0f} mm and comes back (the recording's noise allows "
        f"{limit * 1000:.1f} mm): "
        + cause(
            b - 2,
            "a spike, two labels swapped, or frames out of order? Fix them, or blank those frames to be filled as a "
            "gap",
        ),
        src,
        f"frame {first}" if first == last else f"frames {first}-{last}",
    )


def _check_back_steps(tip: np.ndarray, rate: float, src: str, order: int, first_frame: int, cause) -> None:
    """Refuse frames out of order (a block of frames re-inserted before its place: an export's or an edit's
    error): where the fingertip ``tip`` ``(n, 3)`` travels (its path low-passed at
    :data:`~reachirl.data.segmentation.MIN_SEGMENT_CUTOFF_HZ` moves at least :data:`MIN_TRAVEL_SPEED`), a step
    back against its way of travel longer than :data:`BACK_STEP_NOISE_SDS` SDs of the recording's step noise and
    than :data:`MIN_BACK_STEP_M`. Moved back by a few frames, a block makes the fingertip jump back by as many frames
    of its travel, and no hand steps back mid-reach; in a noisy recording the acceleration check lets the jump pass
    (its limit, 20× the median acceleration, is about 800 m/s² per mm of marker noise at 100 Hz: with 2 mm, a jump
    back of 15 cm between steps forward). The noise is the robust one of :func:`_step_noise`."""
    if not rate > 2.0 * MIN_SEGMENT_CUTOFF_HZ or tip.shape[0] <= filter_padlen(order) or not np.isfinite(tip).all():
        return
    back, travel = _back_steps(tip, rate, order, MIN_TRAVEL_SPEED)
    if not np.isfinite(back).any():  # nowhere moving
        return
    limit = max(BACK_STEP_NOISE_SDS * _step_noise(tip), MIN_BACK_STEP_M)
    f = int(np.argmax(back))
    if back[f] > limit:
        raise InputError(
            f"the fingertip steps {back[f] * 1000:.0f} mm back against its way of travel in one frame, while it "
            f"travels at {travel[f] * rate:.2f} m/s (the recording's noise allows {limit * 1000:.1f} mm): "
            + cause(
                f,
                "frames out of order (a block of frames put back before its place)? Put them in order, or blank "
                "them to be filled as a gap",
            ),
            src,
            f"frame {first_frame + f + 2}",
        )


#: m: the other arm's fingertip moving this far from where it mostly is, in a record where the arm asked for holds no
#: reach, is named in the refusal (a left arm's recording read as a right arm's)
OTHER_ARM_REACH_M = 0.1


def _other_arm_moves(md: MarkerData, mset: MarkerSet, side: str) -> str:
    """Words for a refusal of ``side``'s arm as still: the other arm's fingertip moves (a recording of the other
    arm: ``--side`` or the manifest's side), when the marker set names each arm's markers and the file has the
    other's, and its fingertip ranges :data:`OTHER_ARM_REACH_M` or more from its median place; else ``""``."""
    other = "left" if side == "right" else "right"
    if mset.side_prefix.get(side, "") == mset.side_prefix.get(other, ""):
        return ""
    names = [resolve_name(m, md.names) for m in mset.for_side(other).joints["fingertip"].markers]
    if not names or None in names:
        return ""
    tip = np.mean([md[n] for n in names], axis=0)
    seen = tip[np.isfinite(tip).all(axis=1)]
    if seen.shape[0] < 2:
        return ""
    extent = float(np.linalg.norm(seen - np.median(seen, axis=0), axis=1).max())
    if extent < OTHER_ARM_REACH_M:
        return ""
    return (
        f"; the {other} arm's fingertip ({'+'.join(names)}) moves {extent * 1000:.0f} mm: a recording of the "
        f"{other} arm (--side, or the manifest's side column)?"
    )


def reconstruct_markers(
    md: MarkerData,
    mset: MarkerSet,
    *,
    side: str = "right",
    static: MarkerData | None = None,
    subject_info: SubjectInfo | None = None,
    options: PreprocessOptions | None = None,
    held: list[tuple] | None = None,
) -> MarkerReconstruction:
    """Run steps 1–10 on a marker file; see the module docstring. Its warnings (the noise is large, another
    reach, no rest, a gap cut off) are said only when the record gives a reconstruction, not before a refusal:
    logged at the end, or, given ``held`` (a list), appended to it as :meth:`logging.Logger.warning` arguments for
    the caller to log once its own checks accept the trial."""
    options = options or PreprocessOptions()
    info = subject_info or DEFAULT_SUBJECT
    src = md.source
    if side not in ("right", "left"):
        raise InputError(f"side must be 'right' or 'left', got {side!r}", src)
    ms = mset.for_side(side)
    needed = ("shoulder", "elbow", "fingertip") if options.ik == "segments" else ("shoulder", "fingertip")
    if options.ik == "segments" and options.distal == "wrist":
        needed = (*needed, "wrist")
    for j in needed:
        if j not in ms.joints:
            raise InputError(f"marker set {ms.name!r} gives no {j}, needed for ik={options.ik!r}", src)
    if md.n_frames < 10:
        raise InputError(f"only {md.n_frames} frame{'s' if md.n_frames != 1 else ''}, too few for a reach", src)
    positions = joint_positions(md, ms, static)
    window = seen_window(positions, options.max_gap_frames, src, max(10, filter_padlen(options.filter_order) + 1))
    cropped = slice(window.start, window.stop)
    joints = {j: fill_gaps(p[cropped], options.max_gap_frames, label, src) for j, (p, label) in positions.items()}
    # the arm from every frame where its joints are seen, cut off or not: the same reach, the same arm
    lengths = estimate_lengths({j: p for j, (p, _) in positions.items()})
    check_units(lengths, options, src)

    # the first given of: --up-axis, the file's own statement, the marker set's, the format's convention
    sources = (
        (options.up_axis, "--up-axis"),
        (md.up if md.up_declared else None, "the file's own"),
        (ms.up, f"marker set {ms.name!r}"),
    )
    up_spec, up_source = next(((a, w) for a, w in sources if a), (md.up, "the format's convention"))
    up = lab_axis(up_spec)
    if side == "left":
        if options.lateral_axis:
            lateral = lab_axis(options.lateral_axis)
        else:  # the horizontal lab axis along which the fingertip ranges least
            rng = np.ptp(joints["fingertip"], axis=0)
            cand = [k for k in range(3) if abs(up[k]) < 0.5]
            lateral = np.eye(3)[min(cand, key=lambda k: rng[k])]
        joints = mirror(joints, lateral)
    else:
        lateral = None

    check_glitches(joints, md.rate, src, first_frame=window.start, n_frames=md.n_frames, order=options.filter_order)
    raw_fingertip = joints["fingertip"]
    if options.cutoff_hz is not None:
        joints = {k: lowpass(v, md.rate, options.cutoff_hz, options.filter_order, src) for k, v in joints.items()}
    t = md.t[cropped]
    vel = np.gradient(joints["fingertip"], t, axis=0)
    speed = np.linalg.norm(vel, axis=1)
    # noise alone can carry the speed above min_peak_speed (1 mm of it gives 0.1 m/s at 10 Hz), and the shoulder's
    # noisy path beyond the fingertip's: a reach also takes the fingertip further than noise does
    distance = float(np.median(np.linalg.norm(joints["fingertip"] - joints["shoulder"], axis=1)))
    rest = _rest_only(raw_fingertip, distance, md.rate, options.filter_order, "marker noise")
    still = not np.isfinite(speed).all() or speed.max() < options.min_peak_speed
    if still or rest is not None:
        if window.gaps:  # the movement is in a gap
            label, s0, e0 = max(window.gaps, key=lambda g: g[2] - g[1])
            raise InputError(
                f"{gap_message(label, s0, e0, options.max_gap_frames)}, and no reach is seen outside the long gaps",
                src,
            )
        other_arm = _other_arm_moves(md, mset, side)
        if still:
            raise InputError(
                f"no movement detected: the fingertip's peak speed is {np.nanmax(speed):.3g} m/s "
                f"(< {options.min_peak_speed:g} m/s){other_arm}",
                src,
            )
        raise InputError(rest + other_arm, src)
    path = {k: float(np.sum(np.linalg.norm(np.diff(joints[k], axis=0), axis=1))) for k in ("shoulder", "fingertip")}
    if path["shoulder"] > path["fingertip"]:
        # in a reach the fingertip travels furthest and the shoulder least; the other way round, the marker map
        # is upside down (the reach would be planned from a nonsense posture)
        raise InputError(
            f"the shoulder travels {path['shoulder']:.2f} m and the fingertip {path['fingertip']:.2f} m: are the "
            "markers swapped? (check --markers or the marker set)",
            src,
        )
    reach = np.linalg.norm(joints["fingertip"] - joints["fingertip"][0], axis=1)  # away from where it rested
    # the warnings wait for the record to be accepted (_release): cut at a gap inside the reach, the record holds a
    # fragment of it, whose peak speed makes the noise look large, and the gap is then refused; an up axis or a
    # joint limit refused after the cut is the only thing to say of the record
    notes: list[tuple] = []
    noise: list[tuple] = []
    seg_speed = segmentation_speed(t, raw_fingertip, speed, options, src, filtered=joints["fingertip"], held=noise)
    onset, offset = detect_onset_offset(seg_speed, options.onset_threshold, reach)
    if offset - onset + 1 < 4:
        raise InputError(f"no movement detected: the reach lasts {offset - onset + 1} frames", src)
    if window.gaps:
        seen = np.all([seen_frames(p[cropped]) for p, _ in positions.values()], axis=0)
        _check_window(
            window, onset, offset, seen, positions, joints["fingertip"], md.rate, options.max_gap_frames, src, notes
        )
    notes += noise  # after the gaps cut off, as the record is read
    other = other_reach(seg_speed, options.onset_threshold, joints["fingertip"], onset, offset)
    if other is not None:
        notes.append(
            (
                "%s: the recording holds another reach (%.2f-%.2f s); the trial is the faster one, at %.2f-%.2f s. "
                "Cut the recording to one reach per file to keep the other",
                src,
                t[other[0]],
                t[other[1]],
                t[onset],
                t[offset],
            )
        )
    cut = {"before": onset == 0, "after": offset == len(t) - 1}  # beside a gap cut off, _check_window refused it
    if all(cut.values()):
        notes.append(
            (
                "%s: no rest before or after the movement; the record's edges are used: the reach may be a fragment "
                "of a longer movement",
                src,
            )
        )
    elif any(cut.values()):
        notes.append(
            ("%s: no rest %s the movement; the record's edge is used", src, "before" if onset == 0 else "after")
        )
    rel = {k: v - joints["shoulder"] for k, v in joints.items() if k != "shoulder"}
    disp = joints["fingertip"][offset] - joints["fingertip"][onset]
    fwd = lab_axis(options.forward_axis) if options.forward_axis else None
    basis = sagittal_basis({k: v[onset : offset + 1] for k, v in rel.items()}, up, disp, options, fwd, src)
    planar = {k: v @ basis[:2].T for k, v in rel.items()}
    if options.plane != "axes":  # --plane axes checks its axes against the reach itself (sagittal_basis)
        source = up_source if options.up_axis else f"{up_source}; give --up-axis"
        check_up_axis(rel, basis, up, onset, offset, t, f"{up_spec} ({source})", src)
    if options.up_axis:  # against the recording's own up, else its marker set's, else its format's convention
        ref_spec, ref_source = next(((a, w) for a, w in sources[1:] if a), (md.up, "the format's convention"))
        ref_source = (
            ref_source + " up" if ref_source == "the file's own" else ref_source.replace("marker", "the up of marker")
        )
        check_given_up(rel, up, up_spec, ref_spec, ref_source, onset, src, lateral)

    if subject_info is not None:  # lengths given in the subject info must agree with the markers'
        from .checks import check_segment_lengths

        ua, fa, hand = info.lengths(side)
        check_segment_lengths({"upper_arm_m": ua, "forearm_m": fa, "hand_m": hand}, lengths, src, info.subject)
    arm = build_arm(info, side, lengths)
    if options.ik == "segments":
        q = planar_ik_segments(planar["elbow"], planar[options.distal])
    else:
        try:
            q = arm.ik(planar["fingertip"])
        except ValueError as e:
            raise InputError(f"fingertip IK failed: {e}; the arm is too short for the markers", src) from None
    qd, qdd = derivatives(t, q)
    rec = MarkerReconstruction(
        t=t,
        q=q,
        qd=qd,
        qdd=qdd,
        fingertip=planar["fingertip"],
        speed=speed,
        onset=onset,
        offset=offset,
        arm=arm,
        lengths=lengths,
        basis=basis,
        joints=joints,
        side=side,
        source=src,
        first_frame=window.start,
    )
    _release(notes, held)
    return rec


def _to_trial(
    t,
    q,
    qd,
    qdd,
    arm: ArmModel,
    target_x: float,
    onset: int,
    offset: int,
    *,
    subject: str,
    posture: str,
    trial_id: str,
    side: str,
    source: str,
    options: PreprocessOptions,
) -> Trial:
    sl = slice(onset, offset + 1)
    if not abs(target_x) < arm.length:
        raise InputError(
            f"the target (fingertip x {target_x:.3f} m at offset) is unreachable by the arm "
            f"({arm.l1:.3f} + {arm.l2:.3f} = {arm.length:.3f} m); check the segment lengths",
            source,
        )
    tau = arm.inverse_dynamics(q[sl], qd[sl], qdd[sl])
    cut = 0 < onset and offset < t.shape[0] - 1  # rest before and after: both ends are threshold crossings
    trial = Trial(
        subject=subject,
        posture=posture,
        trial_id=trial_id,
        t=t[sl] - t[onset],
        q=q[sl],
        qd=qd[sl],
        qdd=qdd[sl],
        tau=tau,
        target_x=target_x,
        arm=arm,
        side=side,
        source=source,
        onset_threshold=options.onset_threshold if cut else None,
    )
    return trial.resample(options.n_samples) if options.n_samples else trial


def markers_to_trial(
    md: MarkerData,
    mset: MarkerSet,
    *,
    subject: str,
    posture: str,
    trial_id: str,
    side: str = "right",
    static: MarkerData | None = None,
    subject_info: SubjectInfo | None = None,
    options: PreprocessOptions | None = None,
    held: list[tuple] | None = None,
) -> Trial:
    """A marker file → one :class:`Trial` (onset→offset). Its warnings are said once the trial is made, or held
    (see :func:`reconstruct_markers`)."""
    options = options or PreprocessOptions()
    notes: list[tuple] = []
    rec = reconstruct_markers(
        md, mset, side=side, static=static, subject_info=subject_info, options=options, held=notes
    )
    trial = _to_trial(
        rec.t,
        rec.q,
        rec.qd,
        rec.qdd,
        rec.arm,
        float(rec.fingertip[rec.offset, 0]),
        rec.onset,
        rec.offset,
        subject=subject,
        posture=posture,
        trial_id=trial_id,
        side=side,
        source=md.source,
        options=options,
    )
    _release(notes, held)
    return trial


# ---------------------------------------------------------------------- angles → trial
def angles_to_trial(
    ad: AngleData,
    *,
    subject: str,
    posture: str,
    trial_id: str,
    side: str = "right",
    subject_info: SubjectInfo | None = None,
    options: PreprocessOptions | None = None,
    held: list[tuple] | None = None,
) -> Trial:
    """Joint angles (model convention) → one :class:`Trial`.

    The arm comes from the subject info (lengths or Dumas' means scaled by height). Non-uniform samples are
    first interpolated onto a uniform grid at the median rate (samples missing, a step several times the others,
    are a gap: refused beyond ``max_gap_frames`` of them, as a marker's); then the angles are low-passed (skipped,
    with a log note, when the rate is too low for the cutoff), the fingertip speed from forward kinematics gives
    onset and offset, and q̇, q̈, τ follow as for markers. A record whose fingertip ranges over less than
    :data:`MIN_REACH_RANGE` of its distance from the shoulder is refused as for markers (rest and angle noise).
    Left arms' angles are taken as already in the model convention. Its warning (the noise is large) is said once
    the trial is made, or held (see :func:`reconstruct_markers`).
    """
    options = options or PreprocessOptions()
    info = subject_info or DEFAULT_SUBJECT
    src = ad.source
    arm = build_arm(info, side)
    t, q = ad.t, ad.q
    dt = np.diff(t)
    hole = int(np.argmax(dt))
    missing = round(float(dt[hole] / np.median(dt))) - 1  # samples a step skips: a gap, bridged as markers' are
    if missing > options.max_gap_frames:
        raise InputError(
            f"{missing} samples are missing between samples {hole + 1} and {hole + 2} (the time steps "
            f"{dt[hole]:.4g} s where the recording's steps are {np.median(dt):.4g} s), more than the "
            f"{options.max_gap_frames} a gap may last (--max-gap)",
            src,
        )
    if np.ptp(dt) > 0.01 * np.median(dt):
        t_u = np.arange(t[0], t[-1] + 1e-12, np.median(dt))
        q = CubicSpline(t, q, axis=0)(t_u)
        t = t_u
    rate = 1.0 / float(np.median(np.diff(t)))
    q_seen = q
    if options.cutoff_hz is not None:
        if options.cutoff_hz < rate / 2 and t.shape[0] > filter_padlen(options.filter_order):
            q = lowpass(q, rate, options.cutoff_hz, options.filter_order, src)
        else:
            log.info("%s: %d samples at %.3g Hz, not filtered", src, t.shape[0], rate)
    qd, qdd = derivatives(t, q)
    speed = arm.fingertip_speed(q, qd)
    if speed.max() < options.min_peak_speed:
        slow_clock = rate < 5.0  # a motion-capture rate is tens of Hz or more: a time column in other units
        raise InputError(
            f"no movement detected: the fingertip's peak speed is {speed.max():.3g} m/s "
            f"(< {options.min_peak_speed:g} m/s)"
            + (
                f"; the time column gives {t.shape[0]} samples over {t[-1] - t[0]:.4g} s, {rate:.3g} Hz: "
                "milliseconds, not seconds?"
                if slow_clock
                else ""
            ),
            src,
        )
    tip = arm.fk(q_seen)
    # a spike of the angles, as of the markers: the fingertip they place leaves its path for a few samples (a 20°
    # spike of one sample was taken in: a peak speed twice the reach's)
    tip3 = np.column_stack([tip, np.zeros(tip.shape[0])])
    _check_spikes(tip3, "fingertip (from the angles)", MIN_ANGLE_SPIKE_M, src, 0, lambda f, usual: usual)
    # as for markers: the angles' noise at rest (0.1° is about 1 mm at the fingertip) carries the speed above
    # min_peak_speed, and onset and offset were found in it
    rest = _rest_only(tip, float(np.median(np.linalg.norm(tip, axis=1))), rate, options.filter_order, "angle noise")
    if rest is not None:
        raise InputError(rest, src)
    notes: list[tuple] = []
    onset, offset = detect_onset_offset(
        segmentation_speed(t, tip, speed, options, src, held=notes),
        options.onset_threshold,
        np.linalg.norm(tip - tip[0], axis=1),  # away from where it rested: the reach, not a return
    )
    if offset - onset + 1 < 4:
        raise InputError(f"no movement detected: the reach lasts {offset - onset + 1} samples", src)
    target_x = float(arm.fk(q[offset])[0])
    trial = _to_trial(
        t,
        q,
        qd,
        qdd,
        arm,
        target_x,
        onset,
        offset,
        subject=subject,
        posture=posture,
        trial_id=trial_id,
        side=side,
        source=src,
        options=options,
    )
    _release(notes, held)
    return trial
