"""The lab's bookkeeping, for the benchmarks (benchmarks/bench_*.py) and the experiments
(experiments/exp_*.py, through experiments/_common.py): the machine record, the results file, the
commit, and what more than one benchmark needs (mpeg4). The one home of these: every results file
in benchmarks/results/ carries the same machine block and fields, whichever folder wrote it."""
from __future__ import annotations

import datetime as dt
import json
import math
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

import rscalib

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info(**extra) -> dict:
    """CPU, cores, versions and the load when the benchmark started (timings depend on it)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"usable_cores": cores, "cpu_count": os.cpu_count(), "cpu_model": cpu_model(),
            "platform": platform.platform(), "python": sys.version.split()[0], "numpy": np.__version__,
            "rscalib": rscalib.__version__, "load_average_1min_at_start": load, **extra}


def git_commit() -> str:
    """The repository's HEAD, with "+dirty" when tracked files differ from it."""
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                               capture_output=True, text=True).stdout.strip()
        return head + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def jsonable(x):
    """x with NumPy scalars and arrays as plain Python, and NaN / inf as null (valid JSON)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not math.isfinite(float(x)) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, Path):
        return str(x)
    return x


def write_results(path: Path, benchmark: str, info: dict, settings: dict, rows, table: str, **extra) -> Path:
    """The results file: name, date, commit, command line, machine, settings, any extra fields, the
    rows and the markdown table."""
    result = {"benchmark": benchmark, "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
              "git_commit": git_commit(), "command": " ".join([".venv/bin/python"] + sys.argv),
              "machine": info, "settings": settings, **extra, "results": rows, "table_markdown": table}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(jsonable(result), indent=2) + "\n")
    print(f"\nwritten {path}")
    return path


def mpeg4(folder: Path) -> Path:
    """A render's video.avi re-encoded as MPEG-4 Part 2 (OpenCV's "mp4v" writer; cached beside it):
    closer to a phone's decode cost than the lossless FFV1 render."""
    import cv2

    out = folder / "video_mp4v.mp4"
    if not out.is_file():
        capture = cv2.VideoCapture(str(folder / "video.avi"), cv2.CAP_FFMPEG)
        writer = None
        while True:
            ok, image = capture.read()
            if not ok:
                break
            gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            if writer is None:
                writer = cv2.VideoWriter(str(out), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"mp4v"), 30.0,
                                         gray.shape[::-1], False)
            writer.write(gray)
        writer.release()
        capture.release()
    return out
