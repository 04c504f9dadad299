"""`rscalib simulate`: render a rolling-shutter video of a target with its ground truth
(rscalib.sim.target_video; docs/architecture.md)."""
from __future__ import annotations

import argparse
import re
import sys

from ..errors import InputError
from .common import EXIT_OK, add_force, image_size, number, seconds_in, seed, whole, workers

# Renders of at most an hour (the dense trajectory and the truth grow with the duration).
MAX_DURATION_S = 3600.0


DEFAULT_SIZE = "640x480"   # --size of the default camera


def add_parser(sub) -> None:
    p = sub.add_parser(
        "simulate", help="render a rolling-shutter video of a calibration target, with ground truth",
        description="Render a synthetic rolling-shutter video: every image row is drawn at its own time "
                    "t_i + v*d (supersampled, optional motion blur over the exposure, noise, lens distortion). "
                    "Writes video.avi (lossless FFV1; frame i stamped i/fps), truth.json (line delay, trajectory, "
                    "exact rolling-shutter projections of the target points), camera.yaml (OpenCV) and "
                    "target.yaml (Kalibr).")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    add_force(p)
    p.add_argument("--line-delay", type=seconds_in(-0.01, 0.01), default=30e-6, metavar="D",
                   help="line delay d per row, seconds or with a unit (30us)")
    p.add_argument("--fps", type=number(1.0, 1000.0, " fps"), default=30.0, help="frame rate (30); frame i is stamped i/fps")
    p.add_argument("--size", type=image_size, default=None, metavar="WxH",
                   help="image size WIDTHxHEIGHT of the default camera; f = 500 px * width/640 (640x480)")
    p.add_argument("--camera", default=None, metavar="FILE",
                   help="camera file (OpenCV YAML or Kalibr camchain) instead of the default camera; sets the size")
    p.add_argument("--target", default="checkerboard", metavar="TARGET",
                   help="checkerboard (9x6, 40 mm), circlegrid (7x5, 40 mm), acircles (4x11, 20 mm), "
                        "aprilgrid (Kalibr 6x6, 88 mm) or a Kalibr target YAML (default checkerboard)")
    p.add_argument("--duration", type=seconds_in(0.0, MAX_DURATION_S, low_open=True), default=5.0, metavar="T", help="seconds of video (5)")
    p.add_argument("--exposure", type=seconds_in(0.0, 1.0), default=0.0, metavar="E",
                   help="exposure per row, seconds or with a unit (0 = no motion blur)")
    p.add_argument("--noise", type=number(0.0, 255.0), default=2.0, help="Gaussian intensity noise, 8-bit grey levels (2)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the hand-held motion and the noise (0)")
    p.add_argument("--motion", type=number(0.0, 100.0), default=1.0,
                   help="amplitude of the hand-held motion; 0 = static camera (1)")
    p.add_argument("--supersample", type=whole(1, 8), default=3, metavar="N", help="NxN sub-pixel samples per pixel (3)")
    p.add_argument("--exposure-samples", type=whole(1, 256), default=None, metavar="K",
                   help="times sampled over the exposure (default: enough for <= 0.5 px steps, at most 64)")
    p.add_argument("--frames-dir", nargs="?", const=True, default=None, metavar="DIR",
                   help="also write PNG frames and timestamps.txt (default folder OUT/frames)")
    p.add_argument("--no-video", action="store_true", help="do not write the video file (use with --frames-dir)")
    p.add_argument("--codec", choices=["auto", "ffv1", "mjpg"], default="auto",
                   help="video codec: FFV1 (lossless), MJPG (lossy) or auto (FFV1, else MJPG)")
    p.add_argument("--flicker-hz", type=number(0.0, 1e6, " Hz", low_open=True), default=None, metavar="HZ",
                   help="light flickering at HZ (its intensity frequency: 100 for 50 Hz mains), for `rscalib flicker`")
    p.add_argument("--flicker-depth", type=number(0.0, 1.0), default=0.3, metavar="A",
                   help="flicker modulation depth: gain 1 + A sin(2 pi HZ t + phase) (0.3)")
    p.add_argument("--flicker-phase", type=number(-1e3, 1e3, " rad"), default=0.0, metavar="RAD", help="flicker phase at t = 0, radians (0)")
    p.add_argument("--workers", type=workers, default=None, metavar="N", help="rendering threads (default: up to 4)")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("--scene", action="store_true",
                   help="instead of a target video: a hand-held walk through a textured room, seen by the "
                        "self-calibration paper's 320x240 camera (PNG frames, timestamps.txt, truth.json in OUT), "
                        "for `rscalib selfcalib OUT --pixel-size-mm 0.0112`; uses --duration, --fps, --seed, --noise")
    led = p.add_argument_group(
        "LED / flicker footage (--led)",
        "Instead of a target video: frames of a lamp or diffuser lit by a flickering light, as real LED "
        "recordings look (square wave with a duty cycle, clipping, vignetting, a lamp filling part of the frame, "
        "overlays, JPEG), for `rscalib flicker OUT --frequency HZ`. Uses --flicker-hz (required), --line-delay, "
        "--size, --fps, --exposure, --noise, --seed; frames from --duration unless --frames is given.")
    led.add_argument("--led", action="store_true", help="render LED / flicker footage (writes frames, "
                     "timestamps.txt and truth.json in OUT)")
    led.add_argument("--frames", type=whole(1, 10000), default=None, metavar="N", help="number of frames (e.g. 1 for a still)")
    led.add_argument("--waveform", choices=["square", "sine"], default="square", help="light waveform (square)")
    led.add_argument("--duty", type=number(0.0, 1.0), default=0.5, help="fraction of each period the light is on (0.5)")
    led.add_argument("--off-level", type=number(0.0, 1.0), default=0.0, metavar="L",
                     help="light level when off, relative to on (0)")
    led.add_argument("--lamp", choices=["flat", "disk", "partial"], default="flat",
                     help="flat: the light fills the frame; disk: a lit disk on a dark surround; partial: the "
                          "light covers the left part of the frame (flat)")
    led.add_argument("--brightness", type=number(0.0, 100.0), default=0.8,
                     help="level of the light when on, fraction of full scale; above 1 the bands clip (0.8)")
    led.add_argument("--vignetting", type=number(0.0, 1.0), default=0.0, help="relative fall-off at the corners (0)")
    led.add_argument("--overlay", default=None, metavar="TEXT", help="a text overlay and a box drawn on the frames")
    led.add_argument("--blob", action="store_true", help="an out-of-focus bright blob on the right")
    led.add_argument("--jpeg-quality", type=whole(1, 100), default=None, metavar="Q",
                     help="write JPEG frames at quality Q (default: lossless PNG)")
    led.add_argument("--readout", choices=["top-to-bottom", "bottom-to-top"], default="top-to-bottom",
                     help="sensor readout direction; bottom-to-top gives a negative line delay (top-to-bottom)")
    led.add_argument("--no-timestamps", action="store_true", help="do not write timestamps.txt (frames of "
                     "unknown times)")
    p.set_defaults(func=run)


def _check_out(args: argparse.Namespace, size, frames: float, copies: int = 1) -> None:
    """--out before rendering: writable, with room for the frames (raw size: generous for FFV1/PNG)."""
    from ..io.output_folder import check_output_folder, expected_output_bytes

    check_output_folder(args.out, expected_output_bytes(16, extra_bytes=float(frames) * size[0] * size[1] * copies),
                        command=args.command, force=args.force)


def run_led(args: argparse.Namespace) -> int:
    """`--led`: LED / flicker footage (rscalib.sim.flicker_light) with its truth."""
    import numpy as np

    from ..sim.flicker_light import FlickerLight, FlickerScene, write_flicker_sequence

    if args.flicker_hz is None:
        raise InputError("--led needs --flicker-hz (the light's intensity frequency)")
    match = re.fullmatch(r"(\d+)x(\d+)", args.size)
    if not match:
        raise InputError(f"--size must be WIDTHxHEIGHT (got {args.size!r})")
    size = (int(match.group(1)), int(match.group(2)))
    if not (0 < size[0] <= 20000 and 16 <= size[1] <= 20000):
        raise InputError(f"--size {args.size}: width 1..20000 and height 16..20000")
    if not (np.isfinite(args.fps) and args.fps > 0):
        raise InputError("--fps must be positive")
    count = args.frames if args.frames is not None else int(round(args.duration * args.fps))
    if not 1 <= count <= 10000:
        raise InputError(f"{count} frames: give 1 to 10000 (--frames or --duration x --fps)")
    if not (np.isfinite(args.line_delay) and args.line_delay > 0):
        raise InputError("--line-delay must be positive (use --readout bottom-to-top for the other direction)")
    if not (0 < args.duty < 1):
        raise InputError(f"--duty must be in (0, 1) (got {args.duty})")
    for name in ("brightness", "vignetting", "exposure", "noise"):
        value = getattr(args, name)
        if not (np.isfinite(value) and value >= 0):
            raise InputError(f"--{name} must be a finite number >= 0 (got {value})")
    if args.jpeg_quality is not None and not 1 <= args.jpeg_quality <= 100:
        raise InputError("--jpeg-quality must be 1..100")
    d = args.line_delay * (-1.0 if args.readout == "bottom-to-top" else 1.0)
    light = FlickerLight(args.flicker_hz, duty=args.duty, off_level=args.off_level, waveform=args.waveform,
                         phase=args.flicker_phase / (2 * np.pi))
    scene = FlickerScene(lamp=args.lamp, brightness=args.brightness, vignetting=args.vignetting,
                         overlay_text=args.overlay, blob=args.blob)
    _check_out(args, size, count)
    times = np.arange(count) / args.fps
    truth = write_flicker_sequence(args.out, light, scene, size, d, times, exposure_s=args.exposure,
                                   noise=args.noise, jpeg_quality=args.jpeg_quality, seed=args.seed,
                                   timestamps=not args.no_timestamps)
    if not args.quiet:
        period_rows = 1.0 / (args.flicker_hz * abs(d))
        print(f"rscalib simulate --led: {count} frame(s) {size[0]}x{size[1]}, {args.flicker_hz:g} Hz "
              f"{args.waveform} light (duty {args.duty:g}), line delay {d * 1e6:.4f} us/row ({args.readout}), "
              f"bands every {period_rows:.2f} rows ({size[1] / period_rows:.2f} per frame), "
              f"{truth['clipped_fraction']:.0%} of pixels clipped")
        print(f"  wrote {'JPEG' if args.jpeg_quality else 'PNG'} frames"
              + ("" if args.no_timestamps else ", timestamps.txt") + f" and truth.json to {args.out}")
        print(f"  try: rscalib flicker {args.out} --frequency {args.flicker_hz:g} --out flicker_result")
    return EXIT_OK


def run_scene(args: argparse.Namespace) -> int:
    """`--scene`: a self-calibration sequence (rscalib.sim.scene_video) with its truth."""
    from ..reference_cameras import PAPER_CAMERA_PARAMS, PAPER_PIXEL_SIZE_MM
    from ..sim.scene_video import render_scene_sequence

    if not (args.duration > 0 and args.fps > 0):
        raise InputError("--duration and --fps must be positive")
    num_frames = max(2, int(round(args.duration * args.fps)))
    _check_out(args, (320, 240), num_frames)
    render_scene_sequence(args.out, num_frames=num_frames, seed=args.seed, fps=args.fps, noise_sigma=args.noise)
    if not args.quiet:
        f, cx, cy, k1, k2 = PAPER_CAMERA_PARAMS
        print(f"rscalib simulate --scene: {num_frames} frames 320x240 at {args.fps:g} fps in {args.out}; truth "
              f"f {f} px, (cx, cy) ({cx}, {cy}) px, k1 {k1} mm^-2, k2 {k2} mm^-4")
        print(f"  try: rscalib selfcalib {args.out} --pixel-size-mm {PAPER_PIXEL_SIZE_MM} --out selfcal")
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    from ..sim.target_video import render_video

    if args.scene and args.led:
        raise InputError("give --scene or --led, not both")
    if args.scene:
        if args.size not in (None, "320x240") or args.camera:   # the room walk's camera is fixed: say so
            raise InputError("--scene renders the self-calibration paper's 320x240 camera; --size and --camera "
                             "are for target videos and LED footage")
        return run_scene(args)
    args.size = args.size or DEFAULT_SIZE
    if args.led:
        return run_led(args)
    if args.no_video and not args.frames_dir:
        raise InputError("--no-video needs --frames-dir (nothing would be written)")
    if args.workers is not None and args.workers < 1:
        raise InputError("--workers must be >= 1")
    camera = None
    if args.camera:
        from ..io.cameras import load_camera
        camera = load_camera(args.camera).camera
    match = re.fullmatch(r"(\d+)x(\d+)", args.size)
    size = (camera.width, camera.height) if camera is not None else \
        (int(match.group(1)), int(match.group(2))) if match else (640, 480)
    _check_out(args, size, args.duration * args.fps, copies=2 if args.frames_dir else 1)
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
