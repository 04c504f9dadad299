"""rscalib: camera calibration from video.

Rolling-shutter line-delay calibration (Oth et al. 2013), sequential self-calibration
(Civera et al. 2009) and the LED/flicker line-delay method, on a C++ core. Frames, time and
pixel conventions: docs/conventions.md; the package's layout: docs/architecture.md.

The names below are the public API: first one front door per job, each taking its options and
returning a run with ``.verdict`` and ``.write(out_dir)`` (what the command writes):

    rscalib.calibrate_video(video, target, camera, rscalib.LineDelayOptions())   # rscalib linedelay
    rscalib.localize_video(video, target, camera, line_delay_s)                  # rscalib localize
    rscalib.self_calibrate(video, rscalib.SelfCalibOptions(pixel_size_mm=...))   # rscalib selfcalib
    rscalib.estimate_line_delay_flicker(video, frequency_hz)                     # rscalib flicker
    rscalib.calibrate_intrinsics(images, target)                                 # rscalib intrinsics

then the building blocks (files, detection, the C++ core's camera and splines). They are imported on
first use, so ``import rscalib`` does not load the engines, OpenCV or matplotlib until they are needed.
"""
from __future__ import annotations

import os

# One BLAS thread, set before NumPy, OpenCV or the core load OpenBLAS (the first import of a CLI
# process is this one): a sum split over threads runs in another order, and `rscalib intrinsics`'
# sigmas changed in their last bits between the command and a batch job, whose jobs run with every
# thread pool at one (issue 33). A value the user set is kept; in a process that loaded NumPy first
# it has no effect (docs/reliability.md: determinism).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import importlib  # noqa: E402
from typing import TYPE_CHECKING, Any  # noqa: E402

from .errors import InputError  # noqa: E402

# public name -> module that defines it. First the front doors (one per job: the CLI, batch and the
# experiments call the same), their options and results; then the building blocks.
_EXPORTS = {
    # line delay from a video of a target (Oth et al. 2013), and the trajectory with a known one
    "calibrate_video": ".linedelay.pipeline",
    "LineDelayOptions": ".linedelay.options",
    "LineDelayRun": ".linedelay.pipeline",
    "localize_video": ".linedelay.pipeline",
    "LocalizeOptions": ".linedelay.options",
    "LocalizeRun": ".linedelay.pipeline",
    # self-calibration from a natural scene (Civera et al. 2009)
    "self_calibrate": ".selfcalib.pipeline",
    "SelfCalibOptions": ".selfcalib.options",
    "SelfCalibRun": ".selfcalib.pipeline",
    "track_features": ".selfcalib.tracks",      # its front end's feature tracks, for your own geometry
    "TrackOptions": ".selfcalib.options",
    "TrackSet": ".selfcalib.tracks",
    # line delay from a flickering light
    "estimate_line_delay_flicker": ".flicker.pipeline",
    "FlickerOptions": ".flicker.options",
    "FlickerRun": ".flicker.pipeline",
    # intrinsics from stills (OpenCV)
    "calibrate_intrinsics": ".intrinsics.pipeline",
    "IntrinsicsOptions": ".intrinsics.options",
    "IntrinsicsRun": ".intrinsics.pipeline",
    # what every job ends with
    "Verdict": ".verdict",
    # files, detections, cameras
    "load_camera": ".io.cameras",
    "write_camera": ".io.cameras",
    "CameraFile": ".io.cameras",
    "load_target": ".io.targets",
    "Target": ".io.targets",
    "open_source": ".io.video",
    "FrameSource": ".io.video",
    "read_gray_frames": ".io.video",
    "detect_video": ".detection.pipeline",
    "DetectOptions": ".detection.options",
    "DetectionResult": ".detection.result",
    "Observations": ".observations",
    # the C++ core's building blocks
    "CameraModel": "._core",
    "BSpline": "._core",
    "fit_bspline": "._core",
    "poses_at": "._core",
    "rotation_matrix_to_vector": "._core",
    "rotation_vector_to_matrix": "._core",
    "unwrap_rotation_vectors": "._core",
    # the installed version (its metadata lookup costs ~70 ms: not paid by detection workers)
    "__version__": "._version",
}

__all__ = sorted(_EXPORTS) + ["InputError"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rscalib' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # for type checkers and IDEs: the same names, imported eagerly
    from ._core import (
        BSpline,
        CameraModel,
        fit_bspline,
        poses_at,
        rotation_matrix_to_vector,
        rotation_vector_to_matrix,
        unwrap_rotation_vectors,
    )
    from .detection.options import DetectOptions
    from .detection.pipeline import detect_video
    from .detection.result import DetectionResult
    from .flicker.options import FlickerOptions
    from .flicker.pipeline import FlickerRun, estimate_line_delay_flicker
    from .intrinsics.options import IntrinsicsOptions
    from .intrinsics.pipeline import IntrinsicsRun, calibrate_intrinsics
    from .io.cameras import CameraFile, load_camera, write_camera
    from .io.targets import Target, load_target
    from .io.video import FrameSource, open_source, read_gray_frames
    from .linedelay.options import LineDelayOptions, LocalizeOptions
    from .linedelay.pipeline import LineDelayRun, LocalizeRun, calibrate_video, localize_video
    from .observations import Observations
    from .selfcalib.options import SelfCalibOptions, TrackOptions
    from .selfcalib.pipeline import SelfCalibRun, self_calibrate
    from .selfcalib.tracks import TrackSet, track_features
    from .verdict import Verdict
