"""What both trajectory models (spline.py, linear.py) share: input checks, the PnP seed,
the choice of the pixel noise, the frame rate and when d counts as determined."""
from __future__ import annotations

from typing import Optional

import numpy as np

from .._core import CameraModel
from ..errors import InputError
from ..observations import Observations
from .noise import estimate_pixel_sigma
from .pnp import FramePoses, per_frame_pnp

# The line delay counts as determined when its standard deviation is below this fraction
# of the nominal full-frame delay 1 / (fps * rows) (a readout-time error of 5 % of a frame).
UNDETERMINED_STD_FRACTION = 0.05


def check_inputs(observations: Observations, camera: CameraModel, rows: Optional[int]):
    """The rows read out (default: image height), after checking the inputs both trajectory models share."""
    if not isinstance(observations, Observations):
        raise InputError("observations must be an rscalib.Observations")
    if not isinstance(camera, CameraModel):
        raise InputError("camera must be an rscalib.CameraModel")
    rows = int(rows if rows is not None else observations.image_size[1])
    if rows <= 0:
        raise InputError("rows must be positive")
    if (camera.width, camera.height) != tuple(observations.image_size):
        raise InputError(f"camera is {camera.width}x{camera.height} but the observations are "
                         f"{observations.image_size[0]}x{observations.image_size[1]}")
    if observations.num_frames < 4 or observations.num_observations < 24:
        raise InputError("too few observations: need at least 4 frames with target points")
    return rows


def seed_poses(observations: Observations, camera: CameraModel, warnings: list, min_frames: int
               ) -> tuple[Observations, FramePoses]:
    """GS PnP per frame, the initial guess of both trajectory models: the observations of the
    frames with a pose, and those poses. Frames without a pose are left out with a warning."""
    poses = per_frame_pnp(observations, camera)
    frames_total = observations.num_frames
    used = observations.subset_frames(poses.ok)
    used_poses = FramePoses(poses.ok[poses.ok], poses.rotation_vector[poses.ok],
                            poses.translation[poses.ok], poses.rms_px[poses.ok])
    if frames_total - used.num_frames > 0:
        warnings.append(f"{frames_total - used.num_frames} of {frames_total} frames had no PnP pose "
                        "(too few points) and were left out")
    if used.num_frames < min_frames:
        raise InputError(f"only {used.num_frames} frames have enough target points for a pose")
    return used, used_poses


def choose_pixel_sigma(used: Observations, pixel_sigma: Optional[float]) -> tuple[float, str]:
    """The detection noise σ (px) and where it came from: the user's, else estimated from the
    target grid (rscalib.linedelay.noise), else 0.5 px to be replaced by the residual RMS ("residuals")."""
    if pixel_sigma is not None:
        if not pixel_sigma > 0:
            raise InputError("pixel_sigma must be positive")
        return float(pixel_sigma), "user"
    sigma = estimate_pixel_sigma(used)
    if sigma is None:
        return 0.5, "residuals"
    return sigma, "grid third differences"


def frame_rate_hz(observations: Observations) -> float:
    """Frames per second from the median frame interval; InputError if it cannot be told."""
    intervals = np.diff(observations.frame_times_s)
    if len(intervals) == 0 or not np.median(intervals) > 0:
        raise InputError("cannot determine the frame rate from the timestamps")
    return float(1.0 / np.median(intervals))
