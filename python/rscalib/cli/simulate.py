"""`rscalib simulate`: render a rolling-shutter video of a target with its ground truth
(rscalib.sim.target_video; docs/architecture.md)."""
from __future__ import annotations

import argparse
import re
import sys

from ..errors import InputError
from .common import EXIT_OK

_TIME_UNITS = {"": 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


def seconds(text: str) -> float:
    """A duration in seconds, optionally with a unit: 30e-6, 30us, 0.03ms, 5ms, 1s."""
    match = re.fullmatch(r"\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*(s|ms|us|µs|ns)?\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"not a time: {text!r} (e.g. 30e-6, 30us, 5ms)")
    return float(match.group(1)) * _TIME_UNITS[match.group(2) or ""]


def add_parser(sub) -> None:
    p = sub.add_parser(
        "simulate", help="render a rolling-shutter video of a calibration target, with ground truth",
        description="Render a synthetic rolling-shutter video: every image row is drawn at its own time "
                    "t_i + v*d (supersampled, optional motion blur over the exposure, noise, lens distortion). "
                    "Writes video.avi (lossless FFV1; frame i stamped i/fps), truth.json (line delay, trajectory, "
                    "exact rolling-shutter projections of the target points), camera.yaml (OpenCV) and "
                    "target.yaml (Kalibr).")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--line-delay", type=seconds, default=30e-6, metavar="D",
                   help="line delay d per row, seconds or with a unit (30us)")
    p.add_argument("--fps", type=float, default=30.0, help="frame rate (30); frame i is stamped i/fps")
    p.add_argument("--size", default="640x480", metavar="WxH",
                   help="image size WIDTHxHEIGHT of the default camera; f = 500 px * width/640 (640x480)")
    p.add_argument("--camera", default=None, metavar="FILE",
                   help="camera file (OpenCV YAML or Kalibr camchain) instead of the default camera; sets the size")
    p.add_argument("--target", default="checkerboard", metavar="TARGET",
                   help="checkerboard (9x6, 40 mm), circlegrid (7x5, 40 mm), acircles (4x11, 20 mm), "
                        "aprilgrid (Kalibr 6x6, 88 mm) or a Kalibr target YAML (default checkerboard)")
    p.add_argument("--duration", type=seconds, default=5.0, metavar="T", help="seconds of video (5)")
    p.add_argument("--exposure", type=seconds, default=0.0, metavar="E",
                   help="exposure per row, seconds or with a unit (0 = no motion blur)")
    p.add_argument("--noise", type=float, default=2.0, help="Gaussian intensity noise, 8-bit grey levels (2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the hand-held motion and the noise (0)")
    p.add_argument("--motion", type=float, default=1.0,
                   help="amplitude of the hand-held motion; 0 = static camera (1)")
    p.add_argument("--supersample", type=int, default=3, metavar="N", help="NxN sub-pixel samples per pixel (3)")
    p.add_argument("--exposure-samples", type=int, default=None, metavar="K",
                   help="times sampled over the exposure (default: enough for <= 0.5 px steps, at most 64)")
    p.add_argument("--frames-dir", nargs="?", const=True, default=None, metavar="DIR",
                   help="also write PNG frames and timestamps.txt (default folder OUT/frames)")
    p.add_argument("--no-video", action="store_true", help="do not write the video file (use with --frames-dir)")
    p.add_argument("--codec", choices=["auto", "ffv1", "mjpg"], default="auto",
                   help="video codec: FFV1 (lossless), MJPG (lossy) or auto (FFV1, else MJPG)")
    p.add_argument("--flicker-hz", type=float, default=None, metavar="HZ",
                   help="light flickering at HZ (its intensity frequency: 100 for 50 Hz mains), for `rscalib flicker`")
    p.add_argument("--flicker-depth", type=float, default=0.3, metavar="A",
                   help="flicker modulation depth: gain 1 + A sin(2 pi HZ t + phase) (0.3)")
    p.add_argument("--flicker-phase", type=float, default=0.0, metavar="RAD", help="flicker phase at t = 0, radians (0)")
    p.add_argument("--workers", type=int, default=None, metavar="N", help="rendering threads (default: up to 4)")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("--scene", action="store_true",
                   help="instead of a target video: a hand-held walk through a textured room, seen by the "
                        "self-calibration paper's 320x240 camera (PNG frames, timestamps.txt, truth.json in OUT), "
                        "for `rscalib selfcalib OUT --pixel-size-mm 0.0112`; uses --duration, --fps, --seed, --noise")
    p.set_defaults(func=run)


def run_scene(args: argparse.Namespace) -> int:
    """`--scene`: a self-calibration sequence (rscalib.sim.scene_video) with its truth."""
    from ..selfcalib.prior import PAPER_CAMERA_PARAMS, PAPER_PIXEL_SIZE_MM
    from ..sim.scene_video import render_scene_sequence

    if not (args.duration > 0 and args.fps > 0):
        raise InputError("--duration and --fps must be positive")
    num_frames = max(2, int(round(args.duration * args.fps)))
    render_scene_sequence(args.out, num_frames=num_frames, seed=args.seed, fps=args.fps, noise_sigma=args.noise)
    if not args.quiet:
        f, cx, cy, k1, k2 = PAPER_CAMERA_PARAMS
        print(f"rscalib simulate --scene: {num_frames} frames 320x240 at {args.fps:g} fps in {args.out}; truth "
              f"f {f} px, (cx, cy) ({cx}, {cy}) px, k1 {k1} mm^-2, k2 {k2} mm^-4")
        print(f"  try: rscalib selfcalib {args.out} --pixel-size-mm {PAPER_PIXEL_SIZE_MM} --out selfcal")
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    from ..sim.target_video import render_video

    if args.scene:
        return run_scene(args)
    if args.no_video and not args.frames_dir:
        raise InputError("--no-video needs --frames-dir (nothing would be written)")
    if args.workers is not None and args.workers < 1:
        raise InputError("--workers must be >= 1")
    camera = None
    if args.camera:
        from ..io.cameras import load_camera
        camera = load_camera(args.camera).camera
    result = render_video(args.out, line_delay_s=args.line_delay, fps=args.fps, size=args.size,
                          target=args.target, duration_s=args.duration, exposure_s=args.exposure,
                          noise=args.noise, seed=args.seed, camera=camera, motion=args.motion,
                          supersample=args.supersample, exposure_samples=args.exposure_samples,
                          video=not args.no_video, frames_dir=args.frames_dir, codec=args.codec,
                          flicker_hz=args.flicker_hz, flicker_depth=args.flicker_depth,
                          flicker_phase_rad=args.flicker_phase, workers=args.workers, progress=not args.quiet)
    if not args.quiet:
        c = result.camera
        written = [p.name for p in (result.video_path, result.truth_path, result.camera_path, result.target_path) if p]
        if result.frames_dir is not None:
            written.append(f"{result.frames_dir.name}/ ({result.num_frames} PNG + timestamps.txt)")
        print(f"rscalib simulate: {result.num_frames} frames {c.width}x{c.height} at {result.fps:g} fps, "
              f"{result.target.target_type}, line delay {result.line_delay_s * 1e6:.3f} us/row "
              f"(readout {result.line_delay_s * c.height * 1e3:.3f} ms)"
              + (f", light flickering at {args.flicker_hz:g} Hz (depth {args.flicker_depth:g})"
                 if args.flicker_hz is not None else ""))
        print(f"  rendered in {result.render_seconds:.1f} s ({result.frames_per_second_rendered:.1f} frames/s)"
              + (f", codec {result.codec}" if result.codec else ""))
        print(f"  wrote {', '.join(written)} to {result.out_dir}")
        sys.stdout.flush()
    return EXIT_OK
