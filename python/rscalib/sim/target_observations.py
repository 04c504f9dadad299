"""Simulated rolling-shutter observations of a planar target.

Ground truth for tests and benchmarks of the line-delay engine: a smooth, analytic hand-held
trajectory and, for every frame and target point, the exact rolling-shutter measurement — the row
``v`` solving ``v = v_proj(T_cw(t_i + v * d) P)`` (SPEC §1, §2), with ``u`` from the pose at that same
time. Projection goes through OpenCV (``cv2.projectPoints`` / ``cv2.fisheye.projectPoints``), so the
simulation is an oracle independent of the C++ core.

Conventions (SPEC §1): OpenCV pixels; camera x right, y down, z forward; target = world, points on
z = 0; ``x_c = R(t) x_w + p(t)``; row ``v`` of the frame stamped ``t_i`` is exposed at ``t_i + v * d``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from ..observations import Observations

__all__ = [
    "SimCamera",
    "HandheldTrajectory",
    "SimulatedObservations",
    "calm_then_wild",
    "checkerboard_points",
    "opencv_project",
    "simulate_observations",
    "simulate_default",
    "standoff_distance_m",
]


# --------------------------------------------------------------------------------------------------
# Target and camera


def checkerboard_points(cols: int = 9, rows: int = 6, spacing_m: float = 0.04) -> np.ndarray:
    """Inner corners of a checkerboard on the target plane z = 0.

    Returns (cols*rows, 3) float64, row-major: point id ``r * cols + c`` sits at
    ``(c * spacing_m, r * spacing_m, 0)`` — x along the columns, y along the rows.
    """
    if cols < 1 or rows < 1 or not spacing_m > 0:
        raise ValueError("checkerboard_points: cols, rows must be >= 1 and spacing_m > 0")
    r, c = np.divmod(np.arange(cols * rows), cols)
    return np.column_stack([c * spacing_m, r * spacing_m, np.zeros(cols * rows)]).astype(np.float64)


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


def _local_opencv_matrices(camera: Any) -> tuple[np.ndarray, np.ndarray]:
    """K and distortion vector straight from the documented parameter layout."""
    params = np.asarray(camera.params, dtype=np.float64).reshape(-1)
    fx, fy, cx, cy = params[:4]
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    if camera.model == "pinhole-radtan":
        dist = np.zeros(5)
        dist[: len(params) - 4] = params[4:9]  # k3 optional
    elif camera.model == "pinhole-equidistant":
        dist = params[4:8].copy()
    else:
        raise ValueError(f"simulate: unsupported camera model {camera.model!r}")
    return K, dist


def _opencv_matrices(camera: Any) -> tuple[np.ndarray, np.ndarray]:
    # Prefer the package's converter (one source of truth); the local fallback keeps simulation
    # usable while rscalib.io.cameras is absent.
    try:
        from ..io.cameras import opencv_matrices
    except ImportError:
        return _local_opencv_matrices(camera)
    K, dist = opencv_matrices(camera)
    return np.asarray(K, dtype=np.float64), np.asarray(dist, dtype=np.float64).reshape(-1)


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


def standoff_distance_m(camera: Any, target_points: np.ndarray, fill: float = 0.5) -> float:
    """Distance at which the target's wider extent spans about ``fill`` of the image (pinhole)."""
    pts = np.asarray(target_points, dtype=np.float64)
    extent = pts[:, :2].max(axis=0) - pts[:, :2].min(axis=0)
    fx, fy = float(camera.params[0]), float(camera.params[1])
    # Distance that makes each axis fill `fill` of the image; the larger one keeps both inside.
    return float(max(fx * extent[0] / (fill * camera.width), fy * extent[1] / (fill * camera.height)))


# --------------------------------------------------------------------------------------------------
# Trajectory


def calm_then_wild(duration_s: float, calm: float = 0.15, wild: float = 1.0,
                   transition_s: float = 0.5, t0_s: float = 0.0) -> Callable[[np.ndarray], np.ndarray]:
    """Amplitude profile: ``calm`` in the first half of [t0, t0 + duration], ``wild`` in the second.

    The switch is a tanh of width ``transition_s`` centred at the midpoint, so the trajectory stays
    analytic.
    """
    t_mid = t0_s + 0.5 * duration_s

    def profile(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        return calm + (wild - calm) * 0.5 * (1.0 + np.tanh((t - t_mid) / transition_s))

    return profile


class HandheldTrajectory:
    """Smooth, analytic hand-held motion of a camera looking at a planar target.

    The camera centre hovers around a stand-off point at ``distance_m`` from ``target_center_m``
    (viewing direction tilted from the target normal by a seeded angle up to ``max_view_tilt_deg``),
    displaced by sums of sinusoids. Its orientation looks at the target centre, perturbed by a
    rotation (about the camera's own axes) that is again a sum of sinusoids. Each of the six
    channels has ``components`` sinusoids with seeded log-uniform frequencies in ``freq_range_hz``,
    random phases and weights ~ f^-1/2 (more slow drift than tremor, as a hand moves); the weights of a
    channel sum to its peak, so the peak displacement / angle is a hard bound. Default peaks:
    ``position_amplitude_m = (0.15, 0.15, 0.09) * distance_m`` (≈ 8, 8, 5 cm at 0.55 m) and
    ``rotation_amplitude_deg = (12, 12, 15)`` (pitch, yaw, roll about camera x, y, z). With the
    default 640x480, f = 500 px setup this gives image speeds of typically 200–400 px/s and keeps
    the whole 9x6 board in view.

    Scale factor ``s(t) = amplitude * amplitude_profile(t)`` multiplies both the displacement and the
    rotation perturbation: amplitude 0 gives a static camera; a profile such as
    :func:`calm_then_wild` makes the motion faster in some parts of the sequence. Everything is a
    composition of analytic functions, hence C-infinity, and deterministic given ``seed``. The pose is
    defined for all t; ``duration_s`` documents the intended domain.
    """

    def __init__(self, duration_s: float = 15.0, seed: int = 0, amplitude: float = 1.0,
                 amplitude_profile: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                 target_center_m: Sequence[float] = (0.16, 0.10, 0.0), distance_m: float = 0.55,
                 position_amplitude_m: Optional[Sequence[float]] = None,
                 rotation_amplitude_deg: Sequence[float] = (12.0, 12.0, 15.0),
                 freq_range_hz: tuple[float, float] = (0.2, 3.0), components: int = 4,
                 max_view_tilt_deg: float = 10.0) -> None:
        if not distance_m > 0:
            raise ValueError("HandheldTrajectory: distance_m must be > 0")
        if not 0 < freq_range_hz[0] <= freq_range_hz[1]:
            raise ValueError("HandheldTrajectory: freq_range_hz must satisfy 0 < lo <= hi")
        self.duration_s = float(duration_s)
        self.seed = int(seed)
        self.amplitude = float(amplitude)
        self.amplitude_profile = amplitude_profile
        self.target_center_m = np.asarray(target_center_m, dtype=np.float64).reshape(3)
        self.distance_m = float(distance_m)
        if position_amplitude_m is None:
            # ~8 cm sideways, ~5 cm in depth at 0.55 m: proportional so the framing is scale-free.
            position_amplitude_m = np.array([0.15, 0.15, 0.09]) * self.distance_m
        self.position_amplitude_m = np.asarray(position_amplitude_m, dtype=np.float64).reshape(3)
        self.rotation_amplitude_rad = np.deg2rad(np.asarray(rotation_amplitude_deg, dtype=np.float64).reshape(3))

        rng = np.random.default_rng([0x5157, self.seed])
        lo, hi = np.log(freq_range_hz[0]), np.log(freq_range_hz[1])
        # (6, K): channels x, y, z (position, world frame) then rx, ry, rz (camera frame).
        self.freqs_hz = np.exp(rng.uniform(lo, hi, size=(6, components)))
        self.phases_rad = rng.uniform(0.0, 2.0 * np.pi, size=(6, components))
        weights = self.freqs_hz ** -0.5 * rng.uniform(0.5, 1.0, size=(6, components))
        weights /= weights.sum(axis=1, keepdims=True)
        peaks = np.concatenate([self.position_amplitude_m, self.rotation_amplitude_rad])
        self.coeffs = weights * peaks[:, None]

        # Nominal viewpoint: on the camera side of the target (world z < 0), tilted off the normal.
        tilt = np.deg2rad(max_view_tilt_deg) * np.sqrt(rng.uniform())
        azimuth = rng.uniform(0.0, 2.0 * np.pi)
        view_dir = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)])
        self.nominal_center_m = self.target_center_m + self.distance_m * view_dir

    # -- scale ----------------------------------------------------------------------------------
    def scale(self, t_s: np.ndarray) -> np.ndarray:
        """Motion scale s(t) = amplitude * amplitude_profile(t), shape of t."""
        t_s = np.asarray(t_s, dtype=np.float64)
        s = np.full(t_s.shape, self.amplitude)
        if self.amplitude_profile is not None:
            s = s * np.broadcast_to(np.asarray(self.amplitude_profile(t_s), dtype=np.float64), t_s.shape)
        return s

    def _channels(self, t_s: np.ndarray) -> np.ndarray:
        """(n, 6) displacement [m] and rotation-vector perturbation [rad] at times t."""
        arg = 2.0 * np.pi * self.freqs_hz[None] * t_s[:, None, None] + self.phases_rad[None]
        return np.einsum("nck,ck->nc", np.sin(arg), self.coeffs) * self.scale(t_s)[:, None]

    # -- poses ----------------------------------------------------------------------------------
    def camera_center_w(self, t_s: np.ndarray) -> np.ndarray:
        """(n, 3) camera centre in the world (target) frame."""
        t_s = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        return self.nominal_center_m + self._channels(t_s)[:, :3]

    def pose_cw(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-to-camera pose at times t: ``x_c = R x_w + p``; returns R (n, 3, 3), p (n, 3)."""
        t_s = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).reshape(-1)
        ch = self._channels(t_s)
        center = self.nominal_center_m + ch[:, :3]
        # Look-at frame: z towards the target centre, x as close to world x as possible, y = z × x
        # (right-handed, y down for an upright view). Smooth because z never approaches world x.
        z = self.target_center_m - center
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        x = np.array([1.0, 0.0, 0.0]) - z[:, :1] * z
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        y = np.cross(z, x)
        R_lookat = np.stack([x, y, z], axis=1)  # rows = camera axes in world coordinates
        R_pert = Rotation.from_rotvec(ch[:, 3:]).as_matrix()
        R = np.einsum("nij,njk->nik", R_pert, R_lookat)
        p = -np.einsum("nij,nj->ni", R, center)
        return R, p

    def pose_cw_derivative(self, t_s: np.ndarray, h_s: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
        """Time derivatives (dR/dt (n, 3, 3), dp/dt (n, 3)) by central differences (error ~h²)."""
        t_s = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).reshape(-1)
        R, p = self.pose_cw(np.concatenate([t_s + h_s, t_s - h_s]))
        n = len(t_s)
        return (R[:n] - R[n:]) / (2 * h_s), (p[:n] - p[n:]) / (2 * h_s)

    def angular_velocity_c(self, t_s: np.ndarray, h_s: float = 1e-5) -> np.ndarray:
        """(n, 3) angular velocity of the camera in the camera frame, rad/s (``dR/dt = -[ω]× R``)."""
        R, _ = self.pose_cw(t_s)
        dR, _ = self.pose_cw_derivative(t_s, h_s)
        W = -np.einsum("nij,nkj->nik", dR, R)  # = [ω]×
        return np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)


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
    trajectory: HandheldTrajectory
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
    K, dist = _opencv_matrices(camera)

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
    """640x480 pinhole-radtan camera (f = 500 px, mild barrel distortion), 9x6 board of 4 cm, 30 fps."""
    camera = SimCamera("pinhole-radtan", np.array([500.0, 500.0, 319.5, 239.5, -0.1, 0.05, 0.0, 0.0, 0.0]),
                       640, 480)
    return simulate_observations(camera, line_delay_s, fps=30.0, duration_s=duration_s,
                                 noise_px=noise_px, seed=seed)
