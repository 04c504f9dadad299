"""Peak memory, map size and speed of self-calibration at 640x480 (issue 11; docs/sog.md §15): the real
desk video (../shared/data/real_selfcalib_s3phone) played at STEP x speed, forth and back, for FRAMES
frames. Speed: frames per wall and per CPU second from the first frame with one Gaussian left.

Usage: .venv/bin/python benchmarks/bench_selfcalib_memory.py STEP FRAMES [MAX_FEATURES]
  e.g. 4 1000 (peak RSS at 1000 frames); 12 400 0 (no cap: the map grows) vs 12 400 100.
"""
from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

import rscalib
from rscalib.io.video import read_gray_frames
from rscalib.selfcalib.engine import calibrate_frames, sog_options

VIDEO = Path(__file__).resolve().parents[2] / "shared" / "data" / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"


def main() -> None:
    step, count = int(sys.argv[1]), int(sys.argv[2])
    cap = int(sys.argv[3]) if len(sys.argv) > 3 else None
    images = [image for _, image in read_gray_frames(VIDEO).frames][::step]
    loop = images + images[-2:0:-1]
    frames = [(k / 30.0, loop[k % len(loop)]) for k in range(count)]
    method = rscalib.SelfCalibOptions(pixel_size_mm=0.0070216, restarts=False)
    options = sog_options(method)
    if cap is not None:
        options.max_features = cap
    started = time.time()
    maps, clocks = [], []

    def on_frame(k, bank, report):
        maps.append(bank.num_features)
        clocks.append((bank.num_gaussians, time.perf_counter(), time.process_time()))

    result = calibrate_frames(frames, (640, 480), method, sog=options, on_frame=on_frame)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    elapsed = time.time() - started
    print(f"step {step}, {count} frames, max_features {options.max_features}: map max {max(maps)}, "
          f"peak RSS {peak_mb:.0f} MB, {elapsed:.0f} s ({count / elapsed:.1f} frames/s), f {result.mean[0]:.1f} px "
          f"({result.estimate_from})")
    if result.bundle is not None:   # the bundle adjustments (whole tracks, and cut) are inside the peak
        cut_s = result.bundle_cut.elapsed_s if result.bundle_cut is not None else float("nan")
        print(f"bundle adjustment: {result.bundle.keyframes} keyframes, {result.bundle.points} points, "
              f"{result.bundle.observations} observations, {result.bundle.elapsed_s:.1f} s + drift check {cut_s:.1f} s")
    pruned = next((k for k, (gaussians, _, _) in enumerate(clocks) if gaussians == 1), None)
    if pruned is not None and pruned < len(clocks) - 1:
        frames_after = len(clocks) - 1 - pruned
        wall = clocks[-1][1] - clocks[pruned][1]
        cpu = clocks[-1][2] - clocks[pruned][2]
        print(f"one Gaussian from frame {pruned}: then {frames_after / wall:.1f} frames per wall second, "
              f"{frames_after / cpu:.1f} per CPU second ({frames_after} frames)")


if __name__ == "__main__":
    main()
