"""`rscalib selfcalib`: focal length, principal point and radial distortion from a sequence of an
ordinary scene (Sum-of-Gaussians filter bank, Civera et al. 2009; docs/sog.md). Parses, delegates
to rscalib.selfcalib (calibrate, report) and prints."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from ..selfcalib.options import SUBPIXEL_MODES, FrontEndOptions, SelfCalibOptions
from .common import CAPTURE_GUIDE, FOCAL_PX, FRAMES, line_delay, number


def add_parser(sub) -> None:
    p = sub.add_parser("selfcalib", help="self-calibrate f, principal point and radial distortion from a "
                                         "video or image folder of a natural scene",
                       description="Estimate the focal length, principal point and two radial distortion terms, "
                                   "with 99 % bounds, from 10 s or more of walking and looking around a textured "
                                   "scene (no target): many candidate cameras track the scene side by side and the "
                                   "ones the images contradict are dropped (docs/sog.md). An image folder is read in "
                                   "file-name order with an optional timestamps.txt (one time in seconds per line).")
    p.add_argument("source", help="video file or image folder")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--pixel-size-mm", type=number(1e-4, 1.0, " mm"), default=None,
                   help="sensor pixel pitch in mm: the distortion's radii are in mm, so it sets the units of k1 "
                        "(mm^-2) and k2 (mm^-4) and nothing else (f and the principal point do not depend on it); "
                        f"default {SelfCalibOptions.pixel_size_mm} mm (the camera of Civera et al. 2009)")
    p.add_argument("--max-frames", type=FRAMES, default=None, help="stop after this many frames")
    p.add_argument("--line-delay", type=line_delay(0.0, 1e-3), default=None, metavar="DELAY",
                   help="the camera's rolling-shutter line delay per row, with a unit (30us) or in s/row (3e-5; "
                        "e.g. `rscalib linedelay`'s line_delay_s): every measurement is moved to one time per "
                        "frame (docs/sog.md §18); default: the bundle adjustment estimates it from the tracks "
                        "(docs/sog.md §21; a baseline treats the camera as a global shutter)")
    p.add_argument("--f-range", type=FOCAL_PX, nargs=2, default=None, metavar=("LO", "HI"),
                   help="focal lengths in px the candidates start from (default: a wide range for the image size)")
    p.add_argument("--subpixel", choices=SUBPIXEL_MODES, default=None,
                   help=f"match refinement: 'tracked' ({FrontEndOptions.subpixel}, the default): each feature's warp "
                        "carried from its first view, tracks that do not drift (docs/sog.md §19); 'affine': ECC "
                        "alignment from the identity in every frame; 'parabola' through the NCC peak")
    p.add_argument("--determined-within", type=number(1e-4, 0.5), default=None, metavar="FRACTION",
                   help="call the calibration determined (exit 0) when the 99 %% interval of f is within "
                        f"+-FRACTION of f (default {SelfCalibOptions.determined_within}: 2 %%)")
    advanced = p.add_argument_group("advanced (the paper's baselines, for comparisons; the defaults are the method)")
    advanced.add_argument("--no-bundle", action="store_true",
                          help="baseline: the Sum-of-Gaussians filter alone (Civera et al. 2009), without the "
                               "bundle adjustment over its tracks; 'determined' is then judged by restarting two "
                               "single filters (docs/sog.md §15)")
    advanced.add_argument("--bank", choices=["sog", "single"], default="sog",
                          help="sog: many candidate cameras side by side (default); single: the baseline of one "
                               "filter started at --f0 with --f-sigma, without the adjustment (it can lock onto a "
                               "wrong focal length)")
    advanced.add_argument("--f0", type=FOCAL_PX, default=None,
                          help="with --bank single: initial focal length in px (default: the middle of the f range)")
    advanced.add_argument("--f-sigma", type=FOCAL_PX, default=None,
                          help="with --bank single: initial sigma of f in px (default: a quarter of the f range)")
    advanced.add_argument("--no-restarts", action="store_true",
                          help="with a baseline: skip the restart check; the verdict is then 'not checked' and "
                               "the exit code 3")
    advanced.add_argument("--alpha", type=number(0.0, 1.0, low_open=True), default=None,
                          help=f"chance of dropping a right candidate camera too early ({SelfCalibOptions.sprt_alpha})")
    advanced.add_argument("--beta", type=number(0.0, 1.0, low_open=True), default=None,
                          help=f"chance of keeping a wrong candidate camera too long ({SelfCalibOptions.sprt_beta})")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def selfcalib_options(args: argparse.Namespace) -> SelfCalibOptions:
    """SelfCalibOptions from the flags of `rscalib selfcalib` (only the flags typed)."""
    if args.bank == "sog" and (args.f0 is not None or args.f_sigma is not None):
        raise InputError("--f0 and --f-sigma go with --bank single")
    baseline = "single" if args.bank == "single" else ("filter" if args.no_bundle else None)
    typed = {k: v for k, v in dict(
        pixel_size_mm=args.pixel_size_mm, max_frames=args.max_frames, line_delay_s=args.line_delay,
        f_range_px=None if args.f_range is None else tuple(args.f_range), determined_within=args.determined_within,
        baseline=baseline, f0_px=args.f0, f_sigma_px=args.f_sigma, restarts=False if args.no_restarts else None,
        sprt_alpha=args.alpha, sprt_beta=args.beta).items() if v is not None}
    if args.subpixel is not None:
        typed["front_end"] = FrontEndOptions(subpixel=args.subpixel)
    return SelfCalibOptions(**typed)


def run(args: argparse.Namespace) -> int:
    from ..io.output_folder import check_output_folder, expected_output_bytes
    from ..selfcalib.pipeline import self_calibrate

    options = selfcalib_options(args)
    if not Path(args.source).exists():
        raise InputError(f"not found: {args.source}")
    check_output_folder(args.out, expected_output_bytes(16), inputs=[args.source])
    run_ = self_calibrate(args.source, options, progress=not args.quiet)
    written = run_.write(args.out)
    result, verdict = run_.result, run_.verdict
    fm = result.filter_mean
    print(f"filter: f {fm[0]:.2f} px, cx {fm[1]:.2f}, cy {fm[2]:.2f}; {result.gaussians_left} of "
          f"{result.gaussians_initial} Gaussians left after {result.frames_processed} frames "
          f"({result.frames_per_s:.1f} frames/s)")
    if result.bundle_error:
        print(f"warning: bundle adjustment failed: {result.bundle_error}", file=sys.stderr)
    given = "given" if args.pixel_size_mm is not None else \
        "the default, the camera of Civera et al. 2009: give --pixel-size-mm for yours"
    print(f"pixel size {options.pixel_size_mm} mm ({given}): it sets the units of k1 (mm^-2) and k2 (mm^-4) "
          "only; f and the principal point do not depend on it")
    b = result.bounds_99
    if verdict.claims:
        m = result.mean
        print(f"{result.estimate_from} (in camera.yaml): f {m[0]:.2f} px [{b[0, 0]:.2f}, {b[0, 1]:.2f}], "
              f"cx {m[1]:.2f} [{b[1, 0]:.2f}, {b[1, 1]:.2f}], cy {m[2]:.2f} [{b[2, 0]:.2f}, {b[2, 1]:.2f}], "
              f"k1 {m[3]:.5f} mm^-2, k2 {m[4]:.5f} mm^-4 (reported 99 % bounds)")
        line_delay = result.line_delay_estimate()
        if line_delay is not None:
            d, (lo, hi) = line_delay
            print(f"line delay estimated with it (no --line-delay given): {1e6 * d:.2f} us/row "
                  f"[{1e6 * lo:.2f}, {1e6 * hi:.2f}] (99 %; `rscalib linedelay` on a target video measures it better)")
        print(f"OpenCV camera: {Path(args.out) / written['files']['opencv_yaml']} (within "
              f"{written['opencv_camera']['max_difference_px']:.3f} px of the civera-radial model)")
        print(f"determined: {result.reason}")
    else:
        print(f"NOT DETERMINED: {result.reason}; reported bounds f [{b[0, 0]:.1f}, {b[0, 1]:.1f}], "
              f"cx [{b[1, 0]:.1f}, {b[1, 1]:.1f}], cy [{b[2, 0]:.1f}, {b[2, 1]:.1f}] (no camera.yaml: no number "
              "is claimed)", file=sys.stderr)
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if not verdict.trusted:
        print(f"how to record a self-calibration walk: {CAPTURE_GUIDE}")
    print(f"results: {Path(args.out) / 'result.json'}")
    return verdict.exit_code
