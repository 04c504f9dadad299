"""The verdict of a flicker estimate (rscalib.verdict.Verdict): trusted, not trusted (a check
failed: the reasons say which) or not determined (the data do not determine d: no number is
claimed). The rules and why: docs/formulation.md §12, "The verdict".

Not trusted, with "check --frequency" — the two ways a wrong frequency shows in timestamped frames:

- a bottom-to-top readout measured by the phase drift but not given with --readout. A sensor read
  bottom-to-top is rare, and with a regular frame rate a wrong --frequency paints the same bands:
  the frames' flicker phases f t_i mod 1 are those of a light at f' = n·fps − f read top-to-bottom,
  mirrored (f' t_i ≡ −f t_i). 500 Hz given for a 1000 Hz LED at 30 fps gives d' = −2 d with every
  check passed, and no statistic of the fit tells it from a bottom-to-top sensor under a 500 Hz
  light (docs/formulation.md §12 has the numbers);
- the phase drift refused because the frames' band phases do not follow the timestamps and the
  frequency (or it finds no flicker at all where the spectrum finds strong bands), and the
  spectrum's |d| = ν / f is reported: at 29.97 fps the same 500-for-1000 Hz mistake lands here, and
  the spectrum's d is off by the frequency's factor. Frame times that are inexact (variable frame
  rate) do the same: --method spectrum says so, and is trusted.
"""
from __future__ import annotations

import math
from typing import Optional

from ..readout import AUTO
from ..verdict import NOT_DETERMINED, NOT_TRUSTED, TRUSTED, Verdict
from .result import FlickerResult

# the phase drift's failed checks that mean the bands do not follow the timestamps and the frequency:
# its band phases are off the prediction, or it finds no flicker where the spectrum finds strong bands
DRIFT_MISMATCH = ("phase", "evidence")
FREQUENCY_HINT = "check --frequency (mains lamps flicker at 100/120 Hz; an LED at its PWM frequency)"


def _us(x: float) -> str:
    return f"{x * 1e6:.4f}" if math.isfinite(x) else "?"


def mirrored_light(result: FlickerResult) -> Optional[tuple[float, float]]:
    """(f', d') of the light at f' = n·fps − f, nearest 2f, whose top-to-bottom bands (d' > 0) are the
    same as these bottom-to-top ones with a regular frame rate; None without the frame rate."""
    interval = result.frame_interval_s
    if not (math.isfinite(interval) and interval > 0 and result.line_delay_s < 0):
        return None
    fps = 1.0 / interval
    f = result.frequency_hz
    n = max(1, round(3.0 * f / fps))   # f' nearest 2f: the frequency given is often half the light's
    other = n * fps - f
    if not other > 0:
        return None
    return other, abs(result.line_delay_s) * f / other


def frequency_hint(result: FlickerResult) -> str:
    """The not-trusted reason of a bottom-to-top readout measured but not given."""
    said = (f"the phase drift measured a bottom-to-top readout (d = {_us(result.line_delay_s)} us/row), which is "
            f"rare: {FREQUENCY_HINT}")
    mirror = mirrored_light(result)
    if mirror is not None:
        other, d_other = mirror
        said += (f". At this frame rate a light at {other:.6g} Hz read top-to-bottom (d = {_us(d_other)} us/row) "
                 "paints the same bands")
    return said + "; if the sensor does read bottom-to-top, say so with --readout bottom-to-top"


def judge_flicker(result: FlickerResult, readout: str) -> Verdict:
    """The verdict of a flicker estimate; ``readout``: the direction the user gave (or "auto")."""
    quantity = dict(quantity="line_delay_s", unit="s/row")
    if not result.determined:
        return Verdict(NOT_DETERMINED, "Line delay not determined by the flicker bands of these frames.",
                       [result.reason or "no usable estimate"], **quantity)
    reasons = []
    if result.direction_determined and result.line_delay_s < 0 and readout == AUTO:
        reasons.append(frequency_hint(result))
    drift = result.estimates.get("phase-drift") or {}
    if result.method == "spectrum" and drift.get("failed_check") in DRIFT_MISMATCH:
        reasons.append(f"the bands do not drift between frames as the timestamps and {result.frequency_hz:g} Hz predict "
                       f"(phase drift: {drift.get('reason')}), so this is the spectrum's |d| = bands per row / "
                       f"frequency: {FREQUENCY_HINT}; if the frame times are inexact (a variable frame rate), say so "
                       "with --method spectrum")
    caveats = []
    if not result.direction_determined and readout == AUTO:
        caveats.append("the readout direction is not measured (no phase drift between timestamped frames): "
                       "top-to-bottom assumed; the bands give |d| only")
    trusted = not reasons
    headline = (f"Line delay {_us(result.line_delay_s)} ± {_us(result.line_delay_std_s)} µs/row "
                f"(readout {result.readout_time_s * 1e3:.4f} ms, {result.readout_direction}): "
                + ("trust it." if trusted else "estimated, but do not trust it yet."))
    std = result.line_delay_std_s
    return Verdict(TRUSTED if trusted else NOT_TRUSTED, headline, reasons, value=float(result.line_delay_s),
                   std=float(std) if math.isfinite(std) else None, caveats=caveats, **quantity)
