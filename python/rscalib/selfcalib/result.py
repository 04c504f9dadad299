"""What the self-calibration engine returns (SelfCalibResult: the estimate, its bounds, the
filter's history, the adjustment) and the restarts of the filter baseline."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .._core import CameraModel
from .adjustment import AdjustmentResult
from .driver import SelfCalibHistory

PARAM_NAMES = ("f", "cx", "cy", "k1", "k2")


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
    # The bundle adjustment over the tracks (None: not run or failed, see adjustment_error); its
    # reported covariance (the camera's and the line delay's, two-way clustered) is the bound.
    # estimate_from says which estimate ``mean`` (and so camera() and camera.yaml) is.
    filter_mean: Optional[np.ndarray] = None
    adjustment: Optional[AdjustmentResult] = None
    adjustment_error: str = ""
    line_delay_given: Optional[tuple] = None      # (mean s/row, sigma s/row or 0 when held) given by the user
    tracks: dict = field(default_factory=dict)   # the tracker's counts (tracks.TrackSet.stats) and what was used
    self_check: Optional[dict] = None            # the halves' adjustments (engine._halves_check): z, widen
    estimate_from: str = "filter"

    def adjustment_bounds_99(self) -> Optional[np.ndarray]:
        """The adjustment's 99 % bounds (5, 2) of the camera, whether or not they are the reported
        ones; None without an adjustment."""
        if self.adjustment is None:
            return None
        return np.asarray(self.adjustment.bounds_99_two_way[:5], float)

    def line_delay_estimate(self) -> Optional[tuple[float, np.ndarray]]:
        """The line delay (s/row) the adjustment estimated (none given, or given with a sigma) and
        its 99 % bounds (2,); None when not estimated."""
        adj = self.adjustment
        if adj is None or not adj.estimates_line_delay:
            return None
        return float(adj.line_delay_s), np.asarray(adj.bounds_99_two_way[5], float)

    def _line_delay_summary(self) -> dict:
        estimate = self.line_delay_estimate()
        if estimate is None:
            return {"line_delay_estimated_s": None, "line_delay_bounds_99_s": None}
        bounds = estimate[1]
        return {"line_delay_estimated_s": float(estimate[0]),
                "line_delay_bounds_99_s": [float(b) for b in bounds] if np.all(np.isfinite(bounds)) else None}

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

    def camera(self) -> CameraModel:
        f, cx, cy, k1, k2 = self.mean
        return CameraModel("civera-radial", [f, cx, cy, k1, k2], self.image_size[0], self.image_size[1],
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
                   adjustment=None if self.adjustment is None else adjustment_summary(self.adjustment),
                   adjustment_bounds_99=None if self.adjustment is None else self.adjustment_bounds_99().tolist(),
                   adjustment_error=self.adjustment_error,
                   line_delay_given=None if self.line_delay_given is None else list(self.line_delay_given),
                   tracks=self.tracks, self_check=self.self_check,
                   **self._line_delay_summary(),
                   max_map_size=int(self.history.map_size.max()) if len(self.history) else 0,
                   history=self.history.summary_dict())
        return out


def adjustment_summary(adj: AdjustmentResult) -> dict:
    """The result.json record of an adjustment: the estimate, the reported (two-way clustered)
    covariance and bounds, the solver's facts."""
    def fin(x):
        return float(x) if np.isfinite(x) else None
    return {"names": list(adj.names), "estimate": [fin(v) for v in adj.estimate],
            "bounds_99": [[fin(lo), fin(hi)] for lo, hi in adj.bounds_99_two_way],
            "covariance": [[fin(v) for v in row] for row in adj.covariance_two_way],
            "bounds_99_model": [[fin(lo), fin(hi)] for lo, hi in adj.bounds_99_model],
            "line_delay_estimated": bool(adj.estimates_line_delay),
            "keyframes": int(len(adj.keyframe_poses)), "points": int(len(adj.point_anchor)),
            "observations": int(np.count_nonzero(adj.used)), "inlier_fraction": fin(np.mean(adj.inlier[adj.used]))
            if np.any(adj.used) else None,
            "sigma_px": fin(adj.sigma_px), "rms_px": fin(adj.rms_px), "converged": bool(adj.converged),
            "termination": adj.termination, "iterations": int(adj.iterations), "solve_time_s": fin(adj.solve_time_s),
            "step_sigma": fin(adj.step_sigma), "dropped_points": int(adj.dropped_points),
            "points_out_of_range": int(adj.points_out_of_range), "solved_with_bounds": bool(adj.solved_with_bounds)}
