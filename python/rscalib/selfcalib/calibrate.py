"""Self-calibration from images (Civera et al. 2009; docs/sog.md): the SOG filter bank (C++,
rscalib._core.SogBank) over an image sequence through the per-frame loop of
:mod:`rscalib.selfcalib.driver` with the image front end (:mod:`rscalib.selfcalib.front_end`); the
result, and the conversion of the civera-radial model to OpenCV's."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Optional, Union

import cv2
import numpy as np

from .. import _core
from .._progress import Progress, ProgressArg
from ..errors import InputError
from ..io.limits import check_memory, check_source_memory, frame_memory_bytes
from ..io.video import open_source
from .bundle import BundleResult, TrackRecorder, bundle_adjust
from .driver import SelfCalibHistory, run_bank
from .front_end import FrontEndOptions, ImageFrontEnd
from .prior import PAPER_PIXEL_SIZE_MM, initial_bank, make_bank, single_gaussian_grid
from .rolling_shutter import RollingShutterCorrection, timed_frames

__all__ = ["PARAM_NAMES", "GrayFrames", "Restart", "SelfCalibResult", "civera_to_opencv", "judge_determined",
           "read_gray_frames", "self_calibrate", "default_options", "RANSAC_HYPOTHESES", "RESTART_OFFSET", "DETERMINED_MAX_CONTRACTION",
           "DETERMINED_PP_TOLERANCE", "UNDETERMINED_PP_HALF_WIDTH", "DETERMINED_F_HALF_WIDTH", "MIN_BUNDLE_POINTS", "MAX_READOUT_FRAMES",
           "MAX_BUNDLE_KEYFRAMES", "BUNDLE_DRIFT_CUT_FRAMES", "bundle_covariance", "judge_bundle", "FILTER_MEMORY_FACTOR", "map_size_bound",
           "predicted_memory_bytes"]

PARAM_NAMES = ("f", "cx", "cy", "k1", "k2")

# "Determined" (docs/sog.md §14): after the bank, two single EKFs are restarted over the same frames
# from f = (1 -+ RESTART_OFFSET) times the bank's estimate (sigma RESTART_OFFSET / 2 of it, so the
# estimate is 2 sigma from each start). The data determine the calibration when the restarts come
# back together: their final f differ by at most DETERMINED_MAX_CONTRACTION of their starting
# difference (the data removed >= 65 % of it; rendered 5 s room sequences: 0.18-0.25) and their
# principal points are within DETERMINED_PP_TOLERANCE of the image diagonal of the bank's. The
# reported bounds then span the restarts' estimates too. When they do
# not, the reported bounds are the prior's: f over the initial bank, the principal point within
# UNDETERMINED_PP_HALF_WIDTH of the diagonal around the image centre (the bank's own prior, +-8.6 px
# at 320x240, excludes the paper camera's cy). On the real desk video the filter ends wherever it
# starts (from 355 px: 426; from 525: 636; the bank: 325), each with a +-0.4 % bound: an EKF's own
# covariance is no evidence that f was observed.
RESTART_OFFSET = 0.2
DETERMINED_MAX_CONTRACTION = 0.35
DETERMINED_PP_TOLERANCE = 0.02
UNDETERMINED_PP_HALF_WIDTH = 0.05
_Z99 = 2.5758293035489004
# "Determined" with the bundle adjustment (the default since issue 11; docs/sog.md §20): the
# adjustment over the filter's tracks (bundle.py) removes the filter's bias, and its covariance
# clustered by feature track (errors correlated along a track count once) is the bound. Determined:
# the adjustment converged over >= MIN_BUNDLE_POINTS tracks (fewer clusters make a clustered
# covariance itself uncertain; the real desk video has 32-60) and its 99 % interval of f is within
# +-DETERMINED_F_HALF_WIDTH of f: a user's requirement ("f known to 2 %"), not a fitted number.
DETERMINED_F_HALF_WIDTH = 0.02
MIN_BUNDLE_POINTS = 30
# A rolling shutter reads its rows within one frame interval (at most; a phone at 30 fps, about a
# third to all of it): a line delay whose 99 % interval lies wholly beyond this many frame intervals per
# image is the model misfitting the data, not a shutter (docs/sog.md §21).
MAX_READOUT_FRAMES = 1.25
# Converged: the solver stopped on its own criterion, or the camera's remaining Gauss-Newton step is
# under BUNDLE_STEP_SIGMA of its (model) sigma: it moves no more than a tenth of its uncertainty.
BUNDLE_STEP_SIGMA = 0.1
# The tracks' drift as a systematic error: the adjustment is repeated with every track cut into
# pieces of BUNDLE_DRIFT_CUT_FRAMES frames (each piece its own point, so a drifting patch re-anchors),
# and the shift of the camera between the two counts as one more standard error per parameter
# (docs/sog.md §20). On look-around renders whole tracks left cx 5.7 px off at a 0.5 px sigma; the
# pieces moved it 4.5 px.
BUNDLE_DRIFT_CUT_FRAMES = 40
# Keyframes every 3rd frame (the experiments of docs/sog.md §17-19), sparser on longer sequences so the
# adjustment's dense pose block stays small.
MAX_BUNDLE_KEYFRAMES = 100
# 1-point RANSAC (Civera et al., JFR 2010) is on in the image path: on the real desk video it moved the
# principal point from (303.2, 219.1) to (312.7, 235.7) against the truth (308.6, 236.5); on the
# clean rendered room sequences it changes nothing (docs/sog.md §14).
RANSAC_HYPOTHESES = 100
# Memory of the bank: every Gaussian holds a dense covariance of the state, 18 + 6 per (inverse-depth)
# feature, in doubles. Measured peak over G x dim^2 x 8 B: 1.04-1.08 at 108 Gaussians, 50-200
# features, once 1.38 at 50 (the two update threads' allocations; docs/benchmarks.md, "Peak memory
# against input size"); 1.5 covers both.
FILTER_MEMORY_FACTOR = 1.5
_STATE_WITHOUT_FEATURES = 18
_INVERSE_DEPTH_SIZE = 6


def default_options() -> _core.SogOptions:
    """The bank's options for images: SogOptions() with 1-point RANSAC on."""
    options = _core.SogOptions()
    options.ransac_hypotheses = RANSAC_HYPOTHESES
    return options


@dataclass
class Restart:
    """A single EKF restarted from ``f0`` over the same frames: its final calibration and 99 % bounds."""

    f0: float
    mean: np.ndarray
    bounds_99: np.ndarray

    def summary_dict(self) -> dict:
        return {"f0": self.f0, "mean": self.mean.tolist(), "bounds_99": self.bounds_99.tolist()}


@dataclass
class SelfCalibResult:
    """Estimates (moment-matched over the bank), 99 % bounds, and the history per frame."""

    mean: np.ndarray                  # [f, cx, cy, k1 (mm^-2), k2 (mm^-4)]
    bounds_99: np.ndarray             # (5, 2)
    covariance: np.ndarray            # (5, 5)
    image_size: tuple[int, int]
    pixel_size_mm: tuple[float, float]
    gaussians_initial: int
    gaussians_left: int
    history: SelfCalibHistory
    warnings: list = field(default_factory=list)
    # The verdict (judge_determined): True, False, or None when not checked (a one-pass frame iterator).
    # bounds_99 are the bounds to report: the bank's widened to the restarts' estimates when
    # determined, the prior's when not; filter_bounds_99 are the bank's own.
    determined: Optional[bool] = None
    reason: str = ""
    filter_bounds_99: Optional[np.ndarray] = None
    restarts: list = field(default_factory=list)
    # The bundle adjustment over the filter's tracks (None: not run or failed, see bundle_error);
    # estimate_from says which estimate ``mean`` (and so camera() and camera.yaml) is.
    filter_mean: Optional[np.ndarray] = None
    bundle: Optional[BundleResult] = None
    bundle_cut: Optional[BundleResult] = None     # the drift check: tracks cut into pieces
    bundle_error: str = ""
    estimate_from: str = "filter"

    def line_delay_estimate(self) -> Optional[tuple[float, np.ndarray]]:
        """The line delay (s/row) the bundle adjustment estimated (no line delay given) and its 99 %
        bounds (2,), clustered plus the drift's shift like the camera's; None when not estimated."""
        ba, cut = self.bundle, self.bundle_cut
        if ba is None or ba.line_delay_s is None:
            return None
        if cut is None or cut.line_delay_s is None:
            return ba.line_delay_s, np.array([-np.inf, np.inf])
        sigma_us2 = ba.covariance_globals[5, 5] + (1e6 * (ba.line_delay_s - cut.line_delay_s)) ** 2
        half = _Z99 * np.sqrt(sigma_us2) * 1e-6
        return ba.line_delay_s, np.array([ba.line_delay_s - half, ba.line_delay_s + half])

    def _line_delay_summary(self) -> dict:
        estimate = self.line_delay_estimate()
        if estimate is None:
            return {"bundle_line_delay_s": None, "bundle_line_delay_bounds_99_s": None}
        bounds = estimate[1]
        return {"bundle_line_delay_s": float(estimate[0]),
                "bundle_line_delay_bounds_99_s": [float(b) for b in bounds] if np.all(np.isfinite(bounds)) else None}

    def bundle_bounds_99(self) -> Optional[np.ndarray]:
        """The bundle adjustment's 99 % bounds (5, 2) with the drift's systematic error
        (bundle_covariance), whether or not they are the reported ones; None without an adjustment."""
        if self.bundle is None:
            return None
        half = _Z99 * np.sqrt(np.diag(bundle_covariance(self.bundle, self.bundle_cut)))
        return np.c_[self.bundle.camera - half, self.bundle.camera + half]

    @property
    def frames_processed(self) -> int:
        return len(self.history)

    @property
    def frames_per_s(self) -> float:
        return self.history.frames_per_s

    @property
    def collapse_frame(self) -> Optional[int]:
        """The first frame with one Gaussian left (None if more remain)."""
        return self.history.collapse_frame

    def camera(self) -> _core.CameraModel:
        f, cx, cy, k1, k2 = self.mean
        return _core.CameraModel("civera-radial", [f, cx, cy, k1, k2], self.image_size[0], self.image_size[1],
                                 pixel_size_mm=self.pixel_size_mm)

    def summary_dict(self) -> dict:
        out = {name: float(v) for name, v in zip(PARAM_NAMES, self.mean)}
        for i, name in enumerate(PARAM_NAMES):
            out[f"{name}_bounds_99"] = [float(self.bounds_99[i, 0]), float(self.bounds_99[i, 1])]
        out.update(image_size=list(self.image_size), pixel_size_mm=list(self.pixel_size_mm),
                   frames_processed=self.frames_processed, gaussians_initial=self.gaussians_initial,
                   gaussians_left=self.gaussians_left, frames_per_s=self.frames_per_s,
                   collapse_frame=self.collapse_frame, warnings=list(self.warnings),
                   determined=self.determined, reason=self.reason,
                   filter_bounds_99=None if self.filter_bounds_99 is None else self.filter_bounds_99.tolist(),
                   restarts=[r.summary_dict() for r in self.restarts],
                   estimate_from=self.estimate_from,
                   filter=None if self.filter_mean is None else dict(zip(PARAM_NAMES, map(float, self.filter_mean))),
                   bundle=None if self.bundle is None else self.bundle.summary_dict(),
                   bundle_tracks_cut=None if self.bundle_cut is None else self.bundle_cut.summary_dict(),
                   bundle_bounds_99=None if self.bundle is None else self.bundle_bounds_99().tolist(),
                   bundle_error=self.bundle_error,
                   **self._line_delay_summary(),
                   max_map_size=int(self.history.map_size.max()) if len(self.history) else 0,
                   history=self.history.summary_dict())
        return out


@dataclass
class GrayFrames:
    """The readable frames of a video or image folder: ``frames`` yields (time s, grayscale image)."""

    frames: Iterator[tuple[float, np.ndarray]]
    image_size: tuple[int, int]
    timestamps_from: str                 # how the times were obtained (rscalib.io.video.FrameSource)
    frame_count_estimate: Optional[int]


def read_gray_frames(source) -> GrayFrames:
    """Open a video file or image folder (:func:`rscalib.io.video.open_source`); its image size is
    that of the first readable frame. Unreadable frames are left out."""
    opened = open_source(source)
    check_source_memory(opened)   # from the headers: a huge frame is refused before it is decoded
    frames = opened.frames(gray=True)
    first = next(frames, None)
    while first is not None and first.image is None:
        first = next(frames, None)
    if first is None:
        raise InputError(f"{source}: no readable frames")
    height, width = first.image.shape[:2]

    def readable():
        yield first.time_s, first.image
        for frame in frames:
            if frame.image is not None:
                yield frame.time_s, frame.image

    return GrayFrames(readable(), (width, height), opened.timestamps_source, opened.frame_count_estimate)


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


def _prior_bounds(initial, image_size: tuple[int, int]) -> np.ndarray:
    """What is known without the data (5, 2): the 99 % range of the initial mixture per parameter,
    the principal point's widened to UNDETERMINED_PP_HALF_WIDTH of the image diagonal."""
    sigma = np.sqrt(np.diagonal(initial.covs, axis1=1, axis2=2))
    bounds = np.c_[np.min(initial.means - _Z99 * sigma, axis=0), np.max(initial.means + _Z99 * sigma, axis=0)]
    half = UNDETERMINED_PP_HALF_WIDTH * float(np.hypot(*image_size))
    centre = 0.5 * (bounds[1:3, 0] + bounds[1:3, 1])
    bounds[1:3, 0] = np.minimum(bounds[1:3, 0], centre - half)
    bounds[1:3, 1] = np.maximum(bounds[1:3, 1], centre + half)
    return bounds


def judge_determined(mean: np.ndarray, bounds_99: np.ndarray, gaussians_left: int, restarts: list,
                     image_size: tuple[int, int], prior_bounds: np.ndarray
                     ) -> tuple[Optional[bool], str, np.ndarray]:
    """(determined, reason, bounds to report). Determined: one Gaussian left and every restart
    ending within DETERMINED_MAX_CONTRACTION of their starting difference in f, and within
    DETERMINED_PP_TOLERANCE x the image diagonal of ``mean`` in (cx, cy); the bounds then cover the
    restarts' estimates too. Not determined: the prior's
    bounds. No restarts: None, the bank's bounds."""
    if gaussians_left > 1:
        return False, (f"{gaussians_left} Gaussians remain: the sequence did not single out one calibration"), \
            prior_bounds.copy()
    if not restarts:
        return None, "not checked: the frames could be read only once (no restarts)", bounds_99.copy()
    f0s = [r.f0 for r in restarts]
    f_ends = [float(r.mean[0]) for r in restarts]
    contraction = (max(f_ends) - min(f_ends)) / max(max(f0s) - min(f0s), 1e-9)
    pp_spread = max(float(np.max(np.abs(r.mean[1:3] - mean[1:3]))) for r in restarts)
    pp_tol = DETERMINED_PP_TOLERANCE * float(np.hypot(*image_size))
    ends = ", ".join(f"from f {r.f0:.0f} px to {r.mean[0]:.1f} px" for r in restarts)
    if contraction > DETERMINED_MAX_CONTRACTION or pp_spread > pp_tol:
        return False, (f"the answer depends on where the filter starts (single EKFs restarted {ends}: "
                       f"{contraction:.2f} of their starting difference remains, principal points "
                       f"{pp_spread:.1f} px from the bank's {mean[1]:.1f}, {mean[2]:.1f}): the data do not "
                       "determine the calibration (little rotation or parallax?)"), prior_bounds.copy()
    bounds = bounds_99.copy()
    for r in restarts:
        bounds[:, 0] = np.minimum(bounds[:, 0], r.mean)
        bounds[:, 1] = np.maximum(bounds[:, 1], r.mean)
    return True, (f"one Gaussian left; single EKFs restarted {ends} ({contraction:.2f} of their starting "
                  "difference remains)"), bounds


def bundle_covariance(ba: BundleResult, cut: Optional[BundleResult]) -> np.ndarray:
    """The reported covariance of the adjusted camera (5, 5): clustered by track and keyframe, plus the
    squared shift to the adjustment over tracks cut into pieces (the drift's systematic error) on the
    diagonal; without the cut adjustment, infinite."""
    if cut is None:
        return np.full((5, 5), np.inf)
    return ba.covariance_clustered + np.diag((ba.camera - cut.camera) ** 2)


def _impossible_readout(ba: BundleResult, image_height: Optional[int]) -> bool:
    interval = ba.extra.get("frame_interval_s")
    if ba.line_delay_s is None or image_height is None or not interval:
        return False
    least = min(abs(b) for b in ba.line_delay_bounds_99_s) if np.prod(ba.line_delay_bounds_99_s) > 0 else 0.0
    return least * image_height > MAX_READOUT_FRAMES * interval


def judge_bundle(ba: Optional[BundleResult], cut: Optional[BundleResult], error: str, prior_bounds: np.ndarray,
                 max_f_half_width: float = DETERMINED_F_HALF_WIDTH, image_height: Optional[int] = None
                 ) -> tuple[bool, str, np.ndarray]:
    """(determined, reason, bounds to report) from the bundle adjustment ``ba`` and the same over
    tracks cut into pieces ``cut``: determined when it converged over >= MIN_BUNDLE_POINTS tracks and
    the 99 % interval of f from bundle_covariance is within +-``max_f_half_width`` of f; the bounds
    are then that interval for all five. Not determined: the prior's bounds, widened to include the
    estimate. With the line delay estimated (and ``image_height`` given), a readout of the rows that
    must take longer than MAX_READOUT_FRAMES frame intervals is no rolling shutter: the model does not
    fit the data, not determined either."""
    if ba is None:
        return False, f"the bundle adjustment failed ({error})", prior_bounds.copy()
    f = float(ba.camera[0])
    half_all = _Z99 * np.sqrt(np.diag(bundle_covariance(ba, cut)))
    reported = np.c_[ba.camera - half_all, ba.camera + half_all]
    lo, hi = reported[0]
    half = 0.5 * float(hi - lo) / f
    spread = (f"f {f:.1f} px, 99 % [{lo:.1f}, {hi:.1f}] (+-{100 * half:.1f} %: clustered by feature track and "
              "keyframe, plus the tracks' drift)")
    problem = ""
    if ba.status <= 0 and not ba.step_sigma <= BUNDLE_STEP_SIGMA:
        # A block of keyframes collapsing with its points (docs/sog.md §21) leaves near-singular normal
        # equations and an astronomic step: say so rather than print 1e80.
        far = f"{ba.step_sigma:.2f} sigma" if ba.step_sigma < 1e3 else "over 1000 sigma (near-singular normal equations)"
        problem = f"the bundle adjustment did not converge ({ba.message}; the camera is still {far} from the minimum)"
    elif ba.points < MIN_BUNDLE_POINTS:
        problem = (f"only {ba.points} feature tracks span 3 or more keyframes (>= {MIN_BUNDLE_POINTS} needed for "
                   "a bound; a textured scene seen for longer?)")
    elif cut is None:
        problem = f"the drift check (the adjustment over tracks cut into pieces) failed ({error})"
    elif _impossible_readout(ba, image_height):
        lo, hi = ba.line_delay_bounds_99_s
        problem = (f"the adjustment's line delay ({1e6 * ba.line_delay_s:.1f} us/row, 99 % [{1e6 * lo:.1f}, "
                   f"{1e6 * hi:.1f}]) reads the {image_height} rows in more than {MAX_READOUT_FRAMES:g} frame "
                   f"intervals ({1e3 * ba.extra['frame_interval_s']:.1f} ms): the model does not fit (moving "
                   "objects, zoom, or stabilisation in the video?)")
    elif not np.all(np.isfinite(reported)) or not half <= max_f_half_width:
        problem = (f"the data pin f only to +-{100 * half:.1f} % (bundle adjustment {spread}; determined needs "
                   f"+-{100 * max_f_half_width:g} %): little rotation, or a mostly sideways motion?")
    if problem:
        bounds = prior_bounds.copy()
        bounds[:, 0] = np.minimum(bounds[:, 0], ba.camera)
        bounds[:, 1] = np.maximum(bounds[:, 1], ba.camera)
        return False, problem, bounds
    return True, (f"bundle adjustment over {ba.points} tracks and {ba.keyframes} keyframes: {spread}, "
                  f"residual {ba.sigma_px:.2f} px"), reported


def map_size_bound(options: _core.SogOptions, min_visible: int, max_new_per_frame: int,
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
         line_delay_s: float = 0.0, record: bool = False
         ) -> tuple[_core.SogBank, SelfCalibHistory, ImageFrontEnd, Optional[TrackRecorder]]:
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


def self_calibrate(frames, image_size: tuple[int, int], *,
                   pixel_size_mm=PAPER_PIXEL_SIZE_MM, options: Optional[_core.SogOptions] = None,
                   front_end: Union[FrontEndOptions, ImageFrontEnd, None] = None, grid: Optional[dict] = None,
                   max_frames: Optional[int] = None, progress: ProgressArg = None,
                   expected_frames: Optional[int] = None,
                   on_frame: Optional[Callable[[int, _core.SogBank, _core.SogUpdateReport], None]] = None,
                   restarts: bool = True, line_delay_s: float = 0.0, bundle: bool = True,
                   max_f_half_width: float = DETERMINED_F_HALF_WIDTH) -> SelfCalibResult:
    """Run the SOG bank over `frames`: an iterable of (time_s, image), grayscale or BGR uint8, or a
    callable returning a fresh such iterable (then the frames are read again for the restarts);
    an image of None (unreadable) is skipped.

    pixel_size_mm: the sensor's pixel pitch (the distortion model's radii are in mm);
    grid: keyword arguments of rscalib.selfcalib.prior.initial_bank (ranges, counts);
    front_end: the image front end's options (for 320 px wide images, scaled to this size) or a
    ready :class:`ImageFrontEnd` (then no restarts);
    progress: False/None, True (a progress bar on stderr) or a callable(done, total), with
    `expected_frames` the bar's total when `max_frames` is not given;
    on_frame(k, bank, report) is called after every processed frame of the bank's pass;
    bundle: refine with a bundle adjustment over the filter's tracks (bundle.bundle_adjust), which is
    then the estimate and judges "determined" (judge_bundle, f's 99 % interval within
    +-``max_f_half_width``); False: the filter's estimate, judged by restarts;
    restarts: without the bundle adjustment, check that the data determine the answer
    (judge_determined) when the frames can be read again;
    line_delay_s: the sensor's line delay (s/row; e.g. from `rscalib linedelay`), > 0 to compensate
    the rolling shutter in every measurement (rolling_shutter.RollingShutterCorrection), 0: none."""
    if not (np.isfinite(line_delay_s) and line_delay_s >= 0):
        raise InputError(f"the line delay must be 0 or a positive number of s/row, not {line_delay_s!r}")
    width, height = int(image_size[0]), int(image_size[1])
    options = default_options() if options is None else options
    first_frames, factory = _frame_factory(frames)
    fe_options = front_end.options if isinstance(front_end, ImageFrontEnd) else front_end
    initial = initial_bank(width, height, pixel_size_mm, **(grid or {}))
    search = fe_options or FrontEndOptions()
    features = map_size_bound(options, search.min_visible, search.max_new_per_frame,
                              _frame_count(frames, max_frames, expected_frames))
    needed = predicted_memory_bytes(len(initial), features, (width, height))
    check_memory(needed, f"self-calibration with {len(initial)} Gaussians, up to {features} map features and "
                         f"{width}x{height} frames (Gaussians x (18 + 6 x features)^2 x 8 B x {FILTER_MEMORY_FACTOR} "
                         "+ the frame)")
    per_pass = max_frames if max_frames is not None else expected_frames
    if not (np.isfinite(max_f_half_width) and max_f_half_width > 0):
        raise InputError(f"the half-width of f for 'determined' must be positive, not {max_f_half_width!r}")
    checking = restarts and not bundle and factory is not None and not isinstance(front_end, ImageFrontEnd)
    total = None if per_pass is None else per_pass * (3 if checking else 1)
    with Progress(progress, total, "self-calibrating") as bar:
        def each_frame(k: int, running: _core.SogBank, report: _core.SogUpdateReport) -> None:
            bar.update(k + 1, f"f {running.calibration_mean[0]:.1f} px, {running.num_gaussians} Gaussians")
            if on_frame is not None:
                on_frame(k, running, report)

        bank, history, source, recorder = _run(first_frames, width, height, pixel_size_mm, options, front_end,
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

                single, _, _, _ = _run(factory(), width, height, pixel_size_mm, options, fe_options, one, max_frames,
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
    prior = _prior_bounds(initial, (width, height))
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


def civera_to_opencv(camera: _core.CameraModel, samples: int = 40) -> tuple[_core.CameraModel, float]:
    """OpenCV pinhole-radtan (k1, k2, k3; no tangential terms) closest to a civera-radial camera:
    linear least squares of the radial factor over a grid of image pixels. Returns the camera and
    the largest pixel difference between the two models over that grid."""
    if camera.model != "civera-radial":
        raise InputError("civera_to_opencv needs a civera-radial camera")
    f, cx, cy, _, _ = camera.params
    w, h = camera.width, camera.height
    us, vs = np.meshgrid(np.linspace(0, w - 1, samples), np.linspace(0, h - 1, samples))
    uv_d = np.c_[us.ravel(), vs.ravel()]
    uv_u = camera.undistort(uv_d)
    x_u = (uv_u - [cx, cy]) / f
    x_d = (uv_d - [cx, cy]) / f
    r2 = np.sum(x_u ** 2, axis=1)
    keep = r2 > 1e-12
    # x_d = x_u (1 + K1 r2 + K2 r2^2 + K3 r2^3): linear in K for both coordinates
    a = np.vstack([x_u[keep, j:j + 1] * np.c_[r2[keep], r2[keep] ** 2, r2[keep] ** 3] for j in (0, 1)])
    b = np.concatenate([x_d[keep, j] - x_u[keep, j] for j in (0, 1)])
    k, *_ = np.linalg.lstsq(a, b, rcond=None)
    opencv = _core.CameraModel("pinhole-radtan", [f, f, cx, cy, k[0], k[1], 0.0, 0.0, k[2]], w, h)
    points = np.c_[x_u, np.ones(len(x_u))]
    error = np.linalg.norm(opencv.project(points) - uv_d, axis=1)
    return opencv, float(np.nanmax(error))
