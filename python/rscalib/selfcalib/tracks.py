"""Feature tracks made for the self-calibration bundle adjustment (issue 30; docs/sog.md §23).

The filter's front end (:mod:`front_end`) keeps the ~100 features the EKF bank can afford. The
bundle adjustment wants many long tracks that do not drift, each observation with its image velocity
(its rolling-shutter term). This module makes them from the images alone (no camera model: f is
what is being estimated):

- **KLT with a forward-backward check**: pyramidal Lucas-Kanade from the previous frame
  (``cv2.calcOpticalFlowPyrLK``), tracked back; a point that does not return within
  ``fb_max_px`` is lost.
- **Geometric verification** of each frame pair (and of each keyframe pair, a longer baseline) by
  RANSAC (USAC MAGSAC) fundamental matrix; when a homography explains nearly every inlier (a plane,
  or a rotation: the fundamental matrix is then not determined and would let a moving patch pass)
  the homography is the test, at a wider threshold (:func:`geometric_inliers`).
- **Anchoring**: each track keeps its first view (a patch) and an affine warp from it; at every
  keyframe the warp is refined by inverse-compositional Lucas-Kanade (Baker & Matthews 2004) against
  that first view, with gain and bias normalised (auto-exposure), for all tracks at once. So the
  error does not add up from frame to frame: between keyframes a track carries the KLT error of a
  few frames only. A track whose first view no longer matches ends there (re-anchoring it at its
  KLT position instead keeps that position's error for the rest of the track: measured, §22).
- **New corners** (``cv2.goodFeaturesToTrack``) where tracks are missing, away from live tracks,
  spread over a grid of cells; a corner whose first view fixes a position badly (an edge, faint
  texture: ``position_sigma``, which also weights the track for the adjustment) starts no track.
- **Re-identification**: a track that is lost (left the view, or failed the KLT check) keeps its
  ORB descriptors (at birth and where it was last seen), first view and warp for a while; a new
  corner that matches one (ratio test, mutual best), passes a RANSAC check between a keyframe where
  the lost track was seen and the current frame, and aligns with its first view, takes its old id.
- **Image velocity** of every observation (px/s) from its track's neighbours and the frames' own
  times (:func:`image_velocities`), and **keyframes** chosen online (every ``keyframe_max_gap_frames``
  frames, sooner when the tracks moved ``keyframe_displacement_px`` or fewer than
  ``keyframe_min_survival`` of them survived): :meth:`TrackSet.keyframe_observations` hands the
  adjustment its observations.

Only the previous frame is kept; per track a small patch and a descriptor. Frames are an iterable of
``(time_s, grayscale uint8 image)`` (:func:`rscalib.io.video.read_gray_frames`).
"""
from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass, field, fields
from typing import Iterable, Optional

import cv2
import numpy as np

from .. import checks
from .._progress import Progress, ProgressArg
from ..errors import InputError
from .options import TrackOptions

__all__ = ["KeyframeObservations", "TrackOptions", "TrackSet", "FeatureTracker", "fit_two_view_model",
           "geometric_inliers", "image_velocities", "track_features", "two_view_distance"]



@dataclass
class KeyframeObservations:
    """Observations at keyframes, for the adjustment: row i is track ``track_id[i]`` seen at
    ``uv_px[i]`` (distorted pixels) in frame ``frame[i]`` (time ``t_s[i]``), moving at
    ``velocity_px_s[i]`` (NaN: unknown, e.g. a track seen in one frame only), its track's
    ``position_sigma[i]`` (px per grey level of image noise: a relative weight, larger is worse)."""

    frame: np.ndarray
    t_s: np.ndarray
    track_id: np.ndarray
    uv_px: np.ndarray
    velocity_px_s: np.ndarray
    keyframes: np.ndarray
    position_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.frame)


@dataclass
class TrackSet:
    """Every observation of every track: ``frame`` (N,), ``track_id`` (N,), ``uv_px`` (N, 2),
    ``velocity_px_s`` (N, 2), ``anchored`` (N,): refined against the track's first view (at
    keyframes), ``position_sigma`` (N,): how well the track's first view fixes a position (px per
    grey level of image noise: a relative weight for the adjustment; larger is worse). Per frame: ``t_s`` (F,); ``keyframes``: frame indices. ``stats``: counters and the
    tracker's time; ``reid_events``: (frame, track id, frame it was last seen) per re-identification."""

    image_size: tuple[int, int]
    t_s: np.ndarray
    keyframes: np.ndarray
    frame: np.ndarray
    track_id: np.ndarray
    uv_px: np.ndarray
    velocity_px_s: np.ndarray
    anchored: np.ndarray
    position_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stats: dict = field(default_factory=dict)
    reid_events: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))

    def __len__(self) -> int:
        return len(self.frame)

    def track_lengths(self) -> dict:
        """Per track id: (frames spanned from first to last observation, observations, keyframes seen)."""
        order = np.lexsort((self.frame, self.track_id))
        ids, first = np.unique(self.track_id[order], return_index=True)
        last = np.r_[first[1:], len(order)] - 1
        is_kf = np.isin(self.frame[order], self.keyframes)
        kf_counts = np.add.reduceat(is_kf.astype(np.int64), first) if len(first) else np.zeros(0, np.int64)
        span = self.frame[order][last] - self.frame[order][first] + 1
        return {"track_id": ids, "span_frames": span, "observations": last - first + 1, "keyframes": kf_counts}

    def keyframe_observations(self, min_keyframes: int = 3, max_keyframes: Optional[int] = None
                              ) -> KeyframeObservations:
        """The observations at keyframes (at most ``max_keyframes`` of them, evenly thinned) of the
        tracks seen in at least ``min_keyframes`` of those keyframes."""
        keyframes = np.asarray(self.keyframes, np.int64)
        if max_keyframes is not None and len(keyframes) > max_keyframes:
            if max_keyframes < 2:
                raise InputError("max_keyframes must be at least 2")
            keyframes = keyframes[np.unique(np.round(np.linspace(0, len(keyframes) - 1, max_keyframes)).astype(int))]
        rows = np.flatnonzero(np.isin(self.frame, keyframes))
        ids, counts = np.unique(self.track_id[rows], return_counts=True)
        rows = rows[np.isin(self.track_id[rows], ids[counts >= min_keyframes])]
        sigma = self.position_sigma[rows].copy() if len(self.position_sigma) == len(self) else np.full(len(rows), np.nan)
        return KeyframeObservations(self.frame[rows].copy(), self.t_s[self.frame[rows]], self.track_id[rows].copy(),
                                    self.uv_px[rows].copy(), self.velocity_px_s[rows].copy(), keyframes, sigma)


# --------------------------------------------------------------------------------------------------
# Geometry and velocities


_RANSAC_METHODS = {"ransac": (cv2.FM_RANSAC, cv2.RHO), "magsac": (cv2.USAC_MAGSAC, cv2.USAC_MAGSAC)}


def geometric_inliers(uv0: np.ndarray, uv1: np.ndarray, threshold_px: float, homography_share: float,
                      homography_px_factor: float, min_points: int = 15, method: str = "ransac") -> np.ndarray:
    """Which correspondences ``uv0[i] <-> uv1[i]`` agree with one rigid scene: inliers of a RANSAC
    fundamental matrix (refitted on its inliers) at ``threshold_px`` (Sampson distance); but when a
    homography explains at least ``homography_share`` of those inliers, the views are (nearly)
    related by a homography — a plane, or a rotation — where the fundamental matrix is not
    determined and can bend to fit a moving patch, so the inliers of the homography at
    ``homography_px_factor`` times the threshold are returned instead. Fewer than ``min_points``
    correspondences: all kept. ``method``: "ransac" (OpenCV's RANSAC for F, its PROSAC-based RHO for
    H) or "magsac" (USAC MAGSAC++ for both: ~10x slower here)."""
    uv0 = np.asarray(uv0, np.float64).reshape(-1, 2)
    uv1 = np.asarray(uv1, np.float64).reshape(-1, 2)
    model = fit_two_view_model(uv0, uv1, threshold_px, homography_share, min_points, method)
    if model is None:
        return np.ones(len(uv0), bool)
    return two_view_distance(model, uv0, uv1) <= threshold_px * (homography_px_factor if model[0] == "H" else 1.0)


def fit_two_view_model(uv0: np.ndarray, uv1: np.ndarray, threshold_px: float, homography_share: float,
                       min_points: int = 15, method: str = "ransac") -> Optional[tuple[str, np.ndarray]]:
    """("F", F) or ("H", H) as :func:`geometric_inliers` chooses them; None when it cannot tell
    (fewer than ``min_points`` correspondences, or no model found)."""
    if method not in _RANSAC_METHODS:
        raise InputError(f"unknown RANSAC method {method!r} ({', '.join(_RANSAC_METHODS)})")
    method_f, method_h = _RANSAC_METHODS[method]
    uv0 = np.asarray(uv0, np.float64).reshape(-1, 2)
    uv1 = np.asarray(uv1, np.float64).reshape(-1, 2)
    n = len(uv0)
    if n < max(min_points, 8):
        return None
    with np.errstate(all="ignore"):
        try:
            F, mask_f = cv2.findFundamentalMat(uv0, uv1, method_f, threshold_px, 0.999, 1000)
            H, mask_h = cv2.findHomography(uv0, uv1, method_h, threshold_px, maxIters=1000, confidence=0.999)
        except cv2.error:
            return None
    count_f = 0
    if F is not None and mask_f is not None and F.shape == (3, 3):
        inliers_f = mask_f.ravel().astype(bool)
        if inliers_f.sum() >= 8:   # RANSAC's F comes from a minimal sample: refit on its inliers
            refit, _ = cv2.findFundamentalMat(uv0[inliers_f], uv1[inliers_f], cv2.FM_8POINT)
            if refit is not None and refit.shape == (3, 3):
                F = refit
        count_f = int(np.sum(_sampson_px(F, uv0, uv1) <= threshold_px))
    else:
        F = None
    if H is None or H.shape != (3, 3):
        return ("F", F) if F is not None else None
    if mask_h.sum() >= 4:          # likewise: least squares on the inliers
        refit, _ = cv2.findHomography(uv0[mask_h.ravel() > 0], uv1[mask_h.ravel() > 0], 0)
        if refit is not None and refit.shape == (3, 3):
            H = refit
    count_h = int(np.sum(two_view_distance(("H", H), uv0, uv1) <= threshold_px))
    if F is None or count_h >= homography_share * count_f:
        return ("H", H)
    return ("F", F)


def two_view_distance(model: tuple[str, np.ndarray], uv0: np.ndarray, uv1: np.ndarray) -> np.ndarray:
    """Distances (px) of correspondences from a two-view model: Sampson for F, transfer for H."""
    kind, M = model
    uv0 = np.asarray(uv0, np.float64).reshape(-1, 2)
    uv1 = np.asarray(uv1, np.float64).reshape(-1, 2)
    if kind == "F":
        return _sampson_px(M, uv0, uv1)
    with np.errstate(all="ignore"):
        mapped = cv2.perspectiveTransform(uv0.reshape(-1, 1, 2), M).reshape(-1, 2)
    d = np.linalg.norm(mapped - uv1, axis=1)
    return np.where(np.isfinite(d), d, np.inf)


def _sampson_px(F: np.ndarray, uv0: np.ndarray, uv1: np.ndarray) -> np.ndarray:
    """First-order geometric (Sampson) distance (px) of correspondences from the epipolar geometry F."""
    x0, x1 = np.c_[uv0, np.ones(len(uv0))], np.c_[uv1, np.ones(len(uv1))]
    Fx0, Ftx1 = x0 @ F.T, x1 @ F
    e = np.sum(x1 * Fx0, axis=1)
    den = Fx0[:, 0] ** 2 + Fx0[:, 1] ** 2 + Ftx1[:, 0] ** 2 + Ftx1[:, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, np.abs(e) / np.sqrt(den), np.inf)


def image_velocities(frame: np.ndarray, track_id: np.ndarray, uv_px: np.ndarray, t_s: np.ndarray,
                     max_gap_frames: int = 3) -> np.ndarray:
    """Each observation's image velocity (N, 2) in px/s from its track's neighbouring observations
    (central difference over the frames' own times ``t_s[frame]``, else one-sided), neighbours at
    most ``max_gap_frames`` frames away; NaN without one."""
    frame = np.asarray(frame, np.int64)
    track_id = np.asarray(track_id, np.int64)
    uv = np.asarray(uv_px, np.float64).reshape(-1, 2)
    velocity = np.full((len(frame), 2), np.nan)
    if len(frame) == 0:
        return velocity
    order = np.lexsort((frame, track_id))
    fid, fr, p = track_id[order], frame[order], uv[order]
    t = np.asarray(t_s, np.float64)[fr]
    n = len(fid)
    before, after = np.maximum(np.arange(n) - 1, 0), np.minimum(np.arange(n) + 1, n - 1)
    has_before = (fid[before] == fid) & (fr - fr[before] > 0) & (fr - fr[before] <= max_gap_frames)
    has_after = (fid[after] == fid) & (fr[after] - fr > 0) & (fr[after] - fr <= max_gap_frames)
    with np.errstate(invalid="ignore", divide="ignore"):
        central = (p[after] - p[before]) / (t[after] - t[before])[:, None]
        backward = (p - p[before]) / (t - t[before])[:, None]
        forward = (p[after] - p) / (t[after] - t)[:, None]
    velocity[order] = np.where((has_before & has_after)[:, None], central,
                               np.where(has_before[:, None], backward,
                                        np.where(has_after[:, None], forward, np.nan)))
    return velocity


# --------------------------------------------------------------------------------------------------
# First views and their alignment (inverse-compositional affine Lucas-Kanade, all tracks at once)


class _Anchors:
    """Per track its first view, normalised (zero mean, unit variance under a Gaussian window), and
    what the inverse-compositional update needs from it: the weighted steepest-descent images and the
    inverse Hessian (Baker & Matthews 2004, affine warp ``x -> A x + t`` of offsets ``x`` around the
    track)."""

    def __init__(self, half: int) -> None:
        self.half = half
        size = 2 * half + 1
        offsets = np.arange(-half, half + 1, dtype=np.float32)
        xx, yy = np.meshgrid(offsets, offsets)
        self.x, self.y = xx.ravel(), yy.ravel()
        weight = np.exp(-(self.x ** 2 + self.y ** 2) / (2 * (0.8 * half) ** 2)).astype(np.float32)
        self.weight = weight / weight.sum()
        self.grid = np.stack([self.x, self.y, np.ones_like(self.x)], axis=1)   # (P, 3)
        ext = np.arange(-half - 1, half + 2, dtype=np.float32)
        ex, ey = np.meshgrid(ext, ext)
        self.grid_ext = np.stack([ex.ravel(), ey.ravel()], axis=1)             # (P+, 2): with a border
        self.size = size

    def sample(self, image: np.ndarray, warp: np.ndarray, extended: bool = False) -> np.ndarray:
        """(N, P) bilinear samples of ``image`` at ``warp`` (N, 2, 3) applied to the offsets."""
        n = len(warp)
        if n == 0:
            return np.zeros((0, (self.size + 2 * extended) ** 2), np.float32)
        if extended:
            pos = warp[:, :, :2] @ self.grid_ext.T + warp[:, :, 2:]
            side = self.size + 2
        else:
            pos = warp @ self.grid.T
            side = self.size
        map_x = np.ascontiguousarray(pos[:, 0, :].reshape(n * side, side), dtype=np.float32)
        map_y = np.ascontiguousarray(pos[:, 1, :].reshape(n * side, side), dtype=np.float32)
        out = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return out.reshape(n, side * side)

    def normalise(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mean = values @ self.weight
        centred = values - mean[:, None]
        std = np.sqrt(np.maximum((centred * centred) @ self.weight, 0.0)) + 1e-3
        return centred / std[:, None], std

    def make(self, image: np.ndarray, warp: np.ndarray) -> dict:
        """First views of tracks at ``warp`` (N, 2, 3) in ``image`` (float32)."""
        n, s = len(warp), self.size
        if n == 0:
            p = s * s
            return {"template": np.zeros((0, p), np.float32), "sd_w": np.zeros((0, 6, p), np.float32),
                    "hessian_inv": np.zeros((0, 6, 6), np.float32), "texture": np.zeros(0, np.float32)}
        ext = self.sample(image, warp, extended=True).reshape(n, s + 2, s + 2)
        gy, gx = np.gradient(ext, axis=(1, 2))
        inner = ext[:, 1:-1, 1:-1].reshape(n, -1)
        gx = gx[:, 1:-1, 1:-1].reshape(n, -1)
        gy = gy[:, 1:-1, 1:-1].reshape(n, -1)
        template, std = self.normalise(inner)
        gx, gy = gx / std[:, None], gy / std[:, None]
        sd = np.stack([gx * self.x, gx * self.y, gy * self.x, gy * self.y, gx, gy], axis=1)   # (N, 6, P)
        sd_w = (sd * self.weight).astype(np.float32)
        hessian = (sd_w @ sd.transpose(0, 2, 1)).astype(np.float64)
        # A little damping of the four shape parameters: a track on an edge or a blob has no
        # well-defined shape; its position stays as determined as the texture allows.
        trans = 0.5 * (hessian[:, 4, 4] + hessian[:, 5, 5])
        damping = np.array([self.half ** 2] * 4 + [0.0, 0.0])
        hessian += (1e-2 * trans)[:, None, None] * np.diag(damping)[None] + 1e-9 * np.eye(6)[None]
        return {"template": template.astype(np.float32), "sd_w": sd_w,
                "hessian_inv": np.linalg.inv(hessian).astype(np.float32), "texture": std}

    def align(self, image: np.ndarray, ref: dict, warp: np.ndarray, iterations: int
              ) -> tuple[np.ndarray, np.ndarray]:
        """Refined warps (N, 2, 3) and their zero-normalised cross-correlation with the first view."""
        warp = warp.astype(np.float32).copy()
        n = len(warp)
        zncc = np.zeros(n, np.float32)
        if n == 0:
            return warp, zncc
        for _ in range(iterations):
            current, _ = self.normalise(self.sample(image, warp))
            error = current - ref["template"]
            b = np.einsum("nkp,np->nk", ref["sd_w"], error)
            dp = np.einsum("nkl,nl->nk", ref["hessian_inv"], b)
            step = np.zeros((n, 3, 3), np.float32)
            step[:, 0, 0], step[:, 0, 1], step[:, 0, 2] = 1 + dp[:, 0], dp[:, 1], dp[:, 4]
            step[:, 1, 0], step[:, 1, 1], step[:, 1, 2] = dp[:, 2], 1 + dp[:, 3], dp[:, 5]
            step[:, 2, 2] = 1
            full = np.zeros((n, 3, 3), np.float32)
            full[:, :2], full[:, 2, 2] = warp, 1
            with np.errstate(all="ignore"):
                warp = (full @ np.linalg.inv(step))[:, :2]
            warp = np.where(np.isfinite(warp), warp, 0.0).astype(np.float32)
        current, _ = self.normalise(self.sample(image, warp))
        zncc = (current * ref["template"]) @ self.weight
        return warp, zncc


def _position_sigma(hessian_inv: np.ndarray, texture: np.ndarray) -> np.ndarray:
    """Per first view: the standard deviation (px) of its position with its shape free, per grey
    level of image noise: the largest eigenvalue of the translation block of H⁻¹ (the normalised
    patch's) divided by the patch's contrast (its standard deviation in grey levels). Large on an
    edge (the position along it is not fixed) and on faint texture."""
    block = hessian_inv[:, 4:6, 4:6].astype(np.float64)
    shape = np.sqrt(np.maximum(np.linalg.eigvalsh(0.5 * (block + block.transpose(0, 2, 1)))[:, 1], 0.0))
    return shape / np.maximum(np.asarray(texture, np.float64), 1e-6)


def _take(ref: dict, index: np.ndarray) -> dict:
    return {k: v[index] for k, v in ref.items()}


class _FirstViews:
    """The first views of live and lost tracks in slots of preallocated arrays (tracks refer to
    their slot), so dropping or moving a track copies no patch."""

    def __init__(self, anchors: _Anchors) -> None:
        empty = anchors.make(np.zeros((8, 8), np.float32), np.zeros((0, 2, 3), np.float32))
        self.arrays = {k: np.zeros((64,) + v.shape[1:], v.dtype) for k, v in empty.items()}
        self.free_slots = list(range(63, -1, -1))

    def add(self, ref: dict) -> np.ndarray:
        n = len(ref["template"])
        while len(self.free_slots) < n:
            size = len(self.arrays["template"])
            self.arrays = {k: np.concatenate([v, np.zeros_like(v)]) for k, v in self.arrays.items()}
            self.free_slots = list(range(2 * size - 1, size - 1, -1)) + self.free_slots
        slots = np.array([self.free_slots.pop() for _ in range(n)], np.int64)
        self.put(slots, ref)
        return slots

    def put(self, slots: np.ndarray, ref: dict) -> None:
        for k, v in self.arrays.items():
            v[slots] = ref[k]

    def get(self, slots: np.ndarray) -> dict:
        return {k: v[slots] for k, v in self.arrays.items()}

    def release(self, slots: np.ndarray) -> None:
        self.free_slots.extend(int(i) for i in slots)


def _translation_warps(uv: np.ndarray) -> np.ndarray:
    warp = np.zeros((len(uv), 2, 3), np.float32)
    warp[:, 0, 0] = warp[:, 1, 1] = 1.0
    warp[:, :, 2] = uv
    return warp


# --------------------------------------------------------------------------------------------------
# The tracker


class FeatureTracker:
    """Tracks corners through frames handed to :meth:`add_frame` one at a time; :meth:`result`
    gives the :class:`TrackSet`. See the module docstring for the steps."""

    def __init__(self, image_size: tuple[int, int], options: Optional[TrackOptions] = None) -> None:
        width, height = (int(s) for s in image_size)
        if width < 32 or height < 32:
            raise InputError(f"images of {width}x{height} are too small to track (at least 32x32)")
        self.image_size = (width, height)
        self.options = (options or TrackOptions()).scaled(self.image_size)
        o = self.options
        if o.target_tracks < 1 or o.grid_cols < 1 or o.grid_rows < 1 or o.keyframe_max_gap_frames < 1:
            raise InputError("target_tracks, grid_cols, grid_rows and keyframe_max_gap_frames must be positive")
        if o.on_anchor_failure not in ("end", "reanchor"):
            raise InputError(f"on_anchor_failure must be 'end' or 'reanchor', not {o.on_anchor_failure!r}")
        self._anchors = _Anchors(o.anchor_half_px)
        self._margin = o.anchor_half_px + o.border_px + 1
        self._orb = cv2.ORB_create(nfeatures=1, nlevels=1, edgeThreshold=16, patchSize=31)
        self._klt = dict(winSize=(o.klt_window_px, o.klt_window_px), maxLevel=o.klt_levels,
                         criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, o.klt_iterations, o.klt_epsilon_px))
        self._disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * int(o.min_distance_px) + 1,) * 2)
        self._disk_half = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * int(o.min_distance_px / 2) + 1,) * 2)
        self._next_id = 0
        self._k = -1
        self._prev: Optional[np.ndarray] = None
        # live tracks (parallel arrays)
        self._ids = np.zeros(0, np.int64)
        self._uv = np.zeros((0, 2), np.float64)
        self._step = np.zeros((0, 2), np.float64)   # last frame-to-frame motion (px): KLT's start
        self._warp = np.zeros((0, 2, 3), np.float32)
        self._views = _FirstViews(self._anchors)
        self._slot = np.zeros(0, np.int64)     # each live track's first view in _views
        self._birth_desc = np.zeros((0, 32), np.uint8)
        self._has_desc = np.zeros(0, bool)
        self._anchored = np.zeros(0, bool)     # this frame's position was aligned with the first view
        self._last_kf = -1
        self._kf_ids = np.zeros(0, np.int64)
        self._kf_uv = np.zeros((0, 2))
        # lost tracks that may come back
        self._pool: dict = self._empty_pool()
        # records
        self._obs_ids: list[np.ndarray] = []
        self._obs_uv: list[np.ndarray] = []
        self._obs_anchored: list[np.ndarray] = []
        self._track_sigma: list[float] = []     # per track id: how well its first view fixes a position
        self._t_s: list[float] = []
        self._keyframes: list[int] = []
        self._kf_index: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._reid_events: list[tuple[int, int, int]] = []
        self.stats = {k: 0 for k in ("births", "lost_klt", "left_view", "rejected_frame_ransac",
                                     "rejected_keyframe_ransac", "anchored", "reanchored", "anchor_failed",
                                     "reid_candidates", "reid_rejected_geometry", "reid_rejected_appearance",
                                     "reid_fired")}
        self.stats["wall_s"] = 0.0         # in add_frame (per-call CPU clocks cost ~1 ms under load)

    # ---------------------------------------------------------------- bookkeeping
    def _empty_pool(self) -> dict:
        return {"ids": np.zeros(0, np.int64), "lost_frame": np.zeros(0, np.int64),
                "desc": np.zeros((0, 2, 32), np.uint8), "has_desc": np.zeros((0, 2), bool),
                "warp": np.zeros((0, 2, 3), np.float32), "slot": np.zeros(0, np.int64)}

    def _keep(self, keep: np.ndarray, release: Optional[np.ndarray] = None) -> None:
        """Keep the live tracks ``keep``; the first views of ``release`` (of those dropped) are freed."""
        if release is not None:
            self._views.release(self._slot[release])
        self._ids, self._uv, self._warp = self._ids[keep], self._uv[keep], self._warp[keep]
        self._step = self._step[keep]
        self._slot = self._slot[keep]
        self._birth_desc, self._has_desc = self._birth_desc[keep], self._has_desc[keep]
        self._anchored = self._anchored[keep]

    def _append(self, ids, uv, warp, slots, desc, has_desc, anchored) -> None:
        self._ids = np.r_[self._ids, ids]
        self._uv = np.r_[self._uv, uv]
        start = np.median(self._step, axis=0) if len(self._step) else np.zeros(2)   # the image's motion
        self._step = np.r_[self._step, np.tile(start, (len(uv), 1))]
        self._warp = np.concatenate([self._warp, warp])
        self._slot = np.r_[self._slot, slots]
        self._birth_desc = np.concatenate([self._birth_desc, desc])
        self._has_desc = np.r_[self._has_desc, has_desc]
        self._anchored = np.r_[self._anchored, anchored]

    def _inside(self, uv: np.ndarray) -> np.ndarray:
        m = self._margin
        w, h = self.image_size
        return (uv[:, 0] >= m) & (uv[:, 0] <= w - 1 - m) & (uv[:, 1] >= m) & (uv[:, 1] <= h - 1 - m)

    def _describe(self, image: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ORB descriptors (N, 32) at ``uv`` and which could be computed (not too near the edge)."""
        desc = np.zeros((len(uv), 32), np.uint8)
        ok = np.zeros(len(uv), bool)
        if len(uv) == 0:
            return desc, ok
        points = [cv2.KeyPoint(float(u), float(v), 31.0, -1, 0, 0, i) for i, (u, v) in enumerate(uv)]
        points, computed = self._orb.compute(image, points)
        if computed is not None and len(points):
            index = np.array([p.class_id for p in points], np.int64)
            desc[index], ok[index] = computed, True
        return desc, ok

    def _to_pool(self, index: np.ndarray, prev: np.ndarray) -> None:
        """Live tracks ``index`` are lost (seen last in ``prev``): remember them for re-identification
        (or forget them: their first views are freed)."""
        if len(index) == 0:
            return
        if not self.options.reid:
            self._views.release(self._slot[index])
            return
        desc, ok = self._describe(prev, self._uv[index])
        pool = self._pool
        pool["ids"] = np.r_[pool["ids"], self._ids[index]]
        pool["lost_frame"] = np.r_[pool["lost_frame"], np.full(len(index), self._k - 1)]
        pool["desc"] = np.concatenate([pool["desc"], np.stack([self._birth_desc[index], desc], axis=1)])
        pool["has_desc"] = np.concatenate([pool["has_desc"], np.stack([self._has_desc[index], ok], axis=1)])
        pool["warp"] = np.concatenate([pool["warp"], self._warp[index]])
        pool["slot"] = np.r_[pool["slot"], self._slot[index]]
        keep = (self._k - pool["lost_frame"] <= self.options.reid_max_gap_frames)
        if keep.sum() > self.options.reid_pool_size:
            keep &= np.arange(len(keep)) >= len(keep) - self.options.reid_pool_size
        self._views.release(pool["slot"][~keep])
        self._take_pool(keep)

    def _take_pool(self, keep: np.ndarray) -> None:
        pool = self._pool
        for key in ("ids", "lost_frame", "desc", "has_desc", "warp", "slot"):
            pool[key] = pool[key][keep]

    # ---------------------------------------------------------------- per frame
    def add_frame(self, t_s: float, image: np.ndarray) -> None:
        """Track into the next frame (time ``t_s`` s, grayscale uint8 image of the tracker's size)."""
        started_wall = time.perf_counter()
        image = self._checked(t_s, image)
        self._k += 1
        self._t_s.append(float(t_s))
        o = self.options
        image_f = image.astype(np.float32)
        self._anchored[:] = False
        if self._prev is not None and len(self._ids):
            self._track(image)
        keyframe = self._is_keyframe()
        if keyframe:
            self._anchor(image_f)
            self._verify_keyframe()
        if self._k % o.detect_every_frames == 0 or len(self._ids) < o.detect_below_fraction * o.target_tracks:
            self._births(image, image_f)
        if keyframe:
            self._keyframes.append(self._k)
            self._last_kf = self._k
            self._kf_ids, self._kf_uv = self._ids.copy(), self._uv.copy()
            order = np.argsort(self._ids)
            self._kf_index[self._k] = (self._ids[order], self._uv[order])   # ids sorted: _member
            if len(self._keyframes) > o.reid_search_keyframes:
                self._kf_index.pop(self._keyframes[-o.reid_search_keyframes - 1], None)
        self._obs_ids.append(self._ids.copy())
        self._obs_uv.append(self._uv.copy())
        self._obs_anchored.append(self._anchored.copy())
        self._prev = image
        self.stats["wall_s"] += time.perf_counter() - started_wall

    def _checked(self, t_s: float, image: np.ndarray) -> np.ndarray:
        if image is None:
            raise InputError(f"frame {self._k + 1} has no image")
        image = np.asarray(image)
        if image.ndim == 3 and image.shape[2] == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if image.ndim != 2:
            raise InputError(f"frame {self._k + 1}: expected a grayscale image, got shape {image.shape}")
        if image.dtype != np.uint8:
            raise InputError(f"frame {self._k + 1}: expected uint8 pixels, got {image.dtype}")
        if (image.shape[1], image.shape[0]) != self.image_size:
            raise InputError(f"frame {self._k + 1} is {image.shape[1]}x{image.shape[0]}, expected "
                             f"{self.image_size[0]}x{self.image_size[1]} (all frames must have one size)")
        if isinstance(t_s, bool) or not isinstance(t_s, numbers.Real):
            raise InputError(f"frame {self._k + 1}: the time must be a number of seconds, not {t_s!r}")
        if not math.isfinite(float(t_s)):
            raise InputError(f"frame {self._k + 1}: time {t_s} is not finite")
        if self._t_s and not float(t_s) > self._t_s[-1]:
            raise InputError(f"frame {self._k + 1}: time {t_s} s does not increase (previous {self._t_s[-1]} s)")
        return np.ascontiguousarray(image)

    def _track(self, image: np.ndarray) -> None:
        """KLT from the previous frame with the forward-backward check, then the frame pair's RANSAC."""
        o = self.options
        prev = self._prev
        if o.klt_gain:    # a global gain from the frames' mean levels (auto-exposure is global)
            gain = cv2.mean(image)[0] / max(cv2.mean(prev)[0], 1.0)
            if abs(gain - 1.0) > 0.005:
                prev = cv2.convertScaleAbs(prev, alpha=gain)
        p0 = self._uv.astype(np.float32).reshape(-1, 1, 2)
        # Both passes start from the constant-velocity guess, so a small pyramid suffices for fast
        # turns; the backward pass does not start at p0 (it would return there trivially).
        guess = (self._uv + self._step).astype(np.float32).reshape(-1, 1, 2)
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev, image, p0, guess, flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                              **self._klt)
        back_guess = (p1.reshape(-1, 2) - self._step).astype(np.float32).reshape(-1, 1, 2)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(image, prev, p1, back_guess, flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                                **self._klt)
        p1, back = p1.reshape(-1, 2).astype(np.float64), back.reshape(-1, 2).astype(np.float64)
        ok = (st1.ravel() == 1) & (st2.ravel() == 1) & np.all(np.isfinite(p1), axis=1)
        ok &= np.linalg.norm(back - self._uv, axis=1) <= o.fb_max_px
        inside = self._inside(np.where(np.isfinite(p1), p1, -1e9))
        left = ok & ~inside
        lost = ~ok
        keep = ok & inside
        verified = np.zeros(len(keep), bool)
        idx = np.flatnonzero(keep)
        verified[idx] = geometric_inliers(self._uv[idx], p1[idx], o.ransac_px, o.homography_share,
                                          o.homography_px_factor, o.min_verify_points, o.ransac_method)
        self.stats["lost_klt"] += int(lost.sum())
        self.stats["left_view"] += int(left.sum())
        self.stats["rejected_frame_ransac"] += int((keep & ~verified).sum())
        self._to_pool(np.flatnonzero(lost | left), self._prev)
        moved = p1 - self._uv
        self._step = np.where(verified[:, None], moved, 0.0)
        self._uv = np.where(verified[:, None], p1, self._uv)
        self._warp[:, :, 2] = self._warp[:, :, 2] + moved.astype(np.float32)
        self._keep(verified, release=np.flatnonzero(keep & ~verified))

    def _is_keyframe(self) -> bool:
        o = self.options
        if self._last_kf < 0 or self._k - self._last_kf >= o.keyframe_max_gap_frames:
            return True
        common, a, b = np.intersect1d(self._kf_ids, self._ids, assume_unique=True, return_indices=True)
        if len(self._kf_ids) and len(common) < o.keyframe_min_survival * len(self._kf_ids):
            return True
        if len(common):
            if np.median(np.linalg.norm(self._uv[b] - self._kf_uv[a], axis=1)) >= o.keyframe_displacement_px:
                return True
        return False

    def _anchor(self, image_f: np.ndarray) -> None:
        """Align every live track with its first view; re-anchor those that no longer match."""
        o = self.options
        if not o.anchor or len(self._ids) == 0:
            return
        warp, zncc = self._anchors.align(image_f, self._views.get(self._slot), self._warp, o.anchor_iterations)
        shift = np.linalg.norm(warp[:, :, 2].astype(np.float64) - self._uv, axis=1)
        singular = np.linalg.svd(warp[:, :, :2].astype(np.float64), compute_uv=False)
        good = ((zncc >= o.anchor_min_zncc) & (shift <= o.anchor_max_shift_px) & np.all(np.isfinite(warp), axis=(1, 2))
                & (singular[:, 0] <= o.anchor_max_scale) & (singular[:, 1] >= 1.0 / o.anchor_max_scale)
                & self._inside(warp[:, :, 2].astype(np.float64)))
        self._uv[good] = warp[good, :, 2]
        self._warp[good] = warp[good]
        self._anchored[good] = True
        bad = np.flatnonzero(~good)
        self.stats["anchored"] += int(good.sum())
        self.stats["anchor_failed"] += len(bad)
        if len(bad) and o.on_anchor_failure == "end":     # the first view no longer matches
            self._keep(good, release=bad)
        elif len(bad):    # take a new first view here, at KLT's position
            new_warp = _translation_warps(self._uv[bad])
            self._views.put(self._slot[bad], self._anchors.make(image_f, new_warp))
            self._warp[bad] = new_warp
            self.stats["reanchored"] += len(bad)

    def _verify_keyframe(self) -> None:
        """RANSAC between the last keyframe and this one (a longer baseline than a frame pair)."""
        if self._last_kf < 0:
            return
        o = self.options
        common, a, b = np.intersect1d(self._kf_ids, self._ids, assume_unique=True, return_indices=True)
        if len(common) < o.min_verify_points:
            return
        inl = geometric_inliers(self._kf_uv[a], self._uv[b], o.keyframe_ransac_px, o.homography_share,
                                o.homography_px_factor, o.min_verify_points, o.ransac_method)
        if inl.all():
            return
        keep = np.ones(len(self._ids), bool)
        keep[b[~inl]] = False
        self.stats["rejected_keyframe_ransac"] += int((~inl).sum())
        self._keep(keep, release=b[~inl])

    # ---------------------------------------------------------------- new corners
    def _corners(self, image: np.ndarray) -> np.ndarray:
        """New corners where the grid's cells have fewer tracks than their share."""
        o = self.options
        w, h = self.image_size
        cells = o.grid_cols * o.grid_rows
        quota = int(math.ceil(o.target_tracks / cells))
        cell_of = self._cell_index(self._uv)
        counts = np.bincount(cell_of, minlength=cells) if len(cell_of) else np.zeros(cells, np.int64)
        deficit = np.maximum(quota - counts, 0)
        wanted = int(deficit.sum())
        if wanted == 0 or len(self._ids) >= o.target_tracks:
            return np.zeros((0, 2))
        level = 1 if w >= o.corner_half_resolution_from_px else 0
        f = 2 ** level
        search = cv2.pyrDown(image) if level else image
        sh, sw = search.shape
        mask = np.zeros((sh, sw), np.uint8)
        if len(self._uv):
            uv_int = np.round(self._uv / f).astype(np.int64)
            mask[np.clip(uv_int[:, 1], 0, sh - 1), np.clip(uv_int[:, 0], 0, sw - 1)] = 255
            mask = cv2.dilate(mask, self._disk if level == 0 else self._disk_half)
        mask = np.where(mask > 0, 0, 255).astype(np.uint8)
        m = int(math.ceil(self._margin / f))
        mask[:m], mask[sh - m:], mask[:, :m], mask[:, sw - m:] = 0, 0, 0, 0
        found = cv2.goodFeaturesToTrack(search, maxCorners=min(4 * wanted + 50, 4 * o.target_tracks),
                                        qualityLevel=o.corner_quality, minDistance=o.min_distance_px / f, mask=mask,
                                        blockSize=o.corner_block_size if level == 0 else 3)
        if found is None:
            return np.zeros((0, 2))
        found = found * f          # pyrDown's pixel i is centred on pixel 2i
        found = found.reshape(-1, 2).astype(np.float64)
        cell = self._cell_index(found)
        order = np.argsort(cell, kind="stable")      # goodFeaturesToTrack: strongest first
        sorted_cell = cell[order]
        start = np.searchsorted(sorted_cell, sorted_cell, side="left")
        rank = np.arange(len(order)) - start
        chosen = order[rank < deficit[sorted_cell]]
        return found[np.sort(chosen)]

    def _cell_index(self, uv: np.ndarray) -> np.ndarray:
        o = self.options
        w, h = self.image_size
        if len(uv) == 0:
            return np.zeros(0, np.int64)
        col = np.clip((uv[:, 0] * o.grid_cols / w).astype(np.int64), 0, o.grid_cols - 1)
        row = np.clip((uv[:, 1] * o.grid_rows / h).astype(np.int64), 0, o.grid_rows - 1)
        return row * o.grid_cols + col

    def _births(self, image: np.ndarray, image_f: np.ndarray) -> None:
        """New corners: lost tracks re-identified among them come back, the rest start new tracks
        (a first view is its own anchor)."""
        corners = self._corners(image)
        if len(corners) == 0:
            return
        # first views of all candidates at once; a flat patch cannot anchor (grey levels), an
        # edge-like or faint one slides: such corners go no further (no descriptor, no matching)
        warp = _translation_warps(corners)
        ref = self._anchors.make(image_f, warp)
        sigma = _position_sigma(ref["hessian_inv"], ref["texture"])
        keep = (ref["texture"] > 1.0) & (sigma <= self.options.max_position_sigma)
        corners, warp, ref, sigma = corners[keep], warp[keep], _take(ref, keep), sigma[keep]
        if len(corners) == 0:
            return
        desc, has_desc = self._describe(image, corners)
        revived = np.zeros(len(corners), bool)
        if self.options.reid and len(self._pool["ids"]):
            revived = self._reidentify(image_f, corners, desc, has_desc)
        new = np.flatnonzero(~revived)
        self._track_sigma.extend(sigma[new].tolist())
        ids = np.arange(self._next_id, self._next_id + len(new), dtype=np.int64)
        self._next_id += len(new)
        self._append(ids, corners[new], warp[new], self._views.add(_take(ref, new)), desc[new], has_desc[new],
                     np.ones(len(new), bool))
        self.stats["births"] += len(new)

    def _reidentify(self, image_f: np.ndarray, corners: np.ndarray, desc: np.ndarray, has_desc: np.ndarray
                    ) -> np.ndarray:
        """Match new corners to lost tracks (descriptor, geometry, appearance); the matched tracks
        come back under their old ids (appended to the live tracks). Returns which corners were used."""
        o = self.options
        pool = self._pool
        used = np.zeros(len(corners), bool)
        query = np.flatnonzero(has_desc)
        n_pool = len(pool["ids"])
        if len(query) == 0 or n_pool < 2:
            return used
        # per corner and lost track: the nearer of its two descriptors (at birth, where last seen)
        best = np.full((len(query), n_pool), 10 ** 6, np.int64)
        for which in (0, 1):
            have = np.flatnonzero(pool["has_desc"][:, which])
            if len(have):
                best[:, have] = np.minimum(best[:, have], _hamming(desc[query], pool["desc"][have, which]))
        part = np.argpartition(best, 1, axis=1)[:, :2]
        d_sorted = np.take_along_axis(best, part, axis=1)
        first = np.argmin(d_sorted, axis=1)
        j = part[np.arange(len(query)), first]
        d1 = d_sorted[np.arange(len(query)), first]
        d2 = d_sorted[np.arange(len(query)), 1 - first]
        mutual = np.argmin(best, axis=0)[j] == np.arange(len(query))
        match = (d1 <= o.reid_max_hamming) & (d1 < o.reid_ratio * d2) & mutual
        if not match.any():
            return used
        cand_corner, cand_pool = query[match], j[match]
        self.stats["reid_candidates"] += len(cand_corner)
        ok_geometry = self._reid_geometry(corners[cand_corner], pool["ids"][cand_pool])
        self.stats["reid_rejected_geometry"] += int((~ok_geometry).sum())
        cand_corner, cand_pool = cand_corner[ok_geometry], cand_pool[ok_geometry]
        if len(cand_corner) == 0:
            return used
        ref = self._views.get(pool["slot"][cand_pool])
        start = pool["warp"][cand_pool].copy()
        start[:, :, 2] = corners[cand_corner]
        warp, zncc = self._anchors.align(image_f, ref, start, max(o.anchor_iterations, 6))
        shift = np.linalg.norm(warp[:, :, 2].astype(np.float64) - corners[cand_corner], axis=1)
        good = ((zncc >= o.reid_min_zncc) & (shift <= o.reid_max_shift_px) & np.all(np.isfinite(warp), axis=(1, 2))
                & self._inside(warp[:, :, 2].astype(np.float64)))
        self.stats["reid_rejected_appearance"] += int((~good).sum())
        cand_corner, cand_pool, warp = cand_corner[good], cand_pool[good], warp[good]
        if len(cand_corner) == 0:
            return used
        for p in cand_pool.tolist():
            self._reid_events.append((self._k, int(pool["ids"][p]), int(pool["lost_frame"][p])))
        self._append(pool["ids"][cand_pool], warp[:, :, 2].astype(np.float64), warp, pool["slot"][cand_pool],
                     pool["desc"][cand_pool, 0], pool["has_desc"][cand_pool, 0], np.ones(len(cand_pool), bool))
        self.stats["reid_fired"] += len(cand_corner)
        keep = np.ones(len(pool["ids"]), bool)
        keep[cand_pool] = False
        self._take_pool(keep)
        used[cand_corner] = True
        return used

    def _reid_geometry(self, uv_now: np.ndarray, lost_ids: np.ndarray) -> np.ndarray:
        """Each candidate (lost track -> corner now) against the two-view model (RANSAC) fitted to the
        live tracks seen both in a recent keyframe that saw the lost track and now; rounds of the
        keyframe seeing most of the remaining candidates. Candidates that cannot be checked (fewer
        than min_verify_points such live tracks: the view left that keyframe's scene) fail."""
        o = self.options
        ok = np.zeros(len(lost_ids), bool)
        pending = np.ones(len(lost_ids), bool)
        frames = sorted(self._kf_index)
        for _ in range(2):
            if not pending.any() or not frames:
                break
            seen = [_member(self._kf_index[f][0], lost_ids) & pending for f in frames]
            counts = [int(s.sum()) for s in seen]
            for i in np.argsort(counts)[::-1]:     # the keyframe seeing most that has live support
                if counts[i] == 0 or _member(self._kf_index[frames[i]][0], self._ids).sum() >= o.min_verify_points:
                    break
                counts[i] = 0
            best = int(np.argmax(counts))
            if counts[best] == 0:
                break
            kf_ids, kf_uv = self._kf_index[frames[best]]
            sel = seen[best]
            pending &= ~sel
            # the model from live tracks only (known to be right): candidates on a repeated texture
            # move together and would otherwise carry their own wrong model
            _, a, b = np.intersect1d(kf_ids, self._ids, assume_unique=True, return_indices=True)
            model = fit_two_view_model(kf_uv[a], self._uv[b], o.reid_geometry_px, o.homography_share,
                                       o.min_verify_points, o.ransac_method)
            if model is None:
                continue
            cand_then = kf_uv[np.searchsorted(kf_ids, lost_ids[sel])]
            limit = o.reid_geometry_px * (o.homography_px_factor if model[0] == "H" else 1.0)
            good = two_view_distance(model, cand_then, uv_now[sel]) <= limit
            # an epipolar line is long: the candidate must also have moved like its neighbours did
            then, now = kf_uv[a], self._uv[b]
            k = min(8, len(then))
            near = np.argpartition(np.linalg.norm(cand_then[:, None] - then[None], axis=2), k - 1, axis=1)[:, :k]
            moved = now[near] - then[near]                                  # (C, k, 2)
            expected = np.median(moved, axis=1)
            spread = np.median(np.linalg.norm(moved - expected[:, None], axis=2), axis=1)
            off = np.linalg.norm(uv_now[sel] - cand_then - expected, axis=1)
            good &= off <= np.maximum(o.reid_neighbour_px, 3.0 * spread)
            ok[np.flatnonzero(sel)] = good
        return ok

    # ---------------------------------------------------------------- the result
    def result(self) -> TrackSet:
        """Every observation so far, with image velocities."""
        if self._k < 1:
            raise InputError(f"tracking needs at least 2 frames, got {self._k + 1}")
        counts = [len(i) for i in self._obs_ids]
        frame = np.repeat(np.arange(len(counts), dtype=np.int64), counts)
        track_id = np.concatenate(self._obs_ids) if counts else np.zeros(0, np.int64)
        uv = np.concatenate(self._obs_uv) if counts else np.zeros((0, 2))
        anchored = np.concatenate(self._obs_anchored) if counts else np.zeros(0, bool)
        position_sigma = np.asarray(self._track_sigma)[track_id] if counts else np.zeros(0)
        t_s = np.asarray(self._t_s)
        velocity = image_velocities(frame, track_id, uv, t_s)
        stats = dict(self.stats, frames=len(counts), tracks=int(len(np.unique(track_id))),
                     observations=int(len(frame)), keyframes=len(self._keyframes),
                     live_tracks_median=float(np.median(counts)) if counts else 0.0,
                     ms_per_frame_wall=1e3 * self.stats["wall_s"] / max(len(counts), 1),
                     first_view_mb=sum(v.nbytes for v in self._views.arrays.values()) / 2 ** 20,
                     observations_mb=(frame.nbytes + track_id.nbytes + uv.nbytes + 2 * uv.nbytes) / 2 ** 20,
                     options={f.name: getattr(self.options, f.name) for f in fields(self.options)})
        events = np.array(self._reid_events, np.int64).reshape(-1, 3)
        return TrackSet(self.image_size, t_s, np.asarray(self._keyframes, np.int64), frame, track_id, uv, velocity,
                        anchored, position_sigma=position_sigma, stats=stats, reid_events=events)


def _member(sorted_ids: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Which of ``query`` are in ``sorted_ids`` (sorted, unique)."""
    if len(sorted_ids) == 0:
        return np.zeros(len(query), bool)
    index = np.minimum(np.searchsorted(sorted_ids, query), len(sorted_ids) - 1)
    return sorted_ids[index] == query


def _hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances (len(a), len(b)) between rows of 32-byte descriptors."""
    a64 = np.ascontiguousarray(a, np.uint8).view(np.uint64)     # (len(a), 4)
    b64 = np.ascontiguousarray(b, np.uint8).view(np.uint64)
    distance = np.zeros((len(a), len(b)), np.int64)
    for word in range(a64.shape[1]):
        distance += np.bitwise_count(a64[:, word, None] ^ b64[None, :, word])
    return distance


def track_features(frames: Iterable[tuple[float, np.ndarray]], options: Optional[TrackOptions] = None, *,
                   frame_count: Optional[int] = None, progress: ProgressArg = None) -> TrackSet:
    """Tracks through ``frames`` ((time s, grayscale uint8 image), all of one size, times
    increasing; at least two). ``frame_count``: for the progress bar only."""
    checks.instance(options, "options", (TrackOptions, type(None)), "an rscalib.TrackOptions or None")
    if frame_count is not None:
        checks.whole(frame_count, "frame_count", 0, checks.MAX_FRAMES, " frames")
    checks.progress(progress)
    if isinstance(frames, (str, bytes)) or not hasattr(frames, "__iter__"):
        raise InputError(f"frames must be an iterable of (time_s, image), not a {type(frames).__name__} (for a "
                         "video or folder: rscalib.read_gray_frames(path).frames)")
    tracker: Optional[FeatureTracker] = None
    with Progress(progress, frame_count, "tracking") as bar:
        for k, item in enumerate(frames):
            try:
                t_s, image = item
            except (TypeError, ValueError):
                raise InputError(f"frames: frame {k}: expected (time_s, image), got {type(item).__name__}") from None
            if tracker is None:
                if image is None or np.ndim(image) < 2:
                    raise InputError(f"frames: frame {k}: expected a grayscale image")
                tracker = FeatureTracker((int(np.shape(image)[1]), int(np.shape(image)[0])), options)
            try:
                tracker.add_frame(t_s, image)
            except InputError as error:
                raise InputError(f"frames: {error}") from None
            bar.update(k + 1)
    if tracker is None:
        raise InputError("frames: tracking needs at least 2 frames, got none")
    try:
        return tracker.result()
    except InputError as error:
        raise InputError(f"frames: {error}") from None
