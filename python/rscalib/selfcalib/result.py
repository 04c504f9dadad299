"""What the self-calibration engine returns (SelfCalibResult: the estimate, its bounds, the
filter's history, the adjustment) and the restarts of the filter baseline."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .._core import CameraModel
from ..verdict import Z_99
from .bundle import BundleResult
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


def bundle_covariance(ba: BundleResult, cut: Optional[BundleResult]) -> np.ndarray:
    """The reported covariance of the adjusted camera (5, 5): clustered by track and keyframe, plus the
    squared shift to the adjustment over tracks cut into pieces (the drift's systematic error) on the
    diagonal; without the cut adjustment, infinite."""
    if cut is None:
        return np.full((5, 5), np.inf)
    return ba.covariance_clustered + np.diag((ba.camera - cut.camera) ** 2)


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
        half = Z_99 * np.sqrt(sigma_us2) * 1e-6
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
        half = Z_99 * np.sqrt(np.diag(bundle_covariance(self.bundle, self.bundle_cut)))
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
                   bundle=None if self.bundle is None else self.bundle.summary_dict(),
                   bundle_tracks_cut=None if self.bundle_cut is None else self.bundle_cut.summary_dict(),
                   bundle_bounds_99=None if self.bundle is None else self.bundle_bounds_99().tolist(),
                   bundle_error=self.bundle_error,
                   **self._line_delay_summary(),
                   max_map_size=int(self.history.map_size.max()) if len(self.history) else 0,
                   history=self.history.summary_dict())
        return out
