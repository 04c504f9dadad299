"""Simulated rolling-shutter observations of a planar target.

Ground truth for tests and benchmarks of the line-delay engine: for every frame and target point
seen from a trajectory (sim/trajectories.py), the exact rolling-shutter measurement — the row ``v``
solving ``v = v_proj(T_cw(t_i + v * d) P)`` (the measurement model of docs/formulation.md §3, RS
eq. 6–9), with ``u`` from the pose at that same time. Projection goes through OpenCV
(``cv2.projectPoints`` / ``cv2.fisheye.projectPoints``), so the simulation is an oracle independent of
the C++ core.

Conventions (docs/conventions.md): OpenCV pixels; camera x right, y down, z forward; target = world,
points on z = 0; ``x_c = R(t) x_w + p(t)``; row ``v`` of the frame stamped ``t_i`` is exposed at
``t_i + v * d``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

import cv2
import numpy as np

from .._core import CameraModel
from ..errors import InputError
from ..io.cameras import opencv_matrices
from ..io.targets import target_from_dict
from ..observations import Observations
from .trajectories import HandheldTrajectory, Trajectory, standoff_distance_m
from .trajectories import calm_then_wild as calm_then_wild  # re-exported: benchmarks/exp_linear_vs_spline.py

__all__ = [
    "SimCamera",
    "SimulatedObservations",
    "checkerboard_points",
    "default_camera",
    "opencv_project",
    "rs_projection",
    "simulate_observations",
    "simulate_default",
]


# --------------------------------------------------------------------------------------------------
# Target and camera


def checkerboard_points(cols: int = 9, rows: int = 6, spacing_m: float = 0.04) -> np.ndarray:
    """Inner corners of a checkerboard on the target plane z = 0 (rscalib.io.targets' layout).

    Returns (cols*rows, 3) float64, row-major: point id ``r * cols + c`` sits at
    ``(c * spacing_m, r * spacing_m, 0)`` — x along the columns, y along the rows.
    """
    return target_from_dict({"target_type": "checkerboard", "targetCols": cols, "targetRows": rows,
                             "rowSpacingMeters": spacing_m, "colSpacingMeters": spacing_m}).points_m


def default_camera(size: Sequence[int] = (640, 480), model: str = "pinhole-radtan") -> CameraModel:
    """The simulations' camera: 640x480, f = 500 px, k1 = -0.1, k2 = 0.05, with the focal length
    scaled by width / 640 for other sizes and the principal point at the image centre.
    ``pinhole-equidistant`` gives a fisheye-model camera with the same f and mild k1..k4."""
    width, height = int(size[0]), int(size[1])
    f = 500.0 * width / 640.0
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    if model == "pinhole-radtan":
        return CameraModel(model, [f, f, cx, cy, -0.1, 0.05, 0.0, 0.0, 0.0], width, height)
    if model == "pinhole-equidistant":
        return CameraModel(model, [f, f, cx, cy, -0.02, 0.01, 0.0, 0.0], width, height)
    raise InputError(f"unknown camera model {model!r} (pinhole-radtan, pinhole-equidistant)")


@dataclass
class SimCamera:
    """Minimal camera for simulation (duck-type compatible with the package's camera objects).

    model:  "pinhole-radtan" (params fx, fy, cx, cy, k1, k2, p1, p2[, k3]) or
            "pinhole-equidistant" (params fx, fy, cx, cy, k1, k2, k3, k4).
    width, height: image size in pixels.
    """

    model: str
    params: np.ndarray
    width: int
    height: int

    def __post_init__(self) -> None:
        self.params = np.asarray(self.params, dtype=np.float64).reshape(-1)
        self.width = int(self.width)
        self.height = int(self.height)

    @property
    def image_size(self) -> tuple[int, int]:
        return (self.width, self.height)


def opencv_project(model: str, K: np.ndarray, dist: np.ndarray, points_c: np.ndarray) -> np.ndarray:
    """Project camera-frame points (n, 3) to pixels (n, 2) with OpenCV.

    The caller is responsible for z > 0; OpenCV does not reject points behind the camera.
    """
    pts = np.ascontiguousarray(points_c, dtype=np.float64).reshape(-1, 1, 3)
    if len(pts) == 0:
        return np.zeros((0, 2))
    zero = np.zeros(3)
    if model == "pinhole-equidistant":
        uv, _ = cv2.fisheye.projectPoints(pts, zero, zero, K, dist)
    elif model == "pinhole-radtan":
        uv, _ = cv2.projectPoints(pts, zero, zero, K, dist)
    else:
        raise ValueError(f"simulate: unsupported camera model {model!r}")
    return uv.reshape(-1, 2)


# --------------------------------------------------------------------------------------------------
# Observations


@dataclass
class SimulatedObservations:
    """Simulated detections plus the ground truth that produced them.

    observations:      what a detector would hand over (noisy uv; frames with too few points dropped).
    uv_true:           (M, 2) noise-free rolling-shutter projections, aligned with observations.uv.
    exposure_times_s:  (M,) true exposure time of each observation, t_i + uv_true[:, 1] * d.
    video_frame_index: (F,) index of each kept frame in the uniformly sampled video (t0 + i / fps).
    """

    observations: Observations
    uv_true: np.ndarray
    exposure_times_s: np.ndarray
    line_delay_s: float
    trajectory: Trajectory
    camera: Any
    noise_px: float
    fps: float = 30.0
    video_frame_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def rs_projection(trajectory: Any, model: str, K: np.ndarray, dist: np.ndarray,
                   points_w: np.ndarray, t_frame_s: np.ndarray, line_delay_s: float,
                   tol_px: float = 1e-10, max_iter: int = 30, dt_fd_s: float = 1e-4
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``v = v_proj(T_cw(t_frame + v d) P)`` jointly for all points by Newton's method.

    Returns uv (n, 2) projected at the converged exposure time and a validity mask (in front of
    the camera throughout, converged).
    """
    n = len(points_w)
    valid = np.ones(n, dtype=bool)
    safe = np.array([0.0, 0.0, 1.0])  # stand-in for points behind the camera, keeps OpenCV finite

    def project(t_s: np.ndarray, pw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, p = trajectory.pose_cw(t_s)
        xc = np.einsum("nij,nj->ni", R, pw) + p
        front = xc[:, 2] > 1e-6
        xc[~front] = safe
        return opencv_project(model, K, dist, xc), front

    uv, front = project(t_frame_s, points_w)
    valid &= front
    v = uv[:, 1].copy()
    if line_delay_s != 0.0:
        converged = np.zeros(n, dtype=bool)
        for _ in range(max_iter):
            act = np.flatnonzero(valid & ~converged)
            if len(act) == 0:
                break
            t = t_frame_s[act] + v[act] * line_delay_s
            m = len(act)
            # One OpenCV call for the value and the two finite-difference samples of dv/dt.
            uv3, front3 = project(np.concatenate([t, t + dt_fd_s, t - dt_fd_s]), np.tile(points_w[act], (3, 1)))
            front_all = front3[:m] & front3[m:2 * m] & front3[2 * m:]
            v_dot = (uv3[m:2 * m, 1] - uv3[2 * m:, 1]) / (2 * dt_fd_s)
            slope = 1.0 - line_delay_s * v_dot
            # d * v_dot -> 1 means the row sweeps along with the point: no unique solution.
            ok = front_all & (np.abs(slope) > 1e-6)
            step = np.where(ok, (v[act] - uv3[:m, 1]) / np.where(ok, slope, 1.0), 0.0)
            v[act] -= step
            valid[act[~ok]] = False
            converged[act[ok & (np.abs(step) < tol_px)]] = True
        valid &= converged
    uv, front = project(t_frame_s + v * line_delay_s, points_w)
    valid &= front
    # Final consistency: the row used for the time must be the row projected at that time.
    valid &= np.abs(uv[:, 1] - v) < 1e2 * tol_px
    return uv, valid


def simulate_observations(camera: Any, line_delay_s: float, fps: float = 30.0, duration_s: float = 10.0,
                          noise_px: float = 0.3, seed: int = 0, target_points: Optional[np.ndarray] = None,
                          trajectory: Optional[Any] = None, t0_s: float = 0.0, *,
                          border_px: float = 0.0, min_points_per_frame: int = 4) -> SimulatedObservations:
    """Rolling-shutter observations of a target seen by a moving camera.

    camera:        object with ``model``, ``params``, ``width``, ``height`` (see :class:`SimCamera`).
    line_delay_s:  true line delay d (s/row); row v of frame i is exposed at t_i + v d.
    fps, duration_s, t0_s: frames at t_i = t0_s + i / fps for i = 0 .. floor(duration_s * fps) - 1.
    noise_px:      std of the independent Gaussian noise added to u and v.
    seed:          seeds the default trajectory and the noise (separate streams).
    target_points: (P, 3) on z = 0; default :func:`checkerboard_points` ().
    trajectory:    anything with ``pose_cw(t) -> (R (n,3,3), p (n,3))``; default a
                   :class:`HandheldTrajectory` looking at the target centre from
                   :func:`standoff_distance_m`.
    border_px:     keep only points whose true and noisy uv lie in
                   [border, width-1-border] x [border, height-1-border].
    min_points_per_frame: frames with fewer kept points are dropped entirely.

    Each row is the exact fixed point ``v = v_proj(T_cw(t_i + v d) P)`` (Newton to 1e-10 px), not the
    first-order "measured row" shortcut; u is projected with the pose at that same time.
    """
    if target_points is None:
        target_points = checkerboard_points()
    target_points = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    if not fps > 0 or not duration_s > 0:
        raise ValueError("simulate_observations: fps and duration_s must be > 0")
    if trajectory is None:
        center = 0.5 * (target_points.min(axis=0) + target_points.max(axis=0))
        trajectory = HandheldTrajectory(duration_s=t0_s + duration_s, seed=seed, target_center_m=center,
                                        distance_m=standoff_distance_m(camera, target_points))
    width, height = int(camera.width), int(camera.height)
    K, dist = opencv_matrices(camera)

    num_frames = int(np.floor(duration_s * fps + 1e-9))
    frame_times_s = t0_s + np.arange(num_frames) / fps
    num_points = len(target_points)
    frame_of = np.repeat(np.arange(num_frames), num_points)
    point_of = np.tile(np.arange(num_points), num_frames)

    uv_true, valid = rs_projection(trajectory, camera.model, K, dist, target_points[point_of],
                                    frame_times_s[frame_of], float(line_delay_s))
    # Noise for the full frame x point grid, so a point's noise does not depend on what else was
    # dropped.
    rng = np.random.default_rng([0x6E01, int(seed)])
    uv_noisy = uv_true + rng.normal(0.0, noise_px, size=uv_true.shape) if noise_px > 0 else uv_true.copy()

    def inside(uv: np.ndarray) -> np.ndarray:
        return ((uv[:, 0] >= border_px) & (uv[:, 0] <= width - 1 - border_px)
                & (uv[:, 1] >= border_px) & (uv[:, 1] <= height - 1 - border_px))

    keep = valid & inside(uv_true) & inside(uv_noisy)
    per_frame = np.bincount(frame_of[keep], minlength=num_frames)
    frame_ok = per_frame >= min_points_per_frame
    keep &= frame_ok[frame_of]

    new_index = np.cumsum(frame_ok) - 1
    obs = Observations(frame_times_s=frame_times_s[frame_ok], frame_index=new_index[frame_of[keep]],
                       point_id=point_of[keep], uv=uv_noisy[keep], target_points=target_points,
                       image_size=(width, height))
    uv_true = uv_true[keep]
    return SimulatedObservations(
        observations=obs, uv_true=uv_true,
        exposure_times_s=frame_times_s[frame_of[keep]] + uv_true[:, 1] * float(line_delay_s),
        line_delay_s=float(line_delay_s), trajectory=trajectory, camera=camera, noise_px=float(noise_px),
        fps=float(fps), video_frame_index=np.flatnonzero(frame_ok))


def simulate_default(line_delay_s: float = 30e-6, duration_s: float = 10.0, seed: int = 0,
                     noise_px: float = 0.3) -> SimulatedObservations:
    """:func:`default_camera` (640x480 pinhole-radtan, f = 500 px, mild barrel distortion), 9x6 board of
    4 cm, 30 fps."""
    c = default_camera()
    camera = SimCamera(c.model, c.params, c.width, c.height)
    return simulate_observations(camera, line_delay_s, fps=30.0, duration_s=duration_s,
                                 noise_px=noise_px, seed=seed)
