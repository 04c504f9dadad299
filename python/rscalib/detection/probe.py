"""What checkerboard the frames seem to show, to catch a target file that does not match the video
(wrong size, squares counted instead of inner corners, a smaller board declared than filmed).

OpenCV's chessboard finder also accepts a smaller grid inside a larger board in some frames, each
time at a different place: a 4x3 (5x4, 4x6, 5x5) target file for a 9x6 board then "detects", and
the line delay fits nonsense. So after detection a few frames are searched for the whole board
they show (findChessboardCornersSB grown from a 3x3 start, CALIB_CB_LARGER).

Before detection, :func:`early_board` looks at a few frames of the video's first seconds, so a target
file that does not match fails in seconds rather than after the whole detection (issue 31).
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np

from ..io.targets import Target
from ..io.video import open_source

# findChessboardCornersSB with CALIB_CB_LARGER finds the whole board from a 3x3 start and says its
# size (0.1 s a frame); trying each size with findChessboardCorners instead took 10 s a frame and
# never found a board larger by one (OpenCV does not report sub-grids it was not asked for).
_START_SIZE = (3, 3)
_SB_FLAGS = cv2.CALIB_CB_LARGER | cv2.CALIB_CB_NORMALIZE_IMAGE


def sample_frames(source: Union[str, Path, Sequence], numbers: Sequence[int], limit: int = 4) -> list[np.ndarray]:
    """Grey frames of `source` with the given indices (at most `limit`, spread out)."""
    wanted = sorted(set(int(n) for n in numbers))
    if len(wanted) > limit:
        wanted = [wanted[int(i)] for i in np.linspace(0, len(wanted) - 1, limit)]
    wanted_set = set(wanted)
    out = []
    for frame in open_source(source).frames(gray=True, luma=True):
        if frame.index in wanted_set and frame.image is not None:
            out.append(frame.image)
            if len(out) == len(wanted):
                break
        if frame.index > wanted[-1]:
            break
    return out


def _small(gray: np.ndarray, max_side: int = 800) -> np.ndarray:
    scale = max_side / max(gray.shape)
    return cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else gray


def board_size(gray: np.ndarray) -> Optional[tuple[int, int]]:
    """(cols, rows) of inner corners of the whole checkerboard a frame shows (cols >= rows), or None."""
    try:
        ok, _, meta = cv2.findChessboardCornersSBWithMeta(_small(gray), _START_SIZE, _SB_FLAGS)
    except cv2.error:
        return None
    if not ok or meta is None or meta.ndim != 2:
        return None
    return max(meta.shape), min(meta.shape)


def whole_board_size(gray: np.ndarray) -> Optional[tuple[int, int]]:
    """board_size of a board seen whole: its outer corners at least two squares from the image's border
    (a board cut by the border shows fewer corners than it has), else None."""
    small = _small(gray)
    try:
        ok, corners, meta = cv2.findChessboardCornersSBWithMeta(small, _START_SIZE, _SB_FLAGS)
    except cv2.error:
        return None
    if not ok or meta is None or meta.ndim != 2 or corners is None or len(corners) < 4:
        return None
    uv = corners.reshape(-1, 2)
    rows, cols = meta.shape
    grid = uv.reshape(rows, cols, 2) if rows * cols == len(uv) else None
    if grid is None:
        return None
    step = float(np.median(np.concatenate([np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel(),
                                           np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel()])))
    h, w = small.shape[:2]
    margin = 2.0 * step
    if uv[:, 0].min() < margin or uv[:, 1].min() < margin or uv[:, 0].max() > w - 1 - margin \
            or uv[:, 1].max() > h - 1 - margin:
        return None
    return max(meta.shape), min(meta.shape)


def larger_board_visible(frames: Sequence[np.ndarray], cols: int, rows: int) -> bool:
    """True when some frame shows a checkerboard with more inner corners than cols x rows."""
    for image in frames:
        seen = board_size(image)
        if seen is not None and seen[0] * seen[1] > cols * rows:
            return True
    return False


def largest_board(frames: Sequence[np.ndarray]) -> Optional[tuple[int, int]]:
    """(cols, rows) of inner corners of the checkerboard seen in most of the frames (cols >= rows;
    on a tie the larger), or None."""
    votes: dict = {}
    for image in frames:
        seen = board_size(image)
        if seen is not None:
            votes[seen] = votes.get(seen, 0) + 1
    if not votes:
        return None
    return max(votes.items(), key=lambda kv: (kv[1], kv[0][0] * kv[0][1]))[0]


# early_board: frames sampled from the start of the video, every EARLY_STEP-th, at most EARLY_FRAMES;
# a board size seen in EARLY_AGREE of them settles the question
EARLY_FRAMES, EARLY_STEP, EARLY_AGREE = 6, 10, 2


def early_board(source: Union[str, Path, Sequence], frames: int = EARLY_FRAMES, step: int = EARLY_STEP,
                agree: int = EARLY_AGREE, expected: Optional[tuple[int, int]] = None) -> Optional[tuple[int, int]]:
    """(cols, rows) of the checkerboard seen whole (whole_board_size) in `agree` of the frames 0, step,
    2 step, ... (at most `frames` of them, from the video's start: decoding stops at the last), or None
    when no size is seen that often. Stops as soon as one size is seen `agree` times.

    expected: the size the target file declares (cols, rows, either order). The frames are then searched
    at half resolution first, 0.023 instead of 0.057 s a 640x480 frame: `expected` seen there `agree`
    times, and at full resolution in the last of them, settles it (one full-resolution search instead of
    `agree` or more); any other outcome is decided at full resolution as without `expected` (half
    resolution neither calls a board it cannot resolve a mismatch nor hides a larger board)."""
    votes: dict = {}
    wanted = set(range(0, frames * step, step))
    kept = []
    expected_sorted = sorted(expected) if expected is not None else None
    matches = 0
    for frame in open_source(source).frames(gray=True, luma=True):
        if frame.index in wanted and frame.image is not None:
            if expected_sorted is None:
                seen = whole_board_size(frame.image)
                if seen is not None:
                    votes[seen] = votes.get(seen, 0) + 1
                    if votes[seen] >= agree:
                        return seen
            else:
                small = _small(frame.image)
                kept.append(small)
                half = whole_board_size(cv2.resize(small, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
                if half is not None and sorted(half) == expected_sorted:
                    matches += 1
                    # confirmed once at full resolution: half resolution must not hide a larger board
                    if matches >= agree and whole_board_size(small) == half:
                        return half
        if frame.index >= max(wanted):
            break
    for small in kept:   # expected not settled at half resolution: the frames at full resolution
        seen = whole_board_size(small)
        if seen is not None:
            votes[seen] = votes.get(seen, 0) + 1
            if votes[seen] >= agree:
                return seen
    return None


def mismatch_message(target: Target, seen: Optional[tuple[int, int]]) -> str:
    """One line: what the target file says and what the frames seem to show."""
    rows, cols = target.grid_shape
    said = f"the target file describes a {cols}x{rows} checkerboard (inner corners)"
    if seen is None:
        return said + ", but no checkerboard could be found in the sampled frames (wrong target type?)"
    c, r = seen
    hint = ""
    if {c + 1, r + 1} == {cols, rows}:
        hint = ": count the inner corners, not the squares"
    elif c * r > cols * rows:
        hint = ": the file describes a smaller board than the one filmed"
    return f"{said}, but the frames seem to show a {c}x{r} board{hint}"
