"""Peak resident memory against input size (issue 14; docs/benchmarks.md, "Peak memory against input size").

Each case is one CLI command in its own process, as a user runs it:

- linedelay: `rscalib simulate` target videos (640x480, seed 7) of 5, 15 and 60 s, then
  `rscalib linedelay VIDEO --no-cache` (detection in --workers 2 processes, then the spline solve);
- selfcalib: a `rscalib simulate --scene` room walk (320x240, seed 7) of 40 s, then
  `rscalib selfcalib --no-restarts --max-frames N` for N = 100, 300, 600, 1200; the real desk video
  (../shared/data/real_selfcalib_s3phone, 640x480, 359 frames) with the restarts, as a user runs it;
  and, for lengths real footage here does not have, that video at 2x speed played forth and back
  (PNG frames and timestamps.txt at 30 fps) for 300 and 1000 frames, --no-restarts;
- detection: `rscalib intrinsics` on 4 stills of a 9x6 checkerboard (perspective views of one
  drawing) at 1000x750, 3000x2250, 6000x4500 and 10000x7500, --workers 2 --no-cache.

Memory: the largest process's peak RSS (exact: the kernel's ru_maxrss from wait4, which covers the
command and every process it waited for) and the peak of the sum over the process tree (sampled every
50 ms with psutil: detection workers run at the same time). Renders and stills are cached under
CACHE (rendering the 60 s video takes a while). Times are recorded but the machine is shared:
they are not speed results.

Usage: PYTHONPATH=python .venv/bin/python benchmarks/bench_memory.py [--cases linedelay,selfcalib,detection]
           [--cache /tmp/rscalib_bench_memory] [--out benchmarks/results/bench_memory.json]
The rows of cases not run this time are kept from an earlier --out.
Real data: $RSCALIB_SHARED_DATA, else ../shared/data beside the repository.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import psutil
from _common import machine_info, write_results

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("RSCALIB_SHARED_DATA", ROOT.parent / "shared" / "data"))
DESK = SHARED / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"
CLI = [sys.executable, "-m", "rscalib.cli"]
# The commands run this checkout's package, wherever the benchmark is started from.
CHILD_ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "python"), os.environ.get("PYTHONPATH", "")])}
VIDEO_SECONDS = (5, 15, 60)
SCENE_SECONDS = 40
SCENE_FRAMES = (100, 300, 600, 1200)
DESK_LOOP_FRAMES = (300, 1000)
STILL_SIZES = ((1000, 750), (3000, 2250), (6000, 4500), (10000, 7500))


def measure(argv: list, cwd: Path, log: Path) -> dict:
    """Run ``argv`` (output to ``log``); its exit code, the largest process's peak RSS (MiB, exact), the
    sampled peak of the process tree's summed RSS (MiB) and the wall time."""
    started = time.perf_counter()
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as output:
        proc = subprocess.Popen(argv, cwd=cwd, stdout=output, stderr=subprocess.STDOUT, env=CHILD_ENV)
    tree_peak = 0
    root = psutil.Process(proc.pid)
    status = usage = None
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid == proc.pid:
            break
        try:
            members = [root] + root.children(recursive=True)
            tree_peak = max(tree_peak, sum(p.memory_info().rss for p in members if p.is_running()))
        except psutil.Error:
            pass
        time.sleep(0.05)
    proc.returncode = os.waitstatus_to_exitcode(status)
    lines = log.read_text(errors="replace").strip().splitlines()
    return {"exit": proc.returncode, "peak_rss_mb": usage.ru_maxrss / 1024, "tree_peak_mb": tree_peak / 2 ** 20,
            "wall_s": time.perf_counter() - started, "output_head": lines[:1], "output_tail": lines[-1:]}


def ensure(folder: Path, argv: list) -> Path:
    if not folder.exists():
        tmp = folder.with_name(folder.name + ".tmp")
        subprocess.run(CLI + argv + ["--out", str(tmp), "--quiet"], check=True)
        tmp.rename(folder)
    return folder


def board_stills(folder: Path, width: int, height: int) -> Path:
    """4 perspective views of a drawn 10x7-square checkerboard (9x6 inner corners), width x height."""
    if folder.exists():
        return folder
    tmp = folder.with_name(folder.name + ".tmp")
    tmp.mkdir(parents=True, exist_ok=True)
    square = 100
    board = (np.kron(np.indices((7, 10)).sum(0) % 2, np.ones((square, square))) * 255).astype(np.uint8)
    drawing = np.full((1100, 1400), 255, np.uint8)
    drawing[200:900, 200:1200] = board
    src = np.float32([[0, 0], [1400, 0], [1400, 1100], [0, 1100]])
    tilts = ([0.00, 0.00, 0.00, 0.00], [0.08, 0.00, -0.05, 0.03], [0.00, 0.07, 0.04, -0.06], [-0.06, 0.05, 0.0, 0.08])
    for i, tilt in enumerate(tilts):
        dst = np.float32([[0.1 + tilt[0], 0.1], [0.9, 0.1 + tilt[1]], [0.9 - tilt[2], 0.9], [0.1, 0.9 - tilt[3]]])
        dst *= [width, height]
        warp = cv2.getPerspectiveTransform(src, dst)
        view = cv2.warpPerspective(drawing, warp, (width, height), flags=cv2.INTER_LINEAR, borderValue=255)
        cv2.imwrite(str(tmp / f"still{i}.png"), cv2.cvtColor(view, cv2.COLOR_GRAY2BGR))
    (tmp / "target.yaml").write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n"
                                     "rowSpacingMeters: 0.04\ncolSpacingMeters: 0.04\n")
    tmp.rename(folder)
    return folder


def desk_loop(folder: Path, frames: int, step: int = 2) -> Path:
    """The desk video at ``step`` x speed, forth and back, as ``frames`` PNG frames with timestamps.txt."""
    if folder.exists():
        return folder
    tmp = folder.with_name(folder.name + ".tmp")
    tmp.mkdir(parents=True, exist_ok=True)
    capture = cv2.VideoCapture(str(DESK))
    images = []
    while True:
        ok, image = capture.read()
        if not ok:
            break
        images.append(image)
    capture.release()
    if not images:
        raise SystemExit(f"{DESK}: no frames decoded")
    images = images[::step]
    loop = images + images[-2:0:-1]
    for k in range(frames):
        cv2.imwrite(str(tmp / f"frame_{k:06d}.png"), loop[k % len(loop)])
    (tmp / "timestamps.txt").write_text("".join(f"{k / 30.0:.6f}\n" for k in range(frames)))
    tmp.rename(folder)
    return folder


def run_cases(cases: set, cache: Path, out_dir: Path) -> list:
    rows = []

    def record(case, size, label, argv):
        print(f"{case} {label} ...", flush=True)
        row = {"case": case, "input": label, "size": size, "argv": " ".join(str(a) for a in argv[2:])}
        row.update(measure([str(a) for a in argv], cwd=ROOT, log=out_dir / "logs" / f"{len(rows):02d}_{case}_{size}.log"))
        print(f"  exit {row['exit']}, peak {row['peak_rss_mb']:.0f} MiB, tree {row['tree_peak_mb']:.0f} MiB, "
              f"{row['wall_s']:.0f} s", flush=True)
        rows.append(row)

    if "linedelay" in cases:
        for seconds in VIDEO_SECONDS:
            video = ensure(cache / f"linedelay_{seconds}s", ["simulate", "--duration", str(seconds), "--seed", "7",
                                                              "--supersample", "1", "--workers", "1"])
            record("linedelay", seconds * 30, f"{seconds} s video, 640x480, {seconds * 30} frames",
                   CLI + ["linedelay", video / "video.avi", "--target", video / "target.yaml", "--camera",
                          video / "camera.yaml", "--out", out_dir / f"linedelay_{seconds}s", "--workers", "2",
                          "--no-cache", "--quiet"])
    if "selfcalib" in cases:
        scene = ensure(cache / f"scene_{SCENE_SECONDS}s", ["simulate", "--scene", "--duration", str(SCENE_SECONDS),
                                                           "--seed", "7", "--workers", "1"])
        for frames in SCENE_FRAMES:
            record("selfcalib", frames, f"room walk 320x240, {frames} frames",
                   CLI + ["selfcalib", scene, "--pixel-size-mm", "0.0112", "--max-frames", str(frames), "--no-restarts",
                          "--out", out_dir / f"selfcalib_{frames}", "--quiet"])
        if DESK.exists():
            record("selfcalib", 359, "real desk video 640x480, 359 frames (with the restarts)",
                   CLI + ["selfcalib", DESK, "--pixel-size-mm", "0.0070216", "--out", out_dir / "selfcalib_desk",
                          "--quiet"])
            loop = desk_loop(cache / f"desk_loop_{max(DESK_LOOP_FRAMES)}", max(DESK_LOOP_FRAMES))
            for frames in DESK_LOOP_FRAMES:
                record("selfcalib", frames, f"real desk video at 2x speed, forth and back, {frames} frames",
                       CLI + ["selfcalib", loop, "--pixel-size-mm", "0.0070216", "--max-frames", str(frames),
                              "--no-restarts", "--out", out_dir / f"selfcalib_desk_{frames}", "--quiet"])
    if "detection" in cases:
        for width, height in STILL_SIZES:
            stills = board_stills(cache / f"stills_{width}x{height}", width, height)
            record("detection", width * height, f"4 stills {width}x{height}",
                   CLI + ["intrinsics", *sorted(stills.glob("still*.png")), "--target", stills / "target.yaml",
                          "--out", out_dir / f"intrinsics_{width}x{height}", "--workers", "2", "--no-cache",
                          "--quiet"])
    return rows


def table(rows: list) -> str:
    lines = ["| command | input | exit | peak RSS, largest process (MiB) | peak RSS, process tree (MiB) |",
             "| --- | --- | --- | --- | --- |"]
    for row in rows:
        lines.append(f"| {row['case']} | {row['input']} | {row['exit']} | {row['peak_rss_mb']:.0f} | "
                     f"{row['tree_peak_mb']:.0f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default="linedelay,selfcalib,detection")
    parser.add_argument("--cache", type=Path, default=Path("/tmp/rscalib_bench_memory"))
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bench_memory.json")
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    out_dir = args.cache / "outputs"
    cases = set(args.cases.split(","))
    rows = run_cases(cases, args.cache, out_dir)
    if args.out.exists():   # the other cases' rows of an earlier run stay (run the cases one at a time)
        earlier = json.loads(args.out.read_text()).get("results", [])
        rows = [row for row in earlier if row["case"] not in cases] + rows
    text = table(rows)
    print(text)
    write_results(args.out, "bench_memory", machine_info(), {"cases": args.cases, "cache": str(args.cache)}, rows,
                  text)


if __name__ == "__main__":
    main()
