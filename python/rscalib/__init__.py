"""rscalib: camera calibration from video.

Rolling-shutter line-delay calibration (Oth et al. 2013), sequential self-calibration
(Civera et al. 2009) and the LED/flicker line-delay method, on a C++ core. Frames, time and
pixel conventions: docs/conventions.md; the package's layout: docs/architecture.md.

The names below are the public API. They are imported on first use, so ``import rscalib``
does not load the engines, OpenCV or matplotlib until they are needed.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__
from .errors import InputError

# public name -> module that defines it
_EXPORTS = {
    "BSpline": "._core",
    "CameraModel": "._core",
    "fit_bspline": "._core",
    "poses_at": "._core",
    "rotation_matrix_to_vector": "._core",
    "rotation_vector_to_matrix": "._core",
    "unwrap_rotation_vectors": "._core",
    "Observations": ".observations",
    "open_source": ".io.video",
    "FrameSource": ".io.video",
    "load_target": ".io.targets",
    "Target": ".io.targets",
    "load_camera": ".io.cameras",
    "write_camera": ".io.cameras",
    "CameraFile": ".io.cameras",
    "detect_video": ".detection.pipeline",
    "DetectOptions": ".detection.detectors",
    "DetectionResult": ".detection.result",
    "calibrate_line_delay": ".linedelay.spline",
    "localize": ".linedelay.spline",
    "LineDelayResult": ".linedelay.spline",
    "calibrate_line_delay_linear": ".linedelay.linear",
    "LinearInterpResult": ".linedelay.linear",
    "self_calibrate": ".selfcalib.calibrate",
    "SelfCalibResult": ".selfcalib.calibrate",
    "estimate_line_delay_flicker": ".flicker.estimate",
    "FlickerResult": ".flicker.estimate",
    "calibrate_intrinsics": ".intrinsics",
    "IntrinsicsResult": ".intrinsics",
}

__all__ = sorted(_EXPORTS) + ["InputError", "__version__"]


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
    from .detection.detectors import DetectOptions
    from .detection.pipeline import detect_video
    from .detection.result import DetectionResult
    from .flicker.estimate import FlickerResult, estimate_line_delay_flicker
    from .intrinsics import IntrinsicsResult, calibrate_intrinsics
    from .io.cameras import CameraFile, load_camera, write_camera
    from .io.targets import Target, load_target
    from .io.video import FrameSource, open_source
    from .linedelay.linear import LinearInterpResult, calibrate_line_delay_linear
    from .linedelay.spline import LineDelayResult, calibrate_line_delay, localize
    from .observations import Observations
    from .selfcalib.calibrate import SelfCalibResult, self_calibrate
