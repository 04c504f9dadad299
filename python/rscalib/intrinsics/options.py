"""Every option of the intrinsics job, with its default: the one place a default is written.
`rscalib intrinsics` fills :class:`IntrinsicsOptions` from the flags typed; the front door
:func:`rscalib.calibrate_intrinsics` takes the same object."""
from __future__ import annotations

from dataclasses import dataclass

from ..detection.options import DetectOptions
from ..errors import InputError

MODELS = ("pinhole-radtan", "pinhole-equidistant")
MIN_VIEWS = 3


@dataclass(frozen=True)
class IntrinsicsOptions:
    """How `rscalib intrinsics` calibrates (OpenCV's calibrateCamera / fisheye.calibrate)."""

    model: str = "pinhole-radtan"      # pinhole-radtan (k3 only when the board reaches the corners) | pinhole-equidistant
    max_views: int = 40                # at most this many views, chosen sharp and well spread
    still_frames_only: bool = True     # from a video: only frames still enough that the rolling shutter does not shear
    detection: DetectOptions = DetectOptions()

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise InputError(f"unknown model {self.model!r} (one of {', '.join(MODELS)})")
        if not (isinstance(self.max_views, int) and self.max_views >= MIN_VIEWS):
            raise InputError(f"--max-views must be at least {MIN_VIEWS}")
        if not isinstance(self.detection, DetectOptions):
            raise InputError("detection must be an rscalib.DetectOptions")
