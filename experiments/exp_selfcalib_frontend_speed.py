"""CPU cost per frame of the self-calibration loop with each image front end (issue 11): the desk
video (640x480; or --source) through the SOG bank as `rscalib selfcalib` runs it (default_options(), no
restarts); per frame the CPU time of the whole loop (decoding included) and of the front end's
calls, over the frames after the bank holds one Gaussian.

Usage: RSCALIB_SHARED_DATA=../shared/data PYTHONPATH=python .venv/bin/python
           benchmarks/exp_selfcalib_frontend_speed.py [--front-ends default,tracked,tracked-h]
           [--source VIDEO_OR_FOLDER] [--out benchmarks/results/exp_selfcalib_frontend_speed.json]
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
from exp_selfcalib_bundle import DESK, DESK_PIXEL_SIZE_MM, FRONT_ENDS, TimedSource  # noqa: E402

from rscalib.selfcalib.calibrate import default_options, read_gray_frames  # noqa: E402
from rscalib.selfcalib.driver import run_bank  # noqa: E402
from rscalib.selfcalib.front_end import FrontEndOptions, ImageFrontEnd  # noqa: E402
from rscalib.selfcalib.prior import make_bank  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def one(front_end: str, source_path: Path = DESK) -> dict:
    gray = read_gray_frames(source_path)
    source = TimedSource(ImageFrontEnd(FrontEndOptions(**FRONT_ENDS[front_end]), gray.image_size))
    bank = make_bank(gray.image_size[0], gray.image_size[1], DESK_PIXEL_SIZE_MM, options=default_options())
    loop_cpu, front_cpu, gaussians = [], [], []
    last = [time.process_time(), 0.0]

    def on_frame(k, bank, report) -> None:
        now = time.process_time()
        loop_cpu.append(now - last[0])
        front_cpu.append(source.cpu_s - last[1])
        gaussians.append(bank.num_gaussians)
        last[:] = [now, source.cpu_s]

    run_bank(bank, gray.frames, source, min_visible=source.options.min_visible,
             max_new_per_frame=source.options.max_new_per_frame, on_frame=on_frame)
    single = np.flatnonzero(np.asarray(gaussians) == 1)
    after = slice(int(single[0]) + 1 if len(single) else len(gaussians), None)
    loop_ms, front_ms = 1e3 * np.asarray(loop_cpu[after]), 1e3 * np.asarray(front_cpu[after])
    row = {"front_end": front_end, "source": str(source_path), "frames": len(loop_cpu), "collapse_frame": int(single[0]) if len(single) else None,
           "frames_after_collapse": len(loop_ms),
           "loop_cpu_ms_per_frame_median": float(np.median(loop_ms)) if len(loop_ms) else None,
           "frames_per_cpu_s": float(1e3 / np.mean(loop_ms)) if len(loop_ms) else None,
           "front_end_cpu_ms_per_frame_median": float(np.median(front_ms)) if len(front_ms) else None,
           "front_end_cpu_ms_per_frame_p90": float(np.percentile(front_ms, 90)) if len(front_ms) else None,
           "front_end_cpu_ms_per_frame_all_frames": 1e3 * source.cpu_s / max(source.calls, 1)}
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--front-ends", default="default,tracked,tracked-h")
    ap.add_argument("--source", default=str(DESK), help="a video or image folder (default: the desk video)")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "exp_selfcalib_frontend_speed.json"))
    args = ap.parse_args()
    rows = [one(name, Path(args.source)) for name in args.front_ends.split(",")]
    Path(args.out).write_text(json.dumps({"experiment": "exp_selfcalib_frontend_speed", "command": " ".join(sys.argv),
                                          "machine": machine_info(), "load_average_at_end": os.getloadavg(),
                                          "runs": rows}, indent=1))


if __name__ == "__main__":
    main()
