"""The detection cache: one .npz per (source bytes, target, options, detector version).

A file is written under a temporary name and renamed (two runs on the same video at once each
write a whole file; the last rename wins), and carries a SHA-256 of its arrays. On load the
checksum and the arrays' consistency are checked; a file that fails is removed and reported in
one line naming it (the caller detects again), never a traceback."""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Optional

import numpy as np

from ..io.targets import Target
from ..observations import Observations
from .detectors import DETECTOR_VERSION
from .result import DetectionResult

_ARRAYS = ("frame_times_s", "frame_index", "point_id", "uv", "frame_numbers", "blur_px")


class BadCacheFile(ValueError):
    """A cache file that cannot be used; the message says why."""


def default_cache_dir() -> Path:
    """$RSCALIB_CACHE_DIR, else $XDG_CACHE_HOME/rscalib/detections, else ~/.cache/rscalib/detections."""
    if os.environ.get("RSCALIB_CACHE_DIR"):
        return Path(os.environ["RSCALIB_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rscalib" / "detections"


def arrays_checksum(arrays: dict) -> str:
    """SHA-256 over the cached arrays' names, dtypes, shapes and bytes."""
    digest = hashlib.sha256()
    for name in _ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        digest.update(a.tobytes())
    return digest.hexdigest()


def save_cache(path: Path, result: DetectionResult) -> None:
    obs = result.observations
    arrays = {"frame_times_s": np.asarray(obs.frame_times_s, np.float64),
              "frame_index": np.asarray(obs.frame_index, np.int64), "point_id": np.asarray(obs.point_id, np.int64),
              "uv": np.asarray(obs.uv, np.float64), "frame_numbers": np.asarray(result.frame_numbers, np.int64),
              "blur_px": np.asarray(result.blur_px, np.float64)}
    meta = {"frames_total": result.frames_total, "dropped": result.dropped, "image_size": list(result.image_size),
            "timestamps": result.timestamps, "warnings": result.warnings, "frame_labels": result.frame_labels,
            "detector_version": DETECTOR_VERSION, "checksum": arrays_checksum(arrays)}
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8), **arrays)
        os.replace(tmp, path)  # atomic: a concurrent reader never sees half a file
    except OSError:
        try:
            tmp.unlink()
        except OSError:
            pass
        # a cache that cannot be written only costs time


def _checked(path: Path, target: Target) -> DetectionResult:
    """The cached result, or BadCacheFile saying what is wrong with the file."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in _ARRAYS}
            meta = json.loads(bytes(data["meta"]).decode())
    except Exception as error:  # noqa: BLE001 - zip, npy and JSON readers raise many kinds
        raise BadCacheFile(f"unreadable ({type(error).__name__}: {error})") from None
    if not isinstance(meta, dict) or "checksum" not in meta:
        raise BadCacheFile("written without a checksum (an older rscalib)")
    if meta["checksum"] != arrays_checksum(arrays):
        raise BadCacheFile("its arrays do not match their checksum")
    frames = len(arrays["frame_times_s"])
    if len(arrays["frame_numbers"]) != frames or len(arrays["blur_px"]) != frames \
            or len(meta["frame_labels"]) != frames:
        raise BadCacheFile("its per-frame arrays differ in length")
    if not np.all(np.isfinite(arrays["frame_times_s"])) or not np.all(np.isfinite(arrays["uv"])):
        raise BadCacheFile("it holds NaN or infinite times or corners")
    if len(arrays["point_id"]) and (arrays["point_id"].min() < 0 or arrays["point_id"].max() >= len(target.points_m)):
        raise BadCacheFile("its point ids do not fit the target")
    size = tuple(int(v) for v in meta["image_size"])
    obs = Observations(arrays["frame_times_s"], arrays["frame_index"], arrays["point_id"], arrays["uv"],
                       target.points_m, size)   # checks lengths, ranges and increasing times (InputError)
    dropped = {str(k): int(v) for k, v in dict(meta["dropped"]).items()}
    if int(meta["frames_total"]) != obs.num_frames + sum(dropped.values()):
        raise BadCacheFile("its frame counts do not add up")
    return DetectionResult(obs, int(meta["frames_total"]), obs.num_frames, dropped, True, size,
                           arrays["frame_numbers"].astype(np.int64), [str(s) for s in meta["frame_labels"]],
                           arrays["blur_px"].astype(np.float64), str(meta["timestamps"]),
                           [str(w) for w in meta["warnings"]])


def load_cache(path: Path, target: Target, problems: Optional[list] = None) -> Optional[DetectionResult]:
    """The cached result, or None (detect again). A file that fails the checks is removed, and one
    line naming it and the reason is appended to `problems`."""
    try:
        before = path.stat()
    except OSError:
        return None
    try:
        return _checked(path, target)
    except Exception as error:  # noqa: BLE001 - a bad cache must cost time, never the run
        reason = str(error) if isinstance(error, BadCacheFile) else f"{type(error).__name__}: {error}"
    try:
        now = path.stat()
        if (now.st_ino, now.st_mtime_ns) == (before.st_ino, before.st_mtime_ns):  # not replaced meanwhile
            path.unlink()
    except OSError:
        pass
    if problems is not None:
        problems.append(f"detection cache {path} discarded: {reason}; detected again")
    return None
