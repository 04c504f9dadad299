"""Target observations: what detection produces and the line-delay engine consumes.

Flat arrays (one row per detected target point) rather than per-frame lists, so that
long videos hand over to the C++ core without Python loops. Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import checks
from .errors import InputError


@dataclass
class Observations:
    """Detected target points of a video.

    frame_times_s: (F,) time at which image row 0 of each frame is exposed, seconds, increasing.
    frame_index:   (M,) int, which frame each observation belongs to (index into frame_times_s).
    point_id:      (M,) int, which target point was seen (index into target_points).
    uv:            (M, 2) measured pixel coordinates (OpenCV convention: origin at the centre of
                   the top-left pixel, u right, v down).
    target_points: (P, 3) target points in the target (= world) frame, metres, z = 0.
    image_size:    (width, height) in pixels.
    """

    frame_times_s: np.ndarray
    frame_index: np.ndarray
    point_id: np.ndarray
    uv: np.ndarray
    target_points: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        # rscalib.checks: finite numbers of the right shapes, whole-number indices, an image size that
        # can exist; each refusal names the field
        self.frame_times_s = np.ascontiguousarray(
            checks.finite_array(np.reshape(self.frame_times_s, -1), "observations: frame_times_s"))
        self.frame_index = checks.index_array(self.frame_index, "observations: frame_index")
        self.point_id = checks.index_array(self.point_id, "observations: point_id")
        self.uv = np.ascontiguousarray(checks.finite_array(self.uv, "observations: uv", columns=2))
        self.target_points = np.ascontiguousarray(
            checks.finite_array(self.target_points, "observations: target_points", columns=3))
        self.image_size = checks.image_size(self.image_size, "observations: image_size")
        m = len(self.uv)
        if len(self.frame_index) != m or len(self.point_id) != m:
            raise InputError("observations: frame_index, point_id and uv must have the same length")
        if m and (self.frame_index.min() < 0 or self.frame_index.max() >= len(self.frame_times_s)):
            raise InputError("observations: frame_index out of range of frame_times_s")
        if m and (self.point_id.min() < 0 or self.point_id.max() >= len(self.target_points)):
            raise InputError("observations: point_id out of range of target_points")
        if np.any(np.diff(self.frame_times_s) <= 0):
            raise InputError("observations: frame timestamps (frame_times_s) must be strictly increasing")

    @property
    def num_frames(self) -> int:
        return len(self.frame_times_s)

    @property
    def num_observations(self) -> int:
        return len(self.uv)

    @property
    def rows(self) -> int:
        return self.image_size[1]

    def points_w(self) -> np.ndarray:
        """(M, 3) target point of each observation."""
        return self.target_points[self.point_id]

    def frame_slices(self) -> list[np.ndarray]:
        """Indices of the observations of each frame (empty arrays for frames with none)."""
        order = np.argsort(self.frame_index, kind="stable")
        bounds = np.searchsorted(self.frame_index[order], np.arange(self.num_frames + 1))
        return [order[bounds[i]:bounds[i + 1]] for i in range(self.num_frames)]

    def subset_frames(self, keep: np.ndarray) -> Observations:
        """Observations of the frames where `keep` (bool, (F,)) is true, re-indexed."""
        keep = np.asarray(keep, dtype=bool)
        new_index = np.cumsum(keep) - 1
        mask = keep[self.frame_index]
        return Observations(self.frame_times_s[keep], new_index[self.frame_index[mask]],
                            self.point_id[mask], self.uv[mask], self.target_points, self.image_size)
