"""`rscalib selfcalib` on phone-like rendered room walks (issue 11; docs/sog.md §16, docs/benchmarks.md).

Sequences: the three motion styles of rscalib.sim.scene_realism (walk-forward, look-around,
sideways-dolly) × 320×240 (the paper's camera) and 640×480 (the S3 phone's camera) × SEEDS fresh
seeds (default 5 from 1100: 30 sequences), FRAMES frames each, rendered with every realism option
(photographic tiles from ../shared/data, rolling shutter, motion blur, auto-exposure, noise,
vignetting, frame jitter and drops, H.264) and cached under CACHE. Each is run through the CLI as a
user would, in its own process:

    python -m rscalib selfcalib SEQ --pixel-size-mm PX --out OUT --quiet

recording the exit code, f, cx, cy, k1, k2 with their reported 99 % bounds (and the filter's own),
whether the truth is inside, the "determined" verdict, wall time and peak RSS (/usr/bin/time -f %M).

Usage: PYTHONPATH=python .venv/bin/python benchmarks/bench_selfcalib_realistic.py
           [--seeds 5] [--seed0 1100] [--frames 200] [--workers 2] [--cache /tmp/rscalib_h11_selfcalib_realistic]
           [--out benchmarks/results/bench_selfcalib_realistic.json] [--rolling-shutter none|truth] [--tag T]
       --feature-level: the filter alone on true correspondences of the same motions (320x240, no images)
Photographs: $RSCALIB_SHARED_DATA, else ../shared/data beside the repository (worktrees: set the variable).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import SELFCALIB_PARAMS as NAMES  # noqa: E402  (benchmarks/_common.py)
from _common import SELFCALIB_STYLES as STYLES  # noqa: E402
from _common import run_selfcalib as run_one  # noqa: E402
from _common import selfcalib_pixel_size_mm as pixel_size_mm  # noqa: E402

SIZES = ((320, 240), (640, 480))
REPO = Path(__file__).resolve().parents[1]


def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if "estimate" in r]
    det = [r for r in ok if r["determined"]]
    side = [r for r in ok if r["style"] == "sideways-dolly"]

    def frac(k, n):
        return {"count": k, "of": n, "fraction": round(k / n, 3) if n else None}

    summary = {
        "sequences": len(rows), "with_result": len(ok),
        "truth_inside_all_five_reported_99": frac(sum(all(r["inside"].values()) for r in ok), len(ok)),
        "truth_inside_all_five_filter_99": frac(sum(all(r["inside_filter"].values()) for r in ok), len(ok)),
        "determined": frac(len(det), len(ok)),
        "determined_f_within_2pct": frac(sum(abs(r["f_error_pct"]) <= 2.0 for r in det), len(det)),
        "determined_truth_inside_all_five": frac(sum(all(r["inside"].values()) for r in det), len(det)),
        "determined_truth_inside_each": {n: frac(sum(r["inside"][n] for r in det), len(det)) for n in NAMES},
        "bundle_truth_inside_all_five_any_verdict": frac(sum(all(r["inside_bundle"].values()) for r in ok
                                                             if "inside_bundle" in r), len(ok)),
        "bundle_truth_inside_each_any_verdict": {n: frac(sum(r["inside_bundle"][n] for r in ok if "inside_bundle" in r),
                                                         len(ok)) for n in NAMES},
        "determined_walk_forward_and_look_around": frac(sum(r["determined"] for r in ok if r["style"] != "sideways-dolly"),
                                                        sum(r["style"] != "sideways-dolly" for r in ok)),
        "determined_f_within_2pct_of_all": frac(sum(abs(r["f_error_pct"]) <= 2.0 for r in det), len(det)),
        "not_converged": frac(sum(r.get("bundle_converged") is False for r in ok), len(ok)),
        "median_abs_f_error_pct_estimate": round(sorted(abs(r["f_error_pct"]) for r in ok)[len(ok) // 2], 2)
        if ok else None,
        "sideways_flagged_not_determined": frac(sum(not r["determined"] for r in side), len(side)),
        "sideways_determined_f_within_2pct": frac(sum(r["determined"] and abs(r["f_error_pct"]) <= 2.0 for r in side),
                                                  sum(r["determined"] for r in side)),
        "sideways_confidently_wrong": frac(sum(r["determined"] and not all(r["inside"].values()) for r in side),
                                           len(side)),
        "by_style_size": {},
    }
    delays = [r["line_delay_s"] for r in ok if "line_delay_s" in r]
    if delays:   # estimated by the adjustment (no --line-delay): against the render's
        errors = sorted(abs(d["bundle"] / d["truth"] - 1.0) * 100.0 for d in delays)
        summary["line_delay_inside_bundle_99"] = frac(sum(d["bounds_99"][0] <= d["truth"] <= d["bounds_99"][1]
                                                          for d in delays), len(delays))
        summary["line_delay_median_abs_error_pct"] = round(errors[len(errors) // 2], 2)
        summary["line_delay_max_abs_error_pct"] = round(errors[-1], 2)
    for style in STYLES:
        for w, h in SIZES:
            g = [r for r in ok if r["style"] == style and r["size"] == f"{w}x{h}"]
            if not g:
                continue
            errs = sorted(abs(r["f_error_pct"]) for r in g)
            summary["by_style_size"][f"{style} {w}x{h}"] = {
                "runs": len(g), "determined": sum(r["determined"] for r in g),
                "inside_all_five": sum(all(r["inside"].values()) for r in g),
                "determined_f_within_2pct": sum(r["determined"] and abs(r["f_error_pct"]) <= 2.0 for r in g),
                "bundle_inside_all_five": sum(all(r.get("inside_bundle", {"f": False}).values()) for r in g),
                "filter_inside_all_five": sum(all(r["inside_filter"].values()) for r in g),
                "median_abs_f_error_pct": round(errs[len(errs) // 2], 2), "max_abs_f_error_pct": round(errs[-1], 2),
                "median_wall_s": sorted(r["wall_s"] for r in g)[len(g) // 2],
                "max_peak_rss_mb": max(r.get("peak_rss_mb") or 0 for r in g)}
    return summary


def feature_level_source(style: str, seed: int, frames: int):
    """True correspondences of points on the room's planes seen along ``style``'s motion (0.5 px
    noise, global shutter): the feature-level twin of a rendered sequence."""
    import numpy as np

    from rscalib.sim.scene_features import TrueCorrespondences, simulate_sequence
    from rscalib.sim.scene_realism import ROOM_SIZE_M, StyledRoomMotion

    rng = np.random.default_rng([0xFEA7, seed])
    lx, ly, lz = ROOM_SIZE_M
    points = rng.uniform(size=(4000, 3)) * [lx, ly, lz] - [lx / 2, ly / 2, 0.0]
    face = rng.integers(6, size=len(points))  # snap each point onto one of the six planes
    for k, (axis, value) in enumerate([(2, 0.0), (2, lz), (0, -lx / 2), (0, lx / 2), (1, -ly / 2), (1, ly / 2)]):
        points[face == k, axis] = value
    motion = StyledRoomMotion(style, seed, frames / 30.0)
    return TrueCorrespondences(simulate_sequence(duration_s=frames / 30.0, seed=seed, points_w=points, motion=motion))


def feature_level(seeds: range, frames: int) -> list[dict]:
    """The filter alone on the same motions and room: true correspondences of points on the room's
    planes (0.5 px noise, global shutter), the default bank options; no images (docs/sog.md §16)."""
    from rscalib import SelfCalibOptions
    from rscalib.selfcalib.driver import run_bank
    from rscalib.selfcalib.engine import sog_options
    from rscalib.selfcalib.prior import make_bank
    from rscalib.sim.scene_features import PAPER_CAMERA
    rows = []
    for style in STYLES:
        for seed in seeds:
            source = feature_level_source(style, seed, frames)
            bank = make_bank(320, 240, pixel_size_mm(320), options=sog_options(SelfCalibOptions()))
            history = run_bank(bank, source.frames(), source)
            f, (lo, hi) = history.mean[-1, 0], history.bounds_99[-1, 0]
            rows.append({"style": style, "seed": seed, "f": f, "f_error_pct": 100 * (f / PAPER_CAMERA.f - 1),
                         "f_bounds_99": [lo, hi], "inside": bool(lo <= PAPER_CAMERA.f <= hi),
                         "gaussians_left": bank.num_gaussians})
            print(f"feature level {style:15s} seed {seed}: f {f:.1f} ({rows[-1]['f_error_pct']:+.1f} %) "
                  f"[{lo:.1f}, {hi:.1f}] gaussians {bank.num_gaussians}", flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seed0", type=int, default=1100)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", default="/tmp/rscalib_h11_selfcalib_realistic")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "bench_selfcalib_realistic.json"))
    ap.add_argument("--rolling-shutter", choices=["none", "truth"], default="none",
                    help="truth: pass each render's line delay as --line-delay (what `rscalib linedelay` measures); "
                         "none: the user does not know it (a global-shutter model)")
    ap.add_argument("--styles", default=",".join(STYLES), help="the motion styles to run, comma-separated")
    ap.add_argument("--tag", default="", help="suffix of the runs folder under CACHE (keeps variants apart)")
    ap.add_argument("--feature-level", action="store_true",
                    help="only the filter on true correspondences of the same motions (no images); prints, writes nothing")
    ap.add_argument("--markdown", metavar="RESULT_JSON", default=None,
                    help="print the per-style table of a written result (docs/benchmarks.md) and exit")
    args = ap.parse_args()
    if args.markdown:
        print(markdown_table(summarise(json.loads(Path(args.markdown).read_text())["runs"])))
        return
    if args.feature_level:
        feature_level(range(args.seed0, args.seed0 + args.seeds), args.frames)
        return
    jobs = [(style, size, args.seed0 + k, args.frames, args.cache, args.rolling_shutter, args.tag)
            for k in range(args.seeds) for size in SIZES for style in STYLES if style in args.styles.split(",")]
    started = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(run_one, *job) for job in jobs]
        for fut in as_completed(futures):
            row = fut.result()
            rows.append(row)
            est = row.get("estimate", {})
            print(f"{row['style']:15s} {row['size']} seed {row['seed']}: exit {row['exit']} "
                  f"f {est.get('f', float('nan')):.1f} (truth {row['truth']['f']:.1f}, {row.get('f_error_pct', 0):+.1f} %) "
                  f"determined {row.get('determined')} inside {sum(row.get('inside', {}).values())}/5 "
                  f"BA-inside {sum(row.get('inside_bundle', {}).values())}/5 "
                  f"hw {row.get('bundle_f_half_width_pct', float('nan')):.2f} % {row['wall_s']} s "
                  f"{row.get('peak_rss_mb')} MB"
                  + (f" d {1e6 * row['line_delay_s']['bundle']:.1f} us/row (truth {1e6 * row['line_delay_s']['truth']:.1f})"
                     if "line_delay_s" in row else ""), flush=True)
            doc = write(args, rows, started, len(jobs))  # after every run: a partial result survives
    print(json.dumps(doc["summary"], indent=1))


def markdown_table(summary: dict) -> str:
    """The per style and size table of docs/benchmarks.md."""
    lines = ["| style | size | runs | determined (exit 0) | determined with f within 2 % | truth in all five reported "
             "99 % | truth in all five of the adjustment's own 99 % | median \\|f err\\| | max \\|f err\\| | "
             "median wall s | max peak RSS MB |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for key, g in summary["by_style_size"].items():
        style, size = key.split()
        lines.append(f"| {style} | {size} | {g['runs']} | {g['determined']} | {g.get('determined_f_within_2pct', '')} | "
                     f"{g['inside_all_five']} | {g.get('bundle_inside_all_five', '')} | {g['median_abs_f_error_pct']} % | "
                     f"{g['max_abs_f_error_pct']} % | {g['median_wall_s']} | {g['max_peak_rss_mb']} |")
    return "\n".join(lines)


def write(args: argparse.Namespace, rows: list[dict], started: float, planned: int) -> dict:
    rows = sorted(rows, key=lambda r: (r["style"], r["size"], r["seed"]))
    doc = {"benchmark": "bench_selfcalib_realistic", "args": vars(args), "planned": planned,
           "total_wall_s": round(time.perf_counter() - started, 1), "cpu_count": os.cpu_count(),
           "load_average_at_end": os.getloadavg(), "summary": summarise(rows), "runs": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1))
    return doc


if __name__ == "__main__":
    main()
