"""The flicker engine: row profiles -> FlickerResult (docs/formulation.md §12). The front door
(pipeline.py) reads the frames and chooses the region; this runs the estimators and the checks:

  detrend:     the scene cancelled over all frames, else over blocks of MOVING_BLOCK frames (a
               moving camera), else a smooth polynomial per frame (the flicker phase the same in
               every frame: frame rate and flicker commensurate); the first that gives an estimate.
  estimators:  phase drift (spectrum... phase_drift.py) first, it uses the most information; the
               spectrum (spectrum.py) beside it.
  checks:      σ <= MAX_RELATIVE_STD of |d|; the fitted bands explain the profiles' periodic
               structure (model.residual_tests, which also inflate σ); the estimators agree within
               AGREEMENT_SIGMAS; a readout direction given must be the one measured. Else
               ``determined = False`` with the reasons.
  then:        the readout direction (measured by the phase drift, else given or assumed), the
               vertical blanking (regular timestamps), the modulation depth and the plot material.

Uncertainty: the fit's (curvature or Jacobian, scaled by the residual variance, inflated for
residual power near the band harmonics, for residual common to all frames, and by the χ² of row
segments) and the spread over frames or frame blocks; ``line_delay_std_s`` is the larger.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..errors import InputError
from ..readout import BOTTOM_TO_TOP, TOP_TO_BOTTOM, check_rows_read
from .model import (
    SPECTRUM_MIN_CYCLES,
    LogProfiles,
    frame_blocks,
    frame_fit,
    harmonics_at,
    log_profiles,
    residual_tests,
)
from .options import FlickerOptions
from .phase_drift import drift_model, phase_drift_estimate
from .profiles import RowProfiles
from .result import FlickerResult
from .spectrum import spectrum_estimate

MAX_RELATIVE_STD = 0.25
SAME_PHASE_RESULTANT = 0.95      # |mean exp(2πi f t_i)| above this: phases (almost) all equal
MOVING_BLOCK = 4                 # frames per block when the scene may move (detrend "frames")
SPREAD_DISAGREEMENT = 2.0        # fit vs spread uncertainty ratio that earns a warning
RESIDUAL_PEAK_MAX = 0.25         # residual periodogram peak off the fitted harmonics over the bands' peak
AGREEMENT_SIGMAS = 3.0           # spectrum and phase drift must agree within this many σ
READOUT_SIGN = {"auto": 0, TOP_TO_BOTTOM: 1, BOTTOM_TO_TOP: -1}


def std_of(estimate: dict, frequency_hz: float) -> tuple[float, float, float]:
    """(reported, fit, spread) std of d of an estimator's dict: the larger of the two that exist."""
    fit = estimate.get("std_fit_nu", float("nan")) / frequency_hz
    spread = estimate.get("std_spread_nu", float("nan")) / frequency_hz
    known = [x for x in (fit, spread) if math.isfinite(x) and x > 0]
    return (max(known) if known else float("inf")), fit, spread


def search_limit(profiles: RowProfiles, frequency_hz: float, rows: int,
                 max_line_delay_s: Optional[float]) -> tuple[float, Optional[float]]:
    """(the largest |ν| = f |d| searched, the median frame interval or None): a frame's readout fits
    in its frame interval (unless max_line_delay_s is given); rows alias above 0.5 cycles/row."""
    times = profiles.times_s
    n = profiles.values.shape[0]
    nu_hi = 0.49
    frame_interval = float(np.median(np.diff(times))) if times is not None and n > 1 else None
    if max_line_delay_s is not None:
        nu_hi = min(nu_hi, frequency_hz * float(max_line_delay_s))
    elif frame_interval is not None:
        nu_hi = min(nu_hi, 1.05 * frequency_hz * frame_interval / max(rows, profiles.image_size[1]))
    return nu_hi, frame_interval


def detrend_attempts(frames: int, phase0: Optional[np.ndarray], detrend: str, frequency_hz: float,
                     warnings: list) -> list:
    """(detrend, block) to try in order: over all frames, then in blocks of MOVING_BLOCK, the smooth
    fallback only if those cannot work (one frame, or the same flicker phase in every frame: then a
    warning is added to `warnings`)."""
    def spread_of(index) -> Optional[float]:
        return None if phase0 is None else float(abs(np.mean(np.exp(2j * np.pi * phase0[index]))))

    resultant = spread_of(slice(None))
    attempts: list = []
    if detrend in ("auto", "frames") and frames >= 2 and (detrend == "frames" or resultant is None
                                                          or resultant <= SAME_PHASE_RESULTANT):
        attempts.append(("frames", None))
        blocks = frame_blocks(frames, MOVING_BLOCK)
        if frames >= 2 * MOVING_BLOCK and (phase0 is None or np.mean([spread_of(g) for g in blocks])
                                           <= SAME_PHASE_RESULTANT):
            attempts.append(("frames", MOVING_BLOCK))
    if detrend in ("auto", "smooth") and (detrend == "smooth" or not attempts or resultant is None):
        attempts.append(("smooth", None))
    if detrend == "auto" and frames >= 2 and resultant is not None and resultant > SAME_PHASE_RESULTANT:
        warnings.append(f"the flicker phase is (almost) the same in every frame (frame rate and {frequency_hz:g} Hz "
                        "commensurate): static scene structure cannot be told from bands; assuming the "
                        "scene's row profile is smooth")
    if not attempts:
        raise InputError("detrend 'frames' needs at least 2 frames (the scene is cancelled over them)")
    return attempts


def _first_estimate(attempts: list, log: tuple, options: FlickerOptions, nu_hi: float, sign: int,
                    frequency_hz: float) -> tuple[LogProfiles, dict, Optional[dict]]:
    """(the data, every estimator's dict, the chosen estimate or None) of the first detrend that
    gives a good estimate (a static scene cancels best over all frames; blocks of frames only when
    that fails, e.g. a moving camera), else of the last tried. Phase drift first: it uses the most
    information."""
    y, sw, v, phase0 = log
    span_rows = float(np.ptp(v)) + 1.0
    last = None
    for mode, block in attempts:
        data = LogProfiles(y, sw, v, phase0, mode, options.poly_degree, block)
        spec = spectrum_estimate(data, nu_hi, options.harmonics) if options.method in ("auto", "spectrum") else None
        drift = None
        if options.method in ("auto", "phase-drift") and phase0 is not None and nu_hi > 0.1 / span_rows:
            drift = phase_drift_estimate(data, 0.1 / span_rows, nu_hi, options.harmonics, sign)
        found = {e["method"]: dict(e, detrend=data.label) for e in (drift, spec) if e is not None}
        good = [e for e in found.values() if e["ok"]]
        last = (data, found, None)
        if good:
            return data, found, good[0]
    assert last is not None
    return last


def summarise_estimates(estimates: dict, frequency_hz: float) -> dict:
    """result.json's `estimates`: each estimator's d (s/row), its σ, ok or the reason, and the
    numbers of its tests."""
    f = frequency_hz
    summary = {}
    for name, e in estimates.items():
        entry = {"ok": bool(e["ok"]), "detrend": e["detrend"]}
        if "nu" in e:
            total, fit, spread = std_of(e, f)
            entry.update(line_delay_s=e["nu"] / f, line_delay_std_s=total, line_delay_std_fit_s=fit,
                         line_delay_std_spread_s=spread, delta_chi2=e.get("delta_chi2"))
        if "reason" in e:
            entry["reason"] = e["reason"]
        if "failed_check" in e:
            entry["failed_check"] = e["failed_check"]
        if "alias_nu" in e:
            entry["alias_line_delay_s"] = e["alias_nu"] / f
        for key in ("ambiguity_delta_chi2", "distinct_phases", "joint_vs_free_f", "phase_rms_cycles", "peak_ratio",
                    "segment_chi2", "amplitude_spread", "edge_width_rows"):
            if e.get(key) is not None:
                entry[key] = e[key]
        if "candidates_nu" in e:
            entry["candidate_line_delays_s"] = [c / f for c in e["candidates_nu"]]
        summary[name] = entry
    return summary


@dataclass
class _Judged:
    """The chosen estimate as the checks leave it: ν (cycles/row), its σ of d, determined, why not."""

    nu: float
    std_total: float
    std_fit: float
    std_spread: float
    determined: bool
    reasons: list = field(default_factory=list)
    checks: dict = field(default_factory=dict)

    def refuse_if_too_uncertain(self, frequency_hz: float) -> None:
        if self.determined and not self.std_total <= MAX_RELATIVE_STD * abs(self.nu / frequency_hz):
            self.determined = False
            self.reasons.append(f"std {self.std_total * 1e6:.3g} us/row is more than {MAX_RELATIVE_STD:.0%} of the "
                                "estimate")


def _residual_check(state: _Judged, data: LogProfiles, chosen: dict, kmax: int, frequency_hz: float) -> np.ndarray:
    """The fitted waveform must explain the periodic structure of the profiles: the explained
    fraction, σ inflated for residual power near the band harmonics, and no residual peak off them.
    Returns the projected model (frames, rows)."""
    harmonics = chosen.get("harmonics") or harmonics_at(chosen["nu"], kmax)
    if chosen["method"] == "phase-drift":
        model_yp = drift_model(data, chosen["nu"], chosen["coef"], harmonics)
    else:
        model_yp = np.nan_to_num(frame_fit(data, chosen["nu"], harmonics) * data.sw)
    explained = 1.0 - float(np.sum((data.yp - model_yp) ** 2)) / max(data.null_rss(), 1e-300)
    state.checks["explained_fraction"] = explained
    peak_ratio, peak_nu, inflation = residual_tests(data, model_yp, state.nu)
    state.checks["residual_noise_inflation"] = inflation
    if inflation > 1.0 and math.isfinite(state.std_fit):
        state.std_fit *= math.sqrt(inflation)
        state.std_total = max(state.std_total, state.std_fit)
        state.refuse_if_too_uncertain(frequency_hz)
    if abs(state.nu) * data.span >= SPECTRUM_MIN_CYCLES:
        state.checks["residual_peak_ratio"] = peak_ratio
        if state.determined and peak_ratio > RESIDUAL_PEAK_MAX:
            state.determined = False
            state.reasons.append(f"the fitted bands do not explain the profiles: periodic structure of period "
                                 f"{1.0 / peak_nu:.1f} rows is left ({peak_ratio:.0%} of the bands' peak power)")
    return model_yp


def _agreement_check(state: _Judged, chosen: dict, estimates: dict, frequency_hz: float) -> None:
    """Every estimator that produced an estimate must agree with the one reported."""
    f = frequency_hz
    if not state.determined:
        return
    for name, e in estimates.items():
        if e is chosen or not e["ok"]:
            continue
        s_a, s_b = state.std_total, std_of(e, f)[0]
        gap = abs(abs(chosen["nu"]) - abs(e["nu"])) / f
        sigmas = gap / math.hypot(s_a, s_b) if math.hypot(s_a, s_b) > 0 else float("inf")
        state.checks[f"agreement_{chosen['method']}_vs_{name}_sigmas"] = sigmas
        if not sigmas <= AGREEMENT_SIGMAS:
            state.determined = False
            state.reasons.append(f"the methods disagree: {chosen['method']} {abs(chosen['nu']) / f * 1e6:.6g} and "
                                 f"{name} {abs(e['nu']) / f * 1e6:.6g} us/row ({sigmas:.1f} sigma apart): a "
                                 "harmonic, inexact timestamps or frequency, or not flicker")


def _direction(state: _Judged, chosen: Optional[dict], readout: str, warnings: list) -> tuple[str, bool]:
    """(the readout direction, measured?): the spectrum sees |d|, the phase drift its sign. A
    direction given that the phase drift contradicts makes d undetermined; one not measured is
    said "(given)" or "(assumed)"."""
    sign = READOUT_SIGN[readout]
    measured = chosen is not None and chosen.get("method") == "phase-drift"
    if chosen is not None and not measured:
        state.nu = abs(state.nu) * (-1.0 if sign < 0 else 1.0)
    if measured and sign != 0 and np.sign(state.nu) != sign:
        state.determined = False
        state.reasons.append(f"the phase drift says the readout runs "
                             f"{TOP_TO_BOTTOM if state.nu > 0 else BOTTOM_TO_TOP}, not {readout} as given")
    direction = BOTTOM_TO_TOP if state.nu < 0 else TOP_TO_BOTTOM
    if chosen is not None and not measured:
        if sign == 0:
            warnings.append("readout direction not measured (no usable phase drift between timestamped frames): "
                            "top-to-bottom assumed; the bands give |d| only")
        direction += " (given)" if sign != 0 else " (assumed)"
    return direction, bool(measured)


def _blanking(state: _Judged, chosen: Optional[dict], profiles: RowProfiles, frame_interval: Optional[float],
              rows: int, frequency_hz: float, warnings: list) -> tuple[float, float, float, bool]:
    """(blanking rows, their σ, blanking s, determined): the frame period is (rows + blanking rows)
    × |d|; only from the phase drift with regular timestamps."""
    blank = blank_std = blank_s = float("nan")
    blank_ok = False
    if state.determined and chosen is not None and chosen.get("method") == "phase-drift" and frame_interval:
        intervals = np.diff(profiles.times_s)
        d_abs = abs(state.nu) / frequency_hz
        blank = frame_interval / d_abs - rows
        blank_std = frame_interval * state.std_total / d_abs ** 2
        blank_s = frame_interval - d_abs * rows
        regular = float(np.max(np.abs(intervals - frame_interval))) <= 0.001 * frame_interval
        blank_ok = bool(regular and blank_std <= max(1.0, 0.01 * (rows + blank)) and blank > -3 * blank_std)
        if not regular:
            warnings.append("frame intervals are irregular: the vertical blanking is not determined")
    return blank, blank_std, blank_s, blank_ok


def _plot_material(data: LogProfiles, chosen: dict, model_yp: np.ndarray, rows_v: np.ndarray) -> dict:
    """A few frames' projected profiles (unweighted) with the fitted model, and the phase drift's
    grid of candidates when it ran."""
    n = data.frames
    show = np.unique(np.linspace(0, n - 1, min(n, 3)).round().astype(int))
    observed = data.unweighted(data.yp)
    model = data.unweighted(model_yp)
    return {"rows_v": rows_v, "frames": show, "observed": observed[show], "model": model[show],
            "grid_nu": chosen.get("grid_nu"), "grid_rss": chosen.get("grid_rss")}


def _modulation_depth(data: LogProfiles, chosen: Optional[dict]) -> float:
    """The amplitude of the fundamental of the log gain (≈ the relative depth of the flicker)."""
    if chosen is not None and chosen.get("method") == "phase-drift" and "coef" in chosen:
        return float(np.hypot(*chosen["coef"][:2]))
    if chosen is not None and "nu" in chosen:
        fits = frame_fit(data, chosen["nu"], 1)
        return float(np.nanmedian(np.nanmax(fits, axis=1) - np.nanmin(fits, axis=1)) / 2.0)
    return float("nan")


def _judge_chosen(data: LogProfiles, estimates: dict, chosen: Optional[dict], options: FlickerOptions,
                  frequency_hz: float, warnings: list) -> tuple[_Judged, Optional[dict], Optional[np.ndarray]]:
    """The checks on the chosen estimate (or, when none is good, on the best unclaimed guess of the
    estimator that got furthest): (its state, that estimate, the fitted model)."""
    f = frequency_hz
    determined = chosen is not None
    reasons: list = []
    if chosen is None:
        chosen = next((e for e in estimates.values() if "nu" in e), None)
        reasons.append("; ".join(f"{k}: {e['reason']}" for k, e in estimates.items() if "reason" in e)
                       or "no usable estimate")
    if chosen is None:
        nan = float("nan")
        return _Judged(nan, nan, nan, nan, False, reasons), None, None
    state = _Judged(chosen["nu"], *std_of(chosen, f), determined, reasons)
    if determined and math.isfinite(state.std_fit) and math.isfinite(state.std_spread) and state.std_fit > 0 \
            and state.std_spread > 0:
        ratio = state.std_spread / state.std_fit
        if ratio > SPREAD_DISAGREEMENT or ratio < 1.0 / SPREAD_DISAGREEMENT:
            label = chosen.get("spread_label", "frame")
            warnings.append(f"uncertainty from the fit ({state.std_fit * 1e9:.3g} ns) and from the spread over "
                            f"{label}s ({state.std_spread * 1e9:.3g} ns) disagree; reporting the larger")
    state.refuse_if_too_uncertain(f)
    model_yp = _residual_check(state, data, chosen, options.harmonics, f)
    _agreement_check(state, chosen, estimates, f)
    return state, chosen, model_yp


def estimate_from_profiles(profiles: RowProfiles, frequency_hz: float, options: FlickerOptions) -> FlickerResult:
    """The line delay d (s/row) from row profiles whose region is chosen (profiles.region), for a
    light of intensity frequency ``frequency_hz``; see the module docstring."""
    f = float(frequency_hz)
    check_rows_read(options.rows, profiles.image_size[1])
    rows = options.rows if options.rows is not None else profiles.image_size[1]
    if options.method == "phase-drift" and profiles.times_s is None:
        raise InputError("the phase-drift method needs frame timestamps")
    warnings = list(profiles.warnings)
    nu_hi, frame_interval = search_limit(profiles, f, rows, options.max_line_delay_s)
    log = log_profiles(profiles, f)
    attempts = detrend_attempts(profiles.values.shape[0], log[3], options.detrend, f, warnings)
    data, estimates, chosen = _first_estimate(attempts, log, options, nu_hi, READOUT_SIGN[options.readout], f)
    state, chosen, model_yp = _judge_chosen(data, estimates, chosen, options, f, warnings)
    direction, direction_determined = _direction(state, chosen, options.readout, warnings)
    blank, blank_std, blank_s, blank_ok = _blanking(state, chosen, profiles, frame_interval, rows, f, warnings)
    if not state.determined:
        warnings.append("the data do not determine the line delay: " + "; ".join(state.reasons))
    plot = {} if chosen is None else _plot_material(data, chosen, model_yp, profiles.rows_v)
    nu, span = state.nu, data.span
    line_delay = nu / f
    return FlickerResult(
        line_delay_s=line_delay, line_delay_std_s=state.std_total, line_delay_std_fit_s=state.std_fit,
        line_delay_std_spread_s=state.std_spread, readout_time_s=abs(line_delay) * rows, rows=rows, frequency_hz=f,
        period_rows=1.0 / abs(nu) if nu and math.isfinite(nu) else float("nan"),
        cycles_per_frame=abs(nu) * span if math.isfinite(nu) else float("nan"),
        method=chosen["method"] if chosen is not None else "none", detrend=data.detrend,
        frames_used=profiles.values.shape[0], frames_total=profiles.frames_total,
        modulation_depth=_modulation_depth(data, chosen),
        delta_chi2=float(chosen.get("delta_chi2", float("nan")) if chosen is not None else float("nan")),
        determined=bool(state.determined), warnings=warnings, estimates=summarise_estimates(estimates, f),
        spread_label=chosen.get("spread_label", "frame") if chosen is not None else "frame",
        spread_line_delays_s=np.asarray(chosen.get("per_frame_nu", np.zeros(0)) if chosen is not None
                                        else np.zeros(0)) / f,
        timestamps_source=profiles.timestamps_source, image_size=tuple(profiles.image_size), roi=profiles.roi,
        readout_direction=direction, direction_determined=direction_determined, vertical_blanking_rows=blank,
        vertical_blanking_std_rows=blank_std, vertical_blanking_s=blank_s, blanking_determined=blank_ok,
        frame_interval_s=float("nan") if frame_interval is None else frame_interval,
        reason=None if state.determined else "; ".join(state.reasons), checks=state.checks,
        region=dict(profiles.region), plot=plot)
