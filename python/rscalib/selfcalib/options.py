"""Every option of the self-calibration job, with its default: the one place a default is written.

`rscalib selfcalib` fills :class:`SelfCalibOptions` from the flags a user typed; the Python front
door :func:`rscalib.self_calibrate` takes the same object; the engine reads the fields it needs.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from typing import Optional

from .. import checks
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
        for name in ("patch_half_px", "refine_half_px"):
            checks.whole(getattr(self, name), f"front_end.{name}", 1, 100, " px")
        for name in ("min_visible", "max_new_per_frame"):
            checks.whole(getattr(self, name), f"front_end.{name}", 1, 100_000)
        for name in ("ncc_threshold", "corner_quality"):
            checks.number(getattr(self, name), f"front_end.{name}", 0.0, 1.0, low_open=True)
        for name in ("min_separation_px", "max_search_half_px", "max_refine_shift_px"):
            checks.number(getattr(self, name), f"front_end.{name}", 0.0, 1e5, " px", low_open=True)
        for name in ("max_warp_change", "max_warp_scale"):
            checks.number(getattr(self, name), f"front_end.{name}", 1.0, 1e3)
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


_TRACK_RANSAC_METHODS = ("ransac", "magsac")
_REFERENCE_WIDTH = 640.0   # TrackOptions' pixel sizes are for 640x480; scaled with the width


@dataclass(frozen=True)
class TrackOptions:
    """Options of :class:`FeatureTracker`. Pixel sizes and counts are for 640x480 images and are
    scaled to the image (:meth:`scaled`: lengths with the width, counts with the area)."""

    # --- corners
    target_tracks: int = 800           # live tracks wanted at 640x480 (500-1500 asked; the cost is ~linear)
    grid_cols: int = 8                 # corners spread over cells of ~80x80 px ...
    grid_rows: int = 6                 # ... each asking for its share of target_tracks
    min_distance_px: float = 8.0       # new corners this far from live tracks and from each other
    corner_quality: float = 0.01       # goodFeaturesToTrack qualityLevel (relative to the best corner)
    corner_block_size: int = 5         # its structure-tensor window: 5 is steadier than 3 on H.264
    detect_every_frames: int = 3       # look for corners this often (a search costs ~3 ms at 640x480) ...
    detect_below_fraction: float = 0.25  # ... and every frame while fewer than this share are live
    corner_half_resolution_from_px: int = 480  # images this wide look for corners at half resolution
    #                                            (4x cheaper; the first view, not the corner, is the point)
    # --- KLT
    klt_window_px: int = 11            # 11x11 at 640 (9x9 at 320): the anchoring, not KLT, sets precision
    klt_levels: int = 2                # from the constant-velocity guess: ~25 px of surprise a frame
    klt_iterations: int = 10
    klt_epsilon_px: float = 0.03
    fb_max_px: float = 0.5             # forward-backward check (not scaled: LK's precision is in px)
    klt_gain: bool = True              # scale the previous frame to the current one's brightness first:
    #                                    LK is not gain-invariant; auto-exposure steps biased it by ~2 px
    # --- geometric verification
    ransac_px: float = 1.0             # frame pair: epipolar / transfer threshold
    keyframe_ransac_px: float = 1.5    # keyframe pair (after anchoring: a longer baseline)
    homography_share: float = 0.9      # H explains this share of F's inliers: test with H instead ...
    homography_px_factor: float = 2.0  # ... at this times the threshold (parallax of near points)
    min_verify_points: int = 15        # fewer correspondences: no test possible, all kept
    ransac_method: str = "ransac"      # "magsac" (USAC) costs 10-30 ms a pair here, RANSAC ~1 ms
    # --- keyframes
    keyframe_max_gap_frames: int = 5   # anchoring and keyframes at least this often
    keyframe_displacement_px: float = 15.0  # ... or when the median track moved this far
    keyframe_min_survival: float = 0.8      # ... or when fewer of the last keyframe's tracks are left
    # --- anchoring (inverse-compositional affine Lucas-Kanade against each track's first view)
    anchor: bool = True
    anchor_half_px: int = 9            # 19x19 first view (sqrt-scaled: 13x13 at 320x240; 11x11 there
    #                                    gave 0.21 px RMS, 15x15 0.16, 21x21 more at room creases)
    anchor_iterations: int = 3         # started at KLT's position and the last warp: 3 suffice
    anchor_min_zncc: float = 0.8       # below: the first view no longer matches (on_anchor_failure)
    anchor_max_shift_px: float = 3.0   # anchored vs KLT position (KLT can slip ~2 px in an exposure step)
    on_anchor_failure: str = "end"     # "end" the track, or "reanchor" (a new first view at KLT's
    #                                    position: the track goes on, with that position's error kept)
    anchor_max_scale: float = 1.6      # warp's singular values beyond [1/this, this]: no longer matches
    max_position_sigma: float = 0.5    # no track from a first view that fixes a position this badly
    #                                    (TrackSet.position_sigma, px per grey level of noise): on
    #                                    look-around 640 the tracks above 0.6 had a median RMS error
    #                                    of 0.7-0.9 px, those below 0.29 0.12 px (§22)
    border_px: int = 2                 # tracks keep their patch this far inside the image
    # --- re-identification
    reid: bool = True
    reid_max_gap_frames: int = 300     # a lost track can come back within ~10 s at 30 fps
    reid_pool_size: int = 4000         # lost tracks remembered (oldest forgotten first)
    reid_ratio: float = 0.8            # Lowe's ratio test between the two best lost tracks
    reid_max_hamming: int = 64         # of ORB's 256 bits
    reid_min_zncc: float = 0.85        # the returning corner must also align with the first view
    reid_max_shift_px: float = 2.0     # ... within this of the corner
    reid_geometry_px: float = 2.0      # RANSAC check between a keyframe of the lost track and now
    reid_neighbour_px: float = 20.0    # ... and its motion since then within this (or 3 spreads) of
    #                                    its 8 nearest live tracks' (an epipolar line is long)
    reid_search_keyframes: int = 60    # keyframes searched for one that saw the candidates

    def __post_init__(self) -> None:
        """InputError (one line) for values that mean nothing: counts and sizes must be positive
        whole numbers (klt_levels and border_px may be 0), lengths positive, shares in (0, 1]."""
        from dataclasses import fields

        shares = {"corner_quality", "detect_below_fraction", "homography_share", "keyframe_min_survival",
                  "anchor_min_zncc", "reid_ratio", "reid_min_zncc"}
        choices = {"ransac_method": _TRACK_RANSAC_METHODS, "on_anchor_failure": ("end", "reanchor")}
        for item in fields(self):
            value = getattr(self, item.name)
            if item.name in choices:
                if value not in choices[item.name]:
                    raise InputError(f"TrackOptions.{item.name}: {value!r} is not one of {', '.join(choices[item.name])}")
            elif isinstance(value, bool) or item.type in ("bool", bool):
                if not isinstance(value, bool):
                    raise InputError(f"TrackOptions.{item.name}: give True or False, not {value!r}")
            elif item.type in ("int", int):
                least = 0 if item.name in ("klt_levels", "border_px") else 1
                if not (isinstance(value, int) and value >= least):
                    raise InputError(f"TrackOptions.{item.name}: a whole number >= {least}, not {value!r}")
            else:
                ok = isinstance(value, (int, float)) and math.isfinite(value) and value > 0
                if not ok or (item.name in shares and value > 1):
                    limits = "in (0, 1]" if item.name in shares else "a positive number"
                    raise InputError(f"TrackOptions.{item.name}: {limits}, not {value!r}")

    def scaled(self, image_size: tuple[int, int]) -> TrackOptions:
        """These options for ``image_size`` (width, height)."""
        width, height = image_size
        scale = width / _REFERENCE_WIDTH
        area = width * height / (_REFERENCE_WIDTH * 480.0)

        def odd(n: float) -> int:
            return max(5, int(round(n)) | 1)

        return replace(self, target_tracks=max(50, int(round(self.target_tracks * area))),
                       min_distance_px=max(3.0, self.min_distance_px * scale),
                       klt_window_px=odd(self.klt_window_px * math.sqrt(scale)),
                       keyframe_displacement_px=self.keyframe_displacement_px * scale,
                       reid_neighbour_px=self.reid_neighbour_px * scale,
                       max_position_sigma=self.max_position_sigma * scale,   # ∝ 1 / gradient per px
                       anchor_half_px=max(3, int(round(self.anchor_half_px * math.sqrt(scale)))))



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
    # --- the bundle adjustment (docs/sog.md §24) over the tracks of tracks.py (TrackOptions)
    line_delay_from: Optional[str] = None       # an `rscalib linedelay` result.json: its line delay and sigma
    #                                             are the adjustment's prior (a board filmed once helps later videos)
    tracks: TrackOptions = field(default_factory=TrackOptions)
    robust_loss_scale_px: float = 1.0           # soft-L1 loss: residuals beyond ~this count less (KLT slips)
    max_keyframes: int = 100                    # the adjustment's keyframes at most (evenly thinned): the
    #                                             reduced camera matrix is dense; 212 -> 100 on 30 s at 640x480
    #                                             took the solve 4x faster, f within 0.1 sigma (docs/sog.md §23)
    max_free_iterations: int = 80               # the adjustment's points free this long at most, then held in their
    #                                             range: far points crawled free (378 iterations, 78 s on a 30 s
    #                                             look-around; 134 iterations, 38 s with this: docs/sog.md §25)

    def __post_init__(self) -> None:
        # types first (text, bools, lists): the range checks below then read numbers
        checks.number(self.pixel_size_mm, "pixel_size_mm")
        if self.line_delay_s is not None:
            checks.number(self.line_delay_s, "line_delay_s")
        checks.number(self.determined_within, "determined_within")
        for name in ("f0_px", "f_sigma_px"):
            if getattr(self, name) is not None:
                checks.number(getattr(self, name), name, 0.0, 1e7, " px", low_open=True)
        for name in ("sprt_alpha", "sprt_beta", "robust_loss_scale_px"):
            checks.number(getattr(self, name), name)
        checks.whole(self.ransac_hypotheses, "ransac_hypotheses", 0, 100_000)   # 0: no 1-point RANSAC
        checks.whole(self.max_free_iterations, "max_free_iterations", 0, 100_000)   # 0: no cap
        if not isinstance(self.restarts, bool):
            raise InputError(f"restarts must be True or False, not {self.restarts!r}")
        if self.f_range_px is not None:
            pair = self.f_range_px
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise InputError(f"f_range_px must be (low, high) in px, not {pair!r}")
            for value in pair:
                checks.number(value, "f_range_px")
        if self.line_delay_from is not None:
            checks.instance(self.line_delay_from, "line_delay_from", (str, os.PathLike),
                            "the path of an `rscalib linedelay` result.json")
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
        if not isinstance(self.tracks, TrackOptions):
            raise InputError("tracks must be a TrackOptions")
        if self.line_delay_from is not None and self.line_delay_s is not None:
            raise InputError("give the line delay once: --line-delay or --line-delay-from")
        if not (math.isfinite(self.robust_loss_scale_px) and self.robust_loss_scale_px > 0):
            raise InputError(f"the robust loss scale must be a positive number of px, not {self.robust_loss_scale_px!r}")
        if not (isinstance(self.max_keyframes, int) and self.max_keyframes >= 3):
            raise InputError(f"max_keyframes must be at least 3, not {self.max_keyframes!r}")

    @property
    def bundle(self) -> bool:
        """The method adjusts; the baselines are the filters alone."""
        return self.baseline is None
