"""`rscalib selfcalib` where the adjustment has nothing to hold on to (issue 30, docs/sog.md §24): a
camera that does not move, and one that barely moves (the room walk slowed 50 times: millimetres of
translation, a fraction of a degree of turn). Each must end in exit 3 with the prior's bounds (not an
adjustment's value), write no camera.yaml, and claim no number in result.json (f null).

Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_selfcalib_no_parallax.py [--frames 90]
           [--seeds 2] [--seed0 1600] [--cache /tmp/rscalib_no_parallax] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _common import RESULTS, machine_info, write_results

from rscalib.reference_cameras import PAPER_PIXEL_SIZE_MM
from rscalib.sim.scene_video import render_scene_sequence
from rscalib.sim.trajectories import RoomWalkTrajectory

SLOWDOWN = {"static": 0.0, "barely moving": 0.02}


class Slowed:
    """The room walk at ``factor`` of its speed (0: the first pose held)."""

    def __init__(self, base, factor: float) -> None:
        self.base, self.factor = base, float(factor)

    def pose_cw(self, t_s):
        return self.base.pose_cw(np.asarray(t_s, dtype=np.float64) * self.factor)


def run_case(name: str, seed: int, frames: int, cache: Path) -> dict:
    seq = cache / f"{name.replace(' ', '-')}_s{seed}_n{frames}"
    if not (seq / "truth.json").exists():
        render_scene_sequence(seq, num_frames=frames, seed=seed, noise_sigma=1.0,
                              trajectory=Slowed(RoomWalkTrajectory(seed=seed), SLOWDOWN[name]))
    out = cache / "runs" / seq.name
    started = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "rscalib", "selfcalib", str(seq), "--pixel-size-mm",
                           str(PAPER_PIXEL_SIZE_MM), "--out", str(out), "--quiet", "--force"],
                          capture_output=True, text=True)
    result = json.loads((out / "result.json").read_text()) if (out / "result.json").exists() else {}
    adjustment = result.get("adjustment") or {}
    prior = result.get("filter_bounds_99")
    row = {"case": name, "seed": seed, "frames": frames, "exit": proc.returncode,
           "wall_s": round(time.perf_counter() - started, 1), "reason": result.get("reason"),
           "f_claimed": result.get("f"), "f_bounds_99": result.get("f_bounds_99"),
           "adjustment_f": (adjustment.get("estimate") or [None])[0],
           "adjustment_converged": adjustment.get("converged"), "camera_yaml": (out / "camera.yaml").exists(),
           "verdict": (result.get("verdict") or {}).get("status"), "filter_bounds_99": prior}
    row["ok"] = (row["exit"] == 3 and row["f_claimed"] is None and not row["camera_yaml"]
                 and row["verdict"] == "not determined")
    print(f"{name:14s} seed {seed}: exit {row['exit']} verdict {row['verdict']} f {row['f_claimed']} "
          f"bounds {row['f_bounds_99']} camera.yaml {row['camera_yaml']} ok {row['ok']}: {row['reason']}", flush=True)
    return row


def _interval(bounds) -> str:
    return "—" if not bounds else f"[{bounds[0]:.1f}, {bounds[1]:.1f}] px"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--seed0", type=int, default=1600)
    ap.add_argument("--cache", default="/tmp/rscalib_no_parallax")
    ap.add_argument("--json", default=str(RESULTS / "bench_selfcalib_no_parallax.json"))
    args = ap.parse_args()
    rows = [run_case(name, args.seed0 + k, args.frames, Path(args.cache))
            for k in range(args.seeds) for name in SLOWDOWN]
    table = "\n".join(["| case | seed | exit | verdict | f claimed | f bounds 99 % reported | camera.yaml |",
                       "| --- | ---: | ---: | --- | --- | --- | --- |"] +
                      [f"| {r['case']} | {r['seed']} | {r['exit']} | {r['verdict']} | {r['f_claimed']} | "
                       f"{_interval(r['f_bounds_99'])} | {'written' if r['camera_yaml'] else 'none'} |" for r in rows])
    write_results(Path(args.json), "bench_selfcalib_no_parallax", machine_info(), vars(args), rows, table,
                  all_ok=all(r["ok"] for r in rows))
    print(f"{sum(r['ok'] for r in rows)} of {len(rows)} end in exit 3 with no number claimed and no camera.yaml")


if __name__ == "__main__":
    main()
