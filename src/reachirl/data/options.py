"""Every choice of the way from motion-capture files to trials (:mod:`reachirl.data.preprocess` says what each
step does)."""

from __future__ import annotations

from dataclasses import dataclass

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
