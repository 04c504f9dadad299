"""Checkerboard tracking between full detections: predict, refine, verify, else detect again.

A video is cut into runs of `DetectOptions.full_detection_every` consecutive frame indices
(run_length; run k holds frames k*N .. k*N + N - 1, so a worker that decodes its own segment
of the video starts a run where one sequential pass would).
The first frame of a run is detected from scratch (Detector.detect). Each later frame is
predicted from the board's place in the two frames before it: the image-to-image homography of
the last step applied once more per frame (constant velocity; over up to MAX_GAP_FRAMES frames
without a full board), or the last corners if only one frame is known.
A wide cornerSubPix pass (half-window 0.4 grid steps, on a half-resolution copy when the grid
step is at least HALF_RES_MIN_STEP_PX) pulls the prediction onto the corners;
the detector's own refinement and checks follow (Detector.refine_checkerboard: cornerSubPix
with the full detection's window, ids, blur, local geometry, here with a stricter residual
bound). The track is then verified:

- every predicted corner lies 0.4 grid steps inside the image (else the board nears the border);
- no corner moved further than 0.45 grid steps from its prediction (a neighbour is one step away);
- every corner is a saddle: its diagonal quadrants are bright, the others dark, or the reverse,
  alternating over the grid (a square's outer corner, an occluder or a lost grid fails).

A frame failing any of these is detected from scratch, with one exception that saves the
costliest full detections (a failing one takes ~350 ms at 1080p): when the board is predicted
partly outside the image and the corners predicted well inside are found there (the same
shift and saddle checks), the homography of those corners places the rest; if a corner lies
OUTSIDE_STEPS grid steps beyond the border, no full board is in the image and the frame is
no_target without a full detection. That board (or one seen in part when a full detection
fails) also continues the track, so the board is re-acquired by tracking when it comes back.
Runs are independent of each other, so
worker processes take whole runs and the result does not depend on the number of workers.
Other target types are detected from scratch in every frame (docs/benchmarks.md, issue 17).
"""
from __future__ import annotations

import functools
from dataclasses import replace
from typing import Optional, Sequence

import cv2
import numpy as np

from .. import _core
from ..io.targets import Target
from .detectors import Detector, FrameDetection, grid_reindexings
from .options import DetectOptions

TRACKED_TARGETS = ("checkerboard",)
MAX_SHIFT_STEPS = 0.45  # largest refinement shift from the prediction, in grid steps
MIN_CONTRAST = 20.0     # grey levels between the bright and the dark quadrants of a corner (median)
MIN_SADDLE_GAP = 0.25   # darker bright quadrant minus brighter dark quadrant, in units of that contrast
MAX_TRACK_RESIDUAL = 0.1  # local-homography residual of a tracked corner, grid steps (good ones: < 0.02)
WIDE_WINDOW_STEPS = 0.4   # first sub-pixel pass from the prediction: half-window in grid steps
OUTSIDE_STEPS = 0.1       # a corner this far (grid steps) beyond the border by the homography of the seen ones is
                          # not in the image (lens distortion moves it far less over the one step it extrapolates)
MAX_GAP_FRAMES = 3        # frames a track is extrapolated over (frames with no full board, e.g. it left the image)
RUN_MAX_GREY_BYTES = 128 << 20  # a run's frames at most: runs of 40 640x480 or 1080p frames, 16 of 4K
HALF_RES_MIN_STEP_PX = 16.0  # the wide pass runs on a half-resolution copy from this grid step: a quarter of the
                             # pixels; the full-resolution refinement then ends on the same corners within a median
                             # 0.004 px a frame (docs/formulation.md §16)


def run_length(target: Target, options: DetectOptions, frame_size: Optional[tuple] = None) -> int:
    """Frames per independently processed run: full_detection_every for tracked targets, else 1; with
    the frames' (width, height), at most RUN_MAX_GREY_BYTES of grey frames (a worker holds a run's
    frames when they are shipped to it: 16 frames of 4K, 4 of 27 MP stills)."""
    if target.target_type in TRACKED_TARGETS and options.full_detection_every > 1:
        frames = int(options.full_detection_every)
        if frame_size is not None:
            frames = min(frames, max(1, RUN_MAX_GREY_BYTES // max(1, int(frame_size[0]) * int(frame_size[1]))))
        return frames
    return 1


def detect_run(detector: Detector, images: Sequence[np.ndarray], indices: Sequence[int]) -> list[FrameDetection]:
    """Detections in one run of frames (grey images and their indices in the source, in order):
    full detection on the first, tracking on the rest where the target allows it."""
    if detector.target.target_type not in TRACKED_TARGETS:
        return [detector.detect(image) for image in images]
    tracker = CheckerboardTracker(detector)
    return [tracker.detect(image, index) for image, index in zip(images, indices)]


class RunDetector:
    """Frames one at a time, in order, cut into runs by index (index // run_frames): a fresh
    tracker for each run (the same detections as detect_run on each run), full detection for
    untracked targets."""

    def __init__(self, detector: Detector, run_frames: int):
        self.detector = detector
        self.run_frames = max(1, int(run_frames))
        self.tracked = detector.target.target_type in TRACKED_TARGETS
        self._run: Optional[int] = None
        self._tracker: Optional[CheckerboardTracker] = None

    def detect(self, image: np.ndarray, index: int) -> FrameDetection:
        if not self.tracked:
            return self.detector.detect(image)
        if index // self.run_frames != self._run:  # runs by frame index: any worker can start one
            self._run = index // self.run_frames
            self._tracker = CheckerboardTracker(self.detector)
        return self._tracker.detect(image, index)


class CheckerboardTracker:
    """Sequential per-frame checkerboard detection that tracks the last accepted corners.

    counts: frames detected from scratch ("full"), tracked ("tracked"), and tracks that failed a
    check and were detected from scratch instead ("track_rejected", also counted in "full")."""

    def __init__(self, detector: Detector):
        self.detector = detector
        # tracked corners: a stricter geometry check; the saddle check below replaces the outer
        # ring's (it samples the ring's squares next to the edge corners, and a track cannot
        # slip by a row: every corner stays within MAX_SHIFT_STEPS of its prediction)
        self._refiner = Detector(detector.target, replace(detector.options, max_residual=MAX_TRACK_RESIDUAL,
                                                          check_outer_ring=False))
        self.grid_shape = detector.target.grid_shape
        self._reindexings = np.stack(grid_reindexings(self.grid_shape))  # (k, rows * cols)
        self._history: list[tuple[int, np.ndarray]] = []  # (index, uv) of the last frames with a known board
        self.counts = {"full": 0, "tracked": 0, "track_rejected": 0, "left_image": 0}

    def detect(self, gray: np.ndarray, index: int) -> FrameDetection:
        predicted = self.extrapolate(index)
        step = _min_step(predicted.reshape(*self.grid_shape, 2)) if predicted is not None else float("nan")
        if predicted is not None and self._inside(predicted, gray.shape, step):
            # a wide first pass pulls the prediction (a few px off) onto the corners; the
            # detector's own refinement then runs exactly as after a full detection
            coarse = _wide_subpix(gray, predicted, self.grid_shape, step)
            found = self._refiner.refine_checkerboard(gray, coarse, numbered=True)
            if found.accepted and not refinement_was_reset(found.uv, coarse) and self._verified(
                    gray, predicted, found.uv):
                self.counts["tracked"] += 1
                self._remember(index, found.uv)
                return found
            self.counts["track_rejected"] += 1
        board = None
        if predicted is not None and not self._inside(predicted, gray.shape, step):
            board = self._partial_board(gray, predicted)
            if board is not None and _beyond_border(board, gray.shape).max() >= OUTSIDE_STEPS * _min_step(
                    board.reshape(*self.grid_shape, 2)):
                self.counts["left_image"] += 1
                self._remember(index, board)
                return FrameDetection(np.zeros(0, np.int64), np.zeros((0, 2)), float("nan"), "no_target")
        self.counts["full"] += 1
        found = self.detector.detect(gray)
        if found.accepted:
            self._remember(index, found.uv)
        elif board is not None:
            self._remember(index, board)  # the board's place, seen in part: the next prediction starts here
        return found

    def predict(self, index: int, shape: tuple) -> Optional[np.ndarray]:
        """Predicted corners of frame `index` (numbered as the last frame's), or None when there is
        no track (no accepted previous frame) or the board would near the image border."""
        predicted = self.extrapolate(index)
        return predicted if predicted is not None and self._inside(predicted, shape) else None

    def extrapolate(self, index: int) -> Optional[np.ndarray]:
        """Where the board's corners should be in frame `index` (numbered as the last known
        frame's; anywhere, also outside the image): the last frame-to-frame homography applied
        once per frame since the last known frame (at most MAX_GAP_FRAMES), or the last corners
        if only one frame is known; None without a recent track."""
        if not self._history or not 0 < index - self._history[-1][0] <= MAX_GAP_FRAMES:
            return None
        last_index, last = self._history[-1]
        if len(self._history) < 2 or self._history[0][0] != last_index - 1:
            return last if index == last_index + 1 else None
        before = self._history[0][1]
        # symmetric boards may be numbered differently in the two frames: match the numbering
        numberings = before[self._reindexings]   # (k, rows * cols, 2)
        difference = numberings - last
        before = numberings[int(np.argmin(np.einsum("kij,kij->k", difference, difference)))]
        step = self._corner_homography(before, last)
        if step is None or not np.all(np.isfinite(step)):
            return last if index == last_index + 1 else None
        predicted = cv2.perspectiveTransform(last.reshape(-1, 1, 2), np.linalg.matrix_power(step, index - last_index))
        return predicted.reshape(-1, 2)

    def _corner_homography(self, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """The homography that maps the grid's four outer corners in `before` onto those in `after`
        (whole grids, one numbering): exact through four points, a tenth of a least-squares fit over
        every corner in time, and the prediction it makes is only a start for the wide pass."""
        rows, cols = self.grid_shape
        outer = [0, cols - 1, (rows - 1) * cols, rows * cols - 1]
        return cv2.getPerspectiveTransform(before[outer].astype(np.float32), after[outer].astype(np.float32))

    def _remember(self, index: int, uv: np.ndarray) -> None:
        """The board's corners in frame `index` (detected, tracked, or estimated from its visible
        part as it leaves the image), kept with the one before if that is frame index - 1."""
        if self._history and self._history[-1][0] != index - 1:
            self._history = []
        self._history = (self._history + [(index, uv)])[-2:]

    def _partial_board(self, gray: np.ndarray, predicted: np.ndarray) -> Optional[np.ndarray]:
        """The board's corners (all: the unseen ones from the homography of the seen ones) when
        it is seen in part at its predicted place: the corners predicted well inside the image
        (at least 2 rows and 2 columns of them) are found there (within MAX_SHIFT_STEPS, saddles
        of the board's colour pattern); else None. A corner that lies OUTSIDE_STEPS grid steps
        beyond the border by this board is not in the image, and a full detection, which needs
        every corner, would find no board."""
        rows, cols = self.grid_shape
        grid = predicted.reshape(rows, cols, 2)
        step = _min_step(grid)
        if not np.isfinite(step):
            return None
        seen = (_beyond_border(predicted, gray.shape) <= -(2.0 + WIDE_WINDOW_STEPS * step)).reshape(rows, cols)
        if np.count_nonzero(seen.any(axis=1)) < 2 or np.count_nonzero(seen.any(axis=0)) < 2:
            return None
        found = _wide_subpix(gray, predicted[seen.ravel()], self.grid_shape, step)
        if np.linalg.norm(found - predicted[seen.ravel()], axis=1).max() > MAX_SHIFT_STEPS * step:
            return None
        refined = grid.copy()
        refined[seen] = found
        if not corners_are_saddles(gray, refined, seen):
            return None
        xy = self.detector.target.points_m[:, :2]
        board, _ = cv2.findHomography(xy[seen.ravel()], found, 0)
        if board is None or not np.all(np.isfinite(board)):
            return None
        return cv2.perspectiveTransform(xy.reshape(-1, 1, 2), board).reshape(-1, 2)

    def _inside(self, uv: np.ndarray, shape: tuple, step: Optional[float] = None) -> bool:
        """Whether every corner lies 0.4 grid steps (and 2 px) inside the image: the refinement
        windows and the saddle samples stay on the image (step: uv's smallest grid step, if known)."""
        margin = 2.0 + WIDE_WINDOW_STEPS * (_min_step(uv.reshape(*self.grid_shape, 2)) if step is None else step)
        height, width = shape[:2]
        if not np.all(np.isfinite(uv)):
            return False
        return bool(uv[:, 0].min() >= margin and uv[:, 1].min() >= margin
                    and uv[:, 0].max() <= width - 1 - margin and uv[:, 1].max() <= height - 1 - margin)

    def _verified(self, gray: np.ndarray, predicted: np.ndarray, uv: np.ndarray) -> bool:
        rows, cols = self.grid_shape
        grid = uv.reshape(rows, cols, 2)
        # refined corners may be renumbered (ids): compare each with its nearest prediction. Its
        # own prediction first: when every corner is near it, so is the nearest (the usual case,
        # without the all-pairs distances)
        limit = MAX_SHIFT_STEPS * _min_step(grid)
        own = uv - predicted
        if np.sqrt(np.einsum("ij,ij->i", own, own).max()) > limit:
            difference = uv[:, None, :] - predicted[None, :, :]
            shift_sq = np.einsum("ijk,ijk->ij", difference, difference).min(axis=1)
            if np.sqrt(shift_sq.max()) > limit:
                return False
        return corners_are_saddles(gray, grid)


def refinement_was_reset(refined: np.ndarray, start: np.ndarray) -> bool:
    """Whether a refined corner is exactly one of the refinement's start points. cornerSubPix puts a
    corner back on its start when it would leave its window: such a corner was not found, and a
    grid that did not move can then pass every later check (no shift, a perfect local homography,
    saddles still alternating; frame 1641 of the 60 s speed render, in a variant that refined from
    the previous frame's corners). Any other result differs from its start in the last bits."""
    refined = np.asarray(refined, dtype=np.float64).reshape(-1, 2)
    start = np.asarray(start, dtype=np.float64).reshape(-1, 2)
    # a shared x first (a set lookup, ~8 us): the full comparison of every pair took 130 us a frame
    start_x = set(start[:, 0].tolist())
    if not any(x in start_x for x in refined[:, 0].tolist()):
        return False
    return bool(np.any(np.all(refined[:, None, :] == start[None, :, :], axis=2)))


def _beyond_border(uv: np.ndarray, shape: tuple) -> np.ndarray:
    """How far (px) each point lies beyond the image border; negative inside (minus its distance to the border)."""
    height, width = shape[:2]
    return np.max(np.stack([-uv[:, 0], -uv[:, 1], uv[:, 0] - (width - 1), uv[:, 1] - (height - 1)]), axis=0)


def corners_are_saddles(gray: np.ndarray, grid: np.ndarray, mask: Optional[np.ndarray] = None) -> bool:
    """Whether every corner of a (rows, cols, 2) grid (or those where the (rows, cols) mask is
    set) is a checkerboard saddle: of the four points 0.3 grid steps away along the diagonals,
    one diagonal pair is brighter than the other by a clear gap, and which pair is bright
    alternates from corner to corner. A corner of a single square at the board's edge (three
    bright quadrants) or an occluded corner fails."""
    rows, cols = grid.shape[:2]
    if rows < 2 or cols < 2:
        return False
    # the sample places and the decision in the core (numpy's numbers), the sampling by OpenCV
    map_x, map_y = _core.saddle_sample_points(grid.reshape(-1, 2), rows, cols, 0.3)
    even = _even_corners((rows, cols))
    if mask is not None:
        map_x, map_y, even = map_x[mask.ravel()], map_y[mask.ravel()], even[mask.ravel()]
    values = cv2.remap(gray, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return _core.corners_are_saddles(values.astype(np.float64), even, MIN_CONTRAST, MIN_SADDLE_GAP)


@functools.lru_cache(maxsize=16)
def _even_corners(shape: tuple) -> np.ndarray:
    even = (np.add.outer(np.arange(shape[0]), np.arange(shape[1])) % 2 == 0).ravel()
    even.flags.writeable = False
    return even


def _wide_subpix(gray: np.ndarray, uv: np.ndarray, grid_shape: tuple, step: Optional[float] = None) -> np.ndarray:
    """cornerSubPix with a half-window of WIDE_WINDOW_STEPS grid steps (step: the grid's
    smallest, from uv as a whole grid if not given): pulls predicted corners a few px off
    onto the corners. From a grid step of HALF_RES_MIN_STEP_PX it runs on the image's first
    pyramid level (pixel centres: full = 2 x half), a quarter of the pixels: the refinement
    that follows at full resolution sets the final places."""
    step = _min_step(uv.reshape(*grid_shape, 2)) if step is None else step
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 0.05)
    if step >= HALF_RES_MIN_STEP_PX:
        half_window = int(np.clip(round(0.5 * WIDE_WINDOW_STEPS * step), 2, 30))
        start = (0.5 * uv).astype(np.float32).reshape(-1, 1, 2)
        found = cv2.cornerSubPix(cv2.pyrDown(gray), start, (half_window, half_window), (-1, -1), criteria)
        return 2.0 * found.reshape(-1, 2).astype(np.float64)
    half_window = int(np.clip(round(WIDE_WINDOW_STEPS * step), 2, 60))
    return cv2.cornerSubPix(gray, uv.astype(np.float32).reshape(-1, 1, 2), (half_window, half_window),
                            (-1, -1), criteria).reshape(-1, 2).astype(np.float64)


def _min_step(grid: np.ndarray) -> float:
    """The smallest distance between neighbouring corners of a (rows, cols, 2) grid."""
    along_cols, along_rows = grid[:, 1:] - grid[:, :-1], grid[1:] - grid[:-1]
    smallest_sq = min(np.einsum("ijk,ijk->ij", along_cols, along_cols).min(initial=np.inf),
                      np.einsum("ijk,ijk->ij", along_rows, along_rows).min(initial=np.inf))
    return float(np.sqrt(smallest_sq))
