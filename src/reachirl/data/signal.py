"""A record's samples as signals: the runs of frames a marker is seen or missed, gap filling, the zero-lag
Butterworth low-pass and its noise response, and derivatives by a cubic spline."""

from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt, sosfreqz

from ..errors import InputError

__all__ = [
    "derivatives",
    "fill_gaps",
    "filter_padlen",
    "gap_message",
    "gap_where",
    "long_gaps",
    "lowpass",
    "noise_gains",
    "seen_frames",
    "true_runs",
]


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs ``[start, end)`` of True in a boolean ``(n,)`` mask."""
    d = np.diff(np.r_[0, np.asarray(mask, dtype=int), 0])
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)]


def seen_frames(x: np.ndarray) -> np.ndarray:
    """The frames of ``x`` (``(n,)`` or ``(n, d)``) with every coordinate seen (finite)."""
    return np.all(np.isfinite(np.asarray(x, dtype=float).reshape(np.shape(x)[0], -1)), axis=1)


def long_gaps(x: np.ndarray, max_gap: int) -> list[tuple[int, int]]:
    """The runs ``[start, end)`` of unseen frames of ``x`` (``(n,)`` or ``(n, d)``) longer than ``max_gap``."""
    return [(s, e) for s, e in true_runs(~seen_frames(x)) if e - s > max_gap]


def gap_where(start: int, end: int) -> str:
    """Frames ``[start, end)`` (0-based) in words, 1-based: ``in frame 21``, ``for 20 frames (21-40)``."""
    return f"in frame {end}" if end - start == 1 else f"for {end - start} frames ({start + 1}-{end})"


def gap_message(name: str, start: int, end: int, max_gap: int) -> str:
    where = gap_where(start, end)
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
    missing = ~seen_frames(flat)
    if not missing.any():
        return x
    n = missing.shape[0]
    if missing.all():
        raise InputError(f"marker {name} is never seen", source)
    for s, e in true_runs(missing):
        if e - s > max_gap:
            raise InputError(gap_message(name, s, e, max_gap), source)
    seen = np.flatnonzero(~missing)
    out = flat.copy()
    if seen.size >= 2:
        cs = CubicSpline(seen, flat[seen], axis=0)
        interior = missing & (np.arange(n) > seen[0]) & (np.arange(n) < seen[-1])
        out[interior] = cs(np.flatnonzero(interior))
    out[: seen[0]] = flat[seen[0]]
    out[seen[-1] + 1 :] = flat[seen[-1]]
    return out.reshape(x.shape)


def filter_padlen(order: int) -> int:
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
    padlen = filter_padlen(order)
    if x.shape[0] <= padlen:
        raise InputError(f"too short to filter: {x.shape[0]} frames, need more than {padlen}", source)
    return sosfiltfilt(sos, x, axis=0)


@functools.lru_cache(maxsize=256)
def noise_gains(rate: float, cutoff_hz: float, order: int) -> tuple[float, float]:
    """For white noise of variance 1 on one axis: the variance left in ``x − lowpass(x)`` and the variance of
    ``gradient(lowpass(x))`` (the zero-lag filter's power response is ``|H|⁴``, the central difference's
    ``(rate · sin ω)²``)."""
    sos = butter(order, cutoff_hz / (rate / 2.0), btype="low", output="sos")
    w = np.linspace(0.0, np.pi, 4097)
    h2 = np.abs(sosfreqz(sos, worN=w)[1]) ** 2  # filtfilt's amplitude response
    return float(np.mean((1.0 - h2) ** 2)), float(np.mean(h2**2 * (rate * np.sin(w)) ** 2))


def derivatives(t: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cs = CubicSpline(t, q, axis=0)
    return cs(t, 1), cs(t, 2)
