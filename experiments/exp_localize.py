"""Paper Fig. 5 (Oth et al. 2013 §5.1): continuous-time RS localisation vs per-frame GS PnP.

Rendered 640x480, 30 fps, 10 s hand-held videos (9x6 checkerboard, supersample 2, noise 2 grey
levels) at d = 30 and 60 us. `rscalib.localize_video` on the detections, with the true d, gives
the continuous-time RS trajectory (run.result); its `frame_poses` are the per-frame global-shutter
PnP poses it starts from — the baseline. Both are compared with the analytic rendered trajectory:

- GS PnP, pose placed at the frame timestamp t_i (what a GS pipeline does) and, fairer to it, at
  the frame's mean observation time t_i + mean(v) d (where a GS pose fits the RS image best);
- RS spline at the same mean observation times, and over each frame's whole readout.

Errors: camera-centre distance (mm) and rotation angle of R_est R_trueᵀ (rad, deg), averaged.

Usage: .venv/bin/python experiments/exp_localize.py [--quick] [--seeds N]
Writes benchmarks/results/exp_localize.json and docs/figures/exp_localize.png.
"""
from __future__ import annotations

import time

import _common as C
import numpy as np

import rscalib

NAME = "exp_localize"
LINE_DELAYS_S = [30e-6, 60e-6]
DURATION_S = 10.0


def video(d: float, seed: int):
    return C.get_video(f"vga_d{d * 1e6:.0f}_T{DURATION_S:g}_s{seed}", line_delay_s=d, fps=30.0,
                       duration_s=DURATION_S, seed=seed, size=(640, 480), target="checkerboard",
                       noise=2.0, supersample=2)


def gs_errors(poses, times_s, truth) -> tuple[np.ndarray, np.ndarray]:
    R_g = np.stack([rscalib.rotation_vector_to_matrix(v) for v in poses.rotation_vector])
    R_t, p_t = truth.pose_cw(times_s)
    return C.pose_errors(R_g, poses.translation, R_t, p_t)


def main() -> None:
    p = C.parser(__doc__.splitlines()[0], default_seeds=5, quick_seeds=2)
    args = p.parse_args()
    seeds = C.seeds_from(args)
    timer = C.Timer()
    started = time.perf_counter()
    rows, example = [], None
    for d in LINE_DELAYS_S:
        for seed in range(1, seeds + 1):
            folder, t_render = video(d, seed)
            timer.add("render", t_render)
            t0 = time.perf_counter()
            detection, cam = C.detect(folder)
            timer.add("detect", time.perf_counter() - t0)
            truth = C.truth_trajectory(folder)
            t0 = time.perf_counter()
            res = rscalib.localize_video(detection, camera=cam, line_delay_s=d).result
            timer.add("localize", time.perf_counter() - t0)
            obs = res.used_observations
            mean_row = np.bincount(obs.frame_index, weights=obs.uv[:, 1], minlength=obs.num_frames) / \
                np.maximum(1, np.bincount(obs.frame_index, minlength=obs.num_frames))
            t_frame = obs.frame_times_s
            t_mid = t_frame + mean_row * d
            gs_p0, gs_r0 = gs_errors(res.frame_poses, t_frame, truth)
            gs_p, gs_r = gs_errors(res.frame_poses, t_mid, truth)
            R_e, p_e = rscalib.poses_at(res.trajectory, np.clip(t_mid, res.trajectory.t_begin, res.trajectory.t_end))
            R_t, p_t = truth.pose_cw(t_mid)
            rs_p, rs_r = C.pose_errors(np.asarray(R_e), np.asarray(p_e), R_t, p_t)
            dense = C.trajectory_errors(res.trajectory, truth, C.observed_times(res))
            row = {"d_true_s": d, "seed": seed, "frames": obs.num_frames, "segments": res.num_segments,
                   "rs_rms_px": res.rms_px, "normalised_cost": res.normalised_cost,
                   "gs_rms_px": float(np.sqrt(np.nanmean(res.frame_poses.rms_px ** 2))),
                   "gs_at_frame_time": {"position_mean_mm": 1e3 * gs_p0.mean(), "orientation_mean_rad": gs_r0.mean()},
                   "gs_at_mid_time": {"position_mean_mm": 1e3 * gs_p.mean(), "orientation_mean_rad": gs_r.mean()},
                   "rs_at_mid_time": {"position_mean_mm": 1e3 * rs_p.mean(), "orientation_mean_rad": rs_r.mean()},
                   "rs_over_readout": {"position_mean_mm": dense["position_mean_mm"],
                                       "orientation_mean_rad": np.radians(dense["orientation_mean_deg"])},
                   "solve_time_s": res.solve_time_s}
            rows.append(row)
            print(f"  d={d * 1e6:.0f} us seed {seed}: GS@t_i {row['gs_at_frame_time']['position_mean_mm']:.2f} mm, "
                  f"GS@mid {row['gs_at_mid_time']['position_mean_mm']:.2f} mm, RS@mid "
                  f"{row['rs_at_mid_time']['position_mean_mm']:.3f} mm; orientation GS@mid "
                  f"{np.degrees(row['gs_at_mid_time']['orientation_mean_rad']):.3f} deg, RS "
                  f"{np.degrees(row['rs_at_mid_time']['orientation_mean_rad']):.4f} deg", flush=True)
            if example is None or (d == max(LINE_DELAYS_S) and seed == 1):
                example = (d, seed, folder, res, truth, t_mid)
    table_rows = []
    for d in LINE_DELAYS_S:
        sel = [r for r in rows if r["d_true_s"] == d]
        for key, label in (("gs_at_frame_time", "GS PnP, pose at t_i"), ("gs_at_mid_time", "GS PnP, pose at t_i + mean(v)·d"),
                           ("rs_at_mid_time", "RS spline at t_i + mean(v)·d"), ("rs_over_readout", "RS spline over each readout")):
            pos = np.array([r[key]["position_mean_mm"] for r in sel])
            rot = np.array([r[key]["orientation_mean_rad"] for r in sel])
            table_rows.append([f"{d * 1e6:.0f}", label, len(sel), f"{pos.mean():.3f}", f"{rot.mean():.5f}",
                               f"{np.degrees(rot.mean()):.4f}"])
        table_rows.append([f"{d * 1e6:.0f}", "reprojection RMS GS / RS (px)", len(sel),
                           f"{np.mean([r['gs_rms_px'] for r in sel]):.3f} / {np.mean([r['rs_rms_px'] for r in sel]):.3f}",
                           "", ""])
    table = C.markdown_table(["d (µs)", "trajectory", "videos", "mean position error (mm)",
                              "mean orientation error (rad)", "(deg)"], table_rows, align="llrrrr")
    print("\n" + table)
    timer.add("total", time.perf_counter() - started)
    settings = {"size": [640, 480], "fps": 30.0, "duration_s": DURATION_S, "line_delays_s": LINE_DELAYS_S,
                "seeds": seeds, "target": "checkerboard 9x6, 40 mm", "noise_grey_levels": 2.0, "supersample": 2,
                "localize": "rscalib.localize_video(detections, camera, line_delay_s=true d), LocalizeOptions defaults", "paper_real_data": "GS 189 mm / 0.34 rad, RS 8.34 mm / 0.03 rad"}
    C.write_results(NAME, settings, rows, table, timer.t)
    figure(*example)


def figure(d, seed, folder, res, truth, t_mid) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_dense = np.linspace(res.trajectory.t_begin, res.trajectory.t_end, 3000)
    R_t, p_t = truth.pose_cw(t_dense)
    c_true = -np.einsum("nji,nj->ni", R_t, p_t) * 1e3
    R_e, p_e = rscalib.poses_at(res.trajectory, t_dense)
    c_rs = -np.einsum("nji,nj->ni", np.asarray(R_e), np.asarray(p_e)) * 1e3
    poses = res.frame_poses
    R_g = np.stack([rscalib.rotation_vector_to_matrix(v) for v in poses.rotation_vector])
    c_gs = -np.einsum("nji,nj->ni", R_g, poses.translation) * 1e3
    fig, axes = plt.subplots(4, 1, figsize=(8, 7.5), sharex=True, constrained_layout=True)
    for k, name in enumerate("xyz"):
        ax = axes[k]
        ax.plot(t_dense, c_true[:, k], "k-", lw=1.2, label="truth")
        ax.plot(t_dense, c_rs[:, k], "g--", lw=1.0, label="RS continuous-time")
        ax.plot(t_mid, c_gs[:, k], "b.", ms=3, label="GS PnP (at mean obs. time)")
        ax.set_ylabel(f"{name} (mm)")
    axes[0].legend(fontsize=8, ncol=3, loc="upper right")
    R_tm, p_tm = truth.pose_cw(t_mid)
    ctm = -np.einsum("nji,nj->ni", R_tm, p_tm) * 1e3
    axes[3].plot(t_mid, np.linalg.norm(c_gs - ctm, axis=1), "b.", ms=3, label="GS PnP")
    R_e2, p_e2 = rscalib.poses_at(res.trajectory, np.clip(t_mid, res.trajectory.t_begin, res.trajectory.t_end))
    c_rs2 = -np.einsum("nji,nj->ni", np.asarray(R_e2), np.asarray(p_e2)) * 1e3
    axes[3].plot(t_mid, np.linalg.norm(c_rs2 - ctm, axis=1), "g.", ms=3, label="RS")
    axes[3].set_yscale("log")
    axes[3].set_ylabel("position error (mm)")
    axes[3].set_xlabel("time (s)")
    axes[3].legend(fontsize=8)
    fig.suptitle(f"Camera centre in the target frame, d = {d * 1e6:.0f} µs, 640x480 @ 30 fps, seed {seed}",
                 fontsize=10)
    C.save_figure(fig, NAME)
    plt.close(fig)


if __name__ == "__main__":
    main()
