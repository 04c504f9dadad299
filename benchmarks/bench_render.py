"""Rolling-shutter renderer speed: frames per second of `RollingShutterRenderer.render` (the image
only: no noise, encoding or truth) and of `render_video`'s frame loop (with noise, FFV1 encoding and
the truth projections), at 640x480 and 1280x720, with and without motion blur; plus the one-off
set-up (unprojecting every sub-pixel).

    .venv/bin/python benchmarks/bench_render.py [--frames 10] [--workers N] [--quick]

Prints a markdown table and writes it with the machine info to benchmarks/results/bench_render.json.
The hand-held motion is the default (amplitude 1, seed 0) and d = 30 µs; with blur, the number of
exposure samples is chosen per frame (consecutive copies ≤ ½ px apart), so blur cost grows with the
image speed × exposure.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rscalib.io.targets import Target
from rscalib.sim import target_video as render
from rscalib.sim.target_observations import default_camera
from rscalib.sim.trajectories import target_trajectory

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402
from _common import machine_info  # noqa: E402  (one definition of the machine record)

RESULTS = Path(__file__).resolve().parent / "results" / "bench_render.json"


def time_frames(size, supersample, exposure_s, frames, workers, target="checkerboard"):
    camera = default_camera(size)
    tgt = Target.named(target)
    trajectory = target_trajectory(camera, tgt, 10.0, seed=0)
    started = time.perf_counter()
    renderer = render.RollingShutterRenderer(camera, tgt, trajectory, 30e-6, supersample=supersample,
                                             exposure_s=exposure_s, workers=workers)
    setup_s = time.perf_counter() - started
    times = np.arange(frames) / 30.0  # the frames render_video draws first
    samples = [len(renderer.exposure_offsets_s(t)) for t in times]
    renderer.render(times[0])  # warm-up (first-touch of the ray grid, thread start)
    started = time.perf_counter()
    for t in times:
        renderer.render(t)
    seconds = time.perf_counter() - started
    renderer.close()
    return frames / seconds, setup_s, float(np.mean(samples))


def time_video(size, supersample, exposure_s, frames, workers):
    """Frames/s of render_video's frame loop (render + noise + FFV1 encoding + truth projections),
    without the one-off set-up (ray grid) and the truth.json written at the end."""
    with tempfile.TemporaryDirectory() as out:
        video = render.render_video(out, size=size, duration_s=(frames + 0.5) / 30.0, exposure_s=exposure_s,
                                    supersample=supersample, workers=workers, progress=False)
    return video.frames_per_second_rendered


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10, help="frames timed per case")
    parser.add_argument("--workers", type=int, default=None, help="render threads (default: renderer's)")
    parser.add_argument("--exposure", type=float, default=0.004, help="exposure of the blur cases, s (0.004)")
    parser.add_argument("--quick", action="store_true", help="640x480 only, 3 frames")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    frames = 3 if args.quick else args.frames
    sizes = [(640, 480)] if args.quick else [(640, 480), (1280, 720)]

    rows = []
    for size in sizes:
        for supersample in (3, 2, 1):
            for exposure_s in (0.0, args.exposure):
                fps, setup_s, samples = time_frames(size, supersample, exposure_s, frames, args.workers)
                row = {"size": f"{size[0]}x{size[1]}", "supersample": supersample, "exposure_ms": exposure_s * 1e3,
                       "exposure_samples_mean": samples, "frames_per_s": fps, "setup_s": setup_s}
                if supersample == 3:  # the default: also the whole pipeline with encoding and truth
                    row["video_frames_per_s"] = time_video(size, supersample, exposure_s, frames, args.workers)
                rows.append(row)
                print(f"  {row['size']} ss={supersample} exposure {exposure_s * 1e3:g} ms: {fps:.2f} frames/s",
                      file=sys.stderr)

    header = ("| size | supersample | exposure (ms) | exposure samples | render frames/s | "
              "render_video frames/s | setup (s) |\n|---|---:|---:|---:|---:|---:|---:|")
    lines = [header] + [
        f"| {r['size']} | {r['supersample']}x{r['supersample']} | {r['exposure_ms']:g} | "
        f"{r['exposure_samples_mean']:.1f} | {r['frames_per_s']:.2f} | "
        f"{r['video_frames_per_s']:.2f} | {r['setup_s']:.2f} |" if "video_frames_per_s" in r else
        f"| {r['size']} | {r['supersample']}x{r['supersample']} | {r['exposure_ms']:g} | "
        f"{r['exposure_samples_mean']:.1f} | {r['frames_per_s']:.2f} | | {r['setup_s']:.2f} |"
        for r in rows]
    table = "\n".join(lines)
    info = machine_info()
    print(f"Rolling-shutter rendering, default camera and hand-held motion, {frames} frames per case.")
    print(f"{info['cpu_model']}, nproc {info['usable_cores']}, Python {info['python']}\n")
    print(table)
    _common.write_results(args.out, "bench_render", info, {"frames": frames, "workers": args.workers, "exposure_s": args.exposure,
                     "line_delay_s": 30e-6, "target": "checkerboard"}, rows, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
