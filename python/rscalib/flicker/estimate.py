"""Line delay from the bands of a flickering light (the LED method of Geyer et al. [14] in Oth et al. 2013, §2 and §5).

A light whose intensity repeats at ``frequency_hz`` (f) multiplies row v of frame i by
g(t_i + v d) (docs/conventions.md: row v of frame i is exposed at t_i + v d), so a rolling-shutter
image shows horizontal bands of period P = 1 / (f d) rows: d = ν / f with ν = 1 / P cycles/row.

Model, on the row profile (mean grey over the columns of a region) in log units:

    y_i(v) = s(v) + c_i + h(2π (f t_i + ν v)) + noise

s(v) is the scene's own row profile, c_i a per-frame brightness (auto exposure), h the periodic
log-gain written as K harmonics. The nuisances are removed by one linear projection applied to the
data and to the model alike ("detrend"):

  frames: subtract each row's mean over the frames, then each frame's mean. A static scene cancels
          exactly; needs the flicker phase to differ between frames. With a moving camera the row
          means are taken over blocks of MOVING_BLOCK consecutive frames instead; "auto" tries
          both and keeps the one with the smaller uncertainty.
  smooth: subtract from each frame a low-order polynomial in v. For one frame, or when the flicker
          phase is the same in every frame (frame rate and flicker commensurate); assumes the
          scene has no bands of its own.

Two estimators:

  spectrum:    each frame its own phase (timestamps unused): the summed Hann periodogram
               (zero-padded) gives ν to a fraction of a bin, refined by least squares of K
               harmonics at ν in every frame. Needs a few periods per frame.
  phase-drift: one phase shared by all frames through their timestamps, so the phase drift
               between frames pins d even when a frame shows less than one period (mains flicker):
               profile least squares over a grid in ν (the whole range: a spectral peak may be a
               harmonic), then scipy least_squares on (ν, harmonics). A second minimum of the grid
               almost as good means aliasing. Preferred by "auto" when the frames have timestamps;
               the spectrum is kept as a cross-check (a disagreement suggests inexact timestamps).

Clipped pixels do not follow the light: columns are averaged in strips, and a strip that clips in
any frame is left out of that row in every frame.

Weights: var(log p) ~ σ² / p², so row v weighs median_i(p_i(v))²; rows darker than 1 % of the
brightest row or saturated are left out. Uncertainty: the fit (Jacobian or profile curvature,
scaled by the residual variance) and the spread over frames or frame subsets; the reported
``line_delay_std_s`` is the larger. A result that the data do not determine (no band contrast,
aliasing, std > 25 % of d) has ``determined = False`` and says why in ``warnings``.
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

__all__ = ["FlickerResult", "estimate_line_delay_flicker"]

SPECTRUM_MIN_CYCLES = 2.0        # below this many periods per frame the periodogram peak is leakage
MIN_DELTA_CHI2 = 100.0           # plus 4 per fitted amplitude: noise alone gives ~1 per amplitude + ~10 for the search
MIN_PEAK_RATIO = 10.0            # periodogram peak over its median in the search band
AMBIGUITY_DELTA_CHI2 = 25.0      # a second minimum this close: d is aliased
MAX_RELATIVE_STD = 0.25
SAME_PHASE_RESULTANT = 0.95      # |mean exp(2πi f t_i)| above this: phases (almost) all equal
MOVING_BLOCK = 4                 # frames per block when the scene may move (detrend "frames")
SPREAD_DISAGREEMENT = 2.0        # fit vs spread uncertainty ratio that earns a warning


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


def _harmonics(nu_max: float, harmonics: int) -> int:
    """Harmonics below the row Nyquist frequency (0.5 cycles/row) at the largest ν searched."""
    return max(1, min(int(harmonics), int(math.floor(0.499 / max(nu_max, 1e-12)))))


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


def _frame_rss(data: _Data, nu: float, k_count: int) -> np.ndarray:
    """Per-frame RSS of the best K harmonics at ν (each frame its own amplitudes and phases)."""
    design = _row_design(data.v, nu, k_count).T * data.sw[:, None]
    design -= data.frame_basis @ (data.frame_basis.T @ design)
    u, s, _ = np.linalg.svd(design, full_matrices=False)
    u = u[:, s > 1e-9 * s[0]]
    proj = data.yp @ u
    return np.sum(data.yp ** 2, axis=1) - np.sum(proj ** 2, axis=1)


def _frame_fit(data: _Data, nu: float, k_count: int) -> np.ndarray:
    """Fitted, projected model per frame (frames, rows), unweighted (for plots)."""
    design = _row_design(data.v, nu, k_count).T * data.sw[:, None]
    design -= data.frame_basis @ (data.frame_basis.T @ design)
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


def _spectrum_estimate(data: _Data, nu_hi: float, harmonics: int) -> dict:
    """ν from the summed periodogram, refined by least squares; per-frame estimates for the spread."""
    rows = data.yp.shape[1]
    span = float(np.ptp(data.v)) + 1.0
    nu_lo = SPECTRUM_MIN_CYCLES / span
    out: dict = {"method": "spectrum", "ok": False}
    if nu_hi <= nu_lo:
        out["reason"] = (f"at most {nu_hi * span:.2f} periods fit in the {rows} rows used; the spectrum needs "
                         f"{SPECTRUM_MIN_CYCLES:g}")
        return out
    freqs, power = _periodogram(data)
    band = (freqs >= nu_lo) & (freqs <= nu_hi)
    if not np.any(band) or not np.any(power[band] > 0):
        out["reason"] = "no band contrast (the frames' row profiles do not vary)"
        return out
    index = np.flatnonzero(band)
    peak = index[np.argmax(power[band])]
    # noise floor over all frequencies above the leakage, not just the (maybe narrow) search band
    floor = float(np.median(power[freqs >= nu_lo]))
    ratio = float(power[peak] / max(floor, 1e-300))
    log_power = np.log(np.maximum(power, 1e-300))
    nu0 = _parabolic_peak(freqs, log_power, peak)
    k_count = _harmonics(nu_hi, harmonics)

    def total(nu: float) -> float:
        return float(np.sum(_frame_rss(data, nu, k_count)))

    width = 0.6 / span
    lo, hi = max(nu_lo * 0.5, nu0 - width), nu0 + width
    grid = np.linspace(lo, hi, 61)
    per_frame = np.array([_frame_rss(data, nu, k_count) for nu in grid])  # (grid, frames)
    best = int(np.argmin(per_frame.sum(axis=1)))
    step = grid[1] - grid[0]
    res = minimize_scalar(total, bounds=(grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]),
                          method="bounded", options={"xatol": 1e-6 / span})
    nu = float(res.x)
    rss = total(nu)
    n_eff = data.frames * data.rows_used
    dof = max(1, n_eff - data.nuisance_dof() - data.frames * 2 * k_count - 1)
    sigma2 = rss / dof
    h = 0.01 / span
    curvature = (total(nu + h) - 2.0 * rss + total(nu - h)) / h ** 2
    std_fit = math.sqrt(2.0 * sigma2 / curvature) if curvature > 0 else float("inf")
    # per-frame minimisers on the same grid, refined by a parabola through the three nearest points
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
    delta_chi2 = (data.null_rss() - rss) / sigma2
    # Is the peak a harmonic of bands with a longer period (fewer than 2 per frame, below the band
    # searched)? Then ν/m with m times the harmonics explains much more (a true fundamental
    # carries more energy than its harmonic; fitting scene residue with the extra terms does not).
    for m in (2, 3):
        k_sub = _harmonics(nu / m, harmonics * m)
        if not 0.3 <= nu / m * span < SPECTRUM_MIN_CYCLES or k_sub <= k_count:
            continue
        sub = minimize_scalar(lambda x, k_sub=k_sub: float(np.sum(_frame_rss(data, x, k_sub))),
                              bounds=(nu / m - 0.3 / span, nu / m + 0.3 / span), method="bounded")
        gain = (rss - sub.fun) / sigma2
        if gain > max(MIN_DELTA_CHI2 + 4 * data.frames * 2 * (k_sub - k_count), 0.5 * delta_chi2):
            out.update(nu=nu, harmonics=k_count, delta_chi2=float(delta_chi2), reason=(
                f"the peak at {nu * span:.2f} periods per frame is a harmonic of bands with {sub.x * span:.2f} "
                "periods per frame, too few for the spectrum"))
            return out
    out.update(ok=True, nu=nu, std_fit_nu=std_fit, std_spread_nu=std_spread, per_frame_nu=per_frame_nu,
               spread_label="frame", delta_chi2=float(delta_chi2), peak_ratio=ratio, harmonics=k_count,
               rss=rss, sigma2=sigma2)
    if nu < nu_lo:
        out.update(ok=False, reason=f"{nu * span:.2f} periods per frame: too few for the spectrum")
    elif ratio < MIN_PEAK_RATIO or delta_chi2 < MIN_DELTA_CHI2 + 4 * data.frames * 2 * k_count:
        out.update(ok=False, reason=f"no flicker bands found (spectral peak {ratio:.1f}x the median, "
                                    f"delta chi2 {delta_chi2:.0f})")
    elif best in (0, len(grid) - 1):
        out.update(ok=False, reason="the spectral peak did not refine (minimum at the edge of its window)")
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


def _phase_drift_estimate(data: _Data, nu_lo: float, nu_hi: float, harmonics: int,
                          max_grid_frames: int = 40) -> dict:
    out: dict = {"method": "phase-drift", "ok": False}
    span = float(np.ptp(data.v)) + 1.0
    k_count = _harmonics(nu_hi, harmonics)
    # Coarse profile over ν on a subsample of frames: the minimum is ~1/rows wide whatever the
    # number of frames, so a step of 0.08/rows cannot step over it.
    pick = np.unique(np.linspace(0, data.frames - 1, min(data.frames, max_grid_frames)).round().astype(int))
    coarse = data.subset(pick) if len(pick) < data.frames else data
    grid = np.arange(nu_lo, nu_hi + 0.04 / span, 0.08 / span)
    rss = np.array([_pd_profile_rss(coarse, nu, k_count)[0] for nu in grid])
    best = int(np.argmin(rss))
    dof_coarse = max(1, coarse.frames * coarse.rows_used - coarse.nuisance_dof() - 2 * k_count - 1)
    sigma2_coarse = rss[best] / dof_coarse
    minima = _local_minima(rss)
    others = [i for i in minima if abs(grid[i] - grid[best]) > 0.5 / span]
    out["grid_nu"], out["grid_rss"] = grid, rss
    second = min((rss[i] for i in others), default=np.inf)
    out["ambiguity_delta_chi2"] = float((second - rss[best]) / sigma2_coarse) if np.isfinite(second) else None
    nu0 = float(grid[best])
    _, coef0 = _pd_profile_rss(data, nu0, k_count)
    fit = _pd_refine(data, nu0, coef0, k_count)
    delta_chi2 = (data.null_rss() - fit["rss"]) / fit["sigma2"]
    out.update(ok=True, nu=fit["nu"], std_fit_nu=fit["std_fit_nu"], coef=fit["coef"], harmonics=k_count,
               delta_chi2=float(delta_chi2), rss=fit["rss"], sigma2=fit["sigma2"], converged=fit["converged"])
    # spread over contiguous blocks of frames (contiguous: interleaving can give every block the
    # same flicker phase when the rates are commensurate)
    groups = min(6, data.frames // 3)
    subset_nu = []
    if groups >= 3:
        for block in np.array_split(np.arange(data.frames), groups):
            sub = data.subset(block)
            _, c0 = _pd_profile_rss(sub, fit["nu"], k_count)
            subset_nu.append(_pd_refine(sub, fit["nu"], c0, k_count)["nu"])
    subset_nu = np.array(subset_nu)
    out["per_frame_nu"] = subset_nu
    out["spread_label"] = "frame block"
    out["std_spread_nu"] = float(np.std(subset_nu, ddof=1) / math.sqrt(len(subset_nu))) if len(subset_nu) >= 3 \
        else float("nan")
    if delta_chi2 < MIN_DELTA_CHI2 + 4 * 2 * k_count:
        out.update(ok=False, reason=f"no flicker found (the fit lowers chi2 by only {delta_chi2:.0f})")
    elif out["ambiguity_delta_chi2"] is not None and out["ambiguity_delta_chi2"] < AMBIGUITY_DELTA_CHI2:
        alias = grid[min(others, key=lambda i: rss[i])]
        out.update(ok=False, reason=f"aliased: line delays {grid[best]:.6g} and {alias:.6g} cycles/row fit about "
                                    f"equally well (delta chi2 {out['ambiguity_delta_chi2']:.1f}); frame times "
                                    "and flicker may be (nearly) commensurate")
    elif data.detrend == "smooth" and fit["nu"] * span < SPECTRUM_MIN_CYCLES:
        # with the same flicker phase in every frame only the within-frame pattern is left, and
        # under ~2 periods it is indistinguishable from the scene's own shading
        out.update(ok=False, reason=f"{fit['nu'] * span:.2f} periods per frame and no phase drift between frames: "
                                    "bands cannot be told from scene structure")
    elif best in (0, len(grid) - 1) and abs(fit["nu"] - grid[best]) < 0.1 / span:
        out.update(ok=False, reason="the best line delay is at the edge of the searched range")
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


@dataclass
class FlickerResult:
    """Line delay from flicker bands. Times in seconds, ν in cycles per row."""

    line_delay_s: float
    line_delay_std_s: float          # max(fit, spread) when both exist
    line_delay_std_fit_s: float      # Jacobian / profile curvature, scaled by the residual variance
    line_delay_std_spread_s: float   # spread over frames (spectrum) or blocks of frames (phase drift)
    readout_time_s: float            # d · rows
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
    plot: dict = field(default_factory=dict, repr=False)

    def summary_dict(self) -> dict:
        def clean(x):
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, (list, tuple, np.ndarray)):
                return [clean(v) for v in x]
            if isinstance(x, (float, np.floating)):
                return float(x) if math.isfinite(x) else None
            if isinstance(x, np.integer):
                return int(x)
            return x
        keys = ["line_delay_s", "line_delay_std_s", "line_delay_std_fit_s", "line_delay_std_spread_s",
                "readout_time_s", "rows", "frequency_hz", "period_rows", "cycles_per_frame", "method", "detrend",
                "frames_used", "frames_total", "modulation_depth", "delta_chi2", "determined", "warnings",
                "estimates", "spread_label", "timestamps_source", "image_size", "roi"]
        out = {k: clean(getattr(self, k)) for k in keys}
        out["spread_line_delays_s"] = clean(self.spread_line_delays_s)
        return out


def estimate_line_delay_flicker(frames: Any, frequency_hz: float, timestamps_s: Optional[Sequence[float]] = None, *,
                                rows: Optional[int] = None, roi=None, max_frames: Optional[int] = None,
                                method: str = "auto", detrend: str = "auto", harmonics: int = 4,
                                poly_degree: int = 3, max_line_delay_s: Optional[float] = None,
                                progress: bool = False) -> FlickerResult:
    """Line delay d (s/row) from the bands of a light flickering at ``frequency_hz``.

    frames: arrays, a FrameSource, a video or an image folder (see :func:`read_row_profiles`), or a
        :class:`RowProfiles`. timestamps_s: row-0 times (required for ``phase-drift``; videos carry
        their own). frequency_hz: of the light's intensity (twice the mains frequency for mains lamps).
    rows: sensor rows read out, for readout_time_s (default: image height). roi: (x, y, w, h) region
        whose columns are averaged. method: "auto" (phase drift when timestamps are known and it is
        determined, else spectrum), "spectrum" or "phase-drift". detrend: "auto", "frames", "smooth".
    max_line_delay_s: upper end of the search (default: frame interval / rows when times are known).
    """
    started = time.perf_counter()
    if not (isinstance(frequency_hz, (int, float, np.floating)) and math.isfinite(frequency_hz) and frequency_hz > 0):
        raise InputError(f"flicker frequency must be a positive number of Hz (got {frequency_hz})")
    if method not in ("auto", "spectrum", "phase-drift"):
        raise InputError(f"unknown method {method!r} (auto, spectrum, phase-drift)")
    if detrend not in ("auto", "frames", "smooth"):
        raise InputError(f"unknown detrend {detrend!r} (auto, frames, smooth)")
    if int(harmonics) < 1:
        raise InputError("harmonics must be >= 1")
    profiles = frames if isinstance(frames, RowProfiles) else read_row_profiles(
        frames, timestamps_s, roi=roi, max_frames=max_frames, progress=progress)
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

    # Search range of ν = f d: a frame's readout fits in its frame interval; rows alias above 0.5.
    nu_hi = 0.49
    if max_line_delay_s is not None:
        nu_hi = min(nu_hi, f * float(max_line_delay_s))
    elif times is not None and n > 1:
        nu_hi = min(nu_hi, 1.05 * f * float(np.median(np.diff(times))) / max(rows, height))

    # Weights and log profiles.
    p = profiles.values
    lit = np.all(np.isfinite(p), axis=0)
    if not np.any(lit):
        raise InputError("every row of the region is clipped (saturated or black) in some frame")
    median = np.where(lit, np.median(np.where(lit, p, 0.0), axis=0), 0.0)
    top = float(np.max(median))
    if not top > 0:
        raise InputError("the frames are black in the region used")
    usable = lit & (median > 0.01 * top)
    if np.count_nonzero(usable) < MIN_ROWS:
        raise InputError(f"only {np.count_nonzero(usable)} rows are neither dark nor clipped; need {MIN_ROWS}")
    w = np.where(usable, (median / top) ** 2, 0.0)
    sw = np.sqrt(w / w[usable].mean())
    y = np.log(np.maximum(np.where(lit, p, top), 1e-3 * top))
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
        if mode == "smooth" and best is not None:
            break
        data = _Data(y, sw, v, phase0, mode, poly_degree, block)
        spec = _spectrum_estimate(data, nu_hi, harmonics) if method in ("auto", "spectrum") else None
        drift = None
        if method in ("auto", "phase-drift") and phase0 is not None and nu_hi > 0.1 / span_rows:
            # the whole range, not just around the spectrum's peak: that may be a harmonic
            drift = _phase_drift_estimate(data, 0.1 / span_rows, nu_hi, harmonics)
        found = {e["method"]: dict(e, detrend=data.label) for e in (drift, spec) if e is not None}
        good = [e for e in found.values() if e["ok"]]
        last = (float("inf"), data, found, None)
        if good:
            chosen = good[0]  # phase drift first: it uses the most information
            std = _std_of(chosen, f)[0]
            if best is None or std < best[0]:
                best = (std, data, found, chosen)
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
        if name == "phase-drift" and e.get("ambiguity_delta_chi2") is not None:
            entry["ambiguity_delta_chi2"] = e["ambiguity_delta_chi2"]
        if name == "spectrum" and "peak_ratio" in e:
            entry["peak_ratio"] = e["peak_ratio"]
        summary_estimates[name] = entry

    span = float(np.ptp(v)) + 1.0
    determined = chosen is not None
    if chosen is None:
        # report the best guess of the method that got furthest, marked undetermined
        chosen = next((e for e in estimates.values() if "nu" in e), None)
        reasons = "; ".join(f"{k}: {e['reason']}" for k, e in estimates.items() if "reason" in e)
        warnings.append("the data do not determine the line delay: " + (reasons or "no usable estimate"))
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
        line_delay = nu / f
        if determined and not std_total <= MAX_RELATIVE_STD * abs(line_delay):
            determined = False
            warnings.append(f"the data do not determine the line delay: std {std_total * 1e6:.3g} us/row is more "
                            f"than {MAX_RELATIVE_STD:.0%} of the estimate")
    if determined and len(estimates) == 2 and all(e["ok"] for e in estimates.values()):
        a, b = estimates["spectrum"], estimates["phase-drift"]
        sa, sb = _std_of(a, f)[0], _std_of(b, f)[0]
        if abs(a["nu"] - b["nu"]) / f > 3.0 * math.hypot(sa, sb):
            warnings.append(f"spectrum ({a['nu'] / f * 1e6:.5g} us/row) and phase-drift ({b['nu'] / f * 1e6:.5g} "
                            "us/row) estimates disagree: the spectrum may have locked onto a harmonic (few periods per "
                            "frame), or the frame timestamps are inexact")

    # plot material: a few frames' projected profiles with the fitted model
    plot: dict = {}
    if chosen is not None and "nu" in chosen:
        show = np.unique(np.linspace(0, n - 1, min(n, 3)).round().astype(int))
        if chosen["method"] == "phase-drift":
            model = _pd_fit_curves(data, chosen["nu"], chosen["coef"], chosen["harmonics"])
        else:
            model = _frame_fit(data, chosen["nu"], chosen["harmonics"])
        with np.errstate(divide="ignore", invalid="ignore"):
            observed = np.where(data.sw > 0, data.yp / data.sw, np.nan)
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
        line_delay_std_spread_s=std_spread, readout_time_s=line_delay * rows, rows=rows, frequency_hz=f,
        period_rows=1.0 / nu if nu and math.isfinite(nu) else float("nan"),
        cycles_per_frame=nu * span if math.isfinite(nu) else float("nan"),
        method=chosen["method"] if chosen is not None else "none", detrend=data.detrend, frames_used=n,
        frames_total=profiles.frames_total, modulation_depth=depth, delta_chi2=float(delta_chi2),
        determined=bool(determined), warnings=warnings, estimates=summary_estimates, spread_label=label,
        spread_line_delays_s=spread_nu / f, timestamps_source=profiles.timestamps_source,
        image_size=tuple(profiles.image_size), roi=profiles.roi,
        plot=dict(plot, seconds=time.perf_counter() - started))
