"""Gyroflow lens profiles (JSON), with the fields of Gyroflow's LensProfile struct
(src/core/lens_profile.rs) that a profile of ours can fill; Gyroflow's serde defaults cover the rest.

- fisheye_params holds the camera matrix and distortion of either model; distortion_model says which
  (opencv_fisheye: k1..k4, Gyroflow's default and the model of its database; opencv_standard:
  k1 k2 p1 p2 k3). asymmetrical: true makes Gyroflow use our principal point, not the image centre.
- frame_readout_time (ms) is the time from the first to the last image row: line delay x image
  height (Gyroflow divides it by the video height). null when the line delay is unknown.
- output_dimension is left null: Gyroflow then keeps the video's size.
- Gyroflow stamps a frame at mid-readout; frame_readout_time is a duration and needs no conversion.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Optional

from ..._core import CameraModel
from ..._version import __version__
from ...errors import InputError
from .common import (
    EQUIDISTANT,
    RADTAN,
    CameraFile,
    camera_from_opencv,
    finite_number,
    image_lines,
    image_side_px,
    line_delay_value,
    numeric_array,
    opencv_matrices,
)

READOUT_DIRECTIONS = ("TopToBottom", "BottomToTop", "LeftToRight", "RightToLeft")


def profile_name(brand: str, model: str, lens: str, width: int, height: int, fps: float) -> str:
    """Gyroflow's naming: brand_model_lens_WxH-FPSfps, empty parts left out."""
    parts = [p.strip() for p in (brand, model, lens) if p and p.strip()] or ["rscalib"]
    return "_".join(parts) + f"_{width}x{height}" + (f"-{fps:.2f}fps" if fps > 0 else "")


def write_gyroflow_profile(camera: CameraModel, path, line_delay_s: Optional[float] = None, fps: float = 0.0,
                           rms_px: float = 0.0, note: str = "", num_images: int = 0, camera_brand: str = "",
                           camera_model: str = "", lens_model: str = "",
                           readout_direction: Optional[str] = None) -> None:
    """A Gyroflow lens profile of `camera`; with the line delay (s/row) when it is known.
    readout_direction: one of READOUT_DIRECTIONS (default: from the sign of the line delay)."""
    k, dist = opencv_matrices(camera)
    fisheye = camera.model == EQUIDISTANT
    fps = round(float(fps), 3) if fps and fps > 0 else 0.0
    lines = image_lines(camera, readout_direction)
    readout_ms = None if line_delay_s is None else float(line_delay_s) * lines * 1e3
    if readout_direction is None:
        readout_direction = "BottomToTop" if readout_ms is not None and readout_ms < 0 else "TopToBottom"
    profile = {
        "name": profile_name(camera_brand, camera_model, lens_model, camera.width, camera.height, fps),
        "note": note or ("calibrated with rscalib" + (" (line delay from a target video)" if readout_ms else "")),
        "calibrated_by": "rscalib",
        "camera_brand": camera_brand, "camera_model": camera_model, "lens_model": lens_model, "camera_setting": "",
        "calib_dimension": {"w": int(camera.width), "h": int(camera.height)},
        "orig_dimension": {"w": int(camera.width), "h": int(camera.height)},
        "output_dimension": None,
        "frame_readout_time": None if readout_ms is None else abs(readout_ms),
        "frame_readout_direction": readout_direction,
        "input_horizontal_stretch": 1.0,
        "input_vertical_stretch": 1.0,
        "num_images": int(num_images),
        "fps": fps,
        "official": False,
        "asymmetrical": True,
        "fisheye_params": {"RMS_error": float(rms_px), "camera_matrix": k.tolist(), "distortion_coeffs": dist.tolist()},
        "distortion_model": "opencv_fisheye" if fisheye else "opencv_standard",
        "calibrator_version": f"rscalib {__version__}",
        "date": time.strftime("%Y-%m-%d"),
        "compatible_settings": [],
    }
    Path(path).write_text(json.dumps(profile, indent=2) + "\n")


def is_gyroflow(data) -> bool:
    return isinstance(data, dict) and isinstance(data.get("fisheye_params"), dict) and "calib_dimension" in data


def read_gyroflow(path: Path, data: dict) -> CameraFile:
    """The camera of a Gyroflow lens profile (opencv_fisheye or opencv_standard, asymmetrical or
    not: Gyroflow puts the principal point at the image centre unless asymmetrical is true), with
    the line delay from frame_readout_time when it is given."""
    model_name = data.get("distortion_model") or "opencv_fisheye"
    models = {"opencv_fisheye": EQUIDISTANT, "opencv_standard": RADTAN}
    if not isinstance(model_name, str) or model_name not in models:
        raise InputError(f"{path}: Gyroflow distortion_model '{model_name}' is not supported; supported: "
                         "opencv_fisheye or opencv_standard")
    params, size = data["fisheye_params"], data["calib_dimension"]
    if not isinstance(size, dict) or "camera_matrix" not in params or "distortion_coeffs" not in params:
        raise InputError(f"{path}: fisheye_params (camera_matrix, distortion_coeffs) and calib_dimension "
                         "{w, h} are needed")
    try:
        k = numeric_array(params["camera_matrix"], "fisheye_params.camera_matrix")
        if k.size != 9:
            raise InputError(f"fisheye_params.camera_matrix needs 9 values (3x3), has {k.size}")
        k = k.reshape(3, 3)
        width = image_side_px(size.get("w"), "calib_dimension.w")
        height = image_side_px(size.get("h"), "calib_dimension.h")
        asymmetrical = data.get("asymmetrical", False)
        if not isinstance(asymmetrical, bool) and asymmetrical is not None:
            raise InputError(f"asymmetrical must be true or false, not {str(asymmetrical)[:40]!r}")
        if not asymmetrical:
            k[0, 2], k[1, 2] = width / 2.0, height / 2.0   # what Gyroflow does with a symmetrical profile
        camera = camera_from_opencv(k, params["distortion_coeffs"], width, height, models[model_name],
                                    fields=("fisheye_params.camera_matrix", "fisheye_params.distortion_coeffs"),
                                    size_fields=("calib_dimension.w", "calib_dimension.h"))
        readout_ms = data.get("frame_readout_time")
        line_delay = None
        if readout_ms is not None and readout_ms != 0:
            direction = data.get("frame_readout_direction")
            if direction is not None and (not isinstance(direction, str) or direction not in READOUT_DIRECTIONS):
                raise InputError(f"frame_readout_direction must be one of {', '.join(READOUT_DIRECTIONS)}, not "
                                 f"{str(direction)[:40]!r}")
            line_delay = line_delay_value(finite_number(readout_ms, "frame_readout_time (ms)") * 1e-3 / image_lines(camera, direction),
                                          "frame_readout_time / image lines")
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    return CameraFile(camera, line_delay, "gyroflow")

