"""Self-calibration benchmark (issue 5; docs/benchmarks.md): rendered textured-room sequences through the
engine of `rscalib selfcalib` (rscalib.selfcalib.engine.calibrate_frames with SelfCalibOptions(): the
image front end, the SOG bank and the bundle adjustment over its tracks). Per sequence: error of each parameter, whether the truth is in
the 99 % bounds, Gaussians left, the frame the bank collapses to one Gaussian, frames/s.

Usage: .venv/bin/python benchmarks/bench_selfcalib.py [--sequences 10] [--frames 150]
Writes benchmarks/results/bench_selfcalib.json and prints a markdown table.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import rscalib
from rscalib.selfcalib.engine import calibrate_frames, sog_options
from rscalib.selfcalib.result import PARAM_NAMES
from rscalib.sim.scene_video import render_scene_frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequences", type=int, default=10)
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--pixel-sigma", type=float, default=None, help="SogOptions.pixel_sigma (default: the bank's)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "bench_selfcalib.json")
    args = parser.parse_args()
    runs = []
    for seed in range(args.sequences):
        frames = render_scene_frames(num_frames=args.frames, seed=100 + seed)
        truth = np.asarray(frames.camera.params)
        fps_trace = []
        last = [time.perf_counter()]

        def on_frame(k, bank, report, fps_trace=fps_trace, last=last):
            now = time.perf_counter()
            fps_trace.append((bank.num_gaussians, now - last[0]))
            last[0] = now

        method = rscalib.SelfCalibOptions()
        options = sog_options(method)
        if args.pixel_sigma is not None:
            options.pixel_sigma = args.pixel_sigma
        result = calibrate_frames(zip(frames.timestamps_s, frames.images), (frames.camera.width, frames.camera.height),
                                  method, sog=options, on_frame=on_frame)
        inside = [bool(result.bounds_99[i, 0] <= truth[i] <= result.bounds_99[i, 1]) for i in range(5)]
        many = [dt for n, dt in fps_trace[1:] if n > 50]
        one = [dt for n, dt in fps_trace[1:] if n == 1]
        few = [dt for n, dt in fps_trace[1:] if n <= 5]
        run = dict(seed=100 + seed, truth=truth.tolist(), estimate=result.mean.tolist(),
                   bounds_99=result.bounds_99.tolist(), inside=inside,
                   f_error_rel=float(abs(result.mean[0] - truth[0]) / truth[0]),
                   gaussians_left=result.gaussians_left, collapse_frame=result.collapse_frame,
                   fps_overall=result.frames_per_s,
                   fps_over_50_gaussians=float(1 / np.mean(many)) if many else None,
                   fps_one_gaussian=float(1 / np.mean(one)) if one else None,
                   fps_at_most_5_gaussians=float(1 / np.mean(few)) if few else None)
        runs.append(run)
        print(f"seed {run['seed']}: f {result.mean[0]:.2f} (truth {truth[0]:.2f}, {run['f_error_rel'] * 100:.2f} %), "
              f"inside {inside}, {result.gaussians_left} left, collapse {result.collapse_frame}, "
              f"{result.frames_per_s:.1f} frames/s", flush=True)
    coverage = np.mean([r["inside"] for r in runs], axis=0)
    f_err = np.array([r["f_error_rel"] for r in runs])
    print("\n| parameter | truth inside 99 % bounds |")
    print("|---|---:|")
    for name, c in zip(PARAM_NAMES, coverage):
        print(f"| {name} | {c * 100:.0f} % |")
    print(f"\nf error: median {np.median(f_err) * 100:.2f} %, max {f_err.max() * 100:.2f} %, "
          f"within 1 %: {np.mean(f_err <= 0.01) * 100:.0f} %")
    all_in = np.mean([all(r["inside"]) for r in runs])
    print(f"all five inside their bounds: {all_in * 100:.0f} % of sequences")
    def mean_of(key):
        vals = [r[key] for r in runs if r[key] is not None]
        return float(np.mean(vals)) if vals else None
    summary = dict(sequences=len(runs), frames=args.frames, pixel_sigma=options.pixel_sigma, coverage=dict(zip(PARAM_NAMES, coverage.tolist())),
                   f_error_median=float(np.median(f_err)), f_error_max=float(f_err.max()),
                   f_within_1pct=float(np.mean(f_err <= 0.01)), all_inside=float(all_in),
                   fps_over_50_gaussians=mean_of("fps_over_50_gaussians"), fps_one_gaussian=mean_of("fps_one_gaussian"),
                   fps_at_most_5_gaussians=mean_of("fps_at_most_5_gaussians"),
                   collapse_frames=[r["collapse_frame"] for r in runs],
                   gaussians_left=[r["gaussians_left"] for r in runs])
    print(json.dumps({k: v for k, v in summary.items() if k.startswith("fps") or k.startswith("collapse")}, indent=1))
    out = args.out
    out.write_text(json.dumps(dict(date=time.strftime("%Y-%m-%d"), cores=os.cpu_count(), rscalib=rscalib.__version__,
                                   summary=summary, runs=runs), indent=1))
    print(f"written {out}")


if __name__ == "__main__":
    main()
