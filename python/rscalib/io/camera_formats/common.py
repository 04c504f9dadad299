"""What every camera format shares: the CameraFile a reader returns, and CameraModel <-> OpenCV's
(K, dist), the common ground of all the formats rscalib reads and writes."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..._core import CameraModel
from ...checks import MAX_ABS_LINE_DELAY_S, MAX_IMAGE_SIDE_PX
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


# What a camera file may say: image sides up to 100 000 px, focal lengths up to 10^7 px, the
# principal point within one image size of the image, |line delay| up to 10 ms per row.
MAX_FOCAL_PX = 1e7


def finite_number(value, field: str) -> float:
    """A finite number (a string of one too, not true/false), else InputError naming the field."""
    if isinstance(value, bool):
        raise InputError(f"{field} must be a number, not {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{field} must be a number, not {str(value)[:40]!r}") from None
    if not np.isfinite(number):
        raise InputError(f"{field} must be finite, not {number}")
    return number


def image_side_px(value, field: str) -> int:
    """A whole number of pixels in 1..MAX_IMAGE_SIDE_PX, else InputError naming the field."""
    number = finite_number(value, field)
    if number != int(number) or not 1 <= number <= MAX_IMAGE_SIDE_PX:
        raise InputError(f"{field} must be a whole number of pixels in 1..{MAX_IMAGE_SIDE_PX}, not {number:g}")
    return int(number)


def line_delay_value(value, field: str) -> Optional[float]:
    """The line delay (s/row) a file gives, or None when it gives none; InputError naming the field
    for text, lists, NaN or inf, or more than MAX_ABS_LINE_DELAY_S per row."""
    if value is None:
        return None
    if isinstance(value, (list, tuple, dict)):
        raise InputError(f"{field} must be a number (s/row), not {value!r}")
    number = finite_number(value, f"{field} (s/row)")
    if abs(number) > MAX_ABS_LINE_DELAY_S:
        raise InputError(f"{field} must be at most {MAX_ABS_LINE_DELAY_S:g} s/row in magnitude, not {number:g}")
    return number


def numeric_array(value, field: str) -> np.ndarray:
    """float64 array of a list (or nested list) of numbers, else InputError naming the field."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{field} must be numbers, not {str(value)[:40]!r}") from None
    if not np.all(np.isfinite(array)):
        raise InputError(f"{field} has a non-finite value")
    return array


# How far a camera matrix's fixed entries (below the diagonal: 0, the corner: 1) may be from their
# value: files written with %.17g or %g round-trip far closer; a camera matrix that is not one
# (transposed, scaled, a homography) is off by its focal length or principal point.
CAMERA_MATRIX_TOLERANCE = 1e-9


def check_camera_matrix(k: np.ndarray, field: str) -> None:
    """InputError naming `field` unless k (3x3) is a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]]
    with positive focal lengths: MATLAB's transposed K (cx, cy in the last row), a last row other
    than 0 0 1 (a scaled or projective matrix) or an entry below the diagonal are refused, saying which."""
    off = lambda *values: bool(np.any(np.abs(values) > CAMERA_MATRIX_TOLERANCE))  # noqa: E731
    if not off(k[0, 2], k[1, 2]) and off(k[2, 0], k[2, 1]) and not off(k[2, 2] - 1):
        raise InputError(f"{field}: the principal point is in the last row ({k[2, 0]:g}, {k[2, 1]:g}): this is a "
                         "transposed camera matrix (MATLAB's K'); write K = [fx 0 cx; 0 fy cy; 0 0 1]")
    if off(k[2, 0], k[2, 1], k[2, 2] - 1):
        raise InputError(f"{field}: the last row must be 0 0 1, not {k[2, 0]:g} {k[2, 1]:g} {k[2, 2]:g} "
                         "(not a camera matrix)")
    if off(k[1, 0]):
        raise InputError(f"{field}: the entry below the diagonal is {k[1, 0]:g}, not 0 (a camera matrix is upper "
                         "triangular: [fx 0 cx; 0 fy cy; 0 0 1])")
    if not (k[0, 0] > 0 and k[1, 1] > 0):
        raise InputError(f"{field}: the focal lengths must be positive (fx {k[0, 0]:g}, fy {k[1, 1]:g})")


def camera_from_opencv(camera_matrix, dist_coeffs, width, height, model: str = RADTAN, *,
                       fields: tuple = ("camera_matrix", "distortion_coefficients"),
                       size_fields: tuple = ("image_width", "image_height")) -> CameraModel:
    """CameraModel from OpenCV's K and distortion vector (radtan: 4, 5 or 8+ values with
    zeros beyond k3 only; equidistant: 4 values). Every value is checked (type, finite, range);
    an InputError names the file's field: `fields` (K, distortion) and `size_fields` (width,
    height) as the file calls them."""
    k = numeric_array(camera_matrix, fields[0])
    if k.size != 9:
        raise InputError(f"{fields[0]} needs 9 values (3x3), has {k.size}")
    k = k.reshape(3, 3)
    dist = numeric_array(dist_coeffs, fields[1]).reshape(-1)
    width, height = image_side_px(width, size_fields[0]), image_side_px(height, size_fields[1])
    check_camera_matrix(k, fields[0])
    if abs(k[0, 1]) > 1e-12 * abs(k[0, 0]):
        raise InputError(f"{fields[0]}: camera matrices with skew are not supported")
    if not (0 < k[0, 0] <= MAX_FOCAL_PX and 0 < k[1, 1] <= MAX_FOCAL_PX):
        raise InputError(f"{fields[0]}: the focal lengths must be in (0, {MAX_FOCAL_PX:g}] px "
                         f"(fx {k[0, 0]:g}, fy {k[1, 1]:g})")
    if not (-width <= k[0, 2] <= 2 * width and -height <= k[1, 2] <= 2 * height):
        raise InputError(f"{fields[0]}: the principal point ({k[0, 2]:g}, {k[1, 2]:g}) is far outside the "
                         f"{width}x{height} image")
    intrinsics = [k[0, 0], k[1, 1], k[0, 2], k[1, 2]]
    if model == RADTAN:
        if dist.size > 5 and np.any(dist[5:] != 0):
            raise InputError(f"{fields[1]}: only OpenCV's k1, k2, p1, p2, k3 are supported (rational/prism "
                             "terms are not)")
        coeffs = np.zeros(5)
        coeffs[:min(dist.size, 5)] = dist[:5]
        return CameraModel(model, np.r_[intrinsics, coeffs], width, height)
    if model == EQUIDISTANT:
        if dist.size != 4:
            raise InputError(f"{fields[1]}: pinhole-equidistant needs 4 distortion coefficients k1..k4")
        return CameraModel(model, np.r_[intrinsics, dist], width, height)
    raise InputError(f"unknown camera model {model!r}")


def supported(names) -> str:
    """'a, b or c' for the one-line errors that list what a reader takes."""
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]


def image_lines(camera: CameraModel, readout_direction: Optional[str]) -> int:
    """The image's lines along the readout: columns for a sideways readout (LeftToRight,
    RightToLeft: a portrait video of a landscape sensor), rows otherwise."""
    return int(camera.width if readout_direction in ("LeftToRight", "RightToLeft") else camera.height)
