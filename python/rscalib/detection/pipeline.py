"""Detection over a whole video or image sequence: worker processes that decode their own
segments of a video (or frames decoded here and shipped to them), accepted detections as
Observations, drops counted by reason, a cache."""
from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import queue
import signal
import sys
import threading
import time
from collections import deque
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence, Union

import cv2
import numpy as np

from .. import checks
from .._progress import Progress, ProgressArg
from ..io.limits import bounded_workers, source_frame_size, usable_cores
from ..io.targets import Target, load_target
from ..io.video import FrameSource, LumaPlan, VideoSegment, open_source
from ..observations import Observations
from .cache import default_cache_dir, load_cache, save_cache
from .detectors import DETECTOR_VERSION, DROP_REASONS, Detector, FrameDetection
from .options import DetectOptions
from .result import DetectionResult
from .tracking import RunDetector, detect_run, run_length

# on_frames(start, times_s, point_ids, uvs) of detect_video
FramesCallback = Callable[[int, list, list, list], None]


def detect_video(source: Union[str, Path, Sequence], target: Union[Target, str, Path],
                 options: Optional[DetectOptions] = None, *, progress: ProgressArg = True,
                 alongside: Optional[Callable[[], None]] = None,
                 on_frames: Optional[FramesCallback] = None) -> DetectionResult:
    """Detect `target` in every frame of a video, an image folder (file-name order, optional
    timestamps.txt) or a list of image files.

    options: DetectOptions (None: the defaults): the detector's settings, and how it runs.
    options.workers: processes (default: the usable cores; in this process for under 64 frames). A video
    of at least 4 runs per worker is cut into segments of whole runs (checkerboards are tracked
    within a run: tracking.py) that the workers decode themselves (segment_plan); each segment's
    seek is verified against the frame the segment before it decoded next, and if one is not,
    the video is decoded here instead. Otherwise (image sequences, short videos) frames are
    decoded here, in a thread, and streamed to the workers in runs with a bounded queue. Either
    way memory does not grow with the length, and the result is that of one sequential pass,
    whatever the number of workers. Workers are spawned (not forked), so a calling script needs
    the usual `if __name__ == "__main__":` guard.
    options.cache: reuse / store the result under options.cache_dir (default_cache_dir()), keyed by
    the hash of the source's bytes, the target definition, the detector's settings and DETECTOR_VERSION.
    alongside: called once in this process while the workers start (their start-up, ~0.3 s of imports
    each, runs on the other cores meanwhile): before the first frame is detected, or, when the workers
    decode their own segments, once the first segments are handed to them; an exception it raises
    stops the workers and is raised here (e.g. the line-delay job's check of the target file).
    on_frames(start, times_s, point_ids, uvs): called in this process as accepted detections arrive, in
    frame order, while the workers detect the next ones: frames start, start + 1, ... of the accepted
    frames (their times, and a point-id and a uv array each). A start below the frames already given
    means detection began again (a segment that could not be verified): those after it are replaced.
    Not called for a cached result (e.g. the line-delay job's per-frame poses, computed meanwhile)."""
    checks.source(source, "source")
    checks.optional_callable(alongside, "alongside")
    checks.optional_callable(on_frames, "on_frames")
    checks.instance(target, "target", (str, os.PathLike, Target), "a target file or an rscalib.Target")
    options = DetectOptions() if options is None else options
    checks.instance(options, "options", (DetectOptions,), "an rscalib.DetectOptions or None")
    checks.progress(progress)
    if not isinstance(target, Target):
        target = load_target(target)
    frames = open_source(source)
    workers = bounded_workers(frames, options.workers)  # frame sizes from the headers: refused or bounded before decoding
    frame_size, _ = source_frame_size(frames)   # a run's frames are bounded in bytes (tracking.run_length)
    started = time.perf_counter()
    cache_file = None
    cache_problems: list = []   # a bad cache file: one line each, reported with the result
    if options.cache:
        key = hashlib.sha256("\n".join([frames.content_hash(), target.fingerprint(), options.fingerprint(),
                                        DETECTOR_VERSION]).encode()).hexdigest()[:32]
        cache_file = Path(options.cache_dir) if options.cache_dir is not None else default_cache_dir()
        cache_file = cache_file / f"{key}.npz"
        cached = load_cache(cache_file, target, cache_problems)
        if cached is not None:
            if alongside is not None:
                alongside()
            cached.detect_time_s = time.perf_counter() - started
            return cached
    try:
        result = _detect_frames(frames, target, options, workers, progress, alongside, on_frames, frame_size)
    except BrokenProcessPool:
        # e.g. a worker killed for memory, or a __main__ that spawn cannot re-import
        result = _detect_frames(open_source(source), target, options, 1, progress, on_frames=on_frames,
                                frame_size=frame_size)
        result.warnings.append("detection workers failed; detected in one process instead")
    result.detect_time_s = time.perf_counter() - started
    if cache_file is not None:
        save_cache(cache_file, result)
    result.warnings[:0] = cache_problems
    return result


_WORKER_DETECTOR: Optional[Detector] = None
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent_pid: int) -> None:
    """In a worker: Linux kills it when the process that started it dies (also by SIGKILL), so no
    worker outlives an interrupted or killed run; elsewhere a no-op."""
    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def _worker_init(target: Target, options: DetectOptions, parent_pid: int) -> None:
    global _WORKER_DETECTOR
    die_with_parent(parent_pid)
    # Ctrl-C reaches the whole process group: the parent stops the workers, which must not print a
    # KeyboardInterrupt traceback (blocked since spawn, so also during the imports before this)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    cv2.setNumThreads(1)  # one process per core already
    _WORKER_DETECTOR = Detector(target, options)


@contextlib.contextmanager
def _sigint_blocked():
    """SIGINT blocked in this thread meanwhile (a child spawned meanwhile inherits the mask); a
    Ctrl-C that arrives meanwhile is delivered when it ends."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _worker_detect_run(images: list, indices: list) -> list:
    return detect_run(_WORKER_DETECTOR, images, indices)


# Workers decode their own segment of a video (no decoded frame is shipped) when it has at least
# this many runs per worker; a segment is SEGMENT_RUNS_PER_TASK_MAX runs at most (progress, memory).
SEGMENT_MIN_RUNS_PER_WORKER = 4
SEGMENT_RUNS_PER_TASK_MAX = 15


def segment_plan(frame_count: Optional[int], workers: int, run_frames: int) -> Optional[list]:
    """(start, stop) frame ranges, each a whole number of runs, about 4 per worker; the last open
    (stop None: to the end, the container's frame count may be off). None: too short to pay."""
    if workers < 2 or frame_count is None or frame_count < SEGMENT_MIN_RUNS_PER_WORKER * workers * run_frames:
        return None
    runs_per_task = int(np.clip(round(frame_count / (SEGMENT_MIN_RUNS_PER_WORKER * workers * run_frames)),
                                1, SEGMENT_RUNS_PER_TASK_MAX))
    step = runs_per_task * run_frames
    starts = list(range(0, frame_count, step))
    return [(start, stop) for start, stop in zip(starts, starts[1:] + [None])]


def _worker_detect_segment(path: str, fps: Optional[float], start: int, stop: Optional[int], run_frames: int,
                           decoder_threads: Optional[int] = None, luma: Optional[LumaPlan] = None) -> dict:
    """Decode frames start .. stop - 1 here and detect them as one sequential pass would: runs of
    run_frames frames by index, frames of another size than the segment's first dropped."""
    segment = VideoSegment(path, fps, start, stop, decoder_threads, luma)
    runs = RunDetector(_WORKER_DETECTOR, run_frames)
    frames, size = [], None
    for frame in segment.frames(gray=True):
        info = (frame.index, frame.time_s, frame.label)
        if frame.image is None:
            frames.append((info, frame.problem or "unreadable"))
            continue
        shape = (frame.image.shape[1], frame.image.shape[0])
        size = size or shape
        frames.append((info, runs.detect(frame.image, frame.index) if shape == size else "image_size"))
    return {"frames": frames, "size": size, "first": segment.first, "after": segment.after,
            "last_time_s": segment.last_time_s, "non_increasing": segment.non_increasing,
            "no_container_times": segment.no_container_times}


class _Collected:
    """Accepted detections and drop counts, in frame order, and the DetectionResult they make."""

    def __init__(self, on_frames: Optional[FramesCallback] = None):
        self.dropped = {reason: 0 for reason in DROP_REASONS}
        self.times, self.numbers, self.labels, self.blur, self.ids, self.uvs = [], [], [], [], [], []
        self.total = 0
        self.size = None
        self.on_frames, self.given = on_frames, 0

    def hand_on(self) -> None:
        """The accepted frames not yet given to on_frames, given."""
        if self.on_frames is not None and len(self.ids) > self.given:
            start, self.given = self.given, len(self.ids)
            self.on_frames(start, self.times[start:], self.ids[start:], self.uvs[start:])

    def record(self, info: tuple, detection: Union[FrameDetection, str]) -> None:
        """A frame's detection, or the reason it was dropped before detection."""
        if isinstance(detection, str):
            self.dropped[detection] += 1
            return
        number, time_s, label = info
        if detection.reason is not None:
            self.dropped[detection.reason] += 1
            return
        self.times.append(time_s)
        self.numbers.append(number)
        self.labels.append(label)
        self.blur.append(detection.blur_px)
        self.ids.append(detection.point_id)
        self.uvs.append(detection.uv)

    def result(self, frames: FrameSource, target: Target) -> DetectionResult:
        image_size = self.size or (0, 0)
        counts = [len(i) for i in self.ids]
        observations = Observations(
            frame_times_s=np.asarray(self.times, dtype=np.float64),
            frame_index=np.repeat(np.arange(len(self.ids)), counts),
            point_id=np.concatenate(self.ids) if self.ids else np.zeros(0, np.int64),
            uv=np.concatenate(self.uvs) if self.uvs else np.zeros((0, 2)),
            target_points=target.points_m,
            image_size=image_size,
        )
        return DetectionResult(observations, self.total, len(self.ids),
                               {k: v for k, v in self.dropped.items() if v}, False, image_size,
                               np.asarray(self.numbers, dtype=np.int64), self.labels,
                               np.asarray(self.blur, dtype=np.float64), frames.timestamps_source, list(frames.warnings))


def _detect_segments(frames: FrameSource, plan: list, pool, run_frames: int, workers: int,
                     bar, alongside: Optional[Callable[[], None]] = None,
                     on_frames: Optional[FramesCallback] = None) -> Optional[_Collected]:
    """Detection by workers that decode their own segments (plan). None when a segment cannot be
    verified to start where it claims, or the container has no frame times (the caller then
    decodes here): the result is then exactly that of one sequential pass. alongside runs here once
    the first segments are submitted: the workers start on them at once instead of after it
    (0.3 s of the 60 s speed video, docs/benchmarks.md)."""
    collected = _Collected(on_frames)
    pending: deque = deque()
    tasks = iter(plan)
    # FFmpeg's threads: the cores the workers leave (one each when they fill the machine: FFmpeg's frame
    # threads on top of busy cores cost 15-20 % more CPU for the same frames)
    decoder_threads = max(1, usable_cores() // max(1, workers))
    luma = frames.luma_plan()   # checked once here, on the first frame, for every segment
    previous, last_time_s = None, None
    non_increasing = 0
    while True:
        while len(pending) <= workers:
            task = next(tasks, None)
            if task is None:
                break
            with _sigint_blocked():
                pending.append(pool.submit(_worker_detect_segment, str(frames.paths[0]), frames.fps_nominal,
                                           task[0], task[1], run_frames, decoder_threads, luma))
        if alongside is not None:
            alongside()
            alongside = None
        if not pending:
            break
        segment = pending.popleft().result()
        if not _continues(previous, segment, last_time_s, collected.size):
            for future in pending:
                future.cancel()  # those not started yet
            return None
        collected.size = collected.size or segment["size"]
        for info, detection in segment["frames"]:
            collected.record(info, detection)
        collected.total += len(segment["frames"])
        non_increasing += segment["non_increasing"]
        last_time_s = segment["last_time_s"] if segment["last_time_s"] is not None else last_time_s
        previous = segment
        bar.update(collected.total)
        collected.hand_on()  # the workers detect on meanwhile
    if collected.total == 0:
        return None  # e.g. nothing decodable: the sequential pass reports it
    frames.note_non_increasing(non_increasing)
    return collected


def _continues(previous: Optional[dict], segment: dict, last_time_s: Optional[float], size: Optional[tuple]) -> bool:
    """Whether a segment's frames are those one sequential pass would give after the segments
    before it (previous: the last of them; last_time_s: their last accepted time; size: their
    frame size)."""
    if segment["no_container_times"]:
        return False  # times come from index / fps: the sequential pass decides that
    if segment["size"] is not None and size is not None and segment["size"] != size:
        return False
    if previous is None:
        return True
    if previous["after"] is None:
        return not segment["frames"]  # the previous segment met the end of the file
    if segment["first"] != previous["after"]:
        return False  # the seek landed elsewhere (or on an unusable frame)
    # one pass would have skipped a frame whose time does not increase
    return last_time_s is None or segment["first"][0] > last_time_s


def _start_pool(workers: int, target: Target, options: DetectOptions):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    # spawn: forking a process that already runs OpenCV's thread pool is not safe
    return ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_init, initargs=(target, options, os.getpid()))


def _worker_ready() -> None:
    """A task that only makes the pool start a worker process."""


def _detect_frames(frames: FrameSource, target: Target, options: DetectOptions, workers: Optional[int],
                   progress: bool, alongside: Optional[Callable[[], None]] = None,
                   on_frames: Optional[FramesCallback] = None, frame_size: Optional[tuple] = None) -> DetectionResult:
    estimate = frames.frame_count_estimate
    if workers is None:
        # starting a worker costs ~0.5 s, a frame 5-60 ms: short inputs are faster in-process
        workers = 1 if estimate is not None and estimate < 64 else usable_cores()
    workers = max(1, int(workers))
    main_file = getattr(sys.modules.get("__main__"), "__file__", None)
    if main_file and not os.path.exists(main_file):
        workers = 1  # a script read from stdin: spawned workers could not re-import it
    # runs of consecutive frames by index (run = index // run_frames), each tracked within itself
    # (tracking.py): a worker takes whole runs; in this process they stream through a RunDetector
    run_frames = run_length(target, options, frame_size)
    pool = _start_pool(workers, target, options) if workers > 1 else None
    detector = RunDetector(Detector(target, options), run_frames) if pool is None else None
    plan = segment_plan(estimate, workers, run_frames) if frames.kind == "video" else None
    # OpenCV's own threads, as in a worker (_worker_init): its detectors' sums run in another order on
    # another thread count, and the corners would differ in the last bits between --workers 1 and 2
    cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        if alongside is not None and not plan:
            if pool is not None:  # the pool starts a process per task while none is idle
                with _sigint_blocked():
                    for _ in range(workers):
                        pool.submit(_worker_ready)
            alongside()
        with Progress(progress, estimate, f"detecting {target.target_type}") as bar:
            collected = _detect_segments(frames, plan, pool, run_frames, workers, bar,
                                         alongside, on_frames) if plan else None
            if collected is None:
                collected = _decode_here(frames, pool, detector, run_frames, workers, bar, on_frames)
    except BaseException:
        if pool is not None:  # interrupted (Ctrl-C, SIGTERM) or failed: stop the workers now, not after their frames
            stop_workers(pool)
            pool = None
        raise
    finally:
        cv2.setNumThreads(cv_threads)
        if pool is not None:   # every task is done: the idle workers exit while the caller goes on
            pool.shutdown(wait=False, cancel_futures=True)
    return collected.result(frames, target)


def _decode_here(frames: FrameSource, pool, detector: Optional[RunDetector], run_frames: int, workers: int,
                 bar, on_frames: Optional[FramesCallback] = None) -> _Collected:
    """Decoding in this process (in a thread when there are workers), frames streamed to the
    workers in runs through a bounded queue."""
    collected = _Collected(on_frames)
    pending: deque = deque()
    run: list = []
    max_pending = 2 * workers if run_frames == 1 else workers + 1  # runs in flight: bounded memory

    def submit_run() -> None:
        infos, images = [item[0] for item in run], [item[1] for item in run]
        with _sigint_blocked():   # a worker spawned here starts with Ctrl-C blocked (see _worker_init)
            pending.append((infos, pool.submit(_worker_detect_run, images, [info[0] for info in infos])))
        run.clear()

    def record_run(item) -> None:
        infos, future = item
        for info, detection in zip(infos, future.result()):
            collected.record(info, detection)
        collected.hand_on()

    decoded = frames.frames(gray=True, luma=True)
    if pool is not None:  # decode while the workers detect; in-process, one frame at a time
        decoded = _decoded_ahead(decoded, run_frames)
    for frame in decoded:
        collected.total += 1
        if frame.image is None:
            collected.record(None, frame.problem or "unreadable")
            continue
        size = (frame.image.shape[1], frame.image.shape[0])
        if collected.size is None:
            collected.size = size
        elif size != collected.size:
            collected.record(None, "image_size")
            continue
        info = (frame.index, frame.time_s, frame.label)
        if pool is None:
            collected.record(info, detector.detect(frame.image, frame.index))
        else:
            if run and run[-1][0][0] // run_frames != frame.index // run_frames:
                submit_run()
            run.append((info, frame.image))
            while len(pending) > max_pending:
                record_run(pending.popleft())
        bar.update(collected.total - len(run) - run_frames * len(pending))
    if run:
        submit_run()
    while pending:
        record_run(pending.popleft())
    bar.update(collected.total)
    collected.hand_on()
    return collected


def stop_workers(pool, timeout_s: float = 2.0) -> None:
    """Terminate a ProcessPoolExecutor's workers at once (shutdown() would let running tasks finish)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    deadline = time.monotonic() + timeout_s
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join(1.0)


def _decoded_ahead(frames: Iterator, depth: int) -> Iterator:
    """The frames of an iterator, decoded in a thread up to `depth` frames ahead: OpenCV decodes
    without holding the GIL, so decoding overlaps detection and shipping frames to workers."""
    ready: queue.Queue = queue.Queue(maxsize=max(1, depth))
    stop = threading.Event()
    end = object()

    def put(item) -> bool:
        """Queue an item unless the consumer has stopped (then False)."""
        while not stop.is_set():
            try:
                ready.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def decode() -> None:
        try:
            for frame in frames:
                if not put(frame):
                    return
            item = end
        except BaseException as error:  # re-raised in the consumer (e.g. InputError: no frame)
            item = error
        finally:
            if hasattr(frames, "close"):
                frames.close()  # a generator stopped early releases its video capture here
        put(item)

    thread = threading.Thread(target=decode, name="rscalib-decode", daemon=True)
    thread.start()
    try:
        while True:
            item = ready.get()
            if item is end:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        thread.join()
