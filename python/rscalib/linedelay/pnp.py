"""Per-frame global-shutter pose (PnP): the initial guess of the line-delay engine and the
baseline it is compared against (paper §4.1 and Fig. 5)."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .._core import CameraModel
from ..observations import Observations


@dataclass
class FramePoses:
    """T_cw of every frame from its own points, global-shutter model.

    ok: (F,) bool, a pose was found; rotation_vector, translation: (F, 3), x_c = R x_w + p
    (NaN where not ok); rms_px: (F,) reprojection RMS of that frame's points.
    """

    ok: np.ndarray
    rotation_vector: np.ndarray
    translation: np.ndarray
    rms_px: np.ndarray


def per_frame_pnp(observations: Observations, camera: CameraModel, min_points: int = 6) -> FramePoses:
    """Planar PnP (OpenCV IPPE, then Levenberg-Marquardt) on undistorted, normalised points.

    Normalising through the camera's own unprojection makes this work for every model.
    """
    count = observations.num_frames
    ok = np.zeros(count, dtype=bool)
    rvecs = np.full((count, 3), np.nan)
    tvecs = np.full((count, 3), np.nan)
    rms = np.full(count, np.nan)
    rays = camera.unproject(observations.uv)
    points_w = observations.points_w()
    identity = np.eye(3)
    planar = np.allclose(observations.target_points[:, 2], 0.0)
    for frame, rows in enumerate(observations.frame_slices()):
        rows = rows[np.isfinite(rays[rows, 0])]
        if len(rows) < min_points:
            continue
        obj = points_w[rows].reshape(-1, 1, 3)
        img = rays[rows, :2].reshape(-1, 1, 2)
        flag = cv2.SOLVEPNP_IPPE if planar else cv2.SOLVEPNP_ITERATIVE
        found, rvec, tvec = cv2.solvePnP(obj, img, identity, None, flags=flag)
        if not found:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, identity, None, rvec, tvec)
        rotation = cv2.Rodrigues(rvec)[0]
        points_c = points_w[rows] @ rotation.T + tvec.ravel()
        if np.any(points_c[:, 2] <= 0):
            continue
        uv = camera.project(points_c)
        ok[frame] = True
        rvecs[frame] = rvec.ravel()
        tvecs[frame] = tvec.ravel()
        rms[frame] = float(np.sqrt(np.nanmean((uv - observations.uv[rows]) ** 2)))
    return FramePoses(ok, rvecs, tvecs, rms)
