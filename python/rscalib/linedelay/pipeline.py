"""The front door of the line-delay job: a video of a target -> a line delay with its verdict, and
the files. `rscalib linedelay`, `rscalib localize`, `rscalib demo`, `rscalib batch` and the experiments
all run :func:`calibrate_video` / :func:`localize_video`; ``rscalib.calibrate_video`` is this one.

    the files -> camera (rscalib.io.cameras) and target (rscalib.io.targets) -> the target detected
    in every frame (rscalib.detection.pipeline.detect_video; or detections already made) -> the frames
    of the --start/--end window, turned to a top-to-bottom readout (readout.py) -> the two halves
    solved apart and the whole video from them (spline.py, selfcheck.py; or the linear baseline,
    linear.py) -> the advice on filming (guidance.py) -> the verdict (judge.py)
    -> LineDelayRun, whose .write(out_dir) writes what the CLI writes (report.py).

Never prints: detection progress goes through `progress` (rscalib._progress: True for a bar on
stderr, or a callable (done, total)); `on_detection(detection)` is called once the detections are in,
before the solve; `on_round(RoundRecord)` after each knot-adaptation round of the spline.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Optional, Union

import numpy as np

from .. import checks
from .._core import CameraModel
from .._progress import ProgressArg
from ..detection import probe
from ..detection.pipeline import detect_video
from ..detection.result import DetectionResult
from ..errors import InputError
from ..io.cameras import CameraFile, load_camera
from ..io.targets import Target, load_target
from ..io.video import open_source, video_bits_per_pixel
from ..observations import Observations
from ..readout import AUTO, TOP_TO_BOTTOM
from ..verdict import TRUSTED, Verdict
from . import selfcheck
from .common import (
    IntrinsicsPrior,
    check_solve_memory,
    frame_rate_hz,
    load_intrinsics_prior,
    require_frame_times,
)
from .guidance import capture_guidance
from .judge import Diagnosis, diagnose, residual_structure
from .linear import LinearInterpResult, calibrate_line_delay_linear
from .options import LineDelayOptions, LocalizeOptions
from .pnp import FramePoses, PnpTrajectory, PosesAlongside, compare_with_pnp, per_frame_pnp, pnp_trajectory
from .readout import rotation_hint, time_window, to_top_to_bottom
from .spline import (
    LineDelayResult,
    RoundRecord,
    calibrate_line_delay,
    joined_trajectory,
    localize,
    refit_with_intrinsics,
)

PROBE_FIRST_DETECTED = 150   # detected frames the target-mismatch probe samples from
# The probe of d that starts the self-check's halves (_probe_line_delay): the middle 2 s of a video of
# at least 8 s, fixed knots every 2 frames; its d is used when inside (0, 1.5 x the nominal delay].
PROBE_WINDOW_S, PROBE_MIN_VIDEO_S, PROBE_FRAMES_PER_SEGMENT, PROBE_MAX_NOMINAL = 2.0, 8.0, 2, 1.5
# The camera check's solver steps from the solution (the first is damped): 3 gave the converged shift
# to 0.2 % on the 60 s render with f off by 3 and 6 %, 2 to 4-26 % (docs/benchmarks.md, issue 31).
CAMERA_CHECK_STEPS = 3

PathLike = Union[str, Path]
DetectionCallback = Optional[Callable[[DetectionResult], None]]
RoundCallback = Optional[Callable[[RoundRecord], None]]
VideoInput = Union[PathLike, DetectionResult, Observations]
CameraInput = Union[PathLike, CameraModel, CameraFile]


@dataclass
class LineDelayRun:
    """What :func:`calibrate_video` returns: the line delay with its verdict, the estimate behind it,
    the detections and camera it came from, and :meth:`write` for the files `rscalib linedelay` writes.

    result: the engine's estimate (LineDelayResult: the spline, with its self-check; LinearInterpResult:
    the linear baseline), its warnings led by the detection's; camera: the camera of the files (the
    refined one with refine_intrinsics); readout: the direction used; inputs: the files it read."""

    result: Union[LineDelayResult, LinearInterpResult]
    verdict: Verdict
    camera: CameraModel
    detection: DetectionResult
    options: LineDelayOptions
    readout: str
    inputs: dict
    guidance: dict = field(default_factory=dict)
    diagnosis: Optional[Diagnosis] = None   # the verdict's findings, first cause first (judge.diagnose)

    command = "linedelay"

    @property
    def line_delay_s(self) -> Optional[float]:
        """The line delay in s/row, None when the video does not determine it (no number is claimed)."""
        return self.verdict.value

    @property
    def line_delay_std_s(self) -> Optional[float]:
        return self.verdict.std

    @property
    def readout_time_s(self) -> Optional[float]:
        """line_delay_s x rows read out (None when not determined)."""
        return None if self.line_delay_s is None else self.line_delay_s * self.result.rows

    @property
    def model(self) -> str:
        return "linear" if isinstance(self.result, LinearInterpResult) else "spline"

    @property
    def fps(self) -> float:
        return _fps(self.detection)

    @property
    def settings(self) -> dict:
        """The options that shaped the estimate, as result.json records them."""
        o = self.options
        common = {"readout": self.readout, "start_s": o.start_s, "end_s": o.end_s}
        if self.model == "linear":
            return {"baseline": "linear"} | common
        return {"trajectory_model": "spline", "standardise_errors": o.standardise_errors,
                "motion_prior": o.motion_prior, "adaptive_knots": o.uniform_knots is None} \
            | ({"refine_intrinsics": True} if o.refine_intrinsics else {}) | common

    def summary(self) -> dict:
        """The result.json fields (without the files and the provenance): the estimate's, the
        detection's, the settings, the guidance and the verdict. Not determined: line_delay_s,
        line_delay_std_s and readout_time_s are null, the unclaimed estimate under not_claimed."""
        from .report import run_summary

        return run_summary(self)

    def write(self, out_dir, *, report: bool = True, lens_profile: Optional[dict] = None,
              on_result: Optional[Callable[[dict], None]] = None, command: Optional[str] = None) -> dict:
        """Write what `rscalib linedelay` writes into out_dir (as one set: result.json last) and
        return the result.json dict: result.json, trajectory.csv and trajectory_tum.txt, corners.vnl,
        camera files for other tools (OpenCV, Kalibr, Gyroflow, ROS, mrcal, COLMAP) with the line delay
        — none when it is not determined —, and unless report=False the plots and report.html.
        lens_profile: camera_brand, camera_model, lens_model for the Gyroflow profile; on_result(summary)
        is called once result.json is written, before the plots are drawn."""
        from .report import write_line_delay_run

        return write_line_delay_run(self, out_dir, report=report, gyroflow=lens_profile, on_result=on_result,
                                    command=command or self.command)


@dataclass
class LocalizeRun:
    """What :func:`localize_video` returns: a trajectory with a known line delay (rs-spline:
    LineDelayResult, with `comparison` against per-frame GS PnP; gs-pnp: PnpTrajectory)."""

    result: Union[LineDelayResult, PnpTrajectory]
    verdict: Verdict
    camera: CameraModel
    detection: DetectionResult
    options: LocalizeOptions
    inputs: dict
    comparison: Optional[dict] = None

    command = "localize"

    @property
    def model(self) -> str:
        return self.options.model

    @property
    def fps(self) -> float:
        return _fps(self.detection)

    def write(self, out_dir, *, command: Optional[str] = None) -> dict:
        """result.json, trajectory.csv and trajectory_tum.txt (and trajectory.png for rs-spline)."""
        from .report import write_localize_run

        return write_localize_run(self, out_dir, command=command or self.command)


def _fps(detection: DetectionResult) -> float:
    """Frames per second from the median interval of the detected frames (0 for one frame)."""
    observations = detection.observations
    if observations.num_frames < 2:
        return 0.0
    return float(1.0 / np.median(np.diff(observations.frame_times_s)))


def calibrate_video(video: VideoInput, target: Union[None, PathLike, Target] = None,
                    camera: Optional[CameraInput] = None, options: Optional[LineDelayOptions] = None, *,
                    progress: ProgressArg = False, on_detection: DetectionCallback = None,
                    on_round: RoundCallback = None) -> LineDelayRun:
    """The line delay of a video of a target, with its verdict (`rscalib linedelay`).

    video: a video file or image folder (then `target` is its target file or Target), or detections
    already made (a DetectionResult, or rscalib.Observations with their frame times: the target is then
    not needed); camera: its file (OpenCV, Kalibr, ROS, mrcal, COLMAP, Gyroflow) or a CameraModel;
    options: LineDelayOptions (None: the method's defaults). The result's .line_delay_s, .verdict and
    .write(out_dir) are what the command prints and writes."""
    options = LineDelayOptions() if options is None else options
    _check_arguments(video, target, camera, options, LineDelayOptions, progress, on_detection, on_round)
    camera_model, camera_path = _camera(camera)
    # the spline's per-frame PnP start, computed while the workers detect (the linear baseline has none)
    poses = PosesAlongside(camera_model) if options.baseline is None and options.self_check else None
    detection, video_path = _detections(video, target, camera_model, options, progress, on_detection, poses)
    notes = list(detection.warnings)
    observations = time_window(detection.observations, options.start_s, options.end_s)
    readout = options.readout
    if readout == AUTO:
        hint = rotation_hint(video_path) if video_path is not None else None
        readout = hint or TOP_TO_BOTTOM
        if hint:
            notes.append(f"the video's rotation metadata turns the picture, so the sensor rows are not the image "
                         f"rows: readout {hint} assumed (override with --readout)")
    if options.refine_intrinsics and readout != TOP_TO_BOTTOM:
        raise InputError(f"--refine-intrinsics: only with a top-to-bottom readout for now (here {readout})")
    prior = options.intrinsics_prior
    if options.refine_intrinsics and prior is not None and not isinstance(prior, IntrinsicsPrior):
        options = replace(options, intrinsics_prior=load_intrinsics_prior(prior, camera_model))
    observations, solve_camera = to_top_to_bottom(observations, camera_model, readout)
    if options.baseline == "linear":
        result = calibrate_line_delay_linear(observations, solve_camera, options)
    else:
        # poses of the frames as detected: those of the top-to-bottom problem only when it is the video's own
        result = _solve_with_self_check(observations, solve_camera, options, on_round,
                                        poses.poses_of(observations) if poses and readout == TOP_TO_BOTTOM else None)
        if options.refine_intrinsics:
            camera_model = result.camera  # the camera files carry the refined intrinsics
    result.warnings[:0] = notes
    inputs = {"video": None if video_path is None else str(video_path),
              "target": None if target is None or isinstance(target, Target) else str(target),
              "camera": None if camera_path is None else str(camera_path)}
    camera_check = None
    if options.baseline is None and not options.refine_intrinsics and readout == TOP_TO_BOTTOM:
        camera_check = check_camera(solve_camera, options, result)
    bits_per_pixel = video_bits_per_pixel(video_path) if video_path else None
    try:
        guidance = capture_guidance(result, detection, bits_per_pixel)
    except Exception as error:  # noqa: BLE001 - advice must never cost the result
        guidance = {"advice": [], "error": f"{type(error).__name__}: {error}"}
    diagnosis = diagnose(result, frame_rate_hz=_frame_rate_or_none(result), bits_per_pixel=bits_per_pixel,
                         camera_check=camera_check)
    return LineDelayRun(result, diagnosis.verdict, camera_model, detection, options, readout, inputs, guidance,
                        diagnosis)


def check_camera(camera: CameraModel, options: LineDelayOptions, result: LineDelayResult) -> Optional[dict]:
    """How far d moves when the intrinsics are freed under their prior from the solution (formulation
    §17), in the data's sigma: whether the camera file matters at this video's precision. A camera file
    a few per cent off can bend d by several sigma without a trace in the residuals (J/2N, the halves,
    the image field all normal: the fresh verdict set 3900), so it runs on every determined estimate.
    A few solver steps from the solution, on its knots and error weights, give the refined d to
    0.2 % of the shift (a full re-solve with knot adaptation cost 3-5x as much: docs/benchmarks.md).
    None when d is not determined (nothing is solved)."""
    if not result.determined:
        return None
    field = residual_structure(result)["image_field"]
    try:
        refined_s, cost, refined_params = refit_with_intrinsics(result, camera, options,
                                                                max_iterations=CAMERA_CHECK_STEPS)
    except InputError as error:
        return {"error": str(error)}
    # the data's sigma: before the halves' widening (with the noise model's inflation, §8)
    data_std = result.line_delay_std_s / max(1.0, float((result.self_check or {}).get("widen") or 1.0))
    return {"image_field": field, "line_delay_s": refined_s, "normalised_cost": cost,
            "shift_sigma": float((refined_s - result.line_delay_s) / data_std) if data_std > 0 else None,
            **camera_change(camera, refined_params)}


def camera_change(camera: CameraModel, refined_params) -> dict:
    """How far the intrinsics the board's video prefers are from the camera file's (the camera check's
    refit), in the units a user acts on: the focal length's relative change (the larger of fx, fy), the
    principal point's move in pixels and the largest image displacement of the distortion alone (the
    file's focal length and centre with the refined distortion, over a grid of the image). A camera file
    a few per cent off can leave d unmoved and still be wrong for every other use (the verdict's caveat)."""
    names = list(camera.param_names)
    old = np.asarray(camera.params, dtype=np.float64)
    new = np.asarray(refined_params, dtype=np.float64).reshape(-1)
    if new.shape != old.shape or not np.all(np.isfinite(new)):
        return {}
    out = {"param_names": names, "params_file": old.tolist(), "params_refined": new.tolist()}
    focal = [i for i, n in enumerate(names) if n in ("f", "fx", "fy")]
    if focal:
        changes = [(new[i] - old[i]) / old[i] for i in focal]
        out["focal_change_fraction"] = float(max(changes, key=abs))
    centre = [names.index(n) for n in ("cx", "cy") if n in names]
    if len(centre) == 2:
        out["centre_change_px"] = float(np.hypot(*(new[centre] - old[centre])))
    distortion = [i for i, n in enumerate(names) if n not in ("f", "fx", "fy", "cx", "cy")]
    if distortion:
        mixed = old.copy()
        mixed[distortion] = new[distortion]
        try:
            other = CameraModel(camera.model, mixed, camera.width, camera.height,
                                np.asarray(camera.pixel_size_mm, dtype=np.float64))
            u, v = np.meshgrid(np.linspace(0, camera.width - 1, 9), np.linspace(0, camera.height - 1, 7))
            uv = np.c_[u.ravel(), v.ravel()]
            moved = other.project(camera.unproject(uv))
            step = np.linalg.norm(moved - uv, axis=1)
            out["distortion_change_px"] = float(np.max(step[np.isfinite(step)])) if np.isfinite(step).any() else None
        except (InputError, ValueError, RuntimeError):
            out["distortion_change_px"] = None
    return out


def _frame_rate_or_none(result) -> Optional[float]:
    try:
        return frame_rate_hz(result.used_observations)
    except InputError:
        return None


def _solve_with_self_check(observations: Observations, camera: CameraModel, options: LineDelayOptions,
                           on_round: RoundCallback, poses: Optional[FramePoses] = None) -> LineDelayResult:
    """The spline over the whole video, started from its two halves solved apart (the self-check);
    poses: the frames' per-frame PnP when already computed (PosesAlongside)."""
    # One PnP pass seeds both halves and the whole video (each frame's pose is its own: the halves'
    # are the same). The self-check's halves are solved first, side by side in two threads (the
    # solver releases the GIL), each from its own PnP start: independent estimates. The whole video
    # then starts from their trajectories, knots and d, and adapts on from there (a round or two
    # instead of five: docs/formulation.md §9). Bad input is left to calibrate_line_delay, whose
    # checks say what is wrong.
    if not (options.self_check and observations.num_frames >= 4 and _fits_in_memory(observations.num_observations)):
        poses = None
    elif poses is None:
        poses = per_frame_pnp(observations, camera)
    solved_halves = {}
    line_delay0_s = _probe_line_delay(observations, camera, options, poses) if poses is not None else None

    def solve_half(half):
        shared = None if poses is None else poses.of_frames(observations.frame_times_s, half.frame_times_s)
        solved = calibrate_line_delay(half, camera, options, frame_poses=shared, line_delay0_s=line_delay0_s,
                                      solver_threads=1)
        solved_halves[float(half.frame_times_s[0])] = solved
        return solved

    check = selfcheck.halves(observations, solve_half) if options.self_check else None
    start = _start_from_halves([solved_halves[t] for t in sorted(solved_halves)], options)
    result = calibrate_line_delay(observations, camera, options, progress=on_round, frame_poses=poses, **start)
    if check is not None:
        result.self_check = check
        result.line_delay_std_s = selfcheck.widened_std(result.line_delay_std_s, check)
        # Halves that agree (z <= 3) are no warning: their widening (max(1, z)) is in the self-check
        # block and the report. Whether d is determined stays the data's question (sigma_d before the
        # widening, docs/formulation.md §17): a widened sigma is a matter of trust, said by the verdict.
    return result


def detect(video: PathLike, target: Union[Target, PathLike], camera: CameraModel,
           options: Union[None, LineDelayOptions, LocalizeOptions] = None, *,
           progress: ProgressArg = False, poses: Optional[PosesAlongside] = None) -> DetectionResult:
    """The target (a Target or its file) detected in every frame of the video (or image folder),
    with detect_video's cache (options.detection); InputError when it is detected
    nowhere or the video's size is not the camera's. poses: per-frame PnP of the frames detected,
    computed meanwhile."""
    options = options or LineDelayOptions()
    if not isinstance(target, Target):
        target = load_target(target)
    # the early check of the target file runs while the detection workers start
    early = []
    detection = detect_video(video, target, options.detection, progress=progress,
                             alongside=lambda: early.append(check_target_early(video, target)),
                             on_frames=None if poses is None else poses.of_target(target.points_m))
    if not (early and early[0]):
        check_target_matches(video, target, detection)
    if detection.observations.num_observations == 0:
        raise InputError(f"the target was not detected in any of the {detection.frames_total} frames "
                         "(wrong target file or size?)")
    if tuple(detection.image_size) != (camera.width, camera.height):
        raise InputError(f"the video is {detection.image_size[0]}x{detection.image_size[1]} but the camera file is "
                         f"{camera.width}x{camera.height}")
    return detection


def _probe_line_delay(observations: Observations, camera: CameraModel, options: LineDelayOptions,
                      poses) -> Optional[float]:
    """The halves' start for d: one solve of the middle PROBE_WINDOW_S of the video on fixed knots (one
    per PROBE_FRAMES_PER_SEGMENT frames), or None (the nominal start) when the video is short, the
    knots are the user's, or the probe does not determine d inside (0, PROBE_MAX_NOMINAL x nominal].
    From d's nominal start (the full frame interval) the halves' first round took 10 solver steps to
    bring a hand-held video's d to half of it; from the probe's, 6 (docs/formulation.md §7)."""
    times = observations.frame_times_s
    if options.uniform_knots is not None or times[-1] - times[0] < PROBE_MIN_VIDEO_S:
        return None
    keep = np.abs(times - 0.5 * (times[0] + times[-1])) <= 0.5 * PROBE_WINDOW_S
    part = observations.subset_frames(keep)
    segments = max(1, part.num_frames // PROBE_FRAMES_PER_SEGMENT)
    probe_options = replace(options, uniform_knots=segments, max_rounds=1, self_check=False, refine_intrinsics=False)
    try:
        probe = calibrate_line_delay(part, camera, probe_options,
                                     frame_poses=poses.of_frames(times, part.frame_times_s))
    except InputError:
        return None
    nominal_s = 1.0 / (frame_rate_hz(part) * probe.rows)
    if probe.determined and 0.0 < probe.line_delay_s <= PROBE_MAX_NOMINAL * nominal_s:
        return float(probe.line_delay_s)
    return None


def _start_from_halves(halves: list, options: LineDelayOptions) -> dict:
    """calibrate_line_delay's start for the whole video from its two solved halves: their joined
    trajectory, the inverse-variance mean of their d and the mean of their noise models' fixed-pattern
    parts; {} (the PnP start) without both halves or with fixed knots."""
    if len(halves) != 2 or options.uniform_knots is not None:
        return {}
    weights = [1.0 / h.line_delay_std_s ** 2 if h.determined and 0 < h.line_delay_std_s < math.inf else 0.0
               for h in halves]
    if not sum(weights) > 0:
        return {}
    d = sum(w * h.line_delay_s for w, h in zip(weights, halves)) / sum(weights)
    start = {"start_trajectory": joined_trajectory([h.trajectory for h in halves]), "line_delay0_s": d}
    fixed = [h.noise.get("fixed_pattern_px") for h in halves]
    if all(f is not None and math.isfinite(f) for f in fixed):
        start["start_fixed_pattern_px"] = float(np.mean(fixed))
    return start


def _fits_in_memory(num_observations: int) -> bool:
    try:
        check_solve_memory(num_observations)
    except InputError:
        return False
    return True


def localize_video(video: VideoInput, target: Union[None, PathLike, Target] = None,
                   camera: Optional[CameraInput] = None, line_delay_s: Optional[float] = None,
                   options: Optional[LocalizeOptions] = None, *, progress: ProgressArg = False,
                   on_detection: DetectionCallback = None, on_round: RoundCallback = None) -> LocalizeRun:
    """The camera trajectory of a video of a target with a known line delay (`rscalib localize`).

    line_delay_s: s/row (default: the camera file's). options.model: "rs-spline" (spline.localize, the
    continuous-time rolling-shutter trajectory, paper §5.1, compared with per-frame GS PnP) or
    "gs-pnp" (pnp.pnp_trajectory: per-frame global-shutter poses at mid-readout; the line delay
    may be unknown). Other arguments as calibrate_video's."""
    options = LocalizeOptions() if options is None else options
    _check_arguments(video, target, camera, options, LocalizeOptions, progress, on_detection, on_round)
    if line_delay_s is not None:
        line_delay_s = checks.line_delay(line_delay_s, "line_delay_s")
    camera_model, camera_path = _camera(camera)
    if line_delay_s is None and camera_path is not None:
        line_delay_s = load_camera(camera_path).line_delay_s
    if options.model == "rs-spline" and line_delay_s is None:
        raise InputError("no line delay: pass one (--line-delay, s/row) or a camera file that has one")
    detection, video_path = _detections(video, target, camera_model, options, progress, on_detection)
    inputs = {"video": None if video_path is None else str(video_path),
              "target": None if target is None or isinstance(target, Target) else str(target),
              "camera": None if camera_path is None else str(camera_path)}
    verdict = Verdict(TRUSTED, "Trajectory estimated with the given line delay.", (), quantity="line_delay_s",
                      value=line_delay_s, unit="s/row")
    if options.model == "gs-pnp":
        poses = pnp_trajectory(detection.observations, camera_model, options.rows, line_delay_s)
        poses.warnings[:0] = list(detection.warnings)
        return LocalizeRun(poses, replace(verdict, headline="Per-frame global-shutter poses (PnP)."), camera_model,
                           detection, options, inputs)
    result = localize(detection.observations, camera_model, line_delay_s, options, progress=on_round)
    result.warnings[:0] = list(detection.warnings)
    return LocalizeRun(result, verdict, camera_model, detection, options, inputs,
                       comparison=compare_with_pnp(result, camera_model))


def check_target_early(video: PathLike, target: Target) -> bool:
    """Before detection: a few frames of the video's start (detection.probe.early_board). InputError
    (one line) when they show a checkerboard of another size than the target file's; True when they
    show the file's board whole (no larger board around it: the check after detection is not needed),
    False when they tell nothing (no checkerboard target, or no board seen often enough)."""
    if target.target_type != "checkerboard":
        return False
    rows, cols = target.grid_shape
    try:
        seen = probe.early_board(video, expected=(cols, rows))
    except (InputError, OSError):
        return False
    if seen is None:
        return False
    if sorted(seen) != sorted((cols, rows)):
        raise InputError(probe.mismatch_message(target, seen))
    return True


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


def _check_arguments(video, target, camera, options, options_class, progress, on_detection, on_round) -> None:
    """The front doors' arguments (rscalib.checks), each refused with its name before any file is read."""
    checks.instance(video, "video", (str, os.PathLike, DetectionResult, Observations),
                    "a video file, an image folder, a DetectionResult or rscalib.Observations")
    if not isinstance(video, (DetectionResult, Observations)):
        checks.path(video, "video")
    if target is not None:
        checks.instance(target, "target", (str, os.PathLike, Target), "a target file or an rscalib.Target")
    if camera is not None:
        checks.instance(camera, "camera", (str, os.PathLike, CameraModel, CameraFile),
                        "a camera file, an rscalib.CameraModel or a CameraFile")
    checks.instance(options, "options", (options_class,), f"an rscalib.{options_class.__name__} or None")
    checks.progress(progress)
    checks.optional_callable(on_detection, "on_detection")
    checks.optional_callable(on_round, "on_round")


def _camera(camera: Optional[CameraInput]) -> tuple[CameraModel, Optional[Path]]:
    """The camera model and its file (None when given as a model)."""
    if camera is None:
        raise InputError("a camera is needed: its file (--camera) or a CameraModel")
    if isinstance(camera, CameraModel):
        return camera, None
    if isinstance(camera, CameraFile):
        return camera.camera, None
    if not Path(camera).is_file():
        raise InputError(f"camera file not found: {camera}")
    return load_camera(camera).camera, Path(camera)


def _detections(video: VideoInput, target, camera: CameraModel, options, progress,
                on_detection: DetectionCallback, poses: Optional[PosesAlongside] = None
                ) -> tuple[DetectionResult, Optional[Path]]:
    """The detections of `video` (detected now, or given) and the video's path (None when given);
    poses: filled with their per-frame PnP while detecting."""
    if isinstance(video, Observations):
        video = DetectionResult.from_observations(video)
    if isinstance(video, DetectionResult):
        detection, path = video, None
        if tuple(detection.image_size) != (camera.width, camera.height):
            raise InputError(f"the detections are {detection.image_size[0]}x{detection.image_size[1]} but the camera "
                             f"is {camera.width}x{camera.height}")
    else:
        path = Path(video)
        if not path.exists():
            raise InputError(f"video not found: {video}")
        if target is None:
            raise InputError("a target is needed to detect: its file (--target) or a Target")
        if not isinstance(target, Target) and not Path(target).is_file():
            raise InputError(f"target file not found: {target}")
        require_frame_times(open_source(video).timestamps_source, video)  # before the slow detection
        detection = detect(video, target, camera, options, progress=progress, poses=poses)
        require_frame_times(detection.timestamps, video)  # a video without times or frame rate
    if on_detection is not None:
        on_detection(detection)
    return detection, path
