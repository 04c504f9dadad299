"""What every camera format shares: the CameraFile a reader returns, and CameraModel <-> OpenCV's
(K, dist), the common ground of all the formats rscalib reads and writes."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..._core import CameraModel
from ...errors import InputError

# OpenCV's pixel convention is rscalib's (docs/conventions.md); COLMAP puts pixel centres at +0.5.
RADTAN, EQUIDISTANT = "pinhole-radtan", "pinhole-equidistant"


@dataclass
class CameraFile:
    """A camera read from disk, with the line delay if the file had one.

    source_format: "opencv" | "kalibr" | "ros" | "mrcal" | "colmap"; notes: what the reader
    left out or assumed (e.g. a second camera of a camchain), for the caller to show."""

    camera: CameraModel
    line_delay_s: Optional[float] = None
    source_format: str = "opencv"
    notes: list = field(default_factory=list)


def opencv_matrices(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """(K (3, 3), dist) for cv2 functions: dist is (5,) [k1 k2 p1 p2 k3] for pinhole-radtan,
    (4,) [k1 k2 k3 k4] for pinhole-equidistant (cv2.fisheye)."""
    p = np.asarray(camera.params, dtype=np.float64)
    if camera.model in (RADTAN, EQUIDISTANT):
        k = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1]], dtype=np.float64)
        return k, (p[4:9] if camera.model == RADTAN else p[4:8]).copy()
    raise InputError(f"{camera.model} has no OpenCV equivalent (use pinhole-radtan or pinhole-equidistant)")


def camera_from_opencv(camera_matrix, dist_coeffs, width: int, height: int,
                       model: str = RADTAN) -> CameraModel:
    """CameraModel from OpenCV's K and distortion vector (radtan: 4, 5 or 8+ values with
    zeros beyond k3 only; equidistant: 4 values)."""
    k = np.asarray(camera_matrix, dtype=np.float64).reshape(3, 3)
    dist = np.asarray(dist_coeffs, dtype=np.float64).reshape(-1)
    if abs(k[0, 1]) > 1e-12 * abs(k[0, 0]):
        raise InputError("camera matrices with skew are not supported")
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(dist))):
        raise InputError("the camera matrix or distortion has a non-finite value")
    if not (k[0, 0] > 0 and k[1, 1] > 0):
        raise InputError(f"the focal lengths must be positive (fx {k[0, 0]:g}, fy {k[1, 1]:g})")
    if not (int(width) > 0 and int(height) > 0):
        raise InputError(f"the image size must be positive, not {width}x{height}")
    intrinsics = [k[0, 0], k[1, 1], k[0, 2], k[1, 2]]
    if model == RADTAN:
        if dist.size > 5 and np.any(dist[5:] != 0):
            raise InputError("only OpenCV's k1, k2, p1, p2, k3 are supported (rational/prism terms are not)")
        coeffs = np.zeros(5)
        coeffs[:min(dist.size, 5)] = dist[:5]
        return CameraModel(model, np.r_[intrinsics, coeffs], int(width), int(height))
    if model == EQUIDISTANT:
        if dist.size != 4:
            raise InputError("pinhole-equidistant needs 4 distortion coefficients k1..k4")
        return CameraModel(model, np.r_[intrinsics, dist], int(width), int(height))
    raise InputError(f"unknown camera model {model!r}")


def supported(names) -> str:
    """'a, b or c' for the one-line errors that list what a reader takes."""
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]


def image_lines(camera: CameraModel, readout_direction: Optional[str]) -> int:
    """The image's lines along the readout: columns for a sideways readout (LeftToRight,
    RightToLeft: a portrait video of a landscape sensor), rows otherwise."""
    return int(camera.width if readout_direction in ("LeftToRight", "RightToLeft") else camera.height)
