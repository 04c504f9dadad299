"""Checkerboard detection speed with and without tracking (issue 17), and whether both agree.

    .venv/bin/python benchmarks/bench_detection_speed.py [--sizes 640x480:60:ffv1,1920x1080:20:ffv1+mp4v]
        [--naive-frames 100] [--no-compare]

Speed, per size and codec (a rendered 9x6 checkerboard video, `rscalib simulate --supersample 1`:
FFV1, lossless and slow to decode; "mp4v": the same frames re-encoded as MPEG-4 Part 2 by
OpenCV's writer, closer to the decode cost of a phone's H.264):
  (a) decode only: FrameSource.frames(gray=True, luma=True), the reader detection uses;
  (b) the naive single-process loop: cv2.VideoCapture.read, grey, cv2.findChessboardCornersSB
      (on the first --naive-frames frames);
  (c) detect_video with full detection in every frame (DetectOptions(full_detection_every=1));
  (d) detect_video with tracking (the default, a full detection every 40 frames);
  (c) and (d) on all usable cores, worker start-up included, no cache, each also as CPU ms per
      frame of all its processes (this one and the joined workers: os.times), with the load average;
  and, robust to other load on the machine, the CPU time per frame in one process (first 200
  frames): decoding, full detection, tracked detection (time.process_time, all threads).
Agreement (--compare, on by default): on rendered 640x480 videos (calm, hand-held and wild
motion, and motion blur) and on a sequence made from a real photo (OpenCV's left01.jpg under a
smoothly moving homography) and the 13 real stills as they are (no motion to track: every frame
falls back), (c) against (d) on the frames both accept: median / 99th percentile / max corner
difference in px and the share of frames each accepts; and each against the renderer's exact
corners (truth.json uv_rs), an independent oracle.
Renders are cached in /tmp/rscalib_speed_videos (--videos). The machine may be shared: the load
average at the start and the end is recorded. Writes benchmarks/results/bench_detection_speed.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import _common  # noqa: E402  (benchmarks/_common.py: machine record, results file)
import cv2
import numpy as np

from rscalib.detection.detectors import Detector
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video, usable_cores
from rscalib.detection.tracking import CheckerboardTracker, RunDetector, run_length
from rscalib.io.targets import load_target
from rscalib.io.video import open_source

RESULTS = Path(__file__).resolve().parent / "results" / "bench_detection_speed.json"
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FULL = DetectOptions(full_detection_every=1)
TRACKED = DetectOptions()
# rendered agreement cases: name -> `rscalib simulate` arguments (640x480, 9x6 board)
COMPARE_RENDERS = {
    "calm (motion 0.5)": ["--duration", "10", "--seed", "12", "--motion", "0.5"],
    "hand-held (motion 1)": ["--duration", "10", "--seed", "11", "--motion", "1"],
    "wild (motion 2)": ["--duration", "10", "--seed", "13", "--motion", "2"],
    "blur (motion 1, 8 ms exposure)": ["--duration", "6", "--seed", "14", "--motion", "1", "--exposure", "8ms"],
}
RENDER_DIRS = {"calm (motion 0.5)": "m05_640", "hand-held (motion 1)": "m1_640", "wild (motion 2)": "m2_640",
               "blur (motion 1, 8 ms exposure)": "blur_640"}


def render(folder: Path, args: list) -> Path:
    """A cached `rscalib simulate` render (supersample 1: sharp enough, fast to make)."""
    if not (folder / "video.avi").is_file():
        subprocess.run([sys.executable, "-m", "rscalib", "simulate", "--out", str(folder), "--quiet",
                        "--workers", "2", "--supersample", "1", *args], check=True)
    return folder


def real_photo_sequence(folder: Path, data: Path, frames: int = 150) -> Path:
    """A video of OpenCV's real left01.jpg under a smooth homography (rotation, shift, zoom):
    real texture, noise and JPEG blocks with known inter-frame motion; no truth file."""
    video = folder / "video.avi"
    if video.is_file():
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    photo = cv2.imread(str(data / "opencv_stereo_chessboard" / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    height, width = photo.shape
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"FFV1"), 30.0, (width, height), False)
    for k in range(frames):
        t = k / 30.0
        angle = 4.0 * np.sin(2 * np.pi * 0.3 * t)
        scale = 1.0 + 0.05 * np.sin(2 * np.pi * 0.2 * t)
        warp = cv2.getRotationMatrix2D((width / 2, height / 2), angle, scale)
        warp[:, 2] += [12.0 * np.sin(2 * np.pi * 0.25 * t), 8.0 * np.cos(2 * np.pi * 0.35 * t)]
        writer.write(cv2.warpAffine(photo, warp, (width, height), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REPLICATE))
    writer.release()
    (folder / "target.yaml").write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n"
                                        "rowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n")
    return folder


def process_cpu_s() -> float:
    """CPU time of this process and its finished children (the joined detection workers)."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def rate(source, target, options) -> tuple[float, object]:
    started, cpu_started = time.perf_counter(), process_cpu_s()
    result = detect_video(source, target, replace(options, cache=False), progress=False)
    result.pipeline_cpu_ms = (process_cpu_s() - cpu_started) * 1e3 / max(1, result.frames_total)
    return result.frames_total / (time.perf_counter() - started), result


def cpu_ms_per_frame(video: Path, target, frames: int = 200) -> dict:
    """CPU time per frame in this process (all its threads): decode, full, tracked detection."""
    started, images = time.process_time(), []
    for frame in open_source(video).frames(gray=True, luma=True):
        images.append((frame.index, frame.image))
        if len(images) == frames:
            break
    row = {"cpu_decode_ms": (time.process_time() - started) * 1e3 / len(images)}
    for name, options in (("full", FULL), ("tracked", TRACKED)):
        runs = RunDetector(Detector(target, options), run_length(target, options))
        started = time.process_time()
        for index, image in images:
            runs.detect(image, index)
        row[f"cpu_{name}_ms"] = (time.process_time() - started) * 1e3 / len(images)
    return row


def speed_row(folder: Path, video: Path, naive_frames: int) -> dict:
    target = load_target(folder / "target.yaml")
    started = time.perf_counter()
    decoded = sum(1 for _ in open_source(video).frames(gray=True, luma=True))
    decode_fps = decoded / (time.perf_counter() - started)

    capture = cv2.VideoCapture(str(video), cv2.CAP_FFMPEG)
    rows, cols = target.grid_shape
    started, naive, found = time.perf_counter(), 0, 0
    while naive < naive_frames:
        ok, image = capture.read()
        if not ok:
            break
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        found += bool(cv2.findChessboardCornersSB(gray, (cols, rows))[0])
        naive += 1
    naive_fps = naive / (time.perf_counter() - started)
    capture.release()

    load = os.getloadavg()[0]
    full_fps, full = rate(video, target, FULL)
    tracked_fps, tracked = rate(video, target, TRACKED)
    width, height = full.image_size
    return {"size": f"{width}x{height}", "frames": decoded, "decode_fps": decode_fps, "naive_fps": naive_fps,
            "naive_frames": naive, "naive_found": found, "full_fps": full_fps, "tracked_fps": tracked_fps,
            "full_pipeline_cpu_ms": full.pipeline_cpu_ms, "tracked_pipeline_cpu_ms": tracked.pipeline_cpu_ms,
            "load_average_1min": load, "full_dropped": full.dropped, "tracked_dropped": tracked.dropped,
            "full_accepted": full.frames_detected, "tracked_accepted": tracked.frames_detected,
            "workers": usable_cores(), **cpu_ms_per_frame(video, target), **agreement(full, tracked, folder)}


def per_frame(result) -> dict:
    obs = result.observations
    return {int(number): (obs.point_id[obs.frame_index == k], obs.uv[obs.frame_index == k])
            for k, number in enumerate(result.frame_numbers)}


def agreement(full, tracked, folder: Path) -> dict:
    """Corner differences on the frames both accept, and each one's error against truth.json."""
    a, b = per_frame(full), per_frame(tracked)
    both = sorted(set(a) & set(b))
    diffs = [np.linalg.norm(a[n][1] - b[n][1], axis=1) for n in both if np.array_equal(a[n][0], b[n][0])]
    diff = np.concatenate(diffs) if diffs else np.full(1, np.nan)
    row = {"frames_both": len(both), "id_mismatch_frames": len(both) - len(diffs),
           "diff_median_px": float(np.median(diff)), "diff_p99_px": float(np.percentile(diff, 99)),
           "diff_max_px": float(np.max(diff)), "only_full": len(set(a) - set(b)), "only_tracked": len(set(b) - set(a))}
    truth_file = folder / "truth.json"
    if truth_file.is_file():
        uv_true = np.asarray(json.loads(truth_file.read_text())["projections"]["uv_rs"], dtype=np.float64)
        for name, frames in (("full", a), ("tracked", b)):
            errors = np.concatenate([np.linalg.norm(uv - uv_true[n][ids], axis=1) for n, (ids, uv) in frames.items()])
            row[f"{name}_truth_median_px"] = float(np.median(errors))
            row[f"{name}_truth_p99_px"] = float(np.percentile(errors, 99))
    return row


def tracked_share(source, target) -> dict:
    """How the tracker spent its frames (in this process, runs of 20 as detect_video cuts them)."""
    detector = Detector(target, TRACKED)
    counts = {"full": 0, "tracked": 0, "track_rejected": 0, "left_image": 0}
    tracker = None
    for k, frame in enumerate(f for f in open_source(source).frames(gray=True, luma=True) if f.image is not None):
        if k % TRACKED.full_detection_every == 0:
            if tracker is not None:
                counts = {key: counts[key] + tracker.counts[key] for key in counts}
            tracker = CheckerboardTracker(detector)
        tracker.detect(frame.image, frame.index)
    if tracker is not None:
        counts = {key: counts[key] + tracker.counts[key] for key in counts}
    return counts


def compare_row(name: str, source, folder: Path, target) -> dict:
    full_fps, full = rate(source, target, FULL)
    tracked_fps, tracked = rate(source, target, TRACKED)
    return {"case": name, "frames": full.frames_total, "full_accepted": full.frames_detected,
            "tracked_accepted": tracked.frames_detected, "full_fps": full_fps, "tracked_fps": tracked_fps,
            **tracked_share(source, target), **agreement(full, tracked, folder)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="640x480:60:ffv1,1920x1080:20:ffv1+mp4v",
                        help="WxH:seconds:codecs per size (codecs ffv1 and/or mp4v, joined by +)")
    parser.add_argument("--naive-frames", type=int, default=100, help="frames timed in the naive loop (100)")
    parser.add_argument("--no-compare", action="store_true", help="skip the agreement cases")
    parser.add_argument("--no-speed", action="store_true", help="only the agreement cases")
    parser.add_argument("--data", type=Path, default=DATA, help="the shared real data (../shared/data)")
    parser.add_argument("--videos", type=Path, default=Path("/tmp/rscalib_speed_videos"))
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    info = _common.machine_info(usable_cores=usable_cores(), opencv=cv2.__version__)
    speed, compare = [], []
    for seed, item in enumerate([] if args.no_speed else args.sizes.split(","), start=1):
        size, seconds, codecs = item.split(":")
        folder = render(args.videos / f"speed_{size}_{seconds}s", ["--size", size, "--duration", seconds,
                                                                    "--seed", str(seed)])
        for codec in codecs.split("+"):
            video = folder / "video.avi" if codec == "ffv1" else _common.mpeg4(folder)
            row = {"codec": codec, **speed_row(folder, video, args.naive_frames)}
            speed.append(row)
            print(row, flush=True)
    if not args.no_compare:
        cases = [(name, render(args.videos / RENDER_DIRS[name], extra)) for name, extra in COMPARE_RENDERS.items()]
        for name, folder in cases:
            compare.append(compare_row(name, folder / "video.avi", folder, load_target(folder / "target.yaml")))
            print(compare[-1], flush=True)
        if args.data.is_dir():
            folder = real_photo_sequence(args.videos / "real_left01_warped", args.data)
            target = load_target(folder / "target.yaml")
            compare.append(compare_row("real photo, moving (left01.jpg warped)", folder / "video.avi", folder, target))
            print(compare[-1], flush=True)
            stills = sorted((args.data / "opencv_stereo_chessboard").glob("left*.jpg"))
            compare.append(compare_row("real stills (13, unrelated views)", stills, args.videos, target))
            print(compare[-1], flush=True)
    info["load_average_1min_at_end"] = os.getloadavg()[0]

    lines = ["| size, codec | frames | load | (a) decode only | (b) naive loop, 1 process | (c) detect_video, full | "
             "(d) detect_video, tracked | (d)/(c) | CPU ms/frame in one process: decode, full, tracked | "
             "CPU ms/frame of detect_video (all processes): (c), (d) | accepted (c) / (d) | "
             "diff median / p99 / max (px) |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['size']} {r['codec']} | {r['frames']} | {r['load_average_1min']:.1f} | {r['decode_fps']:.0f} | "
              f"{r['naive_fps']:.1f} | {r['full_fps']:.1f} | {r['tracked_fps']:.1f} | {r['tracked_fps'] / r['full_fps']:.2f} | "
              f"{r['cpu_decode_ms']:.1f}, {r['cpu_full_ms']:.1f}, {r['cpu_tracked_ms']:.1f} | "
              f"{r['full_pipeline_cpu_ms']:.1f}, {r['tracked_pipeline_cpu_ms']:.1f} | "
              f"{r['full_accepted']} / {r['tracked_accepted']} | "
              f"{r['diff_median_px']:.4f} / {r['diff_p99_px']:.4f} / {r['diff_max_px']:.4f} |"
              for r in speed]
    lines += ["", "| case | frames | accepted full / tracked | tracked frames | diff median (px) | diff p99 | diff max | "
              "error vs truth, median full / tracked (px) |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in compare:
        truth = (f"{r['full_truth_median_px']:.4f} / {r['tracked_truth_median_px']:.4f}"
                 if "full_truth_median_px" in r else "–")
        lines.append(f"| {r['case']} | {r['frames']} | {r['full_accepted']} / {r['tracked_accepted']} | "
                     f"{r['tracked']} | {r['diff_median_px']:.4f} | {r['diff_p99_px']:.4f} | {r['diff_max_px']:.4f} | "
                     f"{truth} |")
    table = "\n".join(lines)
    print(f"\n{info['cpu_model']}, {info['usable_cores']} usable cores, OpenCV {info['opencv']}, load average "
          f"{info['load_average_1min_at_start']} at the start, {info['load_average_1min_at_end']} at the end\n")
    print(table)
    _common.write_results(args.out, "bench_detection_speed", info,
                          {"sizes": args.sizes, "naive_frames": args.naive_frames,
                           "full_detection_every": TRACKED.full_detection_every, "codec": "FFV1"},
                          {"speed": speed, "compare": compare}, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
