"""`rscalib selfcalib`: focal length, principal point and radial distortion from a sequence of an
ordinary scene (Sum-of-Gaussians filter bank, Civera et al. 2009; docs/sog.md). Parses, delegates
to rscalib.selfcalib (calibrate, report) and prints."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from ..selfcalib.options import SUBPIXEL_MODES, FrontEndOptions, SelfCalibOptions
from .common import CAPTURE_GUIDE, FOCAL_PX, FRAMES, add_force, line_delay, number


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
    add_force(p)
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
    p.add_argument("--line-delay-from", default=None, metavar="RESULT_JSON",
                   help="the result.json of `rscalib linedelay` (or `rscalib flicker`) on the same camera and video "
                        "mode: its line delay with its sigma becomes the adjustment's prior (a board filmed once "
                        "makes every later self-calibration better)")
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
        line_delay_from=args.line_delay_from,
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
    check_output_folder(args.out, expected_output_bytes(16), inputs=[args.source], command=args.command,
                        force=args.force)
    run_ = self_calibrate(args.source, options, progress=not args.quiet)
    written = run_.write(args.out)
    result, verdict = run_.result, run_.verdict
    b = result.bounds_99
    if verdict.claims:
        m = result.mean
        print(f"determined: f {m[0]:.2f} px [{b[0, 0]:.2f}, {b[0, 1]:.2f}], cx {m[1]:.2f} [{b[1, 0]:.2f}, "
              f"{b[1, 1]:.2f}], cy {m[2]:.2f} [{b[2, 0]:.2f}, {b[2, 1]:.2f}], k1 {m[3]:.5f} [{b[3, 0]:.5f}, "
              f"{b[3, 1]:.5f}] mm^-2, k2 {m[4]:.6f} [{b[4, 0]:.6f}, {b[4, 1]:.6f}] mm^-4 (99 % bounds)")
        print(f"  because: {result.reason}")
    else:
        print(f"NOT DETERMINED: {result.reason}")
        print(f"  no number is claimed (no camera.yaml); what the data allow, 99 %: f [{b[0, 0]:.1f}, {b[0, 1]:.1f}] "
              f"px, cx [{b[1, 0]:.1f}, {b[1, 1]:.1f}], cy [{b[2, 0]:.1f}, {b[2, 1]:.1f}]")
    line_delay = result.line_delay_estimate()
    if line_delay is not None and verdict.claims:
        d, (lo, hi) = line_delay
        said = "with --line-delay-from as its prior" if options.line_delay_from else "from the scene"
        print(f"  line delay estimated with it ({said}): {1e6 * d:.2f} us/row [{1e6 * lo:.2f}, {1e6 * hi:.2f}] "
              "(99 %; `rscalib linedelay` on a target video measures it better)")
    fm, ba_bounds = result.filter_mean, result.adjustment_bounds_99()
    filter_line = (f"  the filter alone (Civera et al. 2009): f {fm[0]:.1f} px, c ({fm[1]:.1f}, {fm[2]:.1f}); "
                   f"{result.gaussians_left} of {result.gaussians_initial} candidate cameras left after "
                   f"{result.frames_processed} frames")
    if ba_bounds is not None and not ba_bounds[0, 0] <= fm[0] <= ba_bounds[0, 1]:
        filter_line += " (outside the adjustment's bounds: not used; sog.md §15)"
    print(filter_line)
    check = result.self_check
    if check:
        z = dict(zip(check["names"], check["z"]))
        worst = sorted(z, key=z.get, reverse=True)[:2]
        said = ", ".join(f"{name} {z[name]:.1f} sigma" for name in worst)
        if max(z.values()) <= 3:
            print(f"  self-check: the two halves of the video agree (largest difference {said})"
                  + (f"; sigmas widened x{check['widen'][0]:.2f}" if check["widen"][0] > 1 else ""))
        else:
            print(f"  self-check: the two halves of the video differ ({said}): every sigma widened "
                  f"x{check['widen'][0]:.1f}")
    if result.adjustment_error:
        print(f"warning: bundle adjustment failed: {result.adjustment_error}", file=sys.stderr)
    given = "given" if args.pixel_size_mm is not None else \
        "the default, the camera of Civera et al. 2009: give --pixel-size-mm for yours"
    print(f"pixel size {options.pixel_size_mm} mm ({given}): it sets the units of k1 (mm^-2) and k2 (mm^-4) "
          "only; f and the principal point do not depend on it")
    if verdict.claims:
        print(f"OpenCV camera: {Path(args.out) / written['files']['opencv_yaml']} (within "
              f"{written['opencv_camera']['max_difference_px']:.3f} px of the civera-radial model)")
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if not verdict.trusted:
        print(f"how to record a self-calibration walk: {CAPTURE_GUIDE}")
    print(f"report: {Path(args.out) / 'report.html'}")
    return verdict.exit_code
