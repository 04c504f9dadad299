"""FlickerResult: the line delay from flicker bands with everything behind it (the estimators'
numbers, the checks, the region, the plot material); `summary_dict()` is result.json's body.

Times in seconds, ν in cycles per row. ``determined`` False: the data do not determine d; the
fields then hold the best unclaimed guess (the front door's FlickerRun claims none of it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass
class FlickerResult:
    """Line delay from flicker bands. Times in seconds, ν in cycles per row."""

    line_delay_s: float              # signed: negative = bottom-to-top readout (docs/conventions.md)
    line_delay_std_s: float          # max(fit, spread) when both exist
    line_delay_std_fit_s: float      # Jacobian / profile curvature, scaled by the residual variance
    line_delay_std_spread_s: float   # spread over frames (spectrum) or blocks of frames (phase drift)
    readout_time_s: float            # |d| · rows
    rows: int
    frequency_hz: float
    period_rows: float
    cycles_per_frame: float          # periods across the rows used
    method: str                      # "spectrum" | "phase-drift"
    detrend: str                     # "frames" | "smooth"
    frames_used: int
    frames_total: int
    modulation_depth: float          # amplitude of the fundamental of the log gain (≈ relative depth)
    delta_chi2: float                # chi² drop from the flicker model: the evidence for the bands
    determined: bool
    warnings: list
    estimates: dict                  # every method tried: line_delay_s, std, ok / reason
    spread_label: str = "frame"
    spread_line_delays_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    timestamps_source: str = "none"
    image_size: tuple = (0, 0)
    roi: Optional[tuple] = None
    readout_direction: str = "top-to-bottom"
    direction_determined: bool = False   # by the phase drift (timestamps); else assumed or given
    vertical_blanking_rows: float = float("nan")
    vertical_blanking_std_rows: float = float("nan")
    vertical_blanking_s: float = float("nan")
    blanking_determined: bool = False
    frame_interval_s: float = float("nan")   # median interval of the frames' timestamps (nan without)
    reason: Optional[str] = None         # why not determined
    checks: dict = field(default_factory=dict)
    region: dict = field(default_factory=dict)
    plot: dict = field(default_factory=dict, repr=False)

    def summary_dict(self) -> dict:
        def clean(x):
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, (list, tuple, np.ndarray)):
                return [clean(v) for v in x]
            if isinstance(x, (float, np.floating)):
                return float(x) if math.isfinite(x) else None
            if isinstance(x, (np.integer, np.bool_)):
                return x.item()
            return x
        keys = ["line_delay_s", "line_delay_std_s", "line_delay_std_fit_s", "line_delay_std_spread_s",
                "readout_time_s", "rows", "frequency_hz", "period_rows", "cycles_per_frame", "method", "detrend",
                "frames_used", "frames_total", "modulation_depth", "delta_chi2", "determined", "reason", "warnings",
                "readout_direction", "direction_determined", "vertical_blanking_rows", "vertical_blanking_std_rows",
                "vertical_blanking_s", "blanking_determined", "frame_interval_s", "checks", "estimates", "region", "spread_label",
                "timestamps_source", "image_size", "roi"]
        out = {k: clean(getattr(self, k)) for k in keys}
        out["spread_line_delays_s"] = clean(self.spread_line_delays_s)
        return out
