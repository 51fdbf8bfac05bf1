"""Every choice of the way from motion-capture files to trials (:mod:`reachirl.data.preprocess` says what each
step does)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PreprocessOptions"]


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
        # numbers are checked here, by name: NaN, text or a fractional order failed deep in numpy and scipy
        # ("attempt to get argmin of an empty sequence", "float division by zero") or passed unseen
        _number("onset_threshold", self.onset_threshold, 0.0, 1.0, "in (0, 1)", open_high=True)
        _integer("max_gap_frames", self.max_gap_frames, 0)
        if self.cutoff_hz is not None:
            _number("cutoff_hz", self.cutoff_hz, 0.0, None, "> 0 (Hz) or None")
        _integer("filter_order", self.filter_order, 1, 8)
        fc = self.segment_cutoff_hz
        if not (fc is None or (isinstance(fc, str) and fc == "auto") or (_real(fc) and 0 < fc < np.inf)):
            raise ValueError(f"segment_cutoff_hz must be 'auto', a number > 0 or None, got {fc!r}")
        _number("min_peak_speed", self.min_peak_speed, 0.0, None, "> 0 (m/s)")
        if self.n_samples is not None:
            _integer("n_samples", self.n_samples, 4)
        r = self.segment_range_m
        if not (isinstance(r, tuple | list) and len(r) == 2 and all(_real(v) for v in r) and 0 < r[0] < r[1] < np.inf):
            raise ValueError(f"segment_range_m must be two numbers 0 < low < high (m), got {r!r}")
        _number("pca_max_tilt_deg", self.pca_max_tilt_deg, 0.0, 90.0, "in (0, 90] (degrees)")
        _number("pca_max_flatness", self.pca_max_flatness, 0.0, 1.0, "in (0, 1]")


def _real(v) -> bool:
    """A real number, not a boolean, not NaN."""
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) and not np.isnan(v)


def _number(name: str, v, low: float, high: float | None, expected: str, open_high: bool = False) -> None:
    """``v`` is a number above ``low`` and up to ``high`` (below it with ``open_high``)."""
    ok = _real(v) and v > low and np.isfinite(v)
    if ok and high is not None:
        ok = v < high if open_high else v <= high
    if not ok:
        raise ValueError(f"{name} must be a number {expected}, got {v!r}")


def _integer(name: str, v, low: int, high: int | None = None) -> None:
    """``v`` is an integer in ``[low, high]``."""
    ok = isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= low and (high is None or v <= high)
    if not ok:
        upto = "" if high is None else f" and <= {high}"
        raise ValueError(f"{name} must be an integer >= {low}{upto}, got {v!r}")
