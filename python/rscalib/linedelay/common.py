"""What both trajectory models (spline.py, linear.py) share: input checks, the PnP seed,
the choice of the pixel noise, the frame rate, when d counts as determined, the warnings every
solve can raise and the fields their result.json summaries have in common."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .._core import CameraModel
from ..errors import InputError
from ..observations import Observations
from .noise import estimate_pixel_sigma
from .pnp import FramePoses, per_frame_pnp

# Threads of a Ceres solve (both trajectory models).
SOLVER_THREADS = 2
# The line delay counts as determined when its standard deviation is below this fraction
# of the nominal full-frame delay 1 / (fps * rows) (a readout-time error of 5 % of a frame).
UNDETERMINED_STD_FRACTION = 0.05
# A detection noise the user may give: finer than any detector to a tenth of a typical target cell.
PIXEL_SIGMA_RANGE_PX = (1e-4, 100.0)


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


# Uniform knot segments at most per frame: finer segments are not determined by the detections
# (the motion prior alone sets them) and only cost time (5000 segments of a 45-frame video: 3 min).
MAX_SEGMENTS_PER_FRAME = 4


def check_segment_count(num_segments: Optional[int], frames: int) -> None:
    """InputError when a fixed number of uniform segments is not 1..MAX_SEGMENTS_PER_FRAME per frame."""
    if num_segments is None:
        return
    most = MAX_SEGMENTS_PER_FRAME * frames
    if not 1 <= int(num_segments) <= most:
        raise InputError(f"uniform knots: {num_segments} segments for {frames} frames; give 1 to {most} "
                         f"(at most {MAX_SEGMENTS_PER_FRAME} a frame)")


# Peak memory of a solve per observed corner (Jacobian blocks, Ceres' workspace, the normal equations),
# measured 2.2 kB with the grouped analytic cost and 4 kB with one autodiff block per corner (robust
# loss, --refine-intrinsics): docs/benchmarks.md "Peak memory against input size"; rounded up.
SOLVE_BYTES_PER_OBSERVATION = 6_000
SOLVE_BASE_BYTES = 300 * 2**20


def check_solve_memory(num_observations: int) -> None:
    """InputError (with the numbers) when a solve over ``num_observations`` corners would not fit in
    the memory available: memory grows linearly with the video, so a long one is refused up front."""
    from ..io.limits import check_memory

    check_memory(SOLVE_BASE_BYTES + SOLVE_BYTES_PER_OBSERVATION * int(num_observations),
                 f"the line-delay solve of {int(num_observations):,} observed corners (shorten the video with "
                 "--start/--end)")


def require_frame_times(timestamps_source: str, source) -> None:
    """InputError when the frames have no times (an image folder without timestamps.txt, a video
    with neither frame times nor a frame rate): the line delay and the trajectory are measured in
    time, and index-as-seconds would scale them (1 s per frame: 30x the line delay at 30 fps)."""
    if timestamps_source == "frame index":
        raise InputError(f"{source}: the frames have no times: put timestamps.txt in the image folder (one time "
                         "per image, in file-name order, in seconds), or give a video with frame times")


def initial_values(observations: Observations, camera: CameraModel, rows: Optional[int],
                   line_delay_s: Optional[float]) -> tuple[int, float, float, float]:
    """(rows, fps, nominal full-frame delay 1 / (fps rows), initial d) after check_inputs: d is the
    given line delay, else the nominal one (docs/formulation.md §7 step 2)."""
    rows = check_inputs(observations, camera, rows)
    fps = frame_rate_hz(observations)
    nominal_delay_s = 1.0 / (fps * rows)
    return rows, fps, nominal_delay_s, float(nominal_delay_s if line_delay_s is None else line_delay_s)


def seed_poses(observations: Observations, camera: CameraModel, warnings: list, min_frames: int,
               poses: Optional[FramePoses] = None) -> tuple[Observations, FramePoses]:
    """GS PnP per frame, the initial guess of both trajectory models: the observations of the
    frames with a pose, and those poses. Frames without a pose are left out with a warning.
    poses: per_frame_pnp(observations, camera) when already computed."""
    if poses is None:
        poses = per_frame_pnp(observations, camera)
    elif len(poses.ok) != observations.num_frames:
        raise ValueError("poses: one per frame of the observations")
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
        low, high = PIXEL_SIGMA_RANGE_PX
        if not low <= pixel_sigma <= high:  # 1e-300 px would claim a line delay known to 1e-300
            raise InputError(f"pixel_sigma must be in [{low:g}, {high:g}] px, not {pixel_sigma:g}")
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


# ------------------------------------------------------------------ --refine-intrinsics

# The default prior on the intrinsics when the calibration carries no covariance
# (docs/formulation.md §14): sigma_f = 2 % of f, sigma_c = 10 px, and per model the distortion's
# sigma (None: held at the camera's value when it is 0, the lens term the calibration did not fit).
DEFAULT_PRIOR_FOCAL_FRACTION = 0.02
DEFAULT_PRIOR_CENTRE_PX = 10.0
DEFAULT_PRIOR_DISTORTION_STD = {
    "pinhole-radtan": (0.05, 0.05, 0.002, 0.002, 0.05),       # k1, k2, p1, p2, k3 (k3 held when 0)
    "pinhole-equidistant": (0.02, 0.02, 0.02, 0.02),          # k1..k4 (k3, k4 held when 0)
    "civera-radial": (None, None),                            # k1, k2 held (mm^-2, mm^-4: no scale-free sigma)
}
# Distortion terms held at the camera's value when it is exactly 0 (not fitted by the calibration).
_HELD_WHEN_ZERO = {"pinhole-radtan": ("k3",), "pinhole-equidistant": ("k3", "k4"), "civera-radial": ()}


@dataclass
class IntrinsicsPrior:
    """The prior N(mean, covariance) on the camera's parameters (their layout, docs/conventions.md)
    for the joint refinement with the line delay (docs/formulation.md §14). fixed: indices held at
    the starting value; source: where the covariance came from ("default ..." or the file)."""

    names: list
    mean: np.ndarray
    covariance: np.ndarray
    fixed: tuple
    source: str

    @property
    def std(self) -> np.ndarray:
        """Prior standard deviation per parameter (0 for the held ones)."""
        std = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        std[list(self.fixed)] = 0.0
        return std

    def to_dict(self) -> dict:
        return {"source": self.source, "std": {n: float(s) for n, s in zip(self.names, self.std)},
                "held": [self.names[i] for i in self.fixed]}


def default_intrinsics_prior(camera: CameraModel) -> IntrinsicsPrior:
    """The documented default prior (no covariance given): sigma_f 2 % of f, sigma_c 10 px,
    the distortion's sigma of DEFAULT_PRIOR_DISTORTION_STD."""
    names = list(camera.param_names)
    mean = np.asarray(camera.params, dtype=np.float64)
    focal = ("f",) if camera.model == "civera-radial" else ("fx", "fy")
    std, fixed = np.zeros(len(names)), []
    distortion = iter(DEFAULT_PRIOR_DISTORTION_STD[camera.model])
    for i, name in enumerate(names):
        if name in focal:
            std[i] = DEFAULT_PRIOR_FOCAL_FRACTION * mean[i]
        elif name in ("cx", "cy"):
            std[i] = DEFAULT_PRIOR_CENTRE_PX
        else:
            sigma = next(distortion)
            if sigma is None or (name in _HELD_WHEN_ZERO[camera.model] and mean[i] == 0.0):
                fixed.append(i)
                sigma = 1.0
            std[i] = sigma
    held = [names[i] for i in fixed]
    source = (f"default (no covariance given): sigma_f {DEFAULT_PRIOR_FOCAL_FRACTION * 100:g} % of f, "
              f"sigma_c {DEFAULT_PRIOR_CENTRE_PX:g} px, distortion "
              + ", ".join(f"{n} {s:g}" for n, s, i in zip(names, std, range(len(names)))
                          if n not in focal + ("cx", "cy") and i not in fixed)
              + (f"; held: {', '.join(held)}" if held else ""))
    return IntrinsicsPrior(names, mean, np.diag(std ** 2), tuple(fixed), source)


def intrinsics_prior_from_std(camera: CameraModel, std, source: str) -> IntrinsicsPrior:
    """A prior from per-parameter standard deviations (a dict name -> sigma, or a sequence in the
    layout's order), e.g. the `std` of an `rscalib intrinsics` result.json; parameters with sigma 0
    (not fitted) are held. The mean is the camera's parameters."""
    names = list(camera.param_names)
    if isinstance(std, dict):
        missing = [n for n in names if n not in std]
        if missing:
            raise InputError(f"the intrinsics prior has no sigma for {', '.join(missing)}")
        std = [std[n] for n in names]
    std = np.asarray(std, dtype=np.float64).reshape(-1)
    if std.size != len(names):
        raise InputError(f"the intrinsics prior needs {len(names)} sigmas ({', '.join(names)}), not {std.size}")
    if not np.all(np.isfinite(std)) or np.any(std < 0):
        raise InputError("the intrinsics prior's sigmas must be finite and non-negative")
    fixed = tuple(int(i) for i in np.flatnonzero(std == 0))
    covariance = np.diag(np.where(std > 0, std, 1.0) ** 2)
    return IntrinsicsPrior(names, np.asarray(camera.params, dtype=np.float64), covariance, fixed, source)


def load_intrinsics_prior(path, camera: CameraModel) -> IntrinsicsPrior:
    """The prior of an `rscalib intrinsics` result.json (its per-parameter `std`; OpenCV gives no
    correlations, so the covariance is diagonal) around the camera's parameters."""
    import json
    from pathlib import Path

    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise InputError(f"cannot read the intrinsics prior {path}: {error}") from None
    if not isinstance(data, dict) or not isinstance(data.get("std"), dict):
        raise InputError(f"{path}: not an `rscalib intrinsics` result.json (no `std` of the parameters)")
    if data.get("model", camera.model) != camera.model:
        raise InputError(f"{path}: the prior is for a {data.get('model')} camera, the camera file is {camera.model}")
    return intrinsics_prior_from_std(camera, data["std"], f"standard deviations of {path}")
