"""Camera files: the front door to rscalib.io.camera_formats.

load_camera reads OpenCV FileStorage (YAML/XML/JSON), Kalibr camchains, ROS camera_info, mrcal
.cameramodel, COLMAP cameras.txt and Gyroflow lens profiles, telling them apart by content; a file
of none of these, or a lens model rscalib has no equal for, is an InputError naming the file and what
is supported. write_camera writes one format; write_camera_set writes every format a result ships
(docs/formats.md: the table of formats, models and the consumers they were checked against).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from .. import checks
from .._core import CameraModel
from ..errors import InputError
from .camera_formats.colmap import is_colmap, read_colmap, write_colmap_cameras
from .camera_formats.common import CameraFile, camera_from_opencv, opencv_matrices
from .camera_formats.gyroflow import is_gyroflow, read_gyroflow, write_gyroflow_profile
from .camera_formats.kalibr import is_kalibr, read_kalibr, refit_without_k3, write_kalibr_camchain
from .camera_formats.mrcal import is_mrcal, parse_mrcal, read_mrcal, write_mrcal_cameramodel
from .camera_formats.opencv import read_opencv, write_opencv_yaml
from .camera_formats.ros import is_ros, read_ros, write_ros_camera_info
from .safe_parse import load_json, load_yaml, one_line, read_text, shown

__all__ = ["CameraFile", "camera_from_opencv", "opencv_matrices", "load_camera", "write_camera",
           "write_camera_set", "write_opencv_yaml", "write_kalibr_camchain", "write_gyroflow_profile",
           "write_ros_camera_info", "write_mrcal_cameramodel", "write_colmap_cameras", "refit_without_k3",
           "CAMERA_FORMATS", "FILE_PURPOSES", "CameraExports"]

READABLE = "OpenCV FileStorage, Kalibr camchain, ROS camera_info, mrcal .cameramodel, COLMAP cameras.txt, Gyroflow profile"


# Larger than any camera file of the formats above (an mrcal model with its optimization inputs is
# a few MB): a bigger file is refused from its size, before it is read.
CAMERA_FILE_MAX_BYTES = 16 * 2 ** 20
# OpenCV's %YAML:1.0 header (not a YAML directive) before a plain YAML file (ROS files saved by OpenCV)
_OPENCV_HEADER = re.compile(r"\A(\s*%YAML[: ]\S*\s*\n)(\s*---\s*\n)?")
_COMMENT_LINES = re.compile(r"\A(\s*#[^\n]*\n)*\s*")


def _structured(path: Path, text: str):
    """The data of a JSON, YAML (block or flow) or Python-literal (mrcal) camera file, each parsed
    within safe_parse's limits; InputError with the reason of the syntax the file most looks like."""
    text = _OPENCV_HEADER.sub("", text)
    if not text[_COMMENT_LINES.match(text).end():].startswith(("{", "[")):
        return load_yaml(text, path)
    mrcal = lambda: parse_mrcal(path, text)  # noqa: E731
    json_ = lambda: load_json(text, path)  # noqa: E731
    yaml_ = lambda: load_yaml(text, path)  # noqa: E731
    # the first parser's complaint is the one shown: that of the syntax the file most looks like
    mrcal_like = "'lensmodel'" in text or "'distortion_model'" in text
    first_error = None
    for parse in (mrcal, json_, yaml_) if mrcal_like else (json_, yaml_, mrcal):
        try:
            return parse()
        except InputError as error:
            first_error = first_error or error
    raise first_error


def load_camera(path) -> CameraFile:
    """Read a camera file of any format above; InputError (one line, naming the file and field)
    for a file or model rscalib cannot use. The file is read within safe_parse's limits (size,
    nesting, aliases, integer length) whatever it holds."""
    path = checks.path(path, "path (the camera file)")
    try:
        return _load_camera(path)
    except InputError as error:
        raise InputError(one_line(str(error))) from None


def _load_camera(path: Path) -> CameraFile:
    if path.is_dir():
        raise InputError(f"{shown(path)} is a folder, not a camera file")
    if not path.is_file():
        raise InputError(f"camera file not found: {shown(path)}")
    text = read_text(path, CAMERA_FILE_MAX_BYTES, "camera file", encoding="utf-8-sig")   # a BOM is not text
    if path.suffix.lower() == ".cameramodel":
        return read_mrcal(path, parse_mrcal(path, text))
    if is_colmap(path, text):
        return read_colmap(path, text)
    if path.suffix.lower() == ".txt":
        raise InputError(f"{shown(path)}: not a COLMAP cameras.txt (lines CAMERA_ID MODEL WIDTH HEIGHT PARAMS[])")
    if "opencv-matrix" in text or text.lstrip().startswith(("<?xml", "<opencv_storage")):
        return read_opencv(path, text)
    data = _structured(path, text)
    if is_gyroflow(data):
        return read_gyroflow(path, data)
    if is_kalibr(data):
        return read_kalibr(path, data)
    if is_ros(data):
        return read_ros(path, data)
    if is_mrcal(data):
        return read_mrcal(path, data)
    raise InputError(f"{shown(path)}: not a camera file rscalib reads ({READABLE}; docs/formats.md)")


CAMERA_FORMATS = ("opencv", "kalibr", "gyroflow", "ros", "mrcal", "colmap")


def write_camera(camera: CameraModel, path, format: str = "opencv", line_delay_s: Optional[float] = None,
                 **options) -> list[str]:
    """Write `camera` (with the line delay, if given and the format holds one) as `format`, one of
    CAMERA_FORMATS; `options` go to that writer. Returns notes on what the format changed."""
    checks.instance(camera, "camera", (CameraModel,), "an rscalib.CameraModel")
    target = checks.path(path, "path (the camera file to write)")
    if target.is_dir():
        raise InputError(f"path {shown(target)} is a folder: give the camera file's name")
    if not target.parent.is_dir():
        raise InputError(f"path {shown(target)}: its folder {shown(target.parent)} does not exist")
    if line_delay_s is not None:
        line_delay_s = checks.line_delay(line_delay_s, "line_delay_s")
    if format == "opencv":
        write_opencv_yaml(camera, path, line_delay_s, **options)
        return []
    if format == "kalibr":
        return write_kalibr_camchain(camera, path, line_delay_s, **options)
    if format == "gyroflow":
        write_gyroflow_profile(camera, path, line_delay_s, **options)
        return []
    if format == "ros":
        write_ros_camera_info(camera, path, **options)
        return []
    if format == "mrcal":
        write_mrcal_cameramodel(camera, path, **options)
        return []
    if format == "colmap":
        write_colmap_cameras(camera, path)
        return []
    raise InputError(f"unknown camera file format {format!r}; supported: {', '.join(CAMERA_FORMATS)}")


# result.json "files" role -> what the file is for (one line in the reports)
FILE_PURPOSES = {
    "opencv_yaml": "the camera for OpenCV (cv2.FileStorage) and for rscalib's --camera",
    "kalibr_camchain": "the camera for Kalibr (camchain, line_delay in s/row)",
    "gyroflow_profile": "lens profile for Gyroflow (frame_readout_time in ms)",
    "ros_camera_info": "the camera for ROS (camera_info YAML, camera_calibration_parsers)",
    "mrcal_cameramodel": "the camera for mrcal (.cameramodel)",
    "mrcal_corners": "the detections for mrcal's tools (corners.vnl: mrcal-calibrate-cameras --corners-cache)",
    "colmap_cameras": "the camera for COLMAP (cameras.txt; principal point +0.5 px, COLMAP's pixels)",
    "trajectory_csv": "the trajectory, world(target)-to-camera pose at each time (CSV)",
    "trajectory_tum": "the trajectory in TUM format (camera position, camera-to-world quaternion)",
    "report": "this report",
    "result_json": "every number of the run, with provenance (JSON)",
}


@dataclass
class CameraExports:
    """What write_camera_set wrote: {role: file name}, notes (what a format changed or could not
    hold), and details for result.json (e.g. the Kalibr refit error)."""

    files: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    details: dict = field(default_factory=dict)


def write_camera_set(camera: CameraModel, out_dir, line_delay_s: Optional[float] = None, fps: float = 0.0,
                     rms_px: float = 0.0, *, opencv_name: Optional[str] = "camera_with_line_delay.yaml",
                     num_images: int = 0, gyroflow: Optional[dict] = None,
                     readout_direction: Optional[str] = None) -> CameraExports:
    """The camera files of a result in out_dir: the OpenCV YAML (unless opencv_name is None: the
    caller wrote it), Kalibr camchain, Gyroflow profile, ROS camera_info, mrcal .cameramodel
    (pinhole-radtan only) and COLMAP cameras.txt. gyroflow: camera_brand, camera_model,
    lens_model (and note) for the Gyroflow profile; readout_direction: Gyroflow's name of it
    (TopToBottom, ...; the image lines along it set image_readout_time_s)."""
    out = Path(out_dir)
    done = CameraExports()
    if opencv_name is not None:
        write_opencv_yaml(camera, out / opencv_name, line_delay_s, readout_direction=readout_direction)
        done.files["opencv_yaml"] = opencv_name
    if camera.model not in ("pinhole-radtan", "pinhole-equidistant"):
        done.notes.append(f"{camera.model} has no equal in Kalibr, Gyroflow, ROS, mrcal or COLMAP: only the "
                          "OpenCV-style file is written")
        return done
    done.notes += write_kalibr_camchain(camera, out / "camchain.yaml", line_delay_s)
    done.files["kalibr_camchain"] = "camchain.yaml"
    if camera.model == "pinhole-radtan" and camera.params[8] != 0:
        refit = refit_without_k3(camera)
        done.details["kalibr_refit_without_k3"] = {"rms_px": refit.rms_px, "max_px": refit.max_px,
                                                   "distortion_coeffs": list(refit.camera.params[4:8])}
    write_gyroflow_profile(camera, out / "gyroflow_lens_profile.json", line_delay_s, fps=fps, rms_px=rms_px,
                           num_images=num_images, readout_direction=readout_direction, **(gyroflow or {}))
    done.files["gyroflow_profile"] = "gyroflow_lens_profile.json"
    write_ros_camera_info(camera, out / "camera_info.yaml")
    done.files["ros_camera_info"] = "camera_info.yaml"
    if camera.model == "pinhole-radtan":
        write_mrcal_cameramodel(camera, out / "camera.cameramodel")
        done.files["mrcal_cameramodel"] = "camera.cameramodel"
    else:
        done.notes.append("no mrcal .cameramodel: mrcal has no model equal to OpenCV's fisheye (pinhole-equidistant)")
    write_colmap_cameras(camera, out / "cameras.txt")
    done.files["colmap_cameras"] = "cameras.txt"
    return done
