"""Self-calibration where the renders are not the world (issue 30, stop 43): two studies through the
front door `rscalib.self_calibrate`, as `rscalib selfcalib` runs.

lens: the realistic room renders (rscalib.sim.scene_realism, every realism option) filmed through a real
  lens instead of the civera-radial camera the self-calibration model assumes: OpenCV's sample camera
  (640x480, pinhole-radtan, k1 -0.28: strong barrel distortion), calibrated here from its 13 stills in
  ../shared/data/opencv_stereo_chessboard with `rscalib.calibrate_intrinsics` (RMS 0.18 px). The
  two-coefficient civera model can only approximate that lens: how do f and the verdict fare? Truth:
  f = (fx + fy) / 2 of the calibration, its principal point.
desk: the real desk video (../shared/data/real_selfcalib_s3phone) with the line delay held at several
  values (SelfCalibOptions.line_delay_s) next to the default (estimated from the scene): how f follows d.

Usage: .venv/bin/python experiments/exp_selfcalib_real_lens.py [--study lens,desk] [--seeds 7001,7002,7003]
           [--styles walk-forward,look-around,sideways-dolly] [--frames 400] [--cache /tmp/rscalib_real_lens]
Writes benchmarks/results/exp_selfcalib_real_lens.json and prints markdown tables (docs/sog.md §27).
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import _common as C

import rscalib
from rscalib.sim.scene_realism import PHONE_PIXEL_SIZE_MM, render_realistic_scene, shared_data_dir

STILLS_TARGET = "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n"
DESK_PIXEL_SIZE_MM = 0.0070216
DESK_TRUTH = {"f": (525.060 + 524.245) / 2, "cx": 308.649, "cy": 236.536}
DESK_LINE_DELAYS_S = (None, 0.0, 30e-6, 50e-6, 90e-6)


def real_lens(data: Path) -> rscalib.CameraModel:
    """OpenCV's sample camera, calibrated from its stills (pinhole-radtan, 640x480)."""
    with tempfile.TemporaryDirectory() as folder:
        target = Path(folder) / "target.yaml"
        target.write_text(STILLS_TARGET)
        run = rscalib.calibrate_intrinsics(data / "opencv_stereo_chessboard", target)
    return run.camera


def row_of(run: rscalib.SelfCalibRun, truth: dict) -> dict:
    """f, cx, cy with their reported 99 % bounds (claimed or not), the verdict, the errors and the
    line delay the adjustment used."""
    summary = run.summary()
    claimed = summary.get("not_claimed") or {}
    value = {n: summary.get(n) if summary.get(n) is not None else claimed.get(n) for n in ("f", "cx", "cy")}
    bounds = {n: summary.get(f"{n}_bounds_99") for n in ("f", "cx", "cy")}
    row = {"exit_code": run.verdict.exit_code, "status": run.verdict.status, "determined": bool(summary.get("determined")),
           **{n: value[n] for n in value}, **{f"{n}_bounds_99": bounds[n] for n in bounds},
           "line_delay_s": summary.get("line_delay_estimated_s", summary.get("line_delay_given")),
           "self_check_widen": (summary.get("self_check") or {}).get("widen", [None])[0]}
    if value["f"] is not None:
        row["f_error_pct"] = 100.0 * (value["f"] / truth["f"] - 1.0)
        row["truth_inside"] = {n: bool(bounds[n] and bounds[n][0] <= truth[n] <= bounds[n][1]) for n in truth}
    return row


def lens_study(args, data: Path) -> list[dict]:
    camera = real_lens(data)
    fx, fy, cx, cy = (float(v) for v in list(camera.params)[:4])
    truth = {"f": (fx + fy) / 2, "cx": cx, "cy": cy}
    print(f"lens: {camera.model} {[round(float(p), 4) for p in camera.params]}", flush=True)
    rows = []
    for style in args.styles.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            folder = Path(args.cache) / f"{style}_{seed}"
            if not (folder / "truth.json").exists():
                render_realistic_scene(folder, style, (640, 480), args.frames, seed, camera=camera, threads=2)
            started = time.perf_counter()
            run = rscalib.self_calibrate(folder / "video.mp4", rscalib.SelfCalibOptions(pixel_size_mm=PHONE_PIXEL_SIZE_MM))
            row = {"study": "lens", "style": style, "seed": seed, "truth": truth, **row_of(run, truth),
                   "wall_s": round(time.perf_counter() - started, 1)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def desk_study(data: Path) -> list[dict]:
    video = data / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"
    rows = []
    for line_delay_s in DESK_LINE_DELAYS_S:
        options = rscalib.SelfCalibOptions(pixel_size_mm=DESK_PIXEL_SIZE_MM, line_delay_s=line_delay_s)
        row = {"study": "desk", "line_delay_held_s": line_delay_s, **row_of(rscalib.self_calibrate(video, options),
                                                                             DESK_TRUTH)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def _bounds(b) -> str:
    return f"[{b[0]:.1f}, {b[1]:.1f}]" if b else "-"


def tables(rows: list[dict]) -> str:
    lines = []
    lens = [r for r in rows if r["study"] == "lens"]
    if lens:
        lines += [f"| style | seed | exit | f (truth {lens[0]['truth']['f']:.1f}) | f error | f 99 % | truth in f, cx, cy "
                  "| widened by |",
                  "| --- | ---: | ---: | ---: | ---: | --- | --- | ---: |"]
        for r in lens:
            inside = r.get("truth_inside") or {}
            lines.append(f"| {r['style']} | {r['seed']} | {r['exit_code']} | {r['f']:.1f} | {r.get('f_error_pct', 0):+.1f} % | "
                         f"{_bounds(r['f_bounds_99'])} | {''.join('y' if inside.get(n) else 'n' for n in ('f', 'cx', 'cy'))} | "
                         f"{r['self_check_widen'] or 1:.2f} |")
    desk = [r for r in rows if r["study"] == "desk"]
    if desk:
        lines += ["", f"| line delay | exit | f (truth {DESK_TRUTH['f']:.1f}) | f error | f 99 % | cx, cy |",
                  "| --- | ---: | ---: | ---: | --- | --- |"]
        for r in desk:
            held = r["line_delay_held_s"]
            d = f"estimated, {1e6 * r['line_delay_s']:.1f} µs/row" if held is None else f"held at {1e6 * held:.0f} µs/row"
            lines.append(f"| {d} | {r['exit_code']} | {r['f']:.1f} | {r.get('f_error_pct', 0):+.1f} % | "
                         f"{_bounds(r['f_bounds_99'])} | {r['cx']:.1f}, {r['cy']:.1f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", default="lens,desk")
    ap.add_argument("--seeds", default="7001,7002,7003")
    ap.add_argument("--styles", default="walk-forward,look-around,sideways-dolly")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--cache", default="/tmp/rscalib_real_lens")
    ap.add_argument("--out", default=str(C.RESULTS / "exp_selfcalib_real_lens.json"))
    args = ap.parse_args()
    data = shared_data_dir() or (C.REPO.parent / "shared" / "data")   # the installed package is not beside it
    if not data.is_dir():
        raise SystemExit("needs ../shared/data (or $RSCALIB_SHARED_DATA): the stills, the desk video, the photographs")
    rows = []
    if "lens" in args.study:
        rows += lens_study(args, data)
    if "desk" in args.study:
        rows += desk_study(data)
    table = tables(rows)
    print(table)
    C.write_results_file(Path(args.out), "exp_selfcalib_real_lens", C.machine_info(), vars(args), rows, table)


if __name__ == "__main__":
    main()
