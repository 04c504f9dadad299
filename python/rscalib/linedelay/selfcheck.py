"""The built-in self-check of a line-delay estimate: the two halves of the video solved separately.

Each half is an independent estimate of the same d (independent detections, independent
trajectory). If both error bars are honest, their difference divided by its standard deviation,

    z = |d_1 - d_2| / sqrt(sigma_1² + sigma_2²),

is a standard normal magnitude. The halves **agree** when z <= AGREE_Z (3). The whole video's
error bar is then widened by the Birge ratio of the two halves, max(1, z) (for two estimates,
sqrt(chi² / (n - 1)) = z): when the halves scatter more than their sigmas say, the sigmas are too
small by about that factor, and so is the whole video's (docs/formulation.md §9). A half that is
too short or does not determine d makes the check inconclusive (agree = None); the whole video's
error bar is then left as it is and the verdict says so.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import numpy as np

from ..errors import InputError
from ..observations import Observations

AGREE_Z = 3.0


def halves(observations: Observations, solve: Callable[[Observations], object], parallel: bool = True) -> dict:
    """Solve the first and second half (by time) of `observations` with `solve` (a function of
    Observations returning a result with line_delay_s, line_delay_std_s, determined) and compare.
    parallel: solve the two halves in two threads at once (the solver releases the GIL; the
    results are the same either way). Returns the JSON-ready check: halves [{t_begin_s, t_end_s,
    line_delay_s, line_delay_std_s, determined}], z, agree (True / False / None), widen (the factor
    for the whole video's sigma)."""
    times = observations.frame_times_s
    t_mid = 0.5 * (times[0] + times[-1])
    out: dict = {"rule": f"agree when z = |d1 - d2| / sqrt(s1^2 + s2^2) <= {AGREE_Z:g}; sigma_d widened by "
                         "max(1, z) (Birge ratio)", "halves": [], "z": None, "agree": None, "widen": 1.0}
    keeps = [times < t_mid, times >= t_mid]

    def attempt(keep: np.ndarray):
        try:
            return solve(observations.subset_frames(keep)), None
        except InputError as error:
            return None, error

    if parallel:
        with ThreadPoolExecutor(max_workers=2, thread_name_prefix="rscalib-half") as pool:
            attempts = list(pool.map(attempt, keeps))
    else:
        attempts = [attempt(keep) for keep in keeps]
    estimates = []
    for keep, (result, error) in zip(keeps, attempts):
        part = {"t_begin_s": float(times[keep][0]) if keep.any() else None,
                "t_end_s": float(times[keep][-1]) if keep.any() else None}
        if error is not None:
            part["error"] = str(error)
            out["halves"].append(part)
            continue
        std = float(result.line_delay_std_s)
        part.update(line_delay_s=float(result.line_delay_s), line_delay_std_s=std if math.isfinite(std) else None,
                    determined=bool(result.determined), normalised_cost=float(result.normalised_cost))
        out["halves"].append(part)
        if result.determined and math.isfinite(std) and std > 0:
            estimates.append((float(result.line_delay_s), std))
    if len(estimates) < 2:
        out["reason"] = "a half of the video does not determine the line delay on its own"
        return out
    (d1, s1), (d2, s2) = estimates
    z = abs(d1 - d2) / math.hypot(s1, s2)
    out.update(z=float(z), agree=bool(z <= AGREE_Z), widen=float(max(1.0, z)))
    return out


def widened_std(std_s: float, check: dict) -> float:
    """The whole video's sigma_d after the self-check's widening rule."""
    return float(std_s * check.get("widen", 1.0)) if np.isfinite(std_s) else std_s
