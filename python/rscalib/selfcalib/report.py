"""Outputs of `rscalib selfcalib`: result.json (through rscalib.io.results), camera.yaml (the OpenCV
pinhole-radtan camera closest to the civera-radial estimate; only when the verdict claims it),
history.png (the estimates with their 99 % bounds and the number of Gaussians per frame) and
report.html (the verdict first, on the shared page of io/report_html)."""
from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..io.camera_formats.civera import civera_to_opencv
from ..io.cameras import write_opencv_yaml
from ..io.output_folder import output_set
from ..io.report_html import Figure, escape, figure_html, list_html, table_html, write_report
from ..io.results import write_result_json
from .result import PARAM_NAMES, SelfCalibResult

if TYPE_CHECKING:
    from .pipeline import SelfCalibRun

CAMERA_FILE = "camera.yaml"
HISTORY_PLOT = "history.png"
REPORT_FILE = "report.html"
UNITS = {"f": "px", "cx": "px", "cy": "px", "k1": "mm⁻²", "k2": "mm⁻⁴"}
LABELS = {"f": "focal length f", "cx": "principal point cx", "cy": "principal point cy",
          "k1": "radial distortion k1", "k2": "radial distortion k2"}


def run_summary(run: SelfCalibRun) -> dict:
    """result.json of a run (without files and provenance): the result's summary, the settings and
    the verdict block. Not determined: f, cx, cy, k1, k2 are null (their bounds stay: what the data
    allow) and the unclaimed estimate is kept apart under `not_claimed` (for diagnosis only)."""
    summary = {**run.result.summary_dict(), "baseline": run.options.baseline,
               "subpixel": run.options.front_end.subpixel, "timestamps_from": run.timestamps_from,
               "pixel_size_given_mm": run.options.pixel_size_mm}
    summary["verdict"] = run.verdict.to_dict()
    if not run.verdict.claims:
        summary["not_claimed"] = {name: summary[name] for name in PARAM_NAMES}
        summary.update({name: None for name in PARAM_NAMES})
    return summary


def write_selfcalib_run(run: SelfCalibRun, out_dir) -> dict:
    """Write out_dir/result.json, out_dir/history.png and, only when the verdict claims the
    calibration, out_dir/camera.yaml (the OpenCV pinhole-radtan camera closest to the civera-radial
    estimate: io.camera_formats.civera.civera_to_opencv), as one set; returns the result.json dict."""
    summary = run_summary(run)
    with output_set(Path(out_dir)) as staged:   # the files replace the previous run's as a set, result.json last
        files = {"plot": HISTORY_PLOT}
        if run.verdict.claims:
            opencv, max_error = civera_to_opencv(run.result.camera())
            write_opencv_yaml(opencv, staged / CAMERA_FILE)
            files["opencv_yaml"] = CAMERA_FILE
            summary["opencv_camera"] = {"file": CAMERA_FILE, "model": "pinhole-radtan (k1, k2, k3 fitted; p1 = p2 = 0)",
                                        "max_difference_px": max_error}
        else:
            summary["opencv_camera"] = None
            summary["export_notes"] = ["no camera.yaml: the calibration is not determined by this sequence, and a "
                                       "file for another tool carries only a value the verdict stands behind"]
        plot_history(run.result, staged / HISTORY_PLOT)
        files["plots"] = [HISTORY_PLOT]
        files["report"] = REPORT_FILE
        del files["plot"]
        summary["files"] = files
        result_path = write_result_json(staged, summary, command=run.command, inputs=run.inputs)
        provenance = json.loads(result_path.read_text()).get("provenance", {})
        write_report_html(staged / REPORT_FILE, run, summary, provenance)
    return summary


def _number(value: float, name: str) -> str:
    return f"{value:.2f} {UNITS[name]}" if name in ("f", "cx", "cy") else f"{value:.4g} {UNITS[name]}"


def result_rows(run: SelfCalibRun) -> list:
    """The report's result table: each parameter claimed (or not) with its 99 % bounds, the line delay."""
    result, claims = run.result, run.verdict.claims
    rows = []
    for i, name in enumerate(PARAM_NAMES):
        lo, hi = result.bounds_99[i]
        value = _number(result.mean[i], name) if claims else "not determined"
        rows.append((LABELS[name], value, f"99 % bounds [{_number(lo, name)}, {_number(hi, name)}]"))
    estimate = result.line_delay_estimate()
    if result.line_delay_given is not None:
        mean, sigma = result.line_delay_given
        rows.append(("line delay (given)", f"{mean * 1e6:.2f} µs/row" + (f" ± {sigma * 1e6:.2f}" if sigma else ""),
                     "held" if not sigma else "the adjustment's prior"))
    if estimate is not None and claims:
        d, (d_lo, d_hi) = estimate
        rows.append(("line delay (estimated with the camera)", f"{d * 1e6:.2f} µs/row",
                     f"99 % bounds [{d_lo * 1e6:.2f}, {d_hi * 1e6:.2f}] µs/row"))
    rows.append(("pixel size", f"{result.pixel_size_mm[0]} mm", "sets the units of k1 and k2 only"))
    return rows


def _how_html(result: SelfCalibResult) -> str:
    """How the answer was reached: the tracks, the adjustment, and what the filter alone said."""
    rows = [("frames", result.frames_processed)]
    tracks = result.tracks or {}
    for key, label in (("adjustment_tracks", "tracks in the adjustment (seen in 3 or more keyframes)"),
                       ("adjustment_keyframes", "keyframes"), ("adjustment_observations", "observations")):
        if key in tracks:
            rows.append((label, tracks[key]))
    adj = result.adjustment
    if adj is not None:
        rows += [("residual (robust sigma)", f"{adj.sigma_px:.3f} px"),
                 ("solver", f"{adj.termination.lower()}, {adj.iterations} iterations, {adj.solve_time_s:.1f} s")]
    check = result.self_check
    if check:
        z = dict(zip(check["names"], check["z"]))
        said = ", ".join(f"{name} {z[name]:.1f} σ" for name in sorted(z, key=z.get, reverse=True)[:3])
        rows.append(("self-check: the two halves of the video adjusted apart",
                     f"they differ by {said}; every σ widened ×{check['widen'][0]:.2f}"
                     if check["widen"][0] > 1 else f"they agree ({said})"))
    if result.filter_mean is not None:
        fm = result.filter_mean
        rows.append(("the filter alone (Civera et al. 2009)", f"f {fm[0]:.1f} px, c ({fm[1]:.1f}, {fm[2]:.1f}); "
                     f"{result.gaussians_left} of {result.gaussians_initial} candidate cameras left"))
    note = ""
    bounds = result.adjustment_bounds_99()
    if bounds is not None and result.filter_mean is not None and not bounds[0, 0] <= result.filter_mean[0] <= bounds[0, 1]:
        note = ("<p>The filter's own f lies outside the adjustment's bounds: a sequential filter commits to its "
                "linearisation early and is biased on this kind of motion; the adjustment over all the tracks is "
                "the estimate (docs/sog.md §15).</p>")
    return f"<h2>How it was reached</h2>{table_html(rows)}{note}"


def write_report_html(path: Path, run: SelfCalibRun, summary: dict, provenance: dict) -> None:
    """report.html: the verdict, the result with its bounds, how it was reached, the plot, the files."""
    result = run.result
    warnings = list(result.warnings)
    figure = Figure(path.parent / HISTORY_PLOT, "The estimates over the sequence",
                    "The filter's estimate of each parameter frame by frame with its 99 % band (blue), and at the "
                    "right end the bundle adjustment's estimate with its bounds (green) and the reported ones (red); "
                    "the bottom panel counts the candidate cameras the filter keeps.")
    sections = [f"<h2>Result</h2>{table_html(result_rows(run), header=('', 'estimate', 'bounds'))}"
                f"<p>{escape(result.reason)}</p>",
                _how_html(result),
                f"<h2>Warnings</h2>{list_html(warnings)}" if warnings else "",
                f"<h2>Plot</h2>{figure_html(figure)}",
                f"<p>About the files:</p>{list_html(summary.get('export_notes', []))}" if summary.get("export_notes")
                else "",
                "<p>The model: Civera's radial distortion, distorted to undistorted, radii in mm at the pixel size "
                "given (docs/conventions.md); camera.yaml is the closest OpenCV pinhole-radtan camera.</p>"]
    write_report(path, "rscalib selfcalib", run.verdict, sections, files=summary["files"], provenance=provenance,
                 advice_line="How to record a self-calibration walk: run `rscalib guide capture` (the guide comes "
                             "with rscalib).")


def _readable_limits(mean: np.ndarray, lo: np.ndarray, hi: np.ndarray, extra=()) -> tuple[float, float]:
    """y limits that show the estimate and its 99 % band after the first fifth of the frames (the
    first frames span the whole prior and would flatten the rest)."""
    start = len(mean) // 5
    values = np.concatenate([mean[start:], lo[start:], hi[start:], np.asarray(extra, float)])
    values = values[np.isfinite(values)]
    if not len(values):
        return 0.0, 1.0
    a, b = float(values.min()), float(values.max())
    pad = 0.08 * (b - a) if b > a else max(abs(a) * 0.01, 1e-6)
    return a - pad, b + pad


def plot_history(result: SelfCalibResult, path: Path) -> None:
    """The five estimates with the bank's 99 % bounds per frame (f on its own large panel, its axis
    fitted to the band), the frame where the bank collapsed to one Gaussian, at the end the restarts'
    estimates, the bundle adjustment with its bounds and the reported estimate and bounds, the
    number of Gaussians, and the verdict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    units = {"f": "px", "cx": "px", "cy": "px", "k1": "mm⁻²", "k2": "mm⁻⁴"}
    history = result.history
    fig, axes = plt.subplots(6, 1, figsize=(9, 13), sharex=True, gridspec_kw={"height_ratios": [3, 1, 1, 1, 1, 1]})
    last = history.frame[-1] if len(history) else 0
    collapse = result.collapse_frame
    for i, name in enumerate(PARAM_NAMES):
        ax = axes[i]
        lo, hi = history.bounds_99[:, i, 0], history.bounds_99[:, i, 1]
        ax.fill_between(history.frame, lo, hi, alpha=0.3, label="99 % band (bank)")
        ax.plot(history.frame, history.mean[:, i], lw=1.2, label="estimate")
        ends = [r.mean[i] for r in result.restarts]
        if ends:
            ax.plot([last] * len(ends), ends, "k>", ms=6, label="restarts (end)")
        rep = result.bounds_99[i]
        ax.vlines([last], rep[0], rep[1], color="C3", lw=3, label="reported 99 % bounds")
        ax.plot([last], [result.mean[i]], "o", color="C3", label=f"reported ({result.estimate_from})")
        if result.adjustment is not None:   # the adjustment's own bounds, also when the prior's are reported
            b_lo, b_hi = result.adjustment_bounds_99()[i]
            x_ba = last + 0.02 * max(last, 1)
            value = result.adjustment.camera_params[i]
            ax.errorbar([x_ba], [value], yerr=[[value - b_lo], [b_hi - value]], fmt="D", color="C2", ms=4, capsize=3,
                        label="bundle adjustment, 99 %")
            ends = [*ends, b_lo, b_hi]
        if collapse is not None:
            ax.axvline(collapse, color="0.4", ls="--", lw=0.8, label="one Gaussian left" if i == 0 else None)
        if result.determined:
            ax.set_ylim(*_readable_limits(history.mean[:, i], lo, hi, ends))
        else:
            ax.set_ylim(*_readable_limits(history.mean[:, i], lo, hi, [*ends, *rep]))
        ax.set_ylabel(f"{name} ({units[name]})")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    axes[5].semilogy(history.frame, history.gaussians, lw=1.2, color="C3")
    if collapse is not None:
        axes[5].axvline(collapse, color="0.4", ls="--", lw=0.8)
    axes[5].set_ylabel("Gaussians")
    axes[5].set_xlabel("frame")
    m, b = result.mean, result.bounds_99
    verdict = {True: "DETERMINED", False: "NOT DETERMINED", None: "NOT CHECKED"}[result.determined]
    title = (f"{verdict}: f {m[0]:.1f} px ({result.estimate_from}), reported 99 % [{b[0, 0]:.1f}, {b[0, 1]:.1f}]"
             + (f"; one Gaussian from frame {collapse}" if collapse is not None else ""))
    fig.suptitle(title + "\n" + textwrap.fill(result.reason, 110), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
