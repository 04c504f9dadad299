"""The band model of the flicker method (docs/formulation.md §12): log row profiles with their
weights and nuisances, the harmonic designs, the fits and the residual tests that both estimators
(spectrum.py, phase_drift.py) and the checks (engine.py) share.

A light whose intensity repeats at f multiplies row v of frame i by g(t_i + v d), so the log row
profile of frame i is the scene's plus sum_k a_k cos(k 2π (φ_i + ν v)) + b_k sin(...), ν = f d
cycles per row. The scene is a nuisance: constant over frames (detrend "frames", in blocks of
frames when the camera moves) or a smooth polynomial per frame (detrend "smooth").
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import InputError
from .profiles import MIN_ROWS, RowProfiles

SPECTRUM_MIN_CYCLES = 2.0   # below this many periods per frame the bands cannot be told from scene shading
MIN_DELTA_CHI2 = 100.0      # plus 4 per fitted amplitude: noise alone gives ~1 per amplitude + ~10 for the search
HARMONIC_NU_MAX = 0.45      # harmonics of the band waveform all below this many cycles per row
BLACK_CLAMP = 0.01          # log profiles are clamped here (fraction of the brightest row)


def frame_blocks(frames: int, block: Optional[int]) -> list:
    """Consecutive frame indices in blocks of `block` (all in one if None); no block of one frame."""
    size = frames if not block else int(block)
    groups = [np.arange(i, min(i + size, frames)) for i in range(0, frames, size)]
    if len(groups) > 1 and len(groups[-1]) < 2:
        groups[-2] = np.concatenate(groups[-2:])
        groups.pop()
    return groups


class LogProfiles:
    """Log row profiles y (frames, rows), their weights sw = sqrt(w) per row, the rows v (centred),
    the frames' flicker phases phase0 = f t_i mod 1 (None without timestamps) and the nuisance
    projection of the scene (detrend "frames": constant within `block`s of frames; "smooth": a
    Legendre polynomial of poly_degree per frame)."""

    def __init__(self, y: np.ndarray, sw: np.ndarray, v: np.ndarray, phase0: Optional[np.ndarray],
                 detrend: str, poly_degree: int, block: Optional[int]) -> None:
        self.y, self.sw, self.v, self.phase0 = y, sw, v, phase0
        self.w = sw ** 2
        self.detrend, self.poly_degree, self.block = detrend, poly_degree, block
        # frames mode: the scene is constant within blocks of consecutive frames (all frames when
        # block is None); a short block follows a moving camera
        self.groups = frame_blocks(y.shape[0], block)
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

    @property
    def span(self) -> float:
        """Rows from the first to the last, inclusive."""
        return float(np.ptp(self.v)) + 1.0

    def subset(self, index) -> LogProfiles:
        return LogProfiles(self.y[index], self.sw, self.v, None if self.phase0 is None else self.phase0[index],
                           self.detrend, self.poly_degree, self.block)

    def rows(self, index) -> LogProfiles:
        """The same frames, only the rows `index` (a segment of the profile)."""
        return LogProfiles(self.y[:, index], self.sw[index], self.v[index], self.phase0, self.detrend,
                           self.poly_degree, self.block)

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

    def unweighted(self, x: np.ndarray) -> np.ndarray:
        """x / sqrt(w) where a row has weight, NaN where it has none (for plots)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.sw > 0, x / self.sw, np.nan)


def log_profiles(profiles: RowProfiles, frequency_hz: float) -> tuple:
    """(y, sw, v, phase0) of LogProfiles from row profiles: var(log p) ~ σ² / p², so a row's weight
    is its level squared (and its columns averaged); black (clipped) bands are clamped at
    BLACK_CLAMP of the brightest row — a clamp, not an offset, so the model stays exact above it.
    v is centred on the middle row; phase0 = f t_i mod 1 (None without timestamps)."""
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
    times = profiles.times_s
    phase0 = None if times is None else np.mod(frequency_hz * times, 1.0)
    return y, sw, v, phase0


# ---- designs and fits ----------------------------------------------------------------------------


def row_design(v: np.ndarray, nu: float, k_count: int) -> np.ndarray:
    """(2K, rows) cos/sin of k·2πνv."""
    out = []
    for k in range(1, k_count + 1):
        arg = 2.0 * np.pi * k * nu * v
        out += [np.cos(arg), np.sin(arg)]
    return np.array(out)


def lstsq_rss(columns: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """RSS and coefficients of target ≈ columnsᵀ c (columns (p, N))."""
    # normal equations: the columns are sinusoids, well conditioned, and p is small
    gram = columns @ columns.T
    rhs = columns @ target
    coef = np.linalg.pinv(gram, rcond=1e-12, hermitian=True) @ rhs
    return float(target @ target - rhs @ coef), coef


def frame_design(data: LogProfiles, nu: float, k_count: int) -> np.ndarray:
    """(rows, 2K) weighted cos/sin of k·2πνv with each frame's own nuisance projected out."""
    design = row_design(data.v, nu, k_count).T * data.sw[:, None]
    return design - data.frame_basis @ (data.frame_basis.T @ design)


def frame_rss(data: LogProfiles, nu: float, k_count: int) -> np.ndarray:
    """Per-frame RSS of the best K harmonics at ν (each frame its own amplitudes and phases)."""
    design = frame_design(data, nu, k_count)
    gram = design.T @ design
    rhs = data.yp @ design                                   # (frames, 2K)
    coef = rhs @ np.linalg.pinv(gram, rcond=1e-10, hermitian=True)
    return data.yy - np.sum(rhs * coef, axis=1)


def total_frame_rss(data: LogProfiles, nu: float, k_count: int) -> float:
    """The RSS of the best K harmonics at ν summed over the frames (each frame its own phase)."""
    return float(np.sum(frame_rss(data, nu, k_count)))


def frame_fit(data: LogProfiles, nu: float, k_count: int) -> np.ndarray:
    """Fitted, projected model per frame (frames, rows), unweighted (for plots)."""
    design = frame_design(data, nu, k_count)
    coef, *_ = np.linalg.lstsq(design, data.yp.T, rcond=None)
    return data.unweighted((design @ coef).T)


def frame_amplitudes(data: LogProfiles, nu: float) -> np.ndarray:
    """(2, frames) cos/sin amplitudes of the fundamental at ν fitted to each frame on its own."""
    design = frame_design(data, nu, 1)
    free, *_ = np.linalg.lstsq(design, data.yp.T, rcond=None)
    return free


def periodogram(data: LogProfiles) -> tuple[np.ndarray, np.ndarray]:
    """(ν, power) of the projected profiles, Hann-windowed and zero-padded 16x, summed over frames."""
    rows = data.yp.shape[1]
    nfft = 1 << int(math.ceil(math.log2(16 * rows)))
    spectrum = np.fft.rfft(data.yp * np.hanning(rows), n=nfft, axis=1)
    return np.arange(spectrum.shape[1]) / nfft, np.sum(np.abs(spectrum) ** 2, axis=0)


def parabolic_peak(x: np.ndarray, y: np.ndarray, i: int) -> float:
    """x of the vertex of the parabola through y[i - 1 : i + 2] (x[i] at the ends)."""
    if i <= 0 or i >= len(y) - 1:
        return float(x[i])
    a, b, c = y[i - 1], y[i], y[i + 1]
    denom = a - 2.0 * b + c
    shift = 0.5 * (a - c) / denom if denom != 0 else 0.0
    return float(x[i] + np.clip(shift, -1.0, 1.0) * (x[1] - x[0]))


def harmonics_at(nu: float, kmax: int) -> int:
    """Harmonics of ν below HARMONIC_NU_MAX cycles/row, at most kmax."""
    return max(1, min(int(kmax), int(math.floor(HARMONIC_NU_MAX / max(abs(nu), 1e-12)))))


def refine_frames(data: LogProfiles, nu0: float, k_count: int, half_width: float, lo: float) -> tuple[float, float]:
    """(ν, RSS) minimising the per-frame-phase RSS near nu0 (grid, then bounded search)."""
    span = data.span
    step = 0.02 / span
    grid = nu0 + np.arange(-half_width, half_width + 0.5 * step, step)
    grid = grid[grid >= lo]
    if len(grid) < 3:
        return nu0, total_frame_rss(data, nu0, k_count)
    total = np.array([total_frame_rss(data, g, k_count) for g in grid])
    b = int(np.argmin(total))
    a, c = grid[max(b - 1, 0)], grid[min(b + 1, len(grid) - 1)]
    res = minimize_scalar(lambda x: total_frame_rss(data, x, k_count), bounds=(a, c), method="bounded",
                          options={"xatol": 1e-7 / span})
    return (float(res.x), float(res.fun)) if res.fun <= total[b] else (float(grid[b]), float(total[b]))


# ---- residual tests ------------------------------------------------------------------------------


def residual_tests(data: LogProfiles, model_yp: np.ndarray, nu: float) -> tuple[float, float, float]:
    """(peak ratio, its ν, noise inflation) from the residual periodogram (summed over frames).

    Peak ratio: the largest residual peak away from the fitted harmonics of ν, over the fitted
    model's largest peak: bands the fit does not explain (another period, a harmonic lock).
    Inflation: the residual power next to the fitted harmonics (weighted by the model's power
    there) over the residual's mean power: scene structure or compression noise near the band
    frequencies makes the white-noise σ of the fit too small by its square root (floored at 1); so
    does a residual common to all frames (the same scene structure), which does not average out."""
    span = data.span
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
