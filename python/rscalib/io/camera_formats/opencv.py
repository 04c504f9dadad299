"""OpenCV FileStorage camera files (YAML, also XML/JSON on reading), read and written through
cv2.FileStorage itself: OpenCV's `%YAML:1.0` header and `!!opencv-matrix` tags are not plain YAML.

pinhole-radtan uses OpenCV's usual keys (`camera_matrix`, `distortion_coefficients` k1 k2 p1 p2 k3),
so any reader of OpenCV calibration files reads it right. pinhole-equidistant (cv2.fisheye) puts
its matrices under `fisheye_camera_matrix` and `fisheye_distortion_coefficients` (k1..k4): a generic
reader then fails instead of taking k1..k4 for k1, k2, p1, p2. Both carry `camera_model` with
rscalib's model name, the name result.json uses. Files of older rscalib versions (plain keys with
`distortion_model: fisheye`) are still read.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from ..._core import CameraModel
from ...errors import InputError
from ..safe_parse import check_nesting
from .common import EQUIDISTANT, RADTAN, CameraFile, camera_from_opencv, image_lines, line_delay_value, opencv_matrices

FISHEYE_PREFIX = "fisheye_"
# `distortion_model` values of older rscalib files and other tools that mean the fisheye model
_EQUIDISTANT_NAMES = ("fisheye", "equidistant", EQUIDISTANT, "kannala-brandt", "opencv_fisheye")


def _node_string(storage, key: str) -> str:
    """The name under `key` ("" if absent); InputError naming the key for a number, list or map."""
    node = storage.getNode(key)
    if node.empty() or node.isNone():
        return ""
    if not node.isString():
        raise InputError(f"field {key} must be a name (such as {RADTAN}), not a number, list or mapping")
    return node.string()


def _node_number(storage, key: str):
    """The number under `key` (None if absent); InputError naming the key for a string or a list."""
    node = storage.getNode(key)
    if node.empty() or node.isNone():
        return None
    if not (node.isInt() or node.isReal()):
        raise InputError(f"field {key} must be a number")
    return node.real()


def _node_matrix(storage, key: str) -> Optional[np.ndarray]:
    """The !!opencv-matrix under `key` (None if absent); InputError naming the key if unreadable."""
    node = storage.getNode(key)
    if node.empty() or node.isNone():
        return None
    try:
        matrix = node.mat()
    except cv2.error:
        matrix = None
    if matrix is None:
        raise InputError(f"field {key} must be an !!opencv-matrix of numbers (rows, cols, dt, data)")
    return matrix


def _storage_text(text: str) -> str:
    """The text as cv2.FileStorage reads it from memory: it tells XML, JSON and YAML apart by the
    first characters, so YAML without OpenCV's header gets one."""
    start = text.lstrip()
    return text if start.startswith(("%YAML", "<", "{")) else "%YAML:1.0\n---\n" + text


def read_opencv(path: Path, text: str) -> CameraFile:
    """An OpenCV FileStorage file whose text (read within safe_parse's size limit) is `text`,
    parsed by cv2.FileStorage from memory (the file name plays no part: OpenCV cannot open some
    names, e.g. with a newline) after a nesting check (OpenCV's parser overflows its stack on
    deeply nested files)."""
    start = text.lstrip()
    check_nesting(text, path, "xml" if start.startswith("<") else "yaml")
    try:
        storage = cv2.FileStorage(_storage_text(text), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError):  # a syntax error: OpenCV's parser raises through its constructor
        raise InputError(f"{path}: not a camera file rscalib reads (OpenCV FileStorage with a syntax error, or "
                         "none of Kalibr camchain, ROS camera_info, mrcal .cameramodel, COLMAP cameras.txt)") from None
    try:
        if not storage.isOpened():
            raise InputError(f"{path}: not an OpenCV FileStorage file")
        model = _node_string(storage, "camera_model")
        legacy = _node_string(storage, "distortion_model")
        fisheye_keys = not storage.getNode(FISHEYE_PREFIX + "camera_matrix").empty()
        prefix = FISHEYE_PREFIX if fisheye_keys else ""
        k = _node_matrix(storage, prefix + "camera_matrix")
        dist = _node_matrix(storage, prefix + "distortion_coefficients")
        width = _node_number(storage, "image_width")
        height = _node_number(storage, "image_height")
        line_delay = line_delay_value(_node_number(storage, "line_delay_s"), "field line_delay_s")
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    finally:
        storage.release()
    if k is None:
        raise InputError(f"{path}: field {prefix}camera_matrix (3x3 !!opencv-matrix) is missing")
    if width is None or height is None:
        raise InputError(f"{path}: fields image_width and image_height are missing")
    if model and model not in (RADTAN, EQUIDISTANT):
        raise InputError(f"{path}: camera_model '{model}' is not supported ({RADTAN} or {EQUIDISTANT})")
    if not model:
        model = EQUIDISTANT if fisheye_keys or legacy in _EQUIDISTANT_NAMES else RADTAN
    dist = np.zeros(5) if dist is None else dist.ravel()
    try:
        camera = camera_from_opencv(k, dist, width, height, model,
                                    fields=(prefix + "camera_matrix", prefix + "distortion_coefficients"))
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    return CameraFile(camera, line_delay, "opencv")


def write_opencv_yaml(camera: CameraModel, path, line_delay_s: Optional[float] = None,
                      extra: Optional[dict] = None, readout_direction: Optional[str] = None) -> None:
    """OpenCV FileStorage YAML: camera_model, image size, the camera matrix and distortion (fisheye_
    keys for pinhole-equidistant), and with a line delay: line_delay_s (s/row) and
    image_readout_time_s = line_delay_s x the image lines along the readout (first to last image
    row; the sensor's readout_time_s over all rows read out is in result.json)."""
    k, dist = opencv_matrices(camera)
    fisheye = camera.model == EQUIDISTANT
    prefix = FISHEYE_PREFIX if fisheye else ""
    # written to memory, then to the file: cv2.FileStorage cannot open every name (a newline in it)
    storage = cv2.FileStorage(".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    try:
        if fisheye:
            storage.writeComment("pinhole-equidistant: OpenCV's fisheye model (cv2.fisheye.projectPoints), "
                                 "fisheye_distortion_coefficients = k1 k2 k3 k4; the keys say fisheye_ so that "
                                 "readers of plain camera_matrix/distortion_coefficients (k1 k2 p1 p2) do not misread it")
        storage.write("camera_model", camera.model)
        storage.write("calibration_time", time.strftime("%Y-%m-%d %H:%M:%S"))
        storage.write("image_width", int(camera.width))
        storage.write("image_height", int(camera.height))
        storage.write(prefix + "camera_matrix", k)
        storage.write(prefix + "distortion_coefficients", dist.reshape(1, -1))
        if line_delay_s is not None:
            storage.write("line_delay_s", float(line_delay_s))
            storage.write("image_readout_time_s", float(line_delay_s) * image_lines(camera, readout_direction))
            if readout_direction is not None:
                storage.write("readout_direction", readout_direction)
        for key, value in (extra or {}).items():
            storage.write(key, value)
        text = storage.releaseAndGetString()
    finally:
        storage.release()
    Path(path).write_text(text)
