"""Speed and peak memory of the C++ (Ceres) self-calibration bundle adjustment (docs/sog.md §22) on a
synthetic problem of the size the new front end will feed it, and of the SciPy adjustment
(tests/python/selfcalib/scipy_reference_bundle.py, the product's former engine) on the same problem for comparison.

The problem: a 640x480 civera-radial camera walking hand-held in a textured room
(rscalib.sim.trajectories.HandheldRoomMotion) for KEYFRAMES keyframes 0.1 s apart, seen through a
30 µs/row rolling shutter (each point at its own row's time), 0.5 px noise; TRACKS feature tracks of up
to TRACK_LENGTH consecutive keyframes (each a room point, re-identified at every keyframe that sees it),
about 50k observations at the defaults. Start: the truth perturbed (camera 5 % and 5 px, poses 2 cm and
0.6 degrees, points 5 %); the line delay estimated from 0, soft_l1 at 2 px; velocities from the tracks
(scipy_reference_bundle.track_velocity), the same for both engines. Each engine runs in its own process, so each peak RSS
(ru_maxrss) is its own (the problem's generation included: `baseline` is the peak before the solve).
Wall times depend on the machine's load (recorded as `load_average`); `cpu_s` is the process's CPU time
(both threads of the solve).

Usage: .venv/bin/python benchmarks/bench_adjustment.py [--keyframes 300] [--tracks 1500] [--track-length 60]
         [--engines ceres,scipy] [--threads 2] [--scipy-timeout 1800] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import resource
import subprocess
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from rscalib import _core
from rscalib.selfcalib.adjustment import KeyframeTracks, adjust
from rscalib.sim.scene_features import CiveraCamera, room_points
from rscalib.sim.trajectories import HandheldRoomMotion

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "python" / "selfcalib"))
from scipy_reference_bundle import FeatureTracks, bundle_adjust, track_velocity  # noqa: E402  (the test-only reference)

CAMERA = CiveraCamera(f=525.06, cx=308.65, cy=236.54, k1=-7.613e-3, k2=9.388e-4, width=640, height=480,
                      pixel_size_mm=0.0070216)
LINE_DELAY_S = 30e-6
REFERENCE_ROW = 239.5
INTERVAL_S = 0.1
NOISE_PX = 0.5


def make_problem(keyframes: int, tracks: int, track_length: int, seed: int = 0) -> FeatureTracks:
    """The recorded tracks of the synthetic walk (FeatureTracks, one frame per keyframe), start perturbed."""
    rng = np.random.default_rng(seed)
    motion = HandheldRoomMotion(seed=seed)
    points = room_points(density_per_m2=60.0, seed=seed)
    times = np.arange(keyframes) * INTERVAL_S
    uv_all = np.full((keyframes, len(points), 2), np.nan)
    for k, t in enumerate(times):
        R_wc, r_w = motion.pose_wc(np.array([t]))
        uv, ok = CAMERA.project((points - r_w[0]) @ R_wc[0])
        for _ in range(4):            # the rolling shutter: each point at its row's time
            R_wc, r_w = motion.pose_wc(t + LINE_DELAY_S * (uv[:, 1] - REFERENCE_ROW))
            x_c = np.einsum("nji,nj->ni", R_wc, points - r_w)
            uv, ok = CAMERA.project(x_c)
        ok &= (x_c[:, 2] > 0.3) & np.all((uv >= 4) & (uv <= [CAMERA.width - 5, CAMERA.height - 5]), axis=1)
        uv_all[k, ok] = uv[ok] + rng.normal(0, NOISE_PX, (ok.sum(), 2))
    visible = np.isfinite(uv_all[:, :, 0])
    candidates = np.flatnonzero(visible.sum(axis=0) >= 3)
    chosen = rng.choice(candidates, size=min(tracks, len(candidates)), replace=False)
    frame, feature, uv = [], [], []
    for j in chosen:     # a track: up to track_length consecutive visible keyframes from a random start
        seen = np.flatnonzero(visible[:, j])
        first = rng.integers(0, max(1, len(seen) - 3))
        keep = seen[first:first + track_length]
        frame.append(keep)
        feature.append(np.full(len(keep), j))
        uv.append(uv_all[keep, j])
    R_cw, p_cw = motion.pose_cw(times)
    turn = Rotation.from_rotvec(rng.normal(0, 0.01, (keyframes, 3))).as_matrix()
    return FeatureTracks(frame=np.concatenate(frame), feature_id=np.concatenate(feature), uv=np.concatenate(uv),
                         R_cw={k: turn[k] @ R_cw[k] for k in range(keyframes)},
                         p_cw={k: p_cw[k] + rng.normal(0, 0.02, 3) for k in range(keyframes)},
                         points={int(j): points[j] * (1 + 0.05 * rng.standard_normal()) for j in chosen},
                         t_s={k: float(times[k]) for k in range(keyframes)})


def start_camera() -> np.ndarray:
    return CAMERA.params * [1.05, 1, 1, 0, 0] + [0, 5, -5, 0, 0]


def run_ceres(tracks: FeatureTracks, threads: int) -> dict:
    frames = np.array(sorted(tracks.R_cw))
    ids = np.unique(tracks.feature_id)
    R = np.array([tracks.R_cw[int(k)] for k in frames])
    p = np.array([tracks.p_cw[int(k)] for k in frames])
    keyframe_tracks = KeyframeTracks(
        keyframe_poses=np.c_[p, Rotation.from_matrix(R).as_rotvec()], keyframe=np.searchsorted(frames, tracks.frame),
        point=np.searchsorted(ids, tracks.feature_id), uv_px=tracks.uv, image_velocity_px_s=track_velocity(tracks),
        points_w=np.array([tracks.points[int(i)] for i in ids]))
    camera = _core.CameraModel("civera-radial", start_camera(), CAMERA.width, CAMERA.height, [CAMERA.pixel_size_mm] * 2)
    started, cpu = time.perf_counter(), time.process_time()
    result = adjust(keyframe_tracks, camera, estimate_line_delay=True, reference_row=REFERENCE_ROW,
                    num_threads=threads)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    sigma = np.sqrt(np.diag(result.covariance_two_way))
    return dict(engine="ceres", wall_s=wall, cpu_s=cpu, solve_s=result.solve_time_s, covariance_s=result.covariance_time_s,
                iterations=result.iterations, termination=result.termination, converged=result.converged,
                f=float(result.camera_params[0]), f_sigma=float(sigma[0]), line_delay_s=result.line_delay_s,
                line_delay_sigma_s=float(sigma[5]), sigma_px=result.sigma_px)


def run_scipy(tracks: FeatureTracks) -> dict:
    started, cpu = time.perf_counter(), time.process_time()
    result = bundle_adjust(tracks, start_camera(), CAMERA.pixel_size_mm, keyframe_step=1, line_delay=True,
                           reference_row=REFERENCE_ROW)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    sigma = np.sqrt(np.diag(result.covariance_clustered))
    return dict(engine="scipy", wall_s=wall, cpu_s=cpu, nfev=result.nfev, polish_steps=result.extra["polish_steps"],
                converged=bool(result.status > 0 or result.step_sigma < 0.1), f=float(result.camera[0]),
                f_sigma=float(sigma[0]), line_delay_s=result.line_delay_s,
                line_delay_sigma_s=float(np.sqrt(result.covariance_globals[5, 5]) * 1e-6), sigma_px=result.sigma_px)


def child(args: argparse.Namespace) -> None:
    tracks = make_problem(args.keyframes, args.tracks, args.track_length)
    baseline_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out = run_ceres(tracks, args.threads) if args.child == "ceres" else run_scipy(tracks)
    out.update(keyframes=args.keyframes, tracks=len(np.unique(tracks.feature_id)), observations=len(tracks),
               threads=args.threads, baseline_peak_mb=baseline_mb,
               peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
               truth_f=CAMERA.f, truth_line_delay_s=LINE_DELAY_S, load_average=os.getloadavg()[0])
    print(json.dumps(out))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keyframes", type=int, default=300)
    parser.add_argument("--tracks", type=int, default=1500)
    parser.add_argument("--track-length", type=int, default=60)
    parser.add_argument("--engines", default="ceres,scipy")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--scipy-timeout", type=float, default=1800.0)
    parser.add_argument("--json", default=None)
    parser.add_argument("--child", choices=["ceres", "scipy"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    results = []
    for engine in args.engines.split(","):
        command = [sys.executable, __file__, "--child", engine, "--keyframes", str(args.keyframes), "--tracks",
                   str(args.tracks), "--track-length", str(args.track_length), "--threads", str(args.threads)]
        timeout = args.scipy_timeout if engine == "scipy" else None
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, check=True)
            results.append(json.loads(done.stdout.strip().splitlines()[-1]))
        except subprocess.TimeoutExpired:
            results.append(dict(engine=engine, timeout_s=timeout))
        except subprocess.CalledProcessError as error:
            results.append(dict(engine=engine, error=error.stderr[-2000:]))
        print(json.dumps(results[-1]), flush=True)
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(results, handle, indent=1)


if __name__ == "__main__":
    main()
