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
    p.add_argument("--trajectory", choices=["spline", "linear"], default="spline",
                   help="trajectory model: the adaptive cubic B-spline (spline, default) or the baseline of "
                        "per-frame poses interpolated linearly / by SLERP (linear, Hedborg et al. 2012)")
    p.add_argument("--uniform-knots", type=int, default=None, metavar="N",
                   help="spline only: N uniform knot segments, no knot adaptation (for experiments)")
    p.add_argument("--no-standardise", action="store_true",
                   help="spline only: weight errors by 1/sigma instead of the A R A^T standardisation")
    p.add_argument("--no-motion-prior", action="store_true", help="spline only: no acceleration prior")
    p.set_defaults(func=run_linedelay)

    q = sub.add_parser("localize", help="continuous-time trajectory with a known line delay, vs per-frame PnP",
                       description="Estimate the camera trajectory of a rolling-shutter video with a known line "
                                   "delay (paper §5.1) and compare it with per-frame global-shutter PnP.")
    _add_common(q)
    q.add_argument("--line-delay", type=float, default=None,
                   help="line delay in s/row (default: from the camera file, if it has one)")
    q.add_argument("--model", choices=["rs-spline", "gs-pnp"], default="rs-spline",
                   help="rs-spline: continuous-time rolling-shutter trajectory (default); gs-pnp: per-frame "
                        "global-shutter PnP poses, written in the same trajectory.csv format for comparison")
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
    from ..detection.pipeline import detect_video
    from ..io.targets import load_target

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


def _check_model_options(args) -> None:
    """One-line errors for option combinations that mean nothing."""
    if args.uniform_knots is not None and args.uniform_knots < 1:
        raise InputError("--uniform-knots must be at least 1")
    if args.max_rounds < 1:
        raise InputError("--max-rounds must be at least 1")
    if args.trajectory == "linear":
        spline_only = [name for name, used in (("--uniform-knots", args.uniform_knots is not None),
                                               ("--no-standardise", args.no_standardise),
                                               ("--no-motion-prior", args.no_motion_prior)) if used]
        if spline_only:
            raise InputError(f"{', '.join(spline_only)} only apply to --trajectory spline (the linear model has "
                             "no knots, no motion prior and unstandardised errors)")


def run_linedelay(args) -> int:
    from ..io.cameras import load_camera
    from ..linedelay.report import write_outputs
    from ..linedelay.spline import calibrate_line_delay

    _check_paths(args)
    _check_model_options(args)
    camera = load_camera(args.camera).camera
    detection = _detect(args, camera)
    extra = {"video": str(args.video), "detection_dropped": detection.dropped,
             "frames_detected": detection.frames_detected, "timestamps_from": detection.timestamps,
             "detection_time_s": detection.detect_time_s}
    if args.trajectory == "linear":
        return _run_linedelay_linear(args, camera, detection, extra)
    _say(args, "estimating trajectory and line delay:")
    knots = {} if args.uniform_knots is None else {"num_segments": args.uniform_knots, "adaptive_knots": False}
    result = calibrate_line_delay(detection.observations, camera, args.rows, pixel_sigma=args.pixel_sigma,
                                  robust_loss=args.robust, max_rounds=args.max_rounds,
                                  standardise_errors=not args.no_standardise,
                                  use_motion_prior=not args.no_motion_prior, progress=_progress(args), **knots)
    result.warnings[:0] = list(detection.warnings)
    extra |= {"trajectory_model": "spline", "standardise_errors": not args.no_standardise,
              "motion_prior": not args.no_motion_prior, "adaptive_knots": args.uniform_knots is None}
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


def _run_linedelay_linear(args, camera, detection, extra) -> int:
    """The linear/SLERP baseline: result.json, trajectory.csv and the camera files (the
    spline-specific plots and report.html are not written)."""
    from ..io.cameras import write_camera_set
    from ..linedelay.linear import calibrate_line_delay_linear

    _say(args, "estimating per-frame poses and line delay (linear interpolation):")
    result = calibrate_line_delay_linear(detection.observations, camera, args.rows, pixel_sigma=args.pixel_sigma,
                                         robust_loss=args.robust)
    warnings = list(detection.warnings) + list(result.warnings)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    obs = result.used_observations
    times = np.sort(np.concatenate([obs.frame_times_s, obs.frame_times_s + 0.5 * result.readout_time_s]))
    _write_states_csv(out / "trajectory.csv", times, result.evaluate(times))
    files = {"trajectory_csv": "trajectory.csv"}
    camera_files, camera_warnings = write_camera_set(camera, out, result.line_delay_s, fps=_fps(detection.observations),
                                                     rms_px=result.rms_px)
    files |= camera_files
    warnings += camera_warnings
    summary = result.summary_dict() | {"frames_total": detection.frames_total} | extra
    summary["warnings"] = warnings
    summary["files"] = files
    (out / "result.json").write_text(json.dumps(summary, indent=2))
    std = result.line_delay_std_s
    print(f"line delay {result.line_delay_s * 1e6:.4f} +- {std * 1e6 if math.isfinite(std) else float('inf'):.4f} "
          f"us/row, readout {result.readout_time_s * 1e3:.4f} ms; J/2N {result.normalised_cost:.3f} "
          "(linear-interpolation baseline)")
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"results: {out / 'result.json'}")
    return EXIT_OK if result.determined else EXIT_UNDETERMINED


def _write_states_csv(path: Path, times, states) -> None:
    """The trajectory CSV of report.write_trajectory_csv: t_s, p (3), phi (3); rows without a
    pose are left out."""
    ok = np.all(np.isfinite(states), axis=1)
    header = "t_s,p_x_m,p_y_m,p_z_m,phi_x_rad,phi_y_rad,phi_z_rad"
    np.savetxt(path, np.c_[np.asarray(times)[ok], states[ok]], delimiter=",", header=header, comments="",
               fmt="%.9f")


def _run_localize_gs_pnp(args, camera, line_delay) -> int:
    """Per-frame GS PnP poses, each stamped at its frame's mid-readout time t_i + rows d / 2
    (the time a global-shutter fit of a rolling-shutter frame best represents), or at t_i
    when no line delay is known."""
    from .. import _core
    from ..linedelay.pnp import per_frame_pnp

    detection = _detect(args, camera)
    obs = detection.observations
    rows = args.rows if args.rows is not None else obs.image_size[1]
    poses = per_frame_pnp(obs, camera)
    if np.count_nonzero(poses.ok) == 0:
        raise InputError("no frame has enough target points for a PnP pose")
    readout_s = (line_delay or 0.0) * rows
    times = obs.frame_times_s[poses.ok] + 0.5 * readout_s
    states = np.c_[poses.translation[poses.ok], _core.unwrap_rotation_vectors(poses.rotation_vector[poses.ok])]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _write_states_csv(out / "trajectory.csv", times, states)
    rms = float(np.sqrt(np.nanmean(poses.rms_px[poses.ok] ** 2)))
    summary = {"trajectory_model": "gs-pnp", "frames_total": detection.frames_total,
               "frames_used": int(np.count_nonzero(poses.ok)),
               "observations": int(np.sum(np.bincount(obs.frame_index, minlength=obs.num_frames)[poses.ok])),
               "rms_px": rms, "line_delay_s": line_delay, "readout_time_s": readout_s if line_delay else None,
               "time_reference": "mid-readout" if line_delay else "row 0 (no line delay given)",
               "warnings": list(detection.warnings), "files": {"trajectory_csv": "trajectory.csv"}}
    (out / "result.json").write_text(json.dumps(summary, indent=2))
    print(f"per-frame GS PnP: {summary['frames_used']} poses, rms {rms:.3f} px")
    print(f"results: {out / 'result.json'}")
    return EXIT_OK


def run_localize(args) -> int:
    from ..io.cameras import load_camera
    from ..linedelay.report import plot_trajectory, write_trajectory_csv
    from ..linedelay.spline import localize

    _check_paths(args)
    camera_file = load_camera(args.camera)
    camera = camera_file.camera
    line_delay = args.line_delay if args.line_delay is not None else camera_file.line_delay_s
    if line_delay is not None and not math.isfinite(line_delay):
        raise InputError("--line-delay must be a finite number")
    if args.model == "gs-pnp":
        return _run_localize_gs_pnp(args, camera, line_delay)
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
    summary = result.summary_dict() | {"trajectory_model": "rs-spline", "frames_total": detection.frames_total,
                                       "gs_pnp_comparison": comparison}
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
