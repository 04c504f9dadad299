"""Line delay from the bands of a flickering light (the LED method of Geyer et al. [14] in Oth et al. 2013, §2 and §5).

A light whose intensity repeats at ``frequency_hz`` (f) multiplies row v of frame i by
g(t_i + v d) (docs/conventions.md), so a rolling-shutter image shows horizontal bands of period
P = 1 / (f |d|) rows: d = ν / f. The model, the two estimators and the checks are in
docs/formulation.md §12; in short:

  profiles:    column strips (rscalib.flicker.profiles), the region with bands chosen by
               rscalib.flicker.region, clipped strips as data, log profile clamped at black.
  spectrum:    each frame its own phase; candidates from periodogram peaks and sub-harmonics,
               refined with up to 12 harmonics (square-ish waves), the fundamental chosen by
               nested tests; |d| only; needs >= 3 periods per frame.
  phase-drift: one phase through the timestamps; both signs of ν; every local minimum of the
               profile is a candidate (explicit cycle / alias resolution), the best must win by
               Δχ² >= 25; each frame's own band phase must match the drift.
  checks:      the estimators agree within 3σ, the residual has no unexplained periodic peak,
               σ <= 25 % of |d|; else ``determined = False`` with ``reason`` (exit 3).

Uncertainty: the fit's (curvature or Jacobian, scaled by the residual variance, inflated for
residual power near the band harmonics, for residual common to all frames, and by the χ² of row
segments) and the spread over frames or frame blocks; ``line_delay_std_s`` is the larger.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from ..errors import InputError
from .profiles import MIN_ROWS, RowProfiles, read_row_profiles
from .region import choose_region

__all__ = ["FlickerResult", "estimate_line_delay_flicker"]

SPECTRUM_MIN_CYCLES = 2.0        # below this many periods per frame the bands cannot be told from scene shading
MAX_AMPLITUDE_SPREAD = 0.5       # spectrum: relative spread of the frames' band amplitudes
SQUARE_MIN_CYCLES = 3.0          # the spectrum alone needs this many: fewer periods of a many-harmonic
                                 # waveform can fit a step or two of a slower light (a harmonic lock)
MIN_DELTA_CHI2 = 100.0           # plus 4 per fitted amplitude: noise alone gives ~1 per amplitude + ~10 for the search
MIN_PEAK_RATIO = 10.0            # periodogram peak over its median in the search band
AMBIGUITY_DELTA_CHI2 = 25.0      # a second minimum this close: d is aliased
MAX_RELATIVE_STD = 0.25
SAME_PHASE_RESULTANT = 0.95      # |mean exp(2πi f t_i)| above this: phases (almost) all equal
MOVING_BLOCK = 4                 # frames per block when the scene may move (detrend "frames")
SPREAD_DISAGREEMENT = 2.0        # fit vs spread uncertainty ratio that earns a warning
KMAX = 12                        # harmonics of the band waveform (square-ish: duty cycle, clipped edges)
HARMONIC_NU_MAX = 0.45           # ... all below this many cycles per row
FUNDAMENTAL_F_AMBIGUOUS = 100.0  # ... but at or above this F with a small share: refuse (either may be the bands)
FUNDAMENTAL_F = 4.0              # nested F below this: a sub-harmonic's extra terms explain nothing
SUBHARMONIC_SHARE = 0.1          # ... or less than this share of what the fundamental's harmonics explain
PHASE_TOLERANCE = 0.01           # flicker phases (cycles) closer than this count as one
PHASE_RMS_MAX = 0.05             # phase drift: frames' own band phases vs the timestamps' prediction (cycles rms)
RESIDUAL_PEAK_MAX = 0.25         # residual periodogram peak off the fitted harmonics over the bands' peak
EDGE_QUANTISATION_ROWS = math.sqrt(2.0 / 12.0)  # σ of a period's span when both end edges are sampled to ±0.5 row
EDGE_MIN_CONTRAST = 10.0         # band contrast in noise σ needed to see how sharp the edges are
AGREEMENT_SIGMAS = 3.0           # spectrum and phase drift must agree within this many σ
BLACK_CLAMP = 0.01                # log profiles are clamped here (fraction of the brightest row)
COARSE_FRAMES = 120              # consecutive frames used for the phase-drift grid


# --------------------------------------------------------------------------------------------------
# Model pieces


def _blocks(frames: int, block: Optional[int]) -> list:
    """Consecutive frame indices in blocks of `block` (all in one if None); no block of one frame."""
    size = frames if not block else int(block)
    groups = [np.arange(i, min(i + size, frames)) for i in range(0, frames, size)]
    if len(groups) > 1 and len(groups[-1]) < 2:
        groups[-2] = np.concatenate(groups[-2:])
        groups.pop()
    return groups


class _Data:
    """Log row profiles, weights and the nuisance projection (see the module docstring)."""

    def __init__(self, y: np.ndarray, sw: np.ndarray, v: np.ndarray, phase0: Optional[np.ndarray],
                 detrend: str, poly_degree: int, block: Optional[int] = None) -> None:
        self.y, self.sw, self.v, self.phase0 = y, sw, v, phase0
        self.w = sw ** 2
        self.detrend, self.poly_degree, self.block = detrend, poly_degree, block
        # frames mode: the scene is constant within blocks of consecutive frames (all frames when
        # block is None); a short block follows a moving camera
        self.groups = _blocks(y.shape[0], block)
        if detrend == "smooth":
            x = 2.0 * (v - v.min()) / max(1.0, np.ptp(v)) - 1.0
            basis = np.polynomial.legendre.legvander(x, poly_degree) * sw[:, None]
            u, s, _ = np.linalg.svd(basis, full_matrices=False)
            self.frame_basis = u[:, s > 1e-10 * s[0]]
        else:
            self.frame_basis = (sw / np.linalg.norm(sw))[:, None]
        self.yp = self.project(y)
        self.yy = np.sum(self.yp ** 2, axis=1)

    @property
    def frames(self) -> int:
        return self.y.shape[0]

    @property
    def rows_used(self) -> int:
        return int(np.count_nonzero(self.w))

    def subset(self, index) -> _Data:
        return _Data(self.y[index], self.sw, self.v, None if self.phase0 is None else self.phase0[index],
                     self.detrend, self.poly_degree, self.block)

    @property
    def label(self) -> str:
        return f"frame blocks of {self.block}" if self.detrend == "frames" and self.block else self.detrend

    def project(self, x: np.ndarray) -> np.ndarray:
        """sqrt(w) · P(x) for x (..., frames, rows): the weighted residual after the nuisances."""
        if self.detrend == "frames":
            if len(self.groups) == 1:
                z = x - x.mean(axis=-2, keepdims=True)
            else:
                z = np.empty_like(x)
                for g in self.groups:
                    z[..., g, :] = x[..., g, :] - x[..., g, :].mean(axis=-2, keepdims=True)
            z = z - (z @ self.w)[..., None] / self.w.sum()
            return z * self.sw
        xw = x * self.sw
        return xw - (xw @ self.frame_basis) @ self.frame_basis.T

    def nuisance_dof(self) -> int:
        if self.detrend == "frames":
            return self.rows_used * len(self.groups) + self.frames - 1
        return self.frames * self.frame_basis.shape[1]

    def null_rss(self) -> float:
        return float(np.sum(self.yp ** 2))


def _row_design(v: np.ndarray, nu: float, k_count: int, derivative: bool = False) -> np.ndarray:
    """(2K, rows) cos/sin of k·2πνv; with derivative, d/dν of them."""
    out = []
    for k in range(1, k_count + 1):
        arg = 2.0 * np.pi * k * nu * v
        if derivative:
            out += [-np.sin(arg) * 2.0 * np.pi * k * v, np.cos(arg) * 2.0 * np.pi * k * v]
        else:
            out += [np.cos(arg), np.sin(arg)]
    return np.array(out)


def _lstsq_rss(columns: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """RSS and coefficients of target ≈ columnsᵀ c (columns (p, N))."""
    # normal equations: the columns are sinusoids, well conditioned, and p is small
    gram = columns @ columns.T
    rhs = columns @ target
    coef = np.linalg.pinv(gram, rcond=1e-12, hermitian=True) @ rhs
    return float(target @ target - rhs @ coef), coef


# ---- spectrum: every frame its own phase -------------------------------------------------------


def _frame_design(data: _Data, nu: float, k_count: int) -> np.ndarray:
    """(rows, 2K) weighted cos/sin of k·2πνv with each frame's own nuisance projected out."""
    design = _row_design(data.v, nu, k_count).T * data.sw[:, None]
    return design - data.frame_basis @ (data.frame_basis.T @ design)


def _frame_rss(data: _Data, nu: float, k_count: int) -> np.ndarray:
    """Per-frame RSS of the best K harmonics at ν (each frame its own amplitudes and phases)."""
    design = _frame_design(data, nu, k_count)
    gram = design.T @ design
    rhs = data.yp @ design                                   # (frames, 2K)
    coef = rhs @ np.linalg.pinv(gram, rcond=1e-10, hermitian=True)
    return data.yy - np.sum(rhs * coef, axis=1)


def _frame_fit(data: _Data, nu: float, k_count: int) -> np.ndarray:
    """Fitted, projected model per frame (frames, rows), unweighted (for plots)."""
    design = _frame_design(data, nu, k_count)
    coef, *_ = np.linalg.lstsq(design, data.yp.T, rcond=None)
    fit = (design @ coef).T
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(data.sw > 0, fit / data.sw, np.nan)


def _periodogram(data: _Data) -> tuple[np.ndarray, np.ndarray]:
    rows = data.yp.shape[1]
    nfft = 1 << int(math.ceil(math.log2(16 * rows)))
    spectrum = np.fft.rfft(data.yp * np.hanning(rows), n=nfft, axis=1)
    return np.arange(spectrum.shape[1]) / nfft, np.sum(np.abs(spectrum) ** 2, axis=0)


def _parabolic_peak(x: np.ndarray, y: np.ndarray, i: int) -> float:
    if i <= 0 or i >= len(y) - 1:
        return float(x[i])
    a, b, c = y[i - 1], y[i], y[i + 1]
    denom = a - 2.0 * b + c
    shift = 0.5 * (a - c) / denom if denom != 0 else 0.0
    return float(x[i] + np.clip(shift, -1.0, 1.0) * (x[1] - x[0]))


def _harmonics_at(nu: float, kmax: int) -> int:
    """Harmonics of ν below HARMONIC_NU_MAX cycles/row, at most kmax."""
    return max(1, min(int(kmax), int(math.floor(HARMONIC_NU_MAX / max(abs(nu), 1e-12)))))


def _refine_frames(data: _Data, nu0: float, k_count: int, half_width: float, lo: float) -> tuple[float, float]:
    """(ν, RSS) minimising the per-frame-phase RSS near nu0 (grid, then bounded search)."""
    span = float(np.ptp(data.v)) + 1.0
    step = 0.02 / span
    grid = nu0 + np.arange(-half_width, half_width + 0.5 * step, step)
    grid = grid[grid >= lo]
    if len(grid) < 3:
        return nu0, float(np.sum(_frame_rss(data, nu0, k_count)))
    total = np.array([float(np.sum(_frame_rss(data, g, k_count))) for g in grid])
    b = int(np.argmin(total))
    a, c = grid[max(b - 1, 0)], grid[min(b + 1, len(grid) - 1)]
    res = minimize_scalar(lambda x: float(np.sum(_frame_rss(data, x, k_count))), bounds=(a, c), method="bounded",
                          options={"xatol": 1e-7 / span})
    return (float(res.x), float(res.fun)) if res.fun <= total[b] else (float(grid[b]), float(total[b]))


def _fundamental(data: _Data, nu: float, k_count: int, rss: float, dof: int) -> tuple[float, list, Optional[str]]:
    """Climb from a candidate to the fundamental it may be a sub-harmonic of: ν·m replaces ν when
    the harmonics of ν that are not multiples of m add little: a nested F test below FUNDAMENTAL_F,
    or less than SUBHARMONIC_SHARE of what the harmonics of ν·m explain (scene structure, which any
    extra sinusoids partly fit, does not make a sub-harmonic)."""
    steps = []
    null = data.null_rss()
    changed = True
    while changed:
        changed = False
        for m in (2, 3, 5):
            k_sub = k_count // m
            if k_sub < 1 or m * nu > HARMONIC_NU_MAX:
                continue
            rss_sub = float(np.sum(_frame_rss(data, m * nu, k_sub)))
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
                nu, k_count = m * nu, _harmonics_at(m * nu, k_count)
                rss = float(np.sum(_frame_rss(data, nu, k_count)))
                changed = True
                break
    return nu, steps, None


def _segment_chi2(data: _Data, nu: float, k_count: int) -> float:
    """χ² per degree of freedom of ν fitted in separate segments of rows (4, or 2 when fewer than
    ~2 periods would fit a quarter) about their weighted mean; nan when the segments are too short."""
    used = np.flatnonzero(data.sw > 0)
    span = float(np.ptp(data.v)) + 1.0
    pieces = 4 if nu * span / 4 >= 2.0 else 2
    if nu * span / pieces < 2.0 or len(used) < pieces * MIN_ROWS:
        return float("nan")
    values, variances = [], []
    for rows in np.array_split(used, pieces):
        index = np.arange(rows[0], rows[-1] + 1)
        part = _Data(data.y[:, index], data.sw[index], data.v[index], data.phase0, data.detrend, data.poly_degree,
                     data.block)
        part_span = float(np.ptp(part.v)) + 1.0
        nu_p, rss_p = _refine_frames(part, nu, k_count, 0.3 / part_span, 0.5 * nu)
        dof = max(1, part.frames * part.rows_used - part.nuisance_dof() - part.frames * 2 * k_count - 1)
        h = 0.01 / (part_span * k_count)
        curv = (float(np.sum(_frame_rss(part, nu_p + h, k_count))) - 2 * rss_p
                + float(np.sum(_frame_rss(part, nu_p - h, k_count)))) / h ** 2
        if not curv > 0:
            return float("nan")
        values.append(nu_p)
        variances.append(2.0 * rss_p / dof / curv)
    values, weights = np.array(values), 1.0 / np.array(variances)
    mean = float(np.sum(weights * values) / np.sum(weights))
    return float(np.sum(weights * (values - mean) ** 2) / (len(values) - 1))


def _edge_width_rows(data: _Data, nu: float, k_count: int, sigma2: float) -> float:
    """Mean width (rows) of the bands' edges: 2 × rows in the middle half of the contrast per edge
    (a ramp w rows wide puts w/2 rows there). Infinite (edges resolved) when the contrast is below
    EDGE_MIN_CONTRAST noise σ (then noise, not sampling, limits the edges) or the wave has no edges."""
    used = data.sw > 0
    model = _frame_fit(data, nu, k_count)[:, used]
    values = (data.yp[:, used] / data.sw[used])
    noise = math.sqrt(max(sigma2, 0.0)) / float(np.sqrt(np.mean(data.w[used])))
    cycles = abs(nu) * (float(np.ptp(data.v)) + 1.0)
    widths = []
    for m, y in zip(model, values):
        lo, hi = np.percentile(m, [5, 95])
        contrast = hi - lo
        if not contrast > EDGE_MIN_CONTRAST * noise or cycles < 1:
            return float("inf")
        middle = np.count_nonzero((y > lo + 0.25 * contrast) & (y < hi - 0.25 * contrast))
        widths.append(2.0 * middle / (2.0 * cycles))
    return float(np.mean(widths)) if widths else float("inf")


def _spectrum_estimate(data: _Data, nu_hi: float, kmax: int, min_cycles: float) -> dict:
    """ν with each frame its own phase: periodogram peaks and their sub-harmonics as candidates,
    each refined by least squares with the harmonics of a square-ish wave, the best kept, and then
    the fundamental chosen over its sub-harmonics (a harmonic of the bands never wins: it misses the
    fundamental; a sub-harmonic only fits noise with its extra terms)."""
    rows = data.yp.shape[1]
    span = float(np.ptp(data.v)) + 1.0
    nu_floor = min_cycles / span
    out: dict = {"method": "spectrum", "ok": False}
    if nu_hi <= nu_floor:
        out["reason"] = f"at most {nu_hi * span:.2f} periods fit in the {rows} rows used"
        return out
    freqs, power = _periodogram(data)
    band = (freqs >= nu_floor) & (freqs <= nu_hi)
    if not np.any(band) or not np.any(power[band] > 0):
        out["reason"] = "no band contrast (the frames' row profiles do not vary)"
        return out
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
        nu_p = _parabolic_peak(freqs, log_power, i)
        seeds.append(nu_p)
        if j < 3:
            seeds += [nu_p / m for m in range(2, 7) if nu_p / m >= nu_floor]
    n_eff = data.frames * data.rows_used
    candidates: list = []  # (ν, RSS, harmonics)
    for seed in sorted(seeds):
        if any(abs(seed - c[0]) < 0.1 / span for c in candidates):
            continue
        k_c = _harmonics_at(seed, kmax)
        nu_c, rss_c = _refine_frames(data, seed, k_c, 0.5 / span, nu_floor * 0.5)
        candidates.append((nu_c, rss_c, k_c))
    sigma2_ref = min(c[1] / max(1, n_eff - data.nuisance_dof() - data.frames * 2 * c[2] - 1) for c in candidates)
    # BIC: the fit against the amplitudes it spends
    nu, rss, k_common = min(candidates, key=lambda c: c[1] / sigma2_ref
                            + math.log(max(n_eff, 2)) * data.frames * 2 * c[2])
    dof = max(1, n_eff - data.nuisance_dof() - data.frames * 2 * k_common - 1)
    # the best candidate may be a sub-harmonic (its extra terms fit noise): climb to the fundamental
    nu_f, steps, ambiguous = _fundamental(data, nu, k_common, rss, dof)
    if ambiguous:
        out.update(nu=nu_f, reason=ambiguous, fundamental_tests=steps)
        return out
    k_count = _harmonics_at(nu_f, kmax)
    nu, rss = _refine_frames(data, nu_f, k_count, 0.1 / span, nu_floor * 0.5)
    dof = max(1, n_eff - data.nuisance_dof() - data.frames * 2 * k_count - 1)
    sigma2 = rss / dof

    def total(x: float) -> float:
        return float(np.sum(_frame_rss(data, x, k_count)))

    h = 0.01 / (span * k_count)
    curvature = (total(nu + h) - 2.0 * rss + total(nu - h)) / h ** 2
    std_fit = math.sqrt(2.0 * sigma2 / curvature) if curvature > 0 else float("inf")
    # per-frame minimisers near ν, refined by a parabola through the three nearest grid points
    step = 0.01 / span
    grid = nu + np.arange(-30, 31) * step
    per_frame = np.array([_frame_rss(data, g, k_count) for g in grid])  # (grid, frames)
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
    # consistency of row segments: ν from each segment of rows against their own σ (a waveform that
    # changes along the frame, vignetting with clipping, makes the white-noise σ too small)
    segment_chi2 = _segment_chi2(data, nu, k_count)
    if segment_chi2 > 1.0 and math.isfinite(std_fit):
        std_fit *= math.sqrt(segment_chi2)
    # edges sharper than a row are sampled, not measured: their quantisation does not average out
    # within a frame (formulation §12), only over frames with different flicker phases
    edge_width = _edge_width_rows(data, nu, k_count, sigma2)
    std_quantisation = nu * EDGE_QUANTISATION_ROWS * max(0.0, 1.0 - edge_width) / span / math.sqrt(data.frames)
    if math.isfinite(std_fit):
        std_fit = math.hypot(std_fit, std_quantisation)
    delta_chi2 = (data.null_rss() - rss) / sigma2
    penalty = math.log(max(n_eff, 2)) * data.frames * 2 * k_count
    # Are these bands a harmonic of bands with fewer periods than the spectrum searches? Then ν/m
    # with m times the harmonics explains much more (a true fundamental carries more than scene
    # residue fitted by the extra terms).
    cycles = nu * span
    tried = sorted({m for m in (2, 3, *np.unique(np.ceil(cycles / np.array([1.9, 1.3, 0.9, 0.6, 0.4])).astype(int)))
                    if m >= 2 and 0.3 <= cycles / m < min_cycles})
    for m in tried:
        k_sub = min(m * k_count, _harmonics_at(nu / m, m * kmax), 2 * kmax)
        if k_sub <= k_count:
            continue
        sub = minimize_scalar(lambda x, k_sub=k_sub: float(np.sum(_frame_rss(data, x, k_sub))),
                              bounds=(nu / m - 0.3 / span, nu / m + 0.3 / span), method="bounded")
        gain = (rss - sub.fun) / sigma2
        if gain > max(MIN_DELTA_CHI2 + 4 * data.frames * 2 * (k_sub - k_count), 0.5 * delta_chi2):
            out.update(nu=nu, harmonics=k_count, delta_chi2=float(delta_chi2), reason=(
                f"the bands at {nu * span:.2f} periods per frame look like a harmonic of bands with "
                f"{sub.x * span:.2f} periods per frame, too few for the spectrum"))
            return out
    out.update(ok=True, nu=nu, std_fit_nu=std_fit, std_spread_nu=std_spread, per_frame_nu=per_frame_nu,
               spread_label="frame", delta_chi2=float(delta_chi2), peak_ratio=ratio, harmonics=k_count,
               rss=rss, sigma2=sigma2, candidates_nu=[c[0] for c in candidates], fundamental_tests=steps,
               segment_chi2=segment_chi2, edge_width_rows=edge_width,
               std_quantisation_nu=std_quantisation)
    # the same light in every frame: the bands' fundamental amplitude may not vary much between frames
    # (a lock on a harmonic of a slower light sees an edge in some frames and none in others)
    amplitude_spread = float("nan")
    if data.frames >= 3:
        design = _frame_design(data, nu, 1)
        free, *_ = np.linalg.lstsq(design, data.yp.T, rcond=None)
        amplitude = np.hypot(free[0], free[1])
        amplitude_spread = float(np.std(amplitude) / max(np.mean(amplitude), 1e-300))
        out["amplitude_spread"] = amplitude_spread
    # periods seen, not spanned: rows left out (unlit, overlays) between two stretches of bands
    # let waves of many periods join them
    seen = nu * min(span, float(data.rows_used))
    if seen < SQUARE_MIN_CYCLES:
        out.update(ok=False, reason=f"{seen:.2f} periods in the rows used: too few for the spectrum alone "
                                    f"(needs {SQUARE_MIN_CYCLES:g} to tell a band period from a harmonic of a "
                                    "slower light)")
    elif amplitude_spread > MAX_AMPLITUDE_SPREAD:
        out.update(ok=False, reason=f"the bands' amplitude varies by {amplitude_spread:.0%} between frames: not "
                                    "the same periodic light in every frame (a harmonic of a slower light?)")
    elif ratio < MIN_PEAK_RATIO or delta_chi2 < MIN_DELTA_CHI2 + penalty:
        out.update(ok=False, reason=f"no flicker bands found (spectral peak {ratio:.1f}x the median, "
                                    f"delta chi2 {delta_chi2:.0f} for {data.frames * 2 * k_count} amplitudes)")
    return out


# ---- phase drift: one phase shared through the timestamps ----------------------------------------


def _pd_model(data: _Data, nu: float, k_count: int, derivative: bool = False) -> np.ndarray:
    """(2K, frames, rows) cos/sin of k·2π(f t_i + ν v), or their d/dν."""
    base = np.exp(2j * np.pi * (data.phase0[:, None] + nu * data.v[None, :]))
    out = np.empty((2 * k_count,) + base.shape)
    power = base
    for k in range(1, k_count + 1):
        if k > 1:
            power = power * base  # e^{ikθ} by products: cheaper than k cos/sin calls
        if derivative:
            factor = 2.0 * np.pi * k * data.v[None, :]
            out[2 * k - 2], out[2 * k - 1] = -power.imag * factor, power.real * factor
        else:
            out[2 * k - 2], out[2 * k - 1] = power.real, power.imag
    return out


def _pd_profile_rss(data: _Data, nu: float, k_count: int) -> tuple[float, np.ndarray]:
    columns = data.project(_pd_model(data, nu, k_count)).reshape(2 * k_count, -1)
    return _lstsq_rss(columns, data.yp.ravel())


def _pd_refine(data: _Data, nu0: float, coef0: np.ndarray, k_count: int) -> dict:
    target = data.yp.ravel()

    def residual(p):
        model = np.tensordot(p[1:], _pd_model(data, p[0], k_count), axes=1)
        return target - data.project(model).ravel()

    def jacobian(p):
        jac = np.empty((target.size, len(p)))
        jac[:, 0] = -data.project(np.tensordot(p[1:], _pd_model(data, p[0], k_count, True), axes=1)).ravel()
        jac[:, 1:] = -data.project(_pd_model(data, p[0], k_count)).reshape(2 * k_count, -1).T
        return jac

    fit = least_squares(residual, np.concatenate([[nu0], coef0]), jac=jacobian, x_scale="jac", method="lm",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    rss = float(fit.fun @ fit.fun)
    dof = max(1, target.size - data.nuisance_dof() - len(fit.x))
    sigma2 = rss / dof
    cov = np.linalg.pinv(fit.jac.T @ fit.jac) * sigma2
    return {"nu": float(fit.x[0]), "coef": fit.x[1:], "rss": rss, "sigma2": sigma2,
            "std_fit_nu": float(math.sqrt(max(cov[0, 0], 0.0))), "converged": bool(fit.success)}


def _local_minima(values: np.ndarray) -> np.ndarray:
    inner = np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:])) + 1
    ends = [i for i in (0, len(values) - 1) if len(values) > 1 and values[i] == values.min()]
    return np.unique(np.concatenate([inner, np.array(ends, dtype=int)]))


def distinct_phases(phase0: np.ndarray, tolerance: float = PHASE_TOLERANCE) -> int:
    """How many different flicker phases (cycles, mod 1) the frames have."""
    x = np.sort(np.mod(phase0, 1.0))
    if len(x) == 0:
        return 0
    gaps = np.diff(np.concatenate([x, [x[0] + 1.0]]))
    return max(1, int(np.sum(gaps > tolerance)))


def _phase_drift_estimate(data: _Data, nu_lo: float, nu_hi: float, kmax: int, sign: int = 0) -> dict:
    """One phase for all frames through their timestamps, ν of either sign (sign > 0 / < 0 restricts).

    Every local minimum of a fundamental-only profile over the whole range is a candidate: with few
    distinct flicker phases Q among the frames, harmonic k' of another ν' reproduces harmonic k of
    the true one when k' ≡ ±k (mod Q) and k'ν' = ±kν (the whole-cycle alternatives of the drift
    between frames). Each candidate is refined with all harmonics on all frames, and the best must
    beat the second by AMBIGUITY_DELTA_CHI2, else the result is aliased."""
    out: dict = {"method": "phase-drift", "ok": False}
    span = float(np.ptp(data.v)) + 1.0
    q = distinct_phases(data.phase0)
    out["distinct_phases"] = q
    if q < 2:
        out["reason"] = ("every frame has the same flicker phase: no drift between frames (frame rate and "
                         "flicker commensurate)")
        return out
    k_count = _harmonics_at(nu_hi, kmax)
    step = 0.08 / span
    positive = np.arange(nu_lo, nu_hi + 0.5 * step, step)
    grid = np.concatenate([-positive[::-1] if sign <= 0 else [], positive if sign >= 0 else []])
    coarse = data.subset(np.arange(min(data.frames, COARSE_FRAMES))) if data.frames > COARSE_FRAMES else data
    rss1 = np.array([_pd_profile_rss(coarse, nu, 1)[0] for nu in grid])
    out["grid_nu"], out["grid_rss"] = grid, rss1
    minima = sorted(_local_minima(rss1), key=lambda i: rss1[i])[:6]
    candidates = []  # (ν, profile RSS with all harmonics)

    def profile(x: float, d: _Data = data) -> float:
        return _pd_profile_rss(d, x, k_count)[0]

    for i in minima:
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        res = minimize_scalar(profile, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 / span})
        if all(abs(res.x - c[0]) > 0.3 / span for c in candidates):
            candidates.append((float(res.x), float(res.fun)))
    candidates.sort(key=lambda c: c[1])
    _, coef0 = _pd_profile_rss(data, candidates[0][0], k_count)
    fit = _pd_refine(data, candidates[0][0], coef0, k_count)
    out["candidates_nu"] = [c[0] for c in candidates]
    second = candidates[1][1] if len(candidates) > 1 else np.inf
    out["ambiguity_delta_chi2"] = float((second - fit["rss"]) / fit["sigma2"]) if np.isfinite(second) else None
    delta_chi2 = (data.null_rss() - fit["rss"]) / fit["sigma2"]
    out.update(ok=True, nu=fit["nu"], std_fit_nu=fit["std_fit_nu"], coef=fit["coef"], harmonics=k_count,
               delta_chi2=float(delta_chi2), rss=fit["rss"], sigma2=fit["sigma2"], converged=fit["converged"])
    # the drift model against free per-frame phases at the same ν: timestamps and frequency must fit
    rss_free = float(np.sum(_frame_rss(data, fit["nu"], k_count)))
    extra = 2 * k_count * (data.frames - 1)
    dof_free = max(1, data.frames * data.rows_used - data.nuisance_dof() - 2 * k_count * data.frames)
    joint_f = ((fit["rss"] - rss_free) / extra) / (rss_free / dof_free) if extra > 0 and rss_free > 0 else 0.0
    out["joint_vs_free_f"] = float(joint_f)
    # each frame's own band phase (fundamental, free) against the phase the timestamps predict
    design = _frame_design(data, fit["nu"], 1)
    free, *_ = np.linalg.lstsq(design, data.yp.T, rcond=None)          # (2, frames)
    measured = free[0] - 1j * free[1]
    predicted = (fit["coef"][0] - 1j * fit["coef"][1]) * np.exp(2j * np.pi * data.phase0)
    weight = np.abs(measured)
    offsets = np.angle(measured / np.where(predicted == 0, 1.0, predicted)) / (2 * np.pi)
    phase_rms = float(np.sqrt(np.sum(weight * offsets ** 2) / max(weight.sum(), 1e-300)))
    out["phase_offsets_cycles"] = offsets
    out["phase_rms_cycles"] = phase_rms
    # spread over contiguous blocks of frames (contiguous: interleaving can give every block the
    # same flicker phase when the rates are commensurate)
    groups = min(6, data.frames // 3)
    subset_nu = []
    if groups >= 3:
        for block in np.array_split(np.arange(data.frames), groups):
            sub = data.subset(block)
            if distinct_phases(sub.phase0) < 2:
                continue
            res = minimize_scalar(profile, bounds=(fit["nu"] - 0.2 / span, fit["nu"] + 0.2 / span), args=(sub,),
                                  method="bounded", options={"xatol": 1e-5 / span})
            subset_nu.append(float(res.x))
    subset_nu = np.array(subset_nu)
    out["per_frame_nu"] = subset_nu
    out["spread_label"] = "frame block"
    out["std_spread_nu"] = float(np.std(subset_nu, ddof=1) / math.sqrt(len(subset_nu))) if len(subset_nu) >= 3 \
        else float("nan")
    if delta_chi2 < MIN_DELTA_CHI2 + 4 * 2 * k_count:
        out.update(ok=False, reason=f"no flicker found (the fit lowers chi2 by only {delta_chi2:.0f})")
    elif out["ambiguity_delta_chi2"] is not None and out["ambiguity_delta_chi2"] < AMBIGUITY_DELTA_CHI2:
        alias = candidates[1][0]
        out.update(ok=False, alias_nu=alias, reason=f"aliased: {fit['nu']:.6g} and {alias:.6g} cycles/row fit about "
                                                    f"equally well (delta chi2 {out['ambiguity_delta_chi2']:.1f})")
    elif phase_rms > PHASE_RMS_MAX:
        out.update(ok=False, reason="the band phases do not drift as the timestamps and the frequency predict "
                                    f"(each frame's own band phase is off by {phase_rms:.3f} cycles rms; joint fit "
                                    f"{joint_f:.1f}x worse per amplitude than free phases): inexact timestamps or "
                                    "frequency, or a moving scene")
    elif data.detrend == "smooth" and abs(fit["nu"]) * span < SPECTRUM_MIN_CYCLES:
        out.update(ok=False, reason=f"{abs(fit['nu']) * span:.2f} periods per frame and no phase drift between "
                                    "frames: bands cannot be told from scene structure")
    return out


def _std_of(e: dict, f: float) -> tuple[float, float, float]:
    """(reported, fit, spread) std of d: the larger of the two that exist."""
    fit = e.get("std_fit_nu", float("nan")) / f
    spread = e.get("std_spread_nu", float("nan")) / f
    known = [x for x in (fit, spread) if math.isfinite(x) and x > 0]
    return (max(known) if known else float("inf")), fit, spread


def _pd_fit_curves(data: _Data, nu: float, coef: np.ndarray, k_count: int) -> np.ndarray:
    model = data.project(np.tensordot(coef, _pd_model(data, nu, k_count), axes=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(data.sw > 0, model / data.sw, np.nan)


# --------------------------------------------------------------------------------------------------
# Result and entry point


def _residual_tests(data: _Data, model_yp: np.ndarray, nu: float) -> tuple[float, float, float]:
    """(peak ratio, its ν, noise inflation) from the residual periodogram (summed over frames).

    Peak ratio: the largest residual peak away from the fitted harmonics of ν, over the fitted
    model's largest peak: bands the fit does not explain (another period, a harmonic lock).
    Inflation: the residual power next to the fitted harmonics (weighted by the model's power
    there) over the residual's mean power: scene structure or compression noise near the band
    frequencies makes the white-noise σ of the fit too small by its square root (floored at 1); so
    does a residual common to all frames (the same scene structure), which does not average out."""
    span = float(np.ptp(data.v)) + 1.0
    rows = data.yp.shape[1]
    nfft = 1 << int(math.ceil(math.log2(16 * rows)))
    window = np.hanning(rows)
    spectra = np.fft.rfft((data.yp - model_yp) * window, n=nfft, axis=1)
    res = np.sum(np.abs(spectra) ** 2, axis=0)
    coherent = np.abs(np.sum(spectra, axis=0)) ** 2   # residual common to the frames (the same scene)
    mod = np.sum(np.abs(np.fft.rfft(model_yp * window, n=nfft, axis=1)) ** 2, axis=0)
    freqs = np.arange(len(res)) / nfft
    band = (freqs >= 2.0 / span) & (freqs <= HARMONIC_NU_MAX)
    if not np.any(band) or not mod[band].max() > 0:
        return 0.0, float("nan"), 1.0
    nearest = np.round(freqs / abs(nu))
    offset = np.abs(freqs - nearest * abs(nu))
    harmonic = (offset <= 1.5 / span) & (nearest >= 1)
    off = band & ~harmonic
    ratio, peak_nu = 0.0, float("nan")
    if np.any(off):
        i = np.flatnonzero(off)[int(np.argmax(res[off]))]
        ratio, peak_nu = float(res[i] / mod[band].max()), float(freqs[i])
    ring = (offset > 1.0 / span) & (offset <= 3.0 / span) & (nearest >= 1) & (freqs <= 0.5)
    weight = np.zeros_like(freqs)
    for k in np.unique(nearest[ring]).astype(int):
        near = np.abs(freqs - k * abs(nu)) <= 0.5 / span
        weight[ring & (nearest == k)] = float(mod[near].max()) * k * k if np.any(near) else 0.0
    level = float(np.mean(res[(freqs > 0) & (freqs <= 0.5)]))
    inflation = 1.0
    if weight.sum() > 0 and level > 0:
        near = max(float(np.sum(weight * res)), float(np.sum(weight * coherent))) / weight.sum()
        inflation = max(1.0, near / level)
    return ratio, peak_nu, inflation


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
                "vertical_blanking_s", "blanking_determined", "checks", "estimates", "region", "spread_label",
                "timestamps_source", "image_size", "roi"]
        out = {k: clean(getattr(self, k)) for k in keys}
        out["spread_line_delays_s"] = clean(self.spread_line_delays_s)
        return out


READOUTS = ("auto", "top-to-bottom", "bottom-to-top")


def estimate_line_delay_flicker(frames: Any, frequency_hz: float, timestamps_s: Optional[Sequence[float]] = None, *,
                                rows: Optional[int] = None, roi=None, max_frames: Optional[int] = None,
                                method: str = "auto", detrend: str = "auto", harmonics: int = KMAX,
                                poly_degree: int = 3, max_line_delay_s: Optional[float] = None,
                                readout: str = "auto", region: str = "auto",
                                progress: bool = False) -> FlickerResult:
    """Line delay d (s/row) from the bands of a light flickering at ``frequency_hz``.

    frames: arrays, a FrameSource, a video or an image folder (see :func:`read_row_profiles`), or a
        :class:`RowProfiles`. timestamps_s: row-0 times (required for ``phase-drift``; videos carry
        their own). frequency_hz: of the light's intensity (twice the mains frequency for mains lamps).
    rows: sensor rows read out, for readout_time_s and the blanking (default: image height). roi:
        (x, y, w, h) region whose columns are averaged (overrides the automatic region). method:
        "auto" (phase drift when timestamps are known, cross-checked by the spectrum), "spectrum" or
        "phase-drift". detrend: "auto", "frames", "smooth". harmonics: of the band waveform (at most).
    readout: "auto" (the phase drift tells the direction; without timestamps top-to-bottom is
        assumed and said), "top-to-bottom" or "bottom-to-top" (d < 0). region: "auto" (strips and
        rows with bands, overlays masked) or "all".
    max_line_delay_s: upper end of |d| searched (default: frame interval / rows when times are known).
    """
    started = time.perf_counter()
    if not (isinstance(frequency_hz, (int, float, np.floating)) and math.isfinite(frequency_hz) and frequency_hz > 0):
        raise InputError(f"flicker frequency must be a positive number of Hz (got {frequency_hz})")
    if method not in ("auto", "spectrum", "phase-drift"):
        raise InputError(f"unknown method {method!r} (auto, spectrum, phase-drift)")
    if detrend not in ("auto", "frames", "smooth"):
        raise InputError(f"unknown detrend {detrend!r} (auto, frames, smooth)")
    if readout not in READOUTS:
        raise InputError(f"unknown readout direction {readout!r} ({', '.join(READOUTS)})")
    if region not in ("auto", "all"):
        raise InputError(f"unknown region choice {region!r} (auto, all)")
    if int(harmonics) < 1:
        raise InputError("harmonics must be >= 1")
    kmax = int(harmonics)
    profiles = frames if isinstance(frames, RowProfiles) else read_row_profiles(
        frames, timestamps_s, roi=roi, max_frames=max_frames, progress=progress)
    region_info = dict(profiles.region)
    if profiles.strips is not None and not region_info:
        region_info = choose_region(profiles, auto=(region == "auto" and profiles.roi is None))
    height = profiles.image_size[1]
    rows = int(rows) if rows is not None else height
    if rows < 1:
        raise InputError("rows must be positive")
    warnings = list(profiles.warnings)
    f = float(frequency_hz)
    n = profiles.values.shape[0]
    times = profiles.times_s
    if method == "phase-drift" and times is None:
        raise InputError("the phase-drift method needs frame timestamps")
    sign = {"auto": 0, "top-to-bottom": 1, "bottom-to-top": -1}[readout]

    # Search range of |ν| = f |d|: a frame's readout fits in its frame interval; rows alias above 0.5.
    nu_hi = 0.49
    frame_interval = float(np.median(np.diff(times))) if times is not None and n > 1 else None
    if max_line_delay_s is not None:
        nu_hi = min(nu_hi, f * float(max_line_delay_s))
    elif frame_interval is not None:
        nu_hi = min(nu_hi, 1.05 * f * frame_interval / max(rows, height))

    # Weights and log profiles: var(log p) ~ σ² / p². Black (clipped) bands are clamped at
    # BLACK_CLAMP of the brightest row: a clamp, not an offset, so the model stays exact above it.
    p = profiles.values
    lit = np.all(np.isfinite(p), axis=0)
    if not np.any(lit):
        raise InputError("no row of the region has a usable column strip")
    median = np.where(lit, np.median(np.where(lit, p, 0.0), axis=0), 0.0)
    top = float(np.max(median))
    if not top > 0:
        raise InputError("the frames are black in the region used")
    # a dark band is data (the light is off there), weighted by the clamp like any dark row: left
    # out, a clipped wave at ν and its harmonic 2ν explain the bright rows alike
    usable = lit
    if np.count_nonzero(usable) < MIN_ROWS:
        raise InputError(f"only {np.count_nonzero(usable)} rows are lit; need {MIN_ROWS}")
    floor = BLACK_CLAMP * top
    w = np.where(usable, (np.maximum(median, floor) / top) ** 2, 0.0)
    if profiles.row_pixels is not None:  # a row averaged over fewer columns is noisier
        w = w * profiles.row_pixels / max(float(np.max(profiles.row_pixels)), 1e-300)
    sw = np.sqrt(w / w[usable].mean())
    y = np.log(np.maximum(np.where(lit, p, top), floor))
    v = profiles.rows_v - 0.5 * (profiles.rows_v[0] + profiles.rows_v[-1])
    phase0 = None if times is None else np.mod(f * times, 1.0)
    span_rows = float(np.ptp(v)) + 1.0

    def spread_of(index) -> Optional[float]:
        return None if phase0 is None else float(abs(np.mean(np.exp(2j * np.pi * phase0[index]))))

    resultant = spread_of(slice(None))
    attempts: list = []  # (detrend, block), tried in order; the smooth fallback only if frames fail
    if detrend in ("auto", "frames") and n >= 2 and (detrend == "frames" or resultant is None
                                                     or resultant <= SAME_PHASE_RESULTANT):
        attempts.append(("frames", None))
        blocks = _blocks(n, MOVING_BLOCK)
        if n >= 2 * MOVING_BLOCK and (phase0 is None or np.mean([spread_of(g) for g in blocks]) <= SAME_PHASE_RESULTANT):
            attempts.append(("frames", MOVING_BLOCK))
    if detrend in ("auto", "smooth") and (detrend == "smooth" or not attempts or resultant is None):
        attempts.append(("smooth", None))
    if detrend == "auto" and n >= 2 and resultant is not None and resultant > SAME_PHASE_RESULTANT:
        warnings.append(f"the flicker phase is (almost) the same in every frame (frame rate and {f:g} Hz "
                        "commensurate): static scene structure cannot be told from bands; assuming the "
                        "scene's row profile is smooth")

    best = None  # (std, data, estimates, chosen)
    last = None
    for mode, block in attempts:
        data = _Data(y, sw, v, phase0, mode, poly_degree, block)
        spec = _spectrum_estimate(data, nu_hi, kmax, SPECTRUM_MIN_CYCLES) if method in ("auto", "spectrum") else None
        drift = None
        if method in ("auto", "phase-drift") and phase0 is not None and nu_hi > 0.1 / span_rows:
            drift = _phase_drift_estimate(data, 0.1 / span_rows, nu_hi, kmax, sign)
        found = {e["method"]: dict(e, detrend=data.label) for e in (drift, spec) if e is not None}
        good = [e for e in found.values() if e["ok"]]
        last = (float("inf"), data, found, None)
        if good:
            # the first detrend that works (a static scene cancels best over all frames; blocks of
            # frames only when that fails, e.g. a moving camera); phase drift first: it uses the
            # most information
            best = (_std_of(good[0], f)[0], data, found, good[0])
            break
    best = best or last
    assert best is not None
    _, data, estimates, chosen = best
    assert data is not None

    summary_estimates = {}
    for name, e in estimates.items():
        entry = {"ok": bool(e["ok"]), "detrend": e["detrend"]}
        if "nu" in e:
            total, fit, spread = _std_of(e, f)
            entry.update(line_delay_s=e["nu"] / f, line_delay_std_s=total, line_delay_std_fit_s=fit,
                         line_delay_std_spread_s=spread, delta_chi2=e.get("delta_chi2"))
        if "reason" in e:
            entry["reason"] = e["reason"]
        if "alias_nu" in e:
            entry["alias_line_delay_s"] = e["alias_nu"] / f
        for key in ("ambiguity_delta_chi2", "distinct_phases", "joint_vs_free_f", "phase_rms_cycles", "peak_ratio",
                    "segment_chi2", "amplitude_spread", "edge_width_rows"):
            if e.get(key) is not None:
                entry[key] = e[key]
        for key in ("candidates_nu",):
            if key in e:
                entry["candidate_line_delays_s"] = [c / f for c in e[key]]
        summary_estimates[name] = entry

    span = float(np.ptp(v)) + 1.0
    determined = chosen is not None
    reasons: list = []
    checks: dict = {}
    if chosen is None:
        # report the best guess of the method that got furthest, marked undetermined
        chosen = next((e for e in estimates.values() if "nu" in e), None)
        reasons.append("; ".join(f"{k}: {e['reason']}" for k, e in estimates.items() if "reason" in e)
                       or "no usable estimate")
    if chosen is None:
        nu = std_total = std_fit = std_spread = float("nan")
        spread_nu, label, depth, delta_chi2 = np.zeros(0), "frame", float("nan"), float("nan")
    else:
        nu = chosen["nu"]
        std_total, std_fit, std_spread = _std_of(chosen, f)
        spread_nu = np.asarray(chosen.get("per_frame_nu", np.zeros(0)))
        label = chosen.get("spread_label", "frame")
        delta_chi2 = chosen.get("delta_chi2", float("nan"))
        if determined and math.isfinite(std_fit) and math.isfinite(std_spread) and std_fit > 0 and std_spread > 0:
            ratio = std_spread / std_fit
            if ratio > SPREAD_DISAGREEMENT or ratio < 1.0 / SPREAD_DISAGREEMENT:
                warnings.append(f"uncertainty from the fit ({std_fit * 1e9:.3g} ns) and from the spread over "
                                f"{label}s ({std_spread * 1e9:.3g} ns) disagree; reporting the larger")
        if determined and not std_total <= MAX_RELATIVE_STD * abs(nu / f):
            determined = False
            reasons.append(f"std {std_total * 1e6:.3g} us/row is more than {MAX_RELATIVE_STD:.0%} of the estimate")

    # Residual test: the fitted waveform must explain the periodic structure of the profiles.
    model_yp = None
    if chosen is not None and "nu" in chosen:
        if chosen["method"] == "phase-drift":
            model_yp = data.project(np.tensordot(chosen["coef"], _pd_model(data, chosen["nu"], chosen["harmonics"]),
                                                 axes=1))
        else:
            model_yp = _frame_fit(data, chosen["nu"], chosen["harmonics"]) * data.sw
            model_yp = np.nan_to_num(model_yp)
        explained = 1.0 - float(np.sum((data.yp - model_yp) ** 2)) / max(data.null_rss(), 1e-300)
        checks["explained_fraction"] = explained
        peak_ratio, peak_nu, inflation = _residual_tests(data, model_yp, nu)
        checks["residual_noise_inflation"] = inflation
        if inflation > 1.0 and math.isfinite(std_fit):
            std_fit *= math.sqrt(inflation)
            std_total = max(std_total, std_fit)
            if determined and not std_total <= MAX_RELATIVE_STD * abs(nu / f):
                determined = False
                reasons.append(f"std {std_total * 1e6:.3g} us/row is more than {MAX_RELATIVE_STD:.0%} of the "
                               "estimate")
        if abs(nu) * span >= SPECTRUM_MIN_CYCLES:
            checks["residual_peak_ratio"] = peak_ratio
            if determined and peak_ratio > RESIDUAL_PEAK_MAX:
                determined = False
                reasons.append(f"the fitted bands do not explain the profiles: periodic structure of period "
                               f"{1.0 / peak_nu:.1f} rows is left ({peak_ratio:.0%} of the bands' peak power)")

    # Cross-check: every method that produced an estimate must agree with the one reported.
    if determined and chosen is not None:
        for name, e in estimates.items():
            if e is chosen or not e["ok"]:
                continue
            s_a, s_b = std_total, _std_of(e, f)[0]
            gap = abs(abs(chosen["nu"]) - abs(e["nu"])) / f
            sigmas = gap / math.hypot(s_a, s_b) if math.hypot(s_a, s_b) > 0 else float("inf")
            checks[f"agreement_{chosen['method']}_vs_{name}_sigmas"] = sigmas
            if not sigmas <= AGREEMENT_SIGMAS:
                determined = False
                reasons.append(f"the methods disagree: {chosen['method']} {abs(chosen['nu']) / f * 1e6:.6g} and "
                               f"{name} {abs(e['nu']) / f * 1e6:.6g} us/row ({sigmas:.1f} sigma apart): a harmonic, "
                               "inexact timestamps or frequency, or not flicker")

    # Readout direction: the spectrum sees |d|; the phase drift sees its sign.
    direction_determined = chosen is not None and chosen.get("method") == "phase-drift"
    if chosen is not None and not direction_determined:
        nu = abs(nu) * (-1.0 if sign < 0 else 1.0)
    if direction_determined and sign != 0 and np.sign(nu) != sign:
        determined = False
        reasons.append(f"the phase drift says the readout runs {'top-to-bottom' if nu > 0 else 'bottom-to-top'}, "
                       f"not {readout} as given")
    direction = "bottom-to-top" if nu < 0 else "top-to-bottom"
    if chosen is not None and not direction_determined:
        if sign == 0:
            warnings.append("readout direction not measured (no usable phase drift between timestamped frames): "
                            "top-to-bottom assumed; the bands give |d| only")
        direction += " (given)" if sign != 0 else " (assumed)"

    # Vertical blanking: the frame period is (rows + blanking rows) x |d|.
    blank = blank_std = blank_s = float("nan")
    blank_ok = False
    if determined and chosen is not None and chosen.get("method") == "phase-drift" and frame_interval:
        intervals = np.diff(times)
        d_abs = abs(nu) / f
        blank = frame_interval / d_abs - rows
        blank_std = frame_interval * std_total / d_abs ** 2
        blank_s = frame_interval - d_abs * rows
        regular = float(np.max(np.abs(intervals - frame_interval))) <= 0.001 * frame_interval
        blank_ok = bool(regular and blank_std <= max(1.0, 0.01 * (rows + blank)) and blank > -3 * blank_std)
        if not regular:
            warnings.append("frame intervals are irregular: the vertical blanking is not determined")

    if not determined:
        warnings.append("the data do not determine the line delay: " + "; ".join(reasons))

    # plot material: a few frames' projected profiles with the fitted model
    plot: dict = {}
    if chosen is not None and "nu" in chosen and model_yp is not None:
        show = np.unique(np.linspace(0, n - 1, min(n, 3)).round().astype(int))
        with np.errstate(divide="ignore", invalid="ignore"):
            observed = np.where(data.sw > 0, data.yp / data.sw, np.nan)
            model = np.where(data.sw > 0, model_yp / data.sw, np.nan)
        plot = {"rows_v": profiles.rows_v, "frames": show, "observed": observed[show], "model": model[show],
                "grid_nu": chosen.get("grid_nu"), "grid_rss": chosen.get("grid_rss")}

    line_delay = nu / f
    depth = float("nan")
    if chosen is not None and chosen.get("method") == "phase-drift" and "coef" in chosen:
        depth = float(np.hypot(*chosen["coef"][:2]))
    elif chosen is not None and "nu" in chosen:
        fits = _frame_fit(data, chosen["nu"], 1)
        depth = float(np.nanmedian(np.nanmax(fits, axis=1) - np.nanmin(fits, axis=1)) / 2.0)
    return FlickerResult(
        line_delay_s=line_delay, line_delay_std_s=std_total, line_delay_std_fit_s=std_fit,
        line_delay_std_spread_s=std_spread, readout_time_s=abs(line_delay) * rows, rows=rows, frequency_hz=f,
        period_rows=1.0 / abs(nu) if nu and math.isfinite(nu) else float("nan"),
        cycles_per_frame=abs(nu) * span if math.isfinite(nu) else float("nan"),
        method=chosen["method"] if chosen is not None else "none", detrend=data.detrend, frames_used=n,
        frames_total=profiles.frames_total, modulation_depth=depth, delta_chi2=float(delta_chi2),
        determined=bool(determined), warnings=warnings, estimates=summary_estimates, spread_label=label,
        spread_line_delays_s=spread_nu / f, timestamps_source=profiles.timestamps_source,
        image_size=tuple(profiles.image_size), roi=profiles.roi, readout_direction=direction,
        direction_determined=bool(direction_determined), vertical_blanking_rows=blank,
        vertical_blanking_std_rows=blank_std, vertical_blanking_s=blank_s, blanking_determined=blank_ok,
        reason=None if determined else "; ".join(reasons), checks=checks, region=region_info,
        plot=dict(plot, seconds=time.perf_counter() - started))
