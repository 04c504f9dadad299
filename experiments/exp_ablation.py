"""Ablation: error standardisation (A R Aᵀ vs plain R) x motion prior (on / off), on rendered videos.

Two regimes: rendered 640x480, 30 fps, 10 s hand-held videos at d = 30 us (the same videos as
exp_localize.py), and the 752x480 BlueFOX videos at 12 MHz (d = 137.5 us, 7 fps: strong
rolling-shutter effects; the same videos as exp_tables_bluefox.py); 9x6 checkerboard, supersample 2,
noise 2 grey levels. For each video, `rscalib.calibrate_video` on its detections with the
defaults except `LineDelayOptions(self_check=False, standardise_errors=..., motion_prior=...)`.
(The fifth variant of the recorded results, the paper's motion-prior weight Q, needed the engine's
`motion_prior_q`, which left the package with issue 29: it is no longer run.)
Reported per variant: median |relative error| of d, fraction with |d̂ − d| <= 3 σ_d, mean σ_d,
median J/2N, mean final segments.

Usage: .venv/bin/python experiments/exp_ablation.py [--quick] [--seeds N]
Writes benchmarks/results/exp_ablation.json and docs/figures/exp_ablation.png.
"""
from __future__ import annotations

import time

import _common as C
import numpy as np

NAME = "exp_ablation"
D_S = 30e-6
DURATION_S = 10.0
VARIANTS = [("A R Aᵀ + prior (default)", True, True), ("A R Aᵀ, no prior", True, False),
            ("plain R + prior", False, True), ("plain R, no prior", False, False)]
BLUEFOX_D_S = 1650 / 12e6
REGIMES = ["640x480, d = 30 µs, 30 fps", "752x480 BlueFOX, d = 137.5 µs, 7 fps"]


def regime_video(regime: str, seed: int):
    if regime == REGIMES[0]:
        return C.get_video(f"vga_d{D_S * 1e6:.0f}_T{DURATION_S:g}_s{seed}", line_delay_s=D_S, fps=30.0,
                           duration_s=DURATION_S, seed=seed, size=(640, 480), target="checkerboard",
                           noise=2.0, supersample=2) + (D_S,)
    fps = 1.0 / (1040 * BLUEFOX_D_S)   # as exp_tables_bluefox.py
    return C.get_video(f"bluefox_12MHz_T{DURATION_S:g}_s{seed}", line_delay_s=BLUEFOX_D_S, fps=fps,
                       duration_s=DURATION_S, seed=seed, camera=C.bluefox_camera(), target="checkerboard",
                       noise=2.0, supersample=2) + (BLUEFOX_D_S,)


def main() -> None:
    p = C.parser(__doc__.splitlines()[0], default_seeds=10, quick_seeds=3)
    args = p.parse_args()
    seeds = C.seeds_from(args)
    timer = C.Timer()
    started = time.perf_counter()
    rows = []
    for regime, seed in [(regime, seed) for regime in REGIMES for seed in range(1, seeds + 1)]:
        folder, t_render, truth_d = regime_video(regime, seed)
        timer.add("render", t_render)
        t0 = time.perf_counter()
        detection, cam = C.detect(folder)
        timer.add("detect", time.perf_counter() - t0)
        for label, standardise, prior in VARIANTS:
            t0 = time.perf_counter()
            try:
                res = C.solve_alone(detection, cam, standardise_errors=standardise, motion_prior=prior)
            except Exception as error:  # noqa: BLE001 — record a failed variant, keep going
                rows.append({"variant": label, "regime": regime, "seed": seed, "error": repr(error)})
                print(f"  seed {seed} {label}: FAILED {error!r}", flush=True)
                continue
            timer.add("calibrate", time.perf_counter() - t0)
            rows.append(C.summary_row(res, truth_d) | {"variant": label, "regime": regime, "seed": seed,
                                                      "standardise_errors": standardise, "use_motion_prior": prior})
            r = rows[-1]
            print(f"  {regime[:12]} seed {seed} {label:26s}: d = {r['d_est_s'] * 1e6:.4f} +- {r['std_s'] * 1e6:.4f} us, "
                  f"rel {100 * r['rel_err']:+.3f} %, J/2N {r['normalised_cost']:.3f}, {r['segments']} segments",
                  flush=True)
    table_rows, aggs = [], []
    for regime, (label, *_) in [(regime, v) for regime in REGIMES for v in VARIANTS]:
        sel = [r for r in rows if r["variant"] == label and r["regime"] == regime and "error" not in r]
        failed = sum(1 for r in rows if r["variant"] == label and r["regime"] == regime and "error" in r)
        if not sel:
            table_rows.append([regime, label, 0, "–", "–", "–", "–", "–", "–"])
            continue
        rel = np.abs([r["rel_err"] for r in sel])
        agg = {"regime": regime, "variant": label, "videos": len(sel), "failed": failed, "median_abs_rel_err": float(np.median(rel)),
               "max_abs_rel_err": float(np.max(rel)),
               "within_3sigma": float(np.mean([r["within_3sigma"] for r in sel])),
               "mean_sigma_us": float(np.mean([r["std_s"] for r in sel]) * 1e6),
               "median_normalised_cost": float(np.median([r["normalised_cost"] for r in sel])),
               "mean_segments": float(np.mean([r["segments"] for r in sel]))}
        aggs.append(agg)
        table_rows.append([regime, label, len(sel) if not failed else f"{len(sel)} (+{failed} failed)",
                           f"{100 * agg['median_abs_rel_err']:.3f} %", f"{100 * agg['max_abs_rel_err']:.3f} %",
                           f"{100 * agg['within_3sigma']:.0f} %", f"{agg['mean_sigma_us']:.4f}",
                           f"{agg['median_normalised_cost']:.3f}", f"{agg['mean_segments']:.0f}"])
    table = C.markdown_table(["regime", "variant", "videos", "median abs. rel. error", "max abs. rel. error", "within 3σ",
                              "mean σ_d (µs)", "median J/2N", "mean segments"], table_rows)
    print("\n" + table)
    timer.add("total", time.perf_counter() - started)
    settings = {"regimes": REGIMES, "duration_s": DURATION_S, "seeds": seeds,
                "target": "checkerboard 9x6, 40 mm", "noise_grey_levels": 2.0, "supersample": 2,
                "variants": [{"label": v[0], "standardise_errors": v[1], "use_motion_prior": v[2]} for v in VARIANTS]}
    C.write_results(NAME, settings, rows, table, timer.t, per_variant=aggs)
    figure(rows)


def figure(rows) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, grid = plt.subplots(len(REGIMES), 2, figsize=(11, 3.4 * len(REGIMES)), constrained_layout=True)
    for axes, regime in zip(grid, REGIMES):
        for k, (label, *_) in enumerate(VARIANTS):
            sel = [r for r in rows if r["variant"] == label and r["regime"] == regime and "error" not in r]
            if not sel:
                continue
            rel = 100 * np.array([r["rel_err"] for r in sel])
            sig = 100 * np.array([r["std_s"] / r["d_true_s"] for r in sel])
            x = k + np.linspace(-0.25, 0.25, len(sel))
            axes[0].errorbar(x, rel, yerr=3 * sig, fmt="o", ms=3, lw=0.8, capsize=2)
            axes[1].plot(x, [r["normalised_cost"] for r in sel], "o", ms=4)
        for ax in axes:
            ax.set_xticks(range(len(VARIANTS)))
            ax.set_xticklabels([v[0].replace(" (default)", "\n(default)").replace(", ", ",\n").replace(" + ", "\n+ ")
                                for v in VARIANTS], fontsize=7)
        axes[0].axhline(0, color="k", lw=0.8)
        axes[0].set_ylabel("(d̂ − d)/d (%), bars ±3σ_d")
        axes[0].set_title(f"Line-delay error: {regime}", fontsize=9)
        axes[1].axhline(1, color="k", lw=0.8, ls=":")
        axes[1].set_yscale("log")
        axes[1].set_ylabel("J / 2N")
        axes[1].set_title(f"Normalised cost: {regime}", fontsize=9)
    C.save_figure(fig, NAME)
    plt.close(fig)


if __name__ == "__main__":
    main()
