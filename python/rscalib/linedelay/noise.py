"""Detection noise from the data: the pixel sigma behind E[J] = 2N (paper eq. 23, docs/formulation.md §8).

Along a straight line of equally spaced target points, the projected image positions are a
smooth function of the index (perspective, lens distortion and the rolling-shutter shift are
all low-order over a few grid steps), so their third difference is nearly zero while for
independent noise it has variance (1 + 9 + 9 + 1) sigma^2 = 20 sigma^2. A robust scale of the
third differences over all frames therefore estimates sigma without any trajectory model.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..observations import Observations

# sigma = median|x| / (Phi^-1(3/4) * sqrt(20)) for x ~ N(0, 20 sigma^2)
_MAD_TO_SIGMA = 1.0 / 0.6744897501960817
_THIRD_DIFFERENCE_VARIANCE = 20.0


def grid_line_quadruples(target_points: np.ndarray, tolerance_m: float = 1e-6) -> np.ndarray:
    """(Q, 4) ids (a, b, c, d) of target points that are collinear and equally spaced by the
    smallest point spacing: b = a + s, c = a + 2s, d = a + 3s (read-only: shared by every solve of
    the same target, each of which asked for it anew at 50 ms a time)."""
    points = np.ascontiguousarray(target_points, dtype=np.float64)
    return _grid_line_quadruples(points.tobytes(), points.shape, float(tolerance_m))


@functools.lru_cache(maxsize=16)
def _grid_line_quadruples(points_bytes: bytes, shape: tuple, tolerance_m: float) -> np.ndarray:
    points = np.frombuffer(points_bytes, dtype=np.float64).reshape(shape)
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
    quads = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    quads.flags.writeable = False
    return quads


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


# --------------------------------------------------------------------------- the noise model of issue 12
# Real detection noise changes from frame to frame (motion blur, compression, board distance), and
# on a nearly still board it repeats from frame to frame (a fixed error pattern per corner that no
# trajectory can fit). docs/formulation.md §8 describes the three parts below.

# Frames with few third differences borrow strength from the video's sigma: a frame's variance is
# the mean of its own n samples' and SHRINK_SAMPLES samples at the video's value.
SHRINK_SAMPLES = 40
# The lag-1 correlation used for the inflation is capped: beyond it the data carry almost no
# independent information and the self-check / determinacy test decide.
MAX_CORRELATION = 0.9


def frame_pixel_sigma(observations: Observations, video_sigma: float,
                      quadruples: np.ndarray | None = None) -> np.ndarray:
    """(F,) detection-noise sigma of each frame (px): the robust scale of that frame's grid third
    differences, shrunk towards `video_sigma` (the frame's n samples weigh against SHRINK_SAMPLES
    samples at the video's value), so a blurred or badly compressed frame is down-weighted."""
    if quadruples is None:
        quadruples = grid_line_quadruples(observations.target_points)
    sigma = np.full(observations.num_frames, float(video_sigma))
    if len(quadruples) == 0 or observations.num_observations == 0:
        return sigma
    num_points = len(observations.target_points)
    table = np.full((observations.num_frames, num_points, 2), np.nan)
    table[observations.frame_index, observations.point_id] = observations.uv
    a, b, c, d = (table[:, quadruples[:, k]] for k in range(4))
    third = np.abs(d - 3.0 * c + 3.0 * b - a).reshape(observations.num_frames, -1)
    # each frame's median |x| over its finite samples, all frames at once (NaNs sort last; the
    # mean of the middle two of an even count, as np.median): a loop over frames took 0.1 s a solve
    n = np.isfinite(third).sum(axis=1)
    ordered = np.sort(third, axis=1)
    rows = np.flatnonzero(n >= 4)
    upper = ordered[rows, n[rows] // 2]
    lower = ordered[rows, (n[rows] - 1) // 2]
    own = np.where(n[rows] % 2 == 1, upper, (lower + upper) / 2.0) * _MAD_TO_SIGMA / np.sqrt(_THIRD_DIFFERENCE_VARIANCE)
    count = n[rows].astype(np.float64)
    own_squared = np.array([x ** 2 for x in own.tolist()])   # libm's pow, as the loop had it (not x * x)
    sigma[rows] = np.sqrt((count * own_squared + SHRINK_SAMPLES * video_sigma ** 2) / (count + SHRINK_SAMPLES))
    return np.maximum(sigma, 1e-3)


@dataclass
class ResidualStructure:
    """What the residuals of a solve say about the noise beyond the white per-frame part.

    fixed_pattern_px: sigma (per coordinate) of an error that repeats for the same corner in the
        next frame (a still board's detection bias): the square root of the lag-1 autocovariance of
        the detrended residuals. It adds to every observation's variance.
    correlation: lag-1 correlation of a corner's standardised residuals between consecutive
        frames (0 for independent errors; near 1 when the same error repeats).
    inflation: sqrt((1 + rho) / (1 - rho)) with rho = clip(correlation, 0, MAX_CORRELATION): the
        factor by which correlated errors widen sigma_d (N frames carry the information of
        N (1 - rho) / (1 + rho) independent ones, AR(1))."""

    fixed_pattern_px: float
    correlation: float
    inflation: float
    pairs: int


def detrend_per_frame(observations: Observations, residual_px: np.ndarray, min_points: int = 8) -> np.ndarray:
    """Residuals less, in each frame, their best affine function of (u, v): what a small pose error
    of that frame would explain (a smooth field over the board) is removed, a corner's own error is
    kept (scaled by sqrt(n / (n - 3)) for the 3 fitted values per coordinate). Frames with fewer than
    min_points corners give NaN."""
    residual = np.asarray(residual_px, dtype=np.float64)
    out = np.full_like(residual, np.nan)
    ok = np.all(np.isfinite(residual), axis=1)
    frames = observations.frame_index[ok]
    count = np.bincount(frames, minlength=observations.num_frames).astype(np.float64)
    keep = count[frames] >= min_points
    rows, frames = np.flatnonzero(ok)[keep], frames[keep]
    if not len(rows):
        return out
    n = count[frames][:, None]

    def frame_sum(values: np.ndarray) -> np.ndarray:  # (k, c) -> (frames, c)
        return np.stack([np.bincount(frames, weights=column, minlength=observations.num_frames)
                         for column in values.T], axis=1)

    # All frames at once: the fitted intercept of an affine fit with centred (u, v) is the mean
    # residual, and the slopes solve the 2 x 2 normal equations (pinv: min-norm, as lstsq).
    uv = observations.uv[rows] - frame_sum(observations.uv[rows])[frames] / n
    r = residual[rows] - frame_sum(residual[rows])[frames] / n
    s = frame_sum(np.c_[uv[:, 0] * uv[:, 0], uv[:, 0] * uv[:, 1], uv[:, 1] * uv[:, 1]])
    normal = np.stack([s[:, [0, 1]], s[:, [1, 2]]], axis=1)                                   # (F, 2, 2)
    cross = frame_sum(np.c_[uv[:, [0]] * r, uv[:, [1]] * r]).reshape(-1, 2, r.shape[1])      # (F, 2, c)
    slopes = np.linalg.pinv(normal) @ cross
    out[rows] = (r - np.einsum("ki,kic->kc", uv, slopes[frames])) * np.sqrt(n / (n - 3))
    return out


def residual_structure(observations: Observations, residual_px: np.ndarray, sigma_obs: np.ndarray
                       ) -> ResidualStructure:
    """The fixed pattern and the frame-to-frame correlation of a solve's residuals."""
    residual = detrend_per_frame(observations, residual_px)
    ok = np.all(np.isfinite(residual), axis=1)
    frames = observations.frame_index
    points = observations.point_id
    num_points = len(observations.target_points)
    key = frames * num_points + points
    index = np.full(observations.num_frames * num_points, -1)
    index[key[ok]] = np.flatnonzero(ok)
    # consecutive used frames seeing the same corner
    following = np.full(len(key), -1)
    nxt = key + num_points
    valid = ok & (frames + 1 < observations.num_frames)
    following[valid] = index[nxt[valid]]
    pair = following >= 0
    std = residual / sigma_obs[:, None]
    if pair.sum() >= 20:
        a, b = std[pair], std[following[pair]]
        correlation = float(np.sum(a * b) / math.sqrt(np.sum(a * a) * np.sum(b * b)))
    else:
        correlation = 0.0
    # the repeating part: the lag-1 autocovariance of a corner's detrended residuals (px², per
    # coordinate) is the variance of what the next frame repeats (white noise contributes nothing)
    fixed = 0.0
    if pair.sum() >= 20:
        ra, rb = residual[pair], residual[following[pair]]
        fixed = math.sqrt(max(0.0, float(np.mean(ra * rb))))
    rho = min(max(correlation, 0.0), MAX_CORRELATION)
    return ResidualStructure(fixed, correlation, math.sqrt((1.0 + rho) / (1.0 - rho)), int(pair.sum()))
