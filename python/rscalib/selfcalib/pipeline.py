"""The front door of the self-calibration job: a video or image folder of a natural scene -> f, the
principal point and the radial distortion with 99 % bounds and a verdict, and the files.
`rscalib selfcalib`, `rscalib batch` and the experiments all run :func:`self_calibrate`;
``rscalib.self_calibrate`` is this one.

    the frames (rscalib.io.video.read_gray_frames) -> the engine (engine.calibrate_frames: the
    Sum-of-Gaussians bank, then the bundle adjustment over its tracks) -> the verdict (judge.py)
    -> SelfCalibRun, whose .write(out_dir) writes what the CLI writes (report.py).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Union

from .. import checks
from .._core import CameraModel, SogBank, SogUpdateReport
from .._progress import ProgressArg
from ..errors import InputError
from ..io.video import GrayFrames, read_gray_frames
from ..verdict import Verdict
from .engine import calibrate_frames
from .judge import selfcalib_verdict
from .options import SelfCalibOptions
from .result import PARAM_NAMES, SelfCalibResult

PathLike = Union[str, Path]


@dataclass
class SelfCalibRun:
    """What :func:`self_calibrate` returns: the calibration with its verdict, the engine's result
    behind it, and :meth:`write` for the files `rscalib selfcalib` writes.

    calibration: {f, cx, cy, k1, k2} (px; mm^-2, mm^-4 at options.pixel_size_mm) when the data
    determine it, None when not (no number is claimed: only the bounds the data allow,
    result.bounds_99)."""

    result: SelfCalibResult
    verdict: Verdict
    options: SelfCalibOptions
    inputs: dict
    timestamps_from: str = "given"

    command = "selfcalib"

    @property
    def calibration(self) -> Optional[dict]:
        if not self.verdict.claims:
            return None
        return {name: float(v) for name, v in zip(PARAM_NAMES, self.result.mean)}

    def camera(self) -> Optional[CameraModel]:
        """The civera-radial camera when determined (None when not)."""
        return self.result.camera() if self.verdict.claims else None

    def summary(self) -> dict:
        """The result.json fields (without the files and the provenance)."""
        from .report import run_summary

        return run_summary(self)

    def write(self, out_dir) -> dict:
        """Write result.json, history.png and, when determined, camera.yaml (the OpenCV camera closest to
        the civera-radial estimate) into out_dir, as one set; returns the result.json dict."""
        from .report import write_selfcalib_run

        return write_selfcalib_run(self, out_dir)


def self_calibrate(source: Union[PathLike, GrayFrames], options: Optional[SelfCalibOptions] = None, *,
                   progress: ProgressArg = False,
                   on_frame: Optional[Callable[[int, SogBank, SogUpdateReport], None]] = None
                   ) -> SelfCalibRun:
    """f, the principal point and the radial distortion of the camera that filmed `source` (a video
    file or image folder of a natural scene, or rscalib.io.video.GrayFrames whose `frames` may be a
    callable returning a fresh iterable), with 99 % bounds and a verdict (`rscalib selfcalib`).
    options: SelfCalibOptions (None: the method's defaults)."""
    options = SelfCalibOptions() if options is None else options
    checks.instance(source, "source", (str, os.PathLike, GrayFrames),
                    "a video file, an image folder or rscalib.io.video.GrayFrames")
    checks.instance(options, "options", (SelfCalibOptions,), "an rscalib.SelfCalibOptions or None")
    checks.progress(progress)
    checks.optional_callable(on_frame, "on_frame")
    if isinstance(source, GrayFrames):
        video, frames, name = source, source.frames, None
    else:
        if not checks.path(source, "source").exists():
            raise InputError(f"not found: {source}")
        video, name = read_gray_frames(source), str(source)
        first = [video.frames]

        def frames():   # the first pass reads the opened video; a baseline's restarts open it again
            return first.pop() if first else read_gray_frames(source).frames

    result = calibrate_frames(frames, video.image_size, options, progress=progress,
                              expected_frames=video.frame_count_estimate, on_frame=on_frame)
    inputs = {"source": name, "pixel_size_mm": options.pixel_size_mm, "max_frames": options.max_frames,
              "baseline": options.baseline, "f_range": options.f_range_px, "f0": options.f0_px,
              "f_sigma": options.f_sigma_px, "sprt_alpha": options.sprt_alpha, "sprt_beta": options.sprt_beta,
              "subpixel": options.front_end.subpixel, "restarts": options.restarts,
              "ransac_hypotheses": options.ransac_hypotheses, "line_delay_s": options.line_delay_s,
              "determined_within": options.determined_within}
    return SelfCalibRun(result, selfcalib_verdict(result), options, inputs, video.timestamps_from)
