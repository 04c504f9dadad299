"""Line-delay engine benchmarks (issue 3; docs/benchmarks.md: line-delay accuracy and speed).

Accuracy: simulated 640x480, 30 fps, 15 s hand-held sequences, 0.3 px noise, 9x6 target, many
seeds: median / 95th percentile of |relative error| of d, and the fraction with |err| <= 3 sigma_d.
Speed: solve time (knot adaptation included) for 15, 60, 120 s of 30 fps observations.

Usage: .venv/bin/python benchmarks/bench_linedelay.py [--seeds 20] [--quick]
Writes benchmarks/results/bench_linedelay.json and prints markdown tables.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

import rscalib
from rscalib.linedelay.spline import calibrate_line_delay
from rscalib.sim import target_observations as simulate

# The solve alone, as `rscalib linedelay` runs it over the whole video (the engine's speed and accuracy;
# the front door adds the self-check's two halves: rscalib.calibrate_video).
OPTIONS = rscalib.LineDelayOptions()


def camera_for(sim) -> rscalib.CameraModel:
    c = sim.camera
    return rscalib.CameraModel(c.model, c.params, c.width, c.height)


def accuracy(seeds: int, line_delays_s, duration_s: float) -> list[dict]:
    rows = []
    for d in line_delays_s:
        for seed in range(seeds):
            sim = simulate.simulate_default(line_delay_s=d, duration_s=duration_s, seed=1000 + seed, noise_px=0.3)
            started = time.perf_counter()
            res = calibrate_line_delay(sim.observations, camera_for(sim), OPTIONS)
            rows.append(dict(d_true_s=d, seed=1000 + seed, d_est_s=res.line_delay_s, std_s=res.line_delay_std_s,
                             normalised_cost=res.normalised_cost, pixel_sigma=res.pixel_sigma,
                             segments=res.num_segments, seconds=time.perf_counter() - started))
            r = rows[-1]
            print(f"  d={d * 1e6:6.2f} us seed={seed:2d}: {r['d_est_s'] * 1e6:9.4f} +- {r['std_s'] * 1e6:.4f} us "
                  f"J/2N={r['normalised_cost']:.3f} {r['seconds']:.1f}s", flush=True)
    return rows


def speed(durations_s) -> list[dict]:
    rows = []
    for duration in durations_s:
        sim = simulate.simulate_default(line_delay_s=30e-6, duration_s=duration, seed=7, noise_px=0.3)
        started = time.perf_counter()
        res = calibrate_line_delay(sim.observations, camera_for(sim), OPTIONS)
        rows.append(dict(duration_s=duration, frames=res.frames_used, observations=res.observations,
                         segments=res.num_segments, rounds=len(res.history),
                         iterations=int(sum(h.iterations for h in res.history)),
                         seconds=time.perf_counter() - started, d_est_s=res.line_delay_s))
        print(f"  {duration:5.0f} s: {rows[-1]['seconds']:.2f} s", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="3 seeds, speed up to 60 s only")
    args = parser.parse_args()
    seeds = 3 if args.quick else args.seeds
    delays = [15e-6, 30e-6, 60e-6, 137e-6]
    print("accuracy:")
    acc = accuracy(seeds, delays, 15.0)
    print("speed:")
    spd = speed([15.0, 60.0] if args.quick else [15.0, 60.0, 120.0])

    print("\n| d (us) | runs | median rel. error | 95th pct rel. error | within 3 sigma | median sigma_d (us) |")
    print("|---:|---:|---:|---:|---:|---:|")
    summary = []
    for d in delays + [None]:
        sel = [r for r in acc if d is None or r["d_true_s"] == d]
        rel = np.array([abs(r["d_est_s"] - r["d_true_s"]) / r["d_true_s"] for r in sel])
        z = np.array([abs(r["d_est_s"] - r["d_true_s"]) / r["std_s"] for r in sel])
        row = dict(d_us=None if d is None else d * 1e6, runs=len(sel), median_rel=float(np.median(rel)),
                   p95_rel=float(np.percentile(rel, 95)), within_3sigma=float(np.mean(z <= 3)),
                   median_std_us=float(np.median([r["std_s"] for r in sel]) * 1e6))
        summary.append(row)
        label = "all" if d is None else f"{d * 1e6:.1f}"
        print(f"| {label} | {row['runs']} | {row['median_rel'] * 100:.3f} % | {row['p95_rel'] * 100:.3f} % | "
              f"{row['within_3sigma'] * 100:.0f} % | {row['median_std_us']:.3f} |")
    print("\n| video | frames | observations | final segments | rounds | Ceres iterations | seconds |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in spd:
        print(f"| {r['duration_s']:.0f} s | {r['frames']} | {r['observations']} | {r['segments']} | {r['rounds']} | "
              f"{r['iterations']} | {r['seconds']:.2f} |")
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    out = Path(__file__).parent / "results" / "bench_linedelay.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(dict(date=time.strftime("%Y-%m-%d"), cpu=cpu, cores=os.cpu_count(),
                                   rscalib=rscalib.__version__, accuracy_summary=summary, accuracy_runs=acc,
                                   speed=spd), indent=1))
    print(f"\nwritten {out}")


if __name__ == "__main__":
    main()
