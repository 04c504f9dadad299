"""Speed and memory of `rscalib selfcalib` on 30 s of 640x480 video (issue 30: <= 60 s wall on the
2-core machine, peak <= 1 GB; docs/benchmarks.md).

Renders (once, cached under CACHE) 30 s walks of the phone camera with every realism option of
rscalib.sim.scene_realism (photographic textures, rolling shutter 30 us/row, blur, auto-exposure,
frame jitter and drops, compression), one per motion style and seed, and runs each through the CLI
in its own process, one at a time (the machine's two cores are the run's):

    python -m rscalib selfcalib SEQ --pixel-size-mm PX --out OUT --quiet

recording the wall time, the peak RSS (/usr/bin/time -f %M), the exit code, f with its bounds and the
line delay (_common.run_selfcalib), and the machine's load average before each run.

Usage: .venv/bin/python benchmarks/bench_selfcalib_speed.py [--styles walk-forward,look-around,sideways-dolly]
           [--seed0 1500] [--seeds 1] [--seconds 30] [--cache /tmp/rscalib_selfcalib_speed]
           [--out benchmarks/results/bench_selfcalib_speed.json]
Photographs: $RSCALIB_SHARED_DATA, else ../shared/data beside the repository.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import SELFCALIB_STYLES as STYLES  # noqa: E402  (benchmarks/_common.py)
from _common import run_selfcalib as run_one  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
FPS = 30
SIZE = (640, 480)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--styles", default=",".join(STYLES))
    ap.add_argument("--seed0", type=int, default=1500)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--cache", default="/tmp/rscalib_selfcalib_speed")
    ap.add_argument("--tag", default="", help="suffix of the runs folder under CACHE (keeps code versions apart)")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "bench_selfcalib_speed.json"))
    args = ap.parse_args()
    frames = int(round(args.seconds * FPS))
    rows = []
    for seed in range(args.seed0, args.seed0 + args.seeds):
        for style in args.styles.split(","):
            load_before = os.getloadavg()[0]
            row = run_one(style, SIZE, seed, frames, args.cache, tag=args.tag)
            row["load_average_before"] = round(load_before, 2)
            rows.append(row)
            f = row.get("estimate", {}).get("f")
            print(f"{style:15s} seed {seed}: exit {row['exit']} wall {row['wall_s']:.1f} s, peak {row['peak_rss_mb']:.0f} MB, "
                  f"{row['frames']} frames, f {f if f is None else round(f, 2)} (truth {row['truth']['f']}), "
                  f"load before {load_before:.2f}", flush=True)
    summary = {"runs": len(rows), "max_wall_s": max(r["wall_s"] for r in rows),
               "max_peak_rss_mb": max(r["peak_rss_mb"] for r in rows),
               "within_60_s": sum(r["wall_s"] <= 60.0 for r in rows),
               "within_1_gb": sum(r["peak_rss_mb"] <= 1024.0 for r in rows)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"benchmark": "bench_selfcalib_speed", "args": vars(args),
                                          "cpu_count": os.cpu_count(), "summary": summary, "runs": rows,
                                          "finished": time.strftime("%Y-%m-%d %H:%M:%S")}, indent=1))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
