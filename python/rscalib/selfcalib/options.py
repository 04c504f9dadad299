"""Every option of the self-calibration job, with its default: the one place a default is written.

`rscalib selfcalib` fills :class:`SelfCalibOptions` from the flags a user typed; the Python front
door :func:`rscalib.self_calibrate` takes the same object; the engine reads the fields it needs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional

from ..errors import InputError
from ..reference_cameras import PAPER_PIXEL_SIZE_MM

# The paper's comparisons: "filter" is the Sum-of-Gaussians bank alone (Civera et al. 2009, no
# adjustment; "determined" by restarting two single filters, docs/sog.md §15); "single" is one EKF
# started at f0 with f_sigma (the baseline the paper's bank improves on).
BASELINES = ("filter", "single")
SUBPIXEL_MODES = ("tracked", "affine", "parabola")
WARP_MODELS = ("affine", "homography")


@dataclass(frozen=True)
class FrontEndOptions:
    """The filter's image front end (sizes for 320x240; scaled with the image width: scaled())."""

    patch_half_px: int = 5            # 11x11 patches, as in Civera's code
    ncc_threshold: float = 0.8
    min_visible: int = 20             # add features while fewer were used in the update
    max_new_per_frame: int = 10
    min_separation_px: float = 20.0   # new corners away from predicted features
    max_search_half_px: float = 60.0  # cap the ellipse's bounding box (first frames span f widely)
    corner_quality: float = 0.01
    # "tracked" (the method): each feature keeps the warp (warp_model) of its last match, NCC searches
    # with the original patch warped by it, ECC starts from it, and a match ECC cannot refine is dropped
    # (no parabola fallback): the reference is always the first view, so errors do not accumulate, and
    # walking towards a wall (scale > 1.7) no longer falls back to an unwarped patch (docs/sog.md §19).
    # "affine": refine each NCC peak by ECC alignment of the patch under an affine warp from the
    # identity (the stored patch is never re-cut; it drifts, docs/sog.md §17); "parabola": parabola
    # through the NCC peak only.
    subpixel: str = "tracked"
    max_refine_shift_px: float = 1.5
    refine_half_px: int = 5           # "tracked": half size of the ECC template
    max_warp_change: float = 1.25     # "tracked": per-frame change of the warp's singular values
    max_warp_scale: float = 4.0       # "tracked": the warp's singular values within [1/this, this]
    warp_model: str = "affine"        # "tracked": "affine" or "homography" (perspective across the patch)

    def __post_init__(self) -> None:
        if self.subpixel not in SUBPIXEL_MODES:
            raise InputError(f"front_end.subpixel must be one of {', '.join(SUBPIXEL_MODES)}, not {self.subpixel!r}")
        if self.warp_model not in WARP_MODELS:
            raise InputError(f"front_end.warp_model must be one of {', '.join(WARP_MODELS)}, not {self.warp_model!r}")

    def scaled(self, width: int) -> FrontEndOptions:
        """These options for images ``width`` pixels wide (the sizes above are for 320 px)."""
        scale = width / 320.0
        return replace(self, patch_half_px=max(3, int(round(self.patch_half_px * max(1.0, scale ** 0.5)))),
                       refine_half_px=max(3, int(round(self.refine_half_px * max(1.0, scale ** 0.5)))),
                       min_separation_px=self.min_separation_px * scale,
                       max_search_half_px=self.max_search_half_px * scale)


@dataclass(frozen=True)
class SelfCalibOptions:
    """How `rscalib selfcalib` estimates f, the principal point and the radial distortion.

    The method: the Sum-of-Gaussians filter bank over the sequence (Civera et al. 2009), then a bundle
    adjustment over its tracks that is the estimate and says whether the data determine it
    (docs/sog.md §20-§21)."""

    pixel_size_mm: float = PAPER_PIXEL_SIZE_MM   # the sensor's pixel pitch: the units of k1 (mm^-2), k2 (mm^-4)
    max_frames: Optional[int] = None            # stop after this many frames
    line_delay_s: Optional[float] = None        # the rolling shutter's (s/row): given, every measurement is moved
    #                                             to one time per frame; None: the adjustment estimates it
    f_range_px: Optional[tuple] = None          # focal lengths the bank starts from (None: wide, by image size)
    determined_within: float = 0.02             # "determined": f's 99 % interval within +- this fraction of f
    baseline: Optional[str] = None              # None: the method; "filter" | "single" (BASELINES)
    f0_px: Optional[float] = None               # "single": the start of f (None: the middle of the f range)
    f_sigma_px: Optional[float] = None          # "single": its sigma (None: a quarter of the f range)
    restarts: bool = True                       # baselines: check "determined" by restarting two filters
    sprt_alpha: float = 0.05                    # chance of dropping a right candidate camera too early
    sprt_beta: float = 0.1                      # chance of keeping a wrong one too long
    # 1-point RANSAC (Civera et al., JFR 2010) in the filter's update: on the real desk video it moved
    # the principal point from (303.2, 219.1) to (312.7, 235.7) against the truth (308.6, 236.5); on the
    # clean rendered room sequences it changes nothing (docs/sog.md §15).
    ransac_hypotheses: int = 100
    front_end: FrontEndOptions = field(default_factory=FrontEndOptions)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pixel_size_mm) and 1e-4 <= self.pixel_size_mm <= 1.0):
            raise InputError(f"the pixel size must be in [0.0001, 1] mm, not {self.pixel_size_mm!r}")
        if self.max_frames is not None and not (isinstance(self.max_frames, int) and self.max_frames >= 2):
            raise InputError(f"max_frames must be at least 2, not {self.max_frames!r}")
        if self.line_delay_s is not None and not (math.isfinite(self.line_delay_s) and 0 <= self.line_delay_s <= 1e-3):
            raise InputError(f"the line delay must be in [0, 1e-3] s/row, not {self.line_delay_s!r}")
        if not (math.isfinite(self.determined_within) and 1e-4 <= self.determined_within <= 0.5):
            raise InputError(f"determined_within must be in [0.0001, 0.5], not {self.determined_within!r}")
        if self.baseline is not None and self.baseline not in BASELINES:
            raise InputError(f"unknown baseline {self.baseline!r} (none, {', '.join(BASELINES)})")
        if self.baseline != "single" and (self.f0_px is not None or self.f_sigma_px is not None):
            raise InputError("f0 and f_sigma go with the single-filter baseline (--bank single)")
        if self.f_range_px is not None:
            lo, hi = self.f_range_px
            if not (0 < lo < hi < 1e7):
                raise InputError(f"the f range must be 0 < low < high, not {self.f_range_px!r}")
        for name in ("sprt_alpha", "sprt_beta"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise InputError(f"{name} must be in (0, 1], not {getattr(self, name)!r}")
        if not isinstance(self.front_end, FrontEndOptions):
            raise InputError("front_end must be a FrontEndOptions")

    @property
    def bundle(self) -> bool:
        """The method adjusts; the baselines are the filters alone."""
        return self.baseline is None
