"""Intrinsic calibration from target detections with OpenCV (Zhang 2000, as in cv2.calibrateCamera):
the engine of the intrinsics job (its front door is pipeline.calibrate_intrinsics).

`calibrate_detections` picks views (all of them for a few stills; for a video the sharpest,
most varied `max_views`), runs cv2.calibrateCameraExtended (pinhole-radtan) or
cv2.fisheye.calibrate (pinhole-equidistant), and reports the RMS, per-view errors and the
standard deviations of the parameters.
"""
from __future__ import annotations

import contextlib
import re
from dataclasses import dataclass, field
from typing import Optional

import cv2
import numpy as np

from .._core import CameraModel
from ..detection.result import DetectionResult
from ..errors import InputError
from ..io.cameras import camera_from_opencv, opencv_matrices
from .options import MIN_VIEWS, IntrinsicsOptions

PARAM_NAMES = {
    "pinhole-radtan": ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"],
    "pinhole-equidistant": ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
}
MIN_POINTS_PER_VIEW = 6


@dataclass
class IntrinsicsResult:
    """An intrinsic calibration. Per-view arrays have one entry per view used.

    params / param_std: in the order of param_names (conventions.md layouts); std devs are
    sigma * sqrt(diag((J^T J)^-1)) with sigma^2 = sum of squared errors / (2N - unknowns).
    view_index: index of each view into the detections' observation frames.
    """

    camera: CameraModel
    model: str
    rms_px: float
    param_names: list
    params: np.ndarray
    param_std: np.ndarray
    view_index: np.ndarray
    view_frames: np.ndarray
    view_labels: list
    view_rms_px: np.ndarray
    view_points: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    views_available: int
    warnings: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready summary (SI units; pixels for intrinsics)."""
        k, dist = opencv_matrices(self.camera)
        return {
            "model": self.model,
            "image_width": int(self.camera.width),
            "image_height": int(self.camera.height),
            "rms_px": float(self.rms_px),
            "parameters": {n: float(v) for n, v in zip(self.param_names, self.params)},
            "std": {n: float(v) for n, v in zip(self.param_names, self.param_std)},
            "camera_matrix": k.tolist(),
            "distortion_coefficients": dist.tolist(),
            "views_used": int(len(self.view_index)),
            "views_available": int(self.views_available),
            "views": [{"frame": int(f), "label": str(lbl), "points": int(n), "rms_px": float(e)}
                      for f, lbl, n, e in zip(self.view_frames, self.view_labels, self.view_points, self.view_rms_px)],
            "warnings": list(self.warnings),
        }


def select_views(detections: DetectionResult, max_views: int) -> np.ndarray:
    """Indices (into the observation frames) of up to max_views views: sharp, and spread over
    image position, target size in the image and target tilt (farthest-point sampling)."""
    obs = detections.observations
    slices = obs.frame_slices()
    usable = np.array([len(s) >= MIN_POINTS_PER_VIEW for s in slices], dtype=bool)
    candidates = np.nonzero(usable)[0]
    if len(candidates) <= max_views:
        return candidates
    blur = np.nan_to_num(detections.blur_px[candidates], nan=np.nanmax(detections.blur_px[candidates])
                         if np.isfinite(detections.blur_px[candidates]).any() else 0.0)
    if len(candidates) >= 2 * max_views:
        # the sharpest half (or at least 2 * max_views) to choose from
        keep = max(2 * max_views, len(candidates) // 2)
        order = np.argsort(blur, kind="stable")[:keep]
        candidates, blur = candidates[np.sort(order)], blur[np.sort(order)]
    features = np.array([_view_features(obs, slices[i]) for i in candidates])
    spread = features.std(axis=0)
    features = features / np.where(spread > 1e-12, spread, 1.0)
    chosen = [int(np.argmin(blur))]
    distance = np.linalg.norm(features - features[chosen[0]], axis=1)
    blur_scale = max(float(np.ptp(blur)), 1e-9)
    while len(chosen) < max_views:
        # far from every chosen view; among near-equals, the sharper (a small penalty)
        score = distance - 0.1 * (blur - blur.min()) / blur_scale
        score[chosen] = -np.inf
        pick = int(np.argmax(score))
        chosen.append(pick)
        distance = np.minimum(distance, np.linalg.norm(features - features[pick], axis=1))
    return np.sort(candidates[chosen])


def _view_features(obs, rows: np.ndarray) -> np.ndarray:
    """Centre (fractions of the image), size (sqrt of hull area fraction) and tilt (normal's
    x, y from a planar PnP with a guessed focal length) of one view."""
    width, height = obs.image_size
    uv = obs.uv[rows]
    xy = obs.target_points[obs.point_id[rows]]
    centre = uv.mean(0) / [width, height]
    hull = cv2.convexHull(uv.astype(np.float32))
    size = np.sqrt(max(cv2.contourArea(hull), 0.0) / (width * height))
    f_guess = 0.9 * max(width, height)
    k = np.array([[f_guess, 0, width / 2], [0, f_guess, height / 2], [0, 0, 1.0]])
    normal = np.zeros(2)
    try:
        ok, rvec, _ = cv2.solvePnP(xy.astype(np.float64), uv.astype(np.float64), k, None, flags=cv2.SOLVEPNP_IPPE)
        if ok:
            normal = cv2.Rodrigues(rvec)[0][:2, 2]
    except cv2.error:
        pass
    return np.r_[centre, size, normal]


# Rolling shutter: a moving board is sheared by up to speed x readout. Views of a video are kept
# when that shift, with the readout bounded by a frame period, is at most STILL_SHIFT_PX; if fewer
# than MIN_STILL_VIEWS are that still, the stillest MIN_STILL_VIEWS are used with a warning.
STILL_SHIFT_PX = 0.5
MIN_STILL_VIEWS = 12
# k3 is fitted only when the board reaches this fraction of the image's half-diagonal (OpenCV's sample
# stills reach 73 % and keep its reference model; the phone video reached ~35 %).
K3_MIN_RADIUS = 0.7


def view_speeds_px_s(detections: DetectionResult) -> np.ndarray:
    """(F,) median image speed (px/s) of each observation frame from its neighbouring frames in the
    source (same corners), NaN where a neighbour is missing (stills, gaps)."""
    obs = detections.observations
    numbers = np.asarray(detections.frame_numbers)
    speed = np.full(obs.num_frames, np.nan)
    if obs.num_frames < 2:
        return speed
    table = np.full((obs.num_frames, len(obs.target_points), 2), np.nan)
    table[obs.frame_index, obs.point_id] = obs.uv
    for f in range(obs.num_frames):
        near = [g for g in (f - 1, f + 1) if 0 <= g < obs.num_frames and abs(numbers[g] - numbers[f]) == 1]
        values = []
        for g in near:
            dt = abs(obs.frame_times_s[g] - obs.frame_times_s[f])
            if dt <= 0:
                continue
            step = np.linalg.norm(table[g] - table[f], axis=1)
            step = step[np.isfinite(step)]
            if step.size >= MIN_POINTS_PER_VIEW:
                values.append(np.median(step) / dt)
        if values:
            speed[f] = float(np.mean(values))
    return speed


def still_frames(detections: DetectionResult, warnings: list) -> Optional[np.ndarray]:
    """Bool (F,) of the observation frames still enough for a rolling-shutter camera, or None when
    the input has no neighbouring frames (stills: nothing to judge)."""
    if detections.timestamps == "frame index":
        return None  # stills (an image folder without times): not a video
    speed = view_speeds_px_s(detections)
    known = np.isfinite(speed)
    if known.sum() < MIN_VIEWS:
        return None
    obs = detections.observations
    period = float(np.median(np.diff(obs.frame_times_s)))
    rows = obs.image_size[1]
    span = np.zeros(obs.num_frames)
    for f, sl in enumerate(obs.frame_slices()):
        if len(sl):
            span[f] = np.ptp(obs.uv[sl, 1]) / rows
    shift = speed * period * span          # px of shear if the readout took a whole frame period
    still = known & (shift <= STILL_SHIFT_PX)
    if still.sum() >= MIN_STILL_VIEWS:
        if still.sum() < known.sum():
            warnings.append(f"rolling shutter: {int(still.sum())} of {int(known.sum())} video frames are still "
                            f"enough (shear <= {STILL_SHIFT_PX:g} px) and were used; moving frames bias the focal "
                            "length and principal point")
        return still
    order = np.argsort(np.where(known, shift, np.inf))[:MIN_STILL_VIEWS]
    keep = np.zeros(obs.num_frames, dtype=bool)
    keep[order] = True
    worst = float(np.max(shift[order]))
    warnings.append(f"rolling shutter: only {int(still.sum())} video frames are still enough; the "
                    f"{MIN_STILL_VIEWS} stillest were used (shear up to {worst:.1f} px), so the intrinsics may be "
                    "biased: film a few seconds holding the camera still at several angles, or use stills")
    return keep


def radial_reach(detections: DetectionResult, views: np.ndarray) -> float:
    """Largest distance of a detected point from the image centre, as a fraction of the half-diagonal."""
    obs = detections.observations
    width, height = obs.image_size
    slices = obs.frame_slices()
    uv = np.concatenate([obs.uv[slices[v]] for v in views]) if len(views) else np.zeros((0, 2))
    if not len(uv):
        return 0.0
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    return float(np.max(np.linalg.norm(uv - centre, axis=1)) / np.hypot(width / 2.0, height / 2.0))


def calibrate_detections(detections: DetectionResult, options: Optional[IntrinsicsOptions] = None) -> IntrinsicsResult:
    """Calibrate from detections (see detection.pipeline.detect_video). InputError when there are too
    few views. options: IntrinsicsOptions (model, max_views, still_frames_only: from a video, use only
    frames still enough that the rolling shutter does not shear the board, still_frames). The model's
    terms are chosen by the data: pinhole-radtan fits k3 only when the board reaches K3_MIN_RADIUS of
    the half-diagonal and k3 is significant."""
    options = options or IntrinsicsOptions()
    model, max_views = options.model, options.max_views
    obs = detections.observations
    if obs.num_frames == 0:
        raise InputError(f"the target was not found in any of {detections.frames_total} frames "
                         f"({_dropped_text(detections.dropped)}); check the target file (e.g. its size)")
    warnings = []
    still = still_frames(detections, warnings) if options.still_frames_only else None
    if still is not None:
        chosen = _select_from(detections, np.flatnonzero(still), max_views)
        views = chosen
    else:
        views = select_views(detections, max_views)
    if len(views) < MIN_VIEWS:
        raise InputError(f"only {len(views)} view(s) with at least {MIN_POINTS_PER_VIEW} target points; "
                         f"need {MIN_VIEWS} or more")
    slices = obs.frame_slices()
    object_points = [obs.target_points[obs.point_id[slices[v]]].astype(np.float64) for v in views]
    image_points = [obs.uv[slices[v]].astype(np.float64) for v in views]
    size = obs.image_size
    with _one_opencv_thread():
        return _solve(detections, views, object_points, image_points, size, model, warnings)


@contextlib.contextmanager
def _one_opencv_thread():
    """OpenCV's solvers on one thread: on two, calibrateCamera's sums run in another order from run to
    run and the last bits of the camera change (measured: fx 249.17631971723708 vs ...13547)."""
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(threads)


def _solve(detections, views, object_points, image_points, size, model, warnings) -> IntrinsicsResult:
    """The fit of calibrate_detections on the chosen views (OpenCV on one thread: _one_opencv_thread)."""
    if model == "pinhole-radtan":
        reach = radial_reach(detections, views)
        fit_k3 = reach >= K3_MIN_RADIUS
        k, dist, rvecs, tvecs, std = _calibrate_radtan(object_points, image_points, size, fit_k3)
        if fit_k3 and not abs(dist[4]) > std[8]:
            warnings.append(f"k3 = {dist[4]:.3g} +- {std[8]:.2g} is not significant: refitted without k3 (k3 = 0)")
            k, dist, rvecs, tvecs, std = _calibrate_radtan(object_points, image_points, size, False)
        elif not fit_k3:
            warnings.append(f"k3 not fitted (k3 = 0): the board reached only {reach * 100:.0f} % of the image's "
                            f"half-diagonal (k3 needs >= {K3_MIN_RADIUS * 100:.0f} %: bring the board into the corners)")
        params = np.r_[k[0, 0], k[1, 1], k[0, 2], k[1, 2], dist[:5]]
    else:
        k, dist, rvecs, tvecs, std = _calibrate_fisheye(object_points, image_points, size)
        params = np.r_[k[0, 0], k[1, 1], k[0, 2], k[1, 2], dist[:4]]
    camera = camera_from_opencv(k, dist, size[0], size[1], model)
    errors = [_reprojection_errors(model, o, i, r, t, k, dist)
              for o, i, r, t in zip(object_points, image_points, rvecs, tvecs)]
    squared = np.concatenate([e ** 2 for e in errors])
    rms = float(np.sqrt(squared.mean()))
    view_rms = np.array([np.sqrt(np.mean(e ** 2)) for e in errors])
    if len(views) < 10:
        warnings.append(f"only {len(views)} views: the distortion terms are weakly determined")
    if rms > 1.0:
        warnings.append(f"RMS {rms:.2f} px is high: check the target dimensions and the views with large errors")
    return IntrinsicsResult(
        camera=camera, model=model, rms_px=rms, param_names=list(PARAM_NAMES[model]), params=params,
        param_std=np.asarray(std, dtype=np.float64), view_index=views,
        view_frames=detections.frame_numbers[views], view_labels=[detections.frame_labels[v] for v in views],
        view_rms_px=view_rms, view_points=np.array([len(i) for i in image_points]),
        rvecs=np.array([np.ravel(r) for r in rvecs]), tvecs=np.array([np.ravel(t) for t in tvecs]),
        views_available=detections.observations.num_frames, warnings=warnings)


def _select_from(detections: DetectionResult, frames: np.ndarray, max_views: int) -> np.ndarray:
    """select_views among the given observation frames only."""
    obs = detections.observations
    keep = np.zeros(obs.num_frames, dtype=bool)
    keep[frames] = True
    sub = DetectionResult(obs.subset_frames(keep), detections.frames_total, int(keep.sum()), detections.dropped,
                          detections.from_cache, detections.image_size, np.asarray(detections.frame_numbers)[keep],
                          [lbl for lbl, k in zip(detections.frame_labels, keep) if k],
                          np.asarray(detections.blur_px)[keep], detections.timestamps)
    return np.flatnonzero(keep)[select_views(sub, max_views)]


def _calibrate_radtan(object_points, image_points, size, fit_k3: bool = True):
    obj = [o.astype(np.float32).reshape(-1, 1, 3) for o in object_points]
    img = [i.astype(np.float32).reshape(-1, 1, 2) for i in image_points]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        _, k, dist, rvecs, tvecs, std_intrinsics, _, _ = cv2.calibrateCameraExtended(
            obj, img, tuple(size), None, None, flags=0 if fit_k3 else cv2.CALIB_FIX_K3, criteria=criteria)
    except cv2.error as error:
        raise InputError(f"calibration failed ({_cv_message(error)})") from None
    # OpenCV's order: fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, ...
    return k, dist.ravel()[:5], rvecs, tvecs, std_intrinsics.ravel()[:9]


def _calibrate_fisheye(object_points, image_points, size):
    obj = [o.reshape(-1, 1, 3).astype(np.float64) for o in object_points]
    img = [i.reshape(-1, 1, 2).astype(np.float64) for i in image_points]
    flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    try:
        _, k, dist, rvecs, tvecs = cv2.fisheye.calibrate(obj, img, tuple(size), None, None, flags=flags,
                                                         criteria=criteria)
    except cv2.error as error:
        raise InputError(f"fisheye calibration failed ({_cv_message(error)}); try more, less tilted views") from None
    dist = dist.ravel()[:4]
    std = _fisheye_std(obj, img, k, dist, rvecs, tvecs)
    return k, dist, rvecs, tvecs, std


def _fisheye_std(obj, img, k, dist, rvecs, tvecs) -> np.ndarray:
    """Std devs of fx, fy, cx, cy, k1..k4 from the full Jacobian (cv2.fisheye.projectPoints
    returns d(uv)/d[fx fy cx cy k1..k4 rvec tvec alpha])."""
    views = len(obj)
    blocks, residuals = [], []
    for v in range(views):
        projected, jacobian = cv2.fisheye.projectPoints(obj[v], rvecs[v], tvecs[v], k, dist)
        residuals.append((img[v] - projected).ravel())
        rows = np.zeros((jacobian.shape[0], 8 + 6 * views))
        rows[:, :8] = jacobian[:, :8]
        rows[:, 8 + 6 * v: 14 + 6 * v] = jacobian[:, 8:14]
        blocks.append(rows)
    jac = np.vstack(blocks)
    res = np.concatenate(residuals)
    dof = max(1, len(res) - jac.shape[1])
    sigma2 = float(res @ res) / dof
    try:
        covariance = np.linalg.inv(jac.T @ jac) * sigma2
    except np.linalg.LinAlgError:
        return np.full(8, np.nan)
    return np.sqrt(np.maximum(np.diag(covariance)[:8], 0.0))


def _reprojection_errors(model, obj, img, rvec, tvec, k, dist) -> np.ndarray:
    if model == "pinhole-radtan":
        projected, _ = cv2.projectPoints(obj.reshape(-1, 1, 3), rvec, tvec, k, dist)
    else:
        projected, _ = cv2.fisheye.projectPoints(obj.reshape(-1, 1, 3), rvec, tvec, k, dist)
    return np.linalg.norm(projected.reshape(-1, 2) - img.reshape(-1, 2), axis=1)


def _cv_message(error: cv2.error) -> str:
    text = str(error)
    match = re.search(r"error: \(-?\d+:[^)]*\) (.*?)(?: in function|$)", text, re.S)
    return (match.group(1) if match else text).strip().splitlines()[0][:200]


def _dropped_text(dropped: dict) -> str:
    if not dropped:
        return "none dropped"
    return ", ".join(f"{count} {reason.replace('_', ' ')}" for reason, count in sorted(dropped.items()))
