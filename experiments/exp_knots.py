"""Paper Fig. 4 (Oth et al. 2013 §4.2): uniform knots swept over a wide range vs adaptive knots.

Rendered 640x480, 30 fps, 10 s videos at d = 30 us with a calm-then-wild hand-held motion
(simulate.calm_then_wild: 0.15 of the default amplitude in the first half, full amplitude in the
second), 9x6 checkerboard, supersample 2, noise 2 grey levels. For each video:
`rscalib.calibrate_video` on its detections with `LineDelayOptions(self_check=False, uniform_knots=N)`
for N uniform segments over ~0.5 ... 60 segments per second (log-spaced), and with the default
adaptive placement (`LineDelayOptions(self_check=False)`). Reported:
line-delay error, J/2N and the trajectory error against the analytic truth (camera-centre mm,
orientation deg, averaged over each frame's readout).

Usage: .venv/bin/python experiments/exp_knots.py [--quick] [--seeds N]
Writes benchmarks/results/exp_knots.json and docs/figures/exp_knots.png.
"""
from __future__ import annotations

import time

import _common as C
import numpy as np

NAME = "exp_knots"
D_S = 30e-6
DURATION_S = 10.0
SEGMENTS_PER_S = np.geomspace(0.5, 60.0, 10)


def main() -> None:
    p = C.parser(__doc__.splitlines()[0], default_seeds=3, quick_seeds=1)
    args = p.parse_args()
    seeds = C.seeds_from(args)
    timer = C.Timer()
    started = time.perf_counter()
    rows = []
    for seed in range(1, seeds + 1):
        folder, t_render = C.get_video(f"vga_ctw_d{D_S * 1e6:.0f}_T{DURATION_S:g}_s{seed}", line_delay_s=D_S,
                                       fps=30.0, duration_s=DURATION_S, seed=seed, size=(640, 480),
                                       target="checkerboard", noise=2.0, supersample=2,
                                       trajectory_kind="calm_then_wild")
        timer.add("render", t_render)
        t0 = time.perf_counter()
        detection, cam = C.detect(folder)
        timer.add("detect", time.perf_counter() - t0)
        truth = C.truth_trajectory(folder)
        obs = detection.observations
        span = obs.frame_times_s[-1] - obs.frame_times_s[0] + 1.0 / 30.0
        runs = [("uniform", int(max(1, round(r * span)))) for r in SEGMENTS_PER_S] + [("adaptive", None)]
        for sweep_index, (kind, segments) in enumerate(runs):
            t0 = time.perf_counter()
            res = C.solve_alone(detection, cam, uniform_knots=segments)
            timer.add(f"calibrate_{kind}", time.perf_counter() - t0)
            err = C.trajectory_errors(res.trajectory, truth, C.observed_times(res))
            # Calm and wild halves separately: where the adaptive placement should differ.
            times = C.observed_times(res)
            half = obs.frame_times_s[0] + 0.5 * span
            calm = C.trajectory_errors(res.trajectory, truth, times[times < half])
            wild = C.trajectory_errors(res.trajectory, truth, times[times >= half])
            knots = np.asarray(res.knots)
            row = C.summary_row(res, D_S) | {"kind": kind, "seed": seed, "sweep_index": sweep_index,
                                            "segments_requested": segments,
                                            "knots": len(knots), "segments_per_s": res.num_segments / span,
                                            "segments_calm_half": int(np.sum(knots[:-1] < half)),
                                            "segments_wild_half": int(np.sum(knots[:-1] >= half)),
                                            **{f"traj_{k}": v for k, v in err.items()},
                                            "traj_calm_position_mean_mm": calm["position_mean_mm"],
                                            "traj_wild_position_mean_mm": wild["position_mean_mm"]}
            rows.append(row)
            print(f"  seed {seed} {kind:8s} {res.num_segments:4d} segments: d {row['d_est_s'] * 1e6:8.4f} +- "
                  f"{row['std_s'] * 1e6:.4f} us ({100 * row['rel_err']:+.3f} %), J/2N {row['normalised_cost']:.3f}, "
                  f"pos {err['position_mean_mm']:.3f} mm, rot {err['orientation_mean_deg']:.4f} deg "
                  f"({time.perf_counter() - t0:.1f} s)", flush=True)
    table_rows = []
    for index in sorted({r["sweep_index"] for r in rows}):
        sel = [r for r in rows if r["sweep_index"] == index]
        kind = sel[0]["kind"]
        table_rows.append([kind, f"{np.mean([r['segments'] for r in sel]):.0f}",
                           f"{np.mean([r['segments_per_s'] for r in sel]):.2f}",
                           f"{np.median([100 * abs(r['rel_err']) for r in sel]):.3f} %",
                           f"{np.mean([r['std_s'] for r in sel]) * 1e6:.4f}",
                           f"{np.mean([r['within_3sigma'] for r in sel]) * 100:.0f} %",
                           f"{np.median([r['normalised_cost'] for r in sel]):.3f}",
                           f"{np.mean([r['traj_position_mean_mm'] for r in sel]):.3f}",
                           f"{np.mean([r['traj_orientation_mean_deg'] for r in sel]):.4f}",
                           f"{np.mean([r['segments_calm_half'] for r in sel]):.0f} / {np.mean([r['segments_wild_half'] for r in sel]):.0f}"])
    table = C.markdown_table(["knots", "segments", "segments/s", "median abs. rel. error of d", "mean σ_d (µs)",
                              "within 3σ", "median J/2N", "position error (mm)", "orientation error (deg)",
                              "segments calm / wild half"], table_rows)
    print("\n" + table)
    timer.add("total", time.perf_counter() - started)
    settings = {"size": [640, 480], "fps": 30.0, "duration_s": DURATION_S, "line_delay_s": D_S, "seeds": seeds,
                "motion": "HandheldTrajectory with calm_then_wild(duration) amplitude profile (0.15 -> 1.0)",
                "segments_per_s": SEGMENTS_PER_S.tolist(), "target": "checkerboard 9x6, 40 mm",
                "noise_grey_levels": 2.0, "supersample": 2,
                "uniform": "rscalib.calibrate_video(detections, LineDelayOptions(self_check=False, uniform_knots=N))",
                "adaptive": "rscalib.calibrate_video(detections, LineDelayOptions(self_check=False))"}
    C.write_results(NAME, settings, rows, table, timer.t)
    figure(rows)


def figure(rows) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seeds = sorted({r["seed"] for r in rows})
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.7), constrained_layout=True)
    for seed in seeds:
        uni = sorted([r for r in rows if r["seed"] == seed and r["kind"] == "uniform"], key=lambda r: r["knots"])
        ada = [r for r in rows if r["seed"] == seed and r["kind"] == "adaptive"]
        k = np.array([r["knots"] for r in uni])
        line, = axes[0].plot(k, [100 * r["rel_err"] for r in uni], "o-", ms=3, lw=1, label=f"seed {seed}")
        c = line.get_color()
        axes[1].plot(k, [r["normalised_cost"] for r in uni], "o-", ms=3, lw=1, color=c)
        axes[2].plot(k, [r["traj_position_mean_mm"] for r in uni], "o-", ms=3, lw=1, color=c)
        for a in ada:
            axes[0].plot(a["knots"], 100 * a["rel_err"], "*", ms=13, color=c, mec="k")
            axes[1].plot(a["knots"], a["normalised_cost"], "*", ms=13, color=c, mec="k")
            axes[2].plot(a["knots"], a["traj_position_mean_mm"], "*", ms=13, color=c, mec="k")
    axes[0].axhline(0, color="k", lw=0.8)
    axes[0].set_yscale("symlog", linthresh=0.1)
    axes[0].set_ylabel("(d̂ − d)/d (%)  [symlog]")
    axes[0].set_title("Line-delay error")
    axes[1].axhline(1, color="k", lw=0.8, ls=":")
    axes[1].set_yscale("log")
    axes[1].set_ylabel("J / 2N")
    axes[1].set_title("Normalised cost")
    axes[2].set_yscale("log")
    axes[2].set_ylabel("mean camera-centre error (mm)")
    axes[2].set_title("Trajectory error vs truth")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("number of knots (breakpoints)")
    axes[0].legend(fontsize=8, title="● uniform  ★ adaptive", title_fontsize=8)
    fig.suptitle(f"Uniform knots vs adaptive placement: 640x480, 30 fps, 10 s calm-then-wild, d = {D_S * 1e6:g} µs",
                 fontsize=10)
    C.save_figure(fig, NAME)
    plt.close(fig)


if __name__ == "__main__":
    main()
