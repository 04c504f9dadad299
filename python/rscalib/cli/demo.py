"""`rscalib demo`: render a rolling-shutter video of a checkerboard with a known line delay into
a temporary folder, calibrate it end to end, print truth vs estimate and where the report is."""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from .._version import __version__
from ..io.output_folder import check_output_folder, expected_output_bytes
from .common import line_delay, number, seed


def add_parser(sub) -> None:
    demo = sub.add_parser("demo", help="run the built-in demonstration (no arguments needed)",
                          description="Render a synthetic rolling-shutter video with a known line delay, "
                                      "calibrate it (detection, trajectory, line delay, report) and print truth "
                                      "vs estimate.")
    demo.add_argument("--line-delay", type=line_delay(0.0, 0.01, low_open=True), default=30e-6, metavar="DELAY",
                      help="true line delay per row, with a unit (30us) or in s/row (default 30us)")
    demo.add_argument("--line-delay-us", type=number(0.0, 1e4, " us/row", low_open=True), default=None,
                      help=argparse.SUPPRESS)   # the flag of earlier versions
    demo.add_argument("--duration", type=number(0.5, 600.0, " s"), default=4.0, help="seconds of video (4)")
    demo.add_argument("--seed", type=seed, default=0, help="random seed of the motion and noise (0)")
    demo.add_argument("--out", default=None, help="folder for the video and results (default: a new temp folder)")
    demo.add_argument("--observations-only", action="store_true",
                      help="skip rendering and detection: simulate corner observations directly (seconds)")
    demo.set_defaults(func=run)


def _round_printer(r) -> None:
    print(f"  round {r.round}: {r.segments:4d} knot segments, d = {r.line_delay_s * 1e6:9.3f} us, "
          f"J/2N = {r.normalised_cost:8.3f}, {r.segments_split} split ({r.solve_time_s:.2f} s)")


def _detection_printer(detection) -> None:
    print(f"  detected the board in {detection.frames_detected} of {detection.frames_total} frames "
          f"({detection.observations.num_observations} corners)")


def run(args: argparse.Namespace) -> int:
    from ..linedelay.options import LineDelayOptions
    from ..linedelay.pipeline import calibrate_video

    started = time.perf_counter()
    line_delay_s = args.line_delay if args.line_delay_us is None else args.line_delay_us * 1e-6
    if args.out:   # the rendered video (raw size, generously), its detection cache and the report
        frames = 0 if args.observations_only else args.duration * 30.0
        # its results are linedelay's (the demo runs it), its video simulate's: no owner check
        check_output_folder(args.out, expected_output_bytes(64, extra_bytes=frames * 640 * 480 * 1.5))
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="rscalib-demo-"))
    out.mkdir(parents=True, exist_ok=True)
    print(f"rscalib {__version__} demo: {args.duration:g} s of hand-held 30 fps video of a 9x6 checkerboard, "
          f"640x480, rolling shutter d = {line_delay_s * 1e6:g} us/row")
    if args.observations_only:
        from .._core import CameraModel
        from ..sim import target_observations as simulate

        sim = simulate.simulate_default(line_delay_s=line_delay_s, duration_s=args.duration, seed=args.seed)
        c = sim.camera
        camera = CameraModel(c.model, c.params, c.width, c.height)
        print(f"  simulated {sim.observations.num_observations} corner observations (exact RS projection, "
              "0.3 px noise)")
        # the engine alone, as before the self-check existed: seconds, for a first look
        run = calibrate_video(sim.observations, camera=camera, options=LineDelayOptions(self_check=False),
                              on_round=_round_printer)
    else:
        from ..detection.options import DetectOptions
        from ..sim.target_video import render_video

        video = out / "video"
        print(f"  rendering into {video} (every row at its own time) ...")
        render_video(video, line_delay_s=line_delay_s, duration_s=args.duration, seed=args.seed, supersample=2,
                     progress=True)
        run = calibrate_video(video / "video.avi", video / "target.yaml", video / "camera.yaml",
                              LineDelayOptions(detection=DetectOptions(cache_dir=out / "cache")), progress=True,
                              on_detection=_detection_printer, on_round=_round_printer)
        camera = run.camera
    result = run.result
    error = result.line_delay_s - line_delay_s
    std = result.line_delay_std_s
    print(f"  truth     d = {line_delay_s * 1e6:.3f} us/row  (readout {line_delay_s * camera.height * 1e3:.3f} ms)")
    print(f"  estimate  d = {result.line_delay_s * 1e6:.3f} +- {std * 1e6:.3f} us/row "
          f"(readout {result.readout_time_s * 1e3:.3f} ms)")
    if math.isfinite(std) and std > 0:
        print(f"  error {error * 1e6:+.3f} us = {error / std:+.2f} sigma; pixel sigma {result.pixel_sigma:.3f} px "
              f"(estimated), J/2N {result.normalised_cost:.3f}, rms {result.rms_px:.3f} px")
    for w in result.warnings:
        print(f"  warning: {w}")
    print(f"  verdict: {run.verdict.headline}")
    if not args.observations_only:
        run.write(out / "result", command="demo")
        print(f"  report: {out / 'result' / 'report.html'}")
    print(f"  took {time.perf_counter() - started:.1f} s")
    return run.verdict.exit_code
