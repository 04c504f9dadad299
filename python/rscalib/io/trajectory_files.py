"""Trajectory files: trajectory.csv (rscalib's own, world-to-camera) and the TUM format
(camera-to-world), so that a trajectory goes straight into evo, the TUM RGB-D tools or any SLAM
evaluation script.

- trajectory.csv: `t_s` then T_cw = (p, phi) at that time, x_c = R(phi) x_w + p (docs/conventions.md);
  the column names say world_to_camera so the file cannot be taken for camera poses in the world.
- TUM: `timestamp tx ty tz qx qy qz qw`, space separated, `#` comments: the camera centre in the
  world (-R^T p) and the camera-to-world rotation R^T as a unit quaternion, scalar last.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

CSV_COLUMNS = ("t_s", "world_to_camera_p_x_m", "world_to_camera_p_y_m", "world_to_camera_p_z_m",
               "world_to_camera_phi_x_rad", "world_to_camera_phi_y_rad", "world_to_camera_phi_z_rad")
TUM_HEADER = ("# TUM trajectory written by rscalib: camera pose in the world (target) frame, camera-to-world\n"
              "# timestamp tx ty tz qx qy qz qw")


def _finite(times, states) -> tuple[np.ndarray, np.ndarray]:
    states = np.asarray(states, dtype=np.float64).reshape(-1, 6)
    ok = np.all(np.isfinite(states), axis=1)
    return np.asarray(times, dtype=np.float64)[ok], states[ok]


def write_trajectory_csv(path, times, states) -> Path:
    """trajectory.csv of T_cw states [p; phi] (n, 6); rows without a pose (NaN) are left out."""
    times, states = _finite(times, states)
    np.savetxt(path, np.c_[times, states], delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt="%.9f")
    return Path(path)


def camera_to_world(states) -> tuple[np.ndarray, np.ndarray]:
    """(camera centres in the world (n, 3), camera-to-world quaternions (n, 4) x y z w) of T_cw states.

    R_wc = exp(-phi): quaternion (-sin(θ/2) phi/θ, cos(θ/2)), θ = |phi| (scipy's Rotation gives the same,
    tests/python/io; written out because importing scipy.spatial cost 0.4 s of every linedelay run)."""
    states = np.asarray(states, dtype=np.float64).reshape(-1, 6)
    phi = states[:, 3:]
    theta = np.linalg.norm(phi, axis=1, keepdims=True)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    # sin(θ/2)/θ -> 1/2 - θ²/48 near 0
    half_sinc = np.where(small, 0.5 - theta ** 2 / 48.0, np.sin(0.5 * safe) / safe)
    quaternion = np.concatenate([-half_sinc * phi, np.cos(0.5 * theta)], axis=1)
    # centre = -R_wc p, Rodrigues with axis k = -phi/θ
    p = states[:, :3]
    axis = np.where(small, 0.0, -phi / safe)
    cos, sin = np.cos(theta), np.sin(theta)
    rotated = (p * cos + np.cross(axis, p) * sin
               + axis * np.sum(axis * p, axis=1, keepdims=True) * (1.0 - cos))
    return -rotated, quaternion


def write_tum_trajectory(path, times, states) -> Path:
    """The T_cw states [p; phi] as a TUM trajectory (camera-to-world); rows without a pose are left out."""
    times, states = _finite(times, states)
    centres, quats = camera_to_world(states)
    np.savetxt(path, np.c_[times, centres, quats], delimiter=" ", header=TUM_HEADER, comments="", fmt="%.9f")
    return Path(path)
