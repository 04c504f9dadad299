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
import time
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

# --------------------------------------------------------------------------------------------------
# Self-calibration runs on rendered walks (bench_selfcalib_realistic, bench_selfcalib_speed)

SELFCALIB_PARAMS = ("f", "cx", "cy", "k1", "k2")
SELFCALIB_STYLES = ("walk-forward", "look-around", "sideways-dolly")


def selfcalib_pixel_size_mm(width: int) -> float:
    """The pixel pitch of the rendered cameras: the paper's at 320 px wide, the phone's otherwise."""
    from rscalib.reference_cameras import PAPER_PIXEL_SIZE_MM, PHONE_PIXEL_SIZE_MM
    return PAPER_PIXEL_SIZE_MM if width == 320 else PHONE_PIXEL_SIZE_MM


def run_selfcalib(style: str, size: tuple[int, int], seed: int, frames: int, cache: str, rolling_shutter: str = "none",
                  tag: str = "") -> dict:
    """One rendered walk (rendered into CACHE once) through `rscalib selfcalib` in its own process: the
    row of bench_selfcalib_realistic and bench_selfcalib_speed (exit, wall, peak RSS, the estimate, its
    bounds and whether the truth is inside, the adjustment's facts)."""
    from rscalib.sim.scene_realism import render_realistic_scene

    seq = Path(cache) / f"{style}_{size[0]}x{size[1]}_s{seed}_n{frames}"
    render_s = 0.0
    if not (seq / "truth.json").exists():  # truth.json is written last
        render_s = render_realistic_scene(seq, style, size, frames, seed).elapsed_s
    truth = json.loads((seq / "truth.json").read_text())
    out = Path(cache) / f"runs{tag}" / seq.name
    cmd = [sys.executable, "-m", "rscalib", "selfcalib", str(seq), "--pixel-size-mm", str(selfcalib_pixel_size_mm(size[0])),
           "--out", str(out), "--quiet"]
    if rolling_shutter == "truth":   # as measured by `rscalib linedelay` (0.15 % median error, docs/benchmarks.md)
        cmd += ["--line-delay", repr(float(truth["line_delay_s"]))]
    log = Path(cache) / f"runs{tag}" / f"{seq.name}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rss_file = log.with_suffix(".maxrss")
    # Peak RSS through /usr/bin/time: a child forked from this (large) worker would inherit the
    # worker's high-water mark across exec (Linux keeps it), so getrusage/wait4 here overstate it.
    with open(log, "w") as sink:
        code = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", str(rss_file), *cmd], stdout=sink,
                              stderr=subprocess.STDOUT).returncode
    wall_s = time.perf_counter() - started
    stderr = log.read_text()
    row = {"style": style, "size": f"{size[0]}x{size[1]}", "seed": seed, "frames": truth["num_frames_rendered"],
           "command": " ".join(cmd), "exit": code, "wall_s": round(wall_s, 1),
           "peak_rss_mb": round(int(rss_file.read_text().split()[-1]) / 1024, 1),
           "render_s": round(render_s, 1), "textures": truth["textures"], "codec": truth["codec_used"],
           "truth": dict(zip(SELFCALIB_PARAMS, truth["camera"]["params"])), "output_tail": stderr[-400:]}
    result_path = out / "result.json"
    if result_path.exists():
        result = json.loads(result_path.read_text())
        # not determined: result.json claims no number; the estimate is kept under not_claimed
        result |= {n: v for n, v in (result.get("not_claimed") or {}).items() if result.get(n) is None}
        row["estimate"] = {n: result[n] for n in SELFCALIB_PARAMS}
        row["bounds_99"] = {n: result[f"{n}_bounds_99"] for n in SELFCALIB_PARAMS}
        row["filter_bounds_99"] = dict(zip(SELFCALIB_PARAMS, result.get("filter_bounds_99", [None] * 5)))
        row["determined"] = bool(result.get("determined"))
        row["reason"] = result.get("reason", "")
        row["gaussians_left"] = result.get("gaussians_left")
        row["frames_per_s"] = result.get("frames_per_s")
        row["inside"] = {n: bool(row["bounds_99"][n][0] <= row["truth"][n] <= row["bounds_99"][n][1]) for n in SELFCALIB_PARAMS}
        fb = row["filter_bounds_99"]
        row["inside_filter"] = {n: bool(fb[n] is not None and fb[n][0] <= row["truth"][n] <= fb[n][1]) for n in SELFCALIB_PARAMS}
        row["f_error_pct"] = 100.0 * (result["f"] / row["truth"]["f"] - 1.0)
        row["estimate_from"] = result.get("estimate_from", "filter")
        if result.get("filter"):
            row["filter_f_error_pct"] = 100.0 * (result["filter"]["f"] / row["truth"]["f"] - 1.0)
        adj = result.get("adjustment")
        if adj:   # the bundle adjustment (docs/sog.md §24), whatever the verdict
            est = dict(zip(adj["names"], adj["estimate"]))
            bb = dict(zip(adj["names"], adj["bounds_99"]))
            row["bundle"] = {n: est[n] for n in SELFCALIB_PARAMS}
            row["bundle_bounds_99"] = {n: bb[n] for n in SELFCALIB_PARAMS}
            row["inside_bundle"] = {n: bool(bb[n][0] is not None and bb[n][0] <= row["truth"][n] <= bb[n][1])
                                    for n in SELFCALIB_PARAMS}
            row["bundle_f_half_width_pct"] = 50.0 * (bb["f"][1] - bb["f"][0]) / est["f"] if bb["f"][0] else None
            row["bundle_s"] = adj.get("solve_time_s")
            row["bundle_converged"] = adj.get("converged")
            row["bundle_f_error_pct"] = 100.0 * (est["f"] / row["truth"]["f"] - 1.0)
            if adj.get("line_delay_estimated"):
                row["line_delay_s"] = {"truth": float(truth["line_delay_s"]), "bundle": est["line_delay_s"],
                                       "bounds_99": bb["line_delay_s"]}
            row["tracks"] = {k: result.get("tracks", {}).get(k) for k in ("adjustment_tracks", "adjustment_keyframes",
                                                                           "ms_per_frame_wall")}
    return row
