"""Every option of target detection, with its default: the one place a default is written.

The detector settings change the detections and are part of the cache key
(:meth:`DetectOptions.fingerprint`); workers, cache and cache_dir only say how the work is done.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Optional, Union

from .. import checks

# the fields that say how detection runs, not what it finds (not in the cache key)
RUN_FIELDS = ("workers", "cache", "cache_dir")
MAX_BLUR_PX = 100.0           # max_blur_px at most (the CLI's --max-blur-px)
MAX_RESIDUAL = 10.0           # max_residual at most: grid steps
MIN_SEARCH_SIDE_PX = 16       # max_search_side_px at least
MAX_SUBPIX_WINDOW_PX = 50     # subpix_window_px at most (the CLI's --subpix-window)
MAX_RUN_FRAMES = 1000         # full_detection_every at most: a worker holds a run's frames


@dataclass(frozen=True)
class DetectOptions:
    """Detector settings (part of the cache key) and how detection runs."""

    max_blur_px: float = 8.0            # edge width (contrast / steepest slope) of a sharp frame, px
    max_residual: float = 0.3           # local-homography residual, in grid steps
    min_points: int = 8                 # partial views (aprilgrid, charuco) with fewer are dropped
    max_search_side_px: int = 1280      # checkerboards: search on a downscaled copy above this
    subpix_window_px: Optional[int] = None  # cornerSubPix half-window; None: from the grid step
    check_outer_ring: bool = True       # checkerboards: the squares around the found grid must alternate
    refine_circles: bool = True         # circle grids: grey-level centroid instead of the blob detector's
    full_detection_every: int = 40      # checkerboards in videos: track between full detections (tracking.py); 1 = off
    # how it runs
    workers: Optional[int] = None       # processes (None: the usable cores; in this process for short inputs)
    cache: bool = True                  # reuse the detections of the same bytes, target and settings
    cache_dir: Union[None, str, Path] = None   # None: the user's cache folder (detection.cache.default_cache_dir)

    def __post_init__(self) -> None:
        # the CLI's ranges (cli/intrinsics.py uses these limits), refused with the field's name;
        # whole numbers given as floats (1e3) are kept as ints
        def put(name, value):
            object.__setattr__(self, name, value)

        checks.number(self.max_blur_px, "max_blur_px (the largest edge width of a sharp frame)", 0.0, MAX_BLUR_PX,
                      " px", low_open=True)
        checks.number(self.max_residual, "max_residual", 0.0, MAX_RESIDUAL, " grid steps", low_open=True)
        put("min_points", checks.whole(self.min_points, "min_points", 1))
        put("max_search_side_px", checks.whole(self.max_search_side_px, "max_search_side_px", MIN_SEARCH_SIDE_PX,
                                               checks.MAX_IMAGE_SIDE_PX, " px"))
        if self.subpix_window_px is not None:
            put("subpix_window_px", checks.whole(self.subpix_window_px, "subpix_window_px (the corner refinement "
                                                 "window)", 1, MAX_SUBPIX_WINDOW_PX, " px"))
        put("full_detection_every", checks.whole(self.full_detection_every, "full_detection_every", 1,
                                                 MAX_RUN_FRAMES, " frames"))
        if self.workers is not None:
            put("workers", checks.whole(self.workers, "workers (detection processes)", 1))
        if self.cache_dir is not None:
            checks.path(self.cache_dir, "cache_dir")

    def fingerprint(self) -> str:
        """The settings that change the detections, as a stable string (the cache key)."""
        settings = {k: v for k, v in asdict(self).items() if k not in RUN_FIELDS}
        return json.dumps(settings, sort_keys=True)
