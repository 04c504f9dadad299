"""A minute of video, end to end, against the naive loop, measured in one run (issue 17).

    .venv/bin/python benchmarks/bench_linedelay_speed.py [--durations 15,60,240] [--codecs ffv1,mp4v] [--videos DIR]

For each duration: a rendered 30 fps, 640x480, 9x6-checkerboard video of a hand-held camera
(`rscalib simulate --supersample 1 --seed 1`, cached in --videos; codec "ffv1" is the lossless render,
slow to decode, "mp4v" the same frames re-encoded as MPEG-4 Part 2, closer to a phone's decode cost:
benchmarks/_common.mpeg4), then, one after the other:
  (a) decode only (FrameSource.frames(gray=True, luma=True), the reader detection uses);
  (b) the naive single-process loop: decode + cv2.findChessboardCornersSB on every frame
      (only for --naive-durations: 50 s a minute of video), --naive-repeats times (3): the ratio is
      against their median, since the loop itself moves by +-20 % with the machine's load;
  (c) `rscalib linedelay --no-cache --no-report` in a subprocess (detection on all cores with
      tracking, the solve with knot adaptation, the two halves' self-check, result.json and the camera
      files): wall time and peak RSS (the largest process of the command and its workers, wait4);
      for --naive-durations as many times as (b), each right after a naive run, and the median run kept;
  (d) the same with the report (plots, report.html).
Ratios (c)/(b) are within this run. The load average is recorded at the start and the end: times
on a shared machine are inflated. Writes benchmarks/results/bench_linedelay_speed.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import _common  # noqa: E402  (benchmarks/_common.py: machine record, results file)
import cv2
import numpy as np

from rscalib.io.video import open_source

RESULTS = Path(__file__).resolve().parent / "results" / "bench_linedelay_speed.json"
CLI = [sys.executable, "-m", "rscalib.cli"]


def render(videos: Path, duration_s: int) -> Path:
    out = videos / f"speed_640x480_{duration_s}s"
    if not (out / "video.avi").exists():
        subprocess.run(CLI + ["simulate", "--out", str(out), "--duration", str(duration_s), "--seed", "1",
                              "--supersample", "1", "--quiet"], check=True)
    return out


def decode_only_s(video: Path) -> tuple[float, int]:
    started, count = time.perf_counter(), 0
    for _ in open_source(video).frames(gray=True, luma=True):
        count += 1
    return time.perf_counter() - started, count


def naive_loop_s(video: Path) -> tuple[float, int]:
    capture, found = cv2.VideoCapture(str(video)), 0
    started = time.perf_counter()
    while True:
        ok, image = capture.read()
        if not ok:
            break
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        ok, _ = cv2.findChessboardCornersSB(gray, (9, 6))
        found += bool(ok)
    capture.release()
    return time.perf_counter() - started, found


def linedelay_run(folder: Path, video: Path, out: Path, report: bool) -> dict:
    argv = CLI + ["linedelay", str(video), "--target", str(folder / "target.yaml"),
                  "--camera", str(folder / "camera.yaml"), "--out", str(out), "--no-cache", "--quiet"]
    if not report:
        argv.append("--no-report")
    # Peak RSS: the largest single process (linedelay or a worker). Through /usr/bin/time when present:
    # a child spawned straight from this process would carry this process's own high-water mark in
    # its ru_maxrss (vfork shares the memory map until exec).
    out.parent.mkdir(parents=True, exist_ok=True)
    peak_file = out.parent / f".{out.name}.maxrss"
    timer = ["/usr/bin/time", "-f", "%M", "-o", str(peak_file)] if Path("/usr/bin/time").exists() else []
    started = time.perf_counter()
    proc = subprocess.Popen(timer + argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)   # its rusage: the largest process it and its workers had
    wall = time.perf_counter() - started
    proc.returncode = os.waitstatus_to_exitcode(status)
    peak_kb = usage.ru_maxrss
    if timer:
        peak_kb = int(peak_file.read_text().split()[-1])
        peak_file.unlink()
    result = json.loads((out / "result.json").read_text()) if (out / "result.json").exists() else {}
    if result.get("line_delay_s") is None and result.get("not_claimed"):   # not determined: the estimate, unclaimed
        result |= result["not_claimed"]
    truth = json.loads((folder / "truth.json").read_text())
    return {"wall_s": wall, "exit": proc.returncode, "peak_rss_mb": peak_kb / 1024,
            "line_delay_us": 1e6 * result.get("line_delay_s", float("nan")),
            "line_delay_std_us": 1e6 * result.get("line_delay_std_s", float("nan")),
            "truth_us": 1e6 * truth.get("line_delay_s", float("nan")),
            "segments": result.get("segments")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--durations", default="15,60,240")
    parser.add_argument("--naive-durations", default="60")
    parser.add_argument("--naive-repeats", type=int, default=3)
    parser.add_argument("--codecs", default="ffv1,mp4v")
    parser.add_argument("--videos", type=Path, default=Path("/tmp/rscalib_speed_videos"))
    parser.add_argument("--results", type=Path, default=RESULTS)
    args = parser.parse_args()
    durations = [int(d) for d in args.durations.split(",")]
    naive = {int(d) for d in args.naive_durations.split(",") if d}
    info = _common.machine_info()
    rows = []
    for duration in durations:
        folder = render(args.videos, duration)
        for codec in args.codecs.split(","):
            video = folder / "video.avi" if codec == "ffv1" else _common.mpeg4(folder)
            row = {"duration_s": duration, "codec": codec}
            row["decode_s"], row["frames"] = decode_only_s(video)
            out = args.videos / "outputs"
            if duration in naive:
                # the naive loop and ours in turn, as many times each: both medians see the same drift of
                # the machine's speed (one run of ours moved by 10 % between two runs of the benchmark)
                runs, ours = [], []
                for _ in range(args.naive_repeats):
                    runs.append(naive_loop_s(video))
                    ours.append(linedelay_run(folder, video, out / f"{duration}s_{codec}_no_report", False))
                row["naive_runs_s"] = [r[0] for r in runs]
                row["naive_s"], row["naive_found"] = float(np.median(row["naive_runs_s"])), runs[0][1]
                row["no_report_runs_s"] = [r["wall_s"] for r in ours]
                row["no_report"] = sorted(ours, key=lambda r: r["wall_s"])[len(ours) // 2]   # the median run
            else:
                row["no_report"] = linedelay_run(folder, video, out / f"{duration}s_{codec}_no_report", False)
            row["report"] = linedelay_run(folder, video, out / f"{duration}s_{codec}_report", True)
            rows.append(row)
            print(json.dumps(row), flush=True)
    info["load_average_1min_at_end"] = os.getloadavg()[0]
    lines = ["| video | codec | frames | decode only (s) | naive loop (s) | linedelay --no-report (s) | ratio to naive "
             "| with report (s) | peak RSS (MB) | d (µs/row), truth |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        nr, rp = row["no_report"], row["report"]
        ratio = f"{nr['wall_s'] / row['naive_s']:.3f}" if "naive_s" in row else "—"
        naive_s = f"{row['naive_s']:.1f}" if "naive_s" in row else "—"
        if "naive_runs_s" in row:
            naive_s += " (median of " + ", ".join(f"{t:.1f}" for t in row["naive_runs_s"]) + ")"
        ours_s = f"{nr['wall_s']:.1f}"
        if "no_report_runs_s" in row:
            ours_s += " (median of " + ", ".join(f"{t:.1f}" for t in row["no_report_runs_s"]) + ")"
        lines.append(f"| {row['duration_s']} s | {row['codec']} | {row['frames']} | {row['decode_s']:.2f} | {naive_s} | "
                     f"{ours_s} | {ratio} | {rp['wall_s']:.1f} | {nr['peak_rss_mb']:.0f} | "
                     f"{nr['line_delay_us']:.4f} ± {nr['line_delay_std_us']:.4f}, {nr['truth_us']:.1f} |")
    table = "\n".join(lines)
    print(table)
    _common.write_results(args.results, "bench_linedelay_speed", info, vars(args) | {"videos": str(args.videos),
                                                                                      "results": str(args.results)},
                          rows, table)


if __name__ == "__main__":
    main()
