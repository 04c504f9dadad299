"""`rscalib flicker`: line delay from the bands of a light flickering at a known frequency (docs/formulation.md, flicker).

Exit codes: 0 determined; 2 bad input (missing file, frequency <= 0, bad region...); 3 the data do
not determine the line delay — no flicker bands found, aliasing, or too uncertain — with
result.json and the plot still written and the reason in its `reason` and `warnings`: no bands,
aliasing, the methods disagree, or the fitted bands leave periodic structure unexplained. "No
flicker" is exit 3, not 2: the input is valid, it just does not contain the answer.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..errors import InputError
from .common import CAPTURE_GUIDE, EXIT_OK, EXIT_UNDETERMINED, FRAMES, ROWS, number


def add_parser(sub) -> None:
    p = sub.add_parser("flicker", help="line delay from the bands of a light flickering at a known frequency",
                       description="Estimate the rolling-shutter line delay d from the horizontal bands that a "
                                   "light flickering at a known frequency paints on the image (period 1/(f d) "
                                   "rows). With frame timestamps (videos, timestamps.txt) a joint fit of the "
                                   "phase drift between frames works even for less than one period per frame "
                                   "(mains flicker); without, the bands' spectrum needs a few periods per "
                                   "frame. Writes result.json and flicker.png. Exit 3 if the data do not "
                                   "determine d (no bands, aliasing), with the reason in result.json.")
    p.add_argument("source", metavar="IMAGES_OR_VIDEO",
                   help="video file, or a folder of images (file-name order, optional timestamps.txt)")
    p.add_argument("--frequency", type=number(0.0, 1e6, " Hz", low_open=True), required=True, metavar="HZ",
                   help="the light's intensity frequency in Hz (twice the mains frequency for mains lamps: 100 or 120)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--rows", type=ROWS, default=None, help="sensor rows read out, for the readout time "
                                                         "(default: image height)")
    p.add_argument("--roi", default=None, metavar="x,y,w,h",
                   help="region whose columns are averaged (default: chosen automatically: the column strips "
                        "whose bands agree, without unlit rows and overlays; result.json says which)")
    p.add_argument("--region", choices=["auto", "all"], default="auto",
                   help="without --roi: auto (strips and rows with bands) or all (every strip)")
    p.add_argument("--readout", choices=["auto", "top-to-bottom", "bottom-to-top"], default="auto",
                   help="readout direction: auto (measured by the phase drift of timestamped frames; else "
                        "top-to-bottom is assumed and said), or given (bottom-to-top: negative line delay)")
    p.add_argument("--max-frames", type=FRAMES, default=None, metavar="N", help="use the first N readable frames")
    p.add_argument("--method", choices=["auto", "spectrum", "phase-drift"], default="auto",
                   help="auto (phase drift when the frames have timestamps, else spectrum), spectrum, phase-drift")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def _check(args) -> None:
    if not (math.isfinite(args.frequency) and args.frequency > 0):
        raise InputError(f"--frequency must be a positive number of Hz (got {args.frequency:g})")
    if args.rows is not None and args.rows <= 0:
        raise InputError("--rows must be positive")
    if args.max_frames is not None and args.max_frames < 1:
        raise InputError("--max-frames must be >= 1")
    if not Path(args.source).exists():
        raise InputError(f"not found: {args.source}")


def run(args: argparse.Namespace) -> int:
    from ..flicker.estimate import estimate_line_delay_flicker
    from ..flicker.report import write_flicker_outputs
    from ..io.output_folder import check_output_folder, expected_output_bytes

    _check(args)
    check_output_folder(args.out, expected_output_bytes(8), inputs=[args.source])
    result = estimate_line_delay_flicker(args.source, args.frequency, rows=args.rows, roi=args.roi,
                                         max_frames=args.max_frames, method=args.method, readout=args.readout,
                                         region=args.region, progress=not args.quiet)
    out = Path(args.out)
    write_flicker_outputs(result, out, source=args.source)
    if result.determined:
        print(f"line delay {result.line_delay_s * 1e6:.5f} +- {result.line_delay_std_s * 1e6:.5f} us/row, "
              f"readout {result.readout_time_s * 1e3:.4f} ms ({result.method}, {result.frames_used} frames, "
              f"band period {result.period_rows:.2f} rows)")
        print(f"readout {result.readout_direction}"
              + ("" if result.direction_determined else "; the bands give |d|"))
        if result.blanking_determined:
            print(f"vertical blanking {result.vertical_blanking_rows:.2f} +- {result.vertical_blanking_std_rows:.2f} "
                  f"rows ({result.vertical_blanking_s * 1e3:.4f} ms)")
    else:
        print("line delay not determined by the data" + (
            f" (best guess {result.line_delay_s * 1e6:.4f} us/row)" if math.isfinite(result.line_delay_s) else ""))
        print(f"reason: {result.reason}")
    region = result.region or {}
    if region.get("bounding_box_xywh"):
        print(f"region ({region.get('mode')}): x,y,w,h = {','.join(str(c) for c in region['bounding_box_xywh'])}, "
              f"{region.get('strips_used')} of {region.get('strips_total')} column strips, "
              f"{region.get('cells_masked', 0)} cells masked")
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"results: {out / 'result.json'}")
    if not result.determined:
        print(f"how to film flicker bands: {CAPTURE_GUIDE}")
    return EXIT_OK if result.determined else EXIT_UNDETERMINED
