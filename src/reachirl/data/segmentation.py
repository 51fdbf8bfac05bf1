"""Where the reach is in a record: the stretch between gaps that holds it (:func:`seen_window`), the speed its
onset and offset are found on (:func:`segmentation_speed`, low-passed as hard as the markers' noise needs), the
onset and offset themselves (:func:`detect_onset_offset`, the reach rather than the return) and another reach
in the same record (:func:`other_reach`)."""

from __future__ import annotations

import functools
import logging
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from .options import PreprocessOptions
from .signal import filter_padlen, gap_message, long_gaps, lowpass, noise_gains, seen_frames, true_runs

__all__ = [
    "MIN_SEGMENT_CUTOFF_HZ",
    "SEGMENT_NOISE_FRACTION",
    "SeenWindow",
    "detect_onset_offset",
    "other_reach",
    "seen_window",
    "segmentation_cutoff",
    "segmentation_speed",
]

log = logging.getLogger(__name__)


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
    rest or a return; the whole record when no gap is that long. ``reconstruct_markers`` then checks
    that every gap cut off lies in the rest."""
    for p, label in positions.values():
        if not seen_frames(p).any():
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

    runs = [r for r in true_runs(~blocked) if r[1] - r[0] >= min_frames and extension(r) >= 0.0]
    if not runs:
        label, s, e = gaps[0]
        raise InputError(gap_message(label, s, e, max_gap), source)
    start, stop = max(runs, key=extension)
    return SeenWindow(start, stop, tuple(gaps))


SEGMENT_NOISE_FRACTION = 0.25  # "auto": the onset speed's marker noise at most this fraction of the threshold
MIN_SEGMENT_CUTOFF_HZ = 3.0  # "auto" goes no lower: below it the filter reshapes a reach's speed profile


def segmentation_cutoff(
    t: np.ndarray,
    points: np.ndarray,
    peak_speed: float,
    options: PreprocessOptions,
    source: object | None = None,
    filtered: np.ndarray | None = None,
    held: list[tuple] | None = None,
) -> float | None:
    """The low-pass cutoff (Hz) of the speed that finds onset and offset, or ``None`` for the angles' own
    ``cutoff_hz`` speed (Berret's).

    A number in ``options.segment_cutoff_hz`` is used as given (when below ``cutoff_hz`` and half the frame rate).
    With the angles unfiltered (``cutoff_hz`` None) it applies all the same, and ``"auto"`` starts from the default
    ``cutoff_hz`` of :class:`PreprocessOptions`, whose speed it takes where the noise allows: onset and offset are
    never found on an unfiltered speed unless ``segment_cutoff_hz`` is None. ``"auto"`` measures
    the markers' noise and lowers the cutoff only as far as it must: the noise is the RMS of ``points`` above
    ``cutoff_hz`` (what the angles' filter removes, rescaled by the share of white noise it holds); from it
    the filter's response predicts the RMS noise of the speed at each cutoff, and the highest cutoff (in
    0.5 Hz steps, not below ``MIN_SEGMENT_CUTOFF_HZ``) whose noise is at most ``SEGMENT_NOISE_FRACTION`` of
    the threshold speed (``onset_threshold`` × ``peak_speed``) is taken. Clean recordings keep the
    ``cutoff_hz`` speed; 1.5 mm of noise on a 0.8 m/s reach at 100 Hz gives about 4 Hz. ``filtered`` is
    ``points`` already low-passed at ``cutoff_hz``, when the caller has it. ``held``: a list, to hold the
    warning that the noise is large (its :meth:`logging.Logger.warning` arguments) for the caller to log once
    the record is accepted, instead of logging it (a record cut at a gap holds a fragment of the reach, whose
    peak speed is not the reach's, until the cut is checked)."""
    fc, base = options.segment_cutoff_hz, options.cutoff_hz
    if fc is None:
        return None
    rate = 1.0 / float(np.median(np.diff(t)))
    if t.shape[0] <= filter_padlen(options.filter_order):
        return None
    if fc != "auto":  # below the angles' cutoff (any, when they are not filtered) and the Nyquist frequency
        return float(fc) if float(fc) < min(base or np.inf, rate / 2) else None
    unfiltered = base is None  # the angles unfiltered: the speed is still found on the default cutoff's at most
    base = PreprocessOptions.cutoff_hz if unfiltered else base
    if base >= rate / 2:
        return None
    points = np.asarray(points, dtype=float).reshape(t.shape[0], -1)
    if filtered is None or unfiltered:
        filtered = lowpass(points, rate, base, options.filter_order, source)
    gains = functools.partial(noise_gains, round(rate, 6), order=options.filter_order)  # cached per rate
    noise_var = float(np.mean((points - filtered.reshape(points.shape)) ** 2)) / gains(float(base))[0]  # per axis

    def speed_noise(f: float) -> float:
        return float(np.sqrt(points.shape[1] * noise_var * gains(float(f))[1]))

    target = SEGMENT_NOISE_FRACTION * options.onset_threshold * peak_speed
    if speed_noise(base) <= target:
        return float(base) if unfiltered else None
    for f in np.arange(base - 0.5, MIN_SEGMENT_CUTOFF_HZ - 1e-9, -0.5):
        if speed_noise(f) <= target:
            return float(f)
    warning = (
        "%s: the recording's noise (%.2g mm RMS, markers or angles seen at the fingertip) is large beside the "
        "onset threshold's speed (%.2g mm/s: --threshold %g of the peak %.2f m/s); onset and offset are found on "
        "a %g Hz speed and may still wander",
        source,
        np.sqrt(noise_var) * 1000,
        options.onset_threshold * peak_speed * 1000,
        options.onset_threshold,
        peak_speed,
        MIN_SEGMENT_CUTOFF_HZ,
    )
    if held is None:
        log.warning(*warning)
    else:
        held.append(warning)
    return MIN_SEGMENT_CUTOFF_HZ


def segmentation_speed(
    t: np.ndarray,
    points: np.ndarray,
    speed: np.ndarray,
    options: PreprocessOptions,
    source: object | None = None,
    filtered: np.ndarray | None = None,
    held: list[tuple] | None = None,
) -> np.ndarray:
    """The fingertip speed that onset and offset are found on: ``points`` ``(n, d)`` (the fingertip, before
    the angles' filter) low-passed at :func:`segmentation_cutoff`, differentiated and normed; ``speed`` (the
    ``cutoff_hz`` speed) as is when that is ``None``. ``filtered``, ``held``: see :func:`segmentation_cutoff`."""
    fc = segmentation_cutoff(t, points, float(np.max(speed)), options, source, filtered, held)
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
    runs = np.array(true_runs(speed >= thr), dtype=int).reshape(-1, 2)
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
