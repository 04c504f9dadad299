"""Outputs of `rscalib flicker`: result.json and flicker.png (row profiles with the fitted model,
and the per-frame or per-block estimates against the final one)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..io.output_folder import output_set
from ..io.results import write_result_json
from .estimate import FlickerResult


def write_flicker_outputs(result: FlickerResult, out_dir, source=None) -> dict:
    """Write out_dir/result.json and out_dir/flicker.png; returns the result.json dict."""
    out = Path(out_dir)
    summary = result.summary_dict() | {"source": str(source) if source is not None else None,
                                       "files": {"plot": "flicker.png"}}
    with output_set(out) as staged:   # the files replace the previous run's as a set, result.json last
        try:
            plot_flicker(result, staged / "flicker.png")
        except Exception as error:  # noqa: BLE001 - a plot of degenerate data must not cost the result
            summary["files"] = {}
            summary["warnings"] = [*summary.get("warnings", []),
                                   f"plot flicker.png skipped: {type(error).__name__}: {error}"]
        write_result_json(staged, summary, command="flicker",
                          inputs={"source": source, "frequency_hz": result.frequency_hz})
    return summary


def plot_flicker(result, path: Path) -> None:
    """Row profiles with the fitted flicker model, and the per-frame (or per-block) estimates."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    ax.set_xlabel("image row v")
    ax.set_ylabel("log row profile - scene (offset)")
    ax.set_title(f"{result.frequency_hz:g} Hz: period {result.period_rows:.1f} rows ({result.method})", fontsize=9)

    ax = axes[1]
    spread = np.asarray(result.spread_line_delays_s) * 1e6
    if len(spread):
        ax.plot(np.arange(len(spread)), spread, "o", ms=3, label=f"per {result.spread_label}")
    if math.isfinite(result.line_delay_s):
        d_us, s_us = result.line_delay_s * 1e6, result.line_delay_std_s * 1e6
        ax.axhline(d_us, color="k", lw=1, label=f"d = {d_us:.5g} us/row")
        if math.isfinite(s_us):
            ax.axhspan(d_us - s_us, d_us + s_us, color="k", alpha=0.15, label="±1 std")
        ax.legend(fontsize=7)
    ax.set_xlabel(result.spread_label)
    ax.set_ylabel("line delay (us/row)")
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.set_title("estimates" + ("" if result.determined else " (NOT determined)"), fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
