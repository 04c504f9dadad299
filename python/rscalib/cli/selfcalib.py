"""`rscalib selfcalib`: focal length, principal point and radial distortion from a sequence of an
ordinary scene (SOG filter bank, SPEC §4)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import InputError
from .common import EXIT_OK, EXIT_UNDETERMINED


def add_parser(sub) -> None:
    p = sub.add_parser("selfcalib", help="self-calibrate f, principal point and radial distortion from a "
                                         "video or image folder of a natural scene",
                       description="Sequential self-calibration with a Sum-of-Gaussians bank of inverse-depth "
                                   "monocular SLAM EKFs (Civera et al. 2009). An image folder is read in file-name "
                                   "order with an optional timestamps.txt (one time in seconds per line).")
    p.add_argument("source", help="video file or image folder")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--pixel-size-mm", type=float, default=0.0112,
                   help="sensor pixel pitch in mm (the distortion radii are in mm; default 0.0112)")
    p.add_argument("--max-frames", type=int, default=None, help="stop after this many frames")
    p.add_argument("--alpha", type=float, default=None, help="SPRT type I error (default 0.05)")
    p.add_argument("--beta", type=float, default=None, help="SPRT type II error (default 0.1)")
    p.add_argument("--f-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="focal-length range of the initial bank in px (default: the paper's, scaled)")
    p.add_argument("--bank", choices=["sog", "single"], default="sog",
                   help="sog: the paper's grid of Gaussians (default); single: one EKF (the baseline the paper "
                        "compares against), started at --f0 with --f-sigma")
    p.add_argument("--f0", type=float, default=None,
                   help="with --bank single: initial focal length in px (default: the middle of the f range)")
    p.add_argument("--f-sigma", type=float, default=None,
                   help="with --bank single: initial sigma of f in px (default: a quarter of the f range)")
    p.add_argument("--subpixel", choices=["affine", "parabola"], default="affine",
                   help="match refinement: ECC affine alignment of the patch (default) or a parabola through "
                        "the NCC peak")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def bank_grid(args: argparse.Namespace, width: int, height: int) -> dict:
    """initial_bank keyword arguments for the --bank/--f-range/--f0/--f-sigma options."""
    from ..selfcalib.prior import initial_bank

    grid = {"f_range": tuple(args.f_range)} if args.f_range else {}
    if args.bank == "sog":
        if args.f0 is not None or args.f_sigma is not None:
            raise InputError("--f0 and --f-sigma go with --bank single")
        return grid
    default = initial_bank(width, height, args.pixel_size_mm, **grid)
    f_lo, f_hi = default.means[:, 0].min(), default.means[:, 0].max()
    f0 = 0.5 * (f_lo + f_hi) if args.f0 is None else args.f0
    f_sigma = 0.25 * (f_hi - f_lo) if args.f_sigma is None else args.f_sigma
    if not f0 > 0 or not f_sigma > 0:
        raise InputError("--f0 and --f-sigma must be positive")
    # One Gaussian per parameter; _grid gives a count-1 grid the range's middle and sigma range/4.
    return {**grid, "f_range": (f0 - 2 * f_sigma, f0 + 2 * f_sigma), "f_count": 1, "k1_count": 1, "k2_count": 1}


def plot_history(result, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..selfcalib.calibrate import PARAM_NAMES

    units = {"f": "px", "cx": "px", "cy": "px", "k1": "mm⁻²", "k2": "mm⁻⁴"}
    fig, axes = plt.subplots(6, 1, figsize=(8, 12), sharex=True)
    frames = result.history_frame
    for i, name in enumerate(PARAM_NAMES):
        ax = axes[i]
        ax.fill_between(frames, result.history_bounds[:, i, 0], result.history_bounds[:, i, 1], alpha=0.3,
                        label="99 % bounds")
        ax.plot(frames, result.history_mean[:, i], lw=1.2, label="estimate")
        ax.set_ylabel(f"{name} ({units[name]})")
    axes[0].legend(fontsize=8)
    axes[5].semilogy(frames, result.history_gaussians, lw=1.2, color="C3")
    axes[5].set_ylabel("Gaussians")
    axes[5].set_xlabel("frame")
    axes[0].set_title("Self-calibration: estimates with 99 % bounds, and the number of Gaussians")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from .. import _core
    from ..io.cameras import write_opencv_yaml
    from ..io.video import open_source
    from ..selfcalib.calibrate import FrontEndOptions, civera_to_opencv, self_calibrate

    if not Path(args.source).exists():
        raise InputError(f"not found: {args.source}")
    if not args.pixel_size_mm > 0:
        raise InputError("--pixel-size-mm must be positive")
    if args.max_frames is not None and args.max_frames < 2:
        raise InputError("--max-frames must be at least 2")
    source = open_source(args.source)
    frames_iter = source.frames(gray=True)
    first = next(frames_iter, None)
    while first is not None and first.image is None:
        first = next(frames_iter, None)
    if first is None:
        raise InputError(f"{args.source}: no readable frames")
    height, width = first.image.shape[:2]

    def frames():
        yield first.time_s, first.image
        for frame in frames_iter:
            if frame.image is not None:
                yield frame.time_s, frame.image

    options = _core.SogOptions()
    if args.alpha is not None:
        options.sprt_alpha = args.alpha
    if args.beta is not None:
        options.sprt_beta = args.beta
    grid = bank_grid(args, width, height)
    total = args.max_frames or source.frame_count_estimate
    bar = None
    if not args.quiet:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        bar = Progress(TextColumn("self-calibrating"), BarColumn(), MofNCompleteColumn(),
                       TextColumn("{task.fields[state]}"), TimeRemainingColumn(), transient=False,
                       console=__import__("rich.console").console.Console(file=sys.stderr))
        task = bar.add_task("sog", total=total, state="")
        bar.start()

    def progress(k, bank):
        if bar is not None:
            mean = bank.calibration_mean
            bar.update(task, completed=k + 1, state=f"f {mean[0]:.1f} px, {bank.num_gaussians} Gaussians")

    try:
        result = self_calibrate(frames(), (width, height), pixel_size_mm=args.pixel_size_mm, options=options,
                                grid=grid, front_end=FrontEndOptions(subpixel=args.subpixel), max_frames=args.max_frames, progress=progress)
    finally:
        if bar is not None:
            bar.stop()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = result.summary_dict()
    summary["bank"] = args.bank
    summary["subpixel"] = args.subpixel
    opencv, max_error = civera_to_opencv(result.camera())
    write_opencv_yaml(opencv, out / "camera.yaml")
    summary["opencv_camera"] = {"file": "camera.yaml", "model": "pinhole-radtan (k1, k2, k3 fitted; p1 = p2 = 0)",
                                "max_difference_px": max_error}
    summary["timestamps_from"] = source.timestamps_source
    plot_history(result, out / "history.png")
    (out / "result.json").write_text(json.dumps(summary, indent=2))
    m, b = result.mean, result.bounds_99
    print(f"f {m[0]:.2f} px [{b[0, 0]:.2f}, {b[0, 1]:.2f}], cx {m[1]:.2f}, cy {m[2]:.2f}, k1 {m[3]:.5f} mm^-2, "
          f"k2 {m[4]:.5f} mm^-4; {result.gaussians_left} of {result.gaussians_initial} Gaussians left after "
          f"{result.frames_processed} frames ({result.frames_per_s:.1f} frames/s)")
    print(f"OpenCV camera: {out / 'camera.yaml'} (within {max_error:.3f} px of the civera-radial model)")
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return EXIT_OK if result.gaussians_left == 1 else EXIT_UNDETERMINED
