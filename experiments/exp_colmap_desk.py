"""The real desk video (issue 11): rscalib's self-calibration (`rscalib.self_calibrate`, the front
door of `rscalib selfcalib`) next to the offline structure-from-motion
self-calibration a user would otherwise reach for — COLMAP through pycolmap (PyPI), one shared
SIMPLE_RADIAL camera over every 2nd or 3rd frame, sequential matching, incremental mapping.

Truth: the authors' offline calibration in ../shared/data/real_selfcalib_s3phone/README.md
(fx 525.06, fy 524.245, c (308.649, 236.536) px). COLMAP's pixel centres sit at +0.5 px
(docs/formats.md): its principal point minus 0.5 is compared. COLMAP holds the principal point at
the image centre unless asked to refine it; both are run.

Usage: .venv/bin/python experiments/exp_colmap_desk.py [--steps 3,2] [--skip-rscalib]
Writes benchmarks/results/exp_colmap_desk.json and prints a markdown table (docs/experiments.md).
"""
from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import _common as C
import cv2

import rscalib

DATA = C.REPO.parent / "shared" / "data" / "real_selfcalib_s3phone"
VIDEO = DATA / "escritorio_traslacion.mp4"
TRUTH = {"fx": 525.060, "fy": 524.245, "cx": 308.649, "cy": 236.536}
PIXEL_SIZE_MM = 0.0070216


def decode(step: int, folder: Path) -> list[str]:
    """Every `step`-th frame of the video as PNG; their names."""
    folder.mkdir(parents=True, exist_ok=True)
    capture = cv2.VideoCapture(str(VIDEO))
    names, index = [], 0
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        if index % step == 0:
            name = f"frame_{index:06d}.png"
            cv2.imwrite(str(folder / name), frame)
            names.append(name)
        index += 1
    capture.release()
    return names


def run_colmap(step: int, refine_principal_point: bool, work: Path) -> dict:
    import pycolmap

    images = work / f"images_step{step}"
    if not images.is_dir():
        decode(step, images)
    database = work / f"step{step}_pp{int(refine_principal_point)}.db"
    output = work / f"sparse_step{step}_pp{int(refine_principal_point)}"
    database.unlink(missing_ok=True)
    output.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "SIMPLE_RADIAL"
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = 2
    pycolmap.extract_features(database, images, camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                              extraction_options=extraction, device=pycolmap.Device.cpu)
    pycolmap.match_sequential(database, device=pycolmap.Device.cpu)
    options = pycolmap.IncrementalPipelineOptions()
    options.ba_refine_principal_point = refine_principal_point
    options.num_threads = 2
    options.random_seed = 0
    models = pycolmap.incremental_mapping(database, images, output, options=options)
    seconds = time.perf_counter() - started
    if not models:
        return {"step": step, "refine_principal_point": refine_principal_point, "seconds": seconds,
                "registered": 0, "error": "no model"}
    best = max(models.values(), key=lambda r: r.num_reg_images())
    camera = next(iter(best.cameras.values()))
    f, cx, cy, k = (float(x) for x in camera.params)
    return {"step": step, "refine_principal_point": refine_principal_point, "seconds": seconds,
            "images": len(list(images.glob("*.png"))), "registered": best.num_reg_images(),
            "points": best.num_points3D(), "f": f, "cx": cx - 0.5, "cy": cy - 0.5, "k": k,
            "f_rel_error": f / (0.5 * (TRUTH["fx"] + TRUTH["fy"])) - 1.0,
            "c_error_px": [cx - 0.5 - TRUTH["cx"], cy - 0.5 - TRUTH["cy"]]}


def run_rscalib(work: Path) -> dict:
    """`rscalib selfcalib VIDEO --pixel-size-mm ...` as its front door, with its files; run first, so
    this process's peak memory is rscalib's (COLMAP has not run yet)."""
    started = time.perf_counter()
    run = rscalib.self_calibrate(VIDEO, rscalib.SelfCalibOptions(pixel_size_mm=PIXEL_SIZE_MM))
    result = run.write(work / "rscalib")
    seconds = time.perf_counter() - started
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"exit": run.verdict.exit_code, "seconds": seconds, "peak_rss_mb": peak_mb, "result": result}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", default="3,2", help="frame steps for COLMAP (every Nth frame)")
    parser.add_argument("--skip-rscalib", action="store_true")
    args = parser.parse_args()
    if not VIDEO.is_file():
        sys.exit(f"{VIDEO} not found (../shared/data beside the repository)")
    rows = []
    with tempfile.TemporaryDirectory(prefix="rscalib_colmap_") as tmp:
        work = Path(tmp)
        ours = None if args.skip_rscalib else run_rscalib(work)
        for step in (int(s) for s in args.steps.split(",")):
            for refine in (False, True):
                row = run_colmap(step, refine, work)
                rows.append(row)
                print(json.dumps(row), flush=True)
    lines = ["| method | frames | f (px) | f error | cx, cy (px) | c error (px) | run time |", "|---|---|---|---|---|---|---|"]
    truth_f = 0.5 * (TRUTH["fx"] + TRUTH["fy"])
    lines.append(f"| offline calibration (README) | — | {truth_f:.1f} | — | {TRUTH['cx']:.1f}, {TRUTH['cy']:.1f} | — | — |")
    for r in rows:
        if "f" not in r:
            lines.append(f"| COLMAP step {r['step']} | 0 registered | — | — | — | — | {r['seconds']:.0f} s |")
            continue
        pp = "refined" if r["refine_principal_point"] else "held at the centre"
        nth = {2: "2nd", 3: "3rd"}.get(r["step"], f"{r['step']}th")
        lines.append(f"| COLMAP SIMPLE_RADIAL, every {nth} frame, principal point {pp} | {r['registered']}/"
                     f"{r['images']} | {r['f']:.1f} | {100 * r['f_rel_error']:+.1f} % | {r['cx']:.1f}, {r['cy']:.1f} | "
                     f"{r['c_error_px'][0]:+.1f}, {r['c_error_px'][1]:+.1f} | {r['seconds']:.0f} s |")
    if ours is not None:
        res = ours["result"]
        f, cx, cy = res.get("f"), res.get("cx"), res.get("cy")
        bounds = res.get("f_bounds_99")
        verdict = "determined" if res.get("determined") else f"not determined (exit {ours['exit']})"
        f_text = "—" if f is None else f"{f:.1f}" + (f" [{bounds[0]:.0f}, {bounds[1]:.0f}]" if bounds else "")
        f_err = "—" if f is None else f"{100 * (f / truth_f - 1):+.1f} %"
        c_text = "—" if cx is None else f"{cx:.1f}, {cy:.1f}"
        c_err = "—" if cx is None else f"{cx - TRUTH['cx']:+.1f}, {cy - TRUTH['cy']:+.1f}"
        lines.append(f"| rscalib selfcalib (all 359 frames, online), {verdict} | 359 | {f_text} | {f_err} | {c_text} | "
                     f"{c_err} | {ours['seconds']:.0f} s |")
    text = "\n".join(lines)
    summary = {"colmap": rows, "rscalib": None if ours is None else {k: v for k, v in ours.items() if k != "result"}}
    if ours is not None:
        summary["rscalib"]["result"] = {k: v for k, v in ours["result"].items() if k != "history"}
    settings = {"steps": args.steps, "command": " ".join([".venv/bin/python"] + sys.argv), "truth": TRUTH}
    C.write_results("exp_colmap_desk", settings, summary, text)
    print(text)


if __name__ == "__main__":
    main()
