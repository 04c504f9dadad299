"""Detection noise from the data: the pixel sigma behind E[J] = 2N (paper eq. 23, docs/formulation.md §8).

Along a straight line of equally spaced target points, the projected image positions are a
smooth function of the index (perspective, lens distortion and the rolling-shutter shift are
all low-order over a few grid steps), so their third difference is nearly zero while for
independent noise it has variance (1 + 9 + 9 + 1) sigma^2 = 20 sigma^2. A robust scale of the
third differences over all frames therefore estimates sigma without any trajectory model.
"""
from __future__ import annotations

import numpy as np

from ..observations import Observations

# sigma = median|x| / (Phi^-1(3/4) * sqrt(20)) for x ~ N(0, 20 sigma^2)
_MAD_TO_SIGMA = 1.0 / 0.6744897501960817
_THIRD_DIFFERENCE_VARIANCE = 20.0


def grid_line_quadruples(target_points: np.ndarray, tolerance_m: float = 1e-6) -> np.ndarray:
    """(Q, 4) ids (a, b, c, d) of target points that are collinear and equally spaced by the
    smallest point spacing: b = a + s, c = a + 2s, d = a + 3s."""
    points = np.asarray(target_points, dtype=np.float64)
    if len(points) < 4:
        return np.zeros((0, 4), dtype=np.int64)
    diff = points[None, :, :] - points[:, None, :]
    dist = np.linalg.norm(diff, axis=2)
    spacing = dist[dist > tolerance_m].min()
    steps = diff[np.abs(dist - spacing) <= max(tolerance_m, 1e-6 * spacing)]
    # one orientation of each step direction
    unique_steps: list[np.ndarray] = []
    for s in steps:
        if not any(np.allclose(s, u, atol=tolerance_m) or np.allclose(s, -u, atol=tolerance_m) for u in unique_steps):
            unique_steps.append(s)
    key = lambda p: tuple(np.round(p / tolerance_m).astype(np.int64))  # noqa: E731
    index = {key(p): i for i, p in enumerate(points)}
    quads = []
    for a, p in enumerate(points):
        for s in unique_steps:
            ids = [index.get(key(p + k * s)) for k in (1, 2, 3)]
            if all(i is not None for i in ids):
                quads.append([a, *ids])
    return np.asarray(quads, dtype=np.int64).reshape(-1, 4)


def third_differences(observations: Observations, quadruples: np.ndarray | None = None) -> np.ndarray:
    """All third differences y_d - 3 y_c + 3 y_b - y_a (u and v separately) of grid-line
    quadruples fully seen in one frame; 1-D array."""
    if quadruples is None:
        quadruples = grid_line_quadruples(observations.target_points)
    if len(quadruples) == 0 or observations.num_observations == 0:
        return np.zeros(0)
    num_points = len(observations.target_points)
    # uv lookup per (frame, point); NaN where unseen
    table = np.full((observations.num_frames, num_points, 2), np.nan)
    table[observations.frame_index, observations.point_id] = observations.uv
    a, b, c, d = (table[:, quadruples[:, k]] for k in range(4))
    third = d - 3.0 * c + 3.0 * b - a
    return third[np.isfinite(third)].ravel()


def estimate_pixel_sigma(observations: Observations, min_samples: int = 50) -> float | None:
    """Robust detection-noise sigma (px) from grid-line third differences, or None when the
    target has too few equally spaced collinear points in view."""
    third = third_differences(observations)
    if third.size < min_samples:
        return None
    return float(np.median(np.abs(third)) * _MAD_TO_SIGMA / np.sqrt(_THIRD_DIFFERENCE_VARIANCE))
