"""A reference for the tests only: the SciPy bundle adjustment the product used before the C++ (Ceres) one
(rscalib.selfcalib.adjustment, docs/sog.md §23). Kept as an independent implementation of the same
model (its own civera-radial projection, Jacobian and covariance) so that tests/python/selfcalib/
test_adjustment.py and benchmarks/bench_adjustment.py can compare the two on the same observations.
It is not part of the package.

Batch bundle adjustment over the tracks of a self-calibration run (issue 11; docs/sog.md §17, §20, §21).

The SOG bank (docs/sog.md) is the online engine; this refines its answer offline: one shared
civera-radial camera ``[f, cx, cy, k1 (mm^-2), k2 (mm^-4)]`` (the filter's parameterisation,
docs/conventions.md), one pose per keyframe and one 3-D point per feature, fitted to the pixels
the filter used (its RANSAC/gate inliers) by SciPy's ``least_squares`` with a robust loss, a sparse
analytic Jacobian and ``x_scale='jac'``, finished by exact Levenberg-Marquardt steps. Optionally the
rolling shutter's line delay is a sixth shared parameter: each observation is predicted at its row's
time through its track's image velocity (§21). Covariances: the model's, clustered by track, and
clustered by track and keyframe (what `rscalib selfcalib` reports, with the drift term of §20).

- :func:`bundle_adjust` runs the adjustment on the recorded :class:`FeatureTracks`.

Gauge: the first keyframe's pose is held at the filter's (the filter's world is the first
camera), and the scale by holding the world z of the point seen most often in that keyframe.
Poses are ``x_c = R_i X + p_i`` with ``R_i = exp([θ_i]×) R0_i`` (θ_i the unknown, R0_i the start).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Optional, Sequence, Union

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from rscalib.errors import InputError
from rscalib.selfcalib.rolling_shutter import MAX_GAP_FRAMES

__all__ = ["BundleProblem", "BundleResult", "FeatureTracks", "build_problem", "bundle_adjust", "project_civera",
           "residuals_and_jacobian"]

_Z99 = 2.5758293035489004
_CAMERA_SIZE = 5      # f, cx, cy, k1, k2
_GLOBAL_SIZE = 6      # the camera and the line delay (µs/row), shared by every observation
_US = 1e-6
_POSE_SIZE = 6
_POINT_SIZE = 3


# --------------------------------------------------------------------------------------------------
# Tracks out of a run


@dataclass
class FeatureTracks:
    """What the filter used: observations (``frame`` (N,), ``feature_id`` (N,), ``uv`` (N, 2)
    distorted pixels), per processed frame its merged pose ``R_cw`` / ``p_cw`` (dicts frame -> (3, 3),
    (3,)), and per feature the latest point of the leading filter in its world (``points``, id -> (3,));
    ``t_s``: per processed frame its time (dict frame -> s; None: not recorded)."""

    frame: np.ndarray
    feature_id: np.ndarray
    uv: np.ndarray
    R_cw: dict
    p_cw: dict
    points: dict
    t_s: Optional[dict] = None

    def __len__(self) -> int:
        return len(self.frame)


def _skew(v: np.ndarray) -> np.ndarray:
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _left_jacobian_so3(theta: np.ndarray) -> np.ndarray:
    """J_l(θ) (n, 3, 3): d exp([θ + δ]×) = [J_l δ]× exp([θ]×) to first order."""
    angle = np.linalg.norm(theta, axis=-1)[..., None, None]
    small = angle < 1e-5
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 0.5 - angle ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    b = np.where(small, 1.0 / 6.0 - angle ** 2 / 120.0, (safe - np.sin(safe)) / safe ** 3)
    K = _skew(theta)
    return np.eye(3) + a * K + b * (K @ K)


def _rising_branch_end(k1: float, k2: float) -> float:
    """The radius (mm) where r (1 + k1 r² + k2 r⁴) stops rising (inf when it never does)."""
    roots = np.roots([5.0 * k2, 3.0 * k1, 1.0]) if k2 != 0.0 else (np.array([-1.0 / (3.0 * k1)]) if k1 != 0.0
                                                                    else np.zeros(0))
    s = [float(r.real) for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and r.real > 0]
    return float(np.sqrt(min(s))) if s else np.inf


def _distort_offsets(a: np.ndarray, k1: float, k2: float, pixel_size_mm: np.ndarray) -> np.ndarray:
    """Undistorted offsets from the centre (n, 2) px -> distorted offsets: r_d (mm) solves
    r_d (1 + k1 r_d² + k2 r_d⁴) = r_u on the rising branch by Newton kept inside a bracket
    (bisection when a step leaves it); beyond the branch r_d is its end. The offset is scaled by
    r_d / r_u."""
    r_u = np.linalg.norm(a * pixel_size_mm, axis=1)
    lo = np.zeros_like(r_u)
    hi = np.full_like(r_u, _rising_branch_end(k1, k2))
    r_d = np.minimum(r_u, hi)
    for _ in range(40):
        r2 = r_d * r_d
        g = r_d * (1.0 + r2 * (k1 + k2 * r2)) - r_u
        dg = 1.0 + r2 * (3.0 * k1 + 5.0 * k2 * r2)
        lo = np.where(g < 0, r_d, lo)
        hi = np.where(g > 0, r_d, hi)
        step = g / np.where(dg > 1e-12, dg, 1e-12)
        new = r_d - step
        outside = (new < lo) | (new > hi)
        new = np.where(outside, np.where(np.isfinite(hi), 0.5 * (lo + hi), 2.0 * r_d + 1e-9), new)
        done = np.abs(new - r_d) < 1e-14
        r_d = new
        if np.all(done):
            break
    scale = np.where(r_u > 1e-12, r_d / np.where(r_u > 1e-12, r_u, 1.0), 1.0)
    return a * scale[:, None]


def project_civera(camera: np.ndarray, points_c: np.ndarray, pixel_size_mm) -> np.ndarray:
    """Distorted pixels (n, 2) of camera-frame points (n, 3) (no validity check: z > 0 assumed)."""
    f, cx, cy, k1, k2 = camera
    px = np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,))
    n = points_c[:, :2] / points_c[:, 2:3]
    return np.array([cx, cy]) + _distort_offsets(f * n, k1, k2, px)


@dataclass
class BundleProblem:
    """Observations indexed into keyframes and points; full parameter vector and which entries vary."""

    obs_pose: np.ndarray      # (N,) keyframe index
    obs_point: np.ndarray     # (N,) point index
    uv: np.ndarray            # (N, 2)
    R0: np.ndarray            # (K, 3, 3) rotation at which each pose's θ = 0
    pixel_size_mm: np.ndarray
    free: np.ndarray          # (n_full,) bool
    x_full: np.ndarray        # the start (and the held values)
    # d uv / d (line delay in µs/row) per observation (N, 2): image velocity (px/s) x (v - v_ref) x 1e-6
    shutter: Optional[np.ndarray] = None

    @property
    def num_poses(self) -> int:
        return len(self.R0)

    @property
    def num_points(self) -> int:
        return (len(self.x_full) - self.point_offset()) // _POINT_SIZE

    def pose_offset(self) -> int:
        return _GLOBAL_SIZE

    def point_offset(self) -> int:
        return _GLOBAL_SIZE + _POSE_SIZE * self.num_poses

    @property
    def estimates_line_delay(self) -> bool:
        return bool(self.free[_CAMERA_SIZE])

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The globals ``[f, cx, cy, k1, k2, line delay µs/row]``, θ (K, 3), p (K, 3), points (P, 3)."""
        full = self.x_full.copy()
        full[self.free] = x
        poses = full[_GLOBAL_SIZE:self.point_offset()].reshape(-1, _POSE_SIZE)
        return full[:_GLOBAL_SIZE], poses[:, :3], poses[:, 3:], full[self.point_offset():].reshape(-1, 3)


def residuals_and_jacobian(problem: BundleProblem, x: np.ndarray, jacobian: bool = True
                           ) -> tuple[np.ndarray, Optional[scipy.sparse.csr_matrix]]:
    """Residuals (2N,) = predicted − measured pixels, and their sparse Jacobian in the free
    parameters (2N, n_free) (None when ``jacobian`` is False). The prediction is at the keyframe's
    time plus the rolling shutter's shift, image velocity × (v − v_ref) × line delay (docs/sog.md §21)."""
    camera, theta, p, X = problem.unpack(x)
    f, cx, cy, k1, k2, line_delay_us = camera
    shutter = problem.shutter if problem.shutter is not None else np.zeros((len(problem.uv), 2))
    dx, dy = problem.pixel_size_mm
    R = Rotation.from_rotvec(theta).as_matrix() @ problem.R0                 # (K, 3, 3)
    Ri = R[problem.obs_pose]
    RX = np.einsum("nij,nj->ni", Ri, X[problem.obs_point])
    h = RX + p[problem.obs_pose]
    z = np.where(h[:, 2] > 1e-6, h[:, 2], 1e-6)                                # a point behind: clamp
    nrm = h[:, :2] / z[:, None]
    a = f * nrm
    delta = _distort_offsets(a, k1, k2, np.array([dx, dy]))
    res = (np.array([cx, cy]) + delta + line_delay_us * shutter - problem.uv).ravel()
    if not jacobian:
        return res, None
    # J_U = dU/dδ = g I + 2 g' δ wᵀ, U(δ) = δ g(r²), w = (dx² δu, dy² δv) (docs/sog.md §5)
    r2 = (dx * delta[:, 0]) ** 2 + (dy * delta[:, 1]) ** 2
    g = 1.0 + k1 * r2 + k2 * r2 ** 2
    gp = k1 + 2.0 * k2 * r2
    w = delta * np.array([dx * dx, dy * dy])
    J_U = g[:, None, None] * np.eye(2) + 2.0 * gp[:, None, None] * delta[:, :, None] * w[:, None, :]
    J_U_inv = np.linalg.inv(J_U)
    d_uv_d_f = np.einsum("nij,nj->ni", J_U_inv, nrm)
    d_uv_d_k = -np.einsum("nij,njk->nik", J_U_inv, np.stack([delta * r2[:, None], delta * (r2 ** 2)[:, None]], 2))
    d_n_d_h = np.zeros((len(h), 2, 3))
    d_n_d_h[:, 0, 0] = d_n_d_h[:, 1, 1] = 1.0 / z
    d_n_d_h[:, :, 2] = -nrm / z[:, None]
    d_uv_d_h = f * np.einsum("nij,njk->nik", J_U_inv, d_n_d_h)
    d_h_d_theta = -_skew(RX) @ _left_jacobian_so3(theta)[problem.obs_pose]
    blocks = np.concatenate([
        d_uv_d_f[:, :, None], np.broadcast_to(np.eye(2), (len(h), 2, 2)), d_uv_d_k,   # camera
        shutter[:, :, None],                                                         # line delay
        d_uv_d_h @ d_h_d_theta, d_uv_d_h,                                            # pose: θ, p
        d_uv_d_h @ Ri,                                                               # point
    ], axis=2)                                                                       # (N, 2, 15)
    pose0 = problem.pose_offset() + _POSE_SIZE * problem.obs_pose
    point0 = problem.point_offset() + _POINT_SIZE * problem.obs_point
    cols_full = np.concatenate([np.broadcast_to(np.arange(_GLOBAL_SIZE), (len(h), _GLOBAL_SIZE)),
                                pose0[:, None] + np.arange(_POSE_SIZE), point0[:, None] + np.arange(_POINT_SIZE)],
                               axis=1)                                               # (N, 15)
    column = np.cumsum(problem.free) - 1
    column[~problem.free] = -1
    cols = np.broadcast_to(column[cols_full][:, None, :], blocks.shape)
    rows = np.broadcast_to((2 * np.arange(len(h)))[:, None, None] + np.arange(2)[None, :, None], blocks.shape)
    keep = cols >= 0
    jac = scipy.sparse.csr_matrix((blocks[keep], (rows[keep], cols[keep])),
                                  shape=(2 * len(h), int(problem.free.sum())))
    return res, jac


# --------------------------------------------------------------------------------------------------
# The adjustment


@dataclass
class BundleResult:
    """The adjusted camera ``[f, cx, cy, k1, k2]``, its covariance (5, 5) and 99 % ``bounds_99`` (5, 2)
    from the model (independent pixel errors), the same cluster-robust by feature track
    (``covariance_tracks``, ``bounds_99_tracks``); ``sigma_px``: the residual standard deviation
    (robustly weighted); sizes, cost, time."""

    camera: np.ndarray
    covariance: np.ndarray
    bounds_99: np.ndarray
    covariance_tracks: np.ndarray
    bounds_99_tracks: np.ndarray
    sigma_px: float
    keyframes: int
    points: int
    observations: int
    inlier_fraction: float
    rms_px: float
    nfev: int
    status: int
    message: str
    elapsed_s: float
    start: np.ndarray
    step_sigma: float = 0.0     # the remaining Gauss-Newton step of the camera, in its model sigmas
    # clustered two ways, by feature track and by keyframe (the bound `rscalib selfcalib` reports)
    covariance_clustered: Optional[np.ndarray] = None
    bounds_99_clustered: Optional[np.ndarray] = None
    extra: dict = field(default_factory=dict)
    # the rolling shutter's line delay (s/row) when estimated (else None), its clustered 99 % bounds,
    # and the globals' clustered covariance (6, 6): the camera then the line delay in µs/row
    line_delay_s: Optional[float] = None
    line_delay_bounds_99_s: Optional[np.ndarray] = None
    covariance_globals: Optional[np.ndarray] = None

    def summary_dict(self) -> dict:
        names = ("f", "cx", "cy", "k1", "k2")
        out = {n: float(v) for n, v in zip(names, self.camera)}
        out.update({f"{n}_bounds_99": [float(b[0]), float(b[1])] for n, b in zip(names, self.bounds_99)})
        out.update({f"{n}_bounds_99_tracks": [float(b[0]), float(b[1])] for n, b in zip(names, self.bounds_99_tracks)})
        if self.bounds_99_clustered is not None:
            out.update({f"{n}_bounds_99_clustered": [float(b[0]), float(b[1])]
                        for n, b in zip(names, self.bounds_99_clustered)})
        out.update(sigma=dict(zip(names, np.sqrt(np.diag(self.covariance)).tolist())),
                   sigma_tracks=dict(zip(names, np.sqrt(np.diag(self.covariance_tracks)).tolist())),
                   sigma_px=self.sigma_px,
                   keyframes=self.keyframes, points=self.points, observations=self.observations,
                   inlier_fraction=self.inlier_fraction, rms_px=self.rms_px, nfev=self.nfev, status=self.status,
                   message=self.message, elapsed_s=self.elapsed_s, start=self.start.tolist(),
                   step_sigma=self.step_sigma, **self.extra)
        if self.line_delay_s is not None:
            out.update(line_delay_s=float(self.line_delay_s),
                       line_delay_bounds_99_s=[float(b) for b in self.line_delay_bounds_99_s])
        return out


def track_velocity(tracks: FeatureTracks) -> np.ndarray:
    """Each observation's image velocity (N, 2) px/s from its track's neighbouring observations
    (central difference, else one-sided; neighbours at most MAX_GAP_FRAMES frame intervals away);
    NaN where the track has no such neighbour or the times were not recorded."""
    velocity = np.full((len(tracks), 2), np.nan)
    if tracks.t_s is None or len(tracks) == 0:
        return velocity
    t = np.array([tracks.t_s.get(int(k), np.nan) for k in tracks.frame.tolist()])
    order = np.lexsort((tracks.frame, tracks.feature_id))
    fid, tt, uv = tracks.feature_id[order], t[order], tracks.uv[order]
    times = np.unique(t[np.isfinite(t)])
    steps = np.diff(times)
    interval = float(np.median(steps[steps > 0])) if np.any(steps > 0) else np.inf
    max_gap = MAX_GAP_FRAMES * interval * 1.5     # 1.5: the frame times jitter about their median
    n = len(fid)
    before, after = np.maximum(np.arange(n) - 1, 0), np.minimum(np.arange(n) + 1, n - 1)
    dt_before, dt_after = tt - tt[before], tt[after] - tt
    has_before = (fid[before] == fid) & (dt_before > 0) & (dt_before <= max_gap)
    has_after = (fid[after] == fid) & (dt_after > 0) & (dt_after <= max_gap)
    with np.errstate(invalid="ignore", divide="ignore"):
        central = (uv[after] - uv[before]) / (tt[after] - tt[before])[:, None]
        backward = (uv - uv[before]) / dt_before[:, None]
        forward = (uv[after] - uv) / dt_after[:, None]
    sorted_velocity = np.where((has_before & has_after)[:, None], central,
                               np.where(has_before[:, None], backward,
                                        np.where(has_after[:, None], forward, np.nan)))
    velocity[order] = sorted_velocity
    return velocity


def build_problem(tracks: FeatureTracks, camera0: np.ndarray, pixel_size_mm: np.ndarray, keyframe_step: int,
                  min_views: int, max_track_frames: Optional[int] = None, line_delay: bool = False,
                  reference_row: Optional[float] = None) -> BundleProblem:
    """The adjustment's problem: observations of features seen in >= ``min_views`` keyframes (every
    ``keyframe_step``-th recorded frame), started from ``camera0`` and the filter's poses and points,
    with the gauge held (module docstring); tracks cut into points of at most ``max_track_frames``
    frames each (None: whole tracks). line_delay: estimate the rolling shutter's line delay too
    (needs the tracks' times), with rows timed from ``reference_row`` (None: camera0's cy)."""
    frames = np.array(sorted(tracks.R_cw))
    keyframes = frames[::keyframe_step]
    key_index = {int(k): i for i, k in enumerate(keyframes)}
    if line_delay and tracks.t_s is None:
        raise InputError("bundle adjustment: the line delay needs the tracks' frame times")
    velocity_all = track_velocity(tracks) if line_delay else np.zeros((len(tracks), 2))
    on_key = np.isin(tracks.frame, keyframes) & np.isin(tracks.feature_id, list(tracks.points))
    fid, frame, uv, velocity = (tracks.feature_id[on_key], tracks.frame[on_key], tracks.uv[on_key],
                                velocity_all[on_key])
    # one observation per (feature, keyframe): the first
    _, first = np.unique(np.c_[fid, frame], axis=0, return_index=True)
    fid, frame, uv, velocity = fid[first], frame[first], uv[first], velocity[first]
    R0 = np.array([tracks.R_cw[int(k)] for k in keyframes])
    p0 = np.array([tracks.p_cw[int(k)] for k in keyframes])
    pose_of = np.array([key_index[int(k)] for k in frame], dtype=np.int64)
    points = {i: tracks.points[int(i)] for i in np.unique(fid)}
    # drop observations of points behind the camera at the start, then features seen too rarely
    X = np.array([points[int(i)] for i in fid]).reshape(-1, 3)
    depth = np.einsum("nij,nj->ni", R0[pose_of], X)[:, 2] + p0[pose_of, 2]
    ok = depth > 1e-3
    fid, frame, pose_of, uv, velocity = fid[ok], frame[ok], pose_of[ok], uv[ok], velocity[ok]
    # a track longer than max_track_frames becomes several points: the front end's match drifts
    # with the age of its patch (docs/sog.md §1), and a fresh point absorbs the offset so far
    segment = np.zeros(len(fid), np.int64)
    if max_track_frames is not None:
        start = {}
        for i, k in zip(fid.tolist(), frame.tolist()):
            start[i] = min(k, start.get(i, k))
        segment = (frame - np.array([start[i] for i in fid.tolist()], dtype=np.int64)) // int(max_track_frames)
    pairs, point_of, counts = np.unique(np.c_[fid, segment], axis=0, return_inverse=True, return_counts=True)
    point_of = point_of.reshape(-1)
    keep = counts >= min_views
    ok = keep[point_of]
    fid, pose_of, uv, velocity = fid[ok], pose_of[ok], uv[ok], velocity[ok]
    point_of = (np.cumsum(keep) - 1)[point_of[ok]]
    keep_ids = pairs[keep, 0]
    if len(keep_ids) < 10:
        raise InputError(f"bundle adjustment: only {len(keep_ids)} features seen in >= {min_views} keyframes")
    X0 = np.array([points[int(i)] for i in keep_ids])
    camera0 = np.asarray(camera0, float)[:_CAMERA_SIZE]
    x_full = np.concatenate([camera0, [0.0], np.c_[np.zeros((len(keyframes), 3)), p0].ravel(), X0.ravel()])
    free = np.ones(len(x_full), bool)
    free[_CAMERA_SIZE] = bool(line_delay)
    shutter = None
    if line_delay:   # a track without a velocity (too short, a gap) is taken as still
        v_ref = float(camera0[2]) if reference_row is None else float(reference_row)
        shutter = np.nan_to_num(velocity) * ((uv[:, 1] - v_ref) * _US)[:, None]
        if not np.any(shutter):   # nothing moves: the line delay is not observed
            free[_CAMERA_SIZE], shutter = False, None
    free[_GLOBAL_SIZE:_GLOBAL_SIZE + _POSE_SIZE] = False          # the first keyframe's pose
    in_first = point_of[pose_of == 0]
    if len(in_first) == 0:
        raise InputError("bundle adjustment: no feature seen in the first keyframe (scale gauge)")
    anchor = np.bincount(point_of, minlength=len(keep_ids))[in_first].argmax()
    free[_GLOBAL_SIZE + _POSE_SIZE * len(keyframes) + _POINT_SIZE * in_first[anchor] + 2] = False  # its z
    return BundleProblem(obs_pose=pose_of, obs_point=point_of, uv=uv, R0=R0, pixel_size_mm=pixel_size_mm, free=free,
                         x_full=x_full, shutter=shutter)


def _camera_columns_of_inverse(problem: BundleProblem, H: scipy.sparse.csr_matrix) -> np.ndarray:
    """H⁻¹ E_globals (n, g) of the normal matrix H (n, n), g the free globals (the camera and, when
    estimated, the line delay), through the Schur complement of the points
    (block diagonal, one block per point): S = A − B C⁻¹ Bᵀ over the camera and poses, then
    H⁻¹ E = [S⁻¹ E; −C⁻¹ Bᵀ S⁻¹ E]. Jacobi-scaled first; pseudo-inverses where singular."""
    scale = 1.0 / np.sqrt(np.maximum(H.diagonal(), 1e-300))
    Hs = (scipy.sparse.diags(scale) @ H @ scipy.sparse.diags(scale)).tocsr()
    na = int(problem.free[:problem.point_offset()].sum())          # free global and pose columns
    ng = int(problem.free[:_GLOBAL_SIZE].sum())
    block = np.repeat(np.arange(problem.num_points), _POINT_SIZE)[problem.free[problem.point_offset():]]
    size = np.bincount(block, minlength=problem.num_points)
    first = np.r_[0, np.cumsum(size)[:-1]]
    slot = np.arange(len(block)) - first[block]
    C = Hs[na:, na:].tocoo()
    blocks = np.zeros((problem.num_points, _POINT_SIZE, _POINT_SIZE))
    blocks[block[C.row], slot[C.row], slot[C.col]] = C.data
    for b in np.flatnonzero(size < _POINT_SIZE):                 # the anchor: its z is held
        blocks[b, size[b]:, size[b]:] = np.eye(_POINT_SIZE - size[b])
    blocks_inv = np.linalg.pinv(blocks, hermitian=True)
    other = np.arange(_POINT_SIZE)[None, :]
    valid = other < size[block][:, None]
    rows = np.broadcast_to(np.arange(len(block))[:, None], valid.shape)[valid]
    cols = (first[block][:, None] + other)[valid]
    data = blocks_inv[block[:, None], slot[:, None], other][valid]
    C_inv = scipy.sparse.csr_matrix((data, (rows, cols)), shape=(len(block), len(block)))
    B = Hs[:na, na:]
    S = Hs[:na, :na].toarray() - (B @ C_inv @ B.T).toarray()
    rhs = np.zeros((na, ng))
    rhs[:ng] = np.diag(scale[:ng])                                 # the free globals come first
    try:
        z_a = scipy.linalg.solve(S, rhs, assume_a="pos")
    except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
        z_a = np.linalg.lstsq(S, rhs, rcond=1e-12)[0]
    z_b = -(C_inv @ (B.T @ z_a))
    return scale[:, None] * np.vstack([z_a, z_b])


def _camera_covariance(problem: BundleProblem, x: np.ndarray, loss_scale_px: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, np.ndarray]:
    """The globals' (6, 6) covariance (the camera and the line delay in µs/row; zero rows and columns
    where held) three ways: from the model, σ² (Jᵀ W J)⁻¹ (independent pixel
    errors), cluster-robust by feature track, H⁻¹ (Σ_j g_j g_jᵀ) H⁻¹ · G / (G − 1) with g_j = J_jᵀ W r_j
    summed over track j (errors correlated along a track, e.g. a patch drifting), and clustered two
    ways, by track and by keyframe (errors shared within a frame too); then the weighted
    residual sigma (px), the fraction of residuals inside the loss scale and the camera's part of the
    Gauss-Newton step still to go, −(H⁻¹ Jᵀ W r)_globals (6,). W: the soft_l1 weights ρ'(z) =
    (1 + z)^-½, z = (r / scale)²."""
    res, jac = residuals_and_jacobian(problem, x)
    weight = 1.0 / np.sqrt(1.0 + (res / loss_scale_px) ** 2)
    dof = max(len(res) - jac.shape[1], 1)
    sigma2 = float(np.sum(weight * res ** 2) / dof)
    z = _camera_columns_of_inverse(problem, (jac.T @ scipy.sparse.diags(weight) @ jac).tocsr())
    ng = z.shape[1]
    cov = sigma2 * z[:ng]
    per_residual = (jac @ z) * (weight * res)[:, None]     # (2N, g): each residual's share of Zᵀ g
    tracks = np.repeat(problem.obs_point, 2)
    per_track = np.zeros((problem.num_points, ng))
    np.add.at(per_track, tracks, per_residual)
    count = len(per_track)
    cov_tracks = per_track.T @ per_track * count / max(count - 1, 1)
    # two-way (Cameron, Gelbach & Miller 2011): errors shared by the features of one keyframe (the
    # rolling shutter's shear, timing, blur) as well as along a track: V_track + V_frame - V_observation
    per_frame = np.zeros((problem.num_poses, ng))
    np.add.at(per_frame, np.repeat(problem.obs_pose, 2), per_residual)
    frames = len(per_frame)
    per_observation = per_residual[0::2] + per_residual[1::2]
    cov_two_way = (cov_tracks + per_frame.T @ per_frame * frames / max(frames - 1, 1)
                   - per_observation.T @ per_observation)
    values, vectors = np.linalg.eigh(0.5 * (cov_two_way + cov_two_way.T))
    cov_two_way = (vectors * np.maximum(values, 0.0)) @ vectors.T    # clipped to positive semi-definite
    step = -per_residual.sum(axis=0)
    free_globals = problem.free[:_GLOBAL_SIZE]

    def globals_sized(a: np.ndarray) -> np.ndarray:
        out = np.zeros((_GLOBAL_SIZE,) * a.ndim)
        out[np.ix_(*[free_globals] * a.ndim)] = a
        return out

    return (globals_sized(cov), globals_sized(cov_tracks), globals_sized(cov_two_way), float(np.sqrt(sigma2)),
            float(np.mean(np.abs(res) <= loss_scale_px)), globals_sized(step))


def _robust_cost(res: np.ndarray, scale: float) -> float:
    """SciPy's soft_l1 cost: ½ Σ 2 s² (√(1 + (r/s)²) − 1)."""
    return float(np.sum(scale * scale * (np.sqrt(1.0 + (res / scale) ** 2) - 1.0)))


def _polish(problem: BundleProblem, x: np.ndarray, loss_scale_px: float, lower: np.ndarray,
            iterations: int) -> tuple[np.ndarray, int]:
    """Finish the minimum with Levenberg-Marquardt steps on the reweighted (soft_l1) normal equations,
    solved exactly (sparse LU): TRF's inexact LSMR steps creep along the flat valley of far points'
    depths (300 evaluations can leave f 0.2 sigma short), and an undamped Gauss-Newton step
    overshoots along it. Stops when the robust cost changes by < 1e-12 of itself. Returns x and the
    number of steps taken."""
    cost = _robust_cost(residuals_and_jacobian(problem, x, jacobian=False)[0], loss_scale_px)
    damping = 1e-4
    for it in range(iterations):
        res, jac = residuals_and_jacobian(problem, x)
        weight = 1.0 / np.sqrt(1.0 + (res / loss_scale_px) ** 2)
        H = (jac.T @ scipy.sparse.diags(weight) @ jac).tocsc()
        gradient = jac.T @ (weight * res)
        diagonal = np.maximum(H.diagonal(), 1e-12)
        while damping <= 1e8:
            try:
                dx = -scipy.sparse.linalg.spsolve(H + scipy.sparse.diags(damping * diagonal), gradient)
            except RuntimeError:   # singular
                dx = np.full(len(x), np.nan)
            trial = np.maximum(x + dx, lower)
            trial_cost = (_robust_cost(residuals_and_jacobian(problem, trial, jacobian=False)[0], loss_scale_px)
                          if np.all(np.isfinite(dx)) else np.inf)
            if trial_cost < cost:
                break
            damping *= 10.0
        else:
            return x, it
        converged = cost - trial_cost <= 1e-12 * cost
        x, cost, damping = trial, trial_cost, max(damping / 10.0, 1e-9)
        if converged:
            return x, it + 1
    return x, iterations


def _frame_interval_s(tracks: FeatureTracks) -> Optional[float]:
    """The median time between recorded frames (None without times)."""
    if not tracks.t_s:
        return None
    steps = np.diff(np.sort(np.fromiter(tracks.t_s.values(), float)))
    steps = steps[steps > 0]
    return float(np.median(steps)) if len(steps) else None


def _depths(problem: BundleProblem, x: np.ndarray) -> np.ndarray:
    _, theta, p, X = problem.unpack(x)
    R = Rotation.from_rotvec(theta).as_matrix() @ problem.R0
    return np.einsum("nij,nj->ni", R[problem.obs_pose], X[problem.obs_point])[:, 2] + p[problem.obs_pose, 2]


def _without_points_behind(problem: BundleProblem, x: np.ndarray, min_views: int, min_depth: float = 1e-3
                           ) -> tuple[BundleProblem, np.ndarray, int]:
    """The problem without the observations of points that went behind the camera (depth <=
    ``min_depth``) and without the points then seen fewer than ``min_views`` times (the scale anchor
    stays): there the clamped projection is not smooth and the solver stalls (a wrong match, or a
    far point whose depth wandered). Returns the problem, x in it and the number of observations
    dropped."""
    behind = _depths(problem, x) <= min_depth
    if not behind.any():
        return problem, x, 0
    full = problem.x_full.copy()
    full[problem.free] = x
    n_points = problem.num_points
    start = problem.point_offset()
    point_free = problem.free[start:].reshape(n_points, _POINT_SIZE)
    anchor = ~point_free.all(axis=1)
    keep_obs = ~behind
    keep_point = (np.bincount(problem.obs_point[keep_obs], minlength=n_points) >= min_views) | anchor
    keep_obs &= keep_point[problem.obs_point]
    new_index = np.cumsum(keep_point) - 1
    x_full = np.concatenate([full[:start], full[start:].reshape(n_points, _POINT_SIZE)[keep_point].ravel()])
    free = np.concatenate([problem.free[:start], point_free[keep_point].ravel()])
    reduced = BundleProblem(obs_pose=problem.obs_pose[keep_obs], obs_point=new_index[problem.obs_point[keep_obs]],
                            uv=problem.uv[keep_obs], R0=problem.R0, pixel_size_mm=problem.pixel_size_mm, free=free,
                            x_full=x_full, shutter=None if problem.shutter is None else problem.shutter[keep_obs])
    return reduced, x_full[free], int(len(keep_obs) - keep_obs.sum())


def bundle_adjust(tracks: FeatureTracks, camera0: Sequence[float], pixel_size_mm: Union[float, Sequence[float]], *,
                  keyframe_step: int = 3, min_views: int = 3, loss_scale_px: float = 2.0,
                  max_nfev: int = 100, ftol: float = 1e-6, max_track_frames: Optional[int] = None,
                  polish_steps: int = 200, line_delay: bool = False,
                  reference_row: Optional[float] = None) -> BundleResult:
    """Adjust the camera, keyframe poses (every ``keyframe_step``-th recorded frame) and points
    (features seen in >= ``min_views`` keyframes) from ``camera0`` and the filter's poses and
    points; soft_l1 loss at ``loss_scale_px``: ``max_nfev`` evaluations of SciPy's TRF, then up to
    ``polish_steps`` exact Levenberg-Marquardt steps (_polish). line_delay: estimate the rolling
    shutter's line delay too, from 0, with rows timed from ``reference_row`` (build_problem)."""
    if len(tracks) == 0:
        raise InputError("bundle adjustment: no tracks")
    started = time.perf_counter()
    px = np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,)).copy()
    problem = build_problem(tracks, np.asarray(camera0, float), px, keyframe_step, min_views, max_track_frames,
                            line_delay, reference_row)
    x0 = problem.x_full[problem.free]
    lower = np.full(len(x0), -np.inf)
    lower[0] = 1.0    # f > 0: from a poor start the mirrored camera (f < 0) is a solution too
    fit = least_squares(lambda x: residuals_and_jacobian(problem, x, jacobian=False)[0], x0,
                        jac=lambda x: residuals_and_jacobian(problem, x)[1],
                        method="trf", tr_solver="lsmr", x_scale="jac",
                        # tight LSMR tolerances (the default's inexact steps crawl: 200+ evaluations);
                        # TRF still creeps near the minimum, so stop at a 1e-6 relative cost change
                        # (f then within ~0.02 % of the full convergence, far inside its sigma)
                        tr_options={"atol": 1e-12, "btol": 1e-12}, ftol=ftol, loss="soft_l1", f_scale=loss_scale_px,
                        bounds=(lower, np.inf), max_nfev=max_nfev)
    x, polished, dropped = fit.x, 0, 0
    for _ in range(3):   # points that went behind a camera: dropped, then the finish again
        problem, x, behind = _without_points_behind(problem, x, min_views)
        dropped += behind
        x, steps = _polish(problem, x, loss_scale_px, lower[:len(x)], polish_steps)
        polished += steps
        if not (_depths(problem, x) <= 1e-3).any():
            break
    globals_ = problem.unpack(x)[0]
    camera = globals_[:_CAMERA_SIZE]
    cov_g, cov_tracks_g, cov_two_way_g, sigma_px, inliers, step = _camera_covariance(problem, x, loss_scale_px)
    # how far from the minimum the solver stopped, in the globals' own (model) sigmas: TRF can run out
    # of evaluations creeping along a flat valley after the camera has long settled
    free_globals = problem.free[:_GLOBAL_SIZE]
    step_sigma = float(np.max(np.abs(step[free_globals]) / np.sqrt(np.maximum(np.diag(cov_g)[free_globals], 1e-300))))
    line_delay_s = line_delay_bounds = None
    if problem.estimates_line_delay:
        half_d = _Z99 * np.sqrt(max(cov_two_way_g[_CAMERA_SIZE, _CAMERA_SIZE], 0.0))
        line_delay_s = float(globals_[_CAMERA_SIZE]) * _US
        line_delay_bounds = np.array([globals_[_CAMERA_SIZE] - half_d, globals_[_CAMERA_SIZE] + half_d]) * _US
    cov, cov_tracks, cov_two_way = (c[:_CAMERA_SIZE, :_CAMERA_SIZE] for c in (cov_g, cov_tracks_g, cov_two_way_g))
    half_two_way = _Z99 * np.sqrt(np.maximum(np.diag(cov_two_way), 0.0))
    half = _Z99 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    half_tracks = _Z99 * np.sqrt(np.maximum(np.diag(cov_tracks), 0.0))
    return BundleResult(camera=camera, covariance=cov, bounds_99=np.c_[camera - half, camera + half],
                        covariance_tracks=cov_tracks, bounds_99_tracks=np.c_[camera - half_tracks, camera + half_tracks],
                        covariance_clustered=cov_two_way,
                        bounds_99_clustered=np.c_[camera - half_two_way, camera + half_two_way],
                        sigma_px=sigma_px, keyframes=problem.num_poses, points=int(problem.obs_point.max()) + 1,
                        observations=len(problem.uv), inlier_fraction=inliers,
                        rms_px=float(np.sqrt(np.mean(residuals_and_jacobian(problem, x, jacobian=False)[0] ** 2))), nfev=int(fit.nfev), status=int(fit.status),
                        message=str(fit.message), elapsed_s=time.perf_counter() - started,
                        start=np.asarray(camera0, float), step_sigma=step_sigma, extra={"polish_steps": polished, "dropped_behind": dropped,
                                                                    "frame_interval_s": _frame_interval_s(tracks)},
                        line_delay_s=line_delay_s, line_delay_bounds_99_s=line_delay_bounds,
                        covariance_globals=cov_two_way_g)
