"""The spectrum estimator of the flicker method (docs/formulation.md §12): each frame its own band
phase, so no timestamps are needed, and |d| only; it needs a few periods per frame.

Candidates are the periodogram's peaks and their sub-harmonics, each refined by least squares with
the harmonics of a square-ish wave; the best (BIC) is kept, then the fundamental is chosen over its
sub-harmonics by nested tests (a harmonic of the bands never wins: it misses the fundamental; a
sub-harmonic only fits noise with its extra terms). The uncertainty is the curvature's, widened by
the χ² of row segments and by the sampling of edges sharper than a row, and the spread over frames.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from scipy.optimize import minimize_scalar

from .model import (
    HARMONIC_NU_MAX,
    MIN_DELTA_CHI2,
    SPECTRUM_MIN_CYCLES,
    LogProfiles,
    frame_amplitudes,
    frame_fit,
    frame_rss,
    harmonics_at,
    parabolic_peak,
    periodogram,
    refine_frames,
    total_frame_rss,
)
from .profiles import MIN_ROWS

MAX_AMPLITUDE_SPREAD = 0.5       # relative spread of the frames' band amplitudes
SQUARE_MIN_CYCLES = 3.0          # the spectrum alone needs this many: fewer periods of a many-harmonic
                                 # waveform can fit a step or two of a slower light (a harmonic lock)
MIN_PEAK_RATIO = 10.0            # periodogram peak over its median in the search band
FUNDAMENTAL_F_AMBIGUOUS = 100.0  # nested F at or above this with a small share: refuse (either may be the bands)
FUNDAMENTAL_F = 4.0              # nested F below this: a sub-harmonic's extra terms explain nothing
SUBHARMONIC_SHARE = 0.1          # ... or less than this share of what the fundamental's harmonics explain
EDGE_QUANTISATION_ROWS = math.sqrt(2.0 / 12.0)  # σ of a period's span when both end edges are sampled to ±0.5 row
EDGE_MIN_CONTRAST = 10.0         # band contrast in noise σ needed to see how sharp the edges are


def _dof(data: LogProfiles, k_count: int) -> int:
    """Degrees of freedom of K harmonics per frame after the nuisances."""
    return max(1, data.frames * data.rows_used - data.nuisance_dof() - data.frames * 2 * k_count - 1)


def fundamental(data: LogProfiles, nu: float, k_count: int, rss: float, dof: int) -> tuple[float, list, Optional[str]]:
    """Climb from a candidate to the fundamental it may be a sub-harmonic of: ν·m replaces ν when
    the harmonics of ν that are not multiples of m add little: a nested F test below FUNDAMENTAL_F,
    or less than SUBHARMONIC_SHARE of what the harmonics of ν·m explain (scene structure, which any
    extra sinusoids partly fit, does not make a sub-harmonic). Returns (ν, the tests, the reason
    when the profile cannot tell ν from ν·m)."""
    steps = []
    null = data.null_rss()
    changed = True
    while changed:
        changed = False
        for m in (2, 3, 5):
            k_sub = k_count // m
            if k_sub < 1 or m * nu > HARMONIC_NU_MAX:
                continue
            rss_sub = total_frame_rss(data, m * nu, k_sub)
            extra = data.frames * 2 * (k_count - k_sub)
            sigma2 = rss / dof
            f_stat = ((rss_sub - rss) / extra) / sigma2
            share = (rss_sub - rss) / max(null - rss_sub, 1e-300)
            steps.append({"from_nu": nu, "m": m, "f": float(f_stat), "share": float(share)})
            if f_stat >= FUNDAMENTAL_F_AMBIGUOUS and share < SUBHARMONIC_SHARE:
                # ν's own harmonics are far above the noise, yet small beside those of ν·m: either
                # could be the bands (a clipped wave whose dark rows carry little weight)
                return nu, steps, (f"the bands repeat every {1 / nu:.1f} or every {1 / (m * nu):.1f} rows: "
                                   f"the profile cannot tell which (F {f_stat:.0f}, share {share:.2f})")
            if f_stat < FUNDAMENTAL_F or share < SUBHARMONIC_SHARE:
                nu, k_count = m * nu, harmonics_at(m * nu, k_count)
                rss = total_frame_rss(data, nu, k_count)
                changed = True
                break
    return nu, steps, None


def segment_chi2(data: LogProfiles, nu: float, k_count: int) -> float:
    """χ² per degree of freedom of ν fitted in separate segments of rows (4, or 2 when fewer than
    ~2 periods would fit a quarter) about their weighted mean; nan when the segments are too short."""
    used = np.flatnonzero(data.sw > 0)
    span = data.span
    pieces = 4 if nu * span / 4 >= 2.0 else 2
    if nu * span / pieces < 2.0 or len(used) < pieces * MIN_ROWS:
        return float("nan")
    values, variances = [], []
    for rows in np.array_split(used, pieces):
        part = data.rows(np.arange(rows[0], rows[-1] + 1))
        part_span = part.span
        nu_p, rss_p = refine_frames(part, nu, k_count, 0.3 / part_span, 0.5 * nu)
        dof = max(1, part.frames * part.rows_used - part.nuisance_dof() - part.frames * 2 * k_count - 1)
        h = 0.01 / (part_span * k_count)
        curv = (total_frame_rss(part, nu_p + h, k_count) - 2 * rss_p + total_frame_rss(part, nu_p - h, k_count)) / h ** 2
        if not curv > 0:
            return float("nan")
        values.append(nu_p)
        variances.append(2.0 * rss_p / dof / curv)
    values, weights = np.array(values), 1.0 / np.array(variances)
    mean = float(np.sum(weights * values) / np.sum(weights))
    return float(np.sum(weights * (values - mean) ** 2) / (len(values) - 1))


def edge_width_rows(data: LogProfiles, nu: float, k_count: int, sigma2: float) -> float:
    """Mean width (rows) of the bands' edges: 2 × rows in the middle half of the contrast per edge
    (a ramp w rows wide puts w/2 rows there). Infinite (edges resolved) when the contrast is below
    EDGE_MIN_CONTRAST noise σ (then noise, not sampling, limits the edges) or the wave has no edges."""
    used = data.sw > 0
    model = frame_fit(data, nu, k_count)[:, used]
    values = (data.yp[:, used] / data.sw[used])
    noise = math.sqrt(max(sigma2, 0.0)) / float(np.sqrt(np.mean(data.w[used])))
    cycles = abs(nu) * data.span
    widths = []
    for m, y in zip(model, values):
        lo, hi = np.percentile(m, [5, 95])
        contrast = hi - lo
        if not contrast > EDGE_MIN_CONTRAST * noise or cycles < 1:
            return float("inf")
        middle = np.count_nonzero((y > lo + 0.25 * contrast) & (y < hi - 0.25 * contrast))
        widths.append(2.0 * middle / (2.0 * cycles))
    return float(np.mean(widths)) if widths else float("inf")


def _periodogram_seeds(data: LogProfiles, nu_floor: float, nu_hi: float) -> Optional[tuple[list, float]]:
    """(ν to start from, the largest peak over the median) from the periodogram in [nu_floor,
    nu_hi]: its six highest peaks, and the sub-harmonics 1/2..1/6 of the three highest; None when
    the profiles have no contrast there."""
    freqs, power = periodogram(data)
    band = (freqs >= nu_floor) & (freqs <= nu_hi)
    if not np.any(band) or not np.any(power[band] > 0):
        return None
    index = np.flatnonzero(band)
    p = power[index]
    inner = index[1:-1][(p[1:-1] >= p[:-2]) & (p[1:-1] >= p[2:])]
    if not len(inner):
        inner = index[[int(np.argmax(p))]]
    peaks = sorted(inner, key=lambda i: -power[i])[:6]
    floor = float(np.median(power[freqs >= nu_floor]))
    ratio = float(power[peaks[0]] / max(floor, 1e-300))
    log_power = np.log(np.maximum(power, 1e-300))
    seeds = []
    for j, i in enumerate(peaks):
        nu_p = parabolic_peak(freqs, log_power, i)
        seeds.append(nu_p)
        if j < 3:
            seeds += [nu_p / m for m in range(2, 7) if nu_p / m >= nu_floor]
    return seeds, ratio


def _best_candidate(data: LogProfiles, seeds: list, kmax: int, nu_floor: float) -> tuple[tuple, list]:
    """((ν, RSS, harmonics) of the best candidate by BIC, all candidates): each seed refined with
    the harmonics that fit below HARMONIC_NU_MAX; the fit against the amplitudes it spends."""
    span = data.span
    n_eff = data.frames * data.rows_used
    candidates: list = []  # (ν, RSS, harmonics)
    for seed in sorted(seeds):
        if any(abs(seed - c[0]) < 0.1 / span for c in candidates):
            continue
        k_c = harmonics_at(seed, kmax)
        nu_c, rss_c = refine_frames(data, seed, k_c, 0.5 / span, nu_floor * 0.5)
        candidates.append((nu_c, rss_c, k_c))
    sigma2_ref = min(c[1] / _dof(data, c[2]) for c in candidates)
    best = min(candidates, key=lambda c: c[1] / sigma2_ref + math.log(max(n_eff, 2)) * data.frames * 2 * c[2])
    return best, candidates


def _curvature_std(data: LogProfiles, nu: float, rss: float, sigma2: float, k_count: int) -> float:
    """σ of ν from the RSS's curvature (a central second difference), scaled by the residual variance."""
    h = 0.01 / (data.span * k_count)
    curvature = (total_frame_rss(data, nu + h, k_count) - 2.0 * rss + total_frame_rss(data, nu - h, k_count)) / h ** 2
    return math.sqrt(2.0 * sigma2 / curvature) if curvature > 0 else float("inf")


def _frame_spread(data: LogProfiles, nu: float, k_count: int) -> tuple[np.ndarray, float]:
    """(each frame's own ν, the σ of their mean): per-frame minimisers near ν, refined by a parabola
    through the three nearest grid points; σ from their MAD (two frames: half their difference)."""
    step = 0.01 / data.span
    grid = nu + np.arange(-30, 31) * step
    per_frame = np.array([frame_rss(data, g, k_count) for g in grid])  # (grid, frames)
    per_frame_nu = np.full(data.frames, np.nan)
    for j, column in enumerate(per_frame.T):
        i = int(np.argmin(column))
        if 0 < i < len(grid) - 1:  # a minimum on the window's edge is no estimate
            a, b, c = column[i - 1:i + 2]
            denom = a - 2 * b + c
            per_frame_nu[j] = grid[i] + (0.5 * (a - c) / denom * step if denom > 0 else 0.0)
    finite = per_frame_nu[np.isfinite(per_frame_nu)]
    std_spread = float("nan")
    if len(finite) >= 3:
        mad = np.median(np.abs(finite - np.median(finite)))
        std_spread = float(1.4826 * mad / math.sqrt(len(finite))) if mad > 0 else float("nan")
    elif len(finite) == 2:
        std_spread = float(abs(finite[1] - finite[0]) / 2.0)
    return per_frame_nu, std_spread


def _harmonic_lock(data: LogProfiles, nu: float, rss: float, sigma2: float, delta_chi2: float, k_count: int,
                   kmax: int) -> Optional[str]:
    """The reason when the bands at ν look like a harmonic of bands with fewer periods than the
    spectrum searches: ν/m with m times the harmonics explains much more (a true fundamental carries
    more than scene residue fitted by the extra terms); None otherwise."""
    span = data.span
    cycles = nu * span
    tried = sorted({m for m in (2, 3, *np.unique(np.ceil(cycles / np.array([1.9, 1.3, 0.9, 0.6, 0.4])).astype(int)))
                    if m >= 2 and 0.3 <= cycles / m < SPECTRUM_MIN_CYCLES})
    for m in tried:
        k_sub = min(m * k_count, harmonics_at(nu / m, m * kmax), 2 * kmax)
        if k_sub <= k_count:
            continue
        sub = minimize_scalar(lambda x, k_sub=k_sub: total_frame_rss(data, x, k_sub),
                              bounds=(nu / m - 0.3 / span, nu / m + 0.3 / span), method="bounded")
        gain = (rss - sub.fun) / sigma2
        if gain > max(MIN_DELTA_CHI2 + 4 * data.frames * 2 * (k_sub - k_count), 0.5 * delta_chi2):
            return (f"the bands at {nu * span:.2f} periods per frame look like a harmonic of bands with "
                    f"{sub.x * span:.2f} periods per frame, too few for the spectrum")
    return None


def _refusal(data: LogProfiles, nu: float, ratio: float, delta_chi2: float, k_count: int,
             amplitude_spread: float) -> Optional[str]:
    """Why a fitted ν is not accepted as bands (None when it is): too few periods seen, amplitudes
    that vary between frames, or too little evidence."""
    # periods seen, not spanned: rows left out (unlit, overlays) between two stretches of bands
    # let waves of many periods join them
    seen = nu * min(data.span, float(data.rows_used))
    penalty = math.log(max(data.frames * data.rows_used, 2)) * data.frames * 2 * k_count
    if seen < SQUARE_MIN_CYCLES:
        return (f"{seen:.2f} periods in the rows used: too few for the spectrum alone (needs "
                f"{SQUARE_MIN_CYCLES:g} to tell a band period from a harmonic of a slower light)")
    if amplitude_spread > MAX_AMPLITUDE_SPREAD:
        return (f"the bands' amplitude varies by {amplitude_spread:.0%} between frames: not the same periodic "
                "light in every frame (a harmonic of a slower light?)")
    if ratio < MIN_PEAK_RATIO or delta_chi2 < MIN_DELTA_CHI2 + penalty:
        return (f"no flicker bands found (spectral peak {ratio:.1f}x the median, delta chi2 {delta_chi2:.0f} for "
                f"{data.frames * 2 * k_count} amplitudes)")
    return None


def spectrum_estimate(data: LogProfiles, nu_hi: float, kmax: int) -> dict:
    """ν in (SPECTRUM_MIN_CYCLES / rows, nu_hi] with each frame its own phase, at most kmax
    harmonics: a dict with method, ok, and nu, its σ (std_fit_nu, std_spread_nu) and the tests'
    numbers, or the reason it is not ok."""
    rows = data.yp.shape[1]
    span = data.span
    nu_floor = SPECTRUM_MIN_CYCLES / span
    out: dict = {"method": "spectrum", "ok": False}
    if nu_hi <= nu_floor:
        out["reason"] = f"at most {nu_hi * span:.2f} periods fit in the {rows} rows used"
        return out
    seeded = _periodogram_seeds(data, nu_floor, nu_hi)
    if seeded is None:
        out["reason"] = "no band contrast (the frames' row profiles do not vary)"
        return out
    seeds, ratio = seeded
    (nu, rss, k_common), candidates = _best_candidate(data, seeds, kmax, nu_floor)
    # the best candidate may be a sub-harmonic (its extra terms fit noise): climb to the fundamental
    nu_f, steps, ambiguous = fundamental(data, nu, k_common, rss, _dof(data, k_common))
    if ambiguous:
        out.update(nu=nu_f, reason=ambiguous, fundamental_tests=steps)
        return out
    k_count = harmonics_at(nu_f, kmax)
    nu, rss = refine_frames(data, nu_f, k_count, 0.1 / span, nu_floor * 0.5)
    sigma2 = rss / _dof(data, k_count)
    std_fit = _curvature_std(data, nu, rss, sigma2, k_count)
    per_frame_nu, std_spread = _frame_spread(data, nu, k_count)
    # consistency of row segments: ν from each segment of rows against their own σ (a waveform that
    # changes along the frame, vignetting with clipping, makes the white-noise σ too small)
    chi2_segments = segment_chi2(data, nu, k_count)
    if chi2_segments > 1.0 and math.isfinite(std_fit):
        std_fit *= math.sqrt(chi2_segments)
    # edges sharper than a row are sampled, not measured: their quantisation does not average out
    # within a frame (formulation §12), only over frames with different flicker phases
    edge_width = edge_width_rows(data, nu, k_count, sigma2)
    std_quantisation = nu * EDGE_QUANTISATION_ROWS * max(0.0, 1.0 - edge_width) / span / math.sqrt(data.frames)
    if math.isfinite(std_fit):
        std_fit = math.hypot(std_fit, std_quantisation)
    delta_chi2 = (data.null_rss() - rss) / sigma2
    lock = _harmonic_lock(data, nu, rss, sigma2, delta_chi2, k_count, kmax)
    if lock is not None:
        out.update(nu=nu, harmonics=k_count, delta_chi2=float(delta_chi2), reason=lock)
        return out
    out.update(ok=True, nu=nu, std_fit_nu=std_fit, std_spread_nu=std_spread, per_frame_nu=per_frame_nu,
               spread_label="frame", delta_chi2=float(delta_chi2), peak_ratio=ratio, harmonics=k_count,
               rss=rss, sigma2=sigma2, candidates_nu=[c[0] for c in candidates], fundamental_tests=steps,
               segment_chi2=chi2_segments, edge_width_rows=edge_width,
               std_quantisation_nu=std_quantisation)
    # the same light in every frame: the bands' fundamental amplitude may not vary much between frames
    # (a lock on a harmonic of a slower light sees an edge in some frames and none in others)
    amplitude_spread = float("nan")
    if data.frames >= 3:
        free = frame_amplitudes(data, nu)
        amplitude = np.hypot(free[0], free[1])
        amplitude_spread = float(np.std(amplitude) / max(np.mean(amplitude), 1e-300))
        out["amplitude_spread"] = amplitude_spread
    refusal = _refusal(data, nu, ratio, delta_chi2, k_count, amplitude_spread)
    if refusal is not None:
        out.update(ok=False, reason=refusal)
    return out
