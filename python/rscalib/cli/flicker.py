"""`rscalib flicker`: line delay from the bands of a light flickering at a known frequency (docs/formulation.md, flicker).

Fill FlickerOptions from the flags a user typed, run the front door
(rscalib.flicker.pipeline.estimate_line_delay_flicker), write its files (FlickerRun.write), print the
verdict and the result, and return the verdict's exit code: 0 trusted; 2 bad input (missing file,
frequency <= 0, bad region...); 3 the data do not determine the line delay — no bands, aliasing,
the methods disagree, or the fitted bands leave periodic structure unexplained — with result.json,
the plots and report.html still written; 4 estimated but not trusted: check --frequency (a
bottom-to-top readout that was not given, or band phases that do not follow the timestamps and the
frequency; flicker/judge.py). "No flicker" is exit 3, not 2: the input is valid, it just does not
contain the answer.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from .. import checks
from ..errors import InputError
from ..flicker.options import METHODS, REGIONS, FlickerOptions
from ..readout import AUTO, ROW_DIRECTIONS, readout_direction
from ..verdict import NOT_DETERMINED
from .common import CAPTURE_GUIDE, FRAMES, ROWS, add_force, number

EXIT_CODES_HELP = ("exit codes: 0 the line delay is estimated and every check passed (trust it); 2 bad input (one "
                   "line on stderr); 3 the frames do not determine the line delay (results written, no number "
                   "claimed); 4 estimated but not trusted: check --frequency (a bottom-to-top readout not given with "
                   "--readout, or band phases that do not follow the timestamps and the frequency); 1 internal error")


def _default(name: str) -> object:
    """The default of a FlickerOptions field, for the help texts (the options class is its one home)."""
    return FlickerOptions.__dataclass_fields__[name].default


def readout_flag(text: str) -> str:
    """--readout: auto or a direction along the rows (rscalib.readout; the earlier words are read too)."""
    try:
        return readout_direction(text, ROW_DIRECTIONS, auto=True)
    except InputError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_parser(sub) -> None:
    p = sub.add_parser("flicker", help="line delay from the bands of a light flickering at a known frequency",
                       description="Estimate the rolling-shutter line delay d from the horizontal bands that a "
                                   "light flickering at a known frequency paints on the image (period 1/(f d) "
                                   "rows). With frame timestamps (videos, timestamps.txt) a joint fit of the "
                                   "phase drift between frames works even for less than one period per frame "
                                   "(mains flicker) and measures the readout direction; without, the bands' "
                                   "spectrum needs a few periods per frame. Writes result.json (with the verdict), "
                                   "report.html and the plots.",
                       epilog=EXIT_CODES_HELP)
    p.add_argument("source", metavar="IMAGES_OR_VIDEO",
                   help="a video file, a folder of images (file-name order, optional timestamps.txt), or a single "
                        "image (the spectrum alone: a few band periods in the frame)")
    p.add_argument("--frequency", type=number(0.0, checks.MAX_FREQUENCY_HZ, " Hz", low_open=True), required=True, metavar="HZ",
                   help="the light's intensity frequency in Hz: twice the mains frequency for mains lamps (100 or "
                        "120), an LED's PWM frequency")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    add_force(p)
    p.add_argument("--rows", type=ROWS, default=None, help="sensor rows read out, for the readout time "
                                                         "(default: image height)")
    p.add_argument("--roi", default=None, metavar="x,y,w,h",
                   help="region whose columns are averaged, in px (default: chosen automatically: the column strips "
                        "whose bands agree, without unlit rows and overlays; result.json says which)")
    p.add_argument("--region", choices=REGIONS, default=None,
                   help=f"without --roi: auto (strips and rows with bands) or all (every strip) "
                        f"(default: {_default('region')})")
    p.add_argument("--readout", type=readout_flag, default=None, metavar="|".join((AUTO,) + ROW_DIRECTIONS),
                   help="readout direction in the image: auto (measured by the phase drift of timestamped frames; "
                        "else top-to-bottom is assumed and said), or given (bottom-to-top: negative line delay); "
                        f"the words of earlier versions are read too (default: {_default('readout')})")
    p.add_argument("--max-frames", type=FRAMES, default=None, metavar="N", help="use the first N readable frames")
    p.add_argument("--method", choices=METHODS, default=None,
                   help="auto (phase drift when the frames have timestamps, cross-checked by the spectrum), "
                        "spectrum (the bands of each frame alone: for frame times known to be inexact), phase-drift "
                        f"(default: {_default('method')})")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def _typed(**values) -> dict:
    """The options a user typed: flags left at None (not given) are not passed, so the defaults
    stay in FlickerOptions."""
    return {k: v for k, v in values.items() if v is not None}


def flicker_options(args) -> FlickerOptions:
    """FlickerOptions from the flags of `rscalib flicker` (batch and the CLI share this)."""
    return FlickerOptions(**_typed(rows=args.rows, roi=args.roi, region=args.region, readout=args.readout,
                                   max_frames=args.max_frames, method=args.method))


def _check(args) -> None:
    if not (math.isfinite(args.frequency) and args.frequency > 0):
        raise InputError(f"--frequency must be a positive number of Hz (got {args.frequency:g})")
    if not Path(args.source).exists():
        raise InputError(f"not found: {args.source}")


def run(args: argparse.Namespace) -> int:
    from ..flicker.pipeline import estimate_line_delay_flicker
    from ..io.output_folder import check_output_folder, expected_output_bytes

    options = flicker_options(args)
    _check(args)
    check_output_folder(args.out, expected_output_bytes(8), inputs=[args.source], command=args.command,
                        force=args.force)
    run = estimate_line_delay_flicker(args.source, args.frequency, options, progress=not args.quiet)
    summary = run.write(args.out)
    print_run(run, summary)
    print(f"results: {Path(args.out) / 'result.json'}")
    print(f"report: {Path(args.out) / 'report.html'}")
    return run.verdict.exit_code


def print_run(run, summary: dict) -> None:
    """The verdict word with the headline, the result (or why there is none), the region and warnings."""
    result, verdict = run.result, run.verdict
    if verdict.status == NOT_DETERMINED:
        print(f"{verdict.status}: line delay not determined by the data (results written; no number is claimed)")
        print(f"reason: {result.reason}")
    else:
        print(f"{verdict.status}: line delay {result.line_delay_s * 1e6:.5f} +- {result.line_delay_std_s * 1e6:.5f} "
              f"us/row, readout {result.readout_time_s * 1e3:.4f} ms ({result.method}, {result.frames_used} frames, "
              f"band period {result.period_rows:.2f} rows)")
        print(f"readout {result.readout_direction}" + ("" if result.direction_determined else "; the bands give |d|"))
        if result.blanking_determined:
            print(f"vertical blanking {result.vertical_blanking_rows:.2f} +- {result.vertical_blanking_std_rows:.2f} "
                  f"rows ({result.vertical_blanking_s * 1e3:.4f} ms)")
        for reason in verdict.reasons:
            print(f"  because: {reason}")
    region = result.region or {}
    if region.get("bounding_box_xywh"):
        print(f"region ({region.get('mode')}): x,y,w,h = {','.join(str(c) for c in region['bounding_box_xywh'])}, "
              f"{region.get('strips_used')} of {region.get('strips_total')} column strips, "
              f"{region.get('cells_masked', 0)} cells masked")
    for w in summary["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    if not verdict.trusted:
        print(f"how to film flicker bands: {CAPTURE_GUIDE}")
