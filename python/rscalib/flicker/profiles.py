"""Row profiles of frames for the flicker method: the mean grey of each row in column strips.

The strips are kept (``RowProfiles.strips``) so that :mod:`rscalib.flicker.region` can choose the
strips and rows that carry bands; ``values`` is their combination (all strips until a region is
chosen). Clipped pixels are data: a strip that clips is left out of a row only while some strip of
that row stays unclipped (scene highlights); where the light itself clips (LED bands saturated or
black), the clipped strips are used."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from .._progress import Progress
from ..errors import InputError
from .options import roi_box

MIN_ROWS = 16
STRIPS = 32                      # column strips per row (region choice, clipped pixels)
CLIPPED_FRACTION = 0.02          # a strip clips in a row when more of its pixels are at 0 or full scale


@dataclass
class RowProfiles:
    """Row profiles of a frame sequence: mean grey over the region's columns, one row per image row."""

    values: np.ndarray                  # (frames, rows) linear grey levels; NaN: no strip used
    rows_v: np.ndarray                  # (rows,) image row of each column of `values`
    times_s: Optional[np.ndarray]       # (frames,) time of row 0; None when unknown
    image_size: tuple                   # (width, height)
    full_scale: Optional[float] = None  # saturation level of integer images
    frames_total: int = 0
    frames_skipped: int = 0
    timestamps_source: str = "given"
    roi: Optional[tuple] = None
    warnings: list = field(default_factory=list)
    strips: Optional[np.ndarray] = field(default=None, repr=False)        # (frames, rows, S) strip means
    strip_clipped: Optional[np.ndarray] = field(default=None, repr=False)  # (rows, S) clipped in some frame
    strip_columns: Optional[np.ndarray] = None  # (S, 2) first and last+1 image column of each strip
    region: dict = field(default_factory=dict)  # what rscalib.flicker.region chose (strips, rows, masks)
    row_pixels: Optional[np.ndarray] = None     # (rows,) columns averaged in each row


def _parse_roi(roi, width: int, height: int) -> tuple[slice, slice, Optional[tuple]]:
    box = roi_box(roi)
    if box is None:
        return slice(0, height), slice(0, width), None
    x, y, w, h = box
    if x + w > width or y + h > height:
        raise InputError(f"region {x},{y},{w},{h} is not inside the {width}x{height} image")
    if h < MIN_ROWS:
        raise InputError(f"region has {h} rows; at least {MIN_ROWS} are needed")
    return slice(y, y + h), slice(x, x + w), (x, y, w, h)


def _gray(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim == 3:
        return image.mean(axis=2)  # channel order does not matter for a gain
    if image.ndim != 2:
        raise InputError(f"a frame must be a 2-D (grey) or 3-D (colour) array, got shape {image.shape}")
    return image


def read_row_profiles(frames: Any, timestamps_s: Optional[Sequence[float]] = None, roi=None,
                      max_frames: Optional[int] = None, progress: bool = False) -> RowProfiles:
    """Row profiles of frames: an array (H, W) / (N, H, W) / (N, H, W, C), a list of arrays, a
    :class:`rscalib.io.video.FrameSource`, or anything :func:`rscalib.io.video.open_source` reads (video,
    image folder with optional timestamps.txt, an image file or a list of them). ``max_frames``: the
    first N usable frames. Image files and folders without timestamps.txt have no known times (the
    phase-drift method needs them)."""
    if max_frames is not None and int(max_frames) < 1:
        raise InputError("max frames must be >= 1")
    if isinstance(frames, np.ndarray) or (isinstance(frames, (list, tuple)) and len(frames) > 0
                                          and isinstance(frames[0], np.ndarray)):
        stack = [frames] if isinstance(frames, np.ndarray) and frames.ndim == 2 else list(frames)
        if isinstance(frames, np.ndarray) and frames.ndim not in (2, 3, 4):
            raise InputError(f"frames must be (H, W), (N, H, W) or (N, H, W, C), got shape {frames.shape}")
        return _profiles(iter((i, None, img) for i, img in enumerate(stack)), len(stack), timestamps_s,
                         roi, max_frames, progress, "given" if timestamps_s is not None else "none")

    from ..io.limits import check_source_memory
    from ..io.video import FrameSource, open_source
    source = frames if isinstance(frames, FrameSource) else open_source(frames)
    check_source_memory(source)   # frame sizes from the headers: refuse before decoding a frame too big
    times_known = source.timestamps_source != "frame index"

    def items():
        for frame in source.frames(gray=True):
            yield frame.index, (frame.time_s if frame.problem is None else None), frame.image if frame.problem is None else None

    result = _profiles(items(), source.frame_count_estimate, timestamps_s, roi, max_frames, progress,
                       source.timestamps_source, source_times=times_known)
    result.warnings[:0] = list(source.warnings)
    if not times_known and timestamps_s is None:
        result.times_s = None
        result.timestamps_source = "none"
        if len(result.values) > 1:   # one frame has no drift to measure: nothing is missing
            result.warnings.append(f"no frame timestamps ({_without_times(frames, source)}): the phase-drift "
                                   "method is unavailable")
    return result


def _without_times(frames: Any, source) -> str:
    """Why a source has no frame times, in its own words."""
    if isinstance(frames, (str, Path)) and Path(frames).is_dir():
        return "image folder without timestamps.txt"
    if source.kind == "images":
        return "image files have none; put them in a folder with a timestamps.txt"
    return "the video has neither frame times nor a frame rate"


def _profiles(items, total, timestamps_s, roi, max_frames, progress, timestamps_source,
              source_times: bool = False) -> RowProfiles:
    # Columns are averaged in strips; a strip "clips" in a row when more than CLIPPED_FRACTION of
    # its pixels sit at 0 or full scale in some frame (combine_strips decides what that means). The
    # same strips are used in every frame, so that the scene cancels.
    strips, clipped, times, size, full_scale, rows_slice, cols_slice, roi_used = [], None, [], None, None, None, None, None
    edges = None
    seen, skipped = 0, 0
    limit = int(max_frames) if max_frames is not None else None
    with Progress(progress, total if limit is None else min(limit, total or limit), "reading frames") as bar:
        for _, time_s, image in items:
            seen += 1
            if image is None:
                skipped += 1
                continue
            gray = _gray(image)
            if size is None:
                size = (gray.shape[1], gray.shape[0])
                rows_slice, cols_slice, roi_used = _parse_roi(roi, *size)
                if np.issubdtype(gray.dtype, np.integer):
                    full_scale = float(np.iinfo(gray.dtype).max)
                elif np.issubdtype(np.asarray(image).dtype, np.integer):
                    full_scale = float(np.iinfo(np.asarray(image).dtype).max)
            elif (gray.shape[1], gray.shape[0]) != size:
                raise InputError(f"frame {seen - 1} is {gray.shape[1]}x{gray.shape[0]}, the first was "
                                 f"{size[0]}x{size[1]}")
            block = np.asarray(gray[rows_slice, cols_slice])
            if edges is None:
                count = max(1, min(STRIPS, block.shape[1] // 8))
                edges = np.linspace(0, block.shape[1], count + 1).round().astype(int)[:-1]
                widths = np.diff(np.append(edges, block.shape[1])).astype(np.float64)
                clipped = np.zeros((block.shape[0], len(edges)), dtype=bool)
            strips.append((np.add.reduceat(block, edges, axis=1, dtype=np.float64) / widths).astype(np.float32))
            if full_scale is not None:
                at_limit = (block >= full_scale) | (block <= 0)
                clipped |= np.add.reduceat(at_limit, edges, axis=1) > CLIPPED_FRACTION * widths
            times.append(time_s)
            bar.advance()
            if limit is not None and len(strips) >= limit:
                break
    if not strips:
        raise InputError("no readable frame" + (f" ({skipped} unreadable)" if skipped else ""))
    if size[1] < MIN_ROWS:
        raise InputError(f"images have {size[1]} rows; at least {MIN_ROWS} are needed")
    times_s = None
    if timestamps_s is not None:
        given = np.asarray(timestamps_s, dtype=np.float64).ravel()
        if len(given) < len(strips):
            raise InputError(f"timestamps_s: {len(given)} times for {len(strips)} frames")
        times_s = given[:len(strips)]
        timestamps_source = "given"
    elif source_times:
        times_s = np.asarray(times, dtype=np.float64)
    if times_s is not None and (not np.all(np.isfinite(times_s)) or np.any(np.diff(times_s) <= 0)):
        raise InputError(f"{'timestamps_s' if timestamps_source == 'given' else 'the frame timestamps'} must be "
                         "finite and strictly increasing")
    columns = np.column_stack([edges, np.append(edges[1:], block.shape[1])]) + cols_slice.start
    result = RowProfiles(values=np.zeros((len(strips), block.shape[0])),
                         rows_v=np.arange(size[1], dtype=np.float64)[rows_slice], times_s=times_s,
                         image_size=size, full_scale=full_scale, frames_total=seen, frames_skipped=skipped,
                         timestamps_source=timestamps_source, roi=roi_used, strips=np.array(strips),
                         strip_clipped=clipped, strip_columns=columns)
    result.values = combine_strips(result)
    return result


def combine_strips(profiles: RowProfiles, use: Optional[np.ndarray] = None,
                   gains: Optional[np.ndarray] = None) -> np.ndarray:
    """(frames, rows) weighted mean of the strips ``use`` (rows, S) bool (all when None), each
    scaled by ``gains`` (S,). In a row, clipped strips are left out while some used strip stays
    unclipped; otherwise (the light itself clips) every used strip counts. Sets
    ``profiles.row_pixels`` (columns averaged in each row)."""
    strips = profiles.strips
    widths = np.diff(profiles.strip_columns, axis=1)[:, 0].astype(np.float64)
    use = np.ones(strips.shape[1:], dtype=bool) if use is None else use
    unclipped = use & ~profiles.strip_clipped
    mostly = unclipped.sum(axis=1) >= 1
    keep = np.where(mostly[:, None], unclipped, use) * widths[None, :]
    scaled = strips if gains is None else strips * np.asarray(gains, dtype=np.float32)[None, None, :]
    profiles.row_pixels = keep.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.einsum("nrs,rs->nr", scaled.astype(np.float64), keep) / keep.sum(axis=1)
