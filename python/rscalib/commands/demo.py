"""`rscalib demo`: simulate, calibrate, print truth vs estimate."""
from __future__ import annotations

import argparse
import time

from .. import __version__
from .common import EXIT_OK


def add_parser(sub) -> None:
    demo = sub.add_parser("demo", help="run the built-in demonstration (no arguments needed)",
                          description="Run the built-in demonstration on synthetic data.")
    demo.add_argument("--line-delay-us", type=float, default=30.0, help="true line delay in us/row (30)")
    demo.add_argument("--duration", type=float, default=10.0, help="seconds of video (10)")
    demo.add_argument("--noise", type=float, default=0.3, help="detection noise in px (0.3)")
    demo.add_argument("--seed", type=int, default=0, help="random seed of the motion and noise (0)")
    demo.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import simulate
    from .._core import CameraModel
    from ..linedelay import calibrate_line_delay

    started = time.perf_counter()
    line_delay_s = args.line_delay_us * 1e-6
    sim = simulate.simulate_default(line_delay_s=line_delay_s, duration_s=args.duration, seed=args.seed,
                                    noise_px=args.noise)
    c = sim.camera
    camera = CameraModel(c.model, c.params, c.width, c.height)
    obs = sim.observations
    print(f"rscalib {__version__} demo: simulated {args.duration:.0f} s of hand-held 30 fps video of a 9x6 "
          f"checkerboard, {c.width}x{c.height}, rolling shutter d = {line_delay_s * 1e6:.2f} us/row, "
          f"{args.noise} px detection noise")
    print(f"  {obs.num_frames} frames, {obs.num_observations} corner observations "
          "(exact rolling-shutter projection, seed {})".format(args.seed))

    def report(r) -> None:
        print(f"  round {r.round}: {r.segments:4d} knot segments, d = {r.line_delay_s * 1e6:9.3f} us, "
              f"J/2N = {r.normalised_cost:8.3f}, {r.segments_split} segments split, "
              f"{r.segments_at_cap} at the density cap ({r.solve_time_s:.2f} s)")

    result = calibrate_line_delay(obs, camera, progress=report)
    error = result.line_delay_s - line_delay_s
    print(f"  truth     d = {line_delay_s * 1e6:.3f} us/row  (readout {line_delay_s * c.height * 1e3:.3f} ms)")
    print(f"  estimate  d = {result.line_delay_s * 1e6:.3f} +- {result.line_delay_std_s * 1e6:.3f} us/row "
          f"(readout {result.readout_time_s * 1e3:.3f} ms)")
    print(f"  error {error * 1e6:+.3f} us = {error / result.line_delay_std_s:+.2f} sigma; "
          f"pixel sigma {result.pixel_sigma:.3f} px (estimated), J/2N {result.normalised_cost:.3f}, "
          f"rms {result.rms_px:.3f} px, {result.num_segments} segments")
    for w in result.warnings:
        print(f"  warning: {w}")
    print(f"  took {time.perf_counter() - started:.1f} s")
    return EXIT_OK
