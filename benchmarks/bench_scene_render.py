"""Rendering speed of the textured-room renderer (rscalib.sim.scene_video), frames/s.

    .venv/bin/python benchmarks/bench_scene_render.py [--frames 60] [--out PATH]

Cases: supersampling 2x2 and 3x3, one and two threads, in memory (float image only) and to disk
(8-bit PNG per frame plus truth.json). Paper camera, 320x240, default room and hand-held walk.
Prints a markdown table; ``--out`` also writes it with the machine record (benchmarks/_common.py).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from rscalib.sim import scene_video as sr  # noqa: E402
from rscalib.sim.trajectories import RoomWalkTrajectory  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="write the results JSON here")
    args = parser.parse_args()

    camera = sr.default_camera()
    start = time.perf_counter()
    scene = sr.room_scene(args.seed)
    scene_s = time.perf_counter() - start
    times_s = np.arange(args.frames) / 30.0
    R, p = RoomWalkTrajectory(seed=args.seed).pose_cw(times_s)

    rows = []
    for supersampling in (2, 3):
        for threads in (1, 2):
            start = time.perf_counter()
            renderer = sr.SceneRenderer(camera, scene, supersampling, threads=threads)
            setup_s = time.perf_counter() - start
            renderer.render(R[0], p[0])  # warm-up
            start = time.perf_counter()
            for i in range(args.frames):
                renderer.render(R[i], p[i])
            fps = args.frames / (time.perf_counter() - start)
            rows.append({"case": "render in memory", "supersampling": supersampling, "threads": threads,
                         "frames_per_s": fps, "setup_s": setup_s})
    with tempfile.TemporaryDirectory() as tmp:
        seq = sr.render_scene_sequence(tmp, num_frames=args.frames, seed=args.seed)
        # elapsed_s includes building the scene (textures) once; report both.
        rows.append({"case": "render_scene_sequence to PNG (incl. scene build)", "supersampling": 2, "threads": 1,
                     "frames_per_s": args.frames / seq.elapsed_s, "setup_s": None})

    table = "\n".join(["| case | supersampling | threads | frames/s |", "|---|---:|---:|---:|"]
                      + [f"| {r['case']} | {r['supersampling']}x{r['supersampling']} | {r['threads']} | "
                         f"{r['frames_per_s']:.1f} |" for r in rows])
    info = _common.machine_info()
    print(f"Scene renderer, 320x240 paper camera, {args.frames} frames, room seed {args.seed} "
          f"(textures built in {scene_s:.2f} s).")
    print(f"{info['cpu_model']}, {info['usable_cores']} usable cores, load {info['load_average_1min_at_start']}\n")
    print(table)
    if args.out is not None:
        _common.write_results(args.out, "bench_scene_render", info,
                              {"frames": args.frames, "seed": args.seed, "image": "320x240"}, rows, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
