"""The self-calibration bundle adjustment in C++ (Ceres; docs/sog.md §23): a thin wrapper.

:func:`adjust` takes feature tracks at keyframes (:class:`KeyframeTracks`: keyframe start poses,
observations, the tracks' image velocities, start points) and a start camera, and returns an
:class:`AdjustmentResult`: the camera, the line delay, their covariances (the model's, clustered by
track, clustered by track and keyframe) with 99 % bounds, and the solver's facts. The engine is
``rscalib._core.solve_bundle``; this module only converts arrays.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence, Union

import numpy as np

from .. import _core
from ..errors import InputError

__all__ = ["AdjustmentResult", "KeyframeTracks", "adjust", "anchored_points"]

Z99 = 2.5758293035489004  # two-sided 99 % normal quantile


@dataclass
class KeyframeTracks:
    """Feature tracks at keyframes. ``keyframe_poses`` (K, 6) the start poses ``[p; phi]``
    (T_cw, ``x_c = R(phi) x_w + p``); per observation (N): ``keyframe`` and ``point`` indices,
    ``uv_px`` (N, 2) distorted pixels and ``image_velocity_px_s`` (N, 2) the track's image
    velocity there (None or NaN rows: still). Start points either ``points_w`` (P, 3) in the world
    (anchored in each point's first keyframe by :func:`anchored_points`) or ``point_anchor`` (P,)
    with ``points_anchored`` (P, 3) ``(a, b, rho)``: the point in its anchor camera is
    ``(a, b, 1) / rho``."""

    keyframe_poses: np.ndarray
    keyframe: np.ndarray
    point: np.ndarray
    uv_px: np.ndarray
    image_velocity_px_s: Optional[np.ndarray] = None
    points_w: Optional[np.ndarray] = None
    point_anchor: Optional[np.ndarray] = None
    points_anchored: Optional[np.ndarray] = None


@dataclass
class AdjustmentResult:
    """The adjusted camera and line delay with covariances over ``names`` (the camera's
    parameters, then ``line_delay_s``; zero rows and columns where held) and 99 % bounds
    (``[lo, hi]`` per name): ``*_model`` (independent pixel errors), ``*_tracks`` (clustered by
    track), ``*_two_way`` (by track and by keyframe, Cameron, Gelbach & Miller 2011). The poses,
    anchored points (and their world points, NaN at or beyond infinity), residuals and flags per
    observation, and Ceres' facts."""

    camera: _core.CameraModel
    line_delay_s: float
    estimates_line_delay: bool
    names: list
    covariance_model: np.ndarray
    covariance_tracks: np.ndarray
    covariance_two_way: np.ndarray
    bounds_99_model: np.ndarray
    bounds_99_tracks: np.ndarray
    bounds_99_two_way: np.ndarray
    keyframe_poses: np.ndarray
    point_anchor: np.ndarray
    points_anchored: np.ndarray
    points_w: np.ndarray
    residuals_px: np.ndarray
    used: np.ndarray
    inlier: np.ndarray
    sigma_px: float
    rms_px: float
    converged: bool
    termination: str
    message: str
    iterations: int
    initial_cost: float
    final_cost: float
    solve_time_s: float
    covariance_time_s: float
    covariance_ok: bool
    step_sigma: float
    dropped_observations: int
    dropped_points: int
    scale_keyframe: int
    points_at_bounds: int
    points_out_of_range: int = 0      # dropped for ending outside the inverse-depth bounds (free solve)
    solved_with_bounds: bool = False  # Ceres' bounds gave the result (too many points left the range, or the
    #                                   free solve reached max_free_iterations)

    @property
    def camera_params(self) -> np.ndarray:
        return np.asarray(self.camera.params, float)

    @property
    def estimate(self) -> np.ndarray:
        """The camera's parameters, then the line delay (s/row), in the order of ``names``."""
        return np.r_[self.camera_params, self.line_delay_s]


def _rotate(phi: np.ndarray, x: np.ndarray) -> np.ndarray:
    """exp([phi]x) x row by row (Rodrigues)."""
    angle = np.linalg.norm(phi, axis=1, keepdims=True)
    safe = np.where(angle > 1e-12, angle, 1.0)
    axis = phi / safe
    cos, sin = np.cos(angle), np.sin(angle)
    rotated = x * cos + np.cross(axis, x) * sin + axis * np.sum(axis * x, axis=1, keepdims=True) * (1 - cos)
    return np.where(angle > 1e-12, rotated, x + np.cross(phi, x))


def anchored_points(keyframe_poses: np.ndarray, keyframe: np.ndarray, point: np.ndarray,
                    points_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each point anchored in the first keyframe that observes it: ``(point_anchor (P,),
    (a, b, rho) (P, 3))``. A point not in front of its anchor starts at infinity on the ray
    through its world position's direction from the anchor (rho = 0). A point never observed
    keeps anchor 0."""
    poses = np.asarray(keyframe_poses, float).reshape(-1, 6)
    points_w = np.asarray(points_w, float).reshape(-1, 3)
    anchor = np.full(len(points_w), np.iinfo(np.int64).max)
    np.minimum.at(anchor, np.asarray(point, np.int64), np.asarray(keyframe, np.int64))
    anchor[anchor == np.iinfo(np.int64).max] = 0
    x_c = _rotate(poses[anchor, 3:], points_w) + poses[anchor, :3]
    z = x_c[:, 2]
    front = z > 0
    depth = np.where(front, z, 1.0)
    direction = np.where(front[:, None], x_c[:, :2] / depth[:, None], 0.0)
    return anchor, np.c_[direction, np.where(front, 1.0 / depth, 0.0)]


def _world_points(poses: np.ndarray, anchor: np.ndarray, abr: np.ndarray) -> np.ndarray:
    rho = abr[:, 2]
    ok = rho > 0
    x_a = np.c_[abr[:, :2], np.ones(len(abr))] / np.where(ok, rho, 1.0)[:, None]
    x_w = _rotate(-poses[anchor, 3:], x_a - poses[anchor, :3])
    x_w[~ok] = np.nan
    return x_w


def adjust(tracks: KeyframeTracks, camera: _core.CameraModel, *,
           free_params: Optional[Union[Sequence[bool], Sequence[str]]] = None,
           line_delay_s: Optional[float] = None, estimate_line_delay: bool = False,
           line_delay_prior: Optional[tuple[float, float]] = None, reference_row: Optional[float] = None,
           loss: str = "soft_l1", loss_scale_px: float = 2.0, max_iterations: int = 200,
           num_threads: int = 2, max_free_iterations: Optional[int] = None,
           options: Optional[_core.BundleOptions] = None) -> AdjustmentResult:
    """Adjust ``camera`` (its model's parameters; ``free_params``: a mask or names, None: all),
    the line delay (held at ``line_delay_s`` (None: 0, a global shutter), estimated from it with
    ``estimate_line_delay``, or with a Gaussian prior ``(mean_s, sigma_s)``), the keyframe poses and
    the points to the tracks.
    ``reference_row``: the row the shutter's shift is counted from (None: the middle row,
    (height - 1) / 2). ``options`` (a ``_core.BundleOptions``) overrides loss, loss_scale_px,
    max_iterations and num_threads. ``max_free_iterations``: the points free that long at most (None: no
    cap), then held in their range (docs/sog.md §25). Raises InputError with the reason on bad input."""
    names = list(camera.param_names)
    if free_params is not None and len(free_params) and isinstance(free_params[0], str):
        unknown = sorted(set(free_params) - set(names))
        if unknown:
            raise InputError(f"free_params: {unknown} are not parameters of {camera.model} ({names})")
        free_params = [n in free_params for n in names]
    if options is None:
        options = _core.BundleOptions()
        options.robust_loss, options.robust_loss_scale_px = loss, float(loss_scale_px)
        options.max_iterations, options.num_threads = int(max_iterations), int(num_threads)
        options.max_free_iterations = 0 if max_free_iterations is None else int(max_free_iterations)
    poses = np.asarray(tracks.keyframe_poses, float)
    uv = np.asarray(tracks.uv_px, float)
    keyframe, point = np.asarray(tracks.keyframe), np.asarray(tracks.point)
    velocity = (np.zeros_like(uv) if tracks.image_velocity_px_s is None
                else np.nan_to_num(np.asarray(tracks.image_velocity_px_s, float), nan=0.0))
    if tracks.points_anchored is not None:
        if tracks.point_anchor is None:
            raise InputError("KeyframeTracks: points_anchored needs point_anchor")
        anchor, abr = np.asarray(tracks.point_anchor), np.asarray(tracks.points_anchored, float)
    elif tracks.points_w is not None:
        if keyframe.dtype.kind not in "iu" or point.dtype.kind not in "iu":
            raise InputError("KeyframeTracks: keyframe and point must be integer arrays")
        if len(keyframe) != len(point) or (len(point) and (point.min() < 0 or point.max() >= len(tracks.points_w))):
            raise InputError("KeyframeTracks: point indices must be 0..P-1, one per observation")
        anchor, abr = anchored_points(poses, keyframe, point, tracks.points_w)
    else:
        raise InputError("KeyframeTracks: give points_w or point_anchor with points_anchored")
    row = (camera.height - 1) / 2.0 if reference_row is None else float(reference_row)
    result = _core.solve_bundle(camera, poses, keyframe, point, uv, velocity, anchor, abr,
                                free_intrinsics=None if free_params is None else [bool(f) for f in free_params],
                                line_delay_s=0.0 if line_delay_s is None else float(line_delay_s), estimate_line_delay=bool(estimate_line_delay),
                                line_delay_prior=None if line_delay_prior is None else tuple(map(float, line_delay_prior)),
                                reference_row=row, options=options)
    estimate = np.r_[result.camera_params, result.line_delay_s]
    # the binding's arrays are read-only views into the C++ result: copies the caller may change
    cov_model, cov_tracks, cov_two_way = (np.array(c) for c in (result.covariance_model, result.covariance_tracks,
                                                               result.covariance_two_way))

    def bounds(cov: np.ndarray) -> np.ndarray:
        half = Z99 * np.sqrt(np.maximum(np.diag(cov), 0.0))
        return np.c_[estimate - half, estimate + half]

    adjusted = _core.CameraModel(camera.model, result.camera_params, camera.width, camera.height,
                                 camera.pixel_size_mm)
    points_anchored = np.array(result.points)
    keyframe_poses = np.array(result.keyframe_poses)
    anchor = np.asarray(anchor, np.int64)
    return AdjustmentResult(
        camera=adjusted, line_delay_s=float(result.line_delay_s),
        estimates_line_delay=bool(estimate_line_delay or line_delay_prior is not None),
        names=names + ["line_delay_s"], covariance_model=cov_model, covariance_tracks=cov_tracks,
        covariance_two_way=cov_two_way, bounds_99_model=bounds(cov_model), bounds_99_tracks=bounds(cov_tracks),
        bounds_99_two_way=bounds(cov_two_way), keyframe_poses=keyframe_poses,
        point_anchor=anchor, points_anchored=points_anchored,
        points_w=_world_points(keyframe_poses, anchor, points_anchored),
        residuals_px=np.array(result.residuals_px), used=np.array(result.used), inlier=np.array(result.inlier),
        sigma_px=result.sigma_px,
        rms_px=result.rms_px, converged=result.converged, termination=result.termination, message=result.message,
        iterations=result.iterations, initial_cost=result.initial_cost, final_cost=result.final_cost,
        solve_time_s=result.solve_time_s, covariance_time_s=result.covariance_time_s,
        covariance_ok=result.covariance_ok, step_sigma=result.step_sigma,
        dropped_observations=result.dropped_observations, dropped_points=result.dropped_points,
        scale_keyframe=result.scale_keyframe, points_at_bounds=result.points_at_bounds,
        points_out_of_range=result.points_out_of_range, solved_with_bounds=result.solved_with_bounds)
