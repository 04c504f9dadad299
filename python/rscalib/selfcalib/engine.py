"""The self-calibration engine over a sequence of frames (docs/sog.md): the Sum-of-Gaussians bank
(C++, rscalib._core.SogBank) through the per-frame loop of :mod:`rscalib.selfcalib.driver` with the
image front end (:mod:`rscalib.selfcalib.front_end`), then the bundle adjustment over its tracks
(:mod:`rscalib.selfcalib.bundle`) and the judgement (:mod:`rscalib.selfcalib.judge`). The job with
its verdict and files is :func:`rscalib.self_calibrate` (pipeline.py), which calls
:func:`calibrate_frames`."""
from __future__ import annotations

from typing import Any, Callable, Iterable, Iterator, Optional

import cv2
import numpy as np

from .._core import SogBank, SogOptions, SogUpdateReport
from .._progress import Progress, ProgressArg
from ..errors import InputError
from ..io.limits import check_memory, frame_memory_bytes
from .bundle import BundleResult, TrackRecorder, bundle_adjust
from .driver import SelfCalibHistory, run_bank
from .front_end import ImageFrontEnd
from .judge import (
    RESTART_OFFSET,
    judge_bundle,
    judge_determined,
    prior_bounds,
)
from .options import SelfCalibOptions
from .prior import initial_bank, make_bank, single_gaussian_grid
from .result import Restart, SelfCalibResult, bundle_covariance
from .rolling_shutter import RollingShutterCorrection, timed_frames

# The tracks' drift as a systematic error: the adjustment is repeated with every track cut into
# pieces of BUNDLE_DRIFT_CUT_FRAMES frames (each piece its own point, so a drifting patch re-anchors),
# and the shift of the camera between the two counts as one more standard error per parameter
# (docs/sog.md §20). On look-around renders whole tracks left cx 5.7 px off at a 0.5 px sigma; the
# pieces moved it 4.5 px.
BUNDLE_DRIFT_CUT_FRAMES = 40
# Keyframes every 3rd frame (the experiments of docs/sog.md §17-19), sparser on longer sequences so the
# adjustment's dense pose block stays small.
MAX_BUNDLE_KEYFRAMES = 100
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


def _run(frames, width: int, height: int, pixel_size_mm, options, front_end, initial, max_frames, on_frame,
         line_delay_s: float, record: bool = False
         ) -> tuple[SogBank, SelfCalibHistory, ImageFrontEnd, Optional[TrackRecorder]]:
    source = front_end if isinstance(front_end, ImageFrontEnd) else ImageFrontEnd(front_end, (width, height))
    bank = make_bank(width, height, pixel_size_mm, options=options, bank=initial)
    gray = _checked_gray(frames, width, height)
    measured = source
    if line_delay_s > 0:  # measurements moved to one time per frame (rolling_shutter.py)
        measured, gray = RollingShutterCorrection(source, line_delay_s, height), timed_frames(gray)
    recorder = None
    if record:   # what the bank used, with the frames' times, for the bundle adjustment (bundle.TrackRecorder)
        if line_delay_s > 0:
            recorder = measured = TrackRecorder(measured, timed=True)
        else:
            gray = timed_frames(gray)
            recorder = measured = TrackRecorder(measured, unwrap=True)

        def each(k, running, report, user=on_frame):
            recorder.on_frame(k, running, report)
            if user is not None:
                user(k, running, report)
        on_frame = each
    history = run_bank(bank, gray, measured, min_visible=source.options.min_visible,
                       max_new_per_frame=source.options.max_new_per_frame, max_frames=max_frames,
                       on_frame=on_frame)
    return bank, history, source, recorder


def _bundle(recorder: TrackRecorder, camera0: np.ndarray, pixel_size_mm, frames: int, line_delay: bool,
            height: int) -> tuple[Optional[BundleResult], Optional[BundleResult], str]:
    """The adjustment over whole tracks and over tracks cut into BUNDLE_DRIFT_CUT_FRAMES pieces
    (None where it failed) and the error message; line_delay: estimate the line delay in both
    (rows timed from the middle row)."""
    step = max(3, -(-frames // MAX_BUNDLE_KEYFRAMES))
    tracks = recorder.tracks()
    shutter = dict(line_delay=line_delay, reference_row=0.5 * (height - 1))
    try:
        ba = bundle_adjust(tracks, camera0, pixel_size_mm, keyframe_step=step, **shutter)
    except (ValueError, np.linalg.LinAlgError) as error:   # InputError is a ValueError
        return None, None, str(error)
    try:
        cut = bundle_adjust(tracks, ba.camera, pixel_size_mm, keyframe_step=step,
                            max_track_frames=BUNDLE_DRIFT_CUT_FRAMES, **shutter)
    except (ValueError, np.linalg.LinAlgError) as error:
        return ba, None, str(error)
    return ba, cut, ""

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
    over its tracks, which is the estimate and judges "determined": judge_bundle, f's 99 % interval
    within +-options.determined_within) or a baseline (the filter alone, judged by restarts:
    judge_determined, when the frames can be read again); line_delay_s > 0 compensates the rolling
    shutter in every measurement (rolling_shutter.RollingShutterCorrection); None lets the adjustment
    estimate it.
    For experiments and tests: front_end, a ready :class:`ImageFrontEnd` (then no restarts); grid,
    keyword arguments of rscalib.selfcalib.prior.initial_bank (ranges, counts; default from
    options.f_range_px, or the single filter of the "single" baseline); sog, the bank's C++ options
    (default: sog_options(options)).
    progress: False/None, True (a progress bar on stderr) or a callable(done, total), with
    `expected_frames` the bar's total when options.max_frames is not given;
    on_frame(k, bank, report) is called after every processed frame of the bank's pass."""
    options = options or SelfCalibOptions()
    pixel_size_mm, max_frames = options.pixel_size_mm, options.max_frames
    line_delay_s = options.line_delay_s or 0.0
    bundle, restarts, max_f_half_width = options.bundle, options.restarts, options.determined_within
    fe = front_end if front_end is not None else options.front_end
    if grid is None:
        grid = _grid_of(options, image_size)
    width, height = int(image_size[0]), int(image_size[1])
    sog = sog_options(options) if sog is None else sog
    first_frames, factory = _frame_factory(frames)
    fe_options = fe.options if isinstance(fe, ImageFrontEnd) else fe
    initial = initial_bank(width, height, pixel_size_mm, **grid)
    search = fe_options
    features = map_size_bound(sog, search.min_visible, search.max_new_per_frame,
                              _frame_count(frames, max_frames, expected_frames))
    needed = predicted_memory_bytes(len(initial), features, (width, height))
    check_memory(needed, f"self-calibration with {len(initial)} Gaussians, up to {features} map features and "
                         f"{width}x{height} frames (Gaussians x (18 + 6 x features)^2 x 8 B x {FILTER_MEMORY_FACTOR} "
                         "+ the frame)")
    per_pass = max_frames if max_frames is not None else expected_frames
    checking = restarts and not bundle and factory is not None and not isinstance(fe, ImageFrontEnd)
    total = None if per_pass is None else per_pass * (3 if checking else 1)
    with Progress(progress, total, "self-calibrating") as bar:
        def each_frame(k: int, running: SogBank, report: SogUpdateReport) -> None:
            bar.update(k + 1, f"f {running.calibration_mean[0]:.1f} px, {running.num_gaussians} Gaussians")
            if on_frame is not None:
                on_frame(k, running, report)

        bank, history, source, recorder = _run(first_frames, width, height, pixel_size_mm, sog, fe,
                                               initial, max_frames, each_frame, line_delay_s, record=bundle)
        mean = np.asarray(bank.calibration_mean)
        runs = []
        if checking and bank.num_gaussians == 1:
            done = len(history)
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
                done += len(history)
        bundled = None, None, ""
        if bundle:
            bar.update(len(history), "bundle adjustment over the filter's tracks")
            bundled = _bundle(recorder, mean, pixel_size_mm, len(history), line_delay_s == 0, height)
    warnings = []
    if bank.num_gaussians > 1:
        warnings.append(f"{bank.num_gaussians} Gaussians remain in the filter bank: the sequence did not single out "
                        "one calibration for the filter "
                        "(move more, with rotation and translation, through a textured scene)")
    if not bundle and line_delay_s == 0:
        warnings.append("the rolling shutter is not compensated (no line delay given, no bundle adjustment): on a "
                        "phone or other rolling-shutter camera give the line delay (`rscalib linedelay`; "
                        "--line-delay) or let the bundle adjustment estimate it (docs/sog.md §21)")
    used = np.median(history.features_used)
    if used < 0.5 * source.options.min_visible:
        warnings.append(f"few features matched per frame (median {used:.0f}); the scene may lack texture")
    filter_bounds = np.asarray(bank.calibration_bounds_99())
    prior = prior_bounds(initial, (width, height))
    covariance = np.asarray(bank.calibration_cov)
    ba, cut, ba_error, estimate, estimate_from = None, None, "", mean, "filter"
    if bundle:
        ba, cut, ba_error = bundled
        determined, reason, bounds = judge_bundle(ba, cut, ba_error, prior, max_f_half_width, height)
        if ba is not None:
            estimate, estimate_from, covariance = ba.camera, "bundle adjustment", bundle_covariance(ba, cut)
    else:
        determined, reason, bounds = judge_determined(mean, filter_bounds, bank.num_gaussians, runs,
                                                      (width, height), prior)
    return SelfCalibResult(
        mean=np.asarray(estimate, float), bounds_99=bounds,
        covariance=covariance, image_size=(width, height),
        pixel_size_mm=tuple(float(x) for x in np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,))),
        gaussians_initial=len(initial), gaussians_left=bank.num_gaussians, history=history, warnings=warnings,
        determined=determined, reason=reason, filter_bounds_99=filter_bounds, restarts=runs, filter_mean=mean,
        bundle=ba, bundle_cut=cut if bundle else None, bundle_error=ba_error, estimate_from=estimate_from)
