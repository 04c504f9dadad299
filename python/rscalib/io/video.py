"""Frames with timestamps from a video file, an image folder or a list of images (streaming).

Videos are read with OpenCV's FFmpeg backend. A frame's time is the container's presentation
time (CAP_PROP_POS_MSEC after each grab), so variable frame rates need nothing special; a
frame whose time does not increase is skipped (`bad_timestamp`). Only when the container has no
times at all (every frame reports 0) do times fall back to index / fps, with a warning.
Image folders are read in file-name order (numbers compared by value, so frame2 < frame10),
with times from `timestamps.txt` in the folder (one time per line, in that order; seconds, or
ms, us or ns told by the frame rate and converted) or else the image index (0, 1, 2, ... s:
timestamps_source "frame index", which the engines that need time refuse). Nothing is kept in memory between frames.
"""
from __future__ import annotations

import contextlib
import functools
import glob
import hashlib
import os
import re
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Optional, Sequence, Union

import cv2
import numpy as np

from .. import checks
from ..errors import InputError
from .limits import check_source_memory

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pbm", ".webp", ".jp2")
TIMESTAMPS_FILE = "timestamps.txt"


@dataclass
class Frame:
    """One frame: index in the source, time of row 0 (s), pixels (None if the frame is unusable,
    with the reason in `problem`: "unreadable" or "bad_timestamp"), and a label for reports."""

    index: int
    time_s: float
    image: Optional[np.ndarray]
    label: str
    problem: Optional[str] = None


@dataclass
class FrameSource:
    """A video or an image sequence; `frames()` decodes lazily, one frame at a time."""

    kind: str                                   # "video" | "images"
    paths: list                                 # the video, or the images in order
    timestamps_source: str                      # "container" | "frame rate" | "timestamps file" | "frame index"
    frame_count_estimate: Optional[int] = None  # from the container for videos (may be off)
    fps_nominal: Optional[float] = None
    times_s: Optional[np.ndarray] = None        # image sequences: the time of every image
    warnings: list = field(default_factory=list)

    def frames(self, gray: bool = False, luma: bool = False) -> Iterator[Frame]:
        """The frames, decoded one at a time. gray: one-channel images; luma (with gray): a video's
        grey frames straight from the decoder's luma plane when its first frame shows that to be the
        grey image (luma_plan), else through BGR as without it."""
        if self.kind == "images":
            yield from self._images(gray)
        else:
            yield from self._video(gray, self.luma_plan() if gray and luma else None)

    def luma_plan(self) -> Optional[LumaPlan]:
        """A video's LumaPlan (None: its grey frames come through BGR; always None for images)."""
        return luma_plan(self.paths[0]) if self.kind == "video" else None

    def content_hash(self) -> str:
        """SHA-256 of the bytes (streamed) of the video, or of every image and the timestamps."""
        digest = hashlib.sha256()
        for path in self.paths:
            digest.update(f"{os.path.getsize(path)}\0".encode())
            with open(path, "rb") as stream:
                for chunk in iter(lambda: stream.read(1 << 22), b""):
                    digest.update(chunk)
        if self.kind == "images":
            digest.update(np.asarray(self.times_s, dtype=np.float64).tobytes())
        return digest.hexdigest()

    def _images(self, gray: bool) -> Iterator[Frame]:
        flag = cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR
        for index, path in enumerate(self.paths):
            try:
                image = cv2.imread(str(path), flag)
            except cv2.error as error:   # e.g. over OpenCV's 2**30-pixel limit: raised, not None
                raise InputError(f"{path}: OpenCV cannot decode this image "
                                 f"({str(error).strip().splitlines()[-1]})") from None
            yield Frame(index, float(self.times_s[index]), image, Path(path).name,
                        None if image is not None else "unreadable")

    def _video(self, gray: bool, luma: Optional[LumaPlan] = None) -> Iterator[Frame]:
        capture = _open_capture(self.paths[0])
        clock = _ContainerClock(self.fps_nominal)
        count = 0
        try:
            with _luma_reading(capture, luma) as reading:
                for frame in decode_frames(capture, clock, 0, None, gray, reading):
                    count += 1
                    yield frame
        finally:
            capture.release()
        if count == 0:
            raise InputError(f"{self.paths[0]}: no frame could be decoded")
        if clock.fallback and clock.warning not in self.warnings:
            self.warnings.append(clock.warning)
            # without a frame rate the times are frame numbers, which the engines that need time refuse
            self.timestamps_source = "frame rate" if clock.fps else "frame index"
        self.note_non_increasing(clock.non_increasing)

    def note_non_increasing(self, count: int) -> None:
        skipped = f"{count} frame(s) skipped: container time not increasing"
        if count and skipped not in self.warnings:
            self.warnings.append(skipped)


def decode_frames(capture: cv2.VideoCapture, clock: _ContainerClock, first_index: int, stop: Optional[int],
                  gray: bool, luma: Optional[LumaReading] = None) -> Iterator[Frame]:
    """Frames first_index, first_index + 1, ... (up to stop, or the end) from a capture standing
    at first_index, with their times from `clock`; luma: the capture gives luma planes (_luma_reading)."""
    index = first_index
    while (stop is None or index < stop) and capture.grab():
        time_s = clock.time_of(index, capture.get(cv2.CAP_PROP_POS_MSEC))
        if time_s is None:
            yield Frame(index, float("nan"), None, f"frame {index}", "bad_timestamp")
        else:
            image = _retrieve(capture, gray, luma)
            if image is None:
                yield Frame(index, time_s, None, f"frame {index}", "unreadable")
            else:
                yield Frame(index, time_s, image, f"frame {index}")
        index += 1


def _retrieve(capture: cv2.VideoCapture, gray: bool, luma: Optional[LumaReading] = None) -> Optional[np.ndarray]:
    """The grabbed frame (grey with gray), or None when it cannot be read."""
    ok, image = capture.retrieve()
    if not ok or image is None:
        return None
    if luma is not None:
        return luma.grey(image)
    if gray and image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


class VideoSegment:
    """Frames start .. stop - 1 of a video file (stop None: to the end) decoded after a frame seek,
    for a worker that decodes its own part of a video. OpenCV's seek may land on another frame
    (inter-frame codecs, variable frame rates), so the caller verifies: `first` is the (time,
    digest of the grey pixels) of the first frame decoded here, `after` that of frame `stop`
    decoded on from here (None at the end); segment k is where it claims when its `first` equals
    segment k-1's `after` (which segment 0, decoded from the file's start, vouches for by induction).
    last_time_s is the clock's last accepted time, against which the next segment's first time
    must increase, as in one sequential pass."""

    def __init__(self, path, fps: Optional[float], start: int, stop: Optional[int],
                 decoder_threads: Optional[int] = None, luma: Optional[LumaPlan] = None):
        self.path, self.fps, self.start, self.stop = path, fps, start, stop
        self.decoder_threads = decoder_threads   # FFmpeg's (None: its default, one per core)
        self.luma = luma                          # grey frames from the luma plane (FrameSource.luma_plan)
        self.first: Optional[tuple] = None
        self.after: Optional[tuple] = None
        self.last_time_s: Optional[float] = None
        self.non_increasing = 0
        self.no_container_times = False

    def frames(self, gray: bool = True) -> Iterator[Frame]:
        capture = _open_capture(self.path, decoder_threads=self.decoder_threads)
        clock = _ContainerClock(self.fps)
        try:
            if self.start > 0 and not capture.set(cv2.CAP_PROP_POS_FRAMES, self.start):
                return  # first stays None: not verifiable
            with _luma_reading(capture, self.luma if gray else None) as luma:
                for frame in decode_frames(capture, clock, self.start, self.stop, gray, luma):
                    if frame.index == self.start and frame.image is not None:
                        self.first = (frame.time_s, frame_digest(frame.image))
                    yield frame
                if self.stop is not None and capture.grab():
                    image = _retrieve(capture, gray, luma)
                    if image is not None:
                        self.after = (capture.get(cv2.CAP_PROP_POS_MSEC) * 1e-3, frame_digest(image))
                    else:
                        self.after = (float("nan"), "unreadable")
        finally:
            capture.release()
            self.last_time_s, self.non_increasing, self.no_container_times = clock.last, clock.non_increasing, clock.fallback


def frame_digest(image: np.ndarray) -> str:
    """A short hash of a frame's pixels and shape (tells decoded frames apart)."""
    digest = hashlib.blake2b(np.ascontiguousarray(image).data, digest_size=16)
    digest.update(repr(image.shape).encode())
    return digest.hexdigest()


# Grey frames from the decoder's luma plane (docs/formulation.md §16). With CAP_PROP_CONVERT_RGB off,
# OpenCV's FFmpeg reader returns the decoded picture's first plane as 8-bit. For 8-bit YUV that is luma,
# the grey image without the YUV -> BGR -> grey round trip (0.47 of 0.95 CPU ms a 640x480 MPEG-4 frame);
# for 10-bit or packed formats it is not an image at all. So a video uses it only when its first frame's
# plane, as is or stretched from limited range (16-235, which OpenCV's BGR conversion stretches to
# 0-255), matches OpenCV's BGR -> grey of that frame, and every capture checks the decoder's format.
LIMITED_TO_FULL_RANGE = np.clip(np.round((np.arange(256) - 16) * 255.0 / 219.0), 0, 255).astype(np.uint8)
# The match: mean and 99th-percentile |difference| in grey levels at most these (colour rounding and
# clipping: 0.2-1.3 mean, p99 2-5 on phone H.264, MJPEG and saturated test patterns; a 10-bit or packed
# plane ~100), and the other mapping's mean at least LUMA_MARGIN worse (else the range is ambiguous).
LUMA_MEAN_MAX, LUMA_P99_MAX, LUMA_MARGIN = 2.5, 10.0, 1.0


@dataclass(frozen=True)
class LumaPlan:
    """How a video's grey frames come from its luma plane: the decoder's pixel format that was
    checked (OpenCV's FourCC code), the frame size (w, h), and whether the plane is limited range."""

    pixel_format: int
    frame_size: tuple
    limited_range: bool


class LumaReading:
    """A capture that gives luma planes (_luma_reading): each retrieved plane made the grey frame."""

    def __init__(self, plan: LumaPlan):
        self.limited_range = plan.limited_range

    def grey(self, plane: np.ndarray) -> np.ndarray:
        return stretch_limited_range(plane) if self.limited_range and plane.ndim == 2 else plane


def stretch_limited_range(plane: np.ndarray) -> np.ndarray:
    """LIMITED_TO_FULL_RANGE applied to an 8-bit plane: addWeighted's saturating rounding gives the
    table's values (no fraction lies within 0.002 of a half) in 0.11 ms a 640x480 frame; cv2.LUT takes 0.26."""
    return cv2.addWeighted(plane, 255.0 / 219.0, plane, 0.0, -16.0 * 255.0 / 219.0)


def luma_plan(path) -> Optional[LumaPlan]:
    """Whether (and how) a video's grey frames can come from its luma plane, from its first frame;
    None when they cannot (then through BGR). Remembered per file (path, size, modification time)."""
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return _luma_plan(str(path), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _luma_plan(path: str, size: int, mtime_ns: int) -> Optional[LumaPlan]:
    del size, mtime_ns   # the cache key
    try:
        bgr_capture = _open_capture(path)
    except InputError:
        return None
    try:
        pixel_format = int(bgr_capture.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT))
        ok, bgr = bgr_capture.read()
    finally:
        bgr_capture.release()
    if not ok or bgr is None or bgr.ndim != 3 or bgr.dtype != np.uint8:
        return None
    frame_size = (bgr.shape[1], bgr.shape[0])
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    del bgr   # a frame at a time: memory does not depend on the frame count or the check
    capture = _open_capture(path)
    try:
        with _luma_reading(capture, LumaPlan(pixel_format, frame_size, False)) as luma:
            ok, plane = capture.read() if luma is not None else (False, None)
    finally:
        capture.release()
    if not ok or plane is None or plane.ndim != 2 or plane.dtype != np.uint8 or plane.shape != grey.shape:
        return None
    errors = {limited: _difference_levels(stretch_limited_range(plane) if limited else plane, grey)
              for limited in (False, True)}
    limited = errors[True][0] < errors[False][0]
    mean, p99 = errors[limited]
    if mean > LUMA_MEAN_MAX or p99 > LUMA_P99_MAX or errors[not limited][0] - mean < LUMA_MARGIN:
        return None
    return LumaPlan(pixel_format, frame_size, limited)


def _difference_levels(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Mean and 99th percentile of |a - b| (8-bit images), from a histogram: no wide copies."""
    counts = cv2.calcHist([cv2.absdiff(a, b)], [0], None, [256], [0, 256]).ravel().astype(np.float64)
    levels = np.arange(counts.size)
    total = counts.sum()
    return float(counts @ levels / total), float(np.searchsorted(np.cumsum(counts), 0.99 * total))


_quiet_lock = threading.Lock()
_quiet_readers = 0
_quiet_saved_level: Optional[int] = None


@contextlib.contextmanager
def _luma_reading(capture: cv2.VideoCapture, plan: Optional[LumaPlan]) -> Iterator[Optional[LumaReading]]:
    """With a plan whose pixel format this capture's decoder has: the capture switched to luma planes
    (before its first retrieve) and OpenCV's per-frame warning about them off meanwhile; yields the
    LumaReading, or None (the capture gives BGR as usual)."""
    global _quiet_readers, _quiet_saved_level
    if plan is None or int(capture.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT)) != plan.pixel_format \
            or not capture.set(cv2.CAP_PROP_CONVERT_RGB, 0):
        yield None
        return
    with _quiet_lock:   # OpenCV's log level is global: the first reader lowers it, the last restores it
        if _quiet_readers == 0:
            _quiet_saved_level = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        _quiet_readers += 1
    try:
        yield LumaReading(plan)
    finally:
        with _quiet_lock:
            _quiet_readers -= 1
            if _quiet_readers == 0 and _quiet_saved_level is not None:
                cv2.utils.logging.setLogLevel(_quiet_saved_level)


class _ContainerClock:
    """Frame times from CAP_PROP_POS_MSEC: checked to increase; index / fps if all are 0."""

    def __init__(self, fps: Optional[float]):
        self.fps = fps if fps and np.isfinite(fps) and fps > 0 else None
        self.fallback = False
        self.last: Optional[float] = None
        self.non_increasing = 0
        self.warning = ""

    def time_of(self, index: int, pos_msec: float) -> Optional[float]:
        if index == 1 and self.last == 0.0 and pos_msec == 0.0:
            # OpenCV reports 0 for frames without a presentation time: the container has none.
            self.fallback = True
            rate = f"{self.fps:g} fps" if self.fps else "1 fps (unknown frame rate)"
            self.warning = f"the video has no frame timestamps; using frame index / {rate}"
        if self.fallback:
            self.last = index / (self.fps or 1.0)
            return self.last
        time_s = pos_msec * 1e-3
        if not np.isfinite(time_s) or (self.last is not None and time_s <= self.last):
            self.non_increasing += 1
            return None
        self.last = time_s
        return time_s


def _open_capture(path, decoder_threads: Optional[int] = None) -> cv2.VideoCapture:
    """VideoCapture with FFmpeg, without console noise: problems become our InputError; FFmpeg's
    own messages stay off unless OPENCV_FFMPEG_LOGLEVEL is set (read when FFmpeg starts).
    decoder_threads: FFmpeg's decoding threads (None: its default, one per core)."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # "can't capture by name" warnings
    try:
        params = [] if decoder_threads is None else [cv2.CAP_PROP_N_THREADS, int(decoder_threads)]
        capture = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG, params)
    finally:
        cv2.utils.logging.setLogLevel(level)
    if not capture.isOpened():
        capture.release()
        raise InputError(f"{path}: cannot open as a video (not a video file, or a codec FFmpeg lacks)")
    return capture


def _natural_key(path) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", Path(path).name)]


def _is_image(path) -> bool:
    return Path(path).suffix.lower() in IMAGE_EXTENSIONS


# Plausible frame intervals of a video, 1 ms to 1 s (1000 to 1 fps): the unit of a timestamps
# file is the one that puts its median frame interval in this range (EuRoC writes nanoseconds).
MIN_FRAME_INTERVAL_S, MAX_FRAME_INTERVAL_S = 1e-3, 1.0
TIME_UNITS = (("seconds", 1), ("milliseconds", 10 ** 3), ("microseconds", 10 ** 6), ("nanoseconds", 10 ** 9))
MAX_ABS_TIME_S = 1e10   # about 300 years: larger is not a time of day or since an epoch


def _time_value(text: str):
    """An int when the text is one (nanoseconds since an epoch need all 19 digits), else a float."""
    return int(text) if re.fullmatch(r"[-+]?\d+", text) else float(text)


def read_timestamps(path, count: int, notes: Optional[list] = None) -> np.ndarray:
    """Times (s) from a timestamps file: one number per line (blank lines and # comments skipped),
    in seconds, or in ms, us or ns when the frame rate says so (then converted, with a line in
    `notes`); InputError naming the file and the reason otherwise."""
    values = []
    for number, line in enumerate(Path(path).read_text(errors="replace").splitlines(), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            values.append(_time_value(text.split()[0].rstrip(",")))
        except (ValueError, OverflowError):
            raise InputError(f"{path}:{number}: not a time in seconds: {line.strip()[:40]!r}") from None
    if len(values) != count:
        raise InputError(f"{path}: {len(values)} timestamps for {count} images (need one per image)")
    raw = np.asarray([float(v) for v in values], dtype=np.float64)
    if not np.all(np.isfinite(raw)) or np.any(np.diff(raw) <= 0):
        raise InputError(f"{path}: timestamps must be finite and strictly increasing")
    unit, divisor = TIME_UNITS[0]
    if count > 1:
        interval = float(np.median(np.diff(raw)))
        fitting = [(name, div) for name, div in TIME_UNITS
                   if MIN_FRAME_INTERVAL_S <= interval / div <= MAX_FRAME_INTERVAL_S]
        if not fitting:
            raise InputError(f"{path}: the median interval between timestamps is {interval:.6g}, which is no "
                             f"frame rate of 1 to 1000 fps in seconds, ms, us or ns (frame intervals 1 ms to 1 s)")
        unit, divisor = fitting[0]
    times = np.asarray([v / divisor for v in values], dtype=np.float64)
    if np.max(np.abs(times)) > MAX_ABS_TIME_S or np.any(np.diff(times) <= 0):
        raise InputError(f"{path}: timestamps up to {np.max(np.abs(times)):.6g} s cannot be told apart "
                         f"(at most {MAX_ABS_TIME_S:g} s)")
    if divisor != 1 and notes is not None:
        notes.append(f"{path}: the timestamps are in {unit} (a frame every {np.median(np.diff(times)) * 1e3:.4g} ms); "
                     "converted to seconds")
    return times


def open_source(source: Union[str, Path, Sequence]) -> FrameSource:
    """A video file, an image folder, an image file, a glob pattern, or a list of image files."""
    checks.source(source, "source")
    if isinstance(source, (str, os.PathLike)):
        items = [source]
    else:
        items = list(source)
    if not items:
        raise InputError("no input images or video given")
    paths: list[Path] = []
    for item in items:
        path = Path(item)
        if not path.exists() and any(ch in str(item) for ch in "*?["):
            matches = sorted(glob.glob(str(item)), key=_natural_key)
            if not matches:
                raise InputError(f"no files match {item}")
            paths.extend(Path(m) for m in matches)
        elif not path.exists():
            raise InputError(f"not found: {item}")
        else:
            paths.append(path)
    if len(paths) == 1 and paths[0].is_dir():
        return _folder(paths[0])
    if len(paths) == 1 and not _is_image(paths[0]):
        return _video_source(paths[0])
    for path in paths:
        if path.is_dir():
            raise InputError(f"{path}: give one folder, one video, or image files — not a mix")
        if not _is_image(path):
            raise InputError(f"{path}: not an image ({', '.join(IMAGE_EXTENSIONS)}); a video must come alone")
    return FrameSource("images", paths, "frame index", len(paths), None, np.arange(len(paths), dtype=np.float64))


def _folder(folder: Path) -> FrameSource:
    images = sorted((p for p in folder.iterdir() if p.is_file() and _is_image(p)), key=_natural_key)
    if not images:
        raise InputError(f"{folder}: no images ({', '.join(IMAGE_EXTENSIONS)}) in the folder")
    stamps = folder / TIMESTAMPS_FILE
    if stamps.is_file():
        notes: list = []
        times = read_timestamps(stamps, len(images), notes)
        return FrameSource("images", images, "timestamps file", len(images), None, times, notes)
    return FrameSource("images", images, "frame index", len(images), None, np.arange(len(images), dtype=np.float64))


def video_bits_per_pixel(source) -> Optional[float]:
    """The bitrate of a video file per pixel and frame (bitrate / (width · height · fps)), from its
    container (OpenCV's CAP_PROP_BITRATE, which includes any audio: a few % high); None for image
    sequences or when the container does not say."""
    path = Path(source) if isinstance(source, (str, Path)) else None
    if path is None or not path.is_file() or _is_image(path):
        return None
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            return None
        kbit_s, fps = capture.get(cv2.CAP_PROP_BITRATE), capture.get(cv2.CAP_PROP_FPS)
        pixels = capture.get(cv2.CAP_PROP_FRAME_WIDTH) * capture.get(cv2.CAP_PROP_FRAME_HEIGHT)
    finally:
        capture.release()
    if not (kbit_s > 0 and fps > 0 and pixels > 0 and np.isfinite(kbit_s * fps * pixels)):
        return None
    return float(kbit_s * 1e3 / (pixels * fps))


def _video_source(path: Path) -> FrameSource:
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    capture = _open_capture(path)
    try:
        count = capture.get(cv2.CAP_PROP_FRAME_COUNT)
        fps = capture.get(cv2.CAP_PROP_FPS)
    finally:
        capture.release()
    count = int(count) if count and np.isfinite(count) and count > 0 else None
    fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else None
    return FrameSource("video", [path], "container", count, fps)


@dataclass
class GrayFrames:
    """The readable frames of a video or image folder: ``frames`` yields (time s, grayscale image)."""

    frames: Iterator[tuple[float, np.ndarray]]
    image_size: tuple[int, int]
    timestamps_from: str                 # how the times were obtained (rscalib.io.video.FrameSource)
    frame_count_estimate: Optional[int]


def read_gray_frames(source) -> GrayFrames:
    """Open a video file or image folder (:func:`rscalib.io.video.open_source`); its image size is
    that of the first readable frame. Unreadable frames are left out."""
    opened = open_source(source)
    check_source_memory(opened)   # from the headers: a huge frame is refused before it is decoded
    frames = opened.frames(gray=True)
    first = next(frames, None)
    while first is not None and first.image is None:
        first = next(frames, None)
    if first is None:
        raise InputError(f"{source}: no readable frames")
    height, width = first.image.shape[:2]

    def readable():
        yield first.time_s, first.image
        for frame in frames:
            if frame.image is not None:
                yield frame.time_s, frame.image

    return GrayFrames(readable(), (width, height), opened.timestamps_source, opened.frame_count_estimate)
