"""What checkerboard the frames seem to show, to catch a target file that does not match the video
(wrong size, squares counted instead of inner corners, a smaller board declared than filmed).

OpenCV's chessboard finder also accepts a smaller grid inside a larger board in some frames, each
time at a different place: a 4x3 target file for a 9x6 board then "detects", and the line delay
fits nonsense. So after detection a few frames are searched for the largest board they show.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np

from ..io.targets import Target
from ..io.video import open_source

MAX_INNER_CORNERS = 16   # largest side searched
_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK


def sample_frames(source: Union[str, Path, Sequence], numbers: Sequence[int], limit: int = 4) -> list[np.ndarray]:
    """Grey frames of `source` with the given indices (at most `limit`, spread out)."""
    wanted = sorted(set(int(n) for n in numbers))
    if len(wanted) > limit:
        wanted = [wanted[int(i)] for i in np.linspace(0, len(wanted) - 1, limit)]
    wanted_set = set(wanted)
    out = []
    for frame in open_source(source).frames(gray=True):
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


def _found(gray: np.ndarray, cols: int, rows: int) -> bool:
    ok, _ = cv2.findChessboardCorners(gray, (cols, rows), flags=_FLAGS)
    return bool(ok)


def larger_board_visible(frames: Sequence[np.ndarray], cols: int, rows: int) -> bool:
    """True when some frame shows a checkerboard with more inner corners than cols x rows."""
    for image in frames:
        g = _small(image)
        for c, r in ((cols + 1, rows), (cols, rows + 1), (rows + 1, cols), (rows, cols + 1)):
            if _found(g, c, r):
                return True
    return False


def largest_board(frames: Sequence[np.ndarray]) -> Optional[tuple[int, int]]:
    """(cols, rows) of inner corners of the largest checkerboard seen in most of the frames (cols >=
    rows), or None."""
    sizes = sorted(((c, r) for c in range(3, MAX_INNER_CORNERS + 1) for r in range(3, c + 1)),
                   key=lambda cr: -cr[0] * cr[1])
    votes: dict = {}
    for image in frames:
        g = _small(image)
        for c, r in sizes:
            if _found(g, c, r):
                votes[(c, r)] = votes.get((c, r), 0) + 1
                break
    if not votes:
        return None
    return max(votes.items(), key=lambda kv: (kv[1], kv[0][0] * kv[0][1]))[0]


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
