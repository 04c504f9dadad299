"""`rscalib intrinsics`: intrinsic calibration from stills or a video of a target."""
from __future__ import annotations

import argparse
import json
from dataclasses import replace

from .common import EXIT_OK, number, whole, workers


def add_parser(sub) -> None:
    p = sub.add_parser(
        "intrinsics", help="calibrate intrinsics and distortion from images or a video of a target",
        description="Intrinsic calibration with OpenCV from still images (files, a glob or a folder) or a "
                    "video of a calibration target. Writes OUT/camera.yaml (OpenCV; the --camera of the other "
                    "commands), the same camera for Kalibr (camchain.yaml), Gyroflow (gyroflow_lens_profile.json), "
                    "ROS (camera_info.yaml), mrcal (camera.cameramodel) and COLMAP (cameras.txt), the detections "
                    "as mrcal's corners.vnl, and OUT/result.json (docs/formats.md).")
    p.add_argument("inputs", nargs="+", metavar="IMAGES_OR_VIDEO",
                   help="a video, an image folder, or image files (shell glob or quoted pattern)")
    p.add_argument("--target", required=True, metavar="TARGET.yaml", help="Kalibr-style target file")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--model", choices=["pinhole-radtan", "pinhole-equidistant"], default="pinhole-radtan",
                   help="camera model (pinhole-radtan)")
    p.add_argument("--max-views", type=whole(3, 10_000, " views"), default=40, metavar="N",
                   help="use at most N views, chosen sharp and well spread (40)")
    p.add_argument("--workers", type=workers, default=None, metavar="N", help="detection processes (all cores)")
    p.add_argument("--max-blur-px", type=number(0.0, 100.0, " px", low_open=True), default=None, metavar="PX",
                   help="drop frames whose edges are wider than this (8)")
    p.add_argument("--subpix-window", type=whole(1, 50, " px"), default=None, metavar="PX",
                   help="cornerSubPix half-window (default: a quarter of the grid step; OpenCV's sample uses 11)")
    p.add_argument("--no-cache", action="store_true", help="detect again even if cached detections exist")
    p.add_argument("--cache-dir", default=None, metavar="DIR", help="detection cache (~/.cache/rscalib/detections)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_lens_profile_options(p)
    p.set_defaults(func=run)


def add_lens_profile_options(p: argparse.ArgumentParser) -> None:
    """--camera-brand, --camera-model, --lens-model: what Gyroflow shows of a lens profile."""
    group = p.add_argument_group("lens profile (the names Gyroflow shows and searches)")
    group.add_argument("--camera-brand", default="", metavar="NAME", help="e.g. GoPro, Sony")
    group.add_argument("--camera-model", default="", metavar="NAME", help="e.g. HERO9 Black, a7 III")
    group.add_argument("--lens-model", default="", metavar="NAME", help="e.g. Wide, 16-35mm at 16mm")


def lens_profile_names(args: argparse.Namespace) -> dict:
    return {"camera_brand": args.camera_brand.strip(), "camera_model": args.camera_model.strip(),
            "lens_model": args.lens_model.strip()}


def run(args: argparse.Namespace) -> int:
    from ..detection.detectors import DetectOptions
    from ..detection.pipeline import detect_video
    from ..errors import InputError
    from ..intrinsics import calibrate_intrinsics, write_intrinsics
    from ..io.limits import bounded_workers
    from ..io.output_folder import check_output_folder, expected_output_bytes
    from ..io.targets import load_target
    from ..io.video import open_source

    if args.max_views < 3:
        raise InputError("--max-views must be at least 3")
    if args.workers is not None and args.workers < 1:
        raise InputError("--workers must be at least 1")
    target = load_target(args.target)
    options = DetectOptions()
    if args.max_blur_px is not None:
        if not args.max_blur_px > 0:
            raise InputError("--max-blur-px must be positive")
        options = replace(options, max_blur_px=args.max_blur_px)
    if args.subpix_window is not None:
        if args.subpix_window < 1:
            raise InputError("--subpix-window must be at least 1")
        options = replace(options, subpix_window_px=args.subpix_window)
    check_output_folder(args.out, expected_output_bytes(32, list(args.inputs), per_input_byte=0.1), inputs=args.inputs)
    source = args.inputs[0] if len(args.inputs) == 1 else args.inputs
    workers = bounded_workers(open_source(source), args.workers)   # frame sizes from headers, before decoding
    detections = detect_video(source, target, workers=workers, cache=not args.no_cache,
                              cache_dir=args.cache_dir, progress=not args.quiet, options=options)
    result = calibrate_intrinsics(detections, model=args.model, max_views=args.max_views)
    camera_path, json_path = write_intrinsics(result, args.out, detections,
                                              extra={"target": {"target_type": target.target_type, **target.spec}},
                                              inputs={"images": [str(i) for i in args.inputs], "target": args.target},
                                              gyroflow=lens_profile_names(args))

    dropped = ", ".join(f"{n} {r.replace('_', ' ')}" for r, n in sorted(detections.dropped.items())) or "none"
    cached = " (cached)" if detections.from_cache else ""
    print(f"{target.describe()}: {detections.frames_total} frames, {detections.frames_detected} with the target"
          f"{cached}; dropped: {dropped}; {len(result.view_index)} views used")
    print(f"  {result.model}, {result.camera.width}x{result.camera.height}, RMS {result.rms_px:.3f} px")
    for name, value, std in zip(result.param_names, result.params, result.param_std):
        unit = " px" if name in ("fx", "fy", "cx", "cy") else ""
        print(f"  {name:>3} = {value:12.6g} +- {std:.3g}{unit}")
    worst = sorted(zip(result.view_rms_px, result.view_labels), reverse=True)[:3]
    print("  largest per-view RMS: " + ", ".join(f"{label} {e:.3f} px" for e, label in worst))
    for warning in detections.warnings + result.warnings:
        print(f"  warning: {warning}")
    summary = json.loads(json_path.read_text())
    for note in summary.get("export_notes", []):
        print(f"  note: {note}")
    others = [name for role, name in summary["files"].items() if role != "opencv_yaml"]
    print(f"  wrote {camera_path}, {json_path} and, for other tools, {', '.join(others)} in {args.out}")
    return EXIT_OK
