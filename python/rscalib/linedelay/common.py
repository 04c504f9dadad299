"""What both trajectory models (spline.py, linear.py) share: input checks, the PnP seed,
the choice of the pixel noise, the frame rate, when d counts as determined, the warnings every
solve can raise and the fields their result.json summaries have in common."""
from __future__ import annotations

import math
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


def initial_values(observations: Observations, camera: CameraModel, rows: Optional[int],
                   line_delay_s: Optional[float]) -> tuple[int, float, float, float]:
    """(rows, fps, nominal full-frame delay 1 / (fps rows), initial d) after check_inputs: d is the
    given line delay, else the nominal one (docs/formulation.md §7 step 2)."""
    rows = check_inputs(observations, camera, rows)
    fps = frame_rate_hz(observations)
    nominal_delay_s = 1.0 / (fps * rows)
    return rows, fps, nominal_delay_s, float(nominal_delay_s if line_delay_s is None else line_delay_s)


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


def assess_noise_and_determinacy(summary, sigma: float, sigma_source: str, nominal_delay_s: float,
                                 warnings: list, *, estimate: bool = True,
                                 std_s: Optional[float] = None) -> tuple[float, float, bool]:
    """(J/2N, pixel sigma, determined) of a solver summary (`_core.RsSolveSummary` or
    `LinearInterpSummary`), appending the warnings.

    The pixel sigma is replaced by the residual RMS when the grid gave no estimate (then J/2N carries
    no information, docs/formulation.md §8). d counts as determined when its covariance is full rank
    and sigma_d < UNDETERMINED_STD_FRACTION of the nominal full-frame delay (§9); with a known d
    (estimate=False) it is not judged. std_s: sigma_d to judge (default the solver's)."""
    cost = summary.measurement_cost / max(1, 2 * summary.num_error_terms)
    if sigma_source == "residuals":
        sigma = summary.rms_px
        warnings.append("pixel sigma could not be estimated from the target grid; using the residual RMS "
                        f"({sigma:.3f} px), so J/2N carries no information")
    determined = True
    std = summary.line_delay_std_s if std_s is None else std_s
    if estimate and not (summary.covariance_ok and math.isfinite(std)
                         and std < UNDETERMINED_STD_FRACTION * nominal_delay_s):
        determined = False
        warnings.append("the line delay is not determined by this data (too little or the wrong kind of "
                        f"motion): sigma_d = {std * 1e6 if math.isfinite(std) else float('inf'):.3g} us; "
                        "move the camera faster, mostly rotating about its x and y axes")
    return cost, sigma, determined


def solve_warnings(summary, warnings: list) -> None:
    """The warnings of the last solve of either model: unprojectable observations, no convergence."""
    if summary.unprojectable:
        warnings.append(f"{summary.unprojectable} observations could not be projected and were ignored")
    if not summary.converged:
        warnings.append(f"the final solve did not report convergence: {summary.message}")


def summary_fields(result, knots: int, **model_fields) -> dict:
    """The JSON-ready fields both results have (LineDelayResult, LinearInterpResult), in their
    result.json order; `model_fields` stand between the trajectory size and the fit statistics."""
    std = result.line_delay_std_s
    return {
        "line_delay_s": result.line_delay_s,
        "line_delay_std_s": std if math.isfinite(std) else None,
        "readout_time_s": result.readout_time_s,
        "rows": result.rows,
        "frames_total": result.frames_total,
        "frames_used": result.frames_used,
        "observations": result.observations,
        "knots": int(knots),
        "segments": result.num_segments,
        **model_fields,
        "rms_px": result.rms_px,
        "normalised_cost": result.normalised_cost,
        "pixel_sigma": result.pixel_sigma,
        "pixel_sigma_source": result.pixel_sigma_source,
        "converged": result.converged,
        "determined": result.determined,
        "warnings": list(result.warnings),
        "initial_line_delay_s": result.initial_line_delay_s,
        "solve_time_s": result.solve_time_s,
    }
