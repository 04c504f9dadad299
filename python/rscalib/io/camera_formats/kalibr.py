"""Kalibr camchain YAML: read cam0; write cam0 with the line delay.

Kalibr's fields (its ConfigReader): camera_model pinhole | omni | eucm | ds, intrinsics
[fu fv pu pv] for pinhole ([xi ...] / [alpha beta ...] first for the others), distortion_model
radtan (k1 k2 p1 p2) | equidistant (k1..k4) | fov | none, distortion_coeffs, resolution [w h],
rostopic, cam_overlaps. Pixels follow OpenCV's convention. rscalib reads pinhole with radtan,
equidistant or none; the other models exit 2 naming what is supported.

Kalibr's radtan has no k3. Dropping k3 moves image points by many pixels at the corners, so the
export refits k1, k2, p1, p2 with k3 = 0 (refit_without_k3) over the whole image and says how far
the refitted camera is from ours.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import yaml

from ..._core import CameraModel
from ...errors import InputError
from .common import EQUIDISTANT, RADTAN, CameraFile, camera_from_opencv, finite_number, line_delay_value, supported

KALIBR_MODELS = ("pinhole",)
KALIBR_DISTORTIONS = ("radtan", "equidistant", "none")
KNOWN_UNSUPPORTED = {"omni": "omnidirectional (Mei)", "eucm": "extended unified", "ds": "double sphere"}
# Kalibr's camera_validator stops without cam_overlaps; a single camera overlaps none.
REFIT_GRID = (41, 31)   # pixels sampled over the image for the k3 refit


def is_kalibr(data) -> bool:
    return isinstance(data, dict) and "cam0" in data


def read_kalibr(path: Path, data: dict) -> CameraFile:
    cam = data["cam0"]
    if not isinstance(cam, dict):
        raise InputError(f"{path}: cam0 must be a mapping of Kalibr's fields (camera_model, intrinsics, "
                         f"distortion_model, distortion_coeffs, resolution), not {str(cam)[:40]!r}")
    notes = []
    others = sorted(str(k) for k in data if str(k).startswith("cam") and k != "cam0")
    if others:
        notes.append(f"{path}: the camchain has {len(others) + 1} cameras; cam0 is used")
    model = cam.get("camera_model", "pinhole")
    if not isinstance(model, str) or model not in KALIBR_MODELS:
        what = f" ({KNOWN_UNSUPPORTED[model]})" if isinstance(model, str) and model in KNOWN_UNSUPPORTED else ""
        raise InputError(f"{path}: cam0 camera_model '{model}'{what} is not supported; supported: camera_model "
                         f"pinhole with distortion_model {supported(KALIBR_DISTORTIONS)}")
    distortion = cam.get("distortion_model", "radtan")
    if not isinstance(distortion, str) or distortion not in KALIBR_DISTORTIONS:
        raise InputError(f"{path}: cam0 distortion_model '{distortion}' is not supported; supported: "
                         f"{supported(KALIBR_DISTORTIONS)}")
    intrinsics = _numbers(path, cam, "intrinsics", 4)
    coeffs = [] if distortion == "none" else _numbers(path, cam, "distortion_coeffs", 4)
    width, height = _numbers(path, cam, "resolution", 2)
    fx, fy, cx, cy = intrinsics
    k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    try:
        camera = camera_from_opencv(k, coeffs or [0, 0, 0, 0], width, height,
                                    EQUIDISTANT if distortion == "equidistant" else RADTAN,
                                    fields=("intrinsics", "distortion_coeffs"),
                                    size_fields=("resolution (width)", "resolution (height)"))
        line_delay = line_delay_value(cam.get("line_delay"), "line_delay")
    except InputError as error:
        raise InputError(f"{path}: cam0 {error}") from None
    return CameraFile(camera, line_delay, "kalibr", notes)


def _numbers(path: Path, cam: dict, key: str, count: Optional[int]) -> list:
    value = cam.get(key)
    if value is None:
        raise InputError(f"{path}: cam0 has no field '{key}'")
    if not isinstance(value, (list, tuple)):
        raise InputError(f"{path}: cam0 {key} must be a list of numbers, not {type(value).__name__} "
                         f"{str(value)[:40]!r}")
    try:
        numbers = [finite_number(v, f"cam0 {key}") for v in value]
    except InputError:
        raise InputError(f"{path}: cam0 {key} must be a list of numbers, not {str(value)[:40]!r}") from None
    if count is not None and len(numbers) != count:
        raise InputError(f"{path}: cam0 {key} needs {count} values, has {len(numbers)}")
    return numbers


@dataclass
class Refit:
    """A pinhole-radtan camera without k3 that projects like the original over the whole image."""

    camera: CameraModel
    rms_px: float    # over a grid of the image's pixels: |refitted projection - pixel|
    max_px: float


def refit_without_k3(camera: CameraModel) -> Refit:
    """k1, k2, p1, p2 with k3 = 0 (fx, fy, cx, cy kept) that best reproduce `camera` over the image.

    The rays of a pixel grid come from the original model; with the focal lengths and principal
    point fixed, the radtan distortion is linear in k1, k2, p1, p2, so the fit is one linear
    least-squares solve in pixels (no iterations, no starting point)."""
    p = np.asarray(camera.params, dtype=np.float64)
    fx, fy, cx, cy = p[:4]
    u, v = np.meshgrid(np.linspace(0, camera.width - 1, REFIT_GRID[0]),
                       np.linspace(0, camera.height - 1, REFIT_GRID[1]))
    pixels = np.c_[u.ravel(), v.ravel()]
    rays = camera.unproject(pixels)
    ok = np.all(np.isfinite(rays), axis=1)
    pixels, x, y = pixels[ok], rays[ok, 0], rays[ok, 1]
    r2 = x * x + y * y
    # pixel residual of the undistorted projection, as a linear function of [k1 k2 p1 p2]
    a_u = fx * np.c_[x * r2, x * r2 * r2, 2 * x * y, r2 + 2 * x * x]
    a_v = fy * np.c_[y * r2, y * r2 * r2, r2 + 2 * y * y, 2 * x * y]
    b = np.r_[pixels[:, 0] - (fx * x + cx), pixels[:, 1] - (fy * y + cy)]
    coeffs = np.linalg.lstsq(np.r_[a_u, a_v], b, rcond=None)[0]
    refitted = CameraModel(RADTAN, np.r_[p[:4], coeffs, 0.0], camera.width, camera.height)
    error = np.linalg.norm(refitted.project(rays[ok]) - pixels, axis=1)
    return Refit(refitted, float(np.sqrt(np.mean(error ** 2))), float(np.max(error)))


def write_kalibr_camchain(camera: CameraModel, path, line_delay_s: Optional[float] = None,
                          rostopic: str = "/cam0/image_raw") -> list[str]:
    """Kalibr camchain YAML (cam0, with cam_overlaps: [] and the line delay in s/row). A radtan
    camera with k3 is refitted without it (refit_without_k3). Returns notes on what changed."""
    notes = []
    p = np.asarray(camera.params, dtype=float)
    if camera.model == RADTAN:
        distortion = "radtan"
        if p[8] != 0:
            refit = refit_without_k3(camera)
            notes.append(f"Kalibr's radtan has no k3: k1, k2, p1, p2 were refitted with k3 = 0 for {Path(path).name}; "
                         f"it projects {refit.rms_px:.3f} px rms, {refit.max_px:.3f} px at most, from the calibrated "
                         "camera over the image")
            p = np.asarray(refit.camera.params, dtype=float)
        coeffs = p[4:8]
    elif camera.model == EQUIDISTANT:
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
        "cam_overlaps": [],
    }
    if line_delay_s is not None:
        cam["line_delay"] = float(line_delay_s)  # seconds per row, as Kalibr's rolling-shutter calibrator
    Path(path).write_text(yaml.safe_dump({"cam0": cam}, sort_keys=False))
    return notes
