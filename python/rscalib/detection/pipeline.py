"""Detection over a whole video or image sequence: decoding here, detection in a pool of
worker processes, accepted detections as Observations, drops counted by reason, a cache."""
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
from typing import Iterator, Optional, Sequence, Union

import cv2
import numpy as np

from .._progress import Progress
from ..io.limits import bounded_workers, usable_cores
from ..io.targets import Target, load_target
from ..io.video import FrameSource, open_source
from ..observations import Observations
from .cache import default_cache_dir, load_cache, save_cache
from .detectors import DETECTOR_VERSION, DROP_REASONS, DetectOptions, Detector, FrameDetection
from .result import DetectionResult
from .tracking import RunDetector, detect_run, run_length


def detect_video(source: Union[str, Path, Sequence], target: Union[Target, str, Path], *,
                 workers: Optional[int] = None, cache: bool = True, cache_dir: Union[str, Path, None] = None,
                 progress: bool = True, options: Optional[DetectOptions] = None) -> DetectionResult:
    """Detect `target` in every frame of a video, an image folder (file-name order, optional
    timestamps.txt) or a list of image files.

    workers: processes (default: the usable cores; in this process for under 64 frames). The
    video is decoded here, in a thread, and streamed to the workers in runs of consecutive
    frames (checkerboards are tracked within a run: tracking.py) with a bounded queue, so memory
    does not grow with its length; the result does not depend on the number of workers. Workers are spawned (not forked), so a calling script needs the usual
    `if __name__ == "__main__":` guard.
    cache: reuse / store the result under cache_dir (default_cache_dir()), keyed by the hash of
    the source's bytes, the target definition, the options and DETECTOR_VERSION."""
    if not isinstance(target, Target):
        target = load_target(target)
    options = options or DetectOptions()
    frames = open_source(source)
    workers = bounded_workers(frames, workers)  # frame sizes from the headers: refused or bounded before decoding
    started = time.perf_counter()
    cache_file = None
    cache_problems: list = []   # a bad cache file: one line each, reported with the result
    if cache:
        key = hashlib.sha256("\n".join([frames.content_hash(), target.fingerprint(), options.fingerprint(),
                                        DETECTOR_VERSION]).encode()).hexdigest()[:32]
        cache_file = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        cache_file = cache_file / f"{key}.npz"
        cached = load_cache(cache_file, target, cache_problems)
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
                                   initializer=_worker_init, initargs=(target, options, os.getpid()))
    # runs of consecutive frames, each tracked within itself (tracking.py): a worker takes whole
    # runs; in this process they stream through a RunDetector (the same detections)
    run_frames = run_length(target, options)
    if pool is None:
        detector = RunDetector(Detector(target, options), run_frames)
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
            record(info, detection)

    try:
        with Progress(progress, estimate, f"detecting {target.target_type}") as bar:
            decoded = frames.frames(gray=True)
            if pool is not None:  # decode while the workers detect; in-process, one frame at a time
                decoded = _decoded_ahead(decoded, run_frames)
            for frame in decoded:
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
                    record(info, detector.detect(frame.image, frame.index))
                else:
                    run.append((info, frame.image))
                    if len(run) == run_frames:
                        submit_run()
                    while len(pending) > max_pending:
                        record_run(pending.popleft())
                bar.update(state["total"] - len(run) - run_frames * len(pending))
            if run:
                submit_run()
            while pending:
                record_run(pending.popleft())
            bar.update(state["total"])
    except BaseException:
        if pool is not None:  # interrupted (Ctrl-C, SIGTERM) or failed: stop the workers now, not after their frames
            stop_workers(pool)
            pool = None
        raise
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
