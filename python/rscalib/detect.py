"""Target detection in images and videos (OpenCV detectors), with quality checks and a cache.

`detect_image` finds one target in one image; `detect_video` streams a video or an image
folder through a pool of worker processes and returns the accepted detections as
`Observations` plus counts of the dropped frames by reason. Detectors:

- checkerboard: cv2.findChessboardCorners (FAST_CHECK), else cv2.findChessboardCornersSB, on a
  copy downscaled to `max_search_side_px`; then cv2.cornerSubPix at full resolution. Full
  boards only: without markers a partial checkerboard has no ids. A found grid must be
  surrounded by squares of alternating colour (drop reason "outer_ring"): when the board's edge
  row leaves the image OpenCV can return a grid shifted by one row onto the squares' outer edge.
- circlegrid: cv2.findCirclesGrid with a SimpleBlobDetector loosened for motion blur; each
  centre then re-measured as a grey-level centroid (robust to noise at the blob thresholds).
- aprilgrid: cv2.aruco DICT_APRILTAG_36h11 with markerBorderBits = 2 (Kalibr's grids), then
  cornerSubPix on the tag corners (Kalibr's X-junctions with the small corner squares).
- charuco: cv2.aruco.CharucoDetector, then cornerSubPix inside the marker-free margin.

Checks (a frame failing one is dropped and counted): `no_target`; `wrong_count` (fewer than
`min_points` points, or a duplicated tag); `blur` (edge width above `max_blur_px`);
`outlier_geometry` (a point off the homography of its neighbours by more than `max_residual`
grid steps). The video reader adds `bad_timestamp`, `unreadable` and `image_size`.

Full-grid detectors number the points from any corner. Of the re-numberings that fit the
target layout and are not mirror images, symmetric grids (square grids, symmetric circle grids,
checkerboards whose diagonal corner squares share a colour) take the one whose x axis points
most to the right in the image; checkerboards with cols + rows odd take the one whose first cell
is black, so their ids survive any rotation. Markers fix the ids of aprilgrids and ChArUco.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from collections import deque
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np

from .errors import InputError
from .observations import Observations
from .targets import APRILGRID_BORDER_BITS, APRILGRID_DICTIONARY, Target, load_target
from .video import FrameSource, open_source

# Bump when a change to the detectors or checks changes their output: it invalidates caches.
DETECTOR_VERSION = "1"

DROP_REASONS = ("no_target", "wrong_count", "blur", "outlier_geometry", "outer_ring", "bad_timestamp",
                "unreadable", "image_size", "detector_error")


@dataclass(frozen=True)
class DetectOptions:
    """Detector settings that change the result (they are part of the cache key)."""

    max_blur_px: float = 8.0            # edge width (contrast / steepest slope) of a sharp frame, px
    max_residual: float = 0.3           # local-homography residual, in grid steps
    min_points: int = 8                 # partial views (aprilgrid, charuco) with fewer are dropped
    max_search_side_px: int = 1280      # checkerboards: search on a downscaled copy above this
    subpix_window_px: Optional[int] = None  # cornerSubPix half-window; None: from the grid step
    check_outer_ring: bool = True       # checkerboards: the squares around the found grid must alternate
    refine_circles: bool = True         # circle grids: grey-level centroid instead of the blob detector's

    def fingerprint(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)


@dataclass
class FrameDetection:
    """Target points found in one image: ids into target.points_m and pixels (OpenCV convention).

    reason is None for an accepted detection, else one of DROP_REASONS (points may still be set,
    e.g. for a blurred frame). blur_px is the measured edge width (NaN if not measured)."""

    point_id: np.ndarray
    uv: np.ndarray
    blur_px: float = float("nan")
    reason: Optional[str] = None

    @property
    def accepted(self) -> bool:
        return self.reason is None


def _empty(reason: str) -> FrameDetection:
    return FrameDetection(np.zeros(0, np.int64), np.zeros((0, 2)), float("nan"), reason)


class _Rejected(Exception):
    """A detector found something but it fails a check; args[0] is the drop reason."""


class Detector:
    """Detects one target type; holds the OpenCV detector objects (create once, reuse)."""

    def __init__(self, target: Target, options: Optional[DetectOptions] = None):
        self.target = target
        self.options = options or DetectOptions()
        self._blob_detectors: dict = {}
        kind = target.target_type
        if kind == "aprilgrid":
            params = cv2.aruco.DetectorParameters()
            params.markerBorderBits = APRILGRID_BORDER_BITS
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE  # cornerSubPix below
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, APRILGRID_DICTIONARY))
            self._aruco = cv2.aruco.ArucoDetector(dictionary, params)
            self._tag_corners = target.tag_corner_ids()
        elif kind == "charuco":
            self._charuco = cv2.aruco.CharucoDetector(target.charuco_board())
        self._reindexings = _grid_reindexings(target.grid_shape) if kind in ("checkerboard", "circlegrid") else []

    def detect(self, image: np.ndarray) -> FrameDetection:
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        try:
            found = getattr(self, "_detect_" + self.target.target_type)(gray)
        except _Rejected as rejected:
            return _empty(rejected.args[0])
        except cv2.error:
            return _empty("detector_error")
        if found is None:
            return _empty("no_target")
        point_id, uv = found
        if len(point_id) < min(self.options.min_points, self.target.num_points):
            return FrameDetection(point_id, uv, float("nan"), "wrong_count")
        blur = edge_width_px(gray, self.target, point_id, uv)
        if blur > self.options.max_blur_px:
            return FrameDetection(point_id, uv, blur, "blur")
        residual = local_homography_residual(self.target, point_id, uv)
        residual = residual[np.isfinite(residual)]
        if residual.size and residual.max() > self.options.max_residual:
            return FrameDetection(point_id, uv, blur, "outlier_geometry")
        return FrameDetection(point_id, uv, blur, None)

    # -- detectors: return (point_id, uv) or None -------------------------------------------

    def _detect_checkerboard(self, gray: np.ndarray):
        rows, cols = self.target.grid_shape
        small, scale = _downscale(gray, self.options.max_search_side_px)
        # The classic detector with FAST_CHECK takes ~2 ms on a 640x480 board; the SB detector
        # (~40-60 ms) finds boards it misses (blur, noise, strong distortion). Both only seed
        # cornerSubPix below, which sets the final positions.
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
        ok, corners = cv2.findChessboardCorners(small, (cols, rows), flags=flags)
        if not ok:
            ok, corners = cv2.findChessboardCornersSB(small, (cols, rows), flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok or corners is None or len(corners) != rows * cols:
            return None
        uv = (corners.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5  # pixel centres
        # cornerSubPix with a window a quarter of the grid step: on OpenCV's left*.jpg it lowers
        # the calibration RMS from 0.26 px (SB alone) to 0.19 px; windows reaching half a square
        # (OpenCV's sample uses 11, i.e. 23 x 23 px) raise it to 0.41 px and bias f by +3 px.
        window = self.options.subpix_window_px or _grid_window(uv, rows, cols)
        uv = _corner_subpix(gray, uv, window)
        uv = self._canonical(gray, uv)
        if self.options.check_outer_ring and not _outer_ring_alternates(gray, uv, rows, cols):
            raise _Rejected("outer_ring")
        return np.arange(rows * cols), uv

    def _detect_circlegrid(self, gray: np.ndarray):
        rows, cols = self.target.grid_shape
        asymmetric = self.target.spec["asymmetricGrid"]
        flags = cv2.CALIB_CB_ASYMMETRIC_GRID if asymmetric else cv2.CALIB_CB_SYMMETRIC_GRID
        ok, centres = cv2.findCirclesGrid(gray, (cols, rows), flags=flags, blobDetector=self._blobs(gray.shape))
        if not ok or centres is None or len(centres) != rows * cols:
            return None
        uv = centres.reshape(-1, 2).astype(np.float64)
        if self.options.refine_circles:
            uv = _grey_centroids(gray, uv)
        uv = self._canonical(gray, uv)
        return np.arange(rows * cols), uv

    def _detect_aprilgrid(self, gray: np.ndarray):
        corners, ids, _ = self._aruco.detectMarkers(gray)
        if ids is None or len(ids) == 0:
            return None
        ids = ids.ravel()
        keep = ids < len(self._tag_corners)  # tags of other grids / stray tags
        corners, ids = [c for c, k in zip(corners, keep) if k], ids[keep]
        if len(ids) == 0:
            return None
        if len(np.unique(ids)) != len(ids):
            raise _Rejected("wrong_count")  # a tag seen twice
        # OpenCV's marker corners (TL, TR, BR, BL of the bitmap) are Kalibr's corners 1, 0, 3, 2.
        quads = np.stack([c.reshape(4, 2) for c in corners])[:, [1, 0, 3, 2]].astype(np.float64)
        point_id = self._tag_corners[ids].ravel()
        side_px = np.linalg.norm(np.roll(quads, -1, axis=1) - quads, axis=2).mean(axis=1)
        # Half-window: 1.5 bits of the 10-bit tag reaches the true corner from OpenCV's integer
        # polygon yet stays inside the 2-bit black border and the 3-bit white gap.
        windows = np.clip(np.round(1.5 * side_px / (6 + 2 * APRILGRID_BORDER_BITS)), 2, 25).astype(int)
        if self.options.subpix_window_px:
            windows[:] = self.options.subpix_window_px
        uv = np.empty((len(ids) * 4, 2))
        for window in np.unique(windows):
            tags = np.nonzero(windows == window)[0]
            rows = (tags[:, None] * 4 + np.arange(4)).ravel()
            uv[rows] = _corner_subpix(gray, quads[tags].reshape(-1, 2), int(window))
        order = np.argsort(point_id)
        return point_id[order], uv[order]

    def _detect_charuco(self, gray: np.ndarray):
        corners, ids, _, _ = self._charuco.detectBoard(gray)
        if ids is None or len(ids) == 0:
            return None
        ids = ids.ravel().astype(np.int64)
        order = np.argsort(ids)
        ids, uv = ids[order], corners.reshape(-1, 2).astype(np.float64)[order]
        # OpenCV's own refinement leaves ~0.5 px errors on synthetic boards; refine inside the
        # marker-free zone around each corner (the white margin between square edge and marker).
        window = self.options.subpix_window_px or self._charuco_window(ids, uv)
        return ids, _corner_subpix(gray, uv, window)

    def _charuco_window(self, ids: np.ndarray, uv: np.ndarray) -> int:
        where = np.full(self.target.num_points, -1)
        where[ids] = np.arange(len(ids))
        pairs = self.target.edge_pairs[(where[self.target.edge_pairs] >= 0).all(axis=1)]
        if len(pairs) == 0:
            return 2
        step = np.median(np.linalg.norm(uv[where[pairs[:, 0]]] - uv[where[pairs[:, 1]]], axis=1))
        spec = self.target.spec
        margin = 0.5 * (1.0 - spec["markerLength"] / spec["squareLength"]) * step
        return int(np.clip(round(0.8 * margin), 2, 12))

    # -- helpers ---------------------------------------------------------------------------

    def _blobs(self, shape: tuple[int, int]):
        """SimpleBlobDetector for dark circles, loosened for motion blur (elongated, soft blobs)."""
        key = shape[:2]
        if key not in self._blob_detectors:
            p = cv2.SimpleBlobDetector_Params()
            p.filterByColor, p.blobColor = True, 0
            p.minThreshold, p.maxThreshold, p.thresholdStep = 20, 230, 10
            p.minRepeatability = 2
            p.filterByArea = True
            p.minArea = 12.0
            p.maxArea = float(shape[0] * shape[1]) / max(4, self.target.num_points)
            p.filterByCircularity, p.minCircularity = True, 0.4
            p.filterByInertia, p.minInertiaRatio = True, 0.15
            p.filterByConvexity, p.minConvexity = True, 0.8
            p.minDistBetweenBlobs = 3.0
            self._blob_detectors[key] = cv2.SimpleBlobDetector_create(p)
        return self._blob_detectors[key]

    def _canonical(self, gray: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Reorder a full-grid detection to the target's ids (see module docstring).

        The detector's own numbering may start at any corner (and, for grids with a symmetry,
        follow a mirrored layout), so every re-indexing of the grid is tried: those that fit
        the target layout (homography residual near the best) and are not mirror images are
        equally valid, and the orientation score picks one."""
        xy = self.target.points_m[:, :2]
        hull = cv2.convexHull(uv.astype(np.float32))
        step_px = np.sqrt(max(cv2.contourArea(hull), 1.0) / len(uv))
        fits = []
        for perm in self._reindexings:
            candidate = uv[perm]
            h, _ = cv2.findHomography(xy, candidate, 0)
            if h is None:
                continue
            predicted = cv2.perspectiveTransform(xy.reshape(-1, 1, 2), h).reshape(-1, 2)
            fits.append((float(np.sqrt(np.mean(np.sum((predicted - candidate) ** 2, axis=1)))), candidate))
        if not fits:
            raise _Rejected("outlier_geometry")
        best_rms = min(f[0] for f in fits)
        best, best_score = None, -np.inf
        for rms, candidate in fits:
            if rms > 1.5 * best_rms + 0.05 * step_px:
                continue  # a different layout, not a symmetry of this one
            a = _affine(xy, candidate)
            if np.linalg.det(a) <= 0:  # the printed side faces the camera: no mirror images
                continue
            score = self._orientation_score(gray, candidate, a)
            if score > best_score:
                best, best_score = candidate, score
        if best is None:
            raise _Rejected("outlier_geometry")
        return best

    def _orientation_score(self, gray: np.ndarray, uv: np.ndarray, a: np.ndarray) -> float:
        x_axis = a[:, 0] / np.linalg.norm(a[:, 0])
        if self.target.target_type == "checkerboard":
            rows, cols = self.target.grid_shape
            if (rows + cols) % 2 == 1 and cols >= 3:
                # first cell black: darker than the next cell along x
                first = _mean_intensity(gray, uv[[0, 1, cols + 1, cols]])
                second = _mean_intensity(gray, uv[[1, 2, cols + 2, cols + 1]])
                return 10.0 + (second - first) + x_axis[0] * 1e-3
        return float(x_axis[0])


def detect_image(image: np.ndarray, target: Target, options: Optional[DetectOptions] = None) -> FrameDetection:
    """Detect the target in one image (gray or BGR)."""
    return Detector(target, options).detect(image)


# -- geometry and quality measures --------------------------------------------------------------


def _downscale(gray: np.ndarray, max_side: int) -> tuple[np.ndarray, float]:
    side = max(gray.shape[:2])
    if not max_side or side <= max_side:
        return gray, 1.0
    scale = max_side / side
    return cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), scale


def _corner_subpix(gray: np.ndarray, uv: np.ndarray, half_window: int) -> np.ndarray:
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.01)
    pts = uv.astype(np.float32).reshape(-1, 1, 2)
    return cv2.cornerSubPix(gray, pts, (half_window, half_window), (-1, -1), criteria).reshape(-1, 2).astype(np.float64)


def _grid_window(uv: np.ndarray, rows: int, cols: int) -> int:
    """cornerSubPix half-window: a quarter of the smallest grid step (the window stays well
    inside the four squares around the corner)."""
    grid = uv.reshape(rows, cols, 2)
    steps = np.concatenate([np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel(),
                            np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel()])
    return int(np.clip(round(steps.min() / 4.0), 2, 12))


def _affine(xy: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """2x2 linear part of the least-squares affine map target xy -> image uv."""
    design = np.column_stack([xy - xy.mean(0), np.ones(len(xy))])
    coeffs, *_ = np.linalg.lstsq(design, uv - uv.mean(0), rcond=None)
    return coeffs[:2].T


def _mean_intensity(gray: np.ndarray, quad: np.ndarray) -> float:
    """Mean intensity in the middle half of a cell given by its 4 corners."""
    centre = quad.mean(0)
    inner = centre + 0.5 * (quad - centre)
    mask = np.zeros(gray.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, np.round(inner).astype(np.int32), 1)
    if not mask.any():
        x, y = np.clip(np.round(centre).astype(int), 0, [gray.shape[1] - 1, gray.shape[0] - 1])
        return float(gray[y, x])
    return float(cv2.mean(gray, mask)[0])


def _grey_centroids(gray: np.ndarray, uv: np.ndarray, iterations: int = 3) -> np.ndarray:
    """Dark circles' centres as grey-level centroids in a disc of 0.45 x the distance to the nearest
    neighbour: weight 1 below dark + Δ/4, 0 above bright − Δ/4, linear between (Δ = local contrast).

    The blob detector's centres average binarised contours over thresholds; a threshold within a
    few noise sigmas of the circles' grey level splits them into noise fragments, which biased
    centres by 0.3 px (rendered 1080p videos; docs/experiments.md, Table 3). A centroid of grey
    levels averages the noise instead. A circle that does not fit its disc keeps its blob centre."""
    out = uv.copy()
    dist = np.linalg.norm(uv[:, None, :] - uv[None, :, :], axis=2)
    np.fill_diagonal(dist, np.inf)
    radius = 0.45 * dist.min(axis=1)
    height, width = gray.shape[:2]
    for i, (u0, v0) in enumerate(uv):
        r = radius[i]
        centre = np.array([u0, v0])
        ok = np.isfinite(r) and r >= 3.0
        for _ in range(iterations if ok else 0):
            x_lo, x_hi = int(math.floor(centre[0] - r)), int(math.ceil(centre[0] + r))
            y_lo, y_hi = int(math.floor(centre[1] - r)), int(math.ceil(centre[1] + r))
            if x_lo < 0 or y_lo < 0 or x_hi >= width or y_hi >= height:
                ok = False
                break
            ys, xs = np.mgrid[y_lo:y_hi + 1, x_lo:x_hi + 1]
            rho = np.hypot(xs - centre[0], ys - centre[1])
            disc = rho <= r
            values = gray[y_lo:y_hi + 1, x_lo:x_hi + 1][disc].astype(np.float64)
            dark, bright = np.percentile(values, [2.0, 98.0])
            contrast = bright - dark
            if contrast < 20.0:
                ok = False
                break
            w = np.clip((bright - 0.25 * contrast - values) / (0.5 * contrast), 0.0, 1.0)
            total = w.sum()
            # the circle must lie inside the disc: little weight in its outer fifth
            if total <= 0 or w[rho[disc] > 0.8 * r].sum() > 0.02 * total:
                ok = False
                break
            centre = np.array([(w * xs[disc]).sum() / total, (w * ys[disc]).sum() / total])
        if ok and np.hypot(*(centre - uv[i])) < 0.25 * r:
            out[i] = centre
    return out


def _outer_ring_alternates(gray: np.ndarray, uv: np.ndarray, rows: int, cols: int,
                           max_wrong_fraction: float = 0.25) -> bool:
    """Whether the cells just outside a found rows x cols inner-corner grid are squares of the
    opposite colour to their inner neighbours, as on a real board (which has a ring of squares
    around its inner corners). When the board's edge row leaves the image OpenCV can return a
    grid shifted by one row whose last "corners" lie on the squares' outer edge; beyond those is
    plain paper, so about half of that side's cells have the wrong colour. Sides whose ring cells
    are not inside the image are not tested."""
    grid = uv.reshape(rows, cols, 2)
    height, width = gray.shape[:2]
    inner = np.array([_mean_intensity(gray, np.array([grid[r, c], grid[r, c + 1], grid[r + 1, c + 1], grid[r + 1, c]]))
                      for r in range(rows - 1) for c in range(cols - 1)])
    if inner.size < 4:
        return True
    ordered = np.sort(inner)
    dark, bright = ordered[:len(ordered) // 2].mean(), ordered[-(len(ordered) // 2):].mean()
    if bright - dark < 20.0:
        return True  # too little contrast to judge
    mid = 0.5 * (dark + bright)
    # (edge corners, the next row/column inwards) for the four sides
    sides = [(grid[0], grid[1]), (grid[-1], grid[-2]), (grid[:, 0], grid[:, 1]), (grid[:, -1], grid[:, -2])]
    for edge, inward in sides:
        outside = 2.0 * edge - inward
        tested = wrong = 0
        for k in range(len(edge) - 1):
            ring = np.array([outside[k], outside[k + 1], edge[k + 1], edge[k]])
            if ring[:, 0].min() < 2 or ring[:, 1].min() < 2 or ring[:, 0].max() > width - 3 or ring[:, 1].max() > height - 3:
                continue
            # Sample the ring cell near the grid only: extrapolation overshoots under perspective,
            # and outer squares may be printed right up to the sheet's edge.
            a = edge[k] + 0.25 * (edge[k + 1] - edge[k])
            b = edge[k] + 0.75 * (edge[k + 1] - edge[k])
            oa = outside[k] + 0.25 * (outside[k + 1] - outside[k])
            ob = outside[k] + 0.75 * (outside[k + 1] - outside[k])
            ring = np.array([a + 0.1 * (oa - a), b + 0.1 * (ob - b), b + 0.6 * (ob - b), a + 0.6 * (oa - a)])
            neighbour = np.array([edge[k], edge[k + 1], inward[k + 1], inward[k]])
            a, b = _mean_intensity(gray, ring), _mean_intensity(gray, neighbour)
            tested += 1
            if (a - mid) * (b - mid) >= 0 or abs(a - b) < 0.25 * (bright - dark):
                wrong += 1
        if tested >= 3 and wrong > max_wrong_fraction * tested:
            return False
    return True


def _grid_reindexings(grid_shape: tuple[int, int]) -> list[np.ndarray]:
    """The ways to number a rows x cols grid row-major from a corner (the dihedral group of
    the index array: 4 re-indexings, 8 for square grids), as index permutations."""
    rows, cols = grid_shape
    ids = np.arange(rows * cols).reshape(rows, cols)
    result = [ids, ids[::-1], ids[:, ::-1], ids[::-1, ::-1]]
    if rows == cols:
        result += [ids.T, ids.T[::-1], ids.T[:, ::-1], ids.T[::-1, ::-1]]
    return [p.ravel() for p in result]


def edge_width_px(gray: np.ndarray, target: Target, point_id: np.ndarray, uv: np.ndarray) -> float:
    """Blur of a detection: the 75th percentile over the target's black/white edges of the edge
    width (contrast / steepest slope of an intensity profile across the edge), px. About 1 px for
    a sharp edge, about L px for a motion blur of L px across the edge. NaN if unmeasurable."""
    where = np.full(target.num_points, -1)
    where[point_id] = np.arange(len(point_id))
    pairs = target.edge_pairs
    pairs = pairs[(where[pairs] >= 0).all(axis=1)]
    if len(pairs) == 0:
        return float("nan")
    a, b = uv[where[pairs[:, 0]]], uv[where[pairs[:, 1]]]
    length = np.linalg.norm(b - a, axis=1)
    ok = length > 1e-6
    a, b, length = a[ok], b[ok], length[ok]
    t = (b - a) / length[:, None]
    kind = target.target_type
    if kind == "circlegrid":
        # from each centre towards its neighbour, across the circle's rim (both directions)
        start = np.concatenate([a, b])
        direction = np.concatenate([t, -t])
        half = np.concatenate([length, length]) * 0.25
        centre = start + direction * half[:, None]
    else:
        # across the edge at its midpoint, staying inside the two cells it separates
        if kind == "aprilgrid":
            fraction = 0.15            # 2-bit black border inside, 3-bit gap outside a 10-bit tag
        elif kind == "charuco":
            s = target.spec
            fraction = min(0.4, 0.4 * (1 - s["markerLength"] / s["squareLength"]))
        else:
            fraction = 0.4
        centre = 0.5 * (a + b)
        direction = np.column_stack([-t[:, 1], t[:, 0]])
        half = length * fraction
    half = np.minimum(half, 16.0)
    keep = half >= 1.5
    if not keep.any():
        return float("nan")
    centre, direction, half = centre[keep], direction[keep], half[keep]
    samples = 48
    s = np.linspace(-1.0, 1.0, samples)[None, :] * half[:, None]
    map_x = (centre[:, 0:1] + s * direction[:, 0:1]).astype(np.float32)
    map_y = (centre[:, 1:2] + s * direction[:, 1:2]).astype(np.float32)
    profiles = cv2.remap(gray, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
    profiles = (profiles[:, :-2] + profiles[:, 1:-1] + profiles[:, 2:]) / 3.0  # light smoothing
    step = 2.0 * half / (samples - 1)
    ends = max(2, samples // 12)
    contrast = np.abs(profiles[:, -ends:].mean(1) - profiles[:, :ends].mean(1))
    slope = np.abs(np.diff(profiles, axis=1)).max(1) / step
    valid = (contrast > 20.0) & (slope > 0)
    if not valid.any():
        return float("nan")
    # the 3-tap smoothing widens a step by about one sample
    width = contrast[valid] / slope[valid] - step[valid]
    return float(np.percentile(np.maximum(width, 0.0), 75))


def local_homography_residual(target: Target, point_id: np.ndarray, uv: np.ndarray, neighbours: int = 8) -> np.ndarray:
    """For each detected point, the distance from its pixel to the prediction of a homography
    fitted to its nearest detected neighbours on the target, in units of the local grid step
    (the pixel distance to its nearest target neighbour). NaN where the neighbours are too few
    or collinear. Local fits tolerate lens distortion; a wrong id or a stray point stands out."""
    n = len(point_id)
    result = np.full(n, np.nan)
    if n < 6:
        return result
    xy = target.points_m[point_id, :2]
    k = min(neighbours, n - 1)
    dist = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    nearest = np.argsort(dist, axis=1)[:, :k]                      # (n, k)
    nx, nu = xy[nearest], uv[nearest]                               # (n, k, 2)
    # Hartley normalisation per neighbourhood
    mx, mu = nx.mean(1, keepdims=True), nu.mean(1, keepdims=True)
    sx = np.sqrt(((nx - mx) ** 2).sum(2).mean(1))[:, None, None] + 1e-300
    su = np.sqrt(((nu - mu) ** 2).sum(2).mean(1))[:, None, None] + 1e-300
    x, u = (nx - mx) / sx, (nu - mu) / su
    ones, zeros = np.ones(x.shape[:2] + (1,)), np.zeros(x.shape[:2] + (3,))
    xh = np.concatenate([x, ones], axis=2)                           # (n, k, 3)
    row1 = np.concatenate([xh, zeros, -u[..., :1] * xh], axis=2)
    row2 = np.concatenate([zeros, xh, -u[..., 1:] * xh], axis=2)
    design = np.concatenate([row1, row2], axis=1)                     # (n, 2k, 9)
    _, sv, vt = np.linalg.svd(design)
    h = vt[:, -1, :].reshape(n, 3, 3)
    spread = np.linalg.svd(x, compute_uv=False)                       # (n, 2)
    well_posed = spread[:, 1] > 0.25 * spread[:, 0]
    p = np.concatenate([(xy[:, None, :] - mx) / sx, np.ones((n, 1, 1))], axis=2)[:, 0, :]
    q = np.einsum("nij,nj->ni", h, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        predicted = q[:, :2] / q[:, 2:3] * su[:, 0] + mu[:, 0]
        step_px = np.linalg.norm(uv[nearest[:, 0]] - uv, axis=1)
        residual = np.linalg.norm(predicted - uv, axis=1) / step_px
    result[well_posed] = residual[well_posed]
    return result


# -- videos -----------------------------------------------------------------------------------


@dataclass
class DetectionResult:
    """Accepted detections of a video or image sequence.

    observations: frames with an accepted detection only (their times from the source),
                  target_points = target.points_m.
    frame_numbers: (F,) index in the source of each observation frame.
    frame_labels: (F,) file name (stills) or "frame N" (videos) of each observation frame.
    blur_px: (F,) edge width of each observation frame (see edge_width_px).
    frames_total: frames read; frames_total = frames_detected + sum(dropped.values()).
    dropped: reason -> number of frames (DROP_REASONS).
    timestamps: where the times come from: "container", "frame rate", "timestamps file", "frame index".
    """

    observations: Observations
    frames_total: int
    frames_detected: int
    dropped: dict
    from_cache: bool
    image_size: tuple[int, int]
    frame_numbers: np.ndarray
    frame_labels: list
    blur_px: np.ndarray
    timestamps: str
    warnings: list = field(default_factory=list)
    detect_time_s: float = 0.0


def default_cache_dir() -> Path:
    """$RSCALIB_CACHE_DIR, else $XDG_CACHE_HOME/rscalib/detections, else ~/.cache/rscalib/detections."""
    if os.environ.get("RSCALIB_CACHE_DIR"):
        return Path(os.environ["RSCALIB_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rscalib" / "detections"


def usable_cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def detect_video(source: Union[str, Path, Sequence], target: Union[Target, str, Path], *,
                 workers: Optional[int] = None, cache: bool = True, cache_dir: Union[str, Path, None] = None,
                 progress: bool = True, options: Optional[DetectOptions] = None) -> DetectionResult:
    """Detect `target` in every frame of a video, an image folder (file-name order, optional
    timestamps.txt) or a list of image files.

    workers: processes (default: the usable cores; in this process for under 64 frames). The
    video is decoded here and streamed to the workers with a bounded queue, so memory does not
    grow with its length. Workers are spawned (not forked), so a calling script needs the usual
    `if __name__ == "__main__":` guard.
    cache: reuse / store the result under cache_dir (default_cache_dir()), keyed by the hash of
    the source's bytes, the target definition, the options and DETECTOR_VERSION."""
    if not isinstance(target, Target):
        target = load_target(target)
    options = options or DetectOptions()
    frames = open_source(source)
    started = time.perf_counter()
    cache_file = None
    if cache:
        key = hashlib.sha256("\n".join([frames.content_hash(), target.fingerprint(), options.fingerprint(),
                                        DETECTOR_VERSION]).encode()).hexdigest()[:32]
        cache_file = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        cache_file = cache_file / f"{key}.npz"
        cached = _load_cache(cache_file, target)
        if cached is not None:
            cached.detect_time_s = time.perf_counter() - started
            return cached
    try:
        result = _detect_frames(frames, target, options, workers, progress)
    except BrokenProcessPool:
        # e.g. a worker killed for memory, or a __main__ that spawn cannot re-import
        result = _detect_frames(open_source(source), target, options, 1, progress)
        result.warnings.append("detection workers failed; detected in one process instead")
    result.detect_time_s = time.perf_counter() - started
    if cache_file is not None:
        _save_cache(cache_file, result)
    return result


_WORKER_DETECTOR: Optional[Detector] = None


def _worker_init(target: Target, options: DetectOptions) -> None:
    global _WORKER_DETECTOR
    cv2.setNumThreads(1)  # one process per core already
    _WORKER_DETECTOR = Detector(target, options)


def _worker_detect(image: np.ndarray) -> FrameDetection:
    return _WORKER_DETECTOR.detect(image)


class _Progress:
    """A rich progress bar on stderr, or nothing."""

    def __init__(self, enabled: bool, total: Optional[int], label: str):
        self._bar = None
        if enabled:
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)
            self._bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                                 TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TimeRemainingColumn(),
                                 console=Console(stderr=True), transient=False)
            self._task = self._bar.add_task(label, total=total, rate="")
            self._start = time.perf_counter()

    def __enter__(self):
        if self._bar:
            self._bar.__enter__()
        return self

    def advance(self, done: int) -> None:
        if self._bar:
            rate = done / max(1e-9, time.perf_counter() - self._start)
            self._bar.update(self._task, completed=done, rate=f"{rate:.1f} frames/s")

    def finish(self, done: int) -> None:
        if self._bar:
            self._bar.update(self._task, total=done, completed=done)

    def __exit__(self, *exc):
        if self._bar:
            self._bar.__exit__(*exc)


def _detect_frames(frames: FrameSource, target: Target, options: DetectOptions, workers: Optional[int],
                   progress: bool) -> DetectionResult:
    estimate = frames.frame_count_estimate
    if workers is None:
        # starting a worker costs ~0.5 s, a frame 5-60 ms: short inputs are faster in-process
        workers = 1 if estimate is not None and estimate < 64 else usable_cores()
    workers = max(1, int(workers))
    main_file = getattr(sys.modules.get("__main__"), "__file__", None)
    if main_file and not os.path.exists(main_file):
        workers = 1  # a script read from stdin: spawned workers could not re-import it
    dropped = {reason: 0 for reason in DROP_REASONS}
    times, numbers, labels, blur, ids, uvs = [], [], [], [], [], []
    state = {"total": 0, "size": None}

    def record(info: tuple, detection: FrameDetection) -> None:
        number, time_s, label = info
        if detection.reason is not None:
            dropped[detection.reason] += 1
            return
        times.append(time_s)
        numbers.append(number)
        labels.append(label)
        blur.append(detection.blur_px)
        ids.append(detection.point_id)
        uvs.append(detection.uv)

    pool = None
    detector = None
    if workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        # spawn: forking a process that already runs OpenCV's thread pool is not safe
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_worker_init, initargs=(target, options))
    else:
        detector = Detector(target, options)
    pending: deque = deque()
    try:
        with _Progress(progress, estimate, f"detecting {target.target_type}") as bar:
            for frame in frames.frames(gray=True):
                state["total"] += 1
                if frame.image is None:
                    dropped[frame.problem or "unreadable"] += 1
                    continue
                size = (frame.image.shape[1], frame.image.shape[0])
                if state["size"] is None:
                    state["size"] = size
                elif size != state["size"]:
                    dropped["image_size"] += 1
                    continue
                info = (frame.index, frame.time_s, frame.label)
                if pool is None:
                    record(info, detector.detect(frame.image))
                else:
                    pending.append((info, pool.submit(_worker_detect, frame.image)))
                    while len(pending) > 2 * workers:  # bounded: memory independent of length
                        record(*_result(pending.popleft()))
                bar.advance(state["total"] - len(pending))
            while pending:
                record(*_result(pending.popleft()))
            bar.finish(state["total"])
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    image_size = state["size"] or (0, 0)
    counts = [len(i) for i in ids]
    observations = Observations(
        frame_times_s=np.asarray(times, dtype=np.float64),
        frame_index=np.repeat(np.arange(len(ids)), counts),
        point_id=np.concatenate(ids) if ids else np.zeros(0, np.int64),
        uv=np.concatenate(uvs) if uvs else np.zeros((0, 2)),
        target_points=target.points_m,
        image_size=image_size,
    )
    return DetectionResult(observations, state["total"], len(ids), {k: v for k, v in dropped.items() if v},
                           False, image_size, np.asarray(numbers, dtype=np.int64), labels,
                           np.asarray(blur, dtype=np.float64), frames.timestamps_source, list(frames.warnings))


def _result(item):
    info, future = item
    return info, future.result()


def _save_cache(path: Path, result: DetectionResult) -> None:
    meta = {"frames_total": result.frames_total, "dropped": result.dropped, "image_size": list(result.image_size),
            "timestamps": result.timestamps, "warnings": result.warnings, "frame_labels": result.frame_labels,
            "detector_version": DETECTOR_VERSION}
    obs = result.observations
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, frame_times_s=obs.frame_times_s, frame_index=obs.frame_index, point_id=obs.point_id,
                 uv=obs.uv, frame_numbers=result.frame_numbers, blur_px=result.blur_px,
                 meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
        os.replace(tmp, path)  # atomic: a concurrent reader never sees half a file
    except OSError:
        pass  # a cache that cannot be written only costs time


def _load_cache(path: Path, target: Target) -> Optional[DetectionResult]:
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            meta = json.loads(bytes(data["meta"]).decode())
            obs = Observations(data["frame_times_s"], data["frame_index"], data["point_id"], data["uv"],
                               target.points_m, tuple(meta["image_size"]))
            return DetectionResult(obs, int(meta["frames_total"]), obs.num_frames, dict(meta["dropped"]), True,
                                   tuple(meta["image_size"]), data["frame_numbers"].astype(np.int64),
                                   list(meta["frame_labels"]), data["blur_px"].astype(np.float64),
                                   meta["timestamps"], list(meta["warnings"]))
    except (OSError, ValueError, KeyError, InputError):
        return None  # unreadable or stale: detect again
