"""Baseline line-delay estimation with a per-frame pose trajectory (Hedborg et al. 2012).

One pose T_cw per frame, at the frame's row-0 time t_k; between two consecutive frames the
camera centre moves linearly and the rotation along the geodesic (SLERP). An observation of
frame k at row v is taken at t = t_k + v d. The poses and d are estimated jointly by Ceres
(rscalib._core.solve_line_delay_linear, cpp/include/rscalib/rs/linear_interp_cost.hpp) from
the plain reprojection errors divided by the pixel sigma.

Gaps: frames further apart than 1.5 median frame intervals (frames without detections or
without a PnP pose in between) are not interpolated between. The observations of the last
frame of a run of consecutive frames use the pair before it, extrapolated past s = 1 (the
first frame's, for a negative d, the pair after it); a frame with no neighbour is dropped.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .._core import CameraModel, LinearInterpOptions, solve_line_delay_linear, unwrap_rotation_vectors
from ..errors import InputError
from ..observations import Observations
from .common import (
    SOLVER_THREADS,
    assess_noise_and_determinacy,
    check_solve_memory,
    choose_pixel_sigma,
    initial_values,
    seed_poses,
    solve_warnings,
    summary_fields,
)
from .options import LineDelayOptions
from .pnp import FramePoses

TRAJECTORY_MODEL = "linear"


@dataclass
class LinearInterpResult:
    """Result of calibrate_line_delay_linear. Times in s, pixels in px."""

    line_delay_s: float
    line_delay_std_s: float
    readout_time_s: float
    rows: int
    frame_times_s: np.ndarray         # (F,) row-0 times of the used frames
    frame_poses: np.ndarray           # (F, 6) T_cw [p; phi] at frame_times_s
    linked_to_next: np.ndarray        # (F,) bool: frame k and k + 1 are interpolated between
    max_frame_interval_s: float
    rms_px: float
    normalised_cost: float            # J / 2N with the weights used
    pixel_sigma: float
    pixel_sigma_source: str
    converged: bool
    determined: bool
    warnings: list[str]
    frames_total: int
    frames_used: int
    observations: int                 # 2-D errors in the solve
    isolated_observations: int        # dropped: their frame has no neighbour
    extrapolated_observations: int    # chain ends: the neighbouring pair, extrapolated
    num_chains: int
    initial_line_delay_s: float
    solve_time_s: float
    observation_time_s: np.ndarray    # (M,) t_k + v d
    residual_px: np.ndarray           # (M, 2) y - pi(...), NaN where not used
    image_velocity_px_s: np.ndarray   # (M, 2) d(uv)/dt at the final estimate (the solver's, for A)
    standardised_sq: np.ndarray       # (M,)
    gs_poses: FramePoses              # the per-frame GS PnP initial guess
    used_observations: Observations = field(repr=False)
    trajectory_model: str = TRAJECTORY_MODEL

    @property
    def num_segments(self) -> int:
        return int(np.count_nonzero(self.linked_to_next))

    def pose_at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """T_cw at times t: R (n, 3, 3), p (n, 3), x_c = R x_w + p. Interpolated between
        linked frames; up to max_frame_interval_s past a chain's end (before its start)
        extrapolated with its last (first) pair, as the solver does; NaN elsewhere."""
        from scipy.spatial.transform import Rotation  # on use: the spline runs never import scipy.spatial

        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).reshape(-1)
        times, poses, linked = self.frame_times_s, self.frame_poses, self.linked_to_next
        count = len(times)
        k = np.clip(np.searchsorted(times, t, side="right") - 1, -1, count - 1)
        first = np.full(len(t), -1)
        inside = (k >= 0) & linked[np.maximum(k, 0)]
        first[inside] = k[inside]
        after_end = ~inside & (k >= 1) & linked[np.maximum(k - 1, 0)] & (t - times[np.maximum(k, 0)] <= self.max_frame_interval_s)
        first[after_end] = k[after_end] - 1
        nxt = np.minimum(k + 1, count - 1)
        before_start = (first < 0) & (k + 1 < count) & linked[nxt] & (times[nxt] - t <= self.max_frame_interval_s)
        first[before_start] = nxt[before_start]
        rotations = np.full((len(t), 3, 3), np.nan)
        translations = np.full((len(t), 3), np.nan)
        ok = first >= 0
        if np.any(ok):
            a = first[ok]
            s = (t[ok] - times[a]) / (times[a + 1] - times[a])
            r_a = Rotation.from_rotvec(poses[a, 3:])
            r_b = Rotation.from_rotvec(poses[a + 1, 3:])
            relative = (r_a.inv() * r_b).as_rotvec()          # |.| <= pi: the short way
            r_s = r_a * Rotation.from_rotvec(s[:, None] * relative)
            centre_a = -r_a.inv().apply(poses[a, :3])
            centre_b = -r_b.inv().apply(poses[a + 1, :3])
            centre = (1.0 - s)[:, None] * centre_a + s[:, None] * centre_b
            rotations[ok] = r_s.as_matrix()
            translations[ok] = -r_s.apply(centre)
        return rotations, translations

    def evaluate(self, t_s) -> np.ndarray:
        """(n, 6) states [p; phi] at times t (rotation vectors unwrapped over the finite rows,
        as the spline's state), NaN where pose_at is."""
        from scipy.spatial.transform import Rotation

        rotations, translations = self.pose_at(t_s)
        out = np.full((len(translations), 6), np.nan)
        ok = np.isfinite(translations[:, 0])
        if np.any(ok):
            out[ok, :3] = translations[ok]
            out[ok, 3:] = unwrap_rotation_vectors(Rotation.from_matrix(rotations[ok]).as_rotvec())
        return out

    def summary_dict(self) -> dict:
        """JSON-ready fields, the keys of LineDelayResult.summary_dict where they apply.
        knots: the frame poses (the interpolant's knots); segments: interpolated intervals."""
        return {"trajectory_model": self.trajectory_model,
                **summary_fields(self, len(self.frame_times_s), chains=self.num_chains,
                                 isolated_observations=self.isolated_observations,
                                 extrapolated_observations=self.extrapolated_observations,
                                 max_frame_interval_s=self.max_frame_interval_s)}


def calibrate_line_delay_linear(observations: Observations, camera: CameraModel,
                                options: Optional[LineDelayOptions] = None, *,
                                line_delay0_s: Optional[float] = None,
                                max_frame_interval_s: Optional[float] = None) -> LinearInterpResult:
    """Line delay d (s/row) with the per-frame linear/SLERP trajectory: the baseline of
    `LineDelayOptions(baseline="linear")`, the plain method (unstandardised errors).

    options: rows, pixel_sigma_px and robust_loss are read (LineDelayOptions; None: the defaults).
    max_frame_interval_s: frames further apart are not interpolated between (default 1.5 median
    frame intervals).
    """
    options = options or LineDelayOptions()
    started = time.perf_counter()
    rows, fps, nominal_delay_s, d = initial_values(observations, camera, options.rows, line_delay0_s)
    warnings: list[str] = []
    if not math.isfinite(d):
        raise InputError("line_delay0_s must be a finite number")
    if max_frame_interval_s is None:
        max_frame_interval_s = 1.5 / fps
    if not max_frame_interval_s > 0:
        raise InputError("max_frame_interval_s must be positive")
    initial_d = d

    frames_total = observations.num_frames
    check_solve_memory(len(observations.uv))
    used, gs = seed_poses(observations, camera, warnings, min_frames=2)
    sigma, sigma_source = choose_pixel_sigma(used, options.pixel_sigma_px)

    solver = LinearInterpOptions()
    solver.pixel_sigma = sigma
    solver.standardise_errors = False
    solver.max_frame_interval_s = float(max_frame_interval_s)
    solver.robust_loss = options.robust_loss
    solver.num_threads = SOLVER_THREADS
    initial_poses = np.c_[gs.translation, gs.rotation_vector]
    summary, refined = solve_line_delay_linear(used.frame_index.astype(np.int32), used.uv, used.points_w(),
                                                     used.frame_times_s, camera, initial_poses, d, solver)
    d = summary.line_delay_s
    std = summary.line_delay_std_s
    frame_times = used.frame_times_s
    linked = np.zeros(len(frame_times), dtype=bool)
    linked[:-1] = np.diff(frame_times) <= summary.max_frame_interval_s

    cost, sigma, determined = assess_noise_and_determinacy(summary, sigma, sigma_source, nominal_delay_s, warnings)
    if summary.isolated:
        warnings.append(f"{summary.isolated} observations were dropped: their frame has no neighbouring frame "
                        "to interpolate with")
    solve_warnings(summary, warnings)

    return LinearInterpResult(
        line_delay_s=d, line_delay_std_s=std, readout_time_s=d * rows, rows=rows, frame_times_s=frame_times,
        frame_poses=np.asarray(refined), linked_to_next=linked, max_frame_interval_s=summary.max_frame_interval_s,
        rms_px=summary.rms_px, normalised_cost=cost, pixel_sigma=sigma, pixel_sigma_source=sigma_source,
        converged=bool(summary.converged), determined=determined, warnings=warnings, frames_total=frames_total,
        frames_used=used.num_frames, observations=summary.num_error_terms,
        isolated_observations=summary.isolated, extrapolated_observations=summary.extrapolated,
        num_chains=summary.num_chains, initial_line_delay_s=initial_d,
        solve_time_s=time.perf_counter() - started,
        observation_time_s=np.asarray(summary.observation_time_s), residual_px=np.asarray(summary.residual_px),
        image_velocity_px_s=np.asarray(summary.image_velocity_px_s),
        standardised_sq=np.asarray(summary.standardised_sq), gs_poses=gs, used_observations=used)
