"""Spline pose evaluation cost: rscalib's C++ B-spline (through its vectorised and scalar Python
API) against SciPy's BSpline, in nanoseconds per evaluated time.

    .venv/bin/python benchmarks/bench_spline.py [--times 1000000] [--segments 100]

Prints a markdown table and writes it with the machine info to benchmarks/results/bench_spline.json.
The vectorised rows are the closest Python-side measure of the C++ evaluation itself (one call,
the loop in C++, no per-time Python overhead); the scalar rows include the Python call overhead.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import _common  # noqa: E402  (benchmarks/_common.py: machine record, results file)
import numpy as np
import scipy
import scipy.interpolate as si
import scipy.spatial.transform

import rscalib

RESULTS = Path(__file__).resolve().parent / "results" / "bench_spline.json"


def best_time(fn, repeats: int) -> float:
    """Smallest wall time of `repeats` runs (after one warm-up run), seconds."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def machine_info() -> dict:
    return _common.machine_info(scipy=scipy.__version__)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--times", type=int, default=1_000_000, help="times per vectorised call")
    parser.add_argument("--scalar-calls", type=int, default=20_000, help="scalar calls to time")
    parser.add_argument("--segments", type=int, default=100, help="spline segments")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    widths = rng.uniform(0.5, 1.5, args.segments)
    breakpoints = np.r_[0.0, np.cumsum(widths)]
    knots = np.asarray(rscalib.BSpline.clamped_knots(breakpoints))
    control = np.c_[rng.normal(scale=0.3, size=(args.segments + 3, 3)),
                    rng.normal(scale=1.0, size=(args.segments + 3, 3))]
    spline = rscalib.BSpline(knots, control)
    reference = si.BSpline(knots, control, 3)
    times = rng.uniform(breakpoints[0], breakpoints[-1], args.times)
    scalar_times = [float(t) for t in times[: args.scalar_calls]]

    # The two implementations must agree, or the comparison means nothing.
    check = times[:10_000]
    for d in range(3):
        ours = spline.evaluate(check, derivative=d)
        theirs = reference.derivative(d)(check) if d else reference(check)
        err = np.abs(ours - theirs).max() / max(1.0, np.abs(theirs).max())
        if err > 1e-10:
            print(f"rscalib and SciPy disagree (derivative {d}, relative error {err:.1e})", file=sys.stderr)
            return 1

    ref_d1, ref_d2 = reference.derivative(1), reference.derivative(2)
    rows = []  # (name, implementation, mode, seconds, count)

    def add(name, impl, mode, fn, count, repeats=args.repeats):
        seconds = best_time(fn, repeats)
        rows.append({"case": name, "implementation": impl, "mode": mode,
                     "count": count, "ns_per_time": seconds / count * 1e9})

    n = args.times
    add("value x(t), 6-D", "rscalib (C++)", "vectorised", lambda: spline.evaluate(times), n)
    add("1st derivative, 6-D", "rscalib (C++)", "vectorised", lambda: spline.evaluate(times, derivative=1), n)
    add("2nd derivative, 6-D", "rscalib (C++)", "vectorised", lambda: spline.evaluate(times, derivative=2), n)
    add("pose T_cw(t) (R, p)", "rscalib (C++)", "vectorised", lambda: rscalib.poses_at(spline, times), n)
    add("value x(t), 6-D", "SciPy BSpline", "vectorised", lambda: reference(times), n)
    add("1st derivative, 6-D", "SciPy BSpline", "vectorised", lambda: ref_d1(times), n)
    add("2nd derivative, 6-D", "SciPy BSpline", "vectorised", lambda: ref_d2(times), n)

    def scipy_pose():
        state = reference(times)
        return scipy.spatial.transform.Rotation.from_rotvec(state[:, 3:]).as_matrix(), state[:, :3]

    add("pose T_cw(t) (R, p)", "SciPy BSpline + Rotation", "vectorised", scipy_pose, n)

    m = len(scalar_times)

    def ours_scalar():
        for t in scalar_times:
            spline.evaluate(t)

    def theirs_scalar():
        for t in scalar_times:
            reference(t)

    add("value x(t), 6-D", "rscalib (C++)", "scalar call from Python", ours_scalar, m)
    add("value x(t), 6-D", "SciPy BSpline", "scalar call from Python", theirs_scalar, m)

    header = "| case | implementation | mode | ns per time |\n|---|---|---|---:|"
    lines = [header] + [f"| {r['case']} | {r['implementation']} | {r['mode']} | {r['ns_per_time']:.1f} |"
                        for r in rows]
    table = "\n".join(lines)
    info = machine_info()
    print(f"Spline evaluation, {args.segments} non-uniform segments, {n} random times per "
          f"vectorised call, {m} scalar calls; best of {args.repeats}.")
    print(f"{info['cpu_model']}, nproc {info['usable_cores']}, Python {info['python']}\n")
    print(table)

    _common.write_results(args.out, "bench_spline", info, {"segments": args.segments, "dimension": 6, "times_per_call": n,
                     "scalar_calls": m, "repeats": args.repeats}, rows, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
