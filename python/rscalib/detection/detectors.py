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

import math
from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np

from ..io.targets import APRILGRID_BORDER_BITS, APRILGRID_DICTIONARY, Target
from .options import DetectOptions
from .quality import edge_width_px, local_homography_residual

# Bump when a change to the detectors or checks changes their output: it invalidates caches.
DETECTOR_VERSION = "5"  # 2: runs by frame index, tracks across frames without a full board (issue 17);
# 3: a track whose refinement put a corner back on its start goes to full detection;
# 4: runs of 40 frames, the tracker's wide pass at half resolution, its prediction from the outer corners;
# 5: a video's grey frames from the decoder's luma plane (rscalib.io.video.luma_plan)

DROP_REASONS = ("no_target", "wrong_count", "blur", "outlier_geometry", "outer_ring", "bad_timestamp",
                "unreadable", "image_size", "detector_error")


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
        self._reindexings = grid_reindexings(target.grid_shape) if kind in ("checkerboard", "circlegrid") else []
        # Re-indexings that are symmetries of the layout (xy[perm] an affine image of xy: flips of a
        # regular grid, not of an asymmetric circle grid) fit the image exactly as well as the first
        # (identity) one: the homography's image error does not depend on an affine change of the
        # target's coordinates, so _canonical fits those once.
        xy = target.points_m[:, :2]
        self._layout_symmetry = [_is_affine_image(xy, xy[perm]) for perm in self._reindexings]

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
        return self._checked(gray, *found)

    def refine_checkerboard(self, image: np.ndarray, uv_guess: np.ndarray, numbered: bool = False) -> FrameDetection:
        """Checkerboards: the full grid of corners near uv_guess ((rows*cols, 2), row-major in any
        of the grid's numberings, e.g. a tracker's prediction) refined and checked exactly as a
        full detection's coarse corners are (cornerSubPix, ids, outer ring, blur, geometry).
        numbered: uv_guess is already in the target's numbering (a track of canonical detections:
        each corner stays near its prediction), so the ids are kept instead of derived again."""
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        try:
            point_id, uv = self._refine_checkerboard(gray, np.asarray(uv_guess, dtype=np.float64), numbered)
        except _Rejected as rejected:
            return _empty(rejected.args[0])
        except cv2.error:
            return _empty("detector_error")
        return self._checked(gray, point_id, uv)

    def _checked(self, gray: np.ndarray, point_id: np.ndarray, uv: np.ndarray) -> FrameDetection:
        """The checks every detection passes: point count, blur, local geometry."""
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
        return self._refine_checkerboard(gray, uv)

    def _refine_checkerboard(self, gray: np.ndarray, uv: np.ndarray, numbered: bool = False):
        rows, cols = self.target.grid_shape
        # cornerSubPix with a window a quarter of the grid step: on OpenCV's left*.jpg it lowers
        # the calibration RMS from 0.26 px (SB alone) to 0.19 px; windows reaching half a square
        # (OpenCV's sample uses 11, i.e. 23 x 23 px) raise it to 0.41 px and bias f by +3 px.
        window = self.options.subpix_window_px or _grid_window(uv, rows, cols)
        uv = _corner_subpix(gray, uv, window)
        if not numbered:
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
        identity_rms = None
        for perm, symmetry in zip(self._reindexings, self._layout_symmetry):
            candidate = uv[perm]
            if symmetry and identity_rms is not None:
                fits.append((identity_rms, candidate))
                continue
            h, _ = cv2.findHomography(xy, candidate, 0)
            if h is None:
                continue
            predicted = cv2.perspectiveTransform(xy.reshape(-1, 1, 2), h).reshape(-1, 2)
            fits.append((float(np.sqrt(np.mean(np.sum((predicted - candidate) ** 2, axis=1)))), candidate))
            if symmetry and np.array_equal(perm, self._reindexings[0]):
                identity_rms = fits[-1][0]
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
    along_cols, along_rows = grid[:, 1:] - grid[:, :-1], grid[1:] - grid[:-1]
    # the smallest squared step, then its root: np.linalg.norm's numbers (x*x + y*y, rounded
    # alike), without its per-call overhead (this runs on every detected and tracked frame)
    smallest_sq = min(float((along_cols[..., 0] * along_cols[..., 0] + along_cols[..., 1] * along_cols[..., 1]).min(
                          initial=np.inf)),
                      float((along_rows[..., 0] * along_rows[..., 0] + along_rows[..., 1] * along_rows[..., 1]).min(
                          initial=np.inf)))
    return int(min(max(round(math.sqrt(smallest_sq) / 4.0), 2), 12))


def _affine(xy: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """2x2 linear part of the least-squares affine map target xy -> image uv."""
    design = np.column_stack([xy - xy.mean(0), np.ones(len(xy))])
    coeffs, *_ = np.linalg.lstsq(design, uv - uv.mean(0), rcond=None)
    return coeffs[:2].T


def _mean_intensity(gray: np.ndarray, quad: np.ndarray) -> float:
    """Mean intensity in the middle half of a cell given by its 4 corners."""
    centre = quad.mean(0)
    polygon = np.round(centre + 0.5 * (quad - centre)).astype(np.int32)
    # the mask covers the polygon's bounding box only (a full-image mask costs ~1 ms at 1080p);
    # plain min / max: np.clip's overhead dominated on these 4-point arrays
    height, width = gray.shape[:2]
    (x0, y0), (x1, y1) = polygon.min(0).tolist(), polygon.max(0).tolist()
    x0, y0 = min(max(x0, 0), width - 1), min(max(y0, 0), height - 1)
    x1, y1 = min(max(x1 + 1, 1), width), min(max(y1 + 1, 1), height)
    if x1 > x0 and y1 > y0:
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(mask, polygon - np.array([x0, y0], np.int32), 1)
        if mask.any():
            return float(cv2.mean(gray[y0:y1, x0:x1], mask)[0])
    x, y = np.round(centre).astype(int).tolist()
    return float(gray[min(max(y, 0), height - 1), min(max(x, 0), width - 1)])


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


def _cell_means(gray: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """_mean_intensity of each of the (n, 4, 2) quads, the same numbers: the polygons and boxes are
    computed for all at once (per call, NumPy's overhead on 4-point arrays was most of the cost)."""
    if len(quads) == 0:
        return np.zeros(0)
    centres = quads.mean(axis=1)
    polygons = np.round(centres[:, None, :] + 0.5 * (quads - centres[:, None, :])).astype(np.int32)
    height, width = gray.shape[:2]
    low = polygons.min(axis=1)
    high = polygons.max(axis=1)
    x0s, y0s = np.clip(low[:, 0], 0, width - 1).tolist(), np.clip(low[:, 1], 0, height - 1).tolist()
    x1s, y1s = np.clip(high[:, 0] + 1, 1, width).tolist(), np.clip(high[:, 1] + 1, 1, height).tolist()
    means = np.empty(len(quads))
    for i, (x0, y0, x1, y1) in enumerate(zip(x0s, y0s, x1s, y1s)):
        if x1 > x0 and y1 > y0:
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            cv2.fillConvexPoly(mask, polygons[i] - np.array([x0, y0], np.int32), 1)
            if cv2.countNonZero(mask):
                means[i] = cv2.mean(gray[y0:y1, x0:x1], mask)[0]
                continue
        x, y = np.round(centres[i]).astype(int).tolist()
        means[i] = float(gray[min(max(y, 0), height - 1), min(max(x, 0), width - 1)])
    return means


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
    inner_quads = [np.array([grid[r, c], grid[r, c + 1], grid[r + 1, c + 1], grid[r + 1, c]])
                   for r in range(rows - 1) for c in range(cols - 1)]
    # (edge corners, the next row/column inwards) for the four sides; every tested ring cell is sampled
    # with its inner neighbour, all in one batch
    sides = [(grid[0], grid[1]), (grid[-1], grid[-2]), (grid[:, 0], grid[:, 1]), (grid[:, -1], grid[:, -2])]
    side_of, pair_quads = [], []
    for side, (edge, inward) in enumerate(sides):
        outside = 2.0 * edge - inward
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
            pair_quads += [np.array([a + 0.1 * (oa - a), b + 0.1 * (ob - b), b + 0.6 * (ob - b), a + 0.6 * (oa - a)]),
                           np.array([edge[k], edge[k + 1], inward[k + 1], inward[k]])]
            side_of.append(side)
    means = _cell_means(gray, np.array(inner_quads + pair_quads).reshape(-1, 4, 2))
    inner, pairs = means[:len(inner_quads)], means[len(inner_quads):].reshape(-1, 2)
    if inner.size < 4:
        return True
    ordered = np.sort(inner)
    dark, bright = ordered[:len(ordered) // 2].mean(), ordered[-(len(ordered) // 2):].mean()
    if bright - dark < 20.0:
        return True  # too little contrast to judge
    mid = 0.5 * (dark + bright)
    wrong_pairs = ((pairs[:, 0] - mid) * (pairs[:, 1] - mid) >= 0) | (np.abs(pairs[:, 0] - pairs[:, 1])
                                                                      < 0.25 * (bright - dark))
    side_of = np.array(side_of, dtype=int)
    for side in range(4):
        tested = int(np.count_nonzero(side_of == side))
        wrong = int(np.count_nonzero(wrong_pairs[side_of == side]))
        if tested >= 3 and wrong > max_wrong_fraction * tested:
            return False
    return True


def _is_affine_image(xy: np.ndarray, image: np.ndarray) -> bool:
    """Whether image = A xy + b exactly (to 1e-9 of the layout's size) for some affine map."""
    design = np.column_stack([xy, np.ones(len(xy))])
    coeffs, *_ = np.linalg.lstsq(design, image, rcond=None)
    size = max(float(np.ptp(xy)), 1e-12)
    return bool(np.abs(design @ coeffs - image).max() <= 1e-9 * size)


def grid_reindexings(grid_shape: tuple[int, int]) -> list[np.ndarray]:
    """The ways to number a rows x cols grid row-major from a corner (the dihedral group of
    the index array: 4 re-indexings, 8 for square grids), as index permutations."""
    rows, cols = grid_shape
    ids = np.arange(rows * cols).reshape(rows, cols)
    result = [ids, ids[::-1], ids[:, ::-1], ids[::-1, ::-1]]
    if rows == cols:
        result += [ids.T, ids.T[::-1], ids.T[:, ::-1], ids.T[::-1, ::-1]]
    return [p.ravel() for p in result]
