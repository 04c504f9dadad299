"""Does compensating the rolling shutter move self-calibration's numbers? (issue 11, docs/sog.md §18)

On the realistic renders of docs/sog.md §16 (rolling shutter at the renderer's known line delay),
the SOG filter and the bundle adjustment over its tracks (rscalib.selfcalib.bundle), each without
and with rscalib.selfcalib.rolling_shutter.RollingShutterCorrection at the true line delay (no
restarts: the filter's own estimate). Prints one row per run and writes a JSON.

    PYTHONPATH=python .venv/bin/python benchmarks/exp_selfcalib_rolling_shutter.py \\
        --renders /tmp/rscalib_h11_selfcalib_realistic --out benchmarks/results/exp_selfcalib_rolling_shutter.json
    (--front-end tracked: the helper front ends of exp_selfcalib_bundle.FRONT_ENDS; --corrected-only)

Renders: `bench_selfcalib_realistic.py --render` (folders style_WxH_sSEED_nFRAMES with truth.json).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

NAMES = ("f", "cx", "cy", "k1", "k2")


def one_run(folder: Path, line_delay_s: float, front_end_name: str = "default") -> dict:
    from rscalib.selfcalib.bundle import TrackRecorder, bundle_adjust
    from rscalib.selfcalib.calibrate import default_options, read_gray_frames
    from rscalib.selfcalib.driver import run_bank
    from rscalib.selfcalib.front_end import FrontEndOptions, ImageFrontEnd
    from rscalib.selfcalib.prior import make_bank
    from rscalib.selfcalib.rolling_shutter import RollingShutterCorrection, timed_frames

    truth = json.loads((folder / "truth.json").read_text())
    pixel_mm = float(truth["camera"]["pixel_size_mm"][0])
    gray = read_gray_frames(folder)
    width, height = gray.image_size
    from exp_selfcalib_bundle import FRONT_ENDS

    front_end = ImageFrontEnd(FrontEndOptions(**FRONT_ENDS[front_end_name]), gray.image_size)
    frames = gray.frames() if callable(gray.frames) else gray.frames
    source = front_end
    if line_delay_s > 0:
        source, frames = RollingShutterCorrection(front_end, line_delay_s, height), timed_frames(frames)
    recorder = TrackRecorder(source)
    bank = make_bank(width, height, pixel_mm, options=default_options())
    started = time.perf_counter()
    run_bank(bank, frames, recorder, min_visible=front_end.options.min_visible,
             max_new_per_frame=front_end.options.max_new_per_frame, on_frame=recorder.on_frame)
    filter_s = time.perf_counter() - started
    mean = np.asarray(bank.calibration_mean)
    ba = bundle_adjust(recorder.tracks(), mean, pixel_mm)
    true = np.asarray(truth["camera"]["params"], float)
    inside = {n: bool(lo <= t <= hi) for n, t, (lo, hi) in zip(NAMES, true, ba.bounds_99_tracks)}
    return {"line_delay_s": line_delay_s, "filter": dict(zip(NAMES, mean.tolist())),
            "filter_f_error_pct": 100 * (mean[0] / true[0] - 1), "gaussians_left": bank.num_gaussians,
            "ba": dict(zip(NAMES, ba.camera.tolist())), "ba_f_error_pct": 100 * (ba.camera[0] / true[0] - 1),
            "ba_bounds_99_tracks": ba.bounds_99_tracks.tolist(), "ba_inside_tracks": inside,
            "filter_s": filter_s, "ba_s": ba.elapsed_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--renders", default="/tmp/rscalib_h11_selfcalib_realistic")
    parser.add_argument("--only", default="", help="comma-separated substrings of the folder names")
    parser.add_argument("--front-end", default="default", help="exp_selfcalib_bundle.FRONT_ENDS name")
    parser.add_argument("--corrected-only", action="store_true", help="skip the global-shutter-model run")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "exp_selfcalib_rolling_shutter.json"))
    args = parser.parse_args()
    folders = sorted(p for p in Path(args.renders).iterdir() if (p / "truth.json").exists())
    if args.only:
        folders = [p for p in folders if any(s in p.name for s in args.only.split(","))]
    rows = []
    for folder in folders:
        truth = json.loads((folder / "truth.json").read_text())
        row = {"sequence": folder.name, "style": truth["style"], "seed": truth["seed"],
               "size": f'{truth["camera"]["width"]}x{truth["camera"]["height"]}',
               "true_line_delay_s": truth["line_delay_s"]}
        row["front_end"] = args.front_end
        for label, d in (("global_shutter_model", 0.0), ("corrected", float(truth["line_delay_s"]))):
            if label == "corrected" or not args.corrected_only:
                row[label] = one_run(folder, d, args.front_end)
        c = row["corrected"]
        g = row.get("global_shutter_model", c)
        print(f'{folder.name:40s} filter f {g["filter_f_error_pct"]:+6.1f} -> {c["filter_f_error_pct"]:+6.1f} %   '
              f'BA f {g["ba_f_error_pct"]:+6.2f} -> {c["ba_f_error_pct"]:+6.2f} %   BA truth in 5 (tracks) '
              f'{sum(g["ba_inside_tracks"].values())} -> {sum(c["ba_inside_tracks"].values())}', flush=True)
        rows.append(row)
    Path(args.out).write_text(json.dumps({"experiment": "exp_selfcalib_rolling_shutter", "runs": rows}, indent=1))
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
