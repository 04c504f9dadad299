"""Shared by the experiments (experiments/exp_*.py): the paper reproductions (issue #6) and the
studies docs/experiments.md reports. They call rscalib's front doors with options (rscalib.__all__)
and the simulators (rscalib.sim), as a user would; never the engines' modules or rscalib._core.

Rendered videos with exact ground truth go through the same code paths as the CLI
(`rscalib simulate` -> `rscalib linedelay` / `rscalib localize`):

    render_video -> video.avi, truth.json, camera.yaml, target.yaml
    rscalib.load_camera(camera.yaml), rscalib.detect_video(video.avi, target.yaml)   (detect, below)
    rscalib.calibrate_video(detections, camera=..., options=rscalib.LineDelayOptions(...)) /
    rscalib.localize_video(detections, camera=..., line_delay_s=...)

Videos are cached under build/exp_videos/<config>/ (build/ is git-ignored); a video is re-rendered
only when its render settings (params.json) differ. Detections are cached by detect_video itself
($RSCALIB_CACHE_DIR if set, else build/exp_videos/_detections).

The machine record and the results file are benchmarks/_common.py's (one home for the lab's
bookkeeping: every file in benchmarks/results/ has the same fields, whichever folder wrote it);
it is imported here as the module `benchmarks._common`, so it never shadows this `_common`.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.append(str(REPO))
import rscalib  # noqa: E402
from benchmarks._common import RESULTS, machine_info  # noqa: E402
from benchmarks._common import write_results as write_results_file  # noqa: E402

VIDEO_ROOT = REPO / "build" / "exp_videos"
FIGURES = REPO / "docs" / "figures"


# -- bookkeeping ------------------------------------------------------------------------------------

def parser(description: str, default_seeds: int, quick_seeds: int) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--seeds", type=int, default=None, help=f"videos (seeds) per configuration ({default_seeds})")
    p.add_argument("--quick", action="store_true", help=f"fewer seeds ({quick_seeds}) for a fast check")
    p.set_defaults(_default_seeds=default_seeds, _quick_seeds=quick_seeds)
    return p


def seeds_from(args) -> int:
    if args.seeds is not None:
        return int(args.seeds)
    return args._quick_seeds if args.quick else args._default_seeds


def write_results(name: str, settings: dict, rows, table: str, timings: Optional[dict] = None, *,
                  path: Optional[Path] = None, **extra) -> Path:
    """benchmarks/results/<name>.json (or `path`): the machine record, the settings, the timings,
    any extra fields, the rows and the markdown table (benchmarks/_common.write_results)."""
    if timings is not None:
        extra = {"timings_s": timings, **extra}
    return write_results_file(path or RESULTS / f"{name}.json", name, machine_info(), settings, rows, table,
                              **extra)


def markdown_table(header: list[str], rows: list[list], align: Optional[str] = None) -> str:
    align = align or ("l" + "r" * (len(header) - 1))
    sep = ["---" if a == "l" else "---:" for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def save_figure(fig, name: str, max_kb: int = 150) -> Path:
    """PNG under docs/figures; lowers the dpi until the file is below max_kb."""
    FIGURES.mkdir(parents=True, exist_ok=True)
    path = FIGURES / f"{name}.png"
    for dpi in (110, 95, 80, 65):
        fig.savefig(path, dpi=dpi)
        if path.stat().st_size < max_kb * 1024:
            break
    print(f"figure {path.relative_to(REPO)} ({path.stat().st_size // 1024} kB)")
    return path


# -- cameras ----------------------------------------------------------------------------------------

def bluefox_camera() -> rscalib.CameraModel:
    """A wide-VGA mvBlueFOX-MLC-like camera: 752x480, 6.0 um pixels (Aptina MT9V034), 3.5 mm
    S-mount lens -> f = 3.5 / 0.006 = 583.3 px (HFOV 65 deg), mild barrel distortion as the
    project's default camera."""
    f = 3.5e-3 / 6.0e-6
    return rscalib.CameraModel("pinhole-radtan", [f, f, 375.5, 239.5, -0.1, 0.05, 0.0, 0.0, 0.0], 752, 480)


# -- trajectories -----------------------------------------------------------------------------------

def calm_then_wild_trajectory(camera, target_name: str, duration_s: float, seed: int):
    """The default hand-held trajectory (sim.trajectories.target_trajectory) with calm_then_wild's
    amplitude profile: 0.15 of the default amplitude in the first half, 1.0 in the second."""
    from rscalib import Target
    from rscalib.sim.trajectories import calm_then_wild, target_trajectory

    return target_trajectory(camera, Target.named(target_name), duration_s, seed, motion=1.0,
                             amplitude_profile=calm_then_wild(duration_s))


# -- videos -----------------------------------------------------------------------------------------

def get_video(config: str, *, line_delay_s: float, fps: float, duration_s: float, seed: int,
              camera: Optional[rscalib.CameraModel] = None, size=(640, 480), target: str = "checkerboard",
              noise: float = 2.0, supersample: int = 2, motion: float = 1.0, trajectory_kind: str = "handheld",
              workers: Optional[int] = None) -> tuple[Path, float]:
    """Render (or reuse) build/exp_videos/<config>/; returns (folder, render seconds, 0 if cached)."""
    from rscalib.sim.target_observations import default_camera
    from rscalib.sim.target_video import render_video

    if camera is None:
        camera = default_camera(size)
    params = {"line_delay_s": line_delay_s, "fps": fps, "duration_s": duration_s, "seed": seed,
              "camera": {"model": camera.model, "params": [float(v) for v in camera.params],
                         "width": camera.width, "height": camera.height},
              "target": target, "noise": noise, "supersample": supersample, "motion": motion,
              "trajectory_kind": trajectory_kind}
    folder = VIDEO_ROOT / config
    marker = folder / "params.json"
    if marker.is_file() and (folder / "video.avi").is_file():
        if json.loads(marker.read_text()) == json.loads(json.dumps(params)):
            return folder, 0.0
    tmp = VIDEO_ROOT / f".{config}.tmp{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    trajectory = None
    if trajectory_kind == "calm_then_wild":
        trajectory = calm_then_wild_trajectory(camera, target, duration_s, seed)
    elif trajectory_kind != "handheld":
        raise ValueError(trajectory_kind)
    started = time.perf_counter()
    render_video(tmp, line_delay_s=line_delay_s, fps=fps, target=target, duration_s=duration_s, noise=noise,
                 seed=seed, camera=camera, motion=motion, supersample=supersample, trajectory=trajectory,
                 workers=workers, progress=False)
    seconds = time.perf_counter() - started
    (tmp / "params.json").write_text(json.dumps(params, indent=1))
    shutil.rmtree(folder, ignore_errors=True)
    tmp.rename(folder)
    print(f"  rendered {config} in {seconds:.1f} s", flush=True)
    return folder, seconds


def truth_trajectory(folder: Path):
    """The analytic trajectory a video was rendered with."""
    from rscalib.sim.target_video import load_truth, trajectory_from_truth

    params = json.loads((folder / "params.json").read_text())
    if params["trajectory_kind"] == "calm_then_wild":
        c = params["camera"]
        camera = rscalib.CameraModel(c["model"], c["params"], c["width"], c["height"])
        return calm_then_wild_trajectory(camera, params["target"], params["duration_s"], params["seed"])
    return trajectory_from_truth(load_truth(folder))


def detect(folder: Path, workers: Optional[int] = None):
    """What `rscalib linedelay` does before solving: the camera and target files written next to the
    video, and rscalib.detect_video with its cache. Returns (DetectionResult, CameraModel)."""
    camera = rscalib.load_camera(folder / "camera.yaml").camera
    cache_dir = None if os.environ.get("RSCALIB_CACHE_DIR") else VIDEO_ROOT / "_detections"
    detection = rscalib.detect_video(folder / "video.avi", rscalib.load_target(folder / "target.yaml"),
                                     rscalib.DetectOptions(workers=workers, cache_dir=cache_dir), progress=False)
    return detection, camera


def solve_alone(detections, camera, **options):
    """rscalib.calibrate_video on detections already made (a DetectionResult or rscalib.Observations),
    with LineDelayOptions(self_check=False, **options): the solve over the whole video without the
    self-check's halves, as the paper's experiments ran it. Returns the engine's estimate (run.result:
    the line delay even when the verdict does not claim it, with its trajectory, knots and history)."""
    options = rscalib.LineDelayOptions(self_check=False, **options)
    return rscalib.calibrate_video(detections, camera=camera, options=options).result


# -- errors against the truth -----------------------------------------------------------------------

def _centres(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    return -np.einsum("nji,nj->ni", R, p)


def _angles(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (rad) of Ra Rbᵀ."""
    c = (np.einsum("nij,nij->n", Ra, Rb) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def pose_errors(R_est, p_est, R_true, p_true) -> tuple[np.ndarray, np.ndarray]:
    """Camera-centre distance (m) and rotation angle (rad) per pose."""
    return (np.linalg.norm(_centres(R_est, p_est) - _centres(R_true, p_true), axis=1), _angles(R_est, R_true))


def trajectory_errors(spline, truth_traj, times_s: np.ndarray) -> dict:
    """Mean / RMS camera-centre error (mm) and orientation error (deg) of a spline vs the truth."""
    times_s = np.clip(times_s, spline.t_begin, spline.t_end)
    R_e, p_e = rscalib.poses_at(spline, times_s)
    R_t, p_t = truth_traj.pose_cw(times_s)
    dp, dr = pose_errors(np.asarray(R_e), np.asarray(p_e), R_t, p_t)
    return {"position_mean_mm": 1e3 * float(np.mean(dp)), "position_rms_mm": 1e3 * float(np.sqrt(np.mean(dp ** 2))),
            "orientation_mean_deg": float(np.degrees(np.mean(dr))),
            "orientation_rms_deg": float(np.degrees(np.sqrt(np.mean(dr ** 2))))}


def observed_times(result, per_frame: int = 9) -> np.ndarray:
    """Times covered by observations: per used frame, `per_frame` times across its readout."""
    obs = result.used_observations
    frac = np.linspace(0.0, 1.0, per_frame)
    return (obs.frame_times_s[:, None] + frac[None, :] * result.readout_time_s).ravel()


def summary_row(result, truth_d: float) -> dict:
    return {"d_true_s": truth_d, "d_est_s": result.line_delay_s, "std_s": result.line_delay_std_s,
            "rel_err": (result.line_delay_s - truth_d) / truth_d,
            "within_3sigma": bool(abs(result.line_delay_s - truth_d) <= 3 * result.line_delay_std_s),
            "normalised_cost": result.normalised_cost, "pixel_sigma": result.pixel_sigma,
            "rms_px": result.rms_px, "segments": result.num_segments, "frames_used": result.frames_used,
            "observations": result.observations, "solve_time_s": result.solve_time_s,
            "determined": result.determined, "warnings": list(result.warnings)}


class Timer:
    def __init__(self) -> None:
        self.t = {}

    def add(self, key: str, seconds: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + float(seconds)


def detection_audit(folder: Path, detection, threshold_px: float = 2.0) -> dict:
    """Detected points vs the exact RS projections in truth.json: median error and the gross
    misdetections (points farther than threshold_px, and the frames holding them)."""
    from rscalib.sim.target_video import load_truth, truth_uv

    uv_true = truth_uv(load_truth(folder), "uv_rs")
    obs = detection.observations
    frames = np.asarray(detection.frame_numbers)[obs.frame_index]
    err = np.linalg.norm(obs.uv - uv_true[frames, obs.point_id], axis=1)
    bad = ~(err <= threshold_px)
    return {"median_detection_error_px": float(np.nanmedian(err)), "gross_points": int(bad.sum()),
            "gross_frames": sorted(int(f) for f in np.unique(frames[bad]))}
