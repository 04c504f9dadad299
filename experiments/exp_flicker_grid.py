"""Flicker line delay on realistic rendered LED / mains footage (issue 13): a grid of cases.

Renderer: rscalib.sim.flicker_light (box-averaged square or sine light, lamp disk / partial / flat,
vignetting, clipping, overlays, noise, JPEG), independent of the estimator's harmonic model. Each
case draws fresh random parameters from its seed: duty 5-95 %, clipping on/off, 0.3-40 periods per
frame, 1 or 12 frames, with or without timestamps, top-to-bottom or bottom-to-top readout. Every
case goes through rscalib.estimate_line_delay_flicker (the front door of `rscalib flicker`; run.result is
its estimate).
Error: on d when the direction is measured (phase drift) or given, on |d| otherwise.

Usage: .venv/bin/python experiments/exp_flicker_grid.py [--cases 56] [--seed0 1300]
Writes benchmarks/results/exp_flicker_grid.json; prints a markdown table.
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import _common as C
import numpy as np

import rscalib
from rscalib.sim.flicker_light import FlickerLight, FlickerScene, render_flicker_frames


def case(index: int, seed0: int) -> dict:
    rng = np.random.default_rng([seed0, index])
    frames = 1 if index % 2 == 0 else 12
    timestamps = frames > 1 and (index // 2) % 2 == 0
    negative = (index // 4) % 2 == 1
    clipping = (index // 8) % 2 == 0
    width, height = [(640, 480), (480, 640), (320, 720), (64, 864)][rng.integers(4)]
    fps = float(rng.choice([24.0, 29.97, 30.0, 50.0, 59.94]))
    readout = rng.uniform(0.3, 0.9) / fps
    d = readout / height * (-1.0 if negative else 1.0)
    cycles = float(np.exp(rng.uniform(np.log(0.3), np.log(40.0))))
    f = cycles / readout
    duty = float(rng.uniform(0.05, 0.95))
    exposure = float(rng.uniform(0.0, 0.3)) / f
    light = FlickerLight(f, duty=duty, off_level=float(rng.choice([0.0, rng.uniform(0.0, 0.6)])),
                         waveform="sine" if rng.random() < 0.15 else "square", phase=float(rng.random()))
    scene = FlickerScene(lamp=str(rng.choice(["flat", "disk", "partial"])), lamp_radius=float(rng.uniform(0.35, 0.7)),
                         coverage=float(rng.uniform(0.4, 0.9)), brightness=float(rng.uniform(1.3, 3.0) if clipping
                                                                                else rng.uniform(0.4, 0.8)),
                         black_level=float(rng.uniform(0.0, 0.06)), vignetting=float(rng.uniform(0.0, 0.5)),
                         overlay_text="LED TEST 1/2000" if rng.random() < 0.4 else None, blob=bool(rng.random() < 0.3),
                         texture=float(rng.choice([0.0, rng.uniform(0.05, 0.4)])))
    start = float(rng.uniform(0, 1))
    times = start + np.arange(frames) / fps
    jpeg = int(rng.integers(70, 96)) if rng.random() < 0.5 else None
    images, truth = render_flicker_frames(light, scene, (width, height), d, times, exposure_s=exposure,
                                          noise=float(rng.uniform(0.5, 3.0)), jpeg_quality=jpeg,
                                          seed=seed0 * 1000 + index)
    started = time.perf_counter()
    run = rscalib.estimate_line_delay_flicker(images if frames > 1 else images[0], f,
                                              timestamps_s=times if timestamps else None)
    res = run.result
    seconds = time.perf_counter() - started
    signed = res.direction_determined
    estimate = res.line_delay_s if signed else abs(res.line_delay_s)
    reference = d if signed else abs(d)
    err = (estimate - reference) / abs(d) if math.isfinite(estimate) else float("nan")
    return dict(index=index, seed=[seed0, index], d_true_s=d, frequency_hz=f, cycles_per_frame=cycles, duty=duty,
                exposure_s=exposure, frames=frames, timestamps=timestamps, negative=negative, clipping=clipping,
                clipped_fraction=truth["clipped_fraction"], size=[width, height], lamp=scene.lamp,
                waveform=light.waveform, jpeg=jpeg, determined=res.determined, verdict=run.verdict.status,
                reason=res.reason, method=res.method,
                line_delay_s=res.line_delay_s, line_delay_std_s=res.line_delay_std_s, relative_error=err,
                sigmas=abs(estimate - reference) / res.line_delay_std_s if res.line_delay_std_s > 0 else float("inf"),
                direction_determined=res.direction_determined, sign_right=bool(np.sign(res.line_delay_s) == np.sign(d))
                if signed else None, region=res.region.get("bounding_box_xywh"), seconds=seconds)


def table(rows: list[dict]) -> tuple[str, dict]:
    det = [r for r in rows if r["determined"]]
    errs = np.abs([r["relative_error"] for r in det])
    within = [r for r in det if r["sigmas"] <= 3.0]
    summary = {"cases": len(rows), "determined": len(det), "refused_exit_3": len(rows) - len(det),
               "median_abs_relative_error": float(np.median(errs)) if len(errs) else None,
               "max_abs_relative_error": float(np.max(errs)) if len(errs) else None,
               "within_3_sigma": len(within),
               "sign_right": sum(1 for r in det if r["sign_right"]), "sign_measured": sum(1 for r in det
                                                                                        if r["direction_determined"]),
               "verdicts": {v: sum(1 for r in rows if r.get("verdict") == v)
                            for v in ("trusted", "not trusted", "not determined")}}
    lines = ["| group | cases | determined | median \\|err\\| | max \\|err\\| | within 3σ |", "|---|---|---|---|---|---|"]
    groups = [("all", lambda r: True), ("1 frame", lambda r: r["frames"] == 1),
              ("12 frames, timestamps", lambda r: r["timestamps"]),
              ("12 frames, no timestamps", lambda r: r["frames"] == 12 and not r["timestamps"]),
              ("clipping", lambda r: r["clipping"]), ("no clipping", lambda r: not r["clipping"]),
              ("bottom-to-top", lambda r: r["negative"]), ("< 2 periods/frame", lambda r: r["cycles_per_frame"] < 2),
              ("duty < 20 % or > 80 %", lambda r: r["duty"] < 0.2 or r["duty"] > 0.8)]
    for name, pick in groups:
        sel = [r for r in rows if pick(r)]
        d = [r for r in sel if r["determined"]]
        e = np.abs([r["relative_error"] for r in d])
        w = sum(1 for r in d if r["sigmas"] <= 3.0)
        lines.append(f"| {name} | {len(sel)} | {len(d)} | " + (f"{np.median(e):.2e} | {np.max(e):.2e}" if len(e)
                                                                 else "- | -") + f" | {w}/{len(d)} |")
    return "\n".join(lines), summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=56)
    parser.add_argument("--seed0", type=int, default=1300, help="fresh seeds: change it for new cases")
    parser.add_argument("--results", type=Path, default=C.RESULTS / "exp_flicker_grid.json", help="where the JSON goes")
    args = parser.parse_args()
    started = time.perf_counter()
    rows = []
    for i in range(args.cases):
        r = case(i, args.seed0)
        rows.append(r)
        status = (f"{r['relative_error']:+.2e} ({r['sigmas']:.1f} sigma, {r['method']})" if r["determined"]
                  else f"refused: {r['reason'][:90]}")
        print(f"  {i:2d} {r['frames']:2d} fr ts={r['timestamps']!s:5} {r['cycles_per_frame']:6.2f} per/fr "
              f"duty {r['duty']:.2f} clip {r['clipped_fraction']:.2f} {'neg' if r['negative'] else 'pos'} "
              f"{r['lamp']:7s}: {status} [{r['seconds']:.1f}s]", flush=True)
    text, summary = table(rows)
    settings = dict(cases=args.cases, seed0=args.seed0, total_seconds=time.perf_counter() - started)
    C.write_results("exp_flicker_grid", settings, {"summary": summary, "per_case": rows}, text, path=args.results)
    print(summary)
    print(text)


if __name__ == "__main__":
    main()
