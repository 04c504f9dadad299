"""Whether the data determine the calibration, and the bounds to report (docs/sog.md §15, §24): by
the bundle adjustment (the method: judge_adjustment) or by restarting two single filters (the filter
baselines: judge_determined); and the verdict (rscalib.verdict.Verdict) of a result."""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..verdict import NOT_DETERMINED, TRUSTED, Z_99, Verdict
from .adjustment import AdjustmentResult
from .result import SelfCalibResult

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
# "Determined" with the bundle adjustment (docs/sog.md §24): the adjustment over the tracks removes the
# filter's bias, and its covariance clustered by feature track and keyframe (errors correlated along a
# track, or within a frame, count once) is the bound. Determined:
# the adjustment converged over >= MIN_BUNDLE_POINTS tracks (fewer clusters make a clustered
# covariance itself uncertain; the real desk video has 32-60) and its 99 % interval of f is within
# +-SelfCalibOptions.determined_within of f: a user's requirement ("f known to 2 %"), not a fitted number.
MIN_BUNDLE_POINTS = 30
# A rolling shutter reads its rows within one frame interval (at most; a phone at 30 fps, about a
# third to all of it): a line delay whose 99 % interval lies wholly beyond this many frame intervals per
# image is the model misfitting the data, not a shutter (docs/sog.md §21).
MAX_READOUT_FRAMES = 1.25
# an f interval wider than +-50 %: the data constrain nothing (a camera that did not move)
UNCONSTRAINED_HALF_WIDTH = 0.5
def prior_bounds(initial, image_size: tuple[int, int]) -> np.ndarray:
    """What is known without the data (5, 2): the 99 % range of the initial mixture per parameter,
    the principal point's widened to UNDETERMINED_PP_HALF_WIDTH of the image diagonal."""
    sigma = np.sqrt(np.diagonal(initial.covs, axis1=1, axis2=2))
    bounds = np.c_[np.min(initial.means - Z_99 * sigma, axis=0), np.max(initial.means + Z_99 * sigma, axis=0)]
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

def _impossible_readout(adj: AdjustmentResult, image_height: int, frame_interval_s: Optional[float]) -> bool:
    """The line delay's whole 99 % interval reads the rows in more than MAX_READOUT_FRAMES frame
    intervals (or the other way round): no rolling shutter does; the model does not fit."""
    if not adj.estimates_line_delay or not frame_interval_s:
        return False
    lo, hi = adj.bounds_99_two_way[5]
    least = min(abs(lo), abs(hi)) if lo * hi > 0 else 0.0
    return least * image_height > MAX_READOUT_FRAMES * frame_interval_s


def _within_prior(reported: np.ndarray, prior_bounds: np.ndarray) -> np.ndarray:
    """The data's 99 % bounds cut to the prior's box (no camera outside it was ever possible: an f
    interval reaching below 0 says the data add nothing there); the prior's bounds of a parameter
    whose data interval misses the box."""
    lo = np.maximum(reported[:, 0], prior_bounds[:, 0])
    hi = np.minimum(reported[:, 1], prior_bounds[:, 1])
    empty = ~(lo <= hi)
    return np.where(empty[:, None], prior_bounds, np.c_[lo, hi])


def judge_adjustment(adj: Optional[AdjustmentResult], error: str, prior_bounds: np.ndarray, max_f_half_width: float,
                     image_height: int, frame_interval_s: Optional[float] = None) -> tuple[bool, str, np.ndarray]:
    """(determined, reason, bounds to report) from the bundle adjustment (docs/sog.md §24).

    A failed, non-converged or implausible adjustment (f outside what the prior allows, a line delay
    no shutter has, too few tracks) is never the reported value: not determined, the prior's bounds.
    Otherwise the bounds are the data's, the adjustment's 99 % (clustered by track and keyframe),
    and the calibration is determined when f's interval is within +-``max_f_half_width`` of f."""
    if adj is None:
        return False, f"the bundle adjustment failed ({error})", prior_bounds.copy()
    camera = np.asarray(adj.camera_params, float)
    reported = np.asarray(adj.bounds_99_two_way[:5], float)
    f = float(camera[0])
    lo, hi = reported[0]
    half = 0.5 * float(hi - lo) / f if f > 0 else np.inf
    spread = (f"f {f:.1f} px, 99 % [{lo:.1f}, {hi:.1f}] (+-{100 * half:.1f} %, clustered by feature track and "
              "keyframe)")
    points = int(len(adj.point_anchor)) - int(adj.dropped_points) - int(adj.points_out_of_range)
    problem = ""
    if not adj.converged:
        far = f"{adj.step_sigma:.2f} sigma" if adj.step_sigma < 1e3 else "over 1000 sigma (near-singular)"
        problem = f"the bundle adjustment did not converge ({adj.message}; the camera is still {far} from the minimum)"
    elif not prior_bounds[0, 0] <= f <= prior_bounds[0, 1]:
        problem = (f"the bundle adjustment ended at f {f:.1f} px, outside the focal lengths the sequence could have "
                   f"({prior_bounds[0, 0]:.0f}-{prior_bounds[0, 1]:.0f} px): it diverged")
    elif not adj.covariance_ok or not np.all(np.isfinite(reported)):
        problem = "the covariance of the adjusted camera could not be computed (near-singular: too little motion?)"
    elif points < MIN_BUNDLE_POINTS:
        problem = (f"only {points} feature tracks span 3 or more keyframes (>= {MIN_BUNDLE_POINTS} needed for a bound; "
                   "a textured scene seen for longer?)")
    elif _impossible_readout(adj, image_height, frame_interval_s):
        d_lo, d_hi = adj.bounds_99_two_way[5]
        problem = (f"the adjustment's line delay ({1e6 * adj.line_delay_s:.1f} us/row, 99 % [{1e6 * d_lo:.1f}, "
                   f"{1e6 * d_hi:.1f}]) reads the {image_height} rows in more than {MAX_READOUT_FRAMES:g} frame "
                   f"intervals ({1e3 * frame_interval_s:.1f} ms): the model does not fit (moving objects, zoom, or "
                   "stabilisation in the video?)")
    if problem:
        return False, problem, prior_bounds.copy()
    if not half <= max_f_half_width:
        why = ("the camera hardly moved, or moved without turning?" if half > UNCONSTRAINED_HALF_WIDTH
               else "little rotation, or a mostly sideways motion?")
        return False, (f"the data pin f only to +-{100 * half:.1f} % ({spread}; determined needs "
                       f"+-{100 * max_f_half_width:g} %): {why}"), _within_prior(reported, prior_bounds)
    return True, (f"bundle adjustment over {points} tracks and {len(adj.keyframe_poses)} keyframes: {spread}, "
                  f"residual {adj.sigma_px:.2f} px"), reported


def selfcalib_verdict(result: SelfCalibResult) -> Verdict:
    """The verdict of a self-calibration: trusted when the data determine it (f's 99 % interval within
    the asked fraction, judge_bundle / judge_determined), else not determined (exit 3) with the reason
    and the bounds the data allow; the headline quantity is f."""
    lo, hi = (float(b) for b in result.bounds_99[0])
    if result.determined:
        m, b = result.mean, result.bounds_99
        return Verdict(TRUSTED, f"f {m[0]:.2f} px [{b[0, 0]:.2f}, {b[0, 1]:.2f}] (99 %): determined by the data.",
                       (), quantity="f_px", value=float(m[0]), std=(hi - lo) / (2 * Z_99), bounds_99=(lo, hi), unit="px",
                       caveats=(result.reason,))
    return Verdict(NOT_DETERMINED, "The calibration is not determined by this sequence.",
                   (result.reason or "not checked",), quantity="f_px", bounds_99=(lo, hi), unit="px")
