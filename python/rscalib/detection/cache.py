"""The detection cache: one .npz per (source bytes, target, options, detector version)."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError
from ..io.targets import Target
from ..observations import Observations
from .detectors import DETECTOR_VERSION
from .result import DetectionResult


def default_cache_dir() -> Path:
    """$RSCALIB_CACHE_DIR, else $XDG_CACHE_HOME/rscalib/detections, else ~/.cache/rscalib/detections."""
    if os.environ.get("RSCALIB_CACHE_DIR"):
        return Path(os.environ["RSCALIB_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rscalib" / "detections"


def save_cache(path: Path, result: DetectionResult) -> None:
    meta = {"frames_total": result.frames_total, "dropped": result.dropped, "image_size": list(result.image_size),
            "timestamps": result.timestamps, "warnings": result.warnings, "frame_labels": result.frame_labels,
            "detector_version": DETECTOR_VERSION}
    obs = result.observations
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, frame_times_s=obs.frame_times_s, frame_index=obs.frame_index, point_id=obs.point_id,
                 uv=obs.uv, frame_numbers=result.frame_numbers, blur_px=result.blur_px,
                 meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
        os.replace(tmp, path)  # atomic: a concurrent reader never sees half a file
    except OSError:
        pass  # a cache that cannot be written only costs time


def load_cache(path: Path, target: Target) -> Optional[DetectionResult]:
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            meta = json.loads(bytes(data["meta"]).decode())
            obs = Observations(data["frame_times_s"], data["frame_index"], data["point_id"], data["uv"],
                               target.points_m, tuple(meta["image_size"]))
            return DetectionResult(obs, int(meta["frames_total"]), obs.num_frames, dict(meta["dropped"]), True,
                                   tuple(meta["image_size"]), data["frame_numbers"].astype(np.int64),
                                   list(meta["frame_labels"]), data["blur_px"].astype(np.float64),
                                   meta["timestamps"], list(meta["warnings"]))
    except (OSError, ValueError, KeyError, InputError):
        return None  # unreadable or stale: detect again
