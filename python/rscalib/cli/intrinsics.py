"""`rscalib intrinsics`: intrinsic calibration from stills or a video of a target."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..detection.options import MAX_BLUR_PX, MAX_SUBPIX_WINDOW_PX, DetectOptions
from ..intrinsics.options import MODELS, IntrinsicsOptions
from .common import add_force, number, whole, workers


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
    add_force(p)
    p.add_argument("--model", choices=MODELS, default=None, help=f"camera model ({IntrinsicsOptions.model})")
    p.add_argument("--max-views", type=whole(3, 10_000, " views"), default=None, metavar="N",
                   help=f"use at most N views, chosen sharp and well spread ({IntrinsicsOptions.max_views})")
    p.add_argument("--workers", type=workers, default=None, metavar="N", help="detection processes (all cores)")
    p.add_argument("--max-blur-px", type=number(0.0, MAX_BLUR_PX, " px", low_open=True), default=None, metavar="PX",
                   help=f"drop frames whose edges are wider than this ({DetectOptions.max_blur_px:g})")
    p.add_argument("--subpix-window", type=whole(1, MAX_SUBPIX_WINDOW_PX, " px"), default=None, metavar="PX",
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


def intrinsics_options(args: argparse.Namespace) -> IntrinsicsOptions:
    """IntrinsicsOptions from the flags of `rscalib intrinsics` (only the flags typed)."""
    detection = DetectOptions(**{k: v for k, v in dict(
        max_blur_px=args.max_blur_px, subpix_window_px=args.subpix_window, workers=args.workers,
        cache=False if args.no_cache else None, cache_dir=args.cache_dir).items() if v is not None})
    return IntrinsicsOptions(**{k: v for k, v in dict(model=args.model, max_views=args.max_views).items()
                                if v is not None}, detection=detection)


def run(args: argparse.Namespace) -> int:
    from ..intrinsics.pipeline import calibrate_intrinsics
    from ..io.output_folder import check_output_folder, expected_output_bytes

    options = intrinsics_options(args)
    check_output_folder(args.out, expected_output_bytes(32, list(args.inputs), per_input_byte=0.1), inputs=list(args.inputs),
                        command=args.command, force=args.force)
    source = args.inputs[0] if len(args.inputs) == 1 else args.inputs
    run_ = calibrate_intrinsics(source, args.target, options, progress=not args.quiet)
    summary = run_.write(args.out, lens_profile=lens_profile_names(args))
    result, detections = run_.result, run_.detection

    dropped = ", ".join(f"{n} {r.replace('_', ' ')}" for r, n in sorted(detections.dropped.items())) or "none"
    cached = " (cached)" if detections.from_cache else ""
    print(f"{run_.target.describe()}: {detections.frames_total} frames, {detections.frames_detected} with the target"
          f"{cached}; dropped: {dropped}; {len(result.view_index)} views used")
    print(f"  {result.model}, {result.camera.width}x{result.camera.height}, RMS {result.rms_px:.3f} px")
    for name, value, std in zip(result.param_names, result.params, result.param_std):
        unit = " px" if name in ("fx", "fy", "cx", "cy") else ""
        print(f"  {name:>3} = {value:12.6g} +- {std:.3g}{unit}")
    worst = sorted(zip(result.view_rms_px, result.view_labels), reverse=True)[:3]
    print("  largest per-view RMS: " + ", ".join(f"{label} {e:.3f} px" for e, label in worst))
    for warning in detections.warnings + result.warnings:
        print(f"  warning: {warning}")
    for note in summary.get("export_notes", []):
        print(f"  note: {note}")
    others = [name for role, name in summary["files"].items() if role != "opencv_yaml"]
    camera_path, json_path = Path(args.out) / "camera.yaml", Path(args.out) / "result.json"
    print(f"  wrote {camera_path}, {json_path} and, for other tools, {', '.join(others)} in {args.out}")
    return run_.verdict.exit_code
