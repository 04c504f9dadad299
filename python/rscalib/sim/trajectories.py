"""Every simulated camera trajectory, in one place.

**Interface.** A trajectory is anything with a vectorised ``pose_cw(t)`` (:class:`Trajectory`): for
times ``t`` (s, flattened to ``(n,)``) the world-to-camera poses ``x_c = R x_w + p``
(docs/conventions.md), ``R`` (n, 3, 3) and ``p`` (n, 3). The renderers and the observation
simulator need no more, so a caller may pass its own.

The simulated motions derive from :class:`CameraMotion`. Each one only says where the camera is and
where it looks (``_pose``: ``R_cw`` and the camera centre); every frame convention follows from it:

- :meth:`~CameraMotion.pose_cw`: world-to-camera ``(R_cw, p_cw)``, the project's convention;
- :meth:`~CameraMotion.pose_wc`: camera-to-world ``(R_wc, centre)``, the convention of the
  self-calibration state (docs/conventions.md, "The self-calibration exception");
- :meth:`~CameraMotion.camera_center_w`, :meth:`~CameraMotion.velocities` (linear velocity in the
  world, angular velocity in the camera), :meth:`~CameraMotion.pose_cw_derivative`,
  :meth:`~CameraMotion.describe`.

Motions — each a smooth, analytic (C∞) hand-held motion built from seeded sums of sinusoids
(:class:`SinusoidBank`), deterministic given its seed:

- :class:`HandheldTrajectory`: hovering in front of a planar target (world = target frame); the
  line-delay simulations (target_observations, target_video).
- :class:`RoomWalkTrajectory`: a person looking around inside a room, world z up (scene_video).
- :class:`HandheldRoomMotion`: hand-held inside a room, world y down (scene_features).

The two room motions are one concept but not one class: their worlds, parametrisations and random
streams differ, and the recorded benchmarks and cached videos depend on the numbers of each.

Wrappers: :class:`TargetFlippedTrajectory` (a motion seen in a target frame turned by 180° about x,
for Kalibr's AprilGrid) and :class:`ShiftedTrajectory` (``pose_cw(t + offset)`` of any trajectory).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Optional, Protocol, Sequence, runtime_checkable

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError

if TYPE_CHECKING:
    from ..io.targets import Target

__all__ = [
    "CameraMotion",
    "HandheldRoomMotion",
    "HandheldTrajectory",
    "RoomWalkTrajectory",
    "ShiftedTrajectory",
    "SinusoidBank",
    "TargetFlippedTrajectory",
    "Trajectory",
    "calm_then_wild",
    "standoff_distance_m",
    "target_trajectory",
    "trajectory_from_description",
]


@runtime_checkable
class Trajectory(Protocol):
    """What the simulators need of a trajectory: world-to-camera poses at times t (vectorised)."""

    def pose_cw(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """R (n, 3, 3) and p (n, 3) of ``x_c = R x_w + p`` at the times t (n,)."""
        ...


def _times(t_s: Any) -> np.ndarray:
    return np.atleast_1d(np.asarray(t_s, dtype=np.float64)).reshape(-1)


# --------------------------------------------------------------------------------------------------
# Building block


class SinusoidBank:
    """``channels`` smooth signals, each a sum of ``components`` sinusoids:
    ``x_c(t) = Σ_k a_ck sin(2π f_ck t + φ_ck)``.

    :meth:`draw` seeds them like a hand: log-uniform frequencies, uniform phases and weights
    ~ f^-1/2 (more slow drift than tremor), normalised so that each channel's weights sum to its
    ``peak`` — a hard bound on the channel.
    """

    def __init__(self, freqs_hz: np.ndarray, phases_rad: np.ndarray, amplitudes: np.ndarray) -> None:
        self.freqs_hz, self.phases_rad, self.amplitudes = freqs_hz, phases_rad, amplitudes

    @classmethod
    def draw(cls, rng: np.random.Generator, channels: int, components: int, freq_range_hz: tuple[float, float],
             peaks: Sequence[float], freq_scale: float = 1.0) -> SinusoidBank:
        """Frequencies (log-uniform in ``freq_range_hz``, then times ``freq_scale``), phases and
        amplitudes, drawn from ``rng`` in that order."""
        lo, hi = np.log(freq_range_hz[0]), np.log(freq_range_hz[1])
        freqs = np.exp(rng.uniform(lo, hi, size=(channels, components))) * freq_scale
        phases = rng.uniform(0.0, 2.0 * np.pi, size=(channels, components))
        weights = freqs ** -0.5 * rng.uniform(0.5, 1.0, size=(channels, components))
        weights /= weights.sum(axis=1, keepdims=True)
        return cls(freqs, phases, weights * np.asarray(peaks, dtype=np.float64)[:, None])

    def __call__(self, t_s: np.ndarray) -> np.ndarray:
        """(n, channels) values at the times t (n,)."""
        arg = 2.0 * np.pi * self.freqs_hz[None] * t_s[:, None, None] + self.phases_rad[None]
        return np.einsum("nck,ck->nc", np.sin(arg), self.amplitudes)


# --------------------------------------------------------------------------------------------------
# The interface of the simulated motions


class CameraMotion:
    """A simulated camera motion: subclasses define :meth:`_pose`, the rest follows from it."""

    def _pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-to-camera rotations R_cw (n, 3, 3) and camera centres in the world (n, 3) at the
        times t (n,), float64."""
        raise NotImplementedError

    def pose_cw(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-to-camera pose at times t: ``x_c = R x_w + p``; returns R (n, 3, 3), p (n, 3)."""
        R, centre = self._pose(_times(t_s))
        R = np.ascontiguousarray(R)
        return R, -np.einsum("nij,nj->ni", R, centre)

    def pose_wc(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-to-world pose at times t: ``x_w = R_wc x_c + r``; returns R_wc (n, 3, 3) and the
        camera centre r (n, 3)."""
        R, centre = self._pose(_times(t_s))
        return np.ascontiguousarray(R.transpose(0, 2, 1)), centre

    def camera_center_w(self, t_s: np.ndarray) -> np.ndarray:
        """(n, 3) camera centre in the world frame."""
        return self._pose(_times(t_s))[1]

    def velocities(self, t_s: np.ndarray, h_s: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
        """Linear velocity of the camera centre in the world (n, 3) and angular velocity in the
        camera frame (n, 3), rad/s, by central differences (error ~h²); ``dR_wc/dt = R_wc [ω]×``."""
        t_s = _times(t_s)
        n = len(t_s)
        R, r = self.pose_wc(np.concatenate([t_s + h_s, t_s - h_s]))
        v = (r[:n] - r[n:]) / (2 * h_s)
        R0, _ = self.pose_wc(t_s)
        W = np.einsum("nji,njk->nik", R0, (R[:n] - R[n:]) / (2 * h_s))
        return v, np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)

    def pose_cw_derivative(self, t_s: np.ndarray, h_s: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
        """Time derivatives (dR/dt (n, 3, 3), dp/dt (n, 3)) of :meth:`pose_cw` by central
        differences (error ~h²)."""
        t_s = _times(t_s)
        R, p = self.pose_cw(np.concatenate([t_s + h_s, t_s - h_s]))
        n = len(t_s)
        return (R[:n] - R[n:]) / (2 * h_s), (p[:n] - p[n:]) / (2 * h_s)

    def describe(self) -> dict:
        """Plain data for truth files; enough to rebuild the motion where
        :func:`trajectory_from_description` can."""
        return {"type": type(self).__name__}


# --------------------------------------------------------------------------------------------------
# Hand-held in front of a planar target


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


def standoff_distance_m(camera: Any, target_points: np.ndarray, fill: float = 0.5) -> float:
    """Distance at which the target's wider extent spans about ``fill`` of the image (pinhole)."""
    pts = np.asarray(target_points, dtype=np.float64)
    extent = pts[:, :2].max(axis=0) - pts[:, :2].min(axis=0)
    fx, fy = float(camera.params[0]), float(camera.params[1])
    # Distance that makes each axis fill `fill` of the image; the larger one keeps both inside.
    return float(max(fx * extent[0] / (fill * camera.width), fy * extent[1] / (fill * camera.height)))


class HandheldTrajectory(CameraMotion):
    """Smooth, analytic hand-held motion of a camera looking at a planar target.

    The camera centre hovers around a stand-off point at ``distance_m`` from ``target_center_m``
    (viewing direction tilted from the target normal by a seeded angle up to ``max_view_tilt_deg``),
    displaced by sums of sinusoids. Its orientation looks at the target centre, perturbed by a
    rotation (about the camera's own axes) that is again a sum of sinusoids. The six channels are a
    :class:`SinusoidBank` of ``components`` sinusoids each, frequencies in ``freq_range_hz``; the
    peak displacement / angle is a hard bound. Default peaks:
    ``position_amplitude_m = (0.15, 0.15, 0.09) * distance_m`` (≈ 8, 8, 5 cm at 0.55 m) and
    ``rotation_amplitude_deg = (12, 12, 15)`` (pitch, yaw, roll about camera x, y, z). With the
    default 640x480, f = 500 px setup this gives image speeds of typically 200–400 px/s and keeps
    the whole 9x6 board in view.

    Scale factor ``s(t) = amplitude * amplitude_profile(t)`` multiplies both the displacement and the
    rotation perturbation: amplitude 0 gives a static camera; a profile such as
    :func:`calm_then_wild` makes the motion faster in some parts of the sequence. The pose is
    defined for all t; ``duration_s`` documents the intended domain.
    """

    _DEFAULT_OPTIONS = {"position_amplitude_m": None, "rotation_amplitude_deg": [12.0, 12.0, 15.0],
                        "freq_range_hz": [0.2, 3.0], "components": 4, "max_view_tilt_deg": 10.0}

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
        # The shape options that differ from the defaults (recorded by describe()).
        given = {"position_amplitude_m": None if position_amplitude_m is None else
                 np.asarray(position_amplitude_m, dtype=np.float64).tolist(),
                 "rotation_amplitude_deg": np.asarray(rotation_amplitude_deg, dtype=np.float64).tolist(),
                 "freq_range_hz": [float(f) for f in freq_range_hz], "components": int(components),
                 "max_view_tilt_deg": float(max_view_tilt_deg)}
        self.options = {k: v for k, v in given.items() if v != self._DEFAULT_OPTIONS[k]}
        if position_amplitude_m is None:
            # ~8 cm sideways, ~5 cm in depth at 0.55 m: proportional so the framing is scale-free.
            position_amplitude_m = np.array([0.15, 0.15, 0.09]) * self.distance_m
        self.position_amplitude_m = np.asarray(position_amplitude_m, dtype=np.float64).reshape(3)
        self.rotation_amplitude_rad = np.deg2rad(np.asarray(rotation_amplitude_deg, dtype=np.float64).reshape(3))

        rng = np.random.default_rng([0x5157, self.seed])
        # Channels x, y, z (position, world frame) then rx, ry, rz (camera frame).
        self.bank = SinusoidBank.draw(rng, 6, components, freq_range_hz,
                                      np.concatenate([self.position_amplitude_m, self.rotation_amplitude_rad]))

        # Nominal viewpoint: on the camera side of the target (world z < 0), tilted off the normal.
        tilt = np.deg2rad(max_view_tilt_deg) * np.sqrt(rng.uniform())
        azimuth = rng.uniform(0.0, 2.0 * np.pi)
        view_dir = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)])
        self.nominal_center_m = self.target_center_m + self.distance_m * view_dir

    def scale(self, t_s: np.ndarray) -> np.ndarray:
        """Motion scale s(t) = amplitude * amplitude_profile(t), shape of t."""
        t_s = np.asarray(t_s, dtype=np.float64)
        s = np.full(t_s.shape, self.amplitude)
        if self.amplitude_profile is not None:
            s = s * np.broadcast_to(np.asarray(self.amplitude_profile(t_s), dtype=np.float64), t_s.shape)
        return s

    def _pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ch = self.bank(t_s) * self.scale(t_s)[:, None]
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
        return np.einsum("nij,njk->nik", R_pert, R_lookat), center

    def describe(self) -> dict:
        """Enough to rebuild the trajectory (:func:`trajectory_from_description`), unless it has an
        amplitude profile (a function: then only the type)."""
        if type(self) is not HandheldTrajectory or self.amplitude_profile is not None:
            return super().describe()
        return {"type": "HandheldTrajectory", "flip_target_x180": False, "seed": self.seed,
                "duration_s": self.duration_s, "amplitude": self.amplitude,
                "target_center_m": self.target_center_m.tolist(), "distance_m": self.distance_m, **self.options}


class TargetFlippedTrajectory(CameraMotion):
    """A motion expressed in a target frame turned by 180° about x (x_v = x, y_v = -y, z_v = -z).

    Kalibr's AprilGrid frame has y up the printed page, so the printed side faces +z; the hand-held
    trajectory looks from -z. Composing with this fixed rotation keeps the camera on the printed side.
    """

    _FLIP = np.diag([1.0, -1.0, -1.0])

    def __init__(self, base: CameraMotion) -> None:
        self.base = base

    def _pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, centre = self.base._pose(t_s)
        return R @ self._FLIP, centre * np.diag(self._FLIP)

    def describe(self) -> dict:
        d = self.base.describe()
        if "flip_target_x180" in d:
            d["flip_target_x180"] = True
        return d


def target_trajectory(camera: Any, target: Target, duration_s: float, seed: int = 0, motion: float = 1.0,
                      amplitude_profile: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                      **handheld_options: Any) -> CameraMotion:
    """The hand-held trajectory of a target video: :class:`HandheldTrajectory` looking at the target
    centre from the stand-off at which the target fills about half the image (``camera``: anything
    with ``params`` [fx, fy, ...], ``width``, ``height``); ``motion`` scales its amplitude (0 = static
    camera); ``handheld_options`` go to HandheldTrajectory (e.g. ``freq_range_hz``). For an AprilGrid
    (Kalibr's frame, printed side towards +z) it is seen through :class:`TargetFlippedTrajectory`."""
    center = target.center_m()
    distance = standoff_distance_m(camera, target.points_m)
    if target.target_type == "aprilgrid":
        return TargetFlippedTrajectory(HandheldTrajectory(
            duration_s=duration_s, seed=seed, amplitude=motion, amplitude_profile=amplitude_profile,
            target_center_m=center * np.array([1.0, -1.0, 1.0]), distance_m=distance, **handheld_options))
    return HandheldTrajectory(duration_s=duration_s, seed=seed, amplitude=motion, amplitude_profile=amplitude_profile,
                              target_center_m=center, distance_m=distance, **handheld_options)


def trajectory_from_description(description: dict) -> CameraMotion:
    """Rebuild a trajectory from its :meth:`~CameraMotion.describe` (HandheldTrajectory, possibly
    target-flipped, without an amplitude profile)."""
    d = description or {}
    if d.get("type") != "HandheldTrajectory" or "seed" not in d:
        raise InputError("the trajectory is not a default HandheldTrajectory (it cannot be rebuilt); use its samples")
    options = {k: d[k] for k in HandheldTrajectory._DEFAULT_OPTIONS if k in d}
    base = HandheldTrajectory(duration_s=d["duration_s"], seed=d["seed"], amplitude=d["amplitude"],
                              target_center_m=d["target_center_m"], distance_m=d["distance_m"], **options)
    return TargetFlippedTrajectory(base) if d.get("flip_target_x180") else base


class ShiftedTrajectory:
    """``pose_cw(t + offset_s)`` of any trajectory: e.g. poses at a fixed time into the exposure."""

    def __init__(self, base: Trajectory, offset_s: float) -> None:
        self.base, self.offset_s = base, float(offset_s)

    def pose_cw(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.base.pose_cw(np.asarray(t_s, dtype=np.float64) + self.offset_s)


# --------------------------------------------------------------------------------------------------
# Hand-held inside a room


class RoomWalkTrajectory(CameraMotion):
    """Smooth hand-held motion of a person looking around inside a room (world z up).

    The camera centre wanders around ``center_m`` by sums of slow sinusoids (peaks
    ``position_amplitude_m``, a hard bound, so the camera stays inside the room). The viewing
    direction has yaw ``yaw0 + Δψ(t)`` (``yaw0`` seeded, ``|Δψ| ≤ yaw_amplitude_deg``), elevation
    ``base_pitch_deg + Δθ(t)`` and a roll about the optical axis, plus a small hand tremor at
    1–4 Hz. With the defaults: ≈ 0.2–0.4 m/s and ≈ 10–30 °/s typical, i.e. a few px of image motion
    per frame at 30 fps with the paper's camera, and ample parallax for monocular SLAM.
    """

    def __init__(self, seed: int = 0, center_m: Sequence[float] = (0.0, 0.0, 1.45),
                 position_amplitude_m: Sequence[float] = (0.7, 0.5, 0.08),
                 position_freq_range_hz: tuple[float, float] = (0.06, 0.3), yaw_amplitude_deg: float = 70.0,
                 pitch_amplitude_deg: float = 12.0, roll_amplitude_deg: float = 6.0, base_pitch_deg: float = -5.0,
                 rotation_freq_range_hz: tuple[float, float] = (0.04, 0.35), tremor_amplitude_deg: float = 0.3,
                 components: int = 3, yaw0_deg: Optional[float] = None) -> None:
        self.seed = seed
        self.center_m = np.asarray(center_m, dtype=np.float64).reshape(3)
        self.position_amplitude_m = np.asarray(position_amplitude_m, dtype=np.float64).reshape(3)
        self.yaw_amplitude_deg = yaw_amplitude_deg
        self.pitch_amplitude_deg = pitch_amplitude_deg
        self.roll_amplitude_deg = roll_amplitude_deg
        self.base_pitch_deg = base_pitch_deg
        self.tremor_amplitude_deg = tremor_amplitude_deg
        rng = np.random.default_rng([0x2D0F, int(seed)])
        if yaw0_deg is None:
            yaw0_deg = float(rng.uniform(0.0, 360.0))
        else:
            rng.uniform()  # keep the later draws independent of whether yaw0 was given
        self.yaw0_deg = yaw0_deg
        rot_peaks = np.deg2rad([yaw_amplitude_deg, pitch_amplitude_deg, roll_amplitude_deg])
        self.position_bank = SinusoidBank.draw(rng, 3, components, position_freq_range_hz, self.position_amplitude_m)
        self.rotation_bank = SinusoidBank.draw(rng, 3, components, rotation_freq_range_hz, rot_peaks)
        self.tremor_bank = SinusoidBank.draw(rng, 3, 2, (1.0, 4.0), np.full(3, np.deg2rad(tremor_amplitude_deg)))

    def angles_rad(self, t_s: np.ndarray) -> np.ndarray:
        """(n, 3) yaw ψ (about world z, from +x), elevation θ (up positive), roll about the optical axis."""
        t_s = _times(t_s)
        ang = self.rotation_bank(t_s) + self.tremor_bank(t_s)
        return ang + np.deg2rad([self.yaw0_deg, self.base_pitch_deg, 0.0])

    def _pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ang = self.angles_rad(t_s)
        psi, theta, roll = ang[:, 0], ang[:, 1], ang[:, 2]
        z = np.stack([np.cos(psi) * np.cos(theta), np.sin(psi) * np.cos(theta), np.sin(theta)], axis=1)
        x = np.stack([np.sin(psi), -np.cos(psi), np.zeros_like(psi)], axis=1)  # horizontal, to the right
        y = np.cross(z, x)  # right-handed with y pointing down for an upright view
        R_level = np.stack([x, y, z], axis=1)  # rows = camera axes in world coordinates
        c, s = np.cos(roll), np.sin(roll)
        R_roll = np.zeros((len(roll), 3, 3))
        R_roll[:, 0, 0], R_roll[:, 0, 1], R_roll[:, 1, 0], R_roll[:, 1, 1] = c, -s, s, c
        R_roll[:, 2, 2] = 1.0
        return R_roll @ R_level, self.center_m + self.position_bank(t_s)

    def describe(self) -> dict:
        return {"type": "RoomWalkTrajectory", "seed": int(self.seed), "center_m": self.center_m.tolist(),
                "position_amplitude_m": self.position_amplitude_m.tolist(),
                "yaw0_deg": self.yaw0_deg, "yaw_amplitude_deg": self.yaw_amplitude_deg,
                "pitch_amplitude_deg": self.pitch_amplitude_deg, "roll_amplitude_deg": self.roll_amplitude_deg,
                "base_pitch_deg": self.base_pitch_deg, "tremor_amplitude_deg": self.tremor_amplitude_deg}


class HandheldRoomMotion(CameraMotion):
    """Smooth hand-held motion inside a room (world y down): the camera centre wanders around
    ``center_m`` and the camera looks roughly along world +z, swinging in yaw, pitch and roll.

    The six channels (position x, y, z; yaw, pitch, roll) are a :class:`SinusoidBank` with
    frequencies in ``freq_range_hz`` (times ``speed``) and peaks ``position_amplitude_m``,
    ``rotation_amplitude_deg`` (hard bounds). Rotation: yaw about world y (down), then pitch about
    camera x, then roll about camera z.
    """

    def __init__(self, seed: int = 0, center_m: Sequence[float] = (0.0, 0.0, 0.0),
                 position_amplitude_m: Sequence[float] = (0.35, 0.15, 0.3),
                 rotation_amplitude_deg: Sequence[float] = (30.0, 12.0, 10.0),
                 freq_range_hz: tuple[float, float] = (0.1, 1.2), components: int = 3,
                 speed: float = 1.0) -> None:
        rng = np.random.default_rng([0xCA11, int(seed)])
        self.center_m = np.asarray(center_m, dtype=np.float64).reshape(3)
        peaks = np.concatenate([np.asarray(position_amplitude_m, dtype=np.float64),
                                np.deg2rad(np.asarray(rotation_amplitude_deg, dtype=np.float64))])
        self.bank = SinusoidBank.draw(rng, 6, components, freq_range_hz, peaks, freq_scale=float(speed))

    def _pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ch = self.bank(t_s)
        R_wc = Rotation.from_euler("YXZ", ch[:, 3:6]).as_matrix()
        return R_wc.transpose(0, 2, 1), self.center_m + ch[:, :3]
