"""`rscalib batch` throughput: videos per minute on a LocalCluster of 1 and of 2 workers (issue 18),
and the per-job cost (wall, CPU, peak memory, bytes written) that docs/scale.md plans 10 000 videos with.

    .venv/bin/python benchmarks/bench_batch.py [--videos 60] [--workers 1 2] [--work DIR]

Renders --videos line-delay videos (320x240, 2 s, 30/25/60 fps: three camera modes, fixed seeds), writes
one manifest, then runs `rscalib batch` on it once per worker count, each time into a new folder with
an empty detection cache (no run reuses another's detections). The machine is shared: the 1-minute load
average is sampled every second during each run and reported with it (timings are upper bounds when
others are busy; a job's CPU seconds are not affected). Writes benchmarks/results/bench_batch.json.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import _common  # noqa: E402  (benchmarks/_common.py: machine record, results file)

RESULTS = Path(__file__).resolve().parent / "results" / "bench_batch.json"
MODES = [("320x240@30", 30, "30us"), ("320x240@25", 25, "20us"), ("320x240@60", 60, "15us")]


def rscalib_cli(args, env=None, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rscalib", *map(str, args)], env=env, capture_output=True,
                          text=True, **kwargs)


def render(data: Path, videos: int) -> Path:
    """The videos (skipped when already rendered) and their manifest."""
    def one(k: int) -> str:
        mode, fps, delay = MODES[k % len(MODES)]
        out = data / f"v{k:03d}"
        if not (out / "video.avi").is_file():
            done = rscalib_cli(["simulate", "--out", out, "--size", "320x240", "--duration", "2", "--fps", fps,
                                "--line-delay", delay, "--seed", 1000 + k, "--supersample", "1", "--workers", "1",
                                "--quiet"])
            if done.returncode:
                raise SystemExit(f"simulate failed: {done.stderr}")
        return f"v{k:03d},linedelay,v{k:03d}/video.avi,{mode},v{k:03d}/target.yaml,v{k:03d}/camera.yaml\n"

    with ThreadPoolExecutor(os.cpu_count() or 2) as pool:
        rows = list(pool.map(one, range(videos)))
    manifest = data / "manifest.csv"
    manifest.write_text("id,command,input,mode,target,camera\n" + "".join(rows))
    return manifest


def folder_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def run(manifest: Path, out: Path, workers: int) -> dict:
    """One batch run; wall time, load during it, and the per-job numbers from its store."""
    shutil.rmtree(out, ignore_errors=True)
    env = {**os.environ, "RSCALIB_CACHE_DIR": str(out.parent / f"{out.name}-cache")}
    shutil.rmtree(env["RSCALIB_CACHE_DIR"], ignore_errors=True)
    loads, running = [], threading.Event()
    running.set()

    def sample() -> None:
        while running.is_set():
            loads.append(os.getloadavg()[0])
            time.sleep(1.0)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    started = time.monotonic()
    done = rscalib_cli(["batch", manifest, "--out", out, "--workers", workers], env=env)
    wall_s = time.monotonic() - started
    running.clear()
    sampler.join()
    if done.returncode:
        raise SystemExit(f"batch failed ({done.returncode}): {done.stderr[-2000:]}")
    with sqlite3.connect(str(out / "results.sqlite")) as db:
        jobs = db.execute("SELECT status, wall_time_s, cpu_time_s, peak_memory_mb FROM jobs").fetchall()
    videos = len(jobs)
    job_wall = [j[1] for j in jobs]
    job_cpu = [j[2] for j in jobs]
    return {"workers": workers, "videos": videos, "wall_s": wall_s, "videos_per_min": 60 * videos / wall_s,
            "statuses": {s: sum(1 for j in jobs if j[0] == s) for s in {j[0] for j in jobs}},
            "job_wall_s_median": statistics.median(job_wall), "job_cpu_s_median": statistics.median(job_cpu),
            "job_cpu_s_mean": statistics.fmean(job_cpu), "cpu_s_total": sum(job_cpu),
            "job_peak_memory_mb_max": max(j[3] for j in jobs),
            "job_peak_memory_mb_median": statistics.median(j[3] for j in jobs),
            # what the batch adds beyond its jobs: cluster start, scheduling, the driver's store and summary
            "overhead_s": wall_s - sum(job_wall) / workers,
            "load_1min_mean": statistics.fmean(loads) if loads else None, "load_1min_max": max(loads, default=None),
            "bytes_per_job_folder": folder_bytes(out / "jobs") / videos, "bytes_per_log": folder_bytes(out / "logs") / videos,
            "store_bytes": (out / "results.sqlite").stat().st_size, "index_bytes": (out / "index.html").stat().st_size}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=int, default=60)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--work", type=Path, default=Path("/tmp/rscalib_bench_batch"), help="scratch folder (kept)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    info = _common.machine_info()
    args.work.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    manifest = render(args.work / "data", args.videos)
    render_s = time.monotonic() - started
    print(f"rendered {args.videos} videos in {render_s:.0f} s (load {os.getloadavg()[0]:.1f})")
    rows = []
    for workers in args.workers:
        row = run(manifest, args.work / f"batch-{workers}w", workers)
        rows.append(row)
        print(f"{workers} worker(s): {row['videos_per_min']:.1f} videos/min ({row['wall_s']:.0f} s), job CPU median "
              f"{row['job_cpu_s_median']:.2f} s, load {row['load_1min_mean']:.1f}")
    table = ["| workers | videos | wall (s) | videos/min | job wall median (s) | job CPU median (s) | "
             "peak memory max (MB) | batch overhead (s) | load avg (mean / max) |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for r in rows:
        table.append(f"| {r['workers']} | {r['videos']} | {r['wall_s']:.0f} | {r['videos_per_min']:.1f} | "
                     f"{r['job_wall_s_median']:.2f} | {r['job_cpu_s_median']:.2f} | {r['job_peak_memory_mb_max']:.0f} | "
                     f"{r['overhead_s']:.1f} | {r['load_1min_mean']:.1f} / {r['load_1min_max']:.1f} |")
    text = "\n".join(table)
    print(text)
    settings = {"videos": args.videos, "video": "320x240, 2 s, supersample 1, modes " + ", ".join(m[0] for m in MODES),
                "command": "linedelay (defaults)", "render_s": render_s}
    _common.write_results(args.out, "bench_batch", info, settings, rows, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
