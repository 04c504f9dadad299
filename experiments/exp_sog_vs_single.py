"""Single EKF vs the Sum-of-Gaussians bank (issue 6, baseline 5; Civera et al. 2009 §VI).

The same rendered textured-room sequences (paper camera, f = 194.06 px; image folders written by
rscalib.sim.scene_video.render_scene_sequence) are self-calibrated by the front door of
`rscalib selfcalib`, rscalib.self_calibrate, with its two filter baselines and no restarts:
(a) the paper's 108-Gaussian bank (`SelfCalibOptions(baseline="filter")`, `--bank filter`) and
(b) one EKF started at a wrong focal length f0 with a wide sigma (`SelfCalibOptions(baseline="single",
f0_px=F0, f_sigma_px=S)`, `--bank single --f0 F0 --f-sigma S`: the same code path, one Gaussian).
Per run: final f error, whether the truth is inside the filter's own 99 % bounds
(run.result.filter_bounds_99), and the f trace. The recorded results (before issue 29) were made
with the then default "affine" front end; the front door now runs the method's "tracked" one.

Usage: .venv/bin/python experiments/exp_sog_vs_single.py [--sequences 4] [--frames 300] [--quick]
Writes benchmarks/results/exp_sog_vs_single.json and docs/figures/exp_sog_vs_single.png and prints
a markdown table. Rendered sequences are cached in build/exp_videos/scene_<seed>_<frames>/.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import _common as C
import numpy as np

import rscalib
from rscalib.sim.scene_video import render_scene_sequence

F0_SIGMA = [(100.0, 50.0), (150.0, 50.0), (300.0, 75.0), (450.0, 125.0)]


def sequence_for(seed: int, frames: int) -> tuple[Path, np.ndarray]:
    """The rendered room walk (an image folder with timestamps.txt, cached) and its true camera."""
    folder = C.VIDEO_ROOT / f"scene_{seed}_{frames}"
    if not (folder / "truth.json").is_file():
        render_scene_sequence(folder, num_frames=frames, seed=seed)
    truth = json.loads((folder / "truth.json").read_text())
    return folder, np.asarray(truth["camera"]["params"], dtype=np.float64)


def run_one(folder: Path, options) -> dict:
    started = time.perf_counter()
    result = rscalib.self_calibrate(folder, options).result
    bounds = result.filter_bounds_99   # the bank's own 99 % bounds
    return dict(f=float(result.mean[0]), f_bounds_99=bounds[0].tolist(),
                mean=result.mean.tolist(), bounds_99=bounds.tolist(),
                f_trace=result.history.mean[:, 0].tolist(), f_lo_trace=result.history.bounds_99[:, 0, 0].tolist(),
                f_hi_trace=result.history.bounds_99[:, 0, 1].tolist(), gaussians_left=result.gaussians_left,
                collapse_frame=result.collapse_frame, seconds=time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequences", type=int, default=4)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--quick", action="store_true", help="2 sequences of 150 frames")
    parser.add_argument("--out", type=Path, default=C.RESULTS / "exp_sog_vs_single.json")
    parser.add_argument("--figure", type=Path, default=C.FIGURES / "exp_sog_vs_single.png")
    args = parser.parse_args()
    if args.quick:
        args.sequences, args.frames = 2, 150
    rows = []
    for s in range(args.sequences):
        seed = 100 + s
        folder, truth = sequence_for(seed, args.frames)
        configs = [("SOG bank (108)", rscalib.SelfCalibOptions(baseline="filter", restarts=False))]
        configs += [(f"single EKF f0={f0:.0f}±{sd:.0f}",
                     rscalib.SelfCalibOptions(baseline="single", f0_px=f0, f_sigma_px=sd, restarts=False))
                    for f0, sd in F0_SIGMA]
        for name, options in configs:
            r = run_one(folder, options)
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
    C.write_results("exp_sog_vs_single",
                    {"sequences": args.sequences, "frames": args.frames, "single_f0_sigma": F0_SIGMA,
                     "front_end": rscalib.SelfCalibOptions().front_end.subpixel, "restarts": False},
                    [{k: v for k, v in r.items() if not k.endswith("trace")} for r in rows]
                    + [{"seed": r["seed"], "config": r["config"], "f_trace": r["f_trace"]} for r in rows], table,
                    path=args.out)


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
