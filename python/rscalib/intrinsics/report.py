"""Outputs of `rscalib intrinsics`: camera.yaml (OpenCV FileStorage), the same camera for Kalibr,
Gyroflow, ROS, mrcal and COLMAP, the detections as mrcal's corners.vnl, and result.json."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from .._version import __version__
from ..detection.detectors import DETECTOR_VERSION
from ..detection.result import DetectionResult
from ..errors import InputError
from ..io.camera_formats.mrcal import write_corners_vnl
from ..io.cameras import write_camera_set, write_opencv_yaml
from ..io.output_folder import output_set
from ..io.results import write_result_json
from ..verdict import Verdict
from .calibrate import IntrinsicsResult


def write_intrinsics(result: IntrinsicsResult, out_dir, detections: Optional[DetectionResult] = None,
                     extra: Optional[dict] = None, inputs: Optional[dict] = None,
                     gyroflow: Optional[dict] = None, verdict: Optional[Verdict] = None) -> tuple[Path, Path]:
    """Write out_dir/camera.yaml (OpenCV FileStorage), the camera files for other tools
    (io.cameras.write_camera_set: Kalibr, Gyroflow, ROS, mrcal, COLMAP), the detections as mrcal's
    corners.vnl (when given, on a grid target) and out_dir/result.json. inputs: the provenance's
    input files ({"images": [...], "target": path}); gyroflow: camera_brand, camera_model, lens_model
    of the Gyroflow profile; verdict: the run's (result.json's verdict block). Returns the paths of
    camera.yaml and result.json."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"cannot create {out}: {error.strerror}") from None
    camera_path, json_path = out / "camera.yaml", out / "result.json"
    with output_set(out) as staged:   # the files replace the previous run's as a set, result.json last
        write_opencv_yaml(result.camera, staged / "camera.yaml", extra={"avg_reprojection_error": float(result.rms_px)})
        summary = {"rscalib_version": __version__, "detector_version": DETECTOR_VERSION, **result.to_dict()}
        fps = 0.0
        if detections is not None and detections.timestamps != "frame index" and \
                detections.observations.num_frames > 1:
            fps = float(1.0 / np.median(np.diff(detections.observations.frame_times_s)))
        exports = write_camera_set(result.camera, staged, None, fps=fps, rms_px=result.rms_px, opencv_name=None,
                                   num_images=len(result.view_index), gyroflow=gyroflow)
        files = {"opencv_yaml": "camera.yaml"} | exports.files
        notes = list(exports.notes)
        if detections is not None:
            obs = detections.observations
            try:
                write_corners_vnl(staged / "corners.vnl", [str(label) for label in detections.frame_labels],
                                  obs.frame_index, obs.point_id, obs.uv, obs.target_points)
                files["mrcal_corners"] = "corners.vnl"
            except InputError as error:
                notes.append(f"no corners.vnl: {error}")
        if exports.details:
            summary["exports"] = exports.details
        summary["export_notes"] = notes
        summary["files"] = files
        if detections is not None:
            times = detections.observations.frame_times_s
            for view, index in zip(summary["views"], result.view_index):
                view["time_s"] = float(times[index])
            summary.update({
                "frames_total": int(detections.frames_total),
                "frames_detected": int(detections.frames_detected),
                "dropped": {k: int(v) for k, v in detections.dropped.items()},
                "timestamps": detections.timestamps,
                "detections_from_cache": bool(detections.from_cache),
            })
            summary["warnings"] = list(detections.warnings) + summary["warnings"]
        summary.update(extra or {})
        if verdict is not None:
            summary["verdict"] = verdict.to_dict()
        if inputs is None:
            inputs = (extra or {}).get("inputs")
        write_result_json(staged, summary, command="intrinsics", inputs=inputs)
    return camera_path, json_path
