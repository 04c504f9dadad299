"""Rolling-shutter line-delay calibration (Oth et al. 2013 §3-4; docs/formulation.md §1-9).

Pipeline: per-frame GS PnP -> rotation-vector unwrapping (eq. 22) -> smoothing spline with
deliberately few uniform knots -> joint Ceres solve of trajectory and line delay -> adaptive
knots (split every segment with J_j >= 2 N_j, §4.2) -> repeat until nothing splits.
The maths and the choices made where the paper is silent: docs/formulation.md.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Union

import numpy as np

from .. import checks
from .._core import BSpline, CameraModel, RsSolverOptions, fit_bspline, solve_line_delay, unwrap_rotation_vectors
from ..errors import InputError
from ..observations import Observations
from ..readout import check_rows_read
from . import noise
from .common import (
    SOLVER_THREADS,
    IntrinsicsPrior,
    assess_noise_and_determinacy,
    check_segment_count,
    check_solve_memory,
    choose_pixel_sigma,
    default_intrinsics_prior,
    initial_values,
    load_intrinsics_prior,
    seed_poses,
    solve_warnings,
    summary_fields,
)
from .options import LineDelayOptions, LocalizeOptions
from .pnp import FramePoses

# diag(Q) of the acceleration prior, [m^2/s^3 x3, rad^2/s^3 x3]: a hand-held camera's
# acceleration spectral density (~2 m/s^2, ~20 rad/s^2 over ~0.3 s). The paper's values are
# kept as PAPER_MOTION_PRIOR_Q; with errors standardised in pixels they bias d (docs/formulation.md).
DEFAULT_MOTION_PRIOR_Q = (1.0, 1.0, 1.0, 1e2, 1e2, 1e2)
PAPER_MOTION_PRIOR_Q = (1e-5, 1e-5, 1e-5, 1e-2, 1e-2, 1e-2)
# A segment splits when J_j >= 2 N_j + SPLIT_MARGIN_SIGMAS sqrt(4 N_j); 0 is the paper's rule, which
# also splits ~1/3 of well-modelled segments by chance (docs/formulation.md §7).
SPLIT_MARGIN_SIGMAS = 2.0
# Rounds before the last are re-solved after knot insertion anyway: solve them loosely.
_ROUND_MAX_ITERATIONS = 30
_ROUND_FUNCTION_TOLERANCE = 1e-6
_FINAL_MAX_ITERATIONS = 100
_FINAL_FUNCTION_TOLERANCE = 1e-9
# A round that splits at most this fraction of the segments is followed by the final (tight) round:
# after such a round (~7 % split on hand-held videos) the next splits at most a few per mille.
_FINAL_AFTER_SPLITS = 0.1
# The fraction of well-modelled segments over the split threshold by chance (the normal tail beyond
# SPLIT_MARGIN_SIGMAS: 2.3 %). After the first round, a round that splits no more than that ends the
# adaptation: a further round would chase noise (docs/formulation.md §7).
CHANCE_SPLIT_FRACTION = 0.5 * math.erfc(SPLIT_MARGIN_SIGMAS / math.sqrt(2.0))
# ... on a trajectory that fits as a whole (J/2N at most this): where the errors are larger than the
# noise model says, the few segments over the threshold are misfit, not chance (15 fps shake videos).
CHANCE_STOP_MAX_COST = 1.1
# The whole video's first round, weighted by its halves' fixed-pattern noise, is final when the weights
# its own residuals give differ from those by at most this fraction (else they are used for a polish).
START_WEIGHTS_TOLERANCE = 0.05


@dataclass
class RoundRecord:
    """One solve of the knot-adaptation loop."""

    round: int
    segments: int
    line_delay_s: float
    line_delay_std_s: float
    normalised_cost: float
    rms_px: float
    segments_split: int
    segments_at_cap: int              # over their expected cost but too short to halve (min_segment_s)
    iterations: int
    solve_time_s: float


@dataclass
class LineDelayResult:
    """Result of calibrate_line_delay / localize. Times in s, pixels in px."""

    line_delay_s: float
    line_delay_std_s: float
    readout_time_s: float
    rows: int
    trajectory: BSpline
    knots: np.ndarray                 # breakpoints of the final spline
    rms_px: float
    normalised_cost: float            # J / 2N (1 when the noise model is right)
    pixel_sigma: float
    pixel_sigma_source: str           # "user" | "grid third differences" | "residuals"
    converged: bool
    determined: bool                  # False: the data do not determine the line delay
    warnings: list[str]
    history: list[RoundRecord]
    frames_total: int
    frames_used: int
    observations: int
    initial_line_delay_s: float
    solve_time_s: float
    segment_cost: np.ndarray          # J_j of the final segments
    segment_count: np.ndarray         # N_j
    observation_time_s: np.ndarray    # (M,) t_i + v d
    residual_px: np.ndarray           # (M, 2) y - pi(...)
    image_velocity_px_s: np.ndarray   # (M, 2) d(uv)/dt at the final estimate (the solver's, for A)
    standardised_sq: np.ndarray       # (M,) squared standardised error
    frame_poses: FramePoses           # the GS PnP initial guess / baseline
    used_observations: Observations = field(repr=False)
    # The noise model (docs/formulation.md §8): per-observation sigma (px) used in the final solve,
    # the fixed-pattern part, the frame-to-frame correlation and the resulting inflation of sigma_d.
    observation_sigma_px: Optional[np.ndarray] = field(default=None, repr=False)
    noise: dict = field(default_factory=dict)
    solver_line_delay_std_s: float = float("nan")   # sigma_d of the solver, before any inflation
    self_check: Optional[dict] = None                # the halves' check (linedelay.selfcheck), if run
    # --refine-intrinsics (docs/formulation.md §14): the refined camera and the intrinsics' summary
    # (start, estimate, sigma, prior, covariance of [d, intrinsics]); None when the camera was known.
    camera: Optional[CameraModel] = field(default=None, repr=False)
    intrinsics: Optional[dict] = None

    @property
    def num_segments(self) -> int:
        return len(self.knots) - 1

    def summary_dict(self) -> dict:
        """JSON-ready fields (the result.json of `rscalib linedelay`, docs/architecture.md)."""
        extra = {"solver_line_delay_std_s": _finite_or_none(self.solver_line_delay_std_s),
                 "noise": self.noise, "self_check": self.self_check}
        if self.intrinsics is not None:
            extra["intrinsics"] = self.intrinsics
        return summary_fields(self, len(self.knots)) | extra | {
            "history": [vars(r) | {"line_delay_std_s": r.line_delay_std_s if math.isfinite(r.line_delay_std_s) else None}
                        for r in self.history],
        }


def _finite_or_none(x: float) -> Optional[float]:
    return float(x) if math.isfinite(x) else None


def _solver_options(pixel_sigma: float, *, estimate_line_delay: bool, standardise_errors: bool,
                    use_motion_prior: bool, robust_loss: str, compute_covariance: bool,
                    threads: int = SOLVER_THREADS) -> RsSolverOptions:
    options = RsSolverOptions()
    options.pixel_sigma = float(pixel_sigma)
    options.estimate_line_delay = estimate_line_delay
    options.standardise_errors = standardise_errors
    options.use_motion_prior = use_motion_prior
    options.motion_prior_q = np.asarray(DEFAULT_MOTION_PRIOR_Q, dtype=np.float64)
    options.robust_loss = robust_loss
    options.num_threads = int(threads)
    options.compute_covariance = compute_covariance
    return options


def _set_tolerance(options: RsSolverOptions, *, final: bool, covariance: bool) -> None:
    """Loose for the knot-adaptation rounds, tight for the final solve; sigma_d only when asked."""
    options.max_iterations = _FINAL_MAX_ITERATIONS if final else _ROUND_MAX_ITERATIONS
    options.function_tolerance = _FINAL_FUNCTION_TOLERANCE if final else _ROUND_FUNCTION_TOLERANCE
    options.compute_covariance = covariance


def initial_trajectory(observations: Observations, poses: FramePoses, line_delay_s: float,
                       segments: int, t_begin: float, t_end: float,
                       acceleration_weight: float = 1e-6) -> BSpline:
    """Smoothing spline [p; phi] through the per-frame PnP poses (unwrapped rotation vectors),
    each placed at its frame's mean observation time t_i + mean(v) d."""
    frames = np.flatnonzero(poses.ok)
    if len(frames) < 4:
        raise InputError(f"only {len(frames)} frames have a pose from PnP; at least 4 are needed")
    mean_row = np.zeros(observations.num_frames)
    counts = np.bincount(observations.frame_index, minlength=observations.num_frames)
    sums = np.bincount(observations.frame_index, weights=observations.uv[:, 1], minlength=observations.num_frames)
    mean_row[counts > 0] = sums[counts > 0] / counts[counts > 0]
    times = observations.frame_times_s[frames] + mean_row[frames] * line_delay_s
    rotation = unwrap_rotation_vectors(poses.rotation_vector[frames])
    samples = np.c_[poses.translation[frames], rotation]
    times = np.clip(times, t_begin, t_end)
    knots = BSpline.clamped_knots(np.linspace(t_begin, t_end, segments + 1))
    return fit_bspline(knots, times, samples, acceleration_weight=[acceleration_weight])


def _segment_samples(breakpoints: np.ndarray) -> np.ndarray:
    # 8 samples a segment: more than the 4 that determine a cubic piece
    return np.unique(np.concatenate([np.linspace(a, b, 8) for a, b in zip(breakpoints[:-1], breakpoints[1:])]))


def restricted_trajectory(trajectory: BSpline, t_begin: float, t_end: float, min_segment_s: float) -> BSpline:
    """`trajectory` on [t_begin, t_end] with its breakpoints there (those closer than min_segment_s
    to an end dropped), fitted to samples of it: where the knots are the same it is the same curve."""
    breaks = np.asarray(trajectory.breakpoints)
    inside = breaks[(breaks > t_begin + min_segment_s) & (breaks < t_end - min_segment_s)]
    breakpoints = np.r_[t_begin, inside, t_end]
    times = _segment_samples(breakpoints)
    samples = trajectory.evaluate(np.clip(times, trajectory.t_begin, trajectory.t_end))
    return fit_bspline(BSpline.clamped_knots(breakpoints), times, samples)


def joined_trajectory(pieces: list[BSpline], acceleration_weight: float = 1e-9) -> BSpline:
    """One spline through consecutive trajectories (e.g. the self-check's halves): all their
    breakpoints, fitted to samples of each on its own span; a gap between them is bridged smoothly (the
    acceleration weight: just enough to determine control points no sample reaches)."""
    breaks = np.unique(np.concatenate([np.asarray(p.breakpoints) for p in pieces]))
    times = [_segment_samples(np.asarray(p.breakpoints)) for p in pieces]
    samples = np.vstack([p.evaluate(t) for p, t in zip(pieces, times)])
    return fit_bspline(BSpline.clamped_knots(breaks), np.concatenate(times), samples,
                             acceleration_weight=[acceleration_weight])


def _split_segments(trajectory: BSpline, segment_cost, segment_count, min_segment_s: float,
                    margin_sigmas: float, correlation: float = 0.0) -> tuple[list[float], int]:
    """Midpoints of the segments with J_j >= 2 N_j + margin * sqrt(4 N_j c) (paper §4.3 step 5
    with margin 0) that are long enough to halve, and the number of segments over that
    threshold but already at the density cap. c = (1 + rho²) / (1 - rho²) is the variance
    inflation of a sum of squares of errors correlated rho from frame to frame (1 when independent)."""
    breaks = trajectory.breakpoints
    rho = min(max(correlation, 0.0), noise.MAX_CORRELATION)
    spread = (1.0 + rho * rho) / (1.0 - rho * rho)
    new_knots, at_cap = [], 0
    for j, (cost, count) in enumerate(zip(segment_cost, segment_count)):
        if count > 0 and cost >= 2.0 * count + margin_sigmas * math.sqrt(4.0 * count * spread):
            if breaks[j + 1] - breaks[j] >= 2.0 * min_segment_s:
                new_knots.append(0.5 * (breaks[j] + breaks[j + 1]))
            else:
                at_cap += 1
    return new_knots, at_cap


def calibrate_line_delay(observations: Observations, camera: CameraModel,
                         options: Optional[LineDelayOptions] = None, *,
                         line_delay0_s: Optional[float] = None,
                         frame_poses: Optional[FramePoses] = None,
                         start_trajectory: Optional[BSpline] = None,
                         progress: Optional[Callable[[RoundRecord], None]] = None,
                         solver_threads: Optional[int] = None,
                         start_fixed_pattern_px: Optional[float] = None) -> LineDelayResult:
    """Estimate the line delay d (s/row) and the continuous-time trajectory (Oth et al. 2013 §3-4):
    the solve alone, on detections already made. The job with its self-check, verdict and files is
    :func:`rscalib.calibrate_video`, which calls this.

    observations: detected target points with frame timestamps; camera: known intrinsics (the start
    with options.refine_intrinsics). options (LineDelayOptions; None: the defaults) read here: rows,
    pixel_sigma_px, robust_loss, max_rounds, min_segment_s, uniform_knots, standardise_errors,
    motion_prior, refine_intrinsics and intrinsics_prior (a common.IntrinsicsPrior here; default
    common.default_intrinsics_prior: sigma_f 2 %, sigma_c 10 px; the result's `camera` and
    `intrinsics` hold the outcome, docs/formulation.md §14). The noise model is docs/formulation.md §8.
    line_delay0_s: the start of d (default 1 / (fps rows)).
    frame_poses: pnp.per_frame_pnp(observations, camera) when already computed (the self-check's
    halves take theirs from the whole video's: FramePoses.of_frames).
    start_trajectory: a solved trajectory to start from instead of the PnP smoothing spline (the whole
    video starts from its self-check halves' joined trajectory, with line_delay0_s their mean d): its
    knots inside this data's time span are the first round's, and the adaptation goes on from there
    (docs/formulation.md §9).
    progress: called after each round.
    start_fixed_pattern_px: with start_trajectory, the noise model's fixed-pattern part (§8) found where
    it was solved (the halves' mean): the errors are weighted by it from the first round, which is then
    the final one (tight, with sigma_d) when its own residuals give weights within START_WEIGHTS_TOLERANCE
    of those, and ends the adaptation unless it splits more than chance would.
    solver_threads: the solver's threads (default SOLVER_THREADS, the machine's 2 cores; the self-check's
    halves, solved side by side, take 1 each: the same numbers, less contention).
    """
    threads = SOLVER_THREADS if solver_threads is None else checks.whole(solver_threads, "solver_threads", 1, 64)
    return _run(observations, camera, options or LineDelayOptions(), estimate=True, line_delay_s=line_delay0_s,
                frame_poses=frame_poses, start_trajectory=start_trajectory, progress=progress, threads=threads,
                start_fixed_pattern_px=start_fixed_pattern_px)


def localize(observations: Observations, camera: CameraModel, line_delay_s: float,
             options: Union[None, LineDelayOptions, LocalizeOptions] = None, *,
             progress: Optional[Callable[[RoundRecord], None]] = None) -> LineDelayResult:
    """Continuous-time trajectory with a known line delay (paper §5.1); options as
    calibrate_line_delay's (rows, pixel_sigma_px, robust_loss, max_rounds). The result's frame_poses
    hold the per-frame GS PnP baseline."""
    if not np.isfinite(line_delay_s):
        raise InputError("line_delay_s must be a finite number")
    given = options or LocalizeOptions()
    if isinstance(given, LocalizeOptions):   # the solve's options: the method's, with the localization's own
        given = LineDelayOptions(rows=given.rows, pixel_sigma_px=given.pixel_sigma_px,
                                 robust_loss=given.robust_loss, max_rounds=given.max_rounds, self_check=False)
    return _run(observations, camera, given, estimate=False, line_delay_s=float(line_delay_s), progress=progress)


def _run(observations, camera, options, *, estimate, line_delay_s=None, frame_poses=None, start_trajectory=None,
         progress=None, threads=SOLVER_THREADS, start_fixed_pattern_px=None) -> LineDelayResult:
    check_rows_read(options.rows, observations.image_size[1])
    intrinsics_prior = options.intrinsics_prior if options.refine_intrinsics else None
    if intrinsics_prior is not None and not isinstance(intrinsics_prior, IntrinsicsPrior):
        intrinsics_prior = load_intrinsics_prior(intrinsics_prior, camera)
    started = time.perf_counter()
    warnings: list[str] = []
    start = _start(observations, camera, options, line_delay_s, frame_poses, start_trajectory, warnings)
    adaptive_knots = options.uniform_knots is None
    rounds = _Rounds(start, camera, options, estimate=estimate, threads=threads, progress=progress)
    prior = _set_intrinsics_prior(rounds.solver, camera, intrinsics_prior) if options.refine_intrinsics else None
    # knots adapted already: chance-level splits end the adaptation from the first round on
    adapted_start = start_trajectory is not None and adaptive_knots
    final, adapted = rounds.adapt(adapted_start, start_fixed_pattern_px)
    if adaptive_knots and not adapted:
        warnings.append(f"knot adaptation stopped at the round cap ({options.max_rounds}) with segments still "
                        "above their expected cost")
    if not (final and adapted):
        rounds.polish()
    summary, structure, history, d = rounds.summary, rounds.structure, rounds.history, rounds.d
    solver_std = summary.line_delay_std_s if estimate else 0.0
    # correlated errors carry less information than their number says (AR(1) effective sample size)
    std = solver_std * structure.inflation if estimate else 0.0
    history[-1].line_delay_s = d
    history[-1].line_delay_std_s = std

    cost, sigma, determined = assess_noise_and_determinacy(summary, start.sigma, start.sigma_source,
                                                           start.nominal_delay_s, warnings, estimate=estimate,
                                                           std_s=std)
    noise_summary = {"model": "per frame" if rounds.per_frame else "one sigma for the video",
                     "white_sigma_px": {"median": float(np.median(rounds.white)),
                                        "p10": float(np.percentile(rounds.white, 10)),
                                        "p90": float(np.percentile(rounds.white, 90))},
                     "fixed_pattern_px": structure.fixed_pattern_px,
                     "frame_to_frame_correlation": structure.correlation,
                     "sigma_d_inflation": structure.inflation}
    _fit_warnings(warnings, summary, structure, history[-1], cost, sigma, options, start.min_segment_s,
                  estimate=estimate, adaptive_knots=adaptive_knots)
    solve_warnings(summary, warnings)
    intrinsics = None
    if options.refine_intrinsics:
        intrinsics = _intrinsics_summary(summary, camera, rounds.camera, prior,
                                         structure.inflation if estimate else 1.0, warnings)

    trajectory, used = rounds.trajectory, start.used
    return LineDelayResult(
        line_delay_s=d, line_delay_std_s=std, readout_time_s=d * start.rows, rows=start.rows,
        trajectory=trajectory, knots=np.asarray(trajectory.breakpoints), rms_px=summary.rms_px,
        normalised_cost=cost, pixel_sigma=sigma, pixel_sigma_source=start.sigma_source,
        converged=bool(summary.converged), determined=determined, warnings=warnings, history=history,
        frames_total=observations.num_frames, frames_used=used.num_frames, observations=summary.num_error_terms,
        initial_line_delay_s=start.d, solve_time_s=time.perf_counter() - started,
        segment_cost=np.asarray(summary.segment_cost), segment_count=np.asarray(summary.segment_count),
        observation_time_s=np.asarray(summary.observation_time_s), residual_px=np.asarray(summary.residual_px),
        image_velocity_px_s=np.asarray(summary.image_velocity_px_s),
        standardised_sq=np.asarray(summary.standardised_sq), frame_poses=start.used_poses, used_observations=used,
        observation_sigma_px=rounds.obs_sigma, noise=noise_summary, solver_line_delay_std_s=solver_std,
        camera=rounds.camera if options.refine_intrinsics else None, intrinsics=intrinsics)


@dataclass
class _Start:
    """What a solve starts from: the rows, frame rate, nominal and starting d, the shortest segment,
    the frames with a PnP pose, the pixel sigma and the first round's trajectory."""

    rows: int
    fps: float
    nominal_delay_s: float
    d: float
    min_segment_s: float
    used: Observations
    used_poses: FramePoses
    sigma: float
    sigma_source: str
    trajectory: BSpline


def _start(observations: Observations, camera: CameraModel, options: LineDelayOptions,
           line_delay_s: Optional[float], frame_poses: Optional[FramePoses], start_trajectory: Optional[BSpline],
           warnings: list) -> _Start:
    rows, fps, nominal_delay_s, d = initial_values(observations, camera, options.rows, line_delay_s)
    min_segment_s, num_segments = options.min_segment_s, options.uniform_knots
    if min_segment_s is None:
        # Halving stops below 2 * min_segment_s, so segments can reach ~1 frame at 30 fps. A 2-frame
        # floor could not follow hand shake (0.5-8 Hz): J/2N ~ 75, d several % off. The floor is about
        # the motion's bandwidth, not the frame rate: at most 1/60 s, also for slow (e.g. 7 fps) cameras.
        min_segment_s = min(0.5 / fps, 1.0 / 60.0)
    check_solve_memory(len(observations.uv))
    used, used_poses = seed_poses(observations, camera, warnings, min_frames=4, poses=frame_poses)
    sigma, sigma_source = choose_pixel_sigma(used, options.pixel_sigma_px)

    t_begin = float(used.frame_times_s[0])
    t_end = float(used.frame_times_s[-1] + 1.0 / fps)  # the last frame's readout
    duration = t_end - t_begin
    # One segment per 4 frames (at least 7.5 per second): too few for hand-held motion on purpose.
    initial_segments_per_s = max(fps / 4.0, 7.5)
    check_segment_count(num_segments, used.num_frames)
    segments = int(num_segments) if num_segments else max(1, int(math.ceil(duration * initial_segments_per_s)))
    if start_trajectory is not None and num_segments is None:
        trajectory = restricted_trajectory(start_trajectory, t_begin, t_end, min_segment_s)
    else:
        trajectory = initial_trajectory(used, used_poses, d, segments, t_begin, t_end)
    return _Start(rows, fps, nominal_delay_s, d, min_segment_s, used, used_poses, sigma, sigma_source, trajectory)


class _Rounds:
    """The knot adaptation (docs/formulation.md §7) and the noise model between its solves (§8):
    white noise per frame from the grid, plus what the residuals show after each round (a fixed
    pattern per corner, frame-to-frame correlation). The trajectory, d, the camera (refined with
    --refine-intrinsics), the last solve's summary and the rounds' history are its state."""

    def __init__(self, start: _Start, camera: CameraModel, options: LineDelayOptions, *, estimate: bool,
                 threads: int, progress: Optional[Callable[[RoundRecord], None]]):
        self.options, self.estimate, self.progress = options, estimate, progress
        self.used, self.min_segment_s = start.used, start.min_segment_s
        self.adaptive_knots = options.uniform_knots is None
        self.trajectory, self.d, self.camera = start.trajectory, start.d, camera
        self.solver = _solver_options(start.sigma, estimate_line_delay=estimate,
                                      standardise_errors=options.standardise_errors,
                                      use_motion_prior=options.motion_prior, robust_loss=options.robust_loss,
                                      compute_covariance=False, threads=threads)
        self.per_frame = start.sigma_source == "grid third differences"
        used = start.used
        self.white = (noise.frame_pixel_sigma(used, start.sigma)[used.frame_index] if self.per_frame
                      else np.full(used.num_observations, start.sigma))
        self.structure = noise.ResidualStructure(0.0, 0.0, 1.0, 0)
        self.obs_sigma = self.white
        if self.per_frame:
            self.use_sigma(self.obs_sigma)
        self.args = (used.frame_times_s[used.frame_index], used.uv, used.points_w(), camera)
        self.history: list[RoundRecord] = []
        self.summary = None

    def use_sigma(self, values: np.ndarray) -> None:
        """The error weights of the next solve: per observation, or one sigma for the video."""
        if self.per_frame:
            self.solver.observation_sigma = values
        else:
            self.solver.pixel_sigma = float(values[0])

    def _solve(self) -> None:
        self.summary = solve_line_delay(*self.args, self.trajectory, self.d, self.solver)
        self.d = self.summary.line_delay_s
        if self.options.refine_intrinsics:  # the next round starts from the refined camera
            self.camera = _with_params(self.camera, self.summary.intrinsics)
            self.args = self.args[:3] + (self.camera,)

    def adapt(self, adapted_start: bool, start_fixed_pattern_px: Optional[float]) -> tuple[bool, bool]:
        """The rounds, up to options.max_rounds: (whether the last was final, whether the knots are adapted).

        Rounds are solved loosely, except the final one: tight, then sigma_d alone. A round is final when
        the round before split few segments (those rarely split again; if the final round still splits
        more than chance would, another round follows). Otherwise a polish on the final knots ends the
        solve. The first round is final only from knots already adapted and errors already weighted by the
        noise model's fixed-pattern part (the whole video from its halves): otherwise its residuals give
        that part, which weighs the errors of the rounds after it (and of sigma_d)."""
        max_rounds, trajectory = self.options.max_rounds, self.trajectory
        adapted = not self.adaptive_knots
        final = False
        if adapted_start and self.per_frame and start_fixed_pattern_px is not None \
                and np.isfinite(start_fixed_pattern_px):
            self.obs_sigma = np.sqrt(self.white ** 2 + float(start_fixed_pattern_px) ** 2)
            self.use_sigma(self.obs_sigma)
            final = True
        for round_index in range(max(1, max_rounds)):
            last_chance = round_index == max_rounds - 1
            # a final round usually ends the adaptation: sigma_d comes with it (wasted if it splits again)
            _set_tolerance(self.solver, final=final, covariance=final and self.estimate)
            self._solve()
            summary = self.summary
            cost = summary.measurement_cost / max(1, 2 * summary.num_error_terms)
            segment_cost = summary.segment_cost
            if self.per_frame:
                # what the residuals say beyond the white part; the split test sees errors weighted by it
                self.structure = noise.residual_structure(self.used, np.asarray(summary.residual_px), self.white)
                new_sigma = np.sqrt(self.white ** 2 + self.structure.fixed_pattern_px ** 2)
                sq = np.asarray(summary.standardised_sq) * (self.obs_sigma / new_sigma) ** 2
                segment_cost = _segment_sums(trajectory, np.asarray(summary.observation_time_s), sq,
                                             len(summary.segment_cost))
            new_knots, at_cap = _split_segments(trajectory, segment_cost, summary.segment_count,
                                                self.min_segment_s, SPLIT_MARGIN_SIGMAS,
                                                self.structure.correlation) if self.adaptive_knots else ([], 0)
            # splits no more than chance would make on a well-modelled trajectory end the adaptation (not in
            # the first round from PnP, whose knots are too few on purpose)
            if (round_index > 0 or adapted_start) and cost <= CHANCE_STOP_MAX_COST and \
                    len(new_knots) <= CHANCE_SPLIT_FRACTION * trajectory.num_segments:
                new_knots = []
            if round_index == 0 and final and self.per_frame and \
                    np.max(np.abs(new_sigma / self.obs_sigma - 1.0)) > START_WEIGHTS_TOLERANCE:
                final = False   # the start's weights (the halves' fixed pattern) are not this video's: re-weigh, polish
            if self.per_frame and not (final and not new_knots):  # the next solve weighs the errors by it
                self.obs_sigma = new_sigma
                self.use_sigma(self.obs_sigma)
            record = RoundRecord(round_index, trajectory.num_segments, self.d, float("nan"), cost, summary.rms_px,
                                 0 if last_chance else len(new_knots), at_cap, summary.iterations,
                                 summary.solve_time_s)
            self.history.append(record)
            if self.progress:
                self.progress(record)
            if not new_knots:
                adapted = True
                break
            if last_chance:
                break
            for t in new_knots:
                trajectory.insert_knot(t)
            final = len(new_knots) <= _FINAL_AFTER_SPLITS * trajectory.num_segments
        return final, adapted

    def polish(self) -> None:
        """The final solve at tight tolerance on the final knots, with the covariance of d."""
        _set_tolerance(self.solver, final=True, covariance=self.estimate)
        self._solve()
        if self.per_frame:
            self.structure = noise.residual_structure(self.used, np.asarray(self.summary.residual_px), self.white)
        self.history[-1].iterations += self.summary.iterations
        self.history[-1].solve_time_s += self.summary.solve_time_s


def _fit_warnings(warnings: list, summary, structure: noise.ResidualStructure, last: RoundRecord, cost: float,
                  sigma: float, options: LineDelayOptions, min_segment_s: float, *, estimate: bool,
                  adaptive_knots: bool) -> None:
    """What the residuals say about the fit, one line each: repeated errors, segments at their
    shortest that still fit badly, noise above sigma, clamped weights."""
    if estimate and structure.inflation > 1.5:
        warnings.append(f"the detection errors repeat from frame to frame (correlation {structure.correlation:.2f}: "
                        f"a nearly still board); sigma_d is widened x{structure.inflation:.1f} for it")
    if cost > 1.5 and adaptive_knots and last.segments_at_cap > 0:
        warnings.append(f"{last.segments_at_cap} trajectory segments are at the shortest allowed length "
                        f"({min_segment_s * 1e3:.1f} ms) and still fit badly: the motion is faster than the spline can "
                        "follow, so sigma_d is optimistic (lower min_segment_s, or move more smoothly)")
    if cost > 1.5:
        hint = ("outliers are down-weighted by the robust loss" if options.robust_loss != "none"
                else "or there are outliers (try robust_loss='huber')")
        warnings.append(f"normalised cost J/2N = {cost:.2f} > 1.5: the detection noise is larger than "
                        f"sigma = {sigma:.3f} px, {hint}")
    if summary.clamped_weights:
        warnings.append(f"{summary.clamped_weights} observations move down the image nearly as fast as the "
                        "shutter; their error weights were clamped")


def refit_with_intrinsics(result: LineDelayResult, camera: CameraModel, options: LineDelayOptions, *,
                          max_iterations: int) -> tuple[float, float, np.ndarray]:
    """d, J/2N and the intrinsics (the camera's layout) after at most `max_iterations` solver steps from `result`'s solution with the intrinsics
    freed under their prior (the camera check, docs/formulation.md §17): the same knots, observations and
    error weights as `result`, so only the intrinsics move d. The first step is the linearised answer to
    "how far would the camera file move d"; a few more follow its curvature. No sigma is computed."""
    used = result.used_observations
    weights = np.asarray(result.observation_sigma_px, dtype=np.float64)   # the final solve's
    solver = _solver_options(float(weights[0]), estimate_line_delay=True,
                             standardise_errors=options.standardise_errors, use_motion_prior=options.motion_prior,
                             robust_loss=options.robust_loss, compute_covariance=False)
    if result.pixel_sigma_source == "grid third differences":
        solver.observation_sigma = weights
    prior = options.intrinsics_prior
    if prior is not None and not isinstance(prior, IntrinsicsPrior):
        prior = load_intrinsics_prior(prior, camera)
    _set_intrinsics_prior(solver, camera, prior)
    solver.max_iterations = int(max_iterations)
    solver.max_outer_iterations = 1   # d moves little: no re-attachment of observations to spans
    solver.function_tolerance = _ROUND_FUNCTION_TOLERANCE
    summary = solve_line_delay(used.frame_times_s[used.frame_index], used.uv, used.points_w(), camera,
                               result.trajectory.copy(), result.line_delay_s, solver)
    return (float(summary.line_delay_s), float(summary.measurement_cost / max(1, 2 * summary.num_error_terms)),
            np.asarray(summary.intrinsics, dtype=np.float64).copy())


def _set_intrinsics_prior(options: RsSolverOptions, camera: CameraModel,
                          prior: Optional[IntrinsicsPrior]) -> IntrinsicsPrior:
    """Switches the solver to the joint refinement of the intrinsics with `prior` (default:
    common.default_intrinsics_prior) around `camera`'s parameters (docs/formulation.md §14)."""
    if prior is None:
        prior = default_intrinsics_prior(camera)
    if len(prior.mean) != len(camera.params):
        raise InputError(f"the intrinsics prior has {len(prior.mean)} parameters, the {camera.model} camera "
                         f"{len(camera.params)}")
    options.refine_intrinsics = True
    options.intrinsics_prior_mean = np.asarray(prior.mean, dtype=np.float64)
    options.intrinsics_prior_covariance = np.asarray(prior.covariance, dtype=np.float64)
    options.fixed_intrinsics = [int(i) for i in prior.fixed]
    return prior


def _with_params(camera: CameraModel, params) -> CameraModel:
    """`camera` with other parameters (same model, size and pixel size): the refined intrinsics, so a
    camera the model refuses (a focal length refined below 0: the verdict benchmark's target in
    millimetres) is said as what it is."""
    try:
        return CameraModel(camera.model, np.asarray(params, dtype=np.float64), camera.width, camera.height,
                           np.asarray(camera.pixel_size_mm, dtype=np.float64))
    except InputError as error:
        raise InputError(f"--refine-intrinsics: the refined intrinsics are not a camera ({error}): the video does not "
                         "determine them; check the target file's square size and the camera file") from None


def _intrinsics_summary(summary, start: CameraModel, refined: CameraModel, prior: IntrinsicsPrior,
                        inflation: float, warnings: list) -> dict:
    """JSON-ready: the intrinsics' start, estimate and sigma, the prior, and the covariance of
    [d, intrinsics] (s/row and the layout's units; scaled by the noise model's inflation, like sigma_d)."""
    names = list(refined.param_names)
    covariance = np.asarray(summary.line_delay_intrinsics_covariance, dtype=np.float64)
    n = len(names)
    if covariance.shape == (n + 1, n + 1):
        covariance = covariance * inflation ** 2
        std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            correlation = covariance / np.outer(std, std)
        correlation_with_d = {name: (float(c) if math.isfinite(c) else None)
                              for name, c in zip(names, correlation[0, 1:])}
        covariance_list = covariance.tolist()
    else:
        std = np.full(n + 1, np.nan)
        correlation_with_d, covariance_list = None, None
        warnings.append("the covariance of the line delay with the intrinsics could not be computed")
    start_p, refined_p = np.asarray(start.params), np.asarray(refined.params)
    prior_std = prior.std
    with np.errstate(invalid="ignore", divide="ignore"):
        shift_sigmas = np.where(prior_std > 0, (refined_p - start_p) / prior_std, 0.0)
    far = [f"{name} moved {z:+.1f} prior sigma" for name, z in zip(names, shift_sigmas) if abs(z) > 3]
    if far:
        warnings.append("the refined intrinsics are far from the given calibration (" + ", ".join(far)
                        + "): check the camera file, or that the video is of the same camera and zoom")
    return {
        "refined": True,
        "model": refined.model,
        "names": names,
        "initial": {name: float(v) for name, v in zip(names, start_p)},
        "estimate": {name: float(v) for name, v in zip(names, refined_p)},
        "std": {name: (float(s) if math.isfinite(s) else None) for name, s in zip(names, std[1:])},
        "shift_in_prior_sigma": {name: float(z) for name, z in zip(names, shift_sigmas)},
        "prior": prior.to_dict(),
        "prior_cost": float(summary.intrinsics_prior_cost),
        "correlation_with_line_delay": correlation_with_d,
        "covariance_order": ["line_delay_s"] + names,
        "covariance": covariance_list,
    }


def _segment_sums(trajectory: BSpline, times: np.ndarray, values: np.ndarray, segments: int) -> np.ndarray:
    """Sum of `values` per knot segment of the observations at `times` (NaN values skipped)."""
    breaks = np.asarray(trajectory.breakpoints)
    ok = np.isfinite(values) & np.isfinite(times)
    j = np.clip(np.searchsorted(breaks, times[ok], side="right") - 1, 0, segments - 1)
    return np.bincount(j, weights=values[ok], minlength=segments)
