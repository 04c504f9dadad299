"""`rscalib linedelay` and `rscalib localize`: video of a target -> line delay (or, with a
known line delay, the continuous-time trajectory) with report and camera files.

Parse the options, run rscalib.linedelay.pipeline (video -> result), write the outputs with
rscalib.linedelay.report, print the result; docs/architecture.md has the data path."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from ..linedelay.options import LOCALIZE_MODELS, ROBUST_LOSSES, LineDelayOptions, LocalizeOptions
from ..readout import AUTO, READOUT_DIRECTIONS, readout_direction
from ..verdict import NOT_DETERMINED
from .common import (
    CAPTURE_GUIDE,
    LINE_DELAY,
    PIXEL_SIGMA,
    ROWS,
    add_force,
    number,
    whole,
    workers,
)
from .intrinsics import add_lens_profile_options, lens_profile_names

# `rscalib linedelay` exit codes (README: exit codes): 0 trusted, 2 bad input, 3 undetermined, and
EXIT_CODES_HELP = ("exit codes: 0 the line delay is estimated and every check passed (trust it); "
                   "2 bad input (one line on stderr); 3 the video does not determine the line delay (results "
                   "written, no number claimed); 4 estimated but not trusted: a check failed (physical limits, "
                   "J/2N above 1.5, the halves' self-check, coverage, uncertainty; the first suspect is named "
                   "first, and the report says what to film differently); "
                   "1 internal error")

# Equal segments at most: each adds 6 unknowns and a band of the Jacobian (more than a few per frame
# are not determined by the data; the solver's memory grows with their square in the covariance).
MAX_UNIFORM_KNOTS = 5000

# engine words -> the flags a CLI user can type
_FLAG_WORDS = (("robust_loss='huber'", "--robust huber"), ("lower min_segment_s", "lower --min-segment-ms"),
               ("min_segment_s", "--min-segment-ms"), ("pixel_sigma", "--pixel-sigma"))


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("video", help="video file, or a folder of images (file-name order, optional timestamps.txt)")
    p.add_argument("--target", required=True, help="target YAML (Kalibr fields: checkerboard, circlegrid, aprilgrid; or ChArUco)")
    p.add_argument("--camera", required=True,
                   help="camera file: OpenCV YAML, Kalibr camchain, ROS camera_info, mrcal .cameramodel, COLMAP "
                        "cameras.txt or Gyroflow profile (docs/formats.md)")
    p.add_argument("--out", required=True, help="output folder (created)")
    add_force(p)
    p.add_argument("--pixel-sigma", type=PIXEL_SIGMA, default=None,
                   help="detection noise in px (default: estimated from the target grid)")
    p.add_argument("--robust", choices=ROBUST_LOSSES, default=None,
                   help=f"robust loss on the standardised errors, against bad detections ({LineDelayOptions.robust_loss})")
    p.add_argument("--rows", type=ROWS, default=None, help="sensor rows read out (default: image height)")
    p.add_argument("--workers", type=workers, default=None, help="detection processes (default: all cores)")
    p.add_argument("--no-cache", action="store_true", help="re-run detection even if cached")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def add_parser(sub) -> None:
    p = sub.add_parser("linedelay", help="estimate the rolling-shutter line delay from a video of a target",
                       description="Detect the target in every frame, estimate the continuous-time trajectory and "
                                   "the line delay jointly, check it on the two halves of the video, and write "
                                   "result.json, report.html (with advice on filming), plots, the trajectory and "
                                   "camera files with the line delay (OpenCV, Kalibr, Gyroflow, ROS, mrcal, COLMAP; "
                                   "docs/formats.md).",
                       epilog=EXIT_CODES_HELP)
    _add_common(p)
    p.add_argument("--start", type=number(), default=None, metavar="S", help="use frames from S seconds on")
    p.add_argument("--end", type=number(), default=None, metavar="S", help="use frames up to S seconds")
    p.add_argument("--readout", type=readout_flag, default=None, metavar="|".join((AUTO,) + READOUT_DIRECTIONS),
                   help="sensor readout direction in the image (auto: top-to-bottom, or from a portrait video's "
                        "rotation metadata, which turns sensor rows into image columns)")
    p.add_argument("--min-segment-ms", type=number(0.0, 1e6, " ms", low_open=True), default=None, metavar="MS",
                   help="shortest knot segment the adaptation may create (default: half a frame, at most 16.7 ms)")
    p.add_argument("--no-self-check", action="store_true",
                   help="do not solve the two halves of the video separately (faster; the error bar is not checked)")
    p.add_argument("--max-rounds", type=whole(1, 100), default=None,
                   help=f"knot-adaptation rounds at most ({LineDelayOptions.max_rounds})")
    p.add_argument("--no-report", action="store_true",
                   help="no plots and no report.html (batch use): result.json, trajectories and camera files only")
    add_lens_profile_options(p)
    advanced = p.add_argument_group("advanced (the paper's baseline and ablations, for comparisons; the defaults "
                                    "are the method)")
    advanced.add_argument("--trajectory", choices=["spline", "linear"], default="spline",
                          help="trajectory model: a smooth curve through time (spline, the method) or the baseline "
                               "of per-frame poses interpolated linearly between frames (linear, Hedborg et al. 2012)")
    advanced.add_argument("--uniform-knots", type=whole(1, MAX_UNIFORM_KNOTS, " segments"), default=None, metavar="N",
                          help="spline only: N equal time segments, no adaptation to the motion")
    advanced.add_argument("--no-standardise", action="store_true",
                          help="spline only: treat every detection's error as plain pixel noise, ignoring how "
                               "image motion during the readout stretches it")
    advanced.add_argument("--no-motion-prior", action="store_true",
                          help="spline only: no penalty on the trajectory's acceleration")
    advanced.add_argument("--refine-intrinsics", action="store_true",
                          help="spline only: refine focal lengths, principal point and distortion jointly with the "
                               "trajectory and the line delay, with the camera file as a prior; result.json gets "
                               "the covariance of the line delay with the intrinsics (docs/formulation.md §14)")
    advanced.add_argument("--intrinsics-prior", default=None, metavar="RESULT_JSON",
                          help="with --refine-intrinsics: the `rscalib intrinsics` result.json whose standard "
                               "deviations are the prior (default: sigma_f 2 %%, sigma_c 10 px, the distortion's "
                               "default sigma)")
    p.set_defaults(func=run_linedelay)

    q = sub.add_parser("localize", help="continuous-time trajectory with a known line delay, vs per-frame PnP",
                       description="Estimate the camera trajectory of a rolling-shutter video with a known line "
                                   "delay and compare it with per-frame global-shutter poses (PnP). Writes "
                                   "trajectory.csv (world-to-camera) and trajectory_tum.txt (TUM format, "
                                   "camera-to-world).")
    _add_common(q)
    q.add_argument("--line-delay", type=LINE_DELAY, default=None, metavar="DELAY",
                   help="line delay per row, with a unit (30us, 0.03ms) or in s/row (3e-5) "
                        "(default: from the camera file, if it has one)")
    q.add_argument("--model", choices=LOCALIZE_MODELS, default=None,
                   help=f"rs-spline: continuous-time rolling-shutter trajectory ({LocalizeOptions.model}, the "
                        "default); gs-pnp: per-frame global-shutter PnP poses, written in the same trajectory.csv "
                        "format for comparison")
    q.set_defaults(func=run_localize)


def readout_flag(text: str) -> str:
    """--readout: auto or a readout direction (rscalib.readout; the earlier words are read too)."""
    try:
        return readout_direction(text, READOUT_DIRECTIONS, auto=True)
    except InputError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _typed(**values) -> dict:
    """The options a user typed: flags left at None (not given) are not passed, so the defaults
    stay in the options classes."""
    return {k: v for k, v in values.items() if v is not None}


def _detection_options(args):
    from ..detection.options import DetectOptions

    return DetectOptions(**_typed(workers=args.workers, cache=False if args.no_cache else None))


def line_delay_options(args) -> LineDelayOptions:
    """LineDelayOptions from the flags of `rscalib linedelay` (batch and the CLI share this)."""
    return LineDelayOptions(**_typed(
        baseline="linear" if args.trajectory == "linear" else None, rows=args.rows, pixel_sigma_px=args.pixel_sigma,
        robust_loss=args.robust, max_rounds=args.max_rounds,
        min_segment_s=None if args.min_segment_ms is None else args.min_segment_ms * 1e-3,
        readout=args.readout, start_s=args.start, end_s=args.end, self_check=False if args.no_self_check else None,
        refine_intrinsics=True if args.refine_intrinsics else None, intrinsics_prior=args.intrinsics_prior,
        uniform_knots=args.uniform_knots, standardise_errors=False if args.no_standardise else None,
        motion_prior=False if args.no_motion_prior else None), detection=_detection_options(args))


def localize_options(args) -> LocalizeOptions:
    """LocalizeOptions from the flags of `rscalib localize`."""
    return LocalizeOptions(**_typed(model=args.model, rows=args.rows, pixel_sigma_px=args.pixel_sigma,
                                    robust_loss=args.robust), detection=_detection_options(args))


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


def in_flags(text: str) -> str:
    """An engine's message in the words of the command line (its options as flags)."""
    for word, flag in _FLAG_WORDS:
        text = text.replace(word, flag)
    return text


def _print_warnings(summary: dict) -> None:
    for w in summary["warnings"]:
        print(f"warning: {in_flags(w)}", file=sys.stderr)


def _check_out(args) -> None:
    """--out before the slow part: a writable folder with room for the report, plots, camera files
    and what grows with the video (trajectories, corners.vnl)."""
    from ..io.output_folder import check_output_folder, expected_output_bytes

    check_output_folder(args.out, expected_output_bytes(32, [args.video], per_input_byte=0.1), inputs=[args.video],
                        command=args.command, force=args.force)


def _check_files(args) -> None:
    """The input files before anything slow (one line each)."""
    if not Path(args.video).exists():
        raise InputError(f"video not found: {args.video}")
    for name, path in (("target", args.target), ("camera", args.camera)):
        if not Path(path).is_file():
            raise InputError(f"{name} file not found: {path}")


def run_linedelay(args) -> int:
    from ..io.limits import keep_freed_memory
    from ..linedelay.pipeline import calibrate_video

    # this process is ours: its solves reuse freed memory instead of page-faulting it in again (the
    # 60 s speed video 6 % faster; self-calibration gains nothing and would keep 120 MB more: not there)
    keep_freed_memory()
    options = line_delay_options(args)
    _check_files(args)
    _check_out(args)
    solving = ("estimating per-frame poses and line delay (linear interpolation):" if options.baseline == "linear"
               else "estimating trajectory and line delay:")
    run = calibrate_video(args.video, args.target, args.camera, options, progress=not args.quiet,
                          on_detection=_on_detection(args, solving), on_round=_on_round(args))
    # the result is printed as soon as result.json is written, before the plots are drawn
    run.write(args.out, lens_profile=lens_profile_names(args), report=not args.no_report,
              on_result=lambda written: _print_result(run, written))
    if args.no_report:
        print(f"results: {Path(args.out) / 'result.json'}")
    else:
        print(f"report: {Path(args.out) / 'report.html'}")
    return run.verdict.exit_code


def _print_result(run, summary: dict) -> None:
    """The line delay (or why there is none), the verdict's reasons, advice and warnings."""
    result, verdict = run.result, run.verdict
    if verdict.status == NOT_DETERMINED:
        print("line delay: not determined by this video (results written; no number is claimed); "
              + in_flags(verdict.reasons[0]))
    else:
        std = result.line_delay_std_s
        said = ("(linear-interpolation baseline)" if run.model == "linear" else verdict.headline.split(": ")[-1])
        image_ms = summary.get("image_readout_time_s", result.readout_time_s) * 1e3
        rows_note = "" if abs(image_ms - result.readout_time_s * 1e3) < 1e-9 else \
            f" over {result.rows} rows (image rows: {image_ms:.4f} ms)"
        print(f"line delay {result.line_delay_s * 1e6:.4f} +- {std * 1e6:.4f} us/row, readout "
              f"{result.readout_time_s * 1e3:.4f} ms{rows_note}; J/2N {result.normalised_cost:.3f}"
              + (" " if run.model == "linear" else "; ") + said)
        for number, reason in enumerate(verdict.reasons):
            print(f"  {'first suspect' if number == 0 and len(verdict.reasons) > 1 else 'because'}: {in_flags(reason)}")
        for caveat in verdict.caveats:
            print(f"  note: {in_flags(caveat)}")
    refined = summary.get("intrinsics")
    if refined:
        print("intrinsics refined: " + ", ".join(
            f"{n} {refined['estimate'][n]:.6g}" + ("" if refined["std"][n] is None else f" +- {refined['std'][n]:.3g}")
            for n in refined["names"] if n not in refined["prior"]["held"]) + f" (prior: {refined['prior']['source']})")
    for advice in (summary.get("guidance") or {}).get("advice", []):
        print(f"  to film better: {advice}")
    _print_warnings(summary)
    if not verdict.trusted:
        print(f"  how to film a better video: {CAPTURE_GUIDE}")


def run_localize(args) -> int:
    from ..linedelay.pipeline import localize_video

    options = localize_options(args)
    _check_files(args)
    _check_out(args)
    run = localize_video(args.video, args.target, args.camera, args.line_delay, options, progress=not args.quiet,
                         on_detection=_on_detection(args, ""), on_round=_on_round(args))
    summary = run.write(args.out)
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
    return run.verdict.exit_code
