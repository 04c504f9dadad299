"""The civera-radial camera (Civera et al. 2009: distorted -> undistorted, radii in mm; the model
self-calibration estimates) for tools that know only OpenCV's models: the closest pinhole-radtan."""
from __future__ import annotations

import numpy as np

from ..._core import CameraModel
from ...errors import InputError


def civera_to_opencv(camera: CameraModel, samples: int = 40) -> tuple[CameraModel, float]:
    """OpenCV pinhole-radtan (k1, k2, k3; no tangential terms) closest to a civera-radial camera:
    linear least squares of the radial factor over a grid of image pixels. Returns the camera and
    the largest pixel difference between the two models over that grid."""
    if camera.model != "civera-radial":
        raise InputError("civera_to_opencv needs a civera-radial camera")
    f, cx, cy, _, _ = camera.params
    w, h = camera.width, camera.height
    us, vs = np.meshgrid(np.linspace(0, w - 1, samples), np.linspace(0, h - 1, samples))
    uv_d = np.c_[us.ravel(), vs.ravel()]
    uv_u = camera.undistort(uv_d)
    x_u = (uv_u - [cx, cy]) / f
    x_d = (uv_d - [cx, cy]) / f
    r2 = np.sum(x_u ** 2, axis=1)
    keep = r2 > 1e-12
    # x_d = x_u (1 + K1 r2 + K2 r2^2 + K3 r2^3): linear in K for both coordinates
    a = np.vstack([x_u[keep, j:j + 1] * np.c_[r2[keep], r2[keep] ** 2, r2[keep] ** 3] for j in (0, 1)])
    b = np.concatenate([x_d[keep, j] - x_u[keep, j] for j in (0, 1)])
    k, *_ = np.linalg.lstsq(a, b, rcond=None)
    opencv = CameraModel("pinhole-radtan", [f, f, cx, cy, k[0], k[1], 0.0, 0.0, k[2]], w, h)
    points = np.c_[x_u, np.ones(len(x_u))]
    error = np.linalg.norm(opencv.project(points) - uv_d, axis=1)
    return opencv, float(np.nanmax(error))
