"""`rscalib linedelay` and `rscalib localize`: video of a target -> line delay (or, with a
known line delay, the continuous-time trajectory) with report and camera files (SPEC §5)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from .common import EXIT_OK, EXIT_UNDETERMINED


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("video", help="video file, or a folder of images (file-name order, optional timestamps.txt)")
    p.add_argument("--target", required=True, help="target YAML (Kalibr fields: checkerboard, circlegrid, aprilgrid; or ChArUco)")
    p.add_argument("--camera", required=True, help="camera YAML (OpenCV FileStorage or Kalibr camchain)")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--pixel-sigma", type=float, default=None,
                   help="detection noise in px (default: estimated from the target grid)")
    p.add_argument("--robust", choices=["none", "huber", "cauchy"], default="none",
                   help="robust loss on the standardised errors, against bad detections (none)")
    p.add_argument("--rows", type=int, default=None, help="sensor rows read out (default: image height)")
    p.add_argument("--workers", type=int, default=None, help="detection processes (default: all cores)")
    p.add_argument("--no-cache", action="store_true", help="re-run detection even if cached")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def add_parser(sub) -> None:
    p = sub.add_parser("linedelay", help="estimate the rolling-shutter line delay from a video of a target",
                       description="Detect the target in every frame, estimate the continuous-time trajectory and "
                                   "the line delay jointly, and write result.json, report.html, plots, the "
                                   "trajectory and camera files with the line delay (OpenCV, Kalibr, Gyroflow).")
    _add_common(p)
    p.add_argument("--max-rounds", type=int, default=8, help="knot-adaptation rounds at most (8)")
    p.set_defaults(func=run_linedelay)

    q = sub.add_parser("localize", help="continuous-time trajectory with a known line delay, vs per-frame PnP",
                       description="Estimate the camera trajectory of a rolling-shutter video with a known line "
                                   "delay (paper §5.1) and compare it with per-frame global-shutter PnP.")
    _add_common(q)
    q.add_argument("--line-delay", type=float, default=None,
                   help="line delay in s/row (default: from the camera file, if it has one)")
    q.set_defaults(func=run_localize)


def _check_paths(args) -> None:
    if not Path(args.video).exists():
        raise InputError(f"video not found: {args.video}")
    for name in ("target", "camera"):
        if not Path(getattr(args, name)).is_file():
            raise InputError(f"{name} file not found: {getattr(args, name)}")
    if args.pixel_sigma is not None and not args.pixel_sigma > 0:
        raise InputError("--pixel-sigma must be positive")
    if args.rows is not None and args.rows <= 0:
        raise InputError("--rows must be positive")


def _say(args, text: str) -> None:
    if not args.quiet:
        print(text, file=sys.stderr)


def _detect(args, camera):
    from ..detect import detect_video
    from ..targets import load_target

    target = load_target(args.target)
    detection = detect_video(args.video, target, workers=args.workers, cache=not args.no_cache,
                             progress=not args.quiet)
    if detection.observations.num_observations == 0:
        raise InputError(f"the target was not detected in any of the {detection.frames_total} frames "
                         "(wrong target file or size?)")
    if tuple(detection.image_size) != (camera.width, camera.height):
        raise InputError(f"the video is {detection.image_size[0]}x{detection.image_size[1]} but the camera file is "
                         f"{camera.width}x{camera.height}")
    for w in detection.warnings:
        _say(args, f"warning: {w}")
    _say(args, f"detection: target in {detection.frames_detected} of {detection.frames_total} frames"
         + (" (cached)" if detection.from_cache else "")
         + ("; dropped: " + ", ".join(f"{k} {v}" for k, v in detection.dropped.items()) if detection.dropped else ""))
    return detection


def _progress(args):
    if args.quiet:
        return None

    def report(r) -> None:
        print(f"  round {r.round}: {r.segments} segments, d = {r.line_delay_s * 1e6:.3f} us/row, "
              f"J/2N = {r.normalised_cost:.3f}, split {r.segments_split} ({r.solve_time_s:.1f} s)", file=sys.stderr)
    return report


def _fps(observations) -> float:
    return float(1.0 / np.median(np.diff(observations.frame_times_s))) if observations.num_frames > 1 else 0.0


def run_linedelay(args) -> int:
    from ..camera_io import read_camera
    from ..linedelay import calibrate_line_delay
    from ..report import write_outputs

    _check_paths(args)
    camera = read_camera(args.camera).camera
    detection = _detect(args, camera)
    _say(args, "estimating trajectory and line delay:")
    result = calibrate_line_delay(detection.observations, camera, args.rows, pixel_sigma=args.pixel_sigma,
                                  robust_loss=args.robust, max_rounds=args.max_rounds, progress=_progress(args))
    result.warnings[:0] = list(detection.warnings)
    extra = {"video": str(args.video), "detection_dropped": detection.dropped,
             "frames_detected": detection.frames_detected, "timestamps_from": detection.timestamps,
             "detection_time_s": detection.detect_time_s}
    summary = write_outputs(result, camera, args.out, frames_total=detection.frames_total, extra=extra,
                            fps=_fps(detection.observations))
    std = result.line_delay_std_s
    print(f"line delay {result.line_delay_s * 1e6:.4f} +- {std * 1e6 if math.isfinite(std) else float('inf'):.4f} "
          f"us/row, readout {result.readout_time_s * 1e3:.4f} ms; J/2N {result.normalised_cost:.3f}; "
          f"{summary['verdict']['headline'].split(': ')[-1]}")
    for w in summary["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    print(f"report: {Path(args.out) / 'report.html'}")
    return EXIT_OK if result.determined else EXIT_UNDETERMINED


def run_localize(args) -> int:
    from ..camera_io import read_camera
    from ..linedelay import localize
    from ..report import plot_trajectory, write_trajectory_csv

    _check_paths(args)
    camera_file = read_camera(args.camera)
    camera = camera_file.camera
    line_delay = args.line_delay if args.line_delay is not None else camera_file.line_delay_s
    if line_delay is None:
        raise InputError("no line delay: pass --line-delay (s/row) or a camera file that has one")
    detection = _detect(args, camera)
    result = localize(detection.observations, camera, args.rows, line_delay_s=line_delay,
                      pixel_sigma=args.pixel_sigma, robust_loss=args.robust, progress=_progress(args))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_trajectory_csv(result, out / "trajectory.csv")
    plot_trajectory(result, out / "trajectory.png")
    comparison = compare_with_pnp(result, camera)
    summary = result.summary_dict() | {"frames_total": detection.frames_total, "gs_pnp_comparison": comparison}
    summary.pop("line_delay_std_s", None)
    (out / "result.json").write_text(json.dumps(summary, indent=2))
    print(f"continuous-time RS trajectory: rms {result.rms_px:.3f} px over {result.observations} points; "
          f"per-frame GS PnP: rms {comparison['gs_pnp_rms_px']:.3f} px; "
          f"mean RS-vs-GS camera-centre difference {comparison['mean_centre_difference_m'] * 1e3:.2f} mm")
    print(f"results: {out / 'result.json'}")
    return EXIT_OK


def compare_with_pnp(result, camera) -> dict:
    """Reprojection RMS of the per-frame GS PnP poses vs the RS trajectory, and how far the
    camera centres of the two differ at the frames' mid-readout times."""
    from .. import _core

    poses = result.frame_poses
    obs = result.used_observations
    t_mid = np.clip(obs.frame_times_s + 0.5 * result.readout_time_s, result.trajectory.t_begin,
                    result.trajectory.t_end)
    rotations, translations = _core.poses_at(result.trajectory, t_mid)
    centre_rs = -np.einsum("nji,nj->ni", rotations, translations)
    r_gs = np.stack([_core.rotation_vector_to_matrix(v) for v in poses.rotation_vector])
    centre_gs = -np.einsum("nji,nj->ni", r_gs, poses.translation)
    diff = np.linalg.norm(centre_rs - centre_gs, axis=1)
    return {"gs_pnp_rms_px": float(np.sqrt(np.nanmean(poses.rms_px ** 2))), "rs_rms_px": result.rms_px,
            "mean_centre_difference_m": float(np.mean(diff)), "max_centre_difference_m": float(np.max(diff))}
