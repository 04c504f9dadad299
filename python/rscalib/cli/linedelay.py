"""`rscalib linedelay` and `rscalib localize`: video of a target -> line delay (or, with a
known line delay, the continuous-time trajectory) with report and camera files.

Parse the options, run rscalib.linedelay.pipeline (video -> result), write the outputs with
rscalib.linedelay.report, print the result; docs/architecture.md has the data path."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..errors import InputError
from .common import EXIT_OK, EXIT_UNDETERMINED


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("video", help="video file, or a folder of images (file-name order, optional timestamps.txt)")
    p.add_argument("--target", required=True, help="target YAML (Kalibr fields: checkerboard, circlegrid, aprilgrid; or ChArUco)")
    p.add_argument("--camera", required=True, help="camera YAML (OpenCV FileStorage or Kalibr camchain)")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--pixel-sigma", type=float, default=None,
                   help="detection noise in px (default: estimated from the target grid)")
    p.add_argument("--robust", choices=["none", "huber", "cauchy"], default="none",
                   help="robust loss on the standardised errors, against bad detections (none)")
    p.add_argument("--rows", type=int, default=None, help="sensor rows read out (default: image height)")
    p.add_argument("--workers", type=int, default=None, help="detection processes (default: all cores)")
    p.add_argument("--no-cache", action="store_true", help="re-run detection even if cached")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def add_parser(sub) -> None:
    p = sub.add_parser("linedelay", help="estimate the rolling-shutter line delay from a video of a target",
                       description="Detect the target in every frame, estimate the continuous-time trajectory and "
                                   "the line delay jointly, and write result.json, report.html, plots, the "
                                   "trajectory and camera files with the line delay (OpenCV, Kalibr, Gyroflow).")
    _add_common(p)
    p.add_argument("--max-rounds", type=int, default=8, help="knot-adaptation rounds at most (8)")
    p.add_argument("--trajectory", choices=["spline", "linear"], default="spline",
                   help="trajectory model: the adaptive cubic B-spline (spline, default) or the baseline of "
                        "per-frame poses interpolated linearly / by SLERP (linear, Hedborg et al. 2012)")
    p.add_argument("--uniform-knots", type=int, default=None, metavar="N",
                   help="spline only: N uniform knot segments, no knot adaptation (for experiments)")
    p.add_argument("--no-standardise", action="store_true",
                   help="spline only: weight errors by 1/sigma instead of the A R A^T standardisation")
    p.add_argument("--no-motion-prior", action="store_true", help="spline only: no acceleration prior")
    p.set_defaults(func=run_linedelay)

    q = sub.add_parser("localize", help="continuous-time trajectory with a known line delay, vs per-frame PnP",
                       description="Estimate the camera trajectory of a rolling-shutter video with a known line "
                                   "delay (paper §5.1) and compare it with per-frame global-shutter PnP.")
    _add_common(q)
    q.add_argument("--line-delay", type=float, default=None,
                   help="line delay in s/row (default: from the camera file, if it has one)")
    q.add_argument("--model", choices=["rs-spline", "gs-pnp"], default="rs-spline",
                   help="rs-spline: continuous-time rolling-shutter trajectory (default); gs-pnp: per-frame "
                        "global-shutter PnP poses, written in the same trajectory.csv format for comparison")
    q.set_defaults(func=run_localize)


def _check_flags(args) -> None:
    """One-line errors for option values that mean nothing (before the slow detection)."""
    if args.pixel_sigma is not None and not args.pixel_sigma > 0:
        raise InputError("--pixel-sigma must be positive")
    if args.rows is not None and args.rows <= 0:
        raise InputError("--rows must be positive")
    if getattr(args, "uniform_knots", None) is not None and args.uniform_knots < 1:
        raise InputError("--uniform-knots must be at least 1")
    if getattr(args, "max_rounds", 1) < 1:
        raise InputError("--max-rounds must be at least 1")
    if getattr(args, "line_delay", None) is not None and not math.isfinite(args.line_delay):
        raise InputError("--line-delay must be a finite number")


def _say(args, text: str) -> None:
    if not args.quiet:
        print(text, file=sys.stderr)


def _on_detection(args, solving: str):
    """Prints the detection's warnings and counts, then what is estimated next."""
    def report(detection) -> None:
        for w in detection.warnings:
            _say(args, f"warning: {w}")
        _say(args, f"detection: target in {detection.frames_detected} of {detection.frames_total} frames"
             + (" (cached)" if detection.from_cache else "")
             + ("; dropped: " + ", ".join(f"{k} {v}" for k, v in detection.dropped.items())
                if detection.dropped else ""))
        if solving:
            _say(args, solving)
    return report


def _on_round(args):
    if args.quiet:
        return None

    def report(r) -> None:
        print(f"  round {r.round}: {r.segments} segments, d = {r.line_delay_s * 1e6:.3f} us/row, "
              f"J/2N = {r.normalised_cost:.3f}, split {r.segments_split} ({r.solve_time_s:.1f} s)", file=sys.stderr)
    return report


def _common_options(args, solving: str) -> dict:
    return dict(rows=args.rows, pixel_sigma=args.pixel_sigma, robust_loss=args.robust, workers=args.workers,
                cache=not args.no_cache, progress=not args.quiet, on_detection=_on_detection(args, solving),
                on_round=_on_round(args))


def _print_warnings(summary: dict) -> None:
    for w in summary["warnings"]:
        print(f"warning: {w}", file=sys.stderr)


def run_linedelay(args) -> int:
    from ..linedelay.pipeline import calibrate_video
    from ..linedelay.report import write_video_outputs

    _check_flags(args)
    solving = ("estimating per-frame poses and line delay (linear interpolation):" if args.trajectory == "linear"
               else "estimating trajectory and line delay:")
    run = calibrate_video(args.video, args.target, args.camera, model=args.trajectory, max_rounds=args.max_rounds,
                          uniform_knots=args.uniform_knots, standardise_errors=not args.no_standardise,
                          use_motion_prior=not args.no_motion_prior, **_common_options(args, solving))
    summary = write_video_outputs(run, args.out)
    result = run.result
    std = result.line_delay_std_s
    verdict = ("(linear-interpolation baseline)" if run.model == "linear"
               else summary["verdict"]["headline"].split(": ")[-1])
    print(f"line delay {result.line_delay_s * 1e6:.4f} +- {std * 1e6 if math.isfinite(std) else float('inf'):.4f} "
          f"us/row, readout {result.readout_time_s * 1e3:.4f} ms; J/2N {result.normalised_cost:.3f}"
          + (" " if run.model == "linear" else "; ") + verdict)
    _print_warnings(summary)
    print(f"report: {Path(args.out) / 'report.html'}")
    return EXIT_OK if run.determined else EXIT_UNDETERMINED


def run_localize(args) -> int:
    from ..linedelay.pipeline import localize_video
    from ..linedelay.report import write_video_outputs

    _check_flags(args)
    run = localize_video(args.video, args.target, args.camera, model=args.model, line_delay_s=args.line_delay,
                         **_common_options(args, ""))
    summary = write_video_outputs(run, args.out)
    result = run.result
    if run.model == "gs-pnp":
        print(f"per-frame GS PnP: {result.frames_used} poses, rms {result.rms_px:.3f} px")
    else:
        comparison = run.comparison
        print(f"continuous-time RS trajectory: rms {result.rms_px:.3f} px over {result.observations} points; "
              f"per-frame GS PnP: rms {comparison['gs_pnp_rms_px']:.3f} px; "
              f"mean RS-vs-GS camera-centre difference {comparison['mean_centre_difference_m'] * 1e3:.2f} mm")
    _print_warnings(summary)
    print(f"results: {Path(args.out) / 'result.json'}")
    return EXIT_OK
