"""What the machine can hold, checked before any frame is decoded (issue 14; docs/benchmarks.md,
"Peak memory against input size").

- :func:`available_memory_bytes`: MemAvailable of /proc/meminfo, lowered to a cgroup limit if the
  process runs under one.
- :func:`frame_memory_bytes` / :func:`check_frame_memory`: the peak working set of decoding and
  processing frames of a size in ``workers`` processes at once; refused up front (InputError with
  both numbers) when it does not fit.
- :func:`worker_count`: worker processes bounded by the usable cores and by memory.
- :func:`source_frame_size`: the largest frame of a video or image set from the file headers only
  (no pixel is decoded), so a 30000x30000 PNG is refused before it is read;
  :func:`check_source_memory` and :func:`bounded_workers` apply the checks above to it (the calls
  to make before decoding a source: self-calibration, intrinsics, detection).
- :func:`keep_freed_memory`: in a process of our own (`rscalib linedelay`), freed
  memory kept for reuse instead of handed back to the system at once.
"""
from __future__ import annotations

import ctypes
import os
import sys
import threading
from pathlib import Path
from typing import Optional, Union

from ..errors import InputError

__all__ = ["FRAME_BYTES_PER_PIXEL", "WORKER_BASE_BYTES", "MEMORY_HEADROOM", "available_memory_bytes", "bounded_workers",
           "check_memory", "check_frame_memory", "check_source_memory", "frame_memory_bytes", "format_bytes", "image_size",
           "keep_freed_memory", "source_frame_size", "usable_cores", "worker_count"]

# Peak bytes per pixel of one frame in flight (measured, docs/benchmarks.md): the self-calibration
# front end on a decoded grey frame peaks at 26-27 B/px (corner search: float eigenvalue and
# derivative images), target detection at 6-10 B/px on a colour frame; plus the frame itself, its
# grey copy and the decoder's buffers. 32 covers every engine.
FRAME_BYTES_PER_PIXEL = 32
# Resident memory of one worker process before it holds a frame (Python, NumPy, OpenCV, rscalib):
# --workers 64 on 2 cores reached 6.5 GB on this alone.
WORKER_BASE_BYTES = 100 * 2 ** 20
# Use at most this fraction of what is available: the rest is for the engine's own state, the
# interpreter and other programs.
MEMORY_HEADROOM = 0.8

_MEMINFO = Path("/proc/meminfo")
# glibc's mallopt parameters (malloc.h) and what keep_freed_memory sets them to: the largest block
# glibc lets the heap serve (32 MB), and no trimming of the heap's free top below 1 GB
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_HEAP_BLOCK_MAX_BYTES = 32 * 2 ** 20
_TRIM_THRESHOLD_BYTES = 2 ** 30
_CGROUP_FILES = (Path("/sys/fs/cgroup/memory.max"), Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"))
_CGROUP_USAGE = (Path("/sys/fs/cgroup/memory.current"), Path("/sys/fs/cgroup/memory/memory.usage_in_bytes"))


def format_bytes(count: float) -> str:
    """``count`` bytes as GiB (or MiB below one GiB), with the exact number."""
    if count >= 2 ** 30:
        return f"{count / 2 ** 30:.1f} GiB ({int(count):,} bytes)"
    return f"{count / 2 ** 20:.0f} MiB ({int(count):,} bytes)"


def _read_int(path: Path) -> Optional[int]:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def keep_freed_memory() -> bool:
    """Freed memory stays with the process for its next allocation (glibc; elsewhere nothing is done:
    False). Each Ceres solve allocates its Jacobian afresh (20-40 MB for a minute of video) and glibc
    would hand it back to the system on every free, so that the next solve page-faults it in again:
    0.4 s of system time in the 60 s speed video's 8 s (docs/benchmarks.md). Process-wide: only for
    processes of our own, never on import."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False  # not glibc (e.g. musl has no mallopt)
    return bool(mallopt(_M_MMAP_THRESHOLD, _HEAP_BLOCK_MAX_BYTES)) and bool(
        mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD_BYTES))


def available_memory_bytes() -> tuple[int, str]:
    """(bytes the process may still use, where that number comes from). Linux: MemAvailable of
    /proc/meminfo, or less if a cgroup limit leaves less; elsewhere the physical memory."""
    available, origin = None, ""
    try:
        for line in _MEMINFO.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available, origin = int(line.split()[1]) * 1024, "MemAvailable in /proc/meminfo"
                break
    except (OSError, ValueError, IndexError):
        pass
    if available is None:
        try:
            available = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
            origin = "physical memory"
        except (OSError, ValueError, AttributeError):
            available, origin = 2 ** 62, "unknown (not checked)"
    for limit_path, usage_path in zip(_CGROUP_FILES, _CGROUP_USAGE):
        limit = _read_int(limit_path)
        if limit is not None and limit < 2 ** 60:
            left = limit - (_read_int(usage_path) or 0)
            if left < available:
                available, origin = max(left, 0), f"cgroup limit {limit_path}"
            break
    return int(available), origin


def check_memory(needed_bytes: float, what: str) -> None:
    """InputError naming ``what``, the bytes it needs and the bytes available, when ``needed_bytes``
    exceeds MEMORY_HEADROOM of the available memory."""
    available, origin = available_memory_bytes()
    if needed_bytes > MEMORY_HEADROOM * available:
        raise InputError(f"{what} needs about {format_bytes(needed_bytes)} of memory, more than "
                         f"{MEMORY_HEADROOM:.0%} of the {format_bytes(available)} available ({origin})")


def frame_memory_bytes(width: int, height: int, workers: int = 1) -> int:
    """Peak memory of ``workers`` processes each decoding and processing one ``width`` x ``height`` frame."""
    return int(max(1, workers) * (WORKER_BASE_BYTES + FRAME_BYTES_PER_PIXEL * int(width) * int(height)))


def check_frame_memory(width: int, height: int, workers: int = 1, what: str = "") -> int:
    """Refuse (InputError with the numbers) frames of ``width`` x ``height`` in ``workers`` processes
    when they would not fit in memory; else the bytes they need. Call before decoding."""
    if width <= 0 or height <= 0:
        raise InputError(f"{what or 'frames'}: image size {width}x{height} is not positive")
    needed = frame_memory_bytes(width, height, workers)
    label = what or "frames"
    procs = f" in {workers} processes" if workers > 1 else ""
    check_memory(needed, f"{label} of {width}x{height} px{procs}")
    return needed


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def worker_count(requested: Optional[int], width: int, height: int) -> int:
    """Worker processes for frames of ``width`` x ``height``: ``requested`` (None: all usable cores)
    bounded by the usable cores and by what memory holds (at least 1; :func:`check_frame_memory`
    then says whether even one fits)."""
    workers = usable_cores() if requested is None else max(1, min(int(requested), usable_cores()))
    available, _ = available_memory_bytes()
    per_worker = frame_memory_bytes(width, height, 1)
    return max(1, min(workers, int(MEMORY_HEADROOM * available // per_worker)))


_PIL_LOCK = threading.Lock()


def image_size(path: Union[str, Path]) -> Optional[tuple[int, int]]:
    """(width, height) of an image file from its header (Pillow reads no pixels), or None when
    Pillow cannot identify the file (the decoder reports it later)."""
    from PIL import Image, UnidentifiedImageError

    with _PIL_LOCK:
        # Pillow refuses huge images in open() itself; here only the header is read, and a huge
        # size is exactly what the caller wants to see.
        limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            with Image.open(path) as image:
                return int(image.size[0]), int(image.size[1])
        except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
            return None
        finally:
            Image.MAX_IMAGE_PIXELS = limit


def _video_size(path: Path) -> Optional[tuple[int, int]]:
    import cv2

    capture = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    try:
        if not capture.isOpened():
            return None
        width, height = capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT)
    finally:
        capture.release()
    return (int(width), int(height)) if width > 0 and height > 0 else None


def source_frame_size(source) -> tuple[Optional[tuple[int, int]], Optional[Path]]:
    """The largest frame (width, height) of a :class:`rscalib.io.video.FrameSource` from headers
    (every image's, or the video stream's) and its file; (None, None) when no header could be read."""
    if source.kind == "video":
        size = _video_size(Path(source.paths[0]))
        return size, (Path(source.paths[0]) if size else None)
    best, best_path = None, None
    for path in source.paths:
        size = image_size(path)
        if size is not None and (best is None or size[0] * size[1] > best[0] * best[1]):
            best, best_path = size, Path(path)
    return best, best_path


def check_source_memory(source, workers: int = 1) -> Optional[tuple[int, int]]:
    """:func:`check_frame_memory` for the largest frame of ``source`` (a FrameSource), read from
    the headers before anything is decoded; the InputError names that file. Returns the size."""
    size, path = source_frame_size(source)
    if size is not None:
        check_frame_memory(size[0], size[1], workers, what=f"{path}: frames")
    return size


def bounded_workers(source, requested: Optional[int]) -> Optional[int]:
    """Before decoding ``source`` (a FrameSource) in worker processes: refuse frames too large for
    even one process (InputError naming the file and the bytes), and bound ``requested`` by the
    usable cores and by memory (:func:`worker_count`). None stays None (the caller's default) unless
    memory holds fewer processes than there are cores."""
    size = check_source_memory(source, workers=1)
    if size is None:
        return requested if requested is None else max(1, min(int(requested), usable_cores()))
    bounded = worker_count(requested, *size)
    if requested is None and bounded >= usable_cores():
        return None
    return bounded
