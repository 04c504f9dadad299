"""Single EKF vs the Sum-of-Gaussians bank (issue 6, baseline 5; Civera et al. 2009 §VI).

The same rendered textured-room sequences (paper camera, f = 194.06 px) are self-calibrated
(a) by the paper's 108-Gaussian bank and (b) by one EKF started at a wrong focal length f0 with a
wide sigma (`rscalib selfcalib --bank single --f0 F0 --f-sigma S`: the same code path, one Gaussian).
Per run: final f error, whether the truth is inside the 99 % bounds, and the f trace.

Usage: .venv/bin/python benchmarks/exp_sog_vs_single.py [--sequences 4] [--frames 300] [--quick]
Writes benchmarks/results/exp_sog_vs_single.json and docs/figures/exp_sog_vs_single.png and prints
a markdown table. Rendered frames are cached in build/exp_videos/scene_<seed>_<frames>.npz.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _common import machine_info, write_results

from rscalib.selfcalib.calibrate import self_calibrate
from rscalib.sim.scene_video import render_scene_frames

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "build" / "exp_videos"
F0_SIGMA = [(100.0, 50.0), (150.0, 50.0), (300.0, 75.0), (450.0, 125.0)]


def frames_for(seed: int, frames: int):
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"scene_{seed}_{frames}.npz"
    if path.exists():
        data = np.load(path)
        return data["times"], data["images"], data["params"]
    rendered = render_scene_frames(num_frames=frames, seed=seed)
    params = np.asarray(rendered.camera.params)
    np.savez_compressed(path, times=rendered.timestamps_s, images=rendered.images, params=params)
    return rendered.timestamps_s, rendered.images, params


def run_one(times, images, grid) -> dict:
    started = time.perf_counter()
    result = self_calibrate(zip(times, images), (images.shape[2], images.shape[1]), grid=grid)
    return dict(f=float(result.mean[0]), f_bounds_99=result.bounds_99[0].tolist(),
                mean=result.mean.tolist(), bounds_99=result.bounds_99.tolist(),
                f_trace=result.history.mean[:, 0].tolist(), f_lo_trace=result.history.bounds_99[:, 0, 0].tolist(),
                f_hi_trace=result.history.bounds_99[:, 0, 1].tolist(), gaussians_left=result.gaussians_left,
                collapse_frame=result.collapse_frame, seconds=time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequences", type=int, default=4)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--quick", action="store_true", help="2 sequences of 150 frames")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "exp_sog_vs_single.json")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "exp_sog_vs_single.png")
    args = parser.parse_args()
    if args.quick:
        args.sequences, args.frames = 2, 150
    info = machine_info()
    rows = []
    for s in range(args.sequences):
        seed = 100 + s
        times, images, truth = frames_for(seed, args.frames)
        configs = [("SOG bank (108)", None)]
        configs += [(f"single EKF f0={f0:.0f}±{sd:.0f}",
                     {"f_range": (f0 - 2 * sd, f0 + 2 * sd), "f_count": 1, "k1_count": 1, "k2_count": 1})
                    for f0, sd in F0_SIGMA]
        for name, grid in configs:
            r = run_one(times, images, grid)
            lo, hi = r["f_bounds_99"]
            inside = [bool(b[0] <= t <= b[1]) for b, t in zip(r["bounds_99"], truth)]
            r.update(seed=seed, config=name, truth=truth.tolist(), f_error_rel=(r["f"] - truth[0]) / truth[0],
                     f_inside=bool(lo <= truth[0] <= hi), all_inside=all(inside))
            rows.append(r)
            print(f"seed {seed} {name:28s} f {r['f']:8.2f} ({r['f_error_rel'] * 100:+.2f} %), "
                  f"bounds [{lo:.1f}, {hi:.1f}], all five inside: {r['all_inside']}", flush=True)
    names = list(dict.fromkeys(r["config"] for r in rows))
    lines = ["| filter | median abs f error | max abs f error | f within 1 % | truth in f's 99 % bounds | all five inside |",
             "|---|---:|---:|---:|---:|---:|"]
    for name in names:
        sel = [r for r in rows if r["config"] == name]
        err = np.abs([r["f_error_rel"] for r in sel]) * 100
        lines.append(f"| {name} | {np.median(err):.2f} % | {err.max():.2f} % | "
                     f"{sum(e <= 1 for e in err)}/{len(sel)} | {sum(r['f_inside'] for r in sel)}/{len(sel)} | "
                     f"{sum(r['all_inside'] for r in sel)}/{len(sel)} |")
    table = "\n".join(lines)
    print("\n" + table)
    plot(rows, names, args.figure)
    write_results(args.out, "exp_sog_vs_single", info,
                  {"sequences": args.sequences, "frames": args.frames, "single_f0_sigma": F0_SIGMA},
                  [{k: v for k, v in r.items() if not k.endswith("trace")} for r in rows]
                  + [{"seed": r["seed"], "config": r["config"], "f_trace": r["f_trace"]} for r in rows], table)


def plot(rows, names, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seed = rows[0]["seed"]
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for i, name in enumerate(names):
        r = next(r for r in rows if r["config"] == name and r["seed"] == seed)
        frames = np.arange(len(r["f_trace"]))
        ax.plot(frames, r["f_trace"], color=f"C{i}", lw=1.4, label=name)
        ax.fill_between(frames, r["f_lo_trace"], r["f_hi_trace"], color=f"C{i}", alpha=0.12)
    ax.axhline(rows[0]["truth"][0], color="k", ls="--", lw=1, label="truth")
    ax.set_ylim(50, 650)
    ax.set_xlabel("frame")
    ax.set_ylabel("f (px), with 99 % bounds")
    ax.set_title(f"Single EKF from a wrong f0 vs the SOG bank (sequence {seed})")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
