"""Outputs of every line-delay result: result.json (through rscalib.io.results), trajectory.csv and
its TUM twin (rscalib.io.trajectory_files), plots, a self-contained report.html with a verdict and
the provenance, camera files for other tools (rscalib.io.cameras.write_camera_set) and the
detections as mrcal's corners.vnl.

Two readout times: `readout_time_s` = d x rows (the rows read out, --rows, default the image
height) and `image_readout_time_s` = d x the image's lines along the readout (first to last image
row: Gyroflow's frame_readout_time). trajectory.csv samples each frame at its row 0 and at the
middle of the image's readout, t + image_readout_time_s / 2.

- `rscalib linedelay` (spline, linear): write_outputs -- everything above;
- `rscalib localize --model rs-spline`: write_localize_outputs -- result.json, trajectory.csv/.png, TUM;
- `rscalib localize --model gs-pnp`: write_pnp_outputs -- result.json, trajectory.csv, TUM;
- a video run of linedelay/pipeline.py: write_video_outputs picks the one of its model.

Each writer writes its files as one set (io.output_folder.output_set): staged, then renamed into
place with result.json last, replacing the previous run's files in that folder.
"""
from __future__ import annotations

import html
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional, Union

import numpy as np  # noqa: E402

from .._core import CameraModel, error_noise_map, unwrap_rotation_vectors  # noqa: E402
from ..errors import InputError  # noqa: E402
from ..io.camera_formats.mrcal import write_corners_vnl  # noqa: E402
from ..io.cameras import write_camera_set  # noqa: E402
from ..io.output_folder import output_set  # noqa: E402
from ..io.report_html import Figure, escape, figure_html, list_html, table_html, write_report  # noqa: E402
from ..io.results import write_result_json  # noqa: E402
from ..io.trajectory_files import CSV_COLUMNS, write_tum_trajectory  # noqa: E402
from ..io.trajectory_files import write_trajectory_csv as _write_csv  # noqa: E402
from ..readout import GYROFLOW_WORDS, TOP_TO_BOTTOM  # noqa: E402
from ..verdict import NOT_DETERMINED, Verdict  # noqa: E402
from .judge import judge_line_delay  # noqa: E402
from .linear import LinearInterpResult  # noqa: E402
from .pnp import PnpTrajectory  # noqa: E402
from .spline import LineDelayResult  # noqa: E402

if TYPE_CHECKING:
    from ..detection.result import DetectionResult
    from .pipeline import LineDelayRun, LocalizeRun

# the results write_outputs takes: the line delay estimated with either trajectory model
Estimate = Union[LineDelayResult, LinearInterpResult]
TRAJECTORY_HEADER = ",".join(CSV_COLUMNS)   # says world_to_camera: T_cw, x_c = R(phi) x_w + p


def _pyplot():
    """pyplot on the Agg backend (files only, no display), imported on first use: `--no-report`
    runs never pay its ~0.6 s import."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ------------------------------------------------------------------------------- trajectories

def _time_origin(result: Estimate) -> float:
    """t = 0 of the plots: the spline's first knot, the linear model's first frame."""
    if isinstance(result, LinearInterpResult):
        return float(result.frame_times_s[0])
    return result.trajectory.t_begin


def image_readout_time_s(result: Estimate) -> float:
    """d x the image's lines along the readout: first to last image row (readout_time_s is d x rows)."""
    return float(result.line_delay_s) * int(result.used_observations.image_size[1])


def trajectory_samples(result: Union[Estimate, PnpTrajectory]) -> tuple[np.ndarray, np.ndarray]:
    """(times, (n, 6) states T_cw [p; phi]) of trajectory.csv: for the continuous-time models, every
    used frame's row-0 time and the middle of its image's readout, t + image_readout_time_s / 2
    (inside the spline's domain); for per-frame PnP, its poses."""
    if isinstance(result, PnpTrajectory):
        return result.times_s, result.states
    frame_times = result.used_observations.frame_times_s
    times = np.sort(np.concatenate([frame_times, frame_times + 0.5 * image_readout_time_s(result)]))
    if isinstance(result, LinearInterpResult):
        return times, result.evaluate(times)
    times = times[(times >= result.trajectory.t_begin) & (times <= result.trajectory.t_end)]
    return times, result.trajectory.evaluate(times)


def write_states_csv(path: Path, times, states) -> Path:
    """The trajectory CSV: t_s, T_cw p (3), phi (3); rows without a pose (NaN) are left out."""
    return _write_csv(path, times, states)


def write_trajectory_csv(result: Union[Estimate, PnpTrajectory], path: Path) -> Path:
    """T_cw of any line-delay result at the times of trajectory_samples: t_s, p (3), φ (3)."""
    return write_states_csv(path, *trajectory_samples(result))


def write_trajectories(result: Union[Estimate, PnpTrajectory], out: Path) -> dict:
    """trajectory.csv (world-to-camera) and trajectory_tum.txt (camera-to-world) at the same times."""
    times, states = trajectory_samples(result)
    write_states_csv(out / "trajectory.csv", times, states)
    write_tum_trajectory(out / "trajectory_tum.txt", times, states)
    return {"trajectory_csv": "trajectory.csv", "trajectory_tum": "trajectory_tum.txt"}


def write_detections_vnl(detections: DetectionResult, path: Path) -> Optional[str]:
    """The detections as mrcal's corners.vnl; the reason instead when the target is not a grid mrcal
    knows (None when written)."""
    obs = detections.observations
    names = [str(label) for label in detections.frame_labels]
    try:
        write_corners_vnl(path, names, obs.frame_index, obs.point_id, obs.uv, obs.target_points)
    except InputError as error:
        return f"no corners.vnl: {error}"
    return None


# ------------------------------------------------------------------------------------- plots

def _save(fig, path: Path) -> Path:
    plt = _pyplot()
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")   # nothing cut off (titles, side panels)
    plt.close(fig)
    return path


def plot_residuals_time(result: Estimate, path: Path) -> Path:
    plt = _pyplot()
    if len(np.unique(result.observation_time_s)) < 2 and result.used_observations.num_frames < 2:
        rms = np.sqrt(np.mean(result.residual_px ** 2, axis=0))
        return _value_panel(path, "Residuals: one frame", [f"rms u {rms[0]:.3f} px, v {rms[1]:.3f} px over "
                                                           f"{len(result.residual_px)} corners"])
    fig, axes = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    t = result.observation_time_s - _time_origin(result)
    for ax, k, name in ((axes[0], 0, "u"), (axes[1], 1, "v")):
        ax.plot(t, result.residual_px[:, k], ".", ms=1.5, alpha=0.4)
        ax.axhline(0, color="k", lw=0.6)
        for s in (-3, 3):
            ax.axhline(s * result.pixel_sigma, color="r", lw=0.6, ls="--")
        ax.set_ylabel(f"{name} residual (px)")
    axes[0].set_title(f"Residuals over time (rms {result.rms_px:.3f} px; dashed: ±3σ, σ = {result.pixel_sigma:.3f} px)")
    axes[1].set_xlabel("time (s)")
    return _save(fig, path)


def plot_residuals_image(result: Estimate, path: Path) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 5.5))
    uv = result.used_observations.uv
    mag = np.linalg.norm(result.residual_px, axis=1)
    sc = ax.scatter(uv[:, 0], uv[:, 1], c=mag, s=2, cmap="viridis", vmax=np.nanpercentile(mag, 99))
    fig.colorbar(sc, ax=ax, label="|residual| (px)")
    w, h = result.used_observations.image_size
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_title("Residual magnitude over the image (also: target coverage)")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    return _save(fig, path)


def plot_covariance_ellipses(result: LineDelayResult, path: Path, count: int = 6) -> Path:
    """Paper Fig. 2: the error covariance of a moving point (red; the detection noise R mapped by the
    line delay's image-motion term A, A R A^T) against R alone (grey), at a few observations with fast
    image motion (the solver's image velocities), drawn at their image position and magnified. Each
    ellipse is numbered; its speed and det A are listed beside the image, so labels never overlap."""
    plt = _pyplot()
    from matplotlib import patches
    obs = result.used_observations
    velocity = result.image_velocity_px_s
    speed = np.linalg.norm(velocity, axis=1)
    fastest = np.argsort(np.nan_to_num(speed, nan=-1.0))[::-1][: max(1, len(speed) // 50)]
    # spread over the image (farthest point first among the fastest 2 %), so ellipses do not overlap
    picks = [fastest[0]]
    distance = np.linalg.norm(obs.uv[fastest] - obs.uv[fastest[0]], axis=1)
    while len(picks) < min(count, len(fastest)):
        far = int(np.argmax(distance))
        picks.append(fastest[far])
        distance = np.minimum(distance, np.linalg.norm(obs.uv[fastest] - obs.uv[fastest[far]], axis=1))
    fig, (ax, side) = plt.subplots(1, 2, figsize=(9.5, 5.2), gridspec_kw={"width_ratios": [3, 1.15]})
    scale = 40.0 / max(result.pixel_sigma, 1e-9)
    r = result.pixel_sigma ** 2 * np.eye(2)
    lines = []
    for number, i in enumerate(picks, start=1):
        a = error_noise_map(result.line_delay_s, velocity[i])
        for cov, color, width in ((r, "0.7", 4.0), (a @ r @ a.T, "r", 1.3)):   # grey wide: visible under red
            values, vectors = np.linalg.eigh(cov)
            angle = np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1]))
            ax.add_patch(patches.Ellipse(obs.uv[i], 2 * scale * np.sqrt(values[1]), 2 * scale * np.sqrt(values[0]),
                                 angle=angle, fill=False, color=color, lw=width))
        ax.annotate(str(number), obs.uv[i], fontsize=9, fontweight="bold", ha="center", va="center")
        lines.append(f"{number}: {speed[i]:.0f} px/s\n    det A = {np.linalg.det(a):.3f}")
    w, h = obs.image_size
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    fig.suptitle(f"Error covariance with motion (red) vs detection noise alone (grey); 1σ magnified ×{scale:.0f}",
                 fontsize=10)
    side.axis("off")
    side.text(0.0, 1.0, "fastest image motion\n\n" + "\n".join(lines), va="top", ha="left", fontsize=9,
              family="monospace", transform=side.transAxes)
    return _save(fig, path)


def plot_knots_and_speed(result: LineDelayResult, path: Path) -> Path:
    """Knot density against the image speed of the observations (the solver's image velocities).
    The spline's end knots repeat (zero-length spans): only the segments between distinct knots count."""
    plt = _pyplot()
    obs = result.used_observations
    speed = np.linalg.norm(result.image_velocity_px_s, axis=1)
    t0 = result.trajectory.t_begin
    knots = np.unique(np.asarray(result.knots, dtype=float)) - t0
    fig, ax = plt.subplots(figsize=(9, 3.8))
    widths = np.diff(knots)
    keep = widths > 1e-9
    ax.bar(knots[:-1][keep], 1.0 / widths[keep], width=widths[keep], align="edge", alpha=0.35, color="C0",
           label="knot density (1/s)", zorder=1)
    ax.set_ylabel("knots per second", color="C0")
    ax.set_xlabel("time (s)")
    ax2 = ax.twinx()
    frame_t = obs.frame_times_s[obs.frame_index] - t0
    frames = np.unique(frame_t)
    median_speed = np.array([np.nanmedian(speed[frame_t == f]) for f in frames])
    ax2.plot(frames, median_speed, color="C1", lw=1.2, label="image speed", zorder=3)
    ax2.set_ylabel("median image speed (px/s)", color="C1")
    ax2.set_ylim(bottom=0)
    ax.set_ylim(bottom=0)
    ax.set_title("Knot density after adaptation (bars), and image motion (line)")
    return _save(fig, path)


def _value_panel(path: Path, title: str, lines: list) -> Path:
    """A plot of a single value (one round, one frame): the value written out instead of empty axes."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 1.6))
    ax.axis("off")
    ax.text(0.0, 0.5, "\n".join(lines), va="center", ha="left", fontsize=11, transform=ax.transAxes)
    ax.set_title(title, loc="left")
    return _save(fig, path)


def plot_rounds(result: LineDelayResult, path: Path) -> Path:
    plt = _pyplot()
    if len(result.history) < 2:
        h = result.history[-1]
        std = "" if not math.isfinite(h.line_delay_std_s) else f" ± {h.line_delay_std_s * 1e6:.4f}"
        return _value_panel(path, "Line delay per round: one round (no knot was added)",
                            [f"round {h.round}: {h.line_delay_s * 1e6:.4f}{std} µs/row, {h.segments} knot segments, "
                             f"J/2N {h.normalised_cost:.3f}"])
    fig, ax = plt.subplots(figsize=(6, 3.6))
    rounds = [h.round for h in result.history]
    d = [h.line_delay_s * 1e6 for h in result.history]
    ax.plot(rounds, d, "o-")
    last = result.history[-1]
    if math.isfinite(last.line_delay_std_s):
        ax.errorbar([last.round], [last.line_delay_s * 1e6], yerr=[3 * last.line_delay_std_s * 1e6], color="r",
                    capsize=4, label="final ±3σ")
        ax.legend()
    for h in result.history:
        ax.annotate(f"{h.segments} seg.", (h.round, h.line_delay_s * 1e6), fontsize=7, xytext=(3, -10),
                    textcoords="offset points")
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("knot-adaptation round")
    ax.set_ylabel("line delay (µs/row)")
    ax.set_title("Line delay per round")
    return _save(fig, path)


def plot_trajectory(result: Estimate, path: Path) -> Path:
    """The estimated T_cw(t) (lines) against the per-frame GS PnP poses it started from (dots)."""
    plt = _pyplot()
    t0 = _time_origin(result)
    if isinstance(result, LinearInterpResult):
        t = np.linspace(result.frame_times_s[0], result.frame_times_s[-1], 2000)
        x = result.evaluate(t)
        poses, model = result.gs_poses, "linear / SLERP between frames"
    else:
        t = np.linspace(result.trajectory.t_begin, result.trajectory.t_end, 2000)
        x = result.trajectory.evaluate(t)
        poses, model = result.frame_poses, "spline"
    frame_t = result.used_observations.frame_times_s
    rot = unwrap_rotation_vectors(poses.rotation_vector)
    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for k, name in enumerate("xyz"):
        axes[0].plot(t - t0, x[:, k], lw=1, label=f"p_{name}")
        axes[0].plot(frame_t - t0, poses.translation[:, k], ".", ms=2, color=f"C{k}")
        axes[1].plot(t - t0, x[:, 3 + k], lw=1, label=f"φ_{name}")
        axes[1].plot(frame_t - t0, rot[:, k], ".", ms=2, color=f"C{k}")
    axes[0].set_ylabel("translation p (m)")
    axes[1].set_ylabel("rotation vector φ (rad)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend(ncol=3, fontsize=8)
    axes[1].legend(ncol=3, fontsize=8)
    axes[0].set_title(f"Trajectory T_cw(t): {model} (lines) and per-frame GS PnP (dots)")
    return _save(fig, path)


@dataclass(frozen=True)
class PlotJob:
    """A plot of the report: its title, how to draw it, its file, the sentence on what to look for,
    and whether it is for the expert (the report's appendix)."""

    title: str
    draw: Callable
    name: str
    look_for: str
    expert: bool = False


def _plot_jobs(result: Estimate, verdict: Verdict) -> list:
    """The report's plots of a line-delay estimate: residuals and trajectory for both models; the
    spline's error ellipses, knot density and rounds besides, in the appendix (the linear model has no
    knots, no rounds and, by default, unstandardised errors). A line delay that is not determined is not
    drawn (the ellipses and the rounds show it)."""
    jobs = [PlotJob("Residuals over time", plot_residuals_time, "residuals_time.png",
                    "Look for points spread evenly between the dashed ±3σ lines all along the video; a burst "
                    "or a drift marks a part of the video the model does not fit."),
            PlotJob("Where the board was seen, and the residuals there", plot_residuals_image, "residuals_image.png",
                    "Look for corners over the whole height of the image (the line delay is read along the "
                    "rows) and no region with larger residuals (a wrong camera file shows at the edges).")]
    jobs.append(PlotJob("Camera trajectory", plot_trajectory, "trajectory.png",
                        "Look for smooth curves through the dots (each frame's own pose); curves that leave the "
                        "dots mean the motion was too fast or too jerky to follow."))
    if isinstance(result, LineDelayResult) and verdict.claims:
        jobs += [PlotJob("How image motion stretches the detection noise (paper Fig. 2)", plot_covariance_ellipses,
                         "covariance_ellipses.png",
                         "Look for red ellipses longer than the grey circles: the rolling shutter at work (the "
                         "faster the image moves, the more a corner's row time blurs its position).", expert=True),
                 PlotJob("Knot density and image motion", plot_knots_and_speed, "knots_speed.png",
                         "Look for bars (knots of the trajectory per second) that rise where the line (image "
                         "speed) rises: the trajectory takes more knots where the motion is fast.", expert=True),
                 PlotJob("Line delay per knot-adaptation round", plot_rounds, "rounds.png",
                         "Look for a line delay that settles over the rounds, the last ones well inside the "
                         "final ±3σ bar.", expert=True)]
    return jobs


def _plots(result: Estimate, verdict: Verdict, out: Path, failed: list) -> dict:
    """The plots of _plot_jobs drawn into out, {file name: (Figure, expert)}; the ones that fail are
    left out and said in `failed`."""
    plt = _pyplot()
    plots = {}
    for job in _plot_jobs(result, verdict):
        # a plot of degenerate data (NaN, infinite sigma) must not cost the user the result
        try:
            plots[job.name] = (Figure(job.draw(result, out / job.name), job.title, job.look_for), job.expert)
        except Exception as error:  # noqa: BLE001
            plt.close("all")
            failed.append(f"plot {job.name} skipped: {type(error).__name__}: {error}")
    return plots


# ---------------------------------------------------------------------------------- writers

def _start(result, out_dir, frames_total: Optional[int], extra: Optional[dict], **fields) -> tuple[Path, dict]:
    """out_dir (created) and the result's summary_dict with `fields`, the frames read (if given)
    and the `extra` fields."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = result.summary_dict() | fields
    if frames_total is not None:
        summary["frames_total"] = int(frames_total)
    summary.update(extra or {})
    return out, summary


# the fields of an estimate that claim a line delay: null when the verdict claims none
_CLAIMED = ("line_delay_s", "line_delay_std_s", "readout_time_s", "image_readout_time_s")


def estimate_summary(result: Estimate, verdict: Verdict, frames_total: Optional[int] = None,
                     extra: Optional[dict] = None) -> dict:
    """The result.json fields of a line-delay estimate with its verdict (without the files): the
    estimate's summary, the frames read, `extra`, image_readout_time_s and the verdict block. When
    the verdict claims no number (not determined), the line delay, its sigma and the readout times
    are null and the unclaimed estimate is kept apart under `not_claimed` (for diagnosis only)."""
    summary = result.summary_dict()
    if frames_total is not None:
        summary["frames_total"] = int(frames_total)
    summary.update(extra or {})
    summary["image_readout_time_s"] = image_readout_time_s(result)
    summary["verdict"] = verdict.to_dict()
    if not verdict.claims:
        summary["not_claimed"] = {k: summary[k] for k in _CLAIMED}
        summary.update({k: None for k in _CLAIMED})
    return summary


def _run_extra(run: LineDelayRun) -> dict:
    """The result.json fields of the video and its detection, then the run's settings and guidance."""
    d = run.detection
    return {"video": run.inputs.get("video"), "detection_dropped": d.dropped, "frames_detected": d.frames_detected,
            "timestamps_from": d.timestamps, "detection_time_s": d.detect_time_s} | run.settings \
        | ({"guidance": run.guidance} if run.guidance else {}) \
        | ({"diagnosis": run.diagnosis.to_dict()} if run.diagnosis is not None else {})


def run_summary(run: LineDelayRun) -> dict:
    """LineDelayRun.summary(): what result.json holds, without the files and the provenance."""
    return estimate_summary(run.result, run.verdict, run.detection.frames_total, _run_extra(run))


def write_outputs(result: Estimate, camera: CameraModel, out_dir, *, verdict: Optional[Verdict] = None,
                  frames_total: Optional[int] = None, extra: Optional[dict] = None, fps: float = 0.0,
                  title: Optional[str] = None, command: str = "linedelay", inputs: Optional[dict] = None,
                  detections: Optional[DetectionResult] = None, readout: str = TOP_TO_BOTTOM,
                  gyroflow: Optional[dict] = None, report: bool = True,
                  on_result: Optional[Callable[[dict], None]] = None) -> dict:
    """Everything of a line-delay estimate (spline or linear model) into out_dir: result.json,
    trajectory.csv and trajectory_tum.txt, the camera files of every format (only when the verdict
    claims a line delay: a file for another tool never carries an undetermined one), the detections
    as corners.vnl (when given), the plots and report.html. Returns the result.json dict (without
    its provenance). verdict: the estimate's (default: judge.judge_line_delay); frames_total: frames
    read (default: the result's); extra: more result.json fields; fps: for the Gyroflow profile;
    readout: the readout direction (rscalib.readout); gyroflow: camera_brand, camera_model,
    lens_model for its profile; command, inputs: the provenance. report: False leaves out the plots
    and report.html (batch use). on_result(summary) is called once result.json is written (in the
    staging folder) and before the plots are drawn (the CLI prints the result there); the folder's
    files appear together when the plots are done."""
    verdict = verdict or judge_line_delay(result)
    with output_set(out_dir) as staged:
        out = Path(staged)
        summary = estimate_summary(result, verdict, frames_total, extra)
        warnings = list(summary["warnings"])

        files = write_trajectories(result, out)
        notes = []
        if verdict.claims:
            exports = write_camera_set(camera, out, result.line_delay_s, fps=fps, rms_px=result.rms_px,
                                       readout_direction=GYROFLOW_WORDS.get(readout), gyroflow=gyroflow)
            files |= exports.files
            notes += exports.notes
            if exports.details:
                summary["exports"] = exports.details
        else:
            notes.append("no camera files with the line delay (OpenCV, Kalibr, Gyroflow, ROS, mrcal, COLMAP): the "
                         "line delay is not determined by this video, and a file for another tool carries only "
                         "a value the verdict stands behind")
        if detections is not None:
            skipped = write_detections_vnl(detections, out / "corners.vnl")
            if skipped is None:
                files["mrcal_corners"] = "corners.vnl"
            else:
                notes.append(skipped)
        if report:  # listed now, drawn after the result is out; result.json is rewritten if one fails
            files["plots"] = [job.name for job in _plot_jobs(result, verdict)]
            files["report"] = "report.html"
        summary["warnings"] = warnings
        summary["export_notes"] = notes
        summary["files"] = files
        result_path = write_result_json(out, summary, command=command, inputs=inputs)
        if on_result is not None:
            on_result(summary)
        if report:
            plots = _plots(result, verdict, out, warnings)
            if len(plots) < len(files["plots"]):
                files["plots"] = list(plots)
                result_path = write_result_json(out, summary, command=command, inputs=inputs)
            if title is None:
                title = "rscalib linedelay" + (" (the linear baseline)" if isinstance(result, LinearInterpResult) else "")
            _write_html(out / "report.html", title, summary, verdict, plots, _provenance_of(result_path))
    return summary


def write_line_delay_run(run: LineDelayRun, out_dir, *, report: bool = True, gyroflow: Optional[dict] = None,
                         on_result: Optional[Callable[[dict], None]] = None, command: str = "linedelay") -> dict:
    """LineDelayRun.write(): write_outputs with everything the run knows."""
    return write_outputs(run.result, run.camera, out_dir, verdict=run.verdict, frames_total=run.detection.frames_total,
                         extra=_run_extra(run), fps=run.fps, detections=run.detection, readout=run.readout,
                         gyroflow=gyroflow, report=report, on_result=on_result, command=command, inputs=run.inputs)


def write_localize_run(run: LocalizeRun, out_dir, *, command: str = "localize") -> dict:
    """LocalizeRun.write(): result.json (with the verdict block and, for rs-spline, the comparison
    against per-frame GS PnP, linedelay.pnp.compare_with_pnp), trajectory.csv and trajectory_tum.txt,
    and trajectory.png for rs-spline. Returns the result.json dict."""
    d = run.detection
    extra = {"video": run.inputs.get("video"), "detection_dropped": d.dropped, "frames_detected": d.frames_detected,
             "timestamps_from": d.timestamps, "detection_time_s": d.detect_time_s}
    with output_set(out_dir) as staged:
        if run.model == "gs-pnp":
            out, summary = _start(run.result, staged, d.frames_total, extra)
            summary["files"] = write_trajectories(run.result, out)
        else:
            out, summary = _start(run.result, staged, d.frames_total, extra, trajectory_model="rs-spline",
                                  gs_pnp_comparison=run.comparison)
            summary.pop("line_delay_std_s", None)  # d was given, not estimated
            summary["image_readout_time_s"] = image_readout_time_s(run.result)
            summary["files"] = write_trajectories(run.result, out) | {
                "plots": [plot_trajectory(run.result, out / "trajectory.png").name]}
        summary["verdict"] = run.verdict.to_dict()
        write_result_json(out, summary, command=command, inputs=run.inputs)
    return summary


def _provenance_of(result_path: Path) -> dict:
    return json.loads(result_path.read_text()).get("provenance", {})


def _table_rows(summary: dict) -> list[tuple[str, object]]:
    """The result, in words a newcomer reads (the expert's numbers: _expert_rows)."""
    std = summary["line_delay_std_s"]
    if (summary.get("verdict") or {}).get("status") == NOT_DETERMINED:
        value, spread = "not determined by this video", "—"
    else:
        value = f"{summary['line_delay_s'] * 1e6:.4f} µs per row"
        spread = "—" if std is None else f"± {std * 1e6:.4f} µs per row (one standard deviation)"
    return [("line delay (time between the start of two rows)", value),
            ("its uncertainty", spread),
            ("readout time of the sensor", "—" if summary.get("readout_time_s") is None else
             f"{summary['readout_time_s'] * 1e3:.3f} ms over {summary['rows']} rows"),
            ("readout time of the image", "—" if summary.get("image_readout_time_s") is None else
             f"{summary['image_readout_time_s'] * 1e3:.3f} ms, first to last image row (Gyroflow's "
             "frame_readout_time)"),
            ("frames used", f"{summary['frames_used']} of {summary['frames_total']}"),
            ("board corners used", summary["observations"])]


def _expert_rows(summary: dict) -> list[tuple[str, object]]:
    """The solver's numbers, each with what it means."""
    if summary.get("trajectory_model") == "linear":
        size = ("frame poses / interpolated intervals / chains",
                f"{summary['knots']} / {summary['segments']} / {summary['chains']}")
    else:
        size = ("knot segments of the trajectory (more where the motion is fast)", summary["segments"])
    solver_std = summary.get("solver_line_delay_std_s")
    return [("normalised cost J/2N (1 when the noise model fits; below 1 it overestimates the noise, so the "
             "uncertainty is on the safe side)", f"{summary['normalised_cost']:.3f}"),
            ("rms of the residuals", f"{summary['rms_px']:.4f} px"),
            ("detection noise σ", f"{summary['pixel_sigma']:.4f} px ({summary['pixel_sigma_source']})"),
            ("the solver's σ of d, before the halves' widening",
             "—" if solver_std is None else f"{solver_std * 1e6:.4f} µs per row"),
            size,
            ("solver converged", "yes" if summary["converged"] else "no"),
            ("solve time", f"{summary['solve_time_s']:.2f} s")]


_ROTATION_WORDS = {"x (pitch)": "pitch (about x)", "y (yaw)": "yaw (about y)", "z (roll)": "roll (about z)"}
_DROP_WORDS = {"no_target": "no board found", "blurred": "blurred", "left_image": "board left the image",
               "unreadable": "unreadable", "outliers": "bad corners", "bad_timestamp": "bad time stamp"}


def guidance_rows(guidance: dict) -> list[tuple[str, str]]:
    """The guidance block of result.json as (label with its unit, value) rows for the report."""
    rows = []
    if "row_span" in guidance:
        rows.append(("image rows the board covered (2nd to 98th percentile)", f"{guidance['row_span'] * 100:.0f} %"))
    deciles = guidance.get("row_coverage_deciles")
    if deciles:
        marks = "".join("■" if x else "□" for x in deciles)
        rows.append(("tenths of the image height with the board, top to bottom",
                     f"{marks} ({sum(deciles)} of {len(deciles)})"))
    speed = guidance.get("image_speed_px_s")
    if speed:
        rows.append(("speed of the board in the image", f"median {speed['median']:.0f} px/s, 90 % below "
                     f"{speed['p90']:.0f} px/s"))
    if "image_speed_across_rows_px_s" in guidance:
        rows.append(("horizontal image speed (across the rows: shows the line delay best)",
                     f"median {guidance['image_speed_across_rows_px_s']:.0f} px/s"))
    if "image_speed_along_columns_px_s" in guidance:
        rows.append(("vertical image speed", f"median {guidance['image_speed_along_columns_px_s']:.0f} px/s"))
    rates = guidance.get("angular_rate_rms_deg_s")
    if rates:
        rows.append(("camera rotation rate (rms)", ", ".join(f"{_ROTATION_WORDS.get(k, k)} {v:.0f} °/s"
                                                             for k, v in rates.items())))
    blur = guidance.get("blur_px")
    if blur:
        rows.append(("blur (width of the board's edges)", f"median {blur['median']:.1f} px, 90 % below "
                     f"{blur['p90']:.1f} px; {blur['blurred_fraction'] * 100:.0f} % of frames blurred"))
    if "frames_dropped" in guidance:
        dropped = guidance["frames_dropped"]
        rows.append(("frames without a usable board", ", ".join(f"{_DROP_WORDS.get(k, k)}: {n}"
                                                                for k, n in dropped.items()) or "none"))
    if guidance.get("video_bits_per_pixel") is not None:
        rows.append(("video bitrate", f"{guidance['video_bits_per_pixel']:.2f} bit per pixel (phones record "
                     "about 0.2-0.4)"))
    if guidance.get("error"):
        rows.append(("advice could not be worked out", guidance["error"]))
    return rows


def _half(h: dict) -> str:
    span = f"{h.get('t_begin_s') or 0:.2f}–{h.get('t_end_s') or 0:.2f} s"
    if "error" in h:
        return f"{span}: {h['error']}"
    std = h.get("line_delay_std_s")
    return (f"{span}: {h['line_delay_s'] * 1e6:.3f} ± {'?' if std is None else f'{std * 1e6:.3f}'} µs/row"
            + ("" if h.get("determined") else " (not determined)"))


def intrinsics_html(summary: dict) -> str:
    """--refine-intrinsics: the refined intrinsics, their sigma, the prior and the correlation with d."""
    ki = summary.get("intrinsics")
    if not ki:
        return ""
    corr = ki.get("correlation_with_line_delay") or {}

    def num(x, fmt=".6g"):
        return "—" if x is None else format(x, fmt)
    rows = "".join(f"<tr><td>{html.escape(n)}</td><td>{num(ki['initial'][n])}</td><td>{num(ki['estimate'][n])}</td>"
                   f"<td>{num(ki['std'][n], '.3g')}</td><td>{num(ki['prior']['std'][n], '.3g')}</td>"
                   f"<td>{num(corr.get(n), '+.3f')}</td></tr>" for n in ki["names"])
    return ("<h2>Intrinsics refined with the line delay</h2><table><tr><th>parameter</th><th>given</th>"
            "<th>refined</th><th>σ</th><th>prior σ</th><th>correlation with d</th></tr>" + rows + "</table>"
            f"<p>Prior: {html.escape(ki['prior']['source'])}. The full covariance of [d, intrinsics] is in "
            "result.json (intrinsics.covariance); the camera files carry the refined intrinsics.</p>")


def _self_check_html(check: Optional[dict]) -> str:
    if not check:
        return ""
    state = {True: "agree", False: "disagree", None: "could not be compared"}[check.get("agree")]
    z = check.get("z")
    said = ""
    if z is not None:
        said = (f"They differ by {z:.2f} of their combined σ" + (" (3 or less is agreement)" if z <= 3 else
                " (more than 3: one of them, or both, is wrong)"))
        if check.get("widen", 1.0) > 1.0:
            said += f"; the uncertainty above is widened ×{check['widen']:.2f} accordingly (the Birge ratio)"
        said += "."
    return (f"<h2>Self-check: the two halves of the video {state}</h2><p>Each half of the video is solved on its "
            f"own.</p>{list_html(_half(h) for h in check.get('halves', []))}<p>{escape(said)}</p>")


def _sentence(text: str) -> str:
    return text[:1].upper() + text[1:] + "." if text else ""


def camera_check_html(summary: dict) -> str:
    """The camera check (docs/formulation.md §17): the camera file's intrinsics next to those the
    board's video prefers when they are freed for a few solver steps, and how far d moved."""
    check = ((summary.get("diagnosis") or {}).get("evidence") or {}).get("camera_check") or {}
    names, given, refit = check.get("param_names"), check.get("params_file"), check.get("params_refined")
    if not (names and given and refit):
        return ""
    rows = "".join(f"<tr><td>{html.escape(n)}</td><td>{a:.6g}</td><td>{b:.6g}</td></tr>"
                   for n, a, b in zip(names, given, refit))
    parts = []
    if check.get("focal_change_fraction") is not None:
        parts.append(f"focal length {check['focal_change_fraction'] * 100:+.2f} %")
    if check.get("centre_change_px") is not None:
        parts.append(f"principal point moved {check['centre_change_px']:.1f} px")
    if check.get("distortion_change_px") is not None:
        parts.append(f"the distortion alone moves the image by up to {check['distortion_change_px']:.1f} px")
    shift = check.get("shift_sigma")
    moved = "" if shift is None else (f" Freeing them moved the line delay by {shift:+.2f} of its σ: 2 or more means "
                                      "the camera file matters for this line delay.")
    return ("<h2>Camera check: does the video agree with the camera file?</h2><p>The camera's intrinsics are freed for a "
            "few solver steps from the solution (with the camera file as a prior).</p><table><tr><th>parameter</th>"
            "<th>camera file</th><th>the video prefers</th></tr>" + rows + "</table>"
            f"<p>{escape(_sentence('; '.join(parts)))}{escape(moved)} A focal length 1.5 % "
            "off, a principal point 8 px off or 10 px of distortion is said in the notes on the verdict even when the "
            "line delay does not depend on it: the camera file would then be wrong for other uses.</p>")


def _write_html(path: Path, title: str, summary: dict, v: Verdict, plots: dict,
                provenance: Optional[dict] = None) -> None:
    warnings = summary["warnings"]
    guidance = summary.get("guidance") or {}
    guidance_html = ("<h2>How the video could be better</h2>" + (list_html(guidance.get("advice", [])) or
                     "<p>Nothing to change: coverage, motion, blur and drops are fine.</p>")
                     + table_html(guidance_rows(guidance))) if guidance else ""
    notes = summary.get("export_notes", [])
    main = "".join(figure_html(f) for f, expert in plots.values() if not expert)
    expert = "".join(figure_html(f) for f, expert in plots.values() if expert)
    caveats = list_html(v.caveats)
    sections = [f"<h2>Result</h2>{table_html(_table_rows(summary))}",
                f"<p>Notes on the verdict:</p>{caveats}" if caveats else "",
                _self_check_html(summary.get("self_check")), camera_check_html(summary), intrinsics_html(summary),
                guidance_html, f"<h2>Warnings</h2>{list_html(warnings)}" if warnings else "",
                f"<h2>Plots</h2>{main}" if main else "",
                f"<p>About the exports:</p>{list_html(notes)}" if notes else "",
                "<p>Conventions: row 0 of a frame is exposed at its timestamp, row v at t + v·d; trajectory.csv holds "
                "the world(target)-to-camera pose, trajectory_tum.txt the camera-to-world pose; formats: "
                "docs/formats.md.</p>"]
    appendix = (f"<h3>The solver's numbers</h3>{table_html(_expert_rows(summary))}" + expert)
    write_report(path, title, v, sections, files=summary["files"], provenance=provenance, appendix=appendix,
                 advice_line="How to film a better calibration video: run `rscalib guide capture` (the guide comes "
                             "with rscalib).")
