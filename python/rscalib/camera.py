"""Cameras: conversions between rscalib.CameraModel and OpenCV's (K, dist) form."""
from __future__ import annotations

import numpy as np

from ._core import CameraModel
from .errors import InputError


def opencv_matrices(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """(K (3, 3), dist) for cv2 functions: dist is (5,) [k1 k2 p1 p2 k3] for pinhole-radtan,
    (4,) [k1 k2 k3 k4] for pinhole-equidistant (cv2.fisheye)."""
    p = np.asarray(camera.params, dtype=np.float64)
    if camera.model == "pinhole-radtan":
        k = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1]], dtype=np.float64)
        return k, p[4:9].copy()
    if camera.model == "pinhole-equidistant":
        k = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1]], dtype=np.float64)
        return k, p[4:8].copy()
    raise InputError(f"{camera.model} has no OpenCV equivalent (use pinhole-radtan or pinhole-equidistant)")


def camera_from_opencv(camera_matrix, dist_coeffs, width: int, height: int,
                       model: str = "pinhole-radtan") -> CameraModel:
    """CameraModel from OpenCV's K and distortion vector (radtan: 4, 5 or 8+ values with
    zeros beyond k3 only; equidistant: 4 values)."""
    k = np.asarray(camera_matrix, dtype=np.float64).reshape(3, 3)
    dist = np.asarray(dist_coeffs, dtype=np.float64).reshape(-1)
    if abs(k[0, 1]) > 1e-12 * abs(k[0, 0]):
        raise InputError("camera matrices with skew are not supported")
    intrinsics = [k[0, 0], k[1, 1], k[0, 2], k[1, 2]]
    if model == "pinhole-radtan":
        if dist.size > 5 and np.any(dist[5:] != 0):
            raise InputError("only OpenCV's k1, k2, p1, p2, k3 are supported (rational/prism terms are not)")
        coeffs = np.zeros(5)
        coeffs[:min(dist.size, 5)] = dist[:5]
        return CameraModel(model, np.r_[intrinsics, coeffs], width, height)
    if model == "pinhole-equidistant":
        if dist.size != 4:
            raise InputError("pinhole-equidistant needs 4 distortion coefficients k1..k4")
        return CameraModel(model, np.r_[intrinsics, dist], width, height)
    raise InputError(f"unknown camera model {model!r}")
