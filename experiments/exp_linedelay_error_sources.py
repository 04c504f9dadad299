"""Where the line-delay error on realistic renders comes from (issue 12; docs/experiments.md
"Where the realistic-render error comes from").

For each video of benchmarks/bench_linedelay_realistic.py (rendered with --render; its truth.json
holds the exact rolling-shutter projection of every corner at the middle of each row's exposure) the
same frames are solved (`rscalib.calibrate_video` on rscalib.Observations,
`LineDelayOptions(self_check=False)`) four times:

- `detected`: the corners the detector found (what `rscalib linedelay` uses);
- `exact`:    the exact mid-exposure projections of the same corners, at the recorded frame times;
- `exact+capture`: the same, at the true capture times (no frame-time jitter or timestamp noise);
- `exact+white`: exact corners plus independent Gaussian noise of the detected corners' RMS error.

`exact` isolates the trajectory model (spline, knots, motion prior) and the time stamps from detection;
`exact+white` shows the error the solver's own sigma describes; `detected` against `exact+white` is
what the detector's error adds beyond white noise of the same size.

    .venv/bin/python experiments/exp_linedelay_error_sources.py --videos /tmp/rscalib_bench_realistic_long
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import _common as C
import numpy as np

import rscalib

SOLVE_ALONE = rscalib.LineDelayOptions(self_check=False)
VARIANTS = ("detected", "exact", "exact+capture", "exact+white")


def corner_sets(folder: Path):
    """(camera, detected Observations, {variant: Observations}, truth) of one rendered video."""
    truth = json.loads((folder / "truth.json").read_text())
    camera = rscalib.load_camera(folder / "camera.yaml").camera
    detection = rscalib.detect_video(folder / "frames", rscalib.load_target(folder / "target.yaml"), progress=False)
    obs = detection.observations
    recorded = np.asarray(truth["recorded_times_s"])
    captured = np.asarray(truth["capture_times_s"])
    frame = np.array([int(np.argmin(np.abs(recorded - t))) for t in obs.frame_times_s])
    if not np.allclose(recorded[frame], obs.frame_times_s, atol=2e-6):
        raise SystemExit(f"{folder}: detected frames do not match truth.json's recorded times")
    mid = truth["projections"].get("uv_rs_mid_exposure")
    if mid is None:
        raise SystemExit(f"{folder}: truth.json has no uv_rs_mid_exposure (render it again)")
    exact = np.full_like(obs.uv, np.nan)
    for k, (f, p) in enumerate(zip(obs.frame_index, obs.point_id)):
        if mid[frame[f]][p] is not None:
            exact[k] = mid[frame[f]][p]
    ok = np.all(np.isfinite(exact), axis=1)
    error = obs.uv[ok] - exact[ok]
    rms_px = float(np.sqrt(np.mean(error ** 2)))
    white = exact[ok] + np.random.default_rng([truth["seed"], 0x57]).normal(0.0, rms_px, exact[ok].shape)

    def observations(uv, times):
        return rscalib.Observations(times, obs.frame_index[ok], obs.point_id[ok], uv, obs.target_points, obs.image_size)

    sets = {"detected": observations(obs.uv[ok], obs.frame_times_s),
            "exact": observations(exact[ok], obs.frame_times_s),
            "exact+capture": observations(exact[ok], captured[frame]),
            "exact+white": observations(white, obs.frame_times_s)}
    return camera, sets, truth, rms_px


def summarise(rows: list[dict]) -> str:
    lines = ["| corners | videos | median \\|error\\| | within 3σ (solver's σ) | mean z | d̂ > d |",
             "|---|---:|---:|---:|---:|---:|"]
    groups = [("all", rows)] + [(s, [r for r in rows if r["style"] == s]) for s in ("handheld", "shake", "sweep")] \
        + [(f"{f:g} fps", [r for r in rows if r["fps"] == f]) for f in (15.0, 24.0, 30.0)]
    for label, subset in groups:
        for variant in VARIANTS:
            z = np.array([r[variant]["z"] for r in subset])
            err = np.array([abs(r[variant]["rel_err"]) for r in subset])
            if not len(z):
                continue
            lines.append(f"| {label}: {variant} | {len(z)} | {100 * np.median(err):.2f} % | "
                         f"{np.sum(np.abs(z) <= 3)}/{len(z)} | {np.mean(z):+.2f} | {np.sum(z > 0)}/{len(z)} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=Path("/tmp/rscalib_bench_realistic_long"))
    parser.add_argument("--out", type=Path,
                        default=C.RESULTS / "exp_linedelay_error_sources.json")
    args = parser.parse_args()
    rows = []
    for folder in sorted(p for p in args.videos.iterdir() if (p / "truth.json").is_file()):
        camera, sets, truth, rms_px = corner_sets(folder)
        if truth["motion_style"] not in ("handheld", "shake", "sweep"):
            continue  # near-static videos: a flag, not an estimate, is the expected answer
        row = {"name": folder.name, "style": truth["motion_style"], "fps": truth["fps"],
               "duration_s": truth["duration_s"], "line_delay_us": truth["line_delay_s"] * 1e6,
               "detected_rms_error_px": rms_px}
        for variant, obs in sets.items():
            result = rscalib.calibrate_video(obs, camera=camera, options=SOLVE_ALONE).result
            d, std = result.line_delay_s, result.line_delay_std_s
            row[variant] = {"d_us": d * 1e6, "std_us": std * 1e6, "segments": result.num_segments,
                            "rel_err": (d - truth["line_delay_s"]) / truth["line_delay_s"],
                            "z": (d - truth["line_delay_s"]) / std, "normalised_cost": result.normalised_cost}
        print(f"{folder.name} {row['style']:8s} {row['fps']:4.0f} fps  " + "  ".join(
            f"{v} {100 * row[v]['rel_err']:+.3f}% ({row[v]['z']:+.1f}σ)" for v in VARIANTS), flush=True)
        rows.append(row)
    table = summarise(rows)
    print(table)
    C.write_results("exp_linedelay_error_sources", {"videos": str(args.videos)}, rows, table, path=args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
