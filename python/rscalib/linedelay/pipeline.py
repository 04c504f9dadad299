"""Video -> line-delay result: the one path of `rscalib linedelay` and `rscalib localize`, and of the
experiments in benchmarks/ (their `_exp_common.detect` is `detect` here).

    check the input files -> load the camera (rscalib.io.cameras) and the target (rscalib.io.targets)
    -> detect the target in every frame (rscalib.detection.pipeline.detect_video) -> check the sizes
    -> estimate the line delay with the chosen trajectory model (calibrate_video: spline, linear)
       or, with a known line delay, the trajectory (localize_video: rs-spline, gs-pnp)
    -> VideoResult, whose outputs linedelay/report.py writes (write_video_outputs).

Never prints: detection progress goes through `progress` (rscalib._progress: True for a bar on
stderr, or a callable (done, total)); `on_detection(detection)` is called once the detections are in,
before the solve; `on_round(RoundRecord)` after each knot-adaptation round of the spline.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Union

import numpy as np

from .._core import CameraModel
from .._progress import ProgressArg
from ..detection import probe
from ..detection.pipeline import detect_video
from ..detection.result import DetectionResult
from ..errors import InputError
from ..io.cameras import load_camera
from ..io.targets import Target, load_target
from ..io.video import open_source, video_bits_per_pixel
from . import selfcheck
from .common import (
    UNDETERMINED_STD_FRACTION,
    IntrinsicsPrior,
    check_solve_memory,
    frame_rate_hz,
    load_intrinsics_prior,
    require_frame_times,
)
from .guidance import capture_guidance
from .linear import LinearInterpResult, calibrate_line_delay_linear
from .pnp import PnpTrajectory, compare_with_pnp, per_frame_pnp, pnp_trajectory
from .readout import READOUTS, rotation_hint, time_window, to_top_down
from .spline import LineDelayResult, RoundRecord, calibrate_line_delay, joined_trajectory, localize

TRAJECTORY_MODELS = ("spline", "linear")    # calibrate_video: `rscalib linedelay --trajectory`
LOCALIZE_MODELS = ("rs-spline", "gs-pnp")   # localize_video: `rscalib localize --model`
PROBE_FIRST_DETECTED = 150   # detected frames the target-mismatch probe samples from

PathLike = Union[str, Path]
DetectionCallback = Optional[Callable[[DetectionResult], None]]
RoundCallback = Optional[Callable[[RoundRecord], None]]


@dataclass
class VideoResult:
    """What calibrate_video and localize_video return: the engine's result with the detections and
    the camera it came from.

    model: "spline" | "linear" (the line delay estimated) or "rs-spline" | "gs-pnp" (a trajectory with
    a known line delay); result: LineDelayResult (spline, rs-spline), LinearInterpResult (linear) or
    PnpTrajectory (gs-pnp), its warnings led by the detection's; inputs: the video, target and camera
    files; settings: the model's options as recorded in result.json; comparison: rs-spline only,
    against per-frame GS PnP (pnp.compare_with_pnp)."""

    model: str
    result: Union[LineDelayResult, LinearInterpResult, PnpTrajectory]
    camera: CameraModel
    detection: DetectionResult
    inputs: dict
    settings: dict = field(default_factory=dict)
    comparison: Optional[dict] = None
    guidance: Optional[dict] = None   # linedelay.guidance.capture_guidance (linedelay runs)

    @property
    def command(self) -> str:
        """The subcommand this run is: `linedelay` (the line delay estimated) or `localize`."""
        return "linedelay" if self.model in TRAJECTORY_MODELS else "localize"

    @property
    def determined(self) -> bool:
        """False when the data do not determine the line delay (a localization always is)."""
        return bool(getattr(self.result, "determined", True))

    @property
    def fps(self) -> float:
        """Frames per second from the median interval of the detected frames (0 for one frame)."""
        observations = self.detection.observations
        if observations.num_frames < 2:
            return 0.0
        return float(1.0 / np.median(np.diff(observations.frame_times_s)))

    def summary_extra(self) -> dict:
        """The result.json fields of the video and its detection, then the model's settings."""
        d = self.detection
        return {"video": self.inputs["video"], "detection_dropped": d.dropped, "frames_detected": d.frames_detected,
                "timestamps_from": d.timestamps, "detection_time_s": d.detect_time_s} | self.settings \
            | ({"guidance": self.guidance} if self.guidance is not None else {})


def check_files(video: PathLike, target: PathLike, camera: PathLike) -> None:
    """InputError (one line) when the video, the target file or the camera file is missing."""
    if not Path(video).exists():
        raise InputError(f"video not found: {video}")
    for name, path in (("target", target), ("camera", camera)):
        if not Path(path).is_file():
            raise InputError(f"{name} file not found: {path}")


def detect(video: PathLike, target: Union[Target, PathLike], camera: CameraModel, *,
           workers: Optional[int] = None, cache: bool = True, cache_dir: Optional[PathLike] = None,
           progress: ProgressArg = False) -> DetectionResult:
    """The target (a Target or its file) detected in every frame of the video (or image folder),
    with detect_video's cache; InputError when it is detected nowhere or the video's size is not
    the camera's."""
    if not isinstance(target, Target):
        target = load_target(target)
    detection = detect_video(video, target, workers=workers, cache=cache, cache_dir=cache_dir, progress=progress)
    check_target_matches(video, target, detection)
    if detection.observations.num_observations == 0:
        raise InputError(f"the target was not detected in any of the {detection.frames_total} frames "
                         "(wrong target file or size?)")
    if tuple(detection.image_size) != (camera.width, camera.height):
        raise InputError(f"the video is {detection.image_size[0]}x{detection.image_size[1]} but the camera file is "
                         f"{camera.width}x{camera.height}")
    return detection


def calibrate_video(video: PathLike, target: PathLike, camera: PathLike, *, model: str = "spline",
                    rows: Optional[int] = None, pixel_sigma: Optional[float] = None, robust_loss: str = "none",
                    max_rounds: int = 8, uniform_knots: Optional[int] = None, standardise_errors: bool = True,
                    use_motion_prior: bool = True, workers: Optional[int] = None, cache: bool = True,
                    cache_dir: Optional[PathLike] = None, progress: ProgressArg = False,
                    on_detection: DetectionCallback = None, on_round: RoundCallback = None,
                    start_s: Optional[float] = None, end_s: Optional[float] = None, readout: str = "auto",
                    self_check: bool = True, min_segment_s: Optional[float] = None,
                    noise_model: str = "frame", refine_intrinsics: bool = False,
                    intrinsics_prior: Union[None, PathLike, IntrinsicsPrior] = None) -> VideoResult:
    """The line delay of a video of a target (`rscalib linedelay`).

    video: file or image folder; target, camera: their files (target YAML; OpenCV or Kalibr camera).
    model: "spline" (calibrate_line_delay: the adaptive B-spline, Oth et al. 2013) or "linear"
    (calibrate_line_delay_linear: per-frame poses, Hedborg et al. 2012). uniform_knots,
    standardise_errors=False and use_motion_prior=False apply to the spline only. rows, pixel_sigma,
    robust_loss, max_rounds: as the engines'. workers, cache, cache_dir: detection (detect_video).
    start_s, end_s: use the frames in this time window only. readout: the sensor's readout direction
    (linedelay.readout.READOUTS) or "auto" (top-down, unless the video's rotation metadata says the
    picture was turned). self_check: also solve the two halves (linedelay.selfcheck; spline only) and
    widen sigma_d by its rule. min_segment_s, noise_model: calibrate_line_delay's. refine_intrinsics
    (spline, top-down readout): refine the camera jointly (calibrate_line_delay's), with the prior
    `intrinsics_prior` (an IntrinsicsPrior, or an `rscalib intrinsics` result.json whose `std` it uses;
    default: the documented default prior); the run's camera is then the refined one."""
    if model not in TRAJECTORY_MODELS:
        raise InputError(f"unknown trajectory model {model!r}; one of {', '.join(TRAJECTORY_MODELS)}")
    check_files(video, target, camera)
    if readout != "auto" and readout not in READOUTS:
        raise InputError(f"unknown readout direction {readout!r} (auto, {', '.join(READOUTS)})")
    if min_segment_s is not None and not min_segment_s > 0:
        raise InputError("the shortest knot segment must be positive")
    if model == "linear":
        spline_only = [name for name, used in (("uniform knots", uniform_knots is not None),
                                               ("unstandardised errors", not standardise_errors),
                                               ("no motion prior", not use_motion_prior)) if used]
        if spline_only:
            raise InputError(f"{', '.join(spline_only)}: only for the spline trajectory (the linear model has no "
                             "knots, no motion prior and unstandardised errors)")
    if refine_intrinsics and model != "spline":
        raise InputError("--refine-intrinsics: only with the spline trajectory")
    if intrinsics_prior is not None and not refine_intrinsics:
        raise InputError("an intrinsics prior is only used with --refine-intrinsics")
    camera_model = load_camera(camera).camera
    if refine_intrinsics and intrinsics_prior is not None and not isinstance(intrinsics_prior, IntrinsicsPrior):
        intrinsics_prior = load_intrinsics_prior(intrinsics_prior, camera_model)
    detection = _detections(video, target, camera_model, workers, cache, cache_dir, progress, on_detection)
    notes = list(detection.warnings)
    observations = time_window(detection.observations, start_s, end_s)
    if readout == "auto":
        hint = rotation_hint(video)
        readout = hint or "top-down"
        if hint:
            notes.append(f"the video's rotation metadata turns the picture, so the sensor rows are not the image "
                         f"rows: readout {hint} assumed (override with --readout)")
    if refine_intrinsics and readout != "top-down":
        raise InputError(f"--refine-intrinsics: only with a top-down readout for now (here {readout})")
    observations, solve_camera = to_top_down(observations, camera_model, readout)
    if model == "linear":
        result = calibrate_line_delay_linear(observations, solve_camera, rows, pixel_sigma=pixel_sigma,
                                             robust_loss=robust_loss)
        settings = {}
    else:
        knots = {} if uniform_knots is None else {"num_segments": uniform_knots, "adaptive_knots": False}
        options = dict(pixel_sigma=pixel_sigma, robust_loss=robust_loss, max_rounds=max_rounds,
                       standardise_errors=standardise_errors, use_motion_prior=use_motion_prior,
                       min_segment_s=min_segment_s, noise_model=noise_model, **knots)
        if refine_intrinsics:  # absent otherwise: the default path's calls are unchanged
            options |= {"refine_intrinsics": True, "intrinsics_prior": intrinsics_prior}
        # One PnP pass seeds both halves and the whole video (each frame's pose is its own: the halves'
        # are the same). The self-check's halves are solved first, side by side in two threads (the
        # solver releases the GIL), each from its own PnP start: independent estimates. The whole video
        # then starts from their trajectories, knots and d, and adapts on from there (a round or two
        # instead of five: docs/formulation.md §9). Bad input is left to calibrate_line_delay, whose
        # checks say what is wrong.
        poses = None
        if self_check and observations.num_frames >= 4 and _fits_in_memory(observations.num_observations):
            poses = per_frame_pnp(observations, solve_camera)
        solved_halves = {}

        def solve_half(half):
            shared = None if poses is None else poses.of_frames(observations.frame_times_s, half.frame_times_s)
            solved = calibrate_line_delay(half, solve_camera, rows, **options, frame_poses=shared)
            solved_halves[float(half.frame_times_s[0])] = solved
            return solved

        check = selfcheck.halves(observations, solve_half) if self_check else None
        start = _start_from_halves([solved_halves[t] for t in sorted(solved_halves)], options)
        result = calibrate_line_delay(observations, solve_camera, rows, progress=on_round, frame_poses=poses,
                                      **(options | start))
        if self_check:
            result.self_check = check
            result.line_delay_std_s = selfcheck.widened_std(result.line_delay_std_s, check)
            if check.get("widen", 1.0) > 1.0:
                result.warnings.append(f"the halves of the video differ by {check['z']:.1f} of their sigma: "
                                       f"sigma_d widened x{check['widen']:.2f} (self-check rule)")
                nominal = 1.0 / (frame_rate_hz(result.used_observations) * result.rows)
                if result.determined and not result.line_delay_std_s < UNDETERMINED_STD_FRACTION * nominal:
                    result.determined = False
                    result.warnings.append("with the widened error bar the line delay is not determined "
                                           f"(sigma_d >= {UNDETERMINED_STD_FRACTION * 100:g} % of a frame's readout)")
        settings = {"trajectory_model": "spline", "standardise_errors": standardise_errors,
                    "motion_prior": use_motion_prior, "adaptive_knots": uniform_knots is None,
                    "noise_model": noise_model}
        if refine_intrinsics:
            settings["refine_intrinsics"] = True
            camera_model = result.camera  # the camera files carry the refined intrinsics
    settings |= {"readout": readout, "start_s": start_s, "end_s": end_s}
    result.warnings[:0] = notes
    run = VideoResult(model, result, camera_model, detection, _inputs(video, target, camera), settings)
    try:
        run.guidance = capture_guidance(result, detection, video_bits_per_pixel(video))
    except Exception as error:  # noqa: BLE001 - advice must never cost the result
        run.guidance = {"advice": [], "error": f"{type(error).__name__}: {error}"}
    return run


def _start_from_halves(halves: list, options: dict) -> dict:
    """calibrate_line_delay's start for the whole video from its two solved halves: their joined
    trajectory and the inverse-variance mean of their d; {} (the PnP start) without both halves or
    with fixed knots."""
    if len(halves) != 2 or "num_segments" in options:
        return {}
    weights = [1.0 / h.line_delay_std_s ** 2 if h.determined and 0 < h.line_delay_std_s < math.inf else 0.0
               for h in halves]
    if not sum(weights) > 0:
        return {}
    d = sum(w * h.line_delay_s for w, h in zip(weights, halves)) / sum(weights)
    return {"start_trajectory": joined_trajectory([h.trajectory for h in halves]), "line_delay0_s": d}


def _fits_in_memory(num_observations: int) -> bool:
    try:
        check_solve_memory(num_observations)
    except InputError:
        return False
    return True


def localize_video(video: PathLike, target: PathLike, camera: PathLike, *, model: str = "rs-spline",
                   line_delay_s: Optional[float] = None, rows: Optional[int] = None,
                   pixel_sigma: Optional[float] = None, robust_loss: str = "none", workers: Optional[int] = None,
                   cache: bool = True, cache_dir: Optional[PathLike] = None, progress: ProgressArg = False,
                   on_detection: DetectionCallback = None, on_round: RoundCallback = None) -> VideoResult:
    """The camera trajectory of a video of a target with a known line delay (`rscalib localize`).

    line_delay_s: s/row (default: the camera file's). model: "rs-spline" (spline.localize, the
    continuous-time rolling-shutter trajectory, paper §5.1, compared with per-frame GS PnP) or
    "gs-pnp" (pnp.pnp_trajectory: per-frame global-shutter poses at mid-readout; the line delay
    may be unknown). Other arguments as calibrate_video's."""
    if model not in LOCALIZE_MODELS:
        raise InputError(f"unknown localization model {model!r}; one of {', '.join(LOCALIZE_MODELS)}")
    check_files(video, target, camera)
    camera_file = load_camera(camera)
    camera_model = camera_file.camera
    if line_delay_s is None:
        line_delay_s = camera_file.line_delay_s
    if line_delay_s is not None and not math.isfinite(line_delay_s):
        raise InputError("the line delay must be a finite number")
    if model == "rs-spline" and line_delay_s is None:
        raise InputError("no line delay: pass one (--line-delay, s/row) or a camera file that has one")
    detection = _detections(video, target, camera_model, workers, cache, cache_dir, progress, on_detection)
    inputs = _inputs(video, target, camera)
    if model == "gs-pnp":
        poses = pnp_trajectory(detection.observations, camera_model, rows, line_delay_s)
        poses.warnings[:0] = list(detection.warnings)
        return VideoResult(model, poses, camera_model, detection, inputs)
    result = localize(detection.observations, camera_model, rows, line_delay_s=line_delay_s,
                      pixel_sigma=pixel_sigma, robust_loss=robust_loss, progress=on_round)
    result.warnings[:0] = list(detection.warnings)
    return VideoResult(model, result, camera_model, detection, inputs,
                       comparison=compare_with_pnp(result, camera_model))


def check_target_matches(video: PathLike, target: Target, detection: DetectionResult) -> None:
    """InputError (one line, with what the frames seem to show) when a checkerboard target file does
    not match the filmed board: detected in few frames, or a larger board is visible in the frames
    where the declared one was found (detection.probe)."""
    if target.target_type != "checkerboard" or detection.frames_total == 0:
        return
    rows, cols = target.grid_shape
    few = detection.frames_detected < 0.5 * detection.frames_total
    # the board is the same in every frame: sample the first detected ones, so the probe decodes a
    # few seconds of video rather than all of it (it decodes up to its last sample)
    numbers = (np.arange(detection.frames_total) if few or detection.frames_detected == 0
               else detection.frame_numbers[:PROBE_FIRST_DETECTED])
    try:
        frames = probe.sample_frames(video, numbers, limit=4 if few else 3)
    except (InputError, OSError):
        return
    if not frames:
        return
    if few or probe.larger_board_visible(frames, cols, rows):
        seen = probe.largest_board(frames)
        if seen is not None and sorted(seen) == sorted((cols, rows)):
            return  # the declared board is there; it was just hard to detect
        if seen is None and not few:
            return
        raise InputError(probe.mismatch_message(target, seen))


def _detections(video, target, camera: CameraModel, workers, cache, cache_dir, progress,
                on_detection: DetectionCallback) -> DetectionResult:
    require_frame_times(open_source(video).timestamps_source, video)  # before the slow detection
    detection = detect(video, target, camera, workers=workers, cache=cache, cache_dir=cache_dir, progress=progress)
    require_frame_times(detection.timestamps, video)  # a video without times or frame rate
    if on_detection is not None:
        on_detection(detection)
    return detection


def _inputs(video, target, camera) -> dict:
    return {"video": str(video), "target": str(target), "camera": str(camera)}
