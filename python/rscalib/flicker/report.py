"""Outputs of `rscalib flicker` (FlickerRun.write): result.json with the verdict block, the plots
(flicker.png: row profiles with the fitted bands, and the per-frame or per-block estimates against
the final one; flicker_search.png: the phase drift's residual over every line delay searched) and a
self-contained report.html (the verdict first, the result with units, each plot with what to look
for, the files, the provenance). Written as one set (io.output_folder.output_set): staged, then
renamed into place with result.json last, replacing the previous run's files in that folder."""
from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..io.output_folder import output_set
from ..io.report_html import Figure, figure_html, list_html, table_html, write_report
from ..io.results import write_result_json
from ..verdict import NOT_DETERMINED, Verdict
from .result import FlickerResult

if TYPE_CHECKING:
    from .pipeline import FlickerRun

# the fields that claim a line delay (in its forms): null when the verdict claims none, kept apart
# under not_claimed (for diagnosis only)
CLAIMED = ("line_delay_s", "line_delay_std_s", "line_delay_std_fit_s", "line_delay_std_spread_s", "readout_time_s",
           "period_rows", "cycles_per_frame", "spread_line_delays_s")



def run_summary(run: FlickerRun) -> dict:
    """FlickerRun.summary(): the result's summary_dict, the source and the verdict block; when the
    verdict claims no number, the line delay's fields are null and kept under not_claimed."""
    summary = run.result.summary_dict() | {"source": run.inputs.get("source")}
    summary["verdict"] = run.verdict.to_dict()
    if not run.verdict.claims:
        summary["not_claimed"] = {k: summary[k] for k in CLAIMED}
        summary.update({k: None for k in CLAIMED})
    return summary


# ------------------------------------------------------------------------------------------- plots

def _pyplot():
    """pyplot on the Agg backend (files only), imported on first use."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    plt = _pyplot()
    fig.tight_layout()
    fig.savefig(path, bbox_inches="tight")   # nothing cut off (long axis labels)
    plt.close(fig)
    return path


def plot_flicker(result: FlickerResult, verdict: Verdict, path: Path) -> Path:
    """Row profiles with the fitted flicker model, and the per-frame (or per-block) estimates with
    the final line delay when the verdict claims one."""
    from matplotlib.ticker import MaxNLocator

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), dpi=90)
    ax = axes[0]
    plot = result.plot
    if plot.get("observed") is not None:
        for k, frame in enumerate(plot["frames"]):
            offset = 2.5 * k * max(result.modulation_depth, 0.02) if math.isfinite(result.modulation_depth) else 0.0
            line, = ax.plot(plot["rows_v"], plot["observed"][k] + offset, ".", ms=1.5, alpha=0.5)
            ax.plot(plot["rows_v"], plot["model"][k] + offset, "-", lw=1.0, color=line.get_color(),
                    label=f"frame {frame}")
        ax.legend(fontsize=7, loc="upper right")
    ax.set_xlabel("image row v (rows)")
    ax.set_ylabel("log grey level − scene\n(natural log, offset per frame)")
    period = f"period {result.period_rows:.1f} rows" if verdict.claims else "period not determined"
    ax.set_title(f"{result.frequency_hz:g} Hz: {period} ({result.method})", fontsize=9)

    ax = axes[1]
    if not verdict.claims:   # no number is claimed, so none is drawn
        ax.axis("off")
        ax.text(0.5, 0.5, "line delay not determined:\nno number is claimed\n(the reason: report, result.json)",
                ha="center", va="center", fontsize=10, transform=ax.transAxes)
        return _save(fig, path)
    spread = np.asarray(result.spread_line_delays_s) * 1e6
    if len(spread):
        ax.plot(np.arange(len(spread)), spread, "o", ms=3, label=f"per {result.spread_label}")
    if math.isfinite(result.line_delay_s):
        d_us, s_us = result.line_delay_s * 1e6, result.line_delay_std_s * 1e6
        ax.axhline(d_us, color="k", lw=1, label=f"d = {d_us:.5g} µs/row")
        if math.isfinite(s_us):
            ax.axhspan(d_us - s_us, d_us + s_us, color="k", alpha=0.15, label="±1σ")
    ax.legend(fontsize=7)
    ax.set_xlabel(f"{result.spread_label} (index)")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("line delay (µs/row)")
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.set_title("estimates", fontsize=9)
    return _save(fig, path)


def plot_search(result: FlickerResult, verdict: Verdict, path: Path) -> Path:
    """The phase drift's residual (fundamental only, the first frames) over every line delay searched,
    both readout directions, with the estimate marked when the verdict claims one."""
    plt = _pyplot()
    grid_nu, grid_rss = (np.asarray(result.plot[k]) for k in ("grid_nu", "grid_rss"))
    fig, ax = plt.subplots(figsize=(10, 3.2), dpi=90)
    ax.plot(grid_nu / result.frequency_hz * 1e6, grid_rss, "-", lw=1)
    if verdict.claims and math.isfinite(result.line_delay_s):
        ax.axvline(result.line_delay_s * 1e6, color="r", lw=0.8, ls="--", label="estimate")
        ax.legend(fontsize=7)
    ax.set_xlabel("line delay searched (µs/row; negative: bottom-to-top readout)")
    ax.set_ylabel("residual sum of squares\n(weighted log grey²)")
    ax.set_title("Phase drift: fit of the fundamental over the line delays searched", fontsize=9)
    return _save(fig, path)


# (file, plot function, caption: what to look for)
PLOTS = (
    ("flicker.png", plot_flicker,
     "Left: each shown frame's row profile with the scene removed (dots) and the fitted bands (line): the line "
     "should follow the stripes of the dots in every frame. Right: the line delay from each frame or block of "
     "frames against the final one (grey: ±1σ): the points should scatter about it without a trend."),
    ("flicker_search.png", plot_search,
     "The deepest minimum is the line delay; a second minimum nearly as deep elsewhere means the bands are "
     "aliased (the estimate is then refused). The deepest on the negative side (a bottom-to-top readout) is "
     "rare: check --frequency."),
)


def _plot_jobs(result: FlickerResult) -> list:
    """The plots this result can draw: flicker.png always; flicker_search.png when the phase drift ran."""
    has_grid = result.plot.get("grid_nu") is not None and result.plot.get("grid_rss") is not None
    return [job for job in PLOTS if job[0] != "flicker_search.png" or has_grid]


# ---------------------------------------------------------------------------------------- writers

def write_flicker_run(run: FlickerRun, out_dir) -> dict:
    """FlickerRun.write(): result.json, the plots and report.html into out_dir as one set; returns
    the result.json dict (without its provenance). A plot that fails is left out and said in the
    warnings (a plot of degenerate data must not cost the result)."""
    summary = run_summary(run)
    with output_set(Path(out_dir)) as staged:
        out = Path(staged)
        plots, failed = {}, []
        for name, plot, caption in _plot_jobs(run.result):
            try:
                plots[name] = (plot(run.result, run.verdict, out / name), caption)
            except Exception as error:  # noqa: BLE001
                _pyplot().close("all")
                failed.append(f"plot {name} skipped: {type(error).__name__}: {error}")
        summary["warnings"] = [*summary.get("warnings", []), *failed]
        summary["files"] = {"plots": list(plots), "report": "report.html"}
        result_path = write_result_json(out, summary, command=run.command, inputs=run.inputs)
        provenance = json.loads(result_path.read_text()).get("provenance", {})
        write_report_html(out / "report.html", summary, run.verdict, plots, provenance)
    return summary


def _us(x) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x * 1e6:.4f} µs/row"


def _direction_note(summary: dict) -> str:
    if summary["direction_determined"]:
        return "measured by the phase drift"
    return "given with --readout" if "given" in summary["readout_direction"] else "assumed: the bands give |d| only"


def result_rows(summary: dict) -> list:
    """(label, value with its unit) of the report's result table."""
    claimed = (summary.get("verdict") or {}).get("status") != NOT_DETERMINED
    rows = [("line delay", _us(summary["line_delay_s"]) if claimed else "not determined (no number is claimed)")]
    if claimed:
        spread = summary.get("line_delay_std_spread_s")
        rows += [("standard deviation", f"{_us(summary['line_delay_std_s'])} (the larger of the fit's "
                  f"{_us(summary.get('line_delay_std_fit_s'))} and the spread over {summary['spread_label']}s' "
                  f"{_us(spread)})"),
                 ("readout time", f"{summary['readout_time_s'] * 1e3:.4f} ms ({summary['rows']} rows read out)"),
                 ("band period", f"{summary['period_rows']:.3f} rows ({summary['cycles_per_frame']:.2f} periods over "
                  "the rows used)"),
                 ("readout direction", f"{summary['readout_direction'].split(' (')[0]} ({_direction_note(summary)})")]
    rows.append(("light frequency (given)", f"{summary['frequency_hz']:g} Hz"))
    if summary.get("blanking_determined"):
        rows.append(("vertical blanking", f"{summary['vertical_blanking_rows']:.2f} ± "
                     f"{summary['vertical_blanking_std_rows']:.2f} rows ({summary['vertical_blanking_s'] * 1e3:.4f} ms)"))
    if summary.get("frame_interval_s") is not None:
        rows.append(("frame interval", f"{summary['frame_interval_s'] * 1e3:.4f} ms "
                     f"({1.0 / summary['frame_interval_s']:.4g} frames/s; timestamps from {summary['timestamps_source']})"))
    else:
        rows.append(("frame timestamps", "none: the phase drift cannot be used"))
    rows += [("method", f"{summary['method']} (scene removed: {summary['detrend']})"),
             ("frames used / read", f"{summary['frames_used']} / {summary['frames_total']}"),
             ("image size", f"{summary['image_size'][0]} × {summary['image_size'][1]} px")]
    region = summary.get("region") or {}
    if region.get("bounding_box_xywh"):
        box = ",".join(str(c) for c in region["bounding_box_xywh"])
        rows.append(("region used", f"x,y,w,h = {box} px ({region.get('mode')}); {region.get('strips_used')} of "
                     f"{region.get('strips_total')} column strips, {region.get('cells_masked', 0)} cells masked"))
    if summary.get("modulation_depth") is not None:
        rows.append(("flicker depth", f"{summary['modulation_depth']:.3f} (amplitude of the fundamental of the log "
                     "gain, ≈ relative depth)"))
    if summary.get("delta_chi2") is not None:
        rows.append(("evidence for the bands", f"Δχ² = {summary['delta_chi2']:.0f}"))
    return rows


def _estimators_html(summary: dict) -> str:
    """One row per estimator: ok or why not (its line delay only when the verdict claims one)."""
    claimed = (summary.get("verdict") or {}).get("status") != NOT_DETERMINED
    cells = []
    for name, e in (summary.get("estimates") or {}).items():
        value = _us(e.get("line_delay_s")) if claimed and e.get("line_delay_s") is not None else "—"
        state = "ok" if e.get("ok") else html.escape(e.get("reason") or "not ok")
        cells.append(f"<tr><td>{html.escape(name)}</td><td>{value}</td><td>{state}</td></tr>")
    if not cells:
        return ""
    return ("<h2>The estimators</h2><table><tr><th>method</th><th>line delay</th><th>result</th></tr>"
            + "".join(cells) + "</table>")


def write_report_html(path: Path, summary: dict, verdict: Verdict, plots: dict, provenance: dict) -> Path:
    """report.html (io.report_html): the verdict (headline, reasons, caveats), the result table, the
    estimators, the warnings, each plot (embedded as PNG) with what to look for, the files and the
    provenance."""
    figures = "".join(figure_html(Figure(p, caption)) for p, caption in plots.values())
    caveats = f"<p>Said with the verdict:</p>{list_html(verdict.caveats)}" if verdict.caveats else ""
    warnings = summary.get("warnings") or []
    sections = [caveats, f"<h2>Result</h2>{table_html(result_rows(summary))}", _estimators_html(summary),
                f"<h2>Warnings</h2>{list_html(warnings)}" if warnings else "",
                f"<h2>Plots</h2>{figures or '<p>No plot could be drawn (see the warnings).</p>'}",
                "<p>Conventions: row v of a frame is exposed at t + v·d (d &lt; 0: the readout runs bottom-to-top); a "
                "light of intensity frequency f paints bands every 1/(f·|d|) rows; the method: "
                "docs/formulation.md, flicker.</p>"]
    write_report(path, "rscalib flicker", verdict, sections, files=summary.get("files") or {},
                 provenance=provenance, advice_line="How to film flicker bands: run `rscalib guide capture` "
                                                    "(the flicker section; the guide comes with rscalib).")
    return path
