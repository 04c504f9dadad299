"""The self-calibration engine over a sequence of frames (docs/sog.md): one pass in which the
Sum-of-Gaussians bank (C++, rscalib._core.SogBank) runs through the per-frame loop of
:mod:`rscalib.selfcalib.driver` with its image front end (:mod:`rscalib.selfcalib.front_end`) while
the adjustment's tracker (:mod:`rscalib.selfcalib.tracks`) follows many long tracks in the same
frames; then the bundle adjustment in C++ (:mod:`rscalib.selfcalib.adjustment`) from the bank's
camera and poses (:mod:`rscalib.selfcalib.keyframes`), and the judgement
(:mod:`rscalib.selfcalib.judge`). The job with its verdict and files is :func:`rscalib.self_calibrate`
(pipeline.py), which calls :func:`calibrate_frames`."""
from __future__ import annotations

import contextlib
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Iterable, Iterator, Optional

import cv2
import numpy as np

from .._core import CameraModel, SogBank, SogOptions, SogUpdateReport
from .._progress import Progress, ProgressArg
from ..errors import InputError
from ..io.limits import check_memory, frame_memory_bytes
from ..verdict import Z_99
from .adjustment import AdjustmentResult, adjust
from .driver import SelfCalibHistory, run_bank
from .front_end import ImageFrontEnd
from .judge import RESTART_OFFSET, judge_adjustment, judge_determined, prior_bounds
from .keyframes import FilterPoses, KeyframePoses, adjustment_start, halves, subset
from .options import SelfCalibOptions
from .prior import initial_bank, make_bank, single_gaussian_grid
from .result import Restart, SelfCalibResult
from .rolling_shutter import RollingShutterCorrection, timed_frames
from .tracks import FeatureTracker, TrackSet

# The adjustment's tracks span at least this many keyframes (a point seen twice has no parallax check)
MIN_TRACK_KEYFRAMES = 3
# The quick first adjustment: this many tracks, those seen in most keyframes
QUICK_TRACKS = 150
# Memory of the bank: every Gaussian holds a dense covariance of the state, 18 + 6 per (inverse-depth)
# feature, in doubles. Measured peak over G x dim^2 x 8 B: 1.04-1.08 at 108 Gaussians, 50-200
# features, once 1.38 at 50 (the two update threads' allocations; docs/benchmarks.md, "Peak memory
# against input size"); 1.5 covers both.
FILTER_MEMORY_FACTOR = 1.5
_STATE_WITHOUT_FEATURES = 18
_INVERSE_DEPTH_SIZE = 6

def sog_options(options: SelfCalibOptions) -> SogOptions:
    """The bank's options (C++ SogOptions) for these self-calibration options."""
    sog = SogOptions()
    sog.ransac_hypotheses = int(options.ransac_hypotheses)
    sog.sprt_alpha = float(options.sprt_alpha)
    sog.sprt_beta = float(options.sprt_beta)
    return sog


def _grid_of(options: SelfCalibOptions, image_size: tuple[int, int]) -> dict:
    """The initial bank's grid (prior.initial_bank's keyword arguments) of these options: the f range
    given, or the single filter of the "single" baseline."""
    width, height = int(image_size[0]), int(image_size[1])
    if options.baseline == "single":
        return single_gaussian_grid(width, height, options.pixel_size_mm, f_range=options.f_range_px,
                                    f0=options.f0_px, f_sigma=options.f_sigma_px)
    return {"f_range": tuple(options.f_range_px)} if options.f_range_px else {}


def _checked_gray(frames: Iterable, width: int, height: int) -> Iterator[tuple[float, Any]]:
    """(time, image) with every image checked for its size and made grayscale (None passes through)."""
    for k, (t_s, image) in enumerate(frames):
        if image is not None:
            if image.shape[:2] != (height, width):
                raise InputError(f"frame {k} is {image.shape[1]}x{image.shape[0]}, expected {width}x{height}")
            if image.ndim == 3:
                image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        yield t_s, image


def _frame_factory(frames) -> tuple[Iterable, Optional[Callable[[], Iterable]]]:
    """The first pass's frames and, when the frames can be read again (a callable returning a fresh
    iterable, or a re-iterable such as a list), a factory for further passes."""
    if callable(frames):
        return frames(), frames
    if iter(frames) is not frames:
        return frames, lambda: frames
    return frames, None

def map_size_bound(options: SogOptions, min_visible: int, max_new_per_frame: int,
                   frames: Optional[int]) -> int:
    """The most features the map can hold: the cap plus one frame's new features (the bank caps
    after each update), or without a cap (max_features <= 0) what ``frames`` frames can add;
    InputError when there is no cap and the number of frames is unknown."""
    if options.max_features > 0:
        return int(options.max_features) + int(max_new_per_frame)
    if frames is None:
        raise InputError("SogOptions.max_features <= 0 (no map cap) needs a known number of frames (max_frames) "
                         "to bound the memory of the filter")
    return int(min_visible) + int(max_new_per_frame) * max(int(frames) - 1, 0)


def predicted_memory_bytes(gaussians: int, features: int, image_size: tuple[int, int]) -> int:
    """Peak memory of a bank of ``gaussians`` filters with ``features`` map features, plus one frame
    of ``image_size`` in the front end (rscalib.io.limits.frame_memory_bytes)."""
    dim = _STATE_WITHOUT_FEATURES + _INVERSE_DEPTH_SIZE * int(features)
    return int(FILTER_MEMORY_FACTOR * gaussians * dim * dim * 8) + frame_memory_bytes(*image_size, 1)


def _frame_count(frames, max_frames: Optional[int], expected_frames: Optional[int]) -> Optional[int]:
    if max_frames is not None:
        return max_frames
    if expected_frames is not None:
        return expected_frames
    return len(frames) if hasattr(frames, "__len__") else None


class _BackgroundTracker:
    """The tracker in a thread of its own, fed the filter's frames through a short queue: OpenCV and
    the bank's C++ update release the GIL, so tracking runs beside the filter on a second core. The
    frames reach it in order, so its tracks are those of a tracker called in line (deterministic)."""

    QUEUED_FRAMES = 8       # a few frames of slack (a 640x480 grey frame is 0.3 MB)

    def __init__(self, tracker: FeatureTracker):
        import queue
        import threading

        self.tracker, self.error = tracker, None
        self.queue: queue.Queue = queue.Queue(maxsize=self.QUEUED_FRAMES)
        self.thread = threading.Thread(target=self._work, name="rscalib-tracker", daemon=True)
        self.thread.start()

    def _work(self) -> None:
        while True:
            item = self.queue.get()
            if item is None:
                return
            if self.error is None:
                try:
                    self.tracker.add_frame(*item)
                except BaseException as error:   # handed to the caller at the next frame or at the end
                    self.error = error

    def add_frame(self, t_s: float, image) -> None:
        if self.error is not None:
            raise self.error
        self.queue.put((t_s, image))

    def result(self) -> TrackSet:
        self.close()
        if self.error is not None:
            raise self.error
        return self.tracker.result()

    def close(self) -> None:
        if self.thread.is_alive():
            self.queue.put(None)
            self.thread.join()

    def __enter__(self) -> _BackgroundTracker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _feeding(tracker, frames: Iterable) -> Iterator:
    """The frames, each handed to the tracker first (one decode serves the filter and the tracker)."""
    for t_s, image in frames:
        if image is not None:
            tracker.add_frame(t_s, image)
        yield t_s, image


def _run(frames, width: int, height: int, pixel_size_mm, options, front_end, initial, max_frames, on_frame,
         line_delay_s: float, tracker: Optional[_BackgroundTracker] = None
         ) -> tuple[SogBank, SelfCalibHistory, ImageFrontEnd, list]:
    """One pass of the bank over the frames (with the tracker fed the same frames, when given); the
    bank, its history, its front end and its merged camera state after every processed frame (when
    tracking: the adjustment starts from those poses)."""
    source = front_end if isinstance(front_end, ImageFrontEnd) else ImageFrontEnd(front_end, (width, height))
    bank = make_bank(width, height, pixel_size_mm, options=options, bank=initial)
    gray = _checked_gray(frames, width, height)
    if tracker is not None:
        gray = _feeding(tracker, gray)
    measured = source
    if line_delay_s > 0:  # measurements moved to one time per frame (rolling_shutter.py)
        measured, gray = RollingShutterCorrection(source, line_delay_s, height), timed_frames(gray)
    states: list = []

    def each(k, running, report):
        if tracker is not None:
            states.append(np.asarray(running.camera_state, float)[:7].copy())
        if on_frame is not None:
            on_frame(k, running, report)

    history = run_bank(bank, gray, measured, min_visible=source.options.min_visible,
                       max_new_per_frame=source.options.max_new_per_frame, max_frames=max_frames, on_frame=each)
    return bank, history, source, states


def _line_delay_mode(options: SelfCalibOptions, height: int) -> tuple[dict, Optional[tuple]]:
    """The adjustment's line delay (adjust's keywords) and what the user gave ((mean, sigma) or None):
    held at --line-delay, a prior from --line-delay-from, else estimated."""
    if options.line_delay_s is not None:
        return {"line_delay_s": float(options.line_delay_s)}, (float(options.line_delay_s), 0.0)
    if options.line_delay_from is not None:
        mean, sigma = line_delay_prior(options.line_delay_from, height)
        return {"line_delay_s": mean, "line_delay_prior": (mean, sigma)}, (mean, sigma)
    return {"estimate_line_delay": True}, None


def line_delay_prior(path, image_height: int) -> tuple[float, float]:
    """(line delay s/row, its sigma) of an `rscalib linedelay` result.json, for the adjustment's prior;
    InputError when it is not one, claims no line delay, or was made at another image height."""
    import json
    from pathlib import Path

    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise InputError(f"--line-delay-from {path}: not a readable result.json ({error})") from None
    verdict = data.get("verdict") if isinstance(data, dict) else None
    if not isinstance(verdict, dict) or verdict.get("quantity") != "line_delay_s":
        raise InputError(f"--line-delay-from {path}: not the result.json of `rscalib linedelay` or `rscalib flicker`")
    mean, sigma = verdict.get("value"), verdict.get("std")
    if not (isinstance(mean, (int, float)) and isinstance(sigma, (int, float)) and sigma > 0):
        raise InputError(f"--line-delay-from {path}: it claims no line delay with a sigma (verdict: "
                         f"{verdict.get('status')})")
    rows = data.get("rows")
    if isinstance(rows, int) and rows != int(image_height):
        raise InputError(f"--line-delay-from {path}: its line delay is per row of {rows} rows, this video has "
                         f"{image_height} (a line delay belongs to one video mode)")
    return float(mean), float(sigma)


def _adjust(tracks: TrackSet, states: list, camera0: CameraModel, options: SelfCalibOptions, line_delay: dict
            ) -> tuple[Optional[AdjustmentResult], str, dict, Optional[dict]]:
    """The adjustment over the tracks from the bank's camera and poses: its result (None when it
    could not run), the reason when not, what went into it, and the self-check of its two halves."""
    # the tracker's counters; its clock as a *_time_s (a time: not compared between runs)
    used: dict = {("tracking_time_s" if k == "wall_s" else k): v for k, v in tracks.stats.items()
                  if isinstance(v, (int, float)) and k != "ms_per_frame_wall"}
    try:
        observations = tracks.keyframe_observations(min_keyframes=MIN_TRACK_KEYFRAMES,
                                                    max_keyframes=options.max_keyframes)
        if len(observations) == 0:
            return None, f"no track spans {MIN_TRACK_KEYFRAMES} keyframes (too little texture or motion?)", used, None
        used.update(adjustment_keyframes=int(len(observations.keyframes)),
                    adjustment_tracks=int(len(np.unique(observations.track_id))),
                    adjustment_observations=int(len(observations)))
        poses = FilterPoses.from_states(states)
        # one thread a solve: Ceres' threads sum the Schur complement in an order that changes from run to
        # run (the last bits of f differed between two runs); the halves run side by side instead
        solve = dict(loss="soft_l1", loss_scale_px=options.robust_loss_scale_px, num_threads=1,
                     max_free_iterations=options.max_free_iterations, **line_delay)
        # First the tracks seen longest alone (a tenth of the cost an iteration): from the filter's
        # camera and poses, which can be far off, most iterations are spent here; the whole set then
        # starts from their answer and converges in a few.
        few = subset(observations, QUICK_TRACKS, MIN_TRACK_KEYFRAMES)
        if len(np.unique(few.track_id)) < len(np.unique(observations.track_id)):
            quick = adjust(adjustment_start(few, poses, camera0), camera0, **solve)
            if quick.converged:
                poses = KeyframePoses(np.asarray(observations.keyframes), np.asarray(quick.keyframe_poses))
                camera0 = quick.camera
                if "estimate_line_delay" in solve:
                    solve = dict(solve, line_delay_s=float(quick.line_delay_s))
        # The whole and the self-check's halves side by side (the solver releases the GIL): the
        # halves start where the whole does, from the quick answer, and converge to their own minima.
        with ThreadPoolExecutor(2) as pool:
            halves_done = pool.submit(_halves_check, observations, poses, camera0, solve)
            adj = adjust(adjustment_start(observations, poses, camera0), camera0, **solve)
            self_check = halves_done.result()
    except (ValueError, np.linalg.LinAlgError) as error:   # InputError is a ValueError
        return None, str(error), used, None
    return adj, "", used, self_check


def _widened(adj: AdjustmentResult, factors: np.ndarray) -> AdjustmentResult:
    """The adjustment with its reported (two-way) covariance and 99 % bounds widened per parameter by
    ``factors`` (>= 1: the self-check's Birge ratios)."""
    from dataclasses import replace

    covariance = adj.covariance_two_way * np.outer(factors, factors)
    half = Z_99 * np.sqrt(np.maximum(np.diag(covariance), 0.0))
    estimate = np.asarray(adj.estimate, float)
    return replace(adj, covariance_two_way=covariance, bounds_99_two_way=np.c_[estimate - half, estimate + half])


def _halves_check(observations, poses, camera: CameraModel, solve: dict) -> Optional[dict]:
    """The self-check (docs/sog.md §24): the first and the second half of the keyframes adjusted
    apart, one after the other (beside the whole), from the whole's start (``camera``, ``poses``).
    Per parameter z = |a - b| / sqrt(sa^2 + sb^2) of the halves'
    estimates with their (two-way clustered) sigmas; when the halves scatter more than their sigmas
    say (z > 1) the whole's sigma is too small by about that factor (the Birge ratio, as the line
    delay's self-check: docs/formulation.md §9). Every parameter is widened by the largest z: a misfit
    seen in one parameter reaches the others through their correlations, in shares the check cannot
    tell (docs/sog.md §24). None when a half cannot be adjusted."""
    parts = halves(observations, MIN_TRACK_KEYFRAMES)
    if any(len(part) == 0 for part in parts):
        return None

    def adjusted(part) -> Optional[AdjustmentResult]:
        try:
            return adjust(adjustment_start(part, poses, camera), camera, **solve)
        except (ValueError, np.linalg.LinAlgError):
            return None

    results = [adjusted(part) for part in parts]
    estimates, sigmas = [], []
    for half in results:
        if half is None or not (half.converged and half.covariance_ok):
            return None
        estimates.append(np.asarray(half.estimate, float))
        sigmas.append(np.sqrt(np.maximum(np.diag(half.covariance_two_way), 0.0)))
    (a, b), (sa, sb) = estimates, sigmas
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where((sa > 0) & (sb > 0), np.abs(a - b) / np.hypot(sa, sb), 0.0)
    names = list(results[0].names)
    return {"names": names, "halves": [e.tolist() for e in estimates], "sigmas": [s.tolist() for s in sigmas],
            "z": z.tolist(), "widen": [float(max(1.0, z.max(initial=0.0)))] * len(z)}


def calibrate_frames(frames, image_size: tuple[int, int], options: Optional[SelfCalibOptions] = None, *,
                     front_end: Optional[ImageFrontEnd] = None, grid: Optional[dict] = None,
                     sog: Optional[SogOptions] = None, progress: ProgressArg = None,
                     expected_frames: Optional[int] = None,
                     on_frame: Optional[Callable[[int, SogBank, SogUpdateReport], None]] = None
                     ) -> SelfCalibResult:
    """The engine over `frames`: an iterable of (time_s, image), grayscale or BGR uint8, or a callable
    returning a fresh such iterable (then the frames are read again for the restarts of the filter
    baselines); an image of None (unreadable) is skipped.

    options (SelfCalibOptions; None: the defaults): the method (the bank, then the bundle adjustment
    over the tracker's tracks, which is the estimate and judges "determined": judge_adjustment, f's 99 %
    interval within +-options.determined_within) or a baseline (the filter alone, judged by restarts:
    judge_determined, when the frames can be read again). The line delay: options.line_delay_s holds
    it (and moves the filter's measurements to one time per frame), options.line_delay_from makes an
    `rscalib linedelay` result its prior, neither lets the adjustment estimate it.
    For experiments and tests: front_end, a ready :class:`ImageFrontEnd` (then no restarts); grid,
    keyword arguments of rscalib.selfcalib.prior.initial_bank (ranges, counts; default from
    options.f_range_px, or the single filter of the "single" baseline); sog, the bank's C++ options
    (default: sog_options(options)).
    progress: False/None, True (a progress bar on stderr) or a callable(done, total), with
    `expected_frames` the bar's total when options.max_frames is not given;
    on_frame(k, bank, report) is called after every processed frame of the bank's pass."""
    options = options or SelfCalibOptions()
    pixel_size_mm, max_frames = options.pixel_size_mm, options.max_frames
    line_delay_mode, line_delay_given = _line_delay_mode(options, int(image_size[1]))
    # the filter's measurements are moved to one time per frame by the line delay given (a prior's mean)
    line_delay_s = line_delay_given[0] if line_delay_given else 0.0
    bundle, restarts = options.bundle, options.restarts
    fe = front_end if front_end is not None else options.front_end
    if grid is None:
        grid = _grid_of(options, image_size)
    width, height = int(image_size[0]), int(image_size[1])
    sog = sog_options(options) if sog is None else sog
    first_frames, factory = _frame_factory(frames)
    fe_options = fe.options if isinstance(fe, ImageFrontEnd) else fe
    initial = initial_bank(width, height, pixel_size_mm, **grid)
    _check_filter_memory(sog, fe_options, len(initial), _frame_count(frames, max_frames, expected_frames),
                         width, height)
    per_pass = max_frames if max_frames is not None else expected_frames
    checking = restarts and not bundle and factory is not None and not isinstance(fe, ImageFrontEnd)
    total = None if per_pass is None else per_pass * (3 if checking else 1)
    with Progress(progress, total, "self-calibrating") as bar:
        def each_frame(k: int, running: SogBank, report: SogUpdateReport) -> None:
            bar.update(k + 1, f"f {running.calibration_mean[0]:.1f} px, {running.num_gaussians} Gaussians")
            if on_frame is not None:
                on_frame(k, running, report)

        with contextlib.ExitStack() as stack:
            tracker = stack.enter_context(_BackgroundTracker(FeatureTracker((width, height), options.tracks))) \
                if bundle else None
            bank, history, source, states = _run(first_frames, width, height, pixel_size_mm, sog, fe,
                                                 initial, max_frames, each_frame, line_delay_s, tracker)
            tracks = tracker.result() if bundle else None
        mean = np.asarray(bank.calibration_mean)
        runs = []
        if checking and bank.num_gaussians == 1:
            runs = _restarts(factory, mean, width, height, pixel_size_mm, sog, fe_options, max_frames, line_delay_s,
                             bar, len(history))
        adjusted: tuple = (None, "", {}, None)
        frame_interval = None
        if bundle:
            bar.update(len(history), "bundle adjustment over the tracks")
            if len(tracks.t_s) != len(states):
                raise InputError("the tracker and the filter saw different frames")   # a bug, said plainly
            camera0 = CameraModel("civera-radial", mean, width, height, pixel_size_mm=_pixel_pair(pixel_size_mm))
            adjusted = _adjust(tracks, states, camera0, options, line_delay_mode)
            frame_interval = float(np.median(np.diff(tracks.t_s))) if len(tracks.t_s) > 1 else None
    warnings = _filter_warnings(bank, history, source, bundle=bundle, line_delay_s=line_delay_s)
    filter_bounds = np.asarray(bank.calibration_bounds_99())
    prior = prior_bounds(initial, (width, height))
    adj, adj_error, tracks_used, self_check = adjusted
    if adj is not None and self_check is not None:
        adj = _widened(adj, np.asarray(self_check["widen"], float))
    estimate, estimate_from = mean, "filter"
    covariance = np.asarray(bank.calibration_cov)
    if bundle:
        determined, reason, bounds = judge_adjustment(adj, adj_error, prior, options.determined_within, height,
                                                      frame_interval)
        if adj is not None:
            # not determined: an estimate the verdict does not stand behind, kept for diagnosis
            # (result.json not_claimed)
            estimate = adj.camera_params
            estimate_from = "bundle adjustment" if determined else "bundle adjustment (not determined)"
            covariance = np.asarray(adj.covariance_two_way[:5, :5])
    else:
        determined, reason, bounds = judge_determined(mean, filter_bounds, bank.num_gaussians, runs,
                                                      (width, height), prior)
    return SelfCalibResult(
        mean=np.asarray(estimate, float), bounds_99=bounds,
        covariance=covariance, image_size=(width, height),
        pixel_size_mm=tuple(float(x) for x in np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,))),
        gaussians_initial=len(initial), gaussians_left=bank.num_gaussians, history=history, warnings=warnings,
        determined=determined, reason=reason, filter_bounds_99=filter_bounds, restarts=runs, filter_mean=mean,
        adjustment=adj, adjustment_error=adj_error, line_delay_given=line_delay_given, tracks=tracks_used,
        self_check=self_check,
        estimate_from=estimate_from)


def _check_filter_memory(sog: SogOptions, fe_options, num_gaussians: int, frames: Optional[int], width: int,
                         height: int) -> None:
    """InputError (one line) when the bank's dense covariances would not fit in memory."""
    features = map_size_bound(sog, fe_options.min_visible, fe_options.max_new_per_frame, frames)
    needed = predicted_memory_bytes(num_gaussians, features, (width, height))
    check_memory(needed, f"self-calibration with {num_gaussians} Gaussians, up to {features} map features and "
                         f"{width}x{height} frames (Gaussians x (18 + 6 x features)^2 x 8 B x {FILTER_MEMORY_FACTOR} "
                         "+ the frame)")


def _restarts(factory, mean: np.ndarray, width: int, height: int, pixel_size_mm, sog: SogOptions, fe_options,
              max_frames: Optional[int], line_delay_s: float, bar, frames_done: int) -> list:
    """The filter baselines' check: the single filter run again from f RESTART_OFFSET below and above
    the bank's answer (judge_determined compares where they end)."""
    runs = []
    done = frames_done
    for sign in (-1.0, 1.0):
        f0 = float(mean[0] * (1.0 + sign * RESTART_OFFSET))
        one = initial_bank(width, height, pixel_size_mm, **single_gaussian_grid(
            width, height, pixel_size_mm, f0=f0, f_sigma=0.5 * RESTART_OFFSET * float(mean[0])))

        def restart_frame(k, running, report, offset=done, f0=f0):
            bar.update(offset + k + 1, f"restart from f {f0:.0f} px: {running.calibration_mean[0]:.1f}")

        single, _, _, _ = _run(factory(), width, height, pixel_size_mm, sog, fe_options, one, max_frames,
                               restart_frame, line_delay_s)
        runs.append(Restart(f0=f0, mean=np.asarray(single.calibration_mean),
                            bounds_99=np.asarray(single.calibration_bounds_99())))
        done += frames_done
    return runs


def _filter_warnings(bank: SogBank, history, source, *, bundle: bool, line_delay_s: float) -> list:
    """What the filter's pass says about the sequence: Gaussians left, the rolling shutter not
    compensated, few features matched."""
    warnings = []
    if bank.num_gaussians > 1:
        warnings.append(f"{bank.num_gaussians} Gaussians remain in the filter bank: the sequence did not single out "
                        "one calibration for the filter "
                        "(move more, with rotation and translation, through a textured scene)")
    if not bundle and line_delay_s == 0:
        warnings.append("the rolling shutter is not compensated (no line delay given, no bundle adjustment): on a "
                        "phone or other rolling-shutter camera give the line delay (`rscalib linedelay`; "
                        "--line-delay) or let the bundle adjustment estimate it (docs/sog.md §24)")
    used = np.median(history.features_used)
    if used < 0.5 * source.options.min_visible:
        warnings.append(f"few features matched per frame (median {used:.0f}); the scene may lack texture")
    return warnings


def _pixel_pair(pixel_size_mm) -> list:
    return [float(x) for x in np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,))]
