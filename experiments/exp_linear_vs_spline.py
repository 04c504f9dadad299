"""Experiment (issue #6): the adaptive B-spline trajectory vs the baseline of per-frame poses
interpolated linearly / by SLERP (Hedborg et al. 2012), on feature-level simulations.

For several seeds and motion kinds, both models estimate the line delay from the same
observations (640x480, f = 500 px, 9x6 board, 30 fps, 0.3 px noise, d = 30 us/row, sigma given):
`rscalib.calibrate_video(observations, camera=..., options)` with
`LineDelayOptions(pixel_sigma_px=0.3, self_check=False)` (the spline) and
`LineDelayOptions(pixel_sigma_px=0.3, baseline="linear")` (the baseline); run.result is each estimate.
Reported: relative error of d, |d_hat - d| <= 3 sigma_d, camera-centre and rotation error of
the trajectory at every frame's mid-readout time, J/2N, solve time.

    .venv/bin/python experiments/exp_linear_vs_spline.py            # 8 seeds, ~5 min on 2 cores
    .venv/bin/python experiments/exp_linear_vs_spline.py --seeds 2  # quick look

Writes benchmarks/results/exp_linear_vs_spline.json and docs/figures/exp_linear_vs_spline.png.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import _common as C
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import rscalib  # noqa: E402
from rscalib.sim.target_observations import (  # noqa: E402
    HandheldTrajectory,
    SimCamera,
    calm_then_wild,
    checkerboard_points,
    simulate_observations,
    standoff_distance_m,
)

D_TRUE_S = 30e-6
NOISE_PX = 0.3
FPS = 30.0
SIM_CAMERA = SimCamera("pinhole-radtan", np.array([500.0, 500.0, 319.5, 239.5, -0.1, 0.05, 0.0, 0.0, 0.0]), 640, 480)

# name -> (HandheldTrajectory keyword arguments, fraction of frames dropped at random)
MOTIONS = {
    "calm (x0.3)": (lambda dur: {"amplitude": 0.3}, 0.0),
    "hand-held (x1)": (lambda dur: {"amplitude": 1.0}, 0.0),
    "calm then wild (x2)": (lambda dur: {"amplitude": 2.0, "amplitude_profile": calm_then_wild(dur)}, 0.0),
    "hand-held, 10% frames lost": (lambda dur: {"amplitude": 1.0}, 0.1),
    "shaky (0.5-8 Hz)": (lambda dur: {"freq_range_hz": (0.5, 8.0)}, 0.0),
}


def centres(rotations, translations):
    return -np.einsum("nji,nj->ni", rotations, translations)


def pose_errors(rotations, translations, truth_r, truth_p):
    centre_mm = 1e3 * np.linalg.norm(centres(rotations, translations) - centres(truth_r, truth_p), axis=1)
    cos = (np.einsum("nij,nij->n", rotations, truth_r) - 1.0) / 2.0
    angle_deg = np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0)))
    ok = np.isfinite(centre_mm)
    return float(np.mean(centre_mm[ok])), float(np.mean(angle_deg[ok])), float(np.mean(~ok))


def run_one(motion: str, seed: int, duration_s: float) -> list[dict]:
    make_kw, drop = MOTIONS[motion]
    points = checkerboard_points()
    trajectory = HandheldTrajectory(duration_s=duration_s, seed=seed,
                                    target_center_m=0.5 * (points.min(axis=0) + points.max(axis=0)),
                                    distance_m=standoff_distance_m(SIM_CAMERA, points), **make_kw(duration_s))
    sim = simulate_observations(SIM_CAMERA, D_TRUE_S, fps=FPS, duration_s=duration_s, noise_px=NOISE_PX,
                                seed=seed, trajectory=trajectory)
    obs = sim.observations
    if drop > 0:
        rng = np.random.default_rng([0x11AE, seed])
        keep = rng.uniform(size=obs.num_frames) >= drop
        obs = obs.subset_frames(keep)
    camera = rscalib.CameraModel(SIM_CAMERA.model, SIM_CAMERA.params, SIM_CAMERA.width, SIM_CAMERA.height)
    # Truth at mid-readout of every video frame inside the sequence (lost frames included).
    t_eval = np.arange(int(duration_s * FPS) - 1) / FPS + 0.5 * D_TRUE_S * SIM_CAMERA.height
    truth_r, truth_p = trajectory.pose_cw(t_eval)
    rows = []
    for model in ("spline", "linear"):
        started = time.perf_counter()
        if model == "spline":
            options = rscalib.LineDelayOptions(pixel_sigma_px=NOISE_PX, self_check=False)
            result = rscalib.calibrate_video(obs, camera=camera, options=options).result
            t = np.clip(t_eval, result.trajectory.t_begin, result.trajectory.t_end)
            rotations, translations = rscalib.poses_at(result.trajectory, t)
        else:
            options = rscalib.LineDelayOptions(pixel_sigma_px=NOISE_PX, baseline="linear")
            result = rscalib.calibrate_video(obs, camera=camera, options=options).result
            rotations, translations = result.pose_at(t_eval)
        elapsed = time.perf_counter() - started
        centre_mm, angle_deg, no_pose = pose_errors(rotations, translations, truth_r, truth_p)
        err = result.line_delay_s - D_TRUE_S
        std = result.line_delay_std_s
        rows.append({"motion": motion, "seed": seed, "model": model, "frames": obs.num_frames,
                     "line_delay_s": result.line_delay_s, "line_delay_std_s": std if np.isfinite(std) else None,
                     "relative_error": err / D_TRUE_S, "within_3_sigma": bool(np.isfinite(std) and abs(err) <= 3 * std),
                     "normalised_cost": result.normalised_cost, "rms_px": result.rms_px,
                     "centre_error_mm": centre_mm, "rotation_error_deg": angle_deg,
                     "fraction_without_pose": no_pose, "segments": int(result.num_segments),
                     # the model's solve (the engine's own clock), and the front door's whole call
                     "time_s": result.solve_time_s, "call_time_s": elapsed})
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| motion | model | median abs rel. error of d | abs err <= 3 sigma | median sigma_d / d | "
             "mean centre error (mm) | mean rotation error (deg) | median J/2N | median time (s) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for motion in MOTIONS:
        for model in ("spline", "linear"):
            sel = [r for r in rows if r["motion"] == motion and r["model"] == model]
            if not sel:
                continue
            rel = np.array([abs(r["relative_error"]) for r in sel])
            within = sum(r["within_3_sigma"] for r in sel)
            sig = np.array([(r["line_delay_std_s"] or np.nan) / D_TRUE_S for r in sel])
            lines.append(f"| {motion} | {model} | {100 * np.median(rel):.2f} % | {within}/{len(sel)} | "
                         f"{100 * np.nanmedian(sig):.2f} % | {np.mean([r['centre_error_mm'] for r in sel]):.2f} | "
                         f"{np.mean([r['rotation_error_deg'] for r in sel]):.3f} | "
                         f"{np.median([r['normalised_cost'] for r in sel]):.2f} | "
                         f"{np.median([r['time_s'] for r in sel]):.1f} |")
    return "\n".join(lines)


def figure(rows: list[dict], path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    motions = list(MOTIONS)
    for m, model in enumerate(("spline", "linear")):
        for i, motion in enumerate(motions):
            sel = [r for r in rows if r["motion"] == motion and r["model"] == model]
            x = i + (m - 0.5) * 0.3
            rel = [100 * r["relative_error"] for r in sel]
            axes[0].plot(np.full(len(rel), x), rel, "o", ms=3, color=f"C{m}", label=model if i == 0 else None)
            err = [r["centre_error_mm"] for r in sel]
            axes[1].plot(np.full(len(err), x), err, "o", ms=3, color=f"C{m}", label=model if i == 0 else None)
    for ax in axes:
        ax.set_xticks(range(len(motions)))
        ax.set_xticklabels([m.replace(" (", "\n(").replace(", ", ",\n") for m in motions], fontsize=7)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].axhline(0, color="k", lw=0.5)
    axes[0].set_ylabel("line-delay error (%)")
    axes[0].set_yscale("symlog", linthresh=1.0)
    axes[1].set_ylabel("mean camera-centre error (mm)")
    axes[1].set_yscale("log")
    fig.suptitle("Spline vs per-frame linear/SLERP trajectory (simulated, d = 30 µs/row, 0.3 px)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--duration", type=float, default=5.0, help="seconds of video per run (5)")
    parser.add_argument("--out", type=Path, default=C.RESULTS / "exp_linear_vs_spline.json", help="the results file")
    parser.add_argument("--figure", type=Path, default=C.FIGURES / "exp_linear_vs_spline.png")
    args = parser.parse_args()
    rows = []
    for motion in MOTIONS:
        for seed in range(args.seeds):
            rows += run_one(motion, seed, args.duration)
            last = rows[-2:]
            print(f"{motion:28s} seed {seed}: " + "; ".join(
                f"{r['model']} {100 * r['relative_error']:+.2f} % ({r['centre_error_mm']:.2f} mm, {r['time_s']:.1f} s)"
                for r in last), flush=True)
    text = table(rows)
    print()
    print(text)
    settings = {"seeds": args.seeds, "duration_s": args.duration, "fps": FPS, "line_delay_s": D_TRUE_S,
                "noise_px": NOISE_PX, "camera": "640x480 pinhole-radtan f=500 k1=-0.1 k2=0.05", "target": "9x6, 4 cm",
                "pixel_sigma": "given (0.3)", "motions": list(MOTIONS),
                "trajectory_error": "mean over every video frame's mid-readout time (lost frames included)",
                "command": "python experiments/exp_linear_vs_spline.py" + ("" if args.seeds == 8 else f" --seeds {args.seeds}")
                + ("" if args.duration == 5.0 else f" --duration {args.duration}")}
    C.write_results("exp_linear_vs_spline", settings, rows, text, path=args.out)
    figure(rows, args.figure)
    print(f"written {args.figure}")


if __name__ == "__main__":
    main()
