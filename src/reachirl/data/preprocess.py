"""From marker trajectories (or joint angles) to a validated :class:`~reachirl.data.trial.Trial`.

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
   10 ms, is an :class:`InputError` naming the frame.
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
   (:func:`other_reach`), and the faster one is kept.
7. **Sagittal plane** (:func:`sagittal_basis`): ``"pca"`` (default), the principal plane (SVD) of the arm's
   joint centres relative to the shoulder over the movement, as Berret; its up axis is the lab's up (opposite
   gravity) projected on the plane, its forward axis normal to up in the plane, pointing where the fingertip
   moves. When that plane is ill-defined (a flat point cloud: 3rd singular value > ``pca_max_flatness`` × the
   2nd, or more than ``pca_max_tilt_deg`` from vertical: an arm that stays near-horizontal, as in some UE-ADL
   reaches) it falls back, with a log note, to ``"vertical"``: the vertical plane through the fingertip's main
   horizontal direction of travel. ``"axes"`` takes given lab axes. The shoulder, frame by frame, is the
   origin.
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

Nothing here prints; problems are :class:`InputError` with the file and frame, notes go to ``logging``.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt, sosfreqz

from ..arm import DUMAS_2007, ArmModel
from ..errors import InputError
from .markersets import MarkerSet, resolve_name
from .readers import AngleData, MarkerData, SubjectInfo
from .trial import Trial

__all__ = [
    "DEFAULT_SUBJECT",
    "MarkerReconstruction",
    "PreprocessOptions",
    "angles_to_trial",
    "calibrate_static",
    "cast_reconstruct",
    "detect_onset_offset",
    "estimate_lengths",
    "fill_gaps",
    "joint_positions",
    "kabsch",
    "lowpass",
    "markers_to_trial",
    "mirror",
    "planar_ik_segments",
    "reconstruct_markers",
    "sagittal_basis",
    "seen_window",
    "segmentation_cutoff",
    "segmentation_speed",
]

log = logging.getLogger(__name__)

#: m/s: a human fingertip peaks near 1-3 m/s in a reach and below 20 m/s in a throw; faster is a glitch
MAX_FINGERTIP_SPEED = 30.0
#: m/s²: a reaching hand's markers peak near 10-30 m/s² (about 3 g); 20 g from one frame to the next is a glitch
MAX_MARKER_ACCELERATION = 200.0

#: s: a record cut at a gap longer than gap filling allows must show this much rest between the gap and the reach
#: (the reach's onset or offset is then seen, not inferred at the gap's edge)
MIN_SEEN_REST_S = 0.1
#: m: how far the fingertip may drift across a gap cut off as rest (a hand at rest drifts by millimetres)
MAX_REST_DRIFT_M = 0.02
#: the least fingertip movement, as a fraction of the shoulder-to-fingertip distance, of a reach seen beside a gap
#: cut off (the virtual subjects' bars lie at least 0.1 arm lengths beyond the start)
MIN_CUT_REACH = 0.1

#: The subject used when no subject-info is given: Berret et al. 2011's mean subject (male, 1.76 m, 69.9 kg).
DEFAULT_SUBJECT = SubjectInfo(subject="default", sex="M", height_m=1.76, mass_kg=69.9)


@dataclass(frozen=True)
class PreprocessOptions:
    """Every preprocessing choice; see the module docstring for what each step does."""

    max_gap_frames: int = 10
    cutoff_hz: float | None = 10.0  # None: no filtering
    filter_order: int = 5
    onset_threshold: float = 0.05  # fraction of the peak fingertip speed
    segment_cutoff_hz: float | str | None = "auto"  # low-pass of the speed that finds onset/offset (Hz, or
    # "auto": as low as the markers' noise needs, see segmentation_cutoff); None: cutoff_hz's speed (Berret)
    min_peak_speed: float = 0.05  # m/s; below it there is no movement
    plane: str = "pca"  # "pca" | "vertical" | "axes"
    up_axis: str | None = None  # lab axis opposite gravity, e.g. "+z"; None: the file format's convention
    forward_axis: str | None = None  # for plane="axes"; None: the horizontal lab axis the fingertip moves along
    lateral_axis: str | None = None  # for mirroring; None: the horizontal lab axis normal to the movement
    ik: str = "segments"  # "segments" | "fingertip"
    distal: str = "fingertip"  # q2 from elbow→"fingertip" or elbow→"wrist" (ik="segments")
    n_samples: int | None = None  # resample onset→offset to this many points (Berret: 200); None keeps frames
    segment_range_m: tuple[float, float] = (
        0.08,
        0.9,
    )  # plausible median joint-centre distances (units check)
    pca_max_tilt_deg: float = 30.0  # a principal plane further than this from vertical is not trusted ...
    pca_max_flatness: float = 0.5  # ... nor one whose 3rd singular value exceeds this × the 2nd; then "vertical"

    def __post_init__(self) -> None:
        if self.plane not in ("pca", "vertical", "axes"):
            raise ValueError(f"plane must be 'pca', 'vertical' or 'axes', got {self.plane!r}")
        if self.ik not in ("segments", "fingertip"):
            raise ValueError(f"ik must be 'segments' or 'fingertip', got {self.ik!r}")
        if self.distal not in ("fingertip", "wrist"):
            raise ValueError(f"distal must be 'fingertip' or 'wrist', got {self.distal!r}")
        if not 0 < self.onset_threshold < 1:
            raise ValueError(f"onset_threshold must be in (0, 1), got {self.onset_threshold}")
        if self.max_gap_frames < 0:
            raise ValueError("max_gap_frames must be >= 0")
        if self.cutoff_hz is not None and self.cutoff_hz <= 0:
            raise ValueError("cutoff_hz must be > 0 or None")
        fc = self.segment_cutoff_hz
        if fc is not None and fc != "auto" and (isinstance(fc, str) or not fc > 0):
            raise ValueError(f"segment_cutoff_hz must be 'auto', a number > 0 or None, got {fc!r}")
        if self.n_samples is not None and self.n_samples < 4:
            raise ValueError("n_samples must be >= 4")


# ---------------------------------------------------------------------- small steps
def _axis(spec: str) -> np.ndarray:
    s = spec.strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    key = s.lstrip("+-")
    if key not in ("x", "y", "z"):
        raise InputError(f"axis must be one of ±x, ±y, ±z, got {spec!r}")
    v = np.zeros(3)
    v["xyz".index(key)] = sign
    return v


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs ``[start, end)`` of True in a boolean ``(n,)`` mask."""
    d = np.diff(np.r_[0, np.asarray(mask, dtype=int), 0])
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)]


def _seen(x: np.ndarray) -> np.ndarray:
    """The frames of ``x`` (``(n,)`` or ``(n, d)``) with every coordinate seen (finite)."""
    return np.all(np.isfinite(np.asarray(x, dtype=float).reshape(np.shape(x)[0], -1)), axis=1)


def long_gaps(x: np.ndarray, max_gap: int) -> list[tuple[int, int]]:
    """The runs ``[start, end)`` of unseen frames of ``x`` (``(n,)`` or ``(n, d)``) longer than ``max_gap``."""
    return [(s, e) for s, e in _runs(~_seen(x)) if e - s > max_gap]


def _gap_where(start: int, end: int) -> str:
    """Frames ``[start, end)`` (0-based) in words, 1-based: ``in frame 21``, ``for 20 frames (21-40)``."""
    return f"in frame {end}" if end - start == 1 else f"for {end - start} frames ({start + 1}-{end})"


def _gap_message(name: str, start: int, end: int, max_gap: int) -> str:
    where = _gap_where(start, end)
    if max_gap == 0:
        return f"marker {name} is missing {where}, and gap filling is off (--max-gap 0)"
    limit = "1 frame" if max_gap == 1 else f"{max_gap} frames"
    return f"marker {name} is missing {where}, longer than the {limit} gap filling allows (--max-gap)"


def fill_gaps(x: np.ndarray, max_gap: int, name: str = "marker", source: object | None = None) -> np.ndarray:
    """Fill runs of NaN frames of ``x`` (``(n,)`` or ``(n, d)``) no longer than ``max_gap``.

    Interior runs by a cubic spline through the seen frames, runs at the ends by the nearest seen value. A
    longer run, or a marker never seen, raises :class:`InputError` naming ``name`` and the frames (1-based).
    """
    x = np.array(x, dtype=float)
    flat = x.reshape(x.shape[0], -1)
    missing = ~_seen(flat)
    if not missing.any():
        return x
    n = missing.shape[0]
    if missing.all():
        raise InputError(f"marker {name} is never seen", source)
    for s, e in _runs(missing):
        if e - s > max_gap:
            raise InputError(_gap_message(name, s, e, max_gap), source)
    seen = np.flatnonzero(~missing)
    out = flat.copy()
    if seen.size >= 2:
        cs = CubicSpline(seen, flat[seen], axis=0)
        interior = missing & (np.arange(n) > seen[0]) & (np.arange(n) < seen[-1])
        out[interior] = cs(np.flatnonzero(interior))
    out[: seen[0]] = flat[seen[0]]
    out[seen[-1] + 1 :] = flat[seen[-1]]
    return out.reshape(x.shape)


def _filter_padlen(order: int) -> int:
    """The edge padding of :func:`lowpass`'s ``sosfiltfilt`` (a record must be longer than this)."""
    return 3 * (2 * ((order + 1) // 2) + 1)


@functools.lru_cache(maxsize=64)
def _butter_sos(order: int, wn: float) -> np.ndarray:
    """The low-pass Butterworth's second-order sections (designed once per order and normalised cutoff: a trial
    filters every marker alike)."""
    sos = butter(order, wn, btype="low", output="sos")
    sos.flags.writeable = False  # shared by every call: each takes a copy (sosfiltfilt needs a writable one)
    return sos


def lowpass(x: np.ndarray, rate: float, cutoff_hz: float, order: int = 5, source: object | None = None):
    """Zero-lag Butterworth low-pass along axis 0 (``butter(order, cutoff)`` applied forward and backward)."""
    x = np.asarray(x, dtype=float)
    nyq = rate / 2.0
    if cutoff_hz >= nyq:
        raise InputError(
            f"the {cutoff_hz:g} Hz low-pass needs a sampling rate above {2 * cutoff_hz:g} Hz, got {rate:g} Hz",
            source,
        )
    sos = _butter_sos(order, cutoff_hz / nyq).copy()
    padlen = _filter_padlen(order)
    if x.shape[0] <= padlen:
        raise InputError(f"too short to filter: {x.shape[0]} frames, need more than {padlen}", source)
    return sosfiltfilt(sos, x, axis=0)


def kabsch(ref: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid transform with ``cur ≈ ref @ R.T + t``; ``ref``, ``cur`` are ``(..., k, 3)``.

    Returns ``R (..., 3, 3)`` (a proper rotation) and ``t (..., 3)``.
    """
    ref = np.asarray(ref, dtype=float)
    cur = np.asarray(cur, dtype=float)
    rc, cc = ref.mean(axis=-2, keepdims=True), cur.mean(axis=-2, keepdims=True)
    H = np.swapaxes(ref - rc, -1, -2) @ (cur - cc)  # (..., 3, 3)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros(H.shape)
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    R = np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)
    t = cc[..., 0, :] - np.einsum("...ij,...j->...i", R, rc[..., 0, :])
    return R, t


def cast_reconstruct(cluster: np.ndarray, ref_cluster: np.ndarray, ref_point: np.ndarray) -> np.ndarray:
    """Carry ``ref_point`` (static) into each frame by the rigid fit of ``cluster (n, k, 3)`` to ``ref_cluster
    (k, 3)``. Frames with fewer than 3 seen cluster markers give NaN."""
    cluster = np.asarray(cluster, dtype=float)
    n, k, _ = cluster.shape
    seen = np.all(np.isfinite(cluster), axis=2)
    out = np.full((n, 3), np.nan)
    full = seen.all(axis=1)
    if full.any():
        R, t = kabsch(np.broadcast_to(ref_cluster, (int(full.sum()), k, 3)), cluster[full])
        out[full] = np.einsum("nij,j->ni", R, ref_point) + t
    for i in np.flatnonzero(~full & (seen.sum(axis=1) >= 3)):
        R, t = kabsch(ref_cluster[seen[i]], cluster[i, seen[i]])
        out[i] = R @ ref_point + t
    return out


def _marker(md: MarkerData, name: str, role: str) -> np.ndarray:
    found = resolve_name(name, md.names)
    if found is None:
        shown = ", ".join(md.names[:12]) + (" …" if len(md.names) > 12 else "")
        raise InputError(f"marker {name!r} ({role}) not found (markers: {shown})", md.source)
    return md[found]


def calibrate_static(static: MarkerData, mset: MarkerSet) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """For each joint given by landmarks: ``(ref_cluster (k, 3), ref_point (3,))`` from the static trial, the
    mean
    over the frames where the cluster and the landmarks are all seen."""
    out = {}
    for joint, spec in mset.joints.items():
        if not spec.needs_static:
            continue
        cl = np.stack([_marker(static, m, f"{joint} cluster") for m in spec.cluster], axis=1)
        lm = np.stack([_marker(static, m, f"{joint} landmark") for m in spec.landmarks], axis=1)
        ok = np.all(np.isfinite(cl), axis=(1, 2)) & np.all(np.isfinite(lm), axis=(1, 2))
        if not ok.any():
            raise InputError(
                f"no frame sees the {joint}'s cluster {list(spec.cluster)} and landmarks "
                f"{list(spec.landmarks)} together",
                static.source,
            )
        out[joint] = (cl[ok].mean(axis=0), lm[ok].mean(axis=(0, 1)))
    return out


def joint_positions(
    md: MarkerData, mset: MarkerSet, static: MarkerData | None = None
) -> dict[str, tuple[np.ndarray, str]]:
    """``{joint: ((n, 3) in metres, NaN where unseen; its label for messages)}`` for every joint of the
    (side-resolved) marker set, before gap filling."""
    calib = {}
    if mset.needs_static:
        if static is None:
            raise InputError(
                f"marker set {mset.name!r} needs a static trial (--static) to place the joint centres",
                md.source,
            )
        calib = calibrate_static(static, mset)
    out = {}
    for joint, spec in mset.joints.items():
        if spec.markers:
            if spec.optional and any(resolve_name(m, md.names) is None for m in spec.markers):
                continue
            arrs = [_marker(md, m, joint) for m in spec.markers]
            for m, a in zip(spec.markers, arrs, strict=True):
                if np.isnan(a).all():
                    raise InputError(f"marker {m!r} ({joint}) is empty in every frame", md.source)
            out[joint] = (np.mean(arrs, axis=0), "+".join(spec.markers))
        else:
            cl = np.stack([_marker(md, m, f"{joint} cluster") for m in spec.cluster], axis=1)
            label = f"{joint} cluster {'/'.join(spec.cluster)} (fewer than 3 of its markers seen)"
            out[joint] = (cast_reconstruct(cl, *calib[joint]), label)
    return out


class SeenWindow(NamedTuple):
    """The frames ``[start, stop)`` of a record that :func:`seen_window` keeps, and the gaps longer than gap
    filling allows outside them (``(label, start, end)``, frames ``[start, end)`` of the record)."""

    start: int
    stop: int
    gaps: tuple[tuple[str, int, int], ...]


def seen_window(
    positions: Mapping[str, tuple[np.ndarray, str]], max_gap: int, source: object = None, min_frames: int = 10
) -> SeenWindow:
    """Where a record with gaps longer than ``max_gap`` can still give a trial: of the stretches of at least
    ``min_frames`` between such gaps (of any joint), the one where the arm extends most (the fingertip's largest
    gain in distance from the shoulder over the stretch's first seen frame), which holds the reach rather than
    rest or a return; the whole record when no gap is that long. :func:`reconstruct_markers` then checks that
    every gap cut off lies in the rest (:func:`_check_window`)."""
    for p, label in positions.values():
        if not _seen(p).any():
            raise InputError(f"marker {label} is never seen", source)
    n = next(iter(positions.values()))[0].shape[0]
    blocked = np.zeros(n, dtype=bool)
    gaps = []
    for p, label in positions.values():
        for s, e in long_gaps(p, max_gap):
            blocked[s:e] = True
            gaps.append((label, s, e))
    if not gaps:
        return SeenWindow(0, n, ())
    gaps.sort(key=lambda g: g[1])
    distance = np.linalg.norm(positions["fingertip"][0] - positions["shoulder"][0], axis=1)  # NaN where unseen

    def extension(run: tuple[int, int]) -> float:
        d = distance[run[0] : run[1]]
        d = d[np.isfinite(d)]
        return float(d.max() - d[0]) if d.size >= 2 else -1.0

    runs = [r for r in _runs(~blocked) if r[1] - r[0] >= min_frames and extension(r) >= 0.0]
    if not runs:
        label, s, e = gaps[0]
        raise InputError(_gap_message(label, s, e, max_gap), source)
    start, stop = max(runs, key=extension)
    return SeenWindow(start, stop, tuple(gaps))


def mirror(points: Mapping[str, np.ndarray], lateral: np.ndarray) -> dict[str, np.ndarray]:
    """Reflect 3-D points across the plane normal to the unit vector ``lateral`` (left arm → right arm)."""
    lateral = np.asarray(lateral, dtype=float)
    P = np.eye(3) - 2 * np.outer(lateral, lateral)
    return {k: np.asarray(v) @ P.T for k, v in points.items()}


SEGMENT_NOISE_FRACTION = 0.25  # "auto": the onset speed's marker noise at most this fraction of the threshold
MIN_SEGMENT_CUTOFF_HZ = 3.0  # "auto" goes no lower: below it the filter reshapes a reach's speed profile


@functools.lru_cache(maxsize=256)
def _noise_gains(rate: float, cutoff_hz: float, order: int) -> tuple[float, float]:
    """For white noise of variance 1 on one axis: the variance left in ``x − lowpass(x)`` and the variance of
    ``gradient(lowpass(x))`` (the zero-lag filter's power response is ``|H|⁴``, the central difference's
    ``(rate · sin ω)²``)."""
    sos = butter(order, cutoff_hz / (rate / 2.0), btype="low", output="sos")
    w = np.linspace(0.0, np.pi, 4097)
    h2 = np.abs(sosfreqz(sos, worN=w)[1]) ** 2  # filtfilt's amplitude response
    return float(np.mean((1.0 - h2) ** 2)), float(np.mean(h2**2 * (rate * np.sin(w)) ** 2))


def segmentation_cutoff(
    t: np.ndarray,
    points: np.ndarray,
    peak_speed: float,
    options: PreprocessOptions,
    source: object | None = None,
    filtered: np.ndarray | None = None,
) -> float | None:
    """The low-pass cutoff (Hz) of the speed that finds onset and offset, or ``None`` for the angles' own
    ``cutoff_hz`` speed (Berret's).

    A number in ``options.segment_cutoff_hz`` is used as given (when below ``cutoff_hz``). ``"auto"`` measures
    the markers' noise and lowers the cutoff only as far as it must: the noise is the RMS of ``points`` above
    ``cutoff_hz`` (what the angles' filter removes, rescaled by the share of white noise it holds); from it
    the filter's response predicts the RMS noise of the speed at each cutoff, and the highest cutoff (in
    0.5 Hz steps, not below ``MIN_SEGMENT_CUTOFF_HZ``) whose noise is at most ``SEGMENT_NOISE_FRACTION`` of
    the threshold speed (``onset_threshold`` × ``peak_speed``) is taken. Clean recordings keep the
    ``cutoff_hz`` speed; 1.5 mm of noise on a 0.8 m/s reach at 100 Hz gives about 4 Hz. ``filtered`` is
    ``points`` already low-passed at ``cutoff_hz``, when the caller has it."""
    fc, base = options.segment_cutoff_hz, options.cutoff_hz
    if fc is None or base is None:
        return None
    rate = 1.0 / float(np.median(np.diff(t)))
    if t.shape[0] <= _filter_padlen(options.filter_order) or base >= rate / 2:
        return None
    if fc != "auto":
        return float(fc) if float(fc) < base else None
    points = np.asarray(points, dtype=float).reshape(t.shape[0], -1)
    if filtered is None:
        filtered = lowpass(points, rate, base, options.filter_order, source)
    gains = functools.partial(_noise_gains, round(rate, 6), order=options.filter_order)  # cached per rate
    noise_var = float(np.mean((points - filtered.reshape(points.shape)) ** 2)) / gains(float(base))[0]  # per axis

    def speed_noise(f: float) -> float:
        return float(np.sqrt(points.shape[1] * noise_var * gains(float(f))[1]))

    target = SEGMENT_NOISE_FRACTION * options.onset_threshold * peak_speed
    if speed_noise(base) <= target:
        return None
    for f in np.arange(base - 0.5, MIN_SEGMENT_CUTOFF_HZ - 1e-9, -0.5):
        if speed_noise(f) <= target:
            return float(f)
    log.warning(
        "%s: the recording's noise (%.2g mm RMS, markers or angles seen at the fingertip) is large for a reach "
        "this slow; onset and offset are "
        "found on a %g Hz speed and may still wander",
        source,
        np.sqrt(noise_var) * 1000,
        MIN_SEGMENT_CUTOFF_HZ,
    )
    return MIN_SEGMENT_CUTOFF_HZ


def segmentation_speed(
    t: np.ndarray,
    points: np.ndarray,
    speed: np.ndarray,
    options: PreprocessOptions,
    source: object | None = None,
    filtered: np.ndarray | None = None,
) -> np.ndarray:
    """The fingertip speed that onset and offset are found on: ``points`` ``(n, d)`` (the fingertip, before
    the angles' filter) low-passed at :func:`segmentation_cutoff`, differentiated and normed; ``speed`` (the
    ``cutoff_hz`` speed) as is when that is ``None``. ``filtered``: see :func:`segmentation_cutoff`."""
    fc = segmentation_cutoff(t, points, float(np.max(speed)), options, source, filtered)
    if fc is None:
        return speed
    rate = 1.0 / float(np.median(np.diff(t)))
    smooth = lowpass(points, rate, fc, options.filter_order, source)
    return np.linalg.norm(np.gradient(smooth, t, axis=0), axis=1)


def detect_onset_offset(speed: np.ndarray, threshold: float = 0.05, reach: np.ndarray | None = None) -> tuple[int, int]:
    """Onset and offset frames (inclusive) of the main movement: around the speed peak, the first frames
    where the speed falls below ``threshold`` × peak bound the movement. Without rest before (after), the
    record's first (last) frame is used.

    ``reach`` (the fingertip's distance from where the recording starts, per frame): a recording may hold the
    reach and the return from it. When the fastest movement brings the fingertip back towards its start and
    another one, separated from it by rest, takes it away, that one is the reach."""
    speed = np.asarray(speed, dtype=float)
    p = int(np.argmax(speed))
    thr = threshold * speed[p]
    if reach is not None:
        p = _reaching_peak(speed, thr, np.asarray(reach, dtype=float), p)
        thr = threshold * speed[p]  # the reach's own peak
    below_before = np.flatnonzero(speed[:p] < thr)
    below_after = np.flatnonzero(speed[p:] < thr)
    onset = int(below_before[-1]) + 1 if below_before.size else 0
    offset = p + int(below_after[0]) - 1 if below_after.size else speed.shape[0] - 1
    return onset, offset


def _moving_runs(speed: np.ndarray, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """The first and last frames of each run of frames whose speed is at least ``thr``."""
    runs = np.array(_runs(speed >= thr), dtype=int).reshape(-1, 2)
    return runs[:, 0], runs[:, 1] - 1


def other_reach(
    speed: np.ndarray, threshold: float, fingertip: np.ndarray, onset: int, offset: int
) -> tuple[int, int] | None:
    """Another movement of the recording (a run of frames above ``threshold`` × the reach's peak speed, outside
    ``onset … offset``) that takes the fingertip forward along the reach by at least half as far: a second reach
    (a return, which goes back, is not one). Its first and last frames, or None."""
    starts, ends = _moving_runs(speed, threshold * float(np.max(speed[onset : offset + 1])))
    d = fingertip[offset] - fingertip[onset]
    length = float(np.linalg.norm(d))
    if length == 0.0:
        return None
    for a, b in zip(starts, ends, strict=True):
        if (b < onset or a > offset) and float((fingertip[b] - fingertip[a]) @ d) / length > 0.5 * length:
            return int(a), int(b)
    return None


def _reaching_peak(speed: np.ndarray, thr: float, reach: np.ndarray, p: int) -> int:
    """The peak of the movement (a run of frames above ``thr``) that takes the fingertip furthest from its start,
    if the one around ``p`` brings it back (a return); else ``p``."""
    starts, ends = _moving_runs(speed, thr)
    if starts.size < 2:
        return p
    extension = reach[ends] - reach[starts]
    own = int(np.flatnonzero((starts <= p) & (p <= ends))[0])
    best = int(np.argmax(extension))
    if extension[own] >= 0 or extension[best] <= 0:
        return p
    return int(starts[best] + np.argmax(speed[starts[best] : ends[best] + 1]))


def sagittal_basis(
    rel: Mapping[str, np.ndarray],
    up: np.ndarray,
    displacement: np.ndarray,
    options: PreprocessOptions,
    forward: np.ndarray | None = None,
    source: object | None = None,
) -> np.ndarray:
    """``(3, 3)`` rows ``forward, up, normal`` of the sagittal plane.

    ``rel`` are the joint centres relative to the shoulder over the movement; ``up`` the lab's up;
    ``displacement`` the fingertip's onset→offset displacement (gives the forward sign).
    """
    up = up / np.linalg.norm(up)
    plane = options.plane
    if plane == "pca":
        pts = np.concatenate([np.asarray(v) for v in rel.values()], axis=0)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        _, s, Vt = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)
        normal = Vt[2]
        up_p = up - (up @ normal) * normal
        tilt = np.degrees(np.arccos(min(1.0, np.linalg.norm(up_p))))
        if s[2] > options.pca_max_flatness * s[1] or tilt > options.pca_max_tilt_deg:
            log.info(
                "%s: principal plane ill-defined (singular values %s, %.0f° from vertical); using the "
                "vertical plane of the fingertip's path",
                source,
                np.round(s, 3),
                tilt,
            )
            plane = "vertical"
        else:
            up_p /= np.linalg.norm(up_p)
            fwd = np.cross(up_p, normal)
    if plane == "vertical":
        up_p = up
        fpath = np.asarray(rel["fingertip"])
        h = fpath - np.outer(fpath @ up, up)
        h = h[np.all(np.isfinite(h), axis=1)]
        _, _, Vt = np.linalg.svd(h - h.mean(axis=0), full_matrices=False)
        fwd = Vt[0] - (Vt[0] @ up) * up
        fwd /= np.linalg.norm(fwd)
    elif plane == "axes":
        up_p = up
        if forward is None:
            h = displacement - (displacement @ up) * up
            k = int(np.argmax(np.abs(h)))
            fwd = np.zeros(3)
            fwd[k] = 1.0
        else:
            fwd = forward - (forward @ up) * up
            if np.linalg.norm(fwd) < 0.5:  # ±x, ±y, ±z: the same axis as up, or its opposite
                raise InputError(
                    "--forward-axis is the up axis (or its opposite); with --plane axes it must be "
                    "a horizontal lab axis, e.g. --up-axis +y --forward-axis +x",
                    source,
                )
        fwd /= np.linalg.norm(fwd)
    if fwd @ displacement < 0:
        fwd = -fwd
    normal = np.cross(fwd, up_p)
    return np.stack([fwd, up_p, normal])


def planar_ik_segments(elbow: np.ndarray, distal: np.ndarray) -> np.ndarray:
    """``q (n, 2)`` from planar shoulder→elbow and elbow→distal vectors (shoulder at the origin).

    q1 = atan2 of the upper arm, q2 = the distal segment's angle minus q1 (both unwrapped over time, q2
    wrapped to (-π, π] at the first frame).
    """
    a1 = np.unwrap(np.arctan2(elbow[:, 1], elbow[:, 0]))
    seg = distal - elbow
    a2 = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    q2 = a2 - a1
    q2 -= 2 * np.pi * np.round(q2[0] / (2 * np.pi))
    return np.stack([a1, q2], axis=1)


def estimate_lengths(joints: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Median 3-D distances: ``upper_arm`` (shoulder→elbow), ``forearm`` (elbow→wrist), ``elbow_fingertip``,
    ``hand`` (wrist→fingertip), ``reach`` (shoulder→fingertip), with their SDs under ``<name>_sd``, over the frames
    where both joints are seen (not NaN); a pair never seen together is left out."""
    pairs = {
        "upper_arm": ("shoulder", "elbow"),
        "forearm": ("elbow", "wrist"),
        "elbow_fingertip": ("elbow", "fingertip"),
        "hand": ("wrist", "fingertip"),
        "reach": ("shoulder", "fingertip"),
    }
    out = {}
    for name, (a, b) in pairs.items():
        if a in joints and b in joints:
            d = np.linalg.norm(joints[b] - joints[a], axis=1)
            d = d[np.isfinite(d)]
            if d.size == 0:  # never seen together (gaps longer than --max-gap on alternate sides): not measured
                continue
            out[name] = float(np.median(d))
            out[f"{name}_sd"] = float(np.std(d))
    return out


def _check_units(lengths: Mapping[str, float], options: PreprocessOptions, source: object) -> None:
    lo, hi = options.segment_range_m
    for name in ("upper_arm", "forearm", "reach", "elbow_fingertip"):
        if name not in lengths:
            continue
        v = lengths[name]
        if v < lo:
            raise InputError(
                f"units look wrong: the median {name.replace('_', ' ')} distance is {v * 1000:.3g} mm, "
                f"absurdly small for an arm (metres declared as mm?)",
                source,
            )
        if v > hi:
            raise InputError(
                f"units look wrong: the median {name.replace('_', ' ')} distance is {v:.3g} m, "
                f"absurdly large for an arm (mm declared as metres?)",
                source,
            )


def build_arm(info: SubjectInfo, side: str, measured: Mapping[str, float] | None = None) -> ArmModel:
    """The subject's arm: sex, height, mass from ``info``; lengths from ``info`` when given, else ``measured``
    (``upper_arm``, ``forearm``, ``elbow_fingertip``), else Dumas' means scaled by height."""
    measured = measured or {}
    ua, fa, hand = info.lengths(side)
    ua = ua if ua is not None else measured.get("upper_arm")
    if fa is None and hand is None and "elbow_fingertip" in measured:
        l2 = measured["elbow_fingertip"]
        if "forearm" in measured and measured["forearm"] < l2 - 0.02:
            fa = measured["forearm"]
        else:  # split elbow→fingertip by Dumas' forearm:hand ratio
            t = DUMAS_2007[info.sex]
            fa = l2 * t["forearm"][3] / (t["forearm"][3] + t["hand"][3])
        hand = l2 - fa
    elif fa is None:
        fa = measured.get("forearm")
    try:
        return ArmModel.from_anthropometrics(
            info.height_m, info.mass_kg, info.sex, upper_arm_m=ua, forearm_m=fa, hand_m=hand
        )
    except ValueError as e:
        raise InputError(f"cannot build subject {info.subject}'s arm: {e}") from None


def _derivatives(t: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cs = CubicSpline(t, q, axis=0)
    return cs(t, 1), cs(t, 2)


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
) -> None:
    """A record cut at gaps longer than gap filling allows (:func:`seen_window`) gives a trial only when those
    gaps lie in the rest: the reach (``onset``/``offset``, frames of the cut) begins and ends in rest seen
    (every joint, no filled frame) for :data:`MIN_SEEN_REST_S` right before and after it; the fingertip is in
    the same place (within :data:`MAX_REST_DRIFT_M`) on both sides of each gap it is seen beyond; after a gap
    before it, the reach extends the arm (it is not a return); and it moves the fingertip by at least
    :data:`MIN_CUT_REACH` of the shoulder-to-fingertip distance (not a fidget or noise while the reach is
    hidden). Each gap cut off is then reported as a warning; otherwise the gap beside the reach is refused as
    :func:`fill_gaps` refuses it. ``seen``: the cut's frames where every joint was seen; ``cut_tip``: the cut's
    fingertip, gaps filled."""
    rest = max(1, round(MIN_SEEN_REST_S * rate))
    before = [g for g in window.gaps if g[2] <= window.start]
    after = [g for g in window.gaps if g[1] >= window.stop]
    near_before = max(before, key=lambda g: g[2]) if before else None
    near_after = min(after, key=lambda g: g[1]) if after else None
    tip = positions["fingertip"][0]
    shoulder = positions["shoulder"][0]
    tip_seen = _seen(tip)
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
        raise InputError(f"{_gap_message(gap[0], gap[1], gap[2], max_gap)}, and {why}", src)
    for label, s, e in window.gaps:
        log.warning(
            "%s: marker %s is missing %s, in the rest %s the reach; the record is used from frame %d to %d",
            src,
            label,
            _gap_where(s, e),
            "before" if e <= window.start else "after",
            window.start + 1,
            window.stop,
        )


def check_glitches(joints: dict[str, np.ndarray], rate: float, src: str, first_frame: int = 0) -> None:
    """Refuse a joint centre that jumps (the low-pass would smear the jump into the reach): faster than any arm
    moves (:data:`MAX_FINGERTIP_SPEED`), or with an acceleration from one frame to the next that no reaching arm
    has (:data:`MAX_MARKER_ACCELERATION`, or 20× the recording's own median where its noise is larger): a spike,
    a marker frozen and then caught up, or two labels swapped for a few frames. ``first_frame``: the record's
    frame at ``joints``' first row, for the messages."""
    for k, x in joints.items():
        step = np.linalg.norm(np.diff(x, axis=0), axis=1)
        if np.nanmax(step, initial=0.0) * rate > MAX_FINGERTIP_SPEED:
            f = int(np.nanargmax(step))
            raise InputError(
                f"the {k} moves {step[f] * 1000:.0f} mm in one frame ({step[f] * rate:.3g} m/s, faster than any "
                f"arm's {MAX_FINGERTIP_SPEED:g} m/s): a glitch in the markers?",
                src,
                f"frame {first_frame + f + 2}",
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
            raise InputError(
                f"the {k} jumps {step[f] * 1000:.0f} mm in one frame (an acceleration of {acc[worst]:.3g} m/s², "
                f"above the limit of {limit:.3g}): a glitch, a marker frozen and caught up, or two labels swapped? "
                "Fix the labels, or blank those frames to be filled as a gap",
                src,
                f"frame {first_frame + f + 2}",
            )


def reconstruct_markers(
    md: MarkerData,
    mset: MarkerSet,
    *,
    side: str = "right",
    static: MarkerData | None = None,
    subject_info: SubjectInfo | None = None,
    options: PreprocessOptions | None = None,
) -> MarkerReconstruction:
    """Run steps 1–10 on a marker file; see the module docstring."""
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
        raise InputError(f"only {md.n_frames} frames, too few for a reach", src)
    positions = joint_positions(md, ms, static)
    window = seen_window(positions, options.max_gap_frames, src, max(10, _filter_padlen(options.filter_order) + 1))
    cropped = slice(window.start, window.stop)
    joints = {j: fill_gaps(p[cropped], options.max_gap_frames, label, src) for j, (p, label) in positions.items()}
    # the arm from every frame where its joints are seen, cut off or not: the same reach, the same arm
    lengths = estimate_lengths({j: p for j, (p, _) in positions.items()})
    _check_units(lengths, options, src)

    up = _axis(options.up_axis or (md.up if md.up_declared else None) or ms.up or md.up)  # the file's own first
    if side == "left":
        if options.lateral_axis:
            lateral = _axis(options.lateral_axis)
        else:  # the horizontal lab axis along which the fingertip ranges least
            rng = np.ptp(joints["fingertip"], axis=0)
            cand = [k for k in range(3) if abs(up[k]) < 0.5]
            lateral = np.eye(3)[min(cand, key=lambda k: rng[k])]
        joints = mirror(joints, lateral)

    check_glitches(joints, md.rate, src, first_frame=window.start)
    raw_fingertip = joints["fingertip"]
    if options.cutoff_hz is not None:
        joints = {k: lowpass(v, md.rate, options.cutoff_hz, options.filter_order, src) for k, v in joints.items()}
    t = md.t[cropped]
    vel = np.gradient(joints["fingertip"], t, axis=0)
    speed = np.linalg.norm(vel, axis=1)
    if not np.isfinite(speed).all() or speed.max() < options.min_peak_speed:
        if window.gaps:  # the movement is in a gap
            label, s0, e0 = max(window.gaps, key=lambda g: g[2] - g[1])
            raise InputError(
                f"{_gap_message(label, s0, e0, options.max_gap_frames)}, and no reach is seen outside the long gaps",
                src,
            )
        raise InputError(
            f"no movement detected: the fingertip's peak speed is {np.nanmax(speed):.3g} m/s "
            f"(< {options.min_peak_speed:g} m/s)",
            src,
        )
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
    seg_speed = segmentation_speed(t, raw_fingertip, speed, options, src, filtered=joints["fingertip"])
    onset, offset = detect_onset_offset(seg_speed, options.onset_threshold, reach)
    other = other_reach(seg_speed, options.onset_threshold, joints["fingertip"], onset, offset)
    if other is not None:
        log.warning(
            "%s: the recording holds another reach (%.2f-%.2f s); the trial is the faster one, at %.2f-%.2f s. Cut "
            "the recording to one reach per file to keep the other",
            src,
            t[other[0]],
            t[other[1]],
            t[onset],
            t[offset],
        )
    if offset - onset + 1 < 4:
        raise InputError(f"no movement detected: the reach lasts {offset - onset + 1} frames", src)
    if window.gaps:
        seen = np.all([_seen(p[cropped]) for p, _ in positions.values()], axis=0)
        _check_window(window, onset, offset, seen, positions, joints["fingertip"], md.rate, options.max_gap_frames, src)
    cut = {"before": onset == 0, "after": offset == len(t) - 1}  # beside a gap cut off, _check_window refused it
    if all(cut.values()):
        log.warning(
            "%s: no rest before or after the movement; the record's edges are used: the reach may be a fragment of "
            "a longer movement",
            src,
        )
    elif any(cut.values()):
        log.warning("%s: no rest %s the movement; the record's edge is used", src, "before" if onset == 0 else "after")
    rel = {k: v - joints["shoulder"] for k, v in joints.items() if k != "shoulder"}
    disp = joints["fingertip"][offset] - joints["fingertip"][onset]
    fwd = _axis(options.forward_axis) if options.forward_axis else None
    basis = sagittal_basis({k: v[onset : offset + 1] for k, v in rel.items()}, up, disp, options, fwd, src)
    planar = {k: v @ basis[:2].T for k, v in rel.items()}

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
    qd, qdd = _derivatives(t, q)
    return MarkerReconstruction(
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
) -> Trial:
    """A marker file → one :class:`Trial` (onset→offset)."""
    options = options or PreprocessOptions()
    rec = reconstruct_markers(md, mset, side=side, static=static, subject_info=subject_info, options=options)
    return _to_trial(
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
) -> Trial:
    """Joint angles (model convention) → one :class:`Trial`.

    The arm comes from the subject info (lengths or Dumas' means scaled by height). Non-uniform samples are
    first interpolated onto a uniform grid at the median rate; then the angles are low-passed (skipped, with a
    log note, when the rate is too low for the cutoff), the fingertip speed from forward kinematics gives
    onset and offset, and q̇, q̈, τ follow as for markers. Left arms' angles are taken as already in the model
    convention.
    """
    options = options or PreprocessOptions()
    info = subject_info or DEFAULT_SUBJECT
    src = ad.source
    arm = build_arm(info, side)
    t, q = ad.t, ad.q
    dt = np.diff(t)
    if np.ptp(dt) > 0.01 * np.median(dt):
        t_u = np.arange(t[0], t[-1] + 1e-12, np.median(dt))
        q = CubicSpline(t, q, axis=0)(t_u)
        t = t_u
    rate = 1.0 / float(np.median(np.diff(t)))
    q_seen = q
    if options.cutoff_hz is not None:
        if options.cutoff_hz < rate / 2 and t.shape[0] > _filter_padlen(options.filter_order):
            q = lowpass(q, rate, options.cutoff_hz, options.filter_order, src)
        else:
            log.info("%s: %d samples at %.3g Hz, not filtered", src, t.shape[0], rate)
    qd, qdd = _derivatives(t, q)
    speed = arm.fingertip_speed(q, qd)
    if speed.max() < options.min_peak_speed:
        raise InputError(
            f"no movement detected: the fingertip's peak speed is {speed.max():.3g} m/s "
            f"(< {options.min_peak_speed:g} m/s)",
            src,
        )
    tip = arm.fk(q_seen)
    onset, offset = detect_onset_offset(
        segmentation_speed(t, tip, speed, options, src),
        options.onset_threshold,
        np.linalg.norm(tip - tip[0], axis=1),  # away from where it rested: the reach, not a return
    )
    if offset - onset + 1 < 4:
        raise InputError(f"no movement detected: the reach lasts {offset - onset + 1} samples", src)
    target_x = float(arm.fk(q[offset])[0])
    return _to_trial(
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
