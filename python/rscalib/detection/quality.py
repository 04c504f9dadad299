"""Quality checks of one detection: blur (edge width) and geometric outliers (local homography)."""
from __future__ import annotations

import functools

import cv2
import numpy as np

from ..io.targets import Target


def edge_width_px(gray: np.ndarray, target: Target, point_id: np.ndarray, uv: np.ndarray) -> float:
    """Blur of a detection: the 75th percentile over the target's black/white edges of the edge
    width (contrast / steepest slope of an intensity profile across the edge), px. About 1 px for
    a sharp edge, about L px for a motion blur of L px across the edge. NaN if unmeasurable."""
    where = np.full(target.num_points, -1)
    where[point_id] = np.arange(len(point_id))
    pairs = target.edge_pairs
    pairs = pairs[(where[pairs] >= 0).all(axis=1)]
    if len(pairs) == 0:
        return float("nan")
    a, b = uv[where[pairs[:, 0]]], uv[where[pairs[:, 1]]]
    length = np.linalg.norm(b - a, axis=1)
    ok = length > 1e-6
    a, b, length = a[ok], b[ok], length[ok]
    t = (b - a) / length[:, None]
    kind = target.target_type
    if kind == "circlegrid":
        # from each centre towards its neighbour, across the circle's rim (both directions)
        start = np.concatenate([a, b])
        direction = np.concatenate([t, -t])
        half = np.concatenate([length, length]) * 0.25
        centre = start + direction * half[:, None]
    else:
        # across the edge at its midpoint, staying inside the two cells it separates
        if kind == "aprilgrid":
            fraction = 0.15            # 2-bit black border inside, 3-bit gap outside a 10-bit tag
        elif kind == "charuco":
            s = target.spec
            fraction = min(0.4, 0.4 * (1 - s["markerLength"] / s["squareLength"]))
        else:
            fraction = 0.4
        centre = 0.5 * (a + b)
        direction = np.column_stack([-t[:, 1], t[:, 0]])
        half = length * fraction
    half = np.minimum(half, 16.0)
    keep = half >= 1.5
    if not keep.any():
        return float("nan")
    centre, direction, half = centre[keep], direction[keep], half[keep]
    samples = 48
    s = np.linspace(-1.0, 1.0, samples)[None, :] * half[:, None]
    map_x = (centre[:, 0:1] + s * direction[:, 0:1]).astype(np.float32)
    map_y = (centre[:, 1:2] + s * direction[:, 1:2]).astype(np.float32)
    profiles = cv2.remap(gray, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
    profiles = (profiles[:, :-2] + profiles[:, 1:-1] + profiles[:, 2:]) / 3.0  # light smoothing
    step = 2.0 * half / (samples - 1)
    ends = max(2, samples // 12)
    contrast = np.abs(profiles[:, -ends:].mean(1) - profiles[:, :ends].mean(1))
    slope = np.abs(np.diff(profiles, axis=1)).max(1) / step
    valid = (contrast > 20.0) & (slope > 0)
    if not valid.any():
        return float("nan")
    # the 3-tap smoothing widens a step by about one sample
    width = contrast[valid] / slope[valid] - step[valid]
    return float(np.percentile(np.maximum(width, 0.0), 75))


_INVERSE_ITERATIONS = 3


@functools.lru_cache(maxsize=32)
def _neighbourhoods(points_bytes: bytes, point_id_bytes: bytes, neighbours: int):
    """The target side of local_homography_residual, the same in every frame that sees the same
    points: each point's nearest neighbours on the target, their normalised coordinates, the
    design's x-rows and whether the neighbourhood is well posed."""
    points = np.frombuffer(points_bytes).reshape(-1, 3)
    point_id = np.frombuffer(point_id_bytes, dtype=np.int64)
    n = len(point_id)
    xy = points[point_id, :2]
    k = min(neighbours, n - 1)
    dist = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    nearest = np.argsort(dist, axis=1)[:, :k]                      # (n, k)
    nx = xy[nearest]                                                # (n, k, 2)
    # Hartley normalisation per neighbourhood
    mx = nx.mean(1, keepdims=True)
    sx = np.sqrt(((nx - mx) ** 2).sum(2).mean(1))[:, None, None] + 1e-300
    x = (nx - mx) / sx
    xh = np.concatenate([x, np.ones(x.shape[:2] + (1,))], axis=2)  # (n, k, 3)
    spread = np.linalg.svd(x, compute_uv=False)                     # (n, 2)
    well_posed = spread[:, 1] > 0.25 * spread[:, 0]
    p = np.concatenate([(xy[:, None, :] - mx) / sx, np.ones((n, 1, 1))], axis=2)[:, 0, :]
    for array in (nearest, xh, well_posed, p):
        array.flags.writeable = False
    return nearest, xh, well_posed, p


def local_homography_residual(target: Target, point_id: np.ndarray, uv: np.ndarray, neighbours: int = 8) -> np.ndarray:
    """For each detected point, the distance from its pixel to the prediction of a homography
    fitted to its nearest detected neighbours on the target, in units of the local grid step
    (the pixel distance to its nearest target neighbour). NaN where the neighbours are too few
    or collinear. Local fits tolerate lens distortion; a wrong id or a stray point stands out."""
    n = len(point_id)
    result = np.full(n, np.nan)
    if n < 6:
        return result
    nearest, xh, well_posed, p = _neighbourhoods(np.ascontiguousarray(target.points_m, dtype=np.float64).tobytes(),
                                                 np.ascontiguousarray(point_id, dtype=np.int64).tobytes(), neighbours)
    nu = uv[nearest]                                                # (n, k, 2)
    mu = nu.mean(1, keepdims=True)
    su = np.sqrt(((nu - mu) ** 2).sum(2).mean(1))[:, None, None] + 1e-300
    u = (nu - mu) / su
    zeros = np.zeros(xh.shape)
    row1 = np.concatenate([xh, zeros, -u[..., :1] * xh], axis=2)
    row2 = np.concatenate([zeros, xh, -u[..., 1:] * xh], axis=2)
    design = np.concatenate([row1, row2], axis=1)                     # (n, 2k, 9)
    # The null vector of each D^T D (the last right singular vector of D): inverse iteration from
    # the homography with h33 = 1 (the normalisation centres both sides, so h33 is far from 0),
    # batched 9x9 solves: several times cheaper than eigh, the same vector to rounding on real
    # detections, and this runs on every detected frame.
    normal = design.transpose(0, 2, 1) @ design                       # (n, 9, 9)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        try:
            h = np.concatenate([np.linalg.solve(normal[:, :8, :8], -normal[:, :8, 8:9])[..., 0], np.ones((n, 1))],
                               axis=1)
            shift = 1e-12 * np.trace(normal, axis1=1, axis2=2)[:, None, None] * np.eye(9)
            for _ in range(_INVERSE_ITERATIONS):
                h = np.linalg.solve(normal + shift, h[..., None])[..., 0]
                h /= np.linalg.norm(h, axis=1, keepdims=True)
        except np.linalg.LinAlgError:  # a degenerate neighbourhood: the eigenvectors, one batch
            h = np.linalg.eigh(normal)[1][:, :, 0]
        h = h.reshape(n, 3, 3)
        q = np.einsum("nij,nj->ni", h, p)
        predicted = q[:, :2] / q[:, 2:3] * su[:, 0] + mu[:, 0]
        step_px = np.linalg.norm(uv[nearest[:, 0]] - uv, axis=1)
        residual = np.linalg.norm(predicted - uv, axis=1) / step_px
    result[well_posed] = residual[well_posed]
    return result
