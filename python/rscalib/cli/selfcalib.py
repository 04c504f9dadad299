"""`rscalib selfcalib`: focal length, principal point and radial distortion from a sequence of an
ordinary scene (Sum-of-Gaussians filter bank, Civera et al. 2009; docs/sog.md). Parses, delegates
to rscalib.selfcalib (calibrate, report) and prints."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from .common import CAPTURE_GUIDE, EXIT_OK, EXIT_UNDETERMINED, FOCAL_PX, FRAMES, number


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
    p.add_argument("--pixel-size-mm", type=number(1e-4, 1.0, " mm"), default=0.0112,
                   help="sensor pixel pitch in mm (the distortion radii are in mm; default 0.0112)")
    p.add_argument("--max-frames", type=FRAMES, default=None, help="stop after this many frames")
    p.add_argument("--line-delay", type=number(0.0, 1e-3, " s/row"), default=0.0, metavar="S_PER_ROW",
                   help="the camera's rolling-shutter line delay in s/row (e.g. `rscalib linedelay`'s "
                        "line_delay_s): every measurement is moved to one time per frame (docs/sog.md §18); "
                        "default 0: the bundle adjustment estimates it from the tracks (docs/sog.md §21; "
                        "with --no-bundle: treated as a global shutter)")
    p.add_argument("--f-range", type=FOCAL_PX, nargs=2, default=None, metavar=("LO", "HI"),
                   help="focal lengths in px the candidates start from (default: a wide range for the image size)")
    advanced = p.add_argument_group("advanced (baselines and tuning for experiments; the defaults are the method)")
    advanced.add_argument("--alpha", type=number(0.0, 1.0, low_open=True), default=None,
                          help="chance of dropping a right candidate camera too early (default 0.05)")
    advanced.add_argument("--beta", type=number(0.0, 1.0, low_open=True), default=None,
                          help="chance of keeping a wrong candidate camera too long (default 0.1)")
    advanced.add_argument("--bank", choices=["sog", "single"], default="sog",
                          help="sog: many candidate cameras side by side (default); single: one filter started at "
                               "--f0 with --f-sigma (the baseline that can lock onto a wrong focal length)")
    advanced.add_argument("--f0", type=FOCAL_PX, default=None,
                          help="with --bank single: initial focal length in px (default: the middle of the f range)")
    advanced.add_argument("--f-sigma", type=FOCAL_PX, default=None,
                          help="with --bank single: initial sigma of f in px (default: a quarter of the f range)")
    p.add_argument("--subpixel", choices=["affine", "parabola", "tracked"], default="tracked",
                   help="match refinement: 'tracked' (default): each feature's warp carried from its first view, "
                        "tracks that do not drift (docs/sog.md §19); 'affine': ECC alignment from the identity "
                        "in every frame; 'parabola' through the NCC peak")
    p.add_argument("--determined-within", type=number(1e-4, 0.5), default=0.02, metavar="FRACTION",
                   help="call the calibration determined (exit 0) when the 99 %% interval of f is within "
                        "+-FRACTION of f (default 0.02: 2 %%)")
    p.add_argument("--no-bundle", action="store_true",
                   help="the filter's estimate only, without the bundle adjustment over its tracks; "
                        "'determined' is then judged by restarting two single filters (docs/sog.md §15)")
    p.add_argument("--no-restarts", action="store_true",
                   help="with --no-bundle: skip the restart check; the verdict is then 'not checked' and the "
                        "exit code 3")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    if not Path(args.source).exists():
        raise InputError(f"not found: {args.source}")
    if not args.pixel_size_mm > 0:
        raise InputError("--pixel-size-mm must be positive")
    if args.max_frames is not None and args.max_frames < 2:
        raise InputError("--max-frames must be at least 2")
    if args.bank == "sog" and (args.f0 is not None or args.f_sigma is not None):
        raise InputError("--f0 and --f-sigma go with --bank single")


def run(args: argparse.Namespace) -> int:
    from ..io.output_folder import check_output_folder, expected_output_bytes
    from ..selfcalib.calibrate import default_options, read_gray_frames, self_calibrate
    from ..selfcalib.front_end import FrontEndOptions
    from ..selfcalib.prior import single_gaussian_grid
    from ..selfcalib.report import write_selfcalib_outputs

    _check(args)
    check_output_folder(args.out, expected_output_bytes(16), inputs=[args.source])
    video = read_gray_frames(args.source)
    width, height = video.image_size
    if args.bank == "single":
        grid = single_gaussian_grid(width, height, args.pixel_size_mm, f_range=args.f_range, f0=args.f0,
                                    f_sigma=args.f_sigma)
    else:
        grid = {"f_range": tuple(args.f_range)} if args.f_range else {}
    options = default_options()
    if args.alpha is not None:
        options.sprt_alpha = args.alpha
    if args.beta is not None:
        options.sprt_beta = args.beta
    first = [video.frames]

    def frames():   # the first pass reads the opened video; restarts open it again
        return first.pop() if first else read_gray_frames(args.source).frames

    result = self_calibrate(frames, video.image_size, restarts=not args.no_restarts, pixel_size_mm=args.pixel_size_mm, options=options,
                            grid=grid, front_end=FrontEndOptions(subpixel=args.subpixel), max_frames=args.max_frames,
                            progress=not args.quiet, expected_frames=video.frame_count_estimate,
                            line_delay_s=args.line_delay, bundle=not args.no_bundle,
                            max_f_half_width=args.determined_within)
    out = Path(args.out)
    written = write_selfcalib_outputs(
        result, out, extra={"bank": args.bank, "subpixel": args.subpixel, "timestamps_from": video.timestamps_from},
        inputs={"source": args.source, "pixel_size_mm": args.pixel_size_mm, "max_frames": args.max_frames,
                "bank": args.bank, "f_range": args.f_range, "f0": args.f0, "f_sigma": args.f_sigma,
                "sprt_alpha": options.sprt_alpha, "sprt_beta": options.sprt_beta, "subpixel": args.subpixel,
                "restarts": not args.no_restarts, "ransac_hypotheses": options.ransac_hypotheses,
                "max_features": options.max_features, "line_delay_s": args.line_delay,
                "bundle": not args.no_bundle, "determined_within": args.determined_within})
    m, b, fm = result.mean, result.bounds_99, result.filter_mean
    print(f"filter: f {fm[0]:.2f} px, cx {fm[1]:.2f}, cy {fm[2]:.2f}; {result.gaussians_left} of "
          f"{result.gaussians_initial} Gaussians left after {result.frames_processed} frames "
          f"({result.frames_per_s:.1f} frames/s)")
    if result.bundle_error:
        print(f"warning: bundle adjustment failed: {result.bundle_error}", file=sys.stderr)
    print(f"{result.estimate_from} (in camera.yaml): f {m[0]:.2f} px [{b[0, 0]:.2f}, {b[0, 1]:.2f}], "
          f"cx {m[1]:.2f} [{b[1, 0]:.2f}, {b[1, 1]:.2f}], cy {m[2]:.2f} [{b[2, 0]:.2f}, {b[2, 1]:.2f}], "
          f"k1 {m[3]:.5f} mm^-2, k2 {m[4]:.5f} mm^-4 (reported 99 % bounds)")
    line_delay = result.line_delay_estimate()
    if line_delay is not None:
        d, (lo, hi) = line_delay
        print(f"line delay estimated with it (no --line-delay given): {1e6 * d:.2f} us/row "
              f"[{1e6 * lo:.2f}, {1e6 * hi:.2f}] (99 %; `rscalib linedelay` on a target video measures it better)")
    print(f"OpenCV camera: {written.camera_yaml} (within {written.opencv_max_difference_px:.3f} px of the "
          "civera-radial model)")
    if result.determined:
        print(f"determined: {result.reason}")
    else:
        print(f"NOT DETERMINED: {result.reason}; reported bounds f [{b[0, 0]:.1f}, {b[0, 1]:.1f}], "
              f"cx [{b[1, 0]:.1f}, {b[1, 1]:.1f}], cy [{b[2, 0]:.1f}, {b[2, 1]:.1f}]", file=sys.stderr)
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if not result.determined:
        print(f"how to record a self-calibration walk: {CAPTURE_GUIDE}")
    return EXIT_OK if result.determined else EXIT_UNDETERMINED
