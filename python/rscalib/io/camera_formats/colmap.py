"""COLMAP cameras.txt: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`, one camera a line, `#` comments.

COLMAP's pixel convention differs from OpenCV's: the centre of the top-left pixel is (0.5, 0.5),
so its principal point is ours + 0.5 px (fx, fy and the distortion are the same). Models read:
SIMPLE_PINHOLE (f cx cy), PINHOLE (fx fy cx cy), SIMPLE_RADIAL (f cx cy k), RADIAL (f cx cy k1 k2),
OPENCV (fx fy cx cy k1 k2 p1 p2), FULL_OPENCV (... k3 k4 k5 k6; k4..k6 must be 0) -> pinhole-radtan;
OPENCV_FISHEYE (fx fy cx cy k1 k2 k3 k4), SIMPLE_RADIAL_FISHEYE (f cx cy k), RADIAL_FISHEYE
(f cx cy k1 k2) -> pinhole-equidistant (COLMAP's fisheye models are cv2.fisheye's polynomial in
the angle). Written: OPENCV (k3 = 0), FULL_OPENCV (k3 != 0) or OPENCV_FISHEYE.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..._core import CameraModel
from ...errors import InputError
from .common import EQUIDISTANT, RADTAN, CameraFile, camera_from_opencv, supported

PIXEL_CENTRE_OFFSET = 0.5   # COLMAP pixel = OpenCV pixel + 0.5

# model -> (parameter count, rscalib model, [fx fy cx cy k...] from COLMAP's params)
_SINGLE_F = lambda p, n: [p[0], p[0], p[1], p[2], *p[3:3 + n]]  # noqa: E731
_TWO_F = lambda p, n: [p[0], p[1], p[2], p[3], *p[4:4 + n]]  # noqa: E731
COLMAP_MODELS = {
    "SIMPLE_PINHOLE": (3, RADTAN, lambda p: _SINGLE_F(p, 0)),
    "PINHOLE": (4, RADTAN, lambda p: _TWO_F(p, 0)),
    "SIMPLE_RADIAL": (4, RADTAN, lambda p: _SINGLE_F(p, 1)),
    "RADIAL": (5, RADTAN, lambda p: _SINGLE_F(p, 2)),
    "OPENCV": (8, RADTAN, lambda p: _TWO_F(p, 4)),
    "FULL_OPENCV": (12, RADTAN, lambda p: _TWO_F(p, 5)),
    "OPENCV_FISHEYE": (8, EQUIDISTANT, lambda p: _TWO_F(p, 4)),
    "SIMPLE_RADIAL_FISHEYE": (4, EQUIDISTANT, lambda p: _SINGLE_F(p, 1)),
    "RADIAL_FISHEYE": (5, EQUIDISTANT, lambda p: _SINGLE_F(p, 2)),
}
_LINE = re.compile(r"^\s*\d+\s+[A-Z_]+\s+\d+\s+\d+(\s+\S+)*\s*$")


def is_colmap(path: Path, text: str) -> bool:
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return bool(lines) and all(_LINE.match(ln) for ln in lines)


def read_colmap(path: Path, text: str) -> CameraFile:
    lines = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{path}: no camera line (CAMERA_ID MODEL WIDTH HEIGHT PARAMS[])")
    notes = [f"{path}: {len(lines)} cameras; camera {lines[0][0]} is used"] if len(lines) > 1 else []
    camera_id, name, width, height, *params = lines[0]
    if name not in COLMAP_MODELS:
        raise InputError(f"{path}: camera {camera_id}: COLMAP model {name} is not supported; supported: "
                         f"{supported(COLMAP_MODELS)}")
    count, model, layout = COLMAP_MODELS[name]
    try:
        values = [float(v) for v in params]
    except (ValueError, OverflowError):
        raise InputError(f"{path}: camera {camera_id}: the parameters must be numbers") from None
    if len(values) != count:
        raise InputError(f"{path}: camera {camera_id}: {name} needs {count} parameters, has {len(values)}")
    if name == "FULL_OPENCV" and any(values[9:]):
        raise InputError(f"{path}: camera {camera_id}: FULL_OPENCV with k4, k5, k6 != 0 is not supported "
                         "(rscalib's pinhole-radtan has k1 k2 p1 p2 k3)")
    fx, fy, cx, cy, *dist = layout(values)
    size = 5 if model == RADTAN else 4
    coeffs = (list(dist) + [0.0] * size)[:size]
    k = np.array([[fx, 0, cx - PIXEL_CENTRE_OFFSET], [0, fy, cy - PIXEL_CENTRE_OFFSET], [0, 0, 1.0]])
    try:
        camera = camera_from_opencv(k, coeffs, width, height, model, fields=("PARAMS", "PARAMS"),
                                    size_fields=("WIDTH", "HEIGHT"))
    except InputError as error:
        raise InputError(f"{path}: camera {camera_id}: {error}") from None
    return CameraFile(camera, None, "colmap", notes)


def colmap_line(camera: CameraModel, camera_id: int = 1) -> str:
    p = np.asarray(camera.params, dtype=np.float64)
    fx, fy, cx, cy = p[0], p[1], p[2] + PIXEL_CENTRE_OFFSET, p[3] + PIXEL_CENTRE_OFFSET
    if camera.model == RADTAN:
        name, dist = ("OPENCV", p[4:8]) if p[8] == 0 else ("FULL_OPENCV", np.r_[p[4:9], 0.0, 0.0, 0.0])
    elif camera.model == EQUIDISTANT:
        name, dist = "OPENCV_FISHEYE", p[4:8]
    else:
        raise InputError(f"{camera.model} has no COLMAP equivalent")
    values = " ".join(f"{v:.17g}" for v in (fx, fy, cx, cy, *dist))
    return f"{camera_id} {name} {int(camera.width)} {int(camera.height)} {values}"


def write_colmap_cameras(camera: CameraModel, path) -> None:
    """cameras.txt with one camera (id 1); the principal point moved by +0.5 px to COLMAP's pixels."""
    Path(path).write_text("# Camera list with one line of data per camera:\n"
                          "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                          "# Number of cameras: 1\n"
                          "# written by rscalib; COLMAP's pixel centres are at +0.5 px from OpenCV's\n"
                          + colmap_line(camera) + "\n")
