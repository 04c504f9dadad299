"""The start of the bundle adjustment (docs/sog.md §24): the tracks at keyframes
(tracks.TrackSet.keyframe_observations), the keyframes' poses from the filter's pass, and each
track's point triangulated from them with the filter's camera — what adjustment.adjust takes.

The filter's camera may be far off (its f 48 % low on the real desk video) and its poses with it;
the adjustment moves them. A track that cannot be triangulated in front of its cameras (too little
parallax, a far point) starts on its first ray at the median depth of the others: inverse-depth
points make that harmless (a far point is a small rho).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._core import CameraModel, rotation_matrix_to_vector, rotation_vector_to_matrix
from ..errors import InputError
from .adjustment import KeyframeTracks
from .tracks import KeyframeObservations


@dataclass
class FilterPoses:
    """The filter's camera pose at every processed frame: ``R_cw`` (F, 3, 3), ``p_cw`` (F, 3)
    (x_c = R_cw x_w + p_cw, the filter's world: its first camera), indexed by frame."""

    R_cw: np.ndarray
    p_cw: np.ndarray

    @classmethod
    def from_states(cls, camera_states: list) -> FilterPoses:
        """From the bank's merged camera states [r_w (3), q_wc (w, x, y, z), ...] per frame."""
        states = np.asarray(camera_states, float).reshape(len(camera_states), -1)
        w, x, y, z = states[:, 3], states[:, 4], states[:, 5], states[:, 6]
        R_wc = np.stack([np.c_[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         np.c_[2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         np.c_[2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]], axis=1)
        R_cw = np.transpose(R_wc, (0, 2, 1))
        return cls(R_cw, -np.einsum("nij,nj->ni", R_cw, states[:, :3]))

    def states(self, frames: np.ndarray) -> np.ndarray:
        """(K, 6) [p; phi] T_cw at these frames."""
        frames = np.asarray(frames, np.int64)
        if len(frames) and (frames.min() < 0 or frames.max() >= len(self.R_cw)):
            raise InputError("a keyframe has no pose of the filter")
        return np.array([np.r_[self.p_cw[f], rotation_matrix_to_vector(self.R_cw[f])] for f in frames])


@dataclass
class KeyframePoses:
    """Poses at some frames (an adjustment's keyframes): ``frames`` (K,), ``states`` (K, 6) [p; phi] T_cw."""

    frames: np.ndarray
    states_cw: np.ndarray

    def states(self, frames: np.ndarray) -> np.ndarray:
        index = {int(f): i for i, f in enumerate(self.frames)}
        missing = [int(f) for f in frames if int(f) not in index]
        if missing:
            raise InputError(f"no pose at frames {missing[:5]}")
        return self.states_cw[[index[int(f)] for f in frames]]


def subset(observations: KeyframeObservations, tracks: int, min_keyframes: int) -> KeyframeObservations:
    """The observations of the ``tracks`` tracks seen in most keyframes (a quick first adjustment:
    few points, the same keyframes)."""
    ids, counts = np.unique(observations.track_id, return_counts=True)
    keep = ids[np.argsort(-counts, kind="stable")[:tracks]]
    keep = keep[np.isin(keep, ids[counts >= min_keyframes])]
    rows = np.flatnonzero(np.isin(observations.track_id, keep))
    sigma = observations.position_sigma[rows] if len(observations.position_sigma) == len(observations) \
        else np.full(len(rows), np.nan)
    return KeyframeObservations(observations.frame[rows], observations.t_s[rows], observations.track_id[rows],
                                observations.uv_px[rows], observations.velocity_px_s[rows], observations.keyframes,
                                sigma)


def triangulate(rays: np.ndarray, views: np.ndarray, point: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """World points (P, 3) of every point index from its normalised rays (N, 3, z = 1) in the views
    (N,) of ``poses`` (K, 6): linear (DLT) triangulation; NaN rows where it fails or the point is not
    in front of every camera that sees it."""
    rotations = np.array([rotation_vector_to_matrix(p[3:]) for p in poses])
    projections = np.concatenate([rotations, poses[:, :3, None]], axis=2)       # (K, 3, 4)
    rows_x = rays[:, :1] * projections[views, 2] - projections[views, 0]        # (N, 4)
    rows_y = rays[:, 1:2] * projections[views, 2] - projections[views, 1]
    count = int(point.max()) + 1 if len(point) else 0
    normal = np.zeros((count, 4, 4))
    np.add.at(normal, point, np.einsum("ni,nj->nij", rows_x, rows_x) + np.einsum("ni,nj->nij", rows_y, rows_y))
    _, vectors = np.linalg.eigh(normal)
    homogeneous = vectors[:, :, 0]                                               # the smallest eigenvalue's
    with np.errstate(divide="ignore", invalid="ignore"):
        points = homogeneous[:, :3] / homogeneous[:, 3:]
    depth = np.einsum("nij,nj->ni", rotations[views], points[point])[:, 2] + poses[views, 2]
    behind = np.zeros(count, bool)
    np.logical_or.at(behind, point, ~(depth > 0))
    points[behind | ~np.all(np.isfinite(points), axis=1)] = np.nan
    return points


def adjustment_start(observations: KeyframeObservations, poses, camera: CameraModel) -> KeyframeTracks:
    """The adjustment's start (KeyframeTracks) from the tracks at keyframes, poses at those keyframes
    (FilterPoses or KeyframePoses: anything with .states(frames)) and a camera to undistort with."""
    keyframes = np.asarray(observations.keyframes, np.int64)
    index_of = {int(f): i for i, f in enumerate(keyframes)}
    views = np.array([index_of[int(f)] for f in observations.frame], np.int64)
    _, point = np.unique(observations.track_id, return_inverse=True)
    kf_poses = poses.states(keyframes)
    rays = np.asarray(camera.unproject(observations.uv_px), float)
    points = triangulate(rays, views, point, kf_poses)
    missing = ~np.all(np.isfinite(points), axis=1)
    if missing.any():
        good = ~missing
        depths = _depths(points, views, point, kf_poses, good)
        median = float(np.median(depths)) if len(depths) else 1.0
        first = np.full(len(points), -1)
        first[point[::-1]] = np.arange(len(point))[::-1]   # each point's first observation
        for j in np.flatnonzero(missing):
            r = first[j]
            R = rotation_vector_to_matrix(kf_poses[views[r], 3:])
            ray = rays[r] / np.linalg.norm(rays[r])
            points[j] = R.T @ (ray * median - kf_poses[views[r], :3])
    return KeyframeTracks(keyframe_poses=kf_poses, keyframe=views, point=point.astype(np.int64),
                          uv_px=np.asarray(observations.uv_px, float),
                          image_velocity_px_s=np.asarray(observations.velocity_px_s, float), points_w=points)


def _depths(points, views, point, poses, good) -> np.ndarray:
    rows = good[point]
    R = np.array([rotation_vector_to_matrix(p[3:]) for p in poses])
    return (np.einsum("nij,nj->ni", R[views[rows]], points[point[rows]]) + poses[views[rows], :3])[:, 2]


def halves(observations: KeyframeObservations, min_keyframes: int) -> list:
    """The observations of the first and the second half of the keyframes (split at the middle
    keyframe), each keeping the tracks seen in at least ``min_keyframes`` of its own keyframes:
    two independent estimates of the same camera (the self-check, docs/sog.md §24)."""
    keyframes = np.asarray(observations.keyframes, np.int64)
    middle = len(keyframes) // 2
    parts = []
    for own in (keyframes[:middle], keyframes[middle:]):
        rows = np.flatnonzero(np.isin(observations.frame, own))
        ids, counts = np.unique(observations.track_id[rows], return_counts=True)
        rows = rows[np.isin(observations.track_id[rows], ids[counts >= min_keyframes])]
        sigma = observations.position_sigma[rows] if len(observations.position_sigma) == len(observations) \
            else np.full(len(rows), np.nan)
        parts.append(KeyframeObservations(observations.frame[rows], observations.t_s[rows],
                                          observations.track_id[rows], observations.uv_px[rows],
                                          observations.velocity_px_s[rows], own, sigma))
    return parts
