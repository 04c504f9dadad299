"""The front door of the intrinsics job: stills or a slow video of a target -> the camera with its
verdict, and the files. `rscalib intrinsics`, `rscalib batch` and the experiments all run
:func:`calibrate_intrinsics`; ``rscalib.calibrate_intrinsics`` is this one.

    the target detected in every image (rscalib.detection.pipeline.detect_video; or detections
    already made) -> OpenCV's calibration over the chosen views (calibrate.calibrate_detections)
    -> the verdict -> IntrinsicsRun, whose .write(out_dir) writes what the CLI writes (report.py).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence, Union

from .. import checks
from .._core import CameraModel
from .._progress import ProgressArg
from ..detection.pipeline import detect_video
from ..detection.result import DetectionResult
from ..errors import InputError
from ..io.limits import bounded_workers
from ..io.targets import Target, load_target
from ..io.video import open_source
from ..verdict import TRUSTED, Verdict
from .calibrate import IntrinsicsResult, calibrate_detections
from .options import IntrinsicsOptions

PathLike = Union[str, Path]


@dataclass
class IntrinsicsRun:
    """What :func:`calibrate_intrinsics` returns: the calibration (result: IntrinsicsResult), its
    verdict, the detections it came from, and :meth:`write` for the files `rscalib intrinsics` writes."""

    result: IntrinsicsResult
    verdict: Verdict
    detection: DetectionResult
    target: Optional[Target]
    options: IntrinsicsOptions
    inputs: dict

    command = "intrinsics"

    @property
    def camera(self) -> CameraModel:
        return self.result.camera

    def write(self, out_dir, *, lens_profile: Optional[dict] = None) -> dict:
        """camera.yaml, the camera files for other tools, corners.vnl and result.json into out_dir (as
        one set); returns the result.json dict. lens_profile: camera_brand, camera_model, lens_model of
        the Gyroflow profile."""
        import json

        from .report import write_intrinsics

        extra = {"target": {"target_type": self.target.target_type, **self.target.spec}} if self.target else None
        _, json_path = write_intrinsics(self.result, out_dir, self.detection, extra=extra, inputs=self.inputs,
                                        gyroflow=lens_profile, verdict=self.verdict)
        return json.loads(Path(json_path).read_text())


def calibrate_intrinsics(source: Union[PathLike, Sequence[PathLike], DetectionResult],
                         target: Union[None, PathLike, Target] = None,
                         options: Optional[IntrinsicsOptions] = None, *, progress: ProgressArg = False) -> IntrinsicsRun:
    """The intrinsics and distortion of the camera that took `source` (a video, an image folder, or a
    list of image files, of `target`: its file or a Target; or detections already made), with its
    verdict (`rscalib intrinsics`). options: IntrinsicsOptions (None: the defaults)."""
    options = IntrinsicsOptions() if options is None else options
    checks.source(source, "source", (DetectionResult,), "or a DetectionResult")
    if target is not None:
        checks.instance(target, "target", (str, os.PathLike, Target), "a target file or an rscalib.Target")
    checks.instance(options, "options", (IntrinsicsOptions,), "an rscalib.IntrinsicsOptions or None")
    checks.progress(progress)
    if isinstance(source, DetectionResult):
        detection, target_ = source, (target if isinstance(target, Target) else None)
        inputs = {"images": None, "target": None if target is None or isinstance(target, Target) else str(target)}
    else:
        if target is None:
            raise InputError("a target is needed to detect: its file (--target) or a Target")
        target_ = target if isinstance(target, Target) else load_target(target)
        workers = bounded_workers(open_source(source), options.detection.workers)   # frame sizes from headers
        detection = detect_video(source, target_, _with_workers(options, workers), progress=progress)
        names = [str(source)] if isinstance(source, (str, Path)) else [str(s) for s in source]
        inputs = {"images": names, "target": None if isinstance(target, Target) else str(target)}
    result = calibrate_detections(detection, options)
    fx_std = float(result.param_std[0])
    verdict = Verdict(TRUSTED, f"fx {result.params[0]:.3f} px, RMS {result.rms_px:.3f} px over "
                               f"{len(result.view_index)} views.", (), quantity="fx_px", value=float(result.params[0]),
                      std=fx_std if math.isfinite(fx_std) else None, unit="px", caveats=tuple(detection.warnings) + tuple(result.warnings))
    return IntrinsicsRun(result, verdict, detection, target_, options, inputs)


def _with_workers(options: IntrinsicsOptions, workers: int):
    from dataclasses import replace

    return replace(options.detection, workers=workers)
