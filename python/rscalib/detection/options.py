"""Every option of target detection, with its default: the one place a default is written.

The detector settings change the detections and are part of the cache key
(:meth:`DetectOptions.fingerprint`); workers, cache and cache_dir only say how the work is done.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Optional, Union

from ..errors import InputError

# the fields that say how detection runs, not what it finds (not in the cache key)
RUN_FIELDS = ("workers", "cache", "cache_dir")


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
    full_detection_every: int = 20      # checkerboards in videos: track between full detections (tracking.py); 1 = off
    # how it runs
    workers: Optional[int] = None       # processes (None: the usable cores; in this process for short inputs)
    cache: bool = True                  # reuse the detections of the same bytes, target and settings
    cache_dir: Union[None, str, Path] = None   # None: the user's cache folder (detection.cache.default_cache_dir)

    def __post_init__(self) -> None:
        if not self.max_blur_px > 0:
            raise InputError(f"the largest edge width of a sharp frame must be positive, not {self.max_blur_px!r}")
        if self.subpix_window_px is not None and not (isinstance(self.subpix_window_px, int)
                                                      and self.subpix_window_px >= 1):
            raise InputError(f"the corner refinement window must be at least 1 px, not {self.subpix_window_px!r}")
        if self.workers is not None and not (isinstance(self.workers, int) and self.workers >= 1):
            raise InputError(f"detection workers must be at least 1, not {self.workers!r}")

    def fingerprint(self) -> str:
        """The settings that change the detections, as a stable string (the cache key)."""
        settings = {k: v for k, v in asdict(self).items() if k not in RUN_FIELDS}
        return json.dumps(settings, sort_keys=True)
