"""Quality checks of one detection: blur (edge width) and geometric outliers (local homography)."""
from __future__ import annotations

import functools

import cv2
import numpy as np

from .. import _core
from ..io.targets import Target

_PROFILE_SAMPLES = 48
_PROFILE_S = np.linspace(-1.0, 1.0, _PROFILE_SAMPLES)
_MAX_HALF_PX = 16.0   # a profile's half length at most
_MIN_HALF_PX = 1.5    # shorter profiles are left out
_MIN_CONTRAST = 20.0  # grey levels: flatter profiles (no edge) are left out


@functools.lru_cache(maxsize=64)
def _edge_rows(pairs_bytes: bytes, num_points: int, point_id_bytes: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Rows of a detection (its point_id order) at both ends of each target edge it sees whole:
    the same for every frame that sees the same points (tracked frames see all of them)."""
    pairs = np.frombuffer(pairs_bytes, dtype=np.int64).reshape(-1, 2)
    point_id = np.frombuffer(point_id_bytes, dtype=np.int64)
    where = np.full(num_points, -1)
    where[point_id] = np.arange(len(point_id))
    rows = where[pairs[(where[pairs] >= 0).all(axis=1)]]
    first, second = np.ascontiguousarray(rows[:, 0]), np.ascontiguousarray(rows[:, 1])
    first.flags.writeable = second.flags.writeable = False
    return first, second


def edge_width_px(gray: np.ndarray, target: Target, point_id: np.ndarray, uv: np.ndarray) -> float:
    """Blur of a detection: the 75th percentile over the target's black/white edges of the edge
    width (contrast / steepest slope of an intensity profile across the edge), px. About 1 px for
    a sharp edge, about L px for a motion blur of L px across the edge. NaN if unmeasurable."""
    first, second = _edge_rows(np.ascontiguousarray(target.edge_pairs, dtype=np.int64).tobytes(), target.num_points,
                               np.ascontiguousarray(point_id, dtype=np.int64).tobytes())
    if len(first) == 0:
        return float("nan")
    kind = target.target_type
    if kind == "circlegrid":
        fraction = 0.25   # from each centre towards its neighbour, across the circle's rim (both directions)
    elif kind == "aprilgrid":
        fraction = 0.15   # 2-bit black border inside, 3-bit gap outside a 10-bit tag
    elif kind == "charuco":
        s = target.spec
        fraction = min(0.4, 0.4 * (1 - s["markerLength"] / s["squareLength"]))
    else:
        fraction = 0.4    # across the edge at its midpoint, staying inside the two cells it separates
    # the profiles' places and the width from them in the core (numpy's numbers, ~40 numpy calls
    # fewer a frame), the sampling by OpenCV
    map_x, map_y, half = _core.edge_profile_maps(uv[first], uv[second], kind == "circlegrid", fraction,
                                                 _PROFILE_S, _MAX_HALF_PX, _MIN_HALF_PX)
    if len(half) == 0:
        return float("nan")
    profiles = cv2.remap(gray, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return _core.edge_width_from_profiles(profiles.astype(np.float64), half, _MIN_CONTRAST)


@functools.lru_cache(maxsize=32)
def _neighbourhoods(points_bytes: bytes, point_id_bytes: bytes, neighbours: int):
    """The target side of local_homography_residual, the same in every frame that sees the same
    points: the points' target coordinates, each one's nearest neighbours on the target and
    whether that neighbourhood is well posed (not nearly collinear)."""
    points = np.frombuffer(points_bytes).reshape(-1, 3)
    point_id = np.frombuffer(point_id_bytes, dtype=np.int64)
    n = len(point_id)
    xy = np.ascontiguousarray(points[point_id, :2])
    k = min(neighbours, n - 1)
    dist = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    nearest = np.ascontiguousarray(np.argsort(dist, axis=1)[:, :k], dtype=np.int32)   # (n, k)
    nx = xy[nearest]                                                # (n, k, 2)
    centred = nx - nx.mean(1, keepdims=True)
    spread = np.linalg.svd(centred, compute_uv=False)               # (n, 2)
    well_posed = spread[:, 1] > 0.25 * spread[:, 0]
    for array in (xy, nearest, well_posed):
        array.flags.writeable = False
    return xy, nearest, well_posed


def local_homography_residual(target: Target, point_id: np.ndarray, uv: np.ndarray, neighbours: int = 8) -> np.ndarray:
    """For each detected point, the distance from its pixel to the prediction of a homography
    fitted to its nearest detected neighbours on the target, in units of the local grid step
    (the pixel distance to its nearest target neighbour). NaN where the neighbours are too few
    or collinear. Local fits tolerate lens distortion; a wrong id or a stray point stands out.
    The fits (the normalised DLT, one per point, on every detected frame) run in the core."""
    n = len(point_id)
    result = np.full(n, np.nan)
    if n < 6:
        return result
    xy, nearest, well_posed = _neighbourhoods(np.ascontiguousarray(target.points_m, dtype=np.float64).tobytes(),
                                              np.ascontiguousarray(point_id, dtype=np.int64).tobytes(), neighbours)
    residual = _core.local_homography_residual(xy, np.ascontiguousarray(uv, dtype=np.float64), nearest)
    result[well_posed] = residual[well_posed]
    return result
