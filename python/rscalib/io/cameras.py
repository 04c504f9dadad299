"""Camera files: read OpenCV FileStorage YAML and Kalibr camchains; write them back (with the
line delay) plus Gyroflow lens profiles.

OpenCV writes a `%YAML:1.0` header and `!!opencv-matrix` tags that PyYAML cannot read, so
OpenCV files go through cv2.FileStorage; Kalibr files are plain YAML.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import cv2
import numpy as np
import yaml

from .._core import CameraModel
from ..errors import InputError


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


@dataclass
class CameraFile:
    """A camera read from disk, with the line delay if the file had one."""

    camera: CameraModel
    line_delay_s: Optional[float] = None
    source_format: str = "opencv"   # "opencv" | "kalibr"


def load_camera(path) -> CameraFile:
    """Read an OpenCV FileStorage YAML/XML/JSON or a Kalibr camchain (cam0)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"camera file not found: {path}")
    text = path.read_text(errors="replace")
    if "cam0" in text and "intrinsics" in text:
        return _read_kalibr(path, text)
    return _read_opencv(path)


def _read_kalibr(path: Path, text: str) -> CameraFile:
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise InputError(f"{path}: not valid YAML ({str(error).splitlines()[0]})") from None
    if not isinstance(data, dict) or "cam0" not in data:
        raise InputError(f"{path}: a Kalibr camchain needs a 'cam0' entry")
    cam = data["cam0"]
    try:
        model = cam.get("camera_model", "pinhole")
        fx, fy, cx, cy = (float(v) for v in cam["intrinsics"])
        distortion = str(cam.get("distortion_model", "radtan"))
        coeffs = [float(v) for v in cam.get("distortion_coeffs", [])]
        width, height = (int(v) for v in cam["resolution"])
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: incomplete Kalibr cam0 ({error})") from None
    if model != "pinhole":
        raise InputError(f"{path}: Kalibr camera_model '{model}' is not supported (pinhole only)")
    k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    if distortion in ("radtan", "none"):
        camera = camera_from_opencv(k, coeffs or [0, 0, 0, 0], width, height, "pinhole-radtan")
    elif distortion in ("equidistant", "fisheye"):
        camera = camera_from_opencv(k, coeffs, width, height, "pinhole-equidistant")
    else:
        raise InputError(f"{path}: Kalibr distortion_model '{distortion}' is not supported (radtan, equidistant)")
    line_delay = cam.get("line_delay")
    return CameraFile(camera, float(line_delay) if line_delay is not None else None, "kalibr")


def _read_opencv(path: Path) -> CameraFile:
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error:
        raise InputError(f"{path}: not an OpenCV FileStorage file or a Kalibr camchain") from None
    try:
        if not storage.isOpened():
            raise InputError(f"{path}: not an OpenCV FileStorage file or a Kalibr camchain")
        k = storage.getNode("camera_matrix").mat()
        dist = storage.getNode("distortion_coefficients").mat()
        width = storage.getNode("image_width").real()
        height = storage.getNode("image_height").real()
        model_node = storage.getNode("distortion_model")
        model_name = model_node.string() if not model_node.empty() else ""
        line_delay_node = storage.getNode("line_delay_s")
        line_delay = None if line_delay_node.empty() else float(line_delay_node.real())
    finally:
        storage.release()
    if k is None or k.shape != (3, 3):
        raise InputError(f"{path}: camera_matrix (3x3) is missing")
    if not width or not height:
        raise InputError(f"{path}: image_width and image_height are missing")
    dist = np.zeros(5) if dist is None else dist.ravel()
    model = "pinhole-equidistant" if model_name in ("fisheye", "equidistant", "pinhole-equidistant") else "pinhole-radtan"
    return CameraFile(camera_from_opencv(k, dist, int(width), int(height), model), line_delay, "opencv")


def write_opencv_yaml(camera: CameraModel, path, line_delay_s: Optional[float] = None,
                      extra: Optional[dict] = None) -> None:
    """OpenCV FileStorage YAML: camera_matrix, distortion_coefficients, image size,
    distortion_model, and (if given) line_delay_s and readout_time_s."""
    k, dist = opencv_matrices(camera)
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("calibration_time", time.strftime("%Y-%m-%d %H:%M:%S"))
    storage.write("image_width", int(camera.width))
    storage.write("image_height", int(camera.height))
    storage.write("distortion_model", "fisheye" if camera.model == "pinhole-equidistant" else "radtan")
    storage.write("camera_matrix", k)
    storage.write("distortion_coefficients", dist.reshape(1, -1))
    if line_delay_s is not None:
        storage.write("line_delay_s", float(line_delay_s))
        storage.write("readout_time_s", float(line_delay_s) * camera.height)
    for key, value in (extra or {}).items():
        storage.write(key, value)
    storage.release()


def write_kalibr_camchain(camera: CameraModel, path, line_delay_s: Optional[float] = None,
                          rostopic: str = "/cam0/image_raw") -> list[str]:
    """Kalibr camchain YAML (cam0). Returns warnings (e.g. a k3 Kalibr cannot hold)."""
    warnings = []
    p = np.asarray(camera.params, dtype=float)
    if camera.model == "pinhole-radtan":
        distortion, coeffs = "radtan", p[4:8]
        if abs(p[8]) > 0:
            warnings.append(f"Kalibr's radtan has no k3; k3 = {p[8]:.4g} was dropped from the camchain")
    elif camera.model == "pinhole-equidistant":
        distortion, coeffs = "equidistant", p[4:8]
    else:
        raise InputError(f"{camera.model} cannot be written as a Kalibr camchain")
    cam = {
        "camera_model": "pinhole",
        "intrinsics": [float(v) for v in p[:4]],
        "distortion_model": distortion,
        "distortion_coeffs": [float(v) for v in coeffs],
        "resolution": [int(camera.width), int(camera.height)],
        "rostopic": rostopic,
    }
    if line_delay_s is not None:
        cam["line_delay"] = float(line_delay_s)  # seconds per row, as Kalibr's RS calibrator
    Path(path).write_text(yaml.safe_dump({"cam0": cam}, sort_keys=False))
    return warnings


def write_gyroflow_profile(camera: CameraModel, path, line_delay_s: float, fps: float = 0.0,
                           rms_px: float = 0.0, note: str = "") -> None:
    """Gyroflow lens profile JSON with frame_readout_time (ms, whole frame) and
    asymmetrical: true so Gyroflow keeps our principal point instead of the image centre.

    Gyroflow stamps a frame at mid-readout; frame_readout_time is a duration and needs no
    conversion, but a time offset measured against rscalib's row-0 timestamps is
    readout/2 earlier than Gyroflow's (docs/conventions.md)."""
    k, dist = opencv_matrices(camera)
    fisheye = camera.model == "pinhole-equidistant"
    params = {"RMS_error": float(rms_px), "camera_matrix": k.tolist(), "distortion_coeffs": dist.tolist()}
    readout_ms = float(line_delay_s) * camera.height * 1e3
    profile = {
        "name": f"rscalib_{camera.width}x{camera.height}",
        "note": note or "calibrated with rscalib (rolling-shutter line delay from a target video)",
        "calibrated_by": "rscalib",
        "camera_brand": "", "camera_model": "", "lens_model": "", "camera_setting": "",
        "calib_dimension": {"w": int(camera.width), "h": int(camera.height)},
        "orig_dimension": {"w": int(camera.width), "h": int(camera.height)},
        "output_dimension": {"w": int(camera.width), "h": int(camera.height)},
        "frame_readout_time": abs(readout_ms),
        "frame_readout_direction": "TopToBottom" if readout_ms >= 0 else "BottomToTop",
        "input_horizontal_stretch": 1.0,
        "fps": float(fps),
        "official": False,
        "asymmetrical": True,
        "distortion_model": "opencv_fisheye" if fisheye else "opencv_standard",
        "use_opencv_fisheye": fisheye,
        "fisheye_params": params,
        "use_opencv_standard": not fisheye,
        "calib_params": params,
        "calibrator_version": "rscalib",
        "date": time.strftime("%Y-%m-%d"),
    }
    Path(path).write_text(json.dumps(profile, indent=2))


CAMERA_FORMATS = ("opencv", "kalibr", "gyroflow")


def write_camera(camera: CameraModel, path, format: str = "opencv", line_delay_s: Optional[float] = None,
                 **options) -> list[str]:
    """Write `camera` (with the line delay, if given) as an OpenCV FileStorage YAML, a Kalibr
    camchain or a Gyroflow lens profile (`format`); `options` go to that writer. Returns warnings."""
    if format == "opencv":
        write_opencv_yaml(camera, path, line_delay_s, **options)
        return []
    if format == "kalibr":
        return write_kalibr_camchain(camera, path, line_delay_s, **options)
    if format == "gyroflow":
        if line_delay_s is None:
            raise InputError("a Gyroflow lens profile needs the line delay")
        write_gyroflow_profile(camera, path, line_delay_s, **options)
        return []
    raise InputError(f"unknown camera file format {format!r}; supported: {', '.join(CAMERA_FORMATS)}")


def write_camera_set(camera: CameraModel, out_dir, line_delay_s: float, fps: float = 0.0,
                     rms_px: float = 0.0) -> tuple[dict, list[str]]:
    """The camera files of a line-delay result in out_dir: OpenCV YAML always; Kalibr camchain and
    Gyroflow profile for the pinhole models. Returns ({role: file name}, warnings)."""
    out_dir = Path(out_dir)
    files, warnings = {}, []
    write_opencv_yaml(camera, out_dir / "camera_with_line_delay.yaml", line_delay_s)
    files["opencv_yaml"] = "camera_with_line_delay.yaml"
    if camera.model in ("pinhole-radtan", "pinhole-equidistant"):
        warnings += write_kalibr_camchain(camera, out_dir / "camchain.yaml", line_delay_s)
        files["kalibr_camchain"] = "camchain.yaml"
        write_gyroflow_profile(camera, out_dir / "gyroflow_lens_profile.json", line_delay_s, fps=fps, rms_px=rms_px)
        files["gyroflow_profile"] = "gyroflow_lens_profile.json"
    return files, warnings
