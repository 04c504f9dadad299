"""Joint refinement of the intrinsics with the line delay (`rscalib linedelay --refine-intrinsics`,
docs/formulation.md §14; docs/experiments.md "Joint refinement of the intrinsics").

For each rendered video (`rscalib simulate`, fresh seeds, two resolutions) four runs of the front
door of `rscalib linedelay --no-self-check`, `rscalib.calibrate_video(video, target, camera,
LineDelayOptions(self_check=False, refine_intrinsics=...))`, each writing the command's files
(run.write): the true camera file or a deliberately wrong one (f 2 % long, principal point +8 px in u
and v), each without and with the refinement. Writes benchmarks/results/exp_refine_intrinsics.json
and prints the markdown table of docs/experiments.md.

    .venv/bin/python experiments/exp_refine_intrinsics.py [--videos DIR] [--render]
"""
from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import rscalib

ROOT = Path(__file__).resolve().parents[1]
VIDEOS = (("640x480", 4101, "30us"), ("640x480", 4102, "20us"), ("640x480", 4103, "45us"),
          ("960x540", 4201, "30us"), ("960x540", 4202, "25us"), ("960x540", 4203, "40us"))
FOCAL_FACTOR, CENTRE_SHIFT_PX = 1.02, 8.0


def cli(*args) -> list[str]:
    return [sys.executable, "-m", "rscalib", *map(str, args)]


def render(folder: Path, size: str, seed: int, delay: str) -> None:
    if not (folder / "truth.json").exists():
        subprocess.run(cli("simulate", "--out", folder, "--size", size, "--seed", seed, "--line-delay", delay,
                           "--duration", 5, "--workers", 1, "--quiet"), check=True)


def wrong_camera(folder: Path) -> Path:
    camera = rscalib.load_camera(folder / "camera.yaml").camera
    p = np.array(camera.params, dtype=np.float64)
    p[:2] *= FOCAL_FACTOR
    p[2:4] += CENTRE_SHIFT_PX
    path = folder / "camera_wrong.yaml"
    rscalib.write_camera(rscalib.CameraModel(camera.model, p, camera.width, camera.height), path)
    return path


def run(folder: Path, camera: Path, refine: bool, out: Path) -> dict:
    if (out / "row.json").exists():  # done before (delete the folder to redo)
        return json.loads((out / "row.json").read_text())
    options = rscalib.LineDelayOptions(self_check=False, refine_intrinsics=refine)
    started = time.perf_counter()
    done = rscalib.calibrate_video(folder / "video.avi", folder / "target.yaml", camera, options)
    done.write(out)
    wall = time.perf_counter() - started
    result = done.result   # the estimate (also when the verdict claims no number)
    truth = json.loads((folder / "truth.json").read_text())
    true_params = np.array(truth["camera"]["params"], dtype=np.float64)
    d, std = result.line_delay_s, result.line_delay_std_s
    command = (f"rscalib.calibrate_video({folder.name}/video.avi, target.yaml, {camera.name}, "
               f"LineDelayOptions(self_check=False, refine_intrinsics={refine}))")
    row = {"video": folder.name, "camera": camera.name, "refine": refine, "exit": done.verdict.exit_code,
           "command": command, "true_line_delay_s": truth["line_delay_s"],
           "line_delay_s": d, "line_delay_std_s": std, "z_d": (d - truth["line_delay_s"]) / std,
           "normalised_cost": result.normalised_cost, "wall_s": wall}
    ki = result.intrinsics
    if ki:
        for i, name in enumerate(("fx", "fy", "cx", "cy")):
            row[f"{name}_error"] = ki["estimate"][name] - true_params[i]
            row[f"{name}_std"] = ki["std"][name]
            row[f"z_{name}"] = row[f"{name}_error"] / ki["std"][name]
        row["corr_d_fy"] = ki["correlation_with_line_delay"]["fy"]
        row["corr_d_cy"] = ki["correlation_with_line_delay"]["cy"]
    (out / "row.json").write_text(json.dumps(row))
    return row


def table(rows: list[dict]) -> str:
    lines = ["| video | start | refine | d true (µs) | d̂ ± σ (µs) | (d̂−d)/σ | fx err ± σ (px) | (f̂−f)/σ fx, fy "
             "| ĉ−c ± σ (px) cx, cy | (ĉ−c)/σ cx, cy | J/2N | time (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        start = "f +2 %, c +8 px" if r["camera"] == "camera_wrong.yaml" else "true"
        if r["refine"]:
            f = f"{r['fx_error']:+.2f} ± {r['fx_std']:.2f}"
            zf = f"{r['z_fx']:+.2f}, {r['z_fy']:+.2f}"
            c = f"{r['cx_error']:+.2f} ± {r['cx_std']:.2f}, {r['cy_error']:+.2f} ± {r['cy_std']:.2f}"
            zc = f"{r['z_cx']:+.2f}, {r['z_cy']:+.2f}"
        else:
            f = zf = c = zc = "(held)"
        lines.append(f"| {r['video']} | {start} | {'yes' if r['refine'] else 'no'} | {r['true_line_delay_s'] * 1e6:.2f} "
                     f"| {r['line_delay_s'] * 1e6:.3f} ± {r['line_delay_std_s'] * 1e6:.3f} | {r['z_d']:+.2f} | {f} | {zf} "
                     f"| {c} | {zc} | {r['normalised_cost']:.3f} | {r['wall_s']:.0f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=ROOT / "build" / "exp_videos" / "refine_intrinsics")
    parser.add_argument("--render", action="store_true", help="render the videos that are missing")
    parser.add_argument("--tables-only", action="store_true")
    args = parser.parse_args()
    result_path = ROOT / "benchmarks" / "results" / "exp_refine_intrinsics.json"
    if args.tables_only:
        print(table(json.loads(result_path.read_text())["rows"]))
        return
    rows = []
    for size, seed, delay in VIDEOS:
        folder = args.videos / f"{size}_{seed}"
        if args.render:
            render(folder, size, seed, delay)
        if not (folder / "truth.json").exists():
            print(f"skipping {folder} (not rendered; --render)", file=sys.stderr)
            continue
        wrong = wrong_camera(folder)
        for camera in (folder / "camera.yaml", wrong):
            for refine in (False, True):
                out = folder / "runs" / f"{camera.stem}_{'refine' if refine else 'fixed'}"
                rows.append(run(folder, camera, refine, out))
                print(json.dumps({k: v for k, v in rows[-1].items() if k != "command"}), file=sys.stderr)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    result_path.parent.mkdir(parents=True, exist_ok=True)
    result_path.write_text(json.dumps({"machine": platform.platform(), "date": time.strftime("%Y-%m-%d %H:%M"),
                                       "commit": commit, "focal_factor": FOCAL_FACTOR,
                                       "centre_shift_px": CENTRE_SHIFT_PX, "rows": rows}, indent=1))
    print(table(rows))


if __name__ == "__main__":
    main()
