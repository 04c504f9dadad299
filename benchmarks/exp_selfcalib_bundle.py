"""Does a batch bundle adjustment make self-calibration trustworthy? (issue 11, an experiment)

The SOG bank runs as `rscalib selfcalib` runs it (default_options(), the image front end, no
restarts); rscalib.selfcalib.bundle.TrackRecorder keeps the measurements it used, its poses and
points; rscalib.selfcalib.bundle.bundle_adjust refines [f, cx, cy, k1, k2] over every 3rd frame,
started (1) from the filter's estimate and (2) from a generic camera (f = image width, c = centre,
k = 0; the filter's poses and points still start the rest). Per run: filter f error, BA f error,
whether the truth is inside the BA's 99 % bounds of each parameter, BA time.

Parts: (a) feature level: true correspondences of the rendered walks' motions
(bench_selfcalib_realistic.feature_level_source), 320x240, 0.5 px noise; (b) image level: the
cached realistic renders (bench_selfcalib_realistic.py renders them into --cache); (c) the real
desk video (truth: the offline calibration; $RSCALIB_SHARED_DATA, else ../shared/data beside the
repository: worktrees set the variable).

Usage: PYTHONPATH=python .venv/bin/python benchmarks/exp_selfcalib_bundle.py [--parts abc]
           [--sizes 320x240,640x480] [--seeds 5] [--seed0 1100] [--frames 200] [--step 3]
           [--cache /tmp/rscalib_h11_selfcalib_realistic] [--out benchmarks/results/exp_selfcalib_bundle.json]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine_info  # noqa: E402
from bench_selfcalib_realistic import NAMES, STYLES, feature_level_source, pixel_size_mm  # noqa: E402

from rscalib.selfcalib.bundle import TrackRecorder, bundle_adjust  # noqa: E402
from rscalib.selfcalib.calibrate import default_options, read_gray_frames  # noqa: E402
from rscalib.selfcalib.driver import run_bank  # noqa: E402
from rscalib.selfcalib.front_end import FrontEndOptions, ImageFrontEnd  # noqa: E402
from rscalib.selfcalib.prior import make_bank  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("RSCALIB_SHARED_DATA", REPO.parent / "shared" / "data"))
DESK = SHARED_DATA / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"
DESK_TRUTH = {"f": 524.65, "cx": 308.6, "cy": 236.5}
DESK_PIXEL_SIZE_MM = 0.0070216


def filter_and_tracks(frames, source, size: tuple[int, int], pixel_mm: float) -> tuple[np.ndarray, object, float]:
    """The bank over ``frames`` with ``source`` wrapped in a TrackRecorder: final calibration mean,
    the tracks, wall time (s)."""
    recorder = TrackRecorder(source)
    bank = make_bank(size[0], size[1], pixel_mm, options=default_options())
    started = time.perf_counter()
    history = run_bank(bank, frames, recorder, min_visible=getattr(source, "options", FrontEndOptions()).min_visible,
                       max_new_per_frame=getattr(source, "options", FrontEndOptions()).max_new_per_frame,
                       on_frame=recorder.on_frame)
    return history.mean[-1].copy(), recorder.tracks(), time.perf_counter() - started


def compare(label: dict, truth: dict, filter_mean: np.ndarray, tracks, size: tuple[int, int], pixel_mm: float,
            step: int, filter_s: float) -> dict:
    """BA from the filter and from a generic camera; errors and coverage against ``truth``."""
    row = dict(label, truth=truth, filter=dict(zip(NAMES, filter_mean.tolist())), filter_s=round(filter_s, 2),
               filter_f_error_pct=100 * (filter_mean[0] / truth["f"] - 1), observations_recorded=len(tracks))
    generic = np.array([size[0], size[0] / 2, size[1] / 2, 0.0, 0.0])
    for name, start in (("ba", filter_mean), ("ba_generic", generic)):
        try:
            ba = bundle_adjust(tracks, start, pixel_mm, keyframe_step=step)
        except (ValueError, np.linalg.LinAlgError) as err:   # InputError is a ValueError
            row[name] = {"error": str(err)}
            continue
        out = ba.summary_dict()
        out["f_error_pct"] = 100 * (ba.camera[0] / truth["f"] - 1)
        out["inside"] = {n: bool(ba.bounds_99[i, 0] <= truth[n] <= ba.bounds_99[i, 1])
                         for i, n in enumerate(NAMES) if n in truth}
        row[name] = out
    return row


def print_row(row: dict) -> None:
    ba, gen = row.get("ba", {}), row.get("ba_generic", {})
    print(f"{row['part']} {row.get('style', ''):15s} {row.get('size', '')} {row.get('seed', '')}: "
          f"filter f {row['filter']['f']:.1f} ({row['filter_f_error_pct']:+.1f} %)  "
          f"BA f {ba.get('f', float('nan')):.1f} ({ba.get('f_error_pct', float('nan')):+.2f} %) "
          f"[{ba.get('f_bounds_99', [np.nan] * 2)[0]:.1f}, {ba.get('f_bounds_99', [np.nan] * 2)[1]:.1f}] "
          f"inside {sum(ba.get('inside', {}).values())}/{len(ba.get('inside', {}))} "
          f"sigma {ba.get('sigma_px', np.nan):.2f} px {ba.get('elapsed_s', np.nan):.1f} s | "
          f"generic f {gen.get('f', float('nan')):.1f} ({gen.get('f_error_pct', float('nan')):+.2f} %)"
          + (f" ERROR {ba['error']}" if "error" in ba else ""), flush=True)


def part_a(args) -> list[dict]:
    from rscalib.sim.scene_features import PAPER_CAMERA

    truth = dict(zip(NAMES, PAPER_CAMERA.params.tolist()))
    rows = []
    for style in STYLES:
        for seed in range(args.seed0, args.seed0 + args.seeds):
            source = feature_level_source(style, seed, args.frames)
            mean, tracks, filter_s = filter_and_tracks(source.frames(), source, (320, 240), pixel_size_mm(320))
            rows.append(compare({"part": "a", "style": style, "size": "320x240", "seed": seed}, truth, mean, tracks,
                                (320, 240), pixel_size_mm(320), args.step, filter_s))
            print_row(rows[-1])
    return rows


def image_run(label: dict, source_path: Path, truth: dict, pixel_mm: float, step: int) -> dict:
    gray = read_gray_frames(source_path)
    front_end = ImageFrontEnd(FrontEndOptions(), gray.image_size)
    mean, tracks, filter_s = filter_and_tracks(gray.frames, front_end, gray.image_size, pixel_mm)
    row = compare(dict(label, size=f"{gray.image_size[0]}x{gray.image_size[1]}"), truth, mean, tracks,
                  gray.image_size, pixel_mm, step, filter_s)
    print_row(row)
    return row


def part_b(args) -> list[dict]:
    rows = []
    for size in args.sizes.split(","):
        for style in STYLES:
            for seed in range(args.seed0, args.seed0 + args.seeds):
                seq = Path(args.cache) / f"{style}_{size}_s{seed}_n{args.frames}"
                if not (seq / "truth.json").exists():
                    print(f"missing {seq} (render it with bench_selfcalib_realistic.py)", flush=True)
                    continue
                camera = json.loads((seq / "truth.json").read_text())["camera"]
                truth = dict(zip(NAMES, camera["params"]))
                rows.append(image_run({"part": "b", "style": style, "seed": seed}, seq, truth,
                                      float(camera["pixel_size_mm"][0]), args.step))
    return rows


def part_c(args) -> list[dict]:
    return [image_run({"part": "c", "style": "desk video", "seed": None}, DESK, DESK_TRUTH, DESK_PIXEL_SIZE_MM,
                      args.step)]


def summarise(rows: list[dict]) -> dict:
    out = {}
    for key in sorted({(r["part"], r.get("style"), r.get("size")) for r in rows}, key=str):
        group = [r for r in rows if (r["part"], r.get("style"), r.get("size")) == key and "f" in r.get("ba", {})]
        if not group:
            continue
        inside = {n: sum(r["ba"]["inside"].get(n, False) for r in group) for n in NAMES if n in group[0]["ba"]["inside"]}
        out[" ".join(str(k) for k in key)] = {
            "runs": len(group),
            "filter_f_error_pct": [round(r["filter_f_error_pct"], 2) for r in group],
            "ba_f_error_pct": [round(r["ba"]["f_error_pct"], 2) for r in group],
            "ba_f_within_2pct": sum(abs(r["ba"]["f_error_pct"]) <= 2 for r in group),
            "ba_inside_99": inside,
            "ba_inside_all": sum(all(r["ba"]["inside"].values()) for r in group),
            "ba_generic_f_error_pct": [round(r["ba_generic"].get("f_error_pct", np.nan), 2) for r in group],
            "ba_median_s": float(np.median([r["ba"]["elapsed_s"] for r in group])),
            "filter_median_s": float(np.median([r["filter_s"] for r in group])),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="abc")
    ap.add_argument("--sizes", default="320x240,640x480")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seed0", type=int, default=1100)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--step", type=int, default=3, help="keyframe every STEP frames")
    ap.add_argument("--cache", default="/tmp/rscalib_h11_selfcalib_realistic")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "exp_selfcalib_bundle.json"))
    args = ap.parse_args()
    started = time.perf_counter()
    rows: list[dict] = []
    for part, run in (("a", part_a), ("b", part_b), ("c", part_c)):
        if part in args.parts:
            rows += run(args)
            doc = {"experiment": "exp_selfcalib_bundle", "args": vars(args), "machine": machine_info(),
                   "command": " ".join(sys.argv), "total_wall_s": round(time.perf_counter() - started, 1),
                   "load_average_at_end": os.getloadavg(), "summary": summarise(rows), "runs": rows}
            Path(args.out).write_text(json.dumps(doc, indent=1, default=float))
    print(json.dumps(summarise(rows), indent=1, default=float))


if __name__ == "__main__":
    main()
