"""rscalib: camera calibration from video.

Rolling-shutter line-delay calibration (Oth et al. 2013) and sequential self-calibration
(Civera et al. 2009) on a C++ core. Frames, time and pixel conventions: docs/conventions.md.
"""
from importlib.metadata import PackageNotFoundError, version as _version

from ._core import (
    BSpline,
    CameraModel,
    fit_bspline,
    poses_at,
    rotation_matrix_to_vector,
    rotation_vector_to_matrix,
    unwrap_rotation_vectors,
)
from .errors import InputError
from .flicker import FlickerResult, estimate_line_delay_flicker
from .linear_interp import LinearInterpResult, calibrate_line_delay_linear
from .linedelay import LineDelayResult, calibrate_line_delay, localize
from .observations import Observations
from .selfcalib import SelfCalibResult, self_calibrate

try:
    __version__ = _version("rscalib")
except PackageNotFoundError:  # running from a source tree without metadata
    from ._core import __version__

__all__ = [
    "BSpline",
    "CameraModel",
    "FlickerResult",
    "InputError",
    "LinearInterpResult",
    "LineDelayResult",
    "Observations",
    "SelfCalibResult",
    "calibrate_line_delay",
    "calibrate_line_delay_linear",
    "estimate_line_delay_flicker",
    "localize",
    "fit_bspline",
    "poses_at",
    "rotation_matrix_to_vector",
    "rotation_vector_to_matrix",
    "self_calibrate",
    "unwrap_rotation_vectors",
    "__version__",
]
