"""ROS camera_info YAML, as camera_calibration_parsers reads and writes it (and the ROS camera
calibrator saves it): image_width, image_height, camera_name, camera_matrix / rectification_matrix /
projection_matrix as {rows, cols, data}, distortion_model, distortion_coefficients.

distortion_model: plumb_bob = OpenCV's k1 k2 p1 p2 k3; rational_polynomial = k1 k2 p1 p2 k3 k4 k5 k6
(read when k4..k6 are 0); equidistant = cv2.fisheye's k1..k4. Pixels follow OpenCV's convention.
Some tools save the file with OpenCV's `%YAML:1.0` header; that line is skipped.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..._core import CameraModel
from ...errors import InputError
from .common import EQUIDISTANT, RADTAN, CameraFile, camera_from_opencv, opencv_matrices, supported

ROS_MODELS = {"plumb_bob": RADTAN, "rational_polynomial": RADTAN, "equidistant": EQUIDISTANT}


def is_ros(data) -> bool:
    return isinstance(data, dict) and isinstance(data.get("camera_matrix"), dict) and "data" in data["camera_matrix"]


def _matrix(path: Path, data: dict, key: str, shape: tuple) -> np.ndarray:
    node = data.get(key)
    if not isinstance(node, dict) or "data" not in node:
        raise InputError(f"{path}: field {key} (rows, cols, data) is missing")
    if not isinstance(node["data"], (list, tuple)):
        raise InputError(f"{path}: {key}.data must be a list of numbers, not {type(node['data']).__name__}")
    try:
        values = np.asarray([float(v) for v in node["data"]], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{path}: {key}.data must be a list of numbers") from None
    if shape and values.size != shape[0] * shape[1]:
        raise InputError(f"{path}: {key} needs {shape[0] * shape[1]} values, has {values.size}")
    return values.reshape(shape) if shape else values


def read_ros(path: Path, data: dict) -> CameraFile:
    name = data.get("distortion_model", "plumb_bob")
    if not isinstance(name, str) or name not in ROS_MODELS:
        raise InputError(f"{path}: distortion_model '{name}' is not supported; supported: {supported(ROS_MODELS)}")
    k = _matrix(path, data, "camera_matrix", (3, 3))
    dist = _matrix(path, data, "distortion_coefficients", ()) if "distortion_coefficients" in data else np.zeros(5)
    if "image_width" not in data or "image_height" not in data:
        raise InputError(f"{path}: fields image_width and image_height are missing")
    width, height = data["image_width"], data["image_height"]
    if name == "equidistant" and dist.size != 4:
        raise InputError(f"{path}: distortion_model equidistant needs 4 coefficients k1..k4, has {dist.size}")
    if name == "rational_polynomial" and np.any(dist[5:] != 0):
        raise InputError(f"{path}: rational_polynomial with k4, k5, k6 != 0 is not supported (rscalib's "
                         "pinhole-radtan has k1 k2 p1 p2 k3)")
    try:
        camera = camera_from_opencv(k, dist, width, height, ROS_MODELS[name])
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    return CameraFile(camera, None, "ros")


def _block(rows: int, cols: int, values) -> dict:
    return {"rows": rows, "cols": cols, "data": [float(v) for v in np.ravel(values)]}


def write_ros_camera_info(camera: CameraModel, path, camera_name: str = "camera") -> None:
    """camera_info YAML for camera_calibration_parsers / image_pipeline. The rectified image of a
    monocular camera keeps K: rectification_matrix is the identity, projection_matrix [K | 0]."""
    k, dist = opencv_matrices(camera)
    data = {
        "image_width": int(camera.width),
        "image_height": int(camera.height),
        "camera_name": camera_name,
        "camera_matrix": _block(3, 3, k),
        "distortion_model": "equidistant" if camera.model == EQUIDISTANT else "plumb_bob",
        "distortion_coefficients": _block(1, dist.size, dist),
        "rectification_matrix": _block(3, 3, np.eye(3)),
        "projection_matrix": _block(3, 4, np.c_[k, np.zeros(3)]),
    }
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
