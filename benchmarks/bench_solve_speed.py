"""Solve speed of the line-delay engine (issue 17; docs/benchmarks.md: "The leaner solve").

The solve of `rscalib linedelay` (knot adaptation + sigma_d, no detection, no self-check) on simulated
30 fps, 640x480, 9x6-board observations of a hand-held camera (rscalib.sim.target_observations, 0.3 px
noise, d = 30 us/row, seed 7) of 15, 60 and 240 s: the wall and CPU time (all threads) of every solve
(Ceres + sigma_d), the knot count, line delay and sigma_d, and the peak memory of the process. Each length runs in its own
process (clean peak memory). The 1-minute load average is recorded: the machine may be shared.

Before/after: run it with the rscalib to measure on PYTHONPATH, under a --label, and compare two runs:
  PYTHONPATH=python .venv/bin/python benchmarks/bench_solve_speed.py --label after
  PYTHONPATH=/tmp/old/python .venv/bin/python benchmarks/bench_solve_speed.py --label before
  .venv/bin/python benchmarks/bench_solve_speed.py --compare before after
(/tmp/old/python: `git archive <commit> python | tar -x -C /tmp/old` plus that commit's built _core).
Writes benchmarks/results/bench_solve_speed_<label>.json.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
DURATIONS_S = (15.0, 60.0, 240.0)


def measure(duration_s: float, seed: int) -> dict:
    """One calibration of `duration_s` seconds of observations, every solve timed."""
    import numpy as np

    import rscalib
    from rscalib import _core
    from rscalib.linedelay import spline
    from rscalib.sim import target_observations as simulate

    sim = simulate.simulate_default(line_delay_s=30e-6, duration_s=duration_s, seed=seed, noise_px=0.3)
    c = sim.camera
    camera = rscalib.CameraModel(c.model, c.params, c.width, c.height)
    solves = []
    # the solve the spline engine calls: its own name for the core's function, or the core module's
    owner = spline if hasattr(spline, "solve_line_delay") else _core
    solve = owner.solve_line_delay
    def timed(*args):
        trajectory, options = args[4], args[6]
        segments = trajectory.num_segments
        started, cpu_started = time.perf_counter(), time.process_time()
        summary = solve(*args)
        solves.append({"segments": segments, "wall_s": time.perf_counter() - started,
                       "cpu_s": time.process_time() - cpu_started,
                       "iterations": summary.iterations, "covariance_s": summary.covariance_time_s,
                       "with_sigma_d": bool(options.compute_covariance), "line_delay_s": summary.line_delay_s})
        return summary

    load_before = os.getloadavg()[0]
    owner.solve_line_delay = timed
    try:
        started = time.perf_counter()
        result = spline.calibrate_line_delay(sim.observations, camera, rscalib.LineDelayOptions())
        total_s = time.perf_counter() - started
    finally:
        owner.solve_line_delay = solve
    return {"duration_s": duration_s, "seed": seed, "frames": result.frames_used,
            "observations": result.observations, "segments": result.num_segments,
            "line_delay_s": result.line_delay_s, "line_delay_std_s": result.line_delay_std_s,
            "error_in_sigma": (result.line_delay_s - sim.line_delay_s) / result.line_delay_std_s,
            "calibrate_s": total_s, "solves_s": float(np.sum([s["wall_s"] for s in solves])),
            "solves_cpu_s": float(np.sum([s["cpu_s"] for s in solves])),
            "solves": solves, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "load_average_1min": [load_before, os.getloadavg()[0]],
            "options": {k: getattr(_core.RsSolverOptions(), k, None)
                        for k in ("num_threads", "analytic_jacobian", "schur_variance")}}


def table(rows: list) -> str:
    lines = ["| video | obs. | solves (segments: s) | solve total (s) | solve CPU (s) | calibrate (s) | knots "
             "| d (us/row) | sigma_d (us/row) | peak MB | load |",
             "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        solves = ", ".join(f"{s['segments']}: {s['wall_s']:.2f}" + ("+σ" if s["with_sigma_d"] else "")
                           for s in r["solves"])
        lines.append(f"| {r['duration_s']:.0f} s | {r['observations']} | {solves} | {r['solves_s']:.2f} | "
                     f"{r['solves_cpu_s']:.2f} | {r['calibrate_s']:.2f} | {r['segments']} | {r['line_delay_s'] * 1e6:.4f} | "
                     f"{r['line_delay_std_s'] * 1e6:.4f} | {r['peak_rss_mb']:.0f} | "
                     f"{r['load_average_1min'][0]:.1f}-{r['load_average_1min'][1]:.1f} |")
    return "\n".join(lines)


def compare(labels: list) -> str:
    runs = [json.loads((RESULTS / f"bench_solve_speed_{label}.json").read_text()) for label in labels]
    lines = ["| video | " + " | ".join(f"{lab} solve wall / CPU (s) | {lab} knots | {lab} d (us/row) ± σ"
                                      for lab in labels)
             + " | speed-up wall / CPU |", "|---:|" + "---:|---:|---:|" * len(labels) + "---:|"]
    by_duration = [{r["duration_s"]: r for r in run["results"]} for run in runs]
    for duration in sorted(by_duration[0]):
        if not all(duration in b for b in by_duration):
            continue
        rows = [b[duration] for b in by_duration]
        cells = [f"{r['solves_s']:.2f} / {r['solves_cpu_s']:.2f} | {r['segments']} | "
                 f"{r['line_delay_s'] * 1e6:.4f} ± {r['line_delay_std_s'] * 1e6:.4f}" for r in rows]
        lines.append(f"| {duration:.0f} s | " + " | ".join(cells) + f" | {rows[0]['solves_s'] / rows[-1]['solves_s']:.1f}x"
                     f" / {rows[0]['solves_cpu_s'] / rows[-1]['solves_cpu_s']:.1f}x |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--label", default="current", help="name of this run (results file suffix)")
    parser.add_argument("--durations", type=float, nargs="+", default=list(DURATIONS_S), metavar="S")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--compare", nargs="+", metavar="LABEL", help="print the table of earlier runs")
    parser.add_argument("--one", type=float, default=None, help=argparse.SUPPRESS)  # the child process
    args = parser.parse_args()
    if args.compare:
        print(compare(args.compare))
        return
    if args.one is not None:
        print(json.dumps(measure(args.one, args.seed)))
        return

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _common import machine_info, write_results

    info = machine_info()
    rows = []
    for duration in args.durations:
        out = subprocess.run([sys.executable, __file__, "--one", str(duration), "--seed", str(args.seed)],
                             check=True, capture_output=True, text=True, env=os.environ).stdout
        rows.append(json.loads(out.strip().splitlines()[-1]))
        r = rows[-1]
        print(f"  {duration:5.0f} s: solves {r['solves_s']:.2f} s ("
              + ", ".join(f"{s['segments']}:{s['wall_s']:.2f}" for s in r["solves"])
              + f"), {r['segments']} knots, d {r['line_delay_s'] * 1e6:.4f} +- {r['line_delay_std_s'] * 1e6:.4f} us, "
              f"peak {r['peak_rss_mb']:.0f} MB, load {r['load_average_1min'][0]:.1f}", flush=True)
    text = table(rows)
    print("\n" + text)
    write_results(RESULTS / f"bench_solve_speed_{args.label}.json", "bench_solve_speed", info,
                  {"durations_s": args.durations, "seed": args.seed, "label": args.label}, rows, text)


if __name__ == "__main__":
    main()
