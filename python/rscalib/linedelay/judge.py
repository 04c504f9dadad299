"""The verdict of a line-delay estimate (rscalib.verdict.Verdict): trusted, not trusted (a check
failed: the reasons say which) or not determined (the data do not determine d: no number is
claimed). The rules and why: docs/formulation.md §9-§10."""
from __future__ import annotations

import math

import numpy as np

from ..verdict import NOT_DETERMINED, NOT_TRUSTED, TRUSTED, Verdict

# J/2N outside this band: the noise model does not fit the detections
COST_BAND = (0.7, 1.5)
# fewer usable frames than this fraction of the video: most of it was not seen
MIN_FRAMES_USED_FRACTION = 0.3
# the board over fewer than this fraction of the image rows (2nd-98th percentile)
MIN_ROW_SPAN = 0.4
# a standard deviation above this fraction of the estimate: too uncertain to act on
MAX_RELATIVE_STD = 0.02


def _us(x: float) -> str:
    return f"{x * 1e6:.3f}" if math.isfinite(x) else "?"


def judge_line_delay(result) -> Verdict:
    """The verdict of a line-delay result (LineDelayResult or LinearInterpResult, with its
    self-check when run)."""
    quantity = dict(quantity="line_delay_s", unit="s/row")
    if not result.determined:
        why = ("the covariance of d is rank deficient" if not math.isfinite(result.line_delay_std_s)
               else f"sigma_d = {_us(result.line_delay_std_s)} us/row is too large")
        return Verdict(NOT_DETERMINED, "Line delay not determined by this video.",
                       [f"the data do not determine the line delay ({why}): too little motion, or the wrong kind "
                        "(move the camera faster, mostly rotating about its vertical axis)"], **quantity)
    reasons = []
    if not COST_BAND[0] <= result.normalised_cost <= COST_BAND[1]:
        reasons.append(f"J/2N = {result.normalised_cost:.2f} is far from 1: the noise model does not fit "
                       "(wrong intrinsics first of all, then outliers or motion the trajectory cannot follow)")
    if result.frames_used < MIN_FRAMES_USED_FRACTION * result.frames_total:
        reasons.append(f"only {result.frames_used} of {result.frames_total} frames were usable")
    rows_seen = result.used_observations.uv[:, 1]
    span = (np.percentile(rows_seen, 98) - np.percentile(rows_seen, 2)) / result.rows if len(rows_seen) else 0
    if span < MIN_ROW_SPAN:
        reasons.append(f"the target covered only {span * 100:.0f} % of the image rows; move it over the whole frame")
    check = getattr(result, "self_check", None)
    if check is not None:
        if check.get("agree") is False:
            h = check["halves"]
            reasons.append(f"the two halves of the video disagree: {_us(h[0]['line_delay_s'])} ± "
                           f"{_us(h[0]['line_delay_std_s'])} vs {_us(h[1]['line_delay_s'])} ± "
                           f"{_us(h[1]['line_delay_std_s'])} us/row ({check['z']:.1f} sigma); the error bar is "
                           f"widened x{check['widen']:.1f}")
        elif check.get("agree") is None:
            reasons.append("self-check inconclusive: " + check.get("reason", "a half could not be solved"))
    if math.isfinite(result.line_delay_std_s) and result.line_delay_s != 0 and \
            result.line_delay_std_s > MAX_RELATIVE_STD * abs(result.line_delay_s):
        reasons.append(f"the uncertainty is {result.line_delay_std_s / abs(result.line_delay_s) * 100:.1f} % of "
                       "the estimate; record longer or with faster motion")
    if not result.converged:
        reasons.append("the solver did not report convergence")
    structured = (check is not None and check.get("agree") is False) or \
        not COST_BAND[0] <= result.normalised_cost <= COST_BAND[1]
    if structured and getattr(result, "intrinsics", None) is None and hasattr(result, "intrinsics"):
        # a camera that is slightly off is what most often makes the halves disagree (docs/experiments.md,
        # "Joint refinement of the intrinsics"): say the next step in the CLI's words
        reasons.append("the first suspect is the camera file: run again with --refine-intrinsics (the camera "
                       "file becomes a prior and is refined with the line delay)")
    trusted = not reasons
    headline = (f"Line delay {_us(result.line_delay_s)} ± {_us(result.line_delay_std_s)} µs/row "
                f"(readout {result.readout_time_s * 1e3:.3f} ms): "
                + ("trust it." if trusted else "estimated, but do not trust it yet."))
    std = result.line_delay_std_s
    return Verdict(TRUSTED if trusted else NOT_TRUSTED, headline, reasons, value=float(result.line_delay_s),
                   std=float(std) if math.isfinite(std) else None,
                   bounds_99=None, **quantity)
