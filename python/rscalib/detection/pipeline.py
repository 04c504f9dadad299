"""Detection over a whole video or image sequence: decoding here, detection in a pool of
worker processes, accepted detections as Observations, drops counted by reason, a cache."""
from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import signal
import sys
import time
from collections import deque
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np

from .._progress import Progress
from ..io.targets import Target, load_target
from ..io.video import FrameSource, open_source
from ..observations import Observations
from .cache import default_cache_dir, load_cache, save_cache
from .detectors import DETECTOR_VERSION, DROP_REASONS, DetectOptions, Detector, FrameDetection
from .result import DetectionResult


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


def _worker_detect(image: np.ndarray) -> FrameDetection:
    return _WORKER_DETECTOR.detect(image)


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
    else:
        detector = Detector(target, options)
    pending: deque = deque()
    try:
        with Progress(progress, estimate, f"detecting {target.target_type}") as bar:
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
                    with _sigint_blocked():   # a worker spawned here starts with Ctrl-C blocked (see _worker_init)
                        pending.append((info, pool.submit(_worker_detect, frame.image)))
                    while len(pending) > 2 * workers:  # bounded: memory independent of length
                        record(*_result(pending.popleft()))
                bar.update(state["total"] - len(pending))
            while pending:
                record(*_result(pending.popleft()))
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


def _result(item):
    info, future = item
    return info, future.result()
