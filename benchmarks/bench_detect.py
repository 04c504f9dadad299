"""Target detection speed, frames per second, per target type at 640x480 and 1920x1080.

    .venv/bin/python benchmarks/bench_detect.py [--frames 40] [--sizes 640x480,1920x1080]

Frames are synthetic: each target (rscalib.io.targets.Target.draw) seen through a pinhole camera
from a random pose (a homography warp), with mild blur and noise. Two rates per case:
- "one process": rscalib.detection.detectors.Detector.detect on decoded grey frames (detection only);
- "detect_video": the whole pipeline on an MJPG video of the same frames repeated 3 times —
  decoding, the worker processes (all usable cores) and their start-up included, no cache.
The target is at least the video's frame rate (30 fps) at 640x480.
Writes a markdown table and the machine info to benchmarks/results/bench_detect.json.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import _common  # noqa: E402  (benchmarks/_common.py: machine record, results file)
import cv2
import numpy as np

from rscalib.detection.detectors import Detector
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video, usable_cores
from rscalib.io.targets import target_from_dict

RESULTS = Path(__file__).resolve().parent / "results" / "bench_detect.json"

TARGETS = {
    "checkerboard 9x6": {"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                         "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03},
    "circlegrid 7x5": {"target_type": "circlegrid", "targetCols": 7, "targetRows": 5, "spacingMeters": 0.035,
                       "asymmetricGrid": False},
    "asymmetric circlegrid 4x11": {"target_type": "circlegrid", "targetCols": 4, "targetRows": 11,
                                   "spacingMeters": 0.02, "asymmetricGrid": True},
    "aprilgrid 6x6": {"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": 0.03, "tagSpacing": 0.3},
    "charuco 7x5": {"target_type": "charuco", "squaresX": 7, "squaresY": 5, "squareLength": 0.035,
                    "markerLength": 0.026, "dictionary": "DICT_5X5_100"},
}


def render_frames(target, size, count, seed):
    """Grey frames of the target from random poses, the target about half the image high."""
    width, height = size
    f = 0.9 * width
    k = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])
    extent = target.points_m.max(0) - target.points_m.min(0)
    centre = 0.5 * (target.points_m.min(0) + target.points_m.max(0))
    distance = f * max(extent[0], extent[1]) / (0.5 * height)  # the board spans half the image height
    board, h_board = target.draw(pixels_per_metre=1.3 * f / distance, margin_m=0.01)
    flip = np.diag([1.0, -1.0, -1.0]) if target.target_type == "aprilgrid" else np.eye(3)  # Kalibr: y up
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(count):
        r = cv2.Rodrigues(np.r_[rng.uniform(-0.4, 0.4, 2), rng.uniform(-0.5, 0.5)])[0] @ flip
        offset = np.r_[rng.uniform(-0.2, 0.2) * distance * width / f, rng.uniform(-0.1, 0.1) * distance,
                       distance * rng.uniform(0.95, 1.2)]
        t = offset - r @ centre
        h = k @ np.column_stack([r[:, 0], r[:, 1], t]) @ np.linalg.inv(h_board)
        image = cv2.warpPerspective(board, h, size, flags=cv2.INTER_LINEAR, borderValue=110)
        image = cv2.GaussianBlur(image, (0, 0), 0.8)
        noisy = image + rng.normal(0, 2.0, image.shape)
        frames.append(np.clip(noisy, 0, 255).astype(np.uint8))
    return frames


def machine_info() -> dict:
    return _common.machine_info(usable_cores=usable_cores(), opencv=cv2.__version__)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="frames per case (40)")
    parser.add_argument("--sizes", default="640x480,1920x1080", help="image sizes (640x480,1920x1080)")
    parser.add_argument("--targets", default=",".join(TARGETS), help="comma-separated target names")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    names = [n.strip() for n in args.targets.split(",")]
    info = machine_info()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            target = target_from_dict(TARGETS[name])
            for size in sizes:
                frames = render_frames(target, size, args.frames, seed=1)
                detector = Detector(target)
                detector.detect(frames[0])  # warm-up
                started = time.perf_counter()
                found = sum(detector.detect(f).accepted for f in frames)
                one_process_fps = len(frames) / (time.perf_counter() - started)

                video = Path(tmp) / f"{target.target_type}_{size[0]}.avi"
                writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, size, False)
                writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
                for _ in range(3):  # a longer video, so worker start-up does not dominate
                    for f in frames:
                        writer.write(f)
                writer.release()
                started = time.perf_counter()
                result = detect_video(video, target, DetectOptions(workers=None, cache=False), progress=False)
                pipeline_fps = result.frames_total / (time.perf_counter() - started)
                rows.append({"target": name, "size": f"{size[0]}x{size[1]}", "frames": len(frames),
                             "detected_one_process": int(found), "video_frames": int(result.frames_total),
                             "detected_pipeline": int(result.frames_detected),
                             "fps_one_process": one_process_fps, "fps_detect_video": pipeline_fps,
                             "workers": usable_cores()})
                print(f"{name:28s} {size[0]:4d}x{size[1]:<4d} one process {one_process_fps:6.1f} fps "
                      f"({found}/{len(frames)}), detect_video {pipeline_fps:6.1f} fps "
                      f"({result.frames_detected}/{result.frames_total})", flush=True)

    header = ("| target | size | frames/s, one process | frames/s, detect_video "
              f"({usable_cores()} workers, start-up included) | detected |\n|---|---|---:|---:|---:|")
    lines = [header] + [f"| {r['target']} | {r['size']} | {r['fps_one_process']:.1f} | {r['fps_detect_video']:.1f} | "
                        f"{r['detected_one_process']}/{r['frames']} |" for r in rows]
    table = "\n".join(lines)
    print(f"\n{info['cpu_model']}, {info['usable_cores']} usable cores, OpenCV {info['opencv']}, "
          f"load average {info['load_average_1min_at_start']}\n")
    print(table)
    _common.write_results(args.out, "bench_detect", info, {"frames_per_case": args.frames, "sizes": args.sizes, "video_codec": "MJPG quality 95"}, rows, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
