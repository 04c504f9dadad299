"""Flicker (LED / mains) line-delay method vs the truth, and vs the target-video method.

Rendered videos (rscalib.sim.target_video.render_video, as `rscalib simulate --flicker-hz`): default camera
640x480, 30 fps, 1 s (30 frames), checkerboard on a background, noise 2 grey levels, supersample 1,
flicker depth 0.3 with a random phase per seed. For each line delay d, light frequency (1 kHz LED,
100 Hz mains) and camera (static, hand-held motion) over several seeds, the video goes through
rscalib.estimate_line_delay_flicker (the front door of `rscalib flicker`; run.result is its
estimate); both estimators are recorded when they apply (spectrum: >= 2 periods per frame;
phase-drift: uses the frame timestamps). With motion, the 1 kHz video also goes through the target
method (rscalib.calibrate_video = `rscalib linedelay`).

Usage: .venv/bin/python experiments/exp_flicker.py [--seeds 5] [--quick] [--no-linedelay]
Writes benchmarks/results/exp_flicker.json and docs/figures/exp_flicker.png; prints a markdown table.
Videos are rendered into a temporary folder and deleted.
"""
from __future__ import annotations

import argparse
import math
import shutil
import tempfile
import time
from pathlib import Path

import _common as C
import numpy as np

import rscalib
from rscalib.sim.target_video import render_video

FIGURE = C.FIGURES / "exp_flicker.png"

LINE_DELAYS_S = (15e-6, 30e-6, 60e-6)   # readout 7.2, 14.4, 28.8 ms of a 33.3 ms frame
FREQUENCIES_HZ = (1000.0, 100.0)
MOTIONS = (0.0, 1.0)
RENDER = dict(fps=30.0, size=(640, 480), duration_s=1.0, noise=2.0, supersample=1, flicker_depth=0.3)


def target_estimate(video, camera_path, target_path) -> dict:
    options = rscalib.LineDelayOptions(detection=rscalib.DetectOptions(workers=1, cache=False))
    result = rscalib.calibrate_video(video, target_path, camera_path, options).result
    return {"line_delay_s": result.line_delay_s, "line_delay_std_s": result.line_delay_std_s,
            "determined": bool(result.determined)}


def run(seeds: int, with_linedelay: bool, work: Path) -> list[dict]:
    rows = []
    for d in LINE_DELAYS_S:
        for motion in MOTIONS:
            for f in FREQUENCIES_HZ:
                for seed in range(seeds):
                    phase = float(np.random.default_rng([7, seed]).uniform(0, 2 * np.pi))
                    out = work / f"d{d * 1e6:g}_f{f:g}_m{motion:g}_s{seed}"
                    started = time.perf_counter()
                    video = render_video(out, line_delay_s=d, seed=100 + seed, motion=motion, flicker_hz=f,
                                         flicker_phase_rad=phase, progress=False, **RENDER)
                    render_s = time.perf_counter() - started
                    started = time.perf_counter()
                    run_ = rscalib.estimate_line_delay_flicker(video.video_path, f)
                    res = run_.result
                    row = dict(d_true_s=d, frequency_hz=f, motion=motion, seed=seed, flicker_phase_rad=phase,
                               method=res.method, detrend=res.detrend, determined=res.determined,
                               verdict=run_.verdict.status,
                               line_delay_s=res.line_delay_s, line_delay_std_s=res.line_delay_std_s,
                               cycles_per_frame=res.cycles_per_frame, warnings=res.warnings,
                               estimates=res.estimates, flicker_seconds=time.perf_counter() - started,
                               render_seconds=render_s)
                    if with_linedelay and motion > 0 and f == FREQUENCIES_HZ[0]:
                        started = time.perf_counter()
                        row["target_method"] = target_estimate(video.video_path, video.camera_path,
                                                               video.target_path)
                        row["target_method"]["seconds"] = time.perf_counter() - started
                    rows.append(row)
                    est = " ".join(f"{k}={v['line_delay_s'] * 1e6:.5f}" for k, v in res.estimates.items()
                                   if v.get("ok"))
                    tgt = (f" target={row['target_method']['line_delay_s'] * 1e6:.4f}"
                           if "target_method" in row else "")
                    print(f"  d={d * 1e6:4.0f}us f={f:6.0f}Hz motion={motion:g} seed={seed}: "
                          f"{res.line_delay_s * 1e6:.5f} +- {res.line_delay_std_s * 1e6:.5f} ({res.method}) "
                          f"[{est}]{tgt}", flush=True)
                    shutil.rmtree(out, ignore_errors=True)
    return rows


def _stats(errors, stds) -> tuple[float, float, float, str]:
    errors, stds = np.abs(np.asarray(errors)), np.asarray(stds)
    if not len(errors):
        return (math.nan,) * 3 + ("-",)
    within = int(np.sum(errors <= 3 * stds))
    return float(np.median(errors)), float(np.max(errors)), float(np.median(stds)), f"{within}/{len(errors)}"


def summarise(rows: list[dict]) -> tuple[list[dict], str]:
    groups, lines = [], []
    header = ("| d (µs) | light | camera | estimator | determined | median \\|err\\| (ns) | max \\|err\\| (ns) | "
              "median σ (ns) | \\|err\\| ≤ 3σ |")
    lines += [header, "|" + "---|" * 9]
    for d in LINE_DELAYS_S:
        for f in FREQUENCIES_HZ:
            for motion in MOTIONS:
                sel = [r for r in rows if r["d_true_s"] == d and r["frequency_hz"] == f and r["motion"] == motion]
                if not sel:
                    continue
                light = f"{f:g} Hz ({sel[0]['cycles_per_frame']:.2f} periods/frame)"
                camera = "static" if motion == 0 else "hand-held"
                for name in ("auto", "spectrum", "phase-drift"):
                    if name == "auto":
                        picked = [(r["line_delay_s"], r["line_delay_std_s"], r["determined"]) for r in sel]
                        label = "auto (" + "/".join(sorted({r["method"] for r in sel})) + ")"
                    else:
                        picked = [(r["estimates"][name]["line_delay_s"], r["estimates"][name]["line_delay_std_s"],
                                   r["estimates"][name]["ok"]) for r in sel
                                  if name in r["estimates"] and "line_delay_s" in r["estimates"][name]]
                        label = name
                        if not picked:
                            continue
                    ok = [(e, s) for e, s, k in picked if k]
                    med, worst, sig, within = _stats([e - d for e, _ in ok], [s for _, s in ok])
                    groups.append(dict(d_true_s=d, frequency_hz=f, motion=motion, estimator=label,
                                       determined=f"{len(ok)}/{len(picked)}", median_abs_err_s=med,
                                       max_abs_err_s=worst, median_std_s=sig, within_3sigma=within))
                    lines.append(f"| {d * 1e6:g} | {light} | {camera} | {label} | {len(ok)}/{len(picked)} | "
                                 f"{med * 1e9:.3g} | {worst * 1e9:.3g} | {sig * 1e9:.3g} | {within} |")
        target = [r["target_method"] for r in rows if r["d_true_s"] == d and "target_method" in r]
        if target:
            med, worst, sig, within = _stats([t["line_delay_s"] - d for t in target],
                                             [t["line_delay_std_s"] for t in target])
            groups.append(dict(d_true_s=d, frequency_hz=None, motion=1.0, estimator="target video",
                               determined=f"{sum(t['determined'] for t in target)}/{len(target)}",
                               median_abs_err_s=med, max_abs_err_s=worst, median_std_s=sig, within_3sigma=within))
            lines.append(f"| {d * 1e6:g} | (1 kHz video) | hand-held | target video (`rscalib linedelay`) | "
                         f"{sum(t['determined'] for t in target)}/{len(target)} | {med * 1e9:.3g} | "
                         f"{worst * 1e9:.3g} | {sig * 1e9:.3g} | {within} |")
    return groups, "\n".join(lines)


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.4), dpi=80)
    styles = {(1000.0, 0.0): ("o", "C0", "1 kHz, static"), (1000.0, 1.0): ("s", "C1", "1 kHz, hand-held"),
              (100.0, 0.0): ("^", "C2", "100 Hz, static"), (100.0, 1.0): ("v", "C3", "100 Hz, hand-held")}
    offsets = {key: (i - 1.5) * 0.12 for i, key in enumerate(styles)}
    for key, (marker, color, label) in styles.items():
        sel = [r for r in rows if (r["frequency_hz"], r["motion"]) == key and r["determined"]]
        x = [LINE_DELAYS_S.index(r["d_true_s"]) + offsets[key] for r in sel]
        ax.plot(x, [abs(r["line_delay_s"] - r["d_true_s"]) / r["d_true_s"] for r in sel], marker, color=color,
                ms=4, label=f"{label}: |error|")
        ax.plot(x, [r["line_delay_std_s"] / r["d_true_s"] for r in sel], "_", color=color, ms=9, mew=1.2)
    target = [r for r in rows if "target_method" in r]
    if target:
        x = [LINE_DELAYS_S.index(r["d_true_s"]) + 0.3 for r in target]
        ax.plot(x, [abs(r["target_method"]["line_delay_s"] - r["d_true_s"]) / r["d_true_s"] for r in target],
                "D", color="k", ms=4, label="target video, hand-held")
        ax.plot(x, [r["target_method"]["line_delay_std_s"] / r["d_true_s"] for r in target], "_", color="k", ms=9)
    ax.set_yscale("log")
    ax.set_xticks(range(len(LINE_DELAYS_S)), [f"d = {d * 1e6:g} µs" for d in LINE_DELAYS_S])
    ax.set_ylabel("relative |error| (markers), σ (bars)")
    ax.set_title("Line delay from flicker bands, 640x480, 30 frames", fontsize=10)
    ax.legend(fontsize=7, ncol=2, loc="upper left")
    ax.grid(alpha=0.3, which="both", axis="y")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="videos per configuration (5)")
    parser.add_argument("--quick", action="store_true", help="2 seeds")
    parser.add_argument("--no-linedelay", action="store_true", help="skip the target-video comparison")
    args = parser.parse_args()
    seeds = 2 if args.quick else args.seeds
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="exp_flicker_") as work:
        rows = run(seeds, not args.no_linedelay, Path(work))
    groups, table = summarise(rows)
    figure(rows, FIGURE)
    settings = dict(RENDER, line_delays_s=LINE_DELAYS_S, frequencies_hz=FREQUENCIES_HZ, motions=MOTIONS,
                    seeds=seeds, camera="default (f = 500 px), checkerboard 9x6 40 mm",
                    total_seconds=time.perf_counter() - started)
    C.write_results("exp_flicker", settings, {"per_video": rows, "summary": groups}, table)
    print(f"written {FIGURE} ({FIGURE.stat().st_size / 1024:.0f} kB)\n")
    print(table)


if __name__ == "__main__":
    main()
