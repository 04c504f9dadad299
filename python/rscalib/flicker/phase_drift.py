"""The phase-drift estimator of the flicker method (docs/formulation.md §12): one band phase for
all frames through their timestamps, φ_i = f t_i, so ν of either sign (the readout direction) and
less than a period per frame (mains flicker) are measured.

Every local minimum of a fundamental-only profile over the whole range is a candidate (explicit
cycle and alias resolution); each is refined with all harmonics on all frames, and the best must
beat the second by AMBIGUITY_DELTA_CHI2, else the result is aliased. Each frame's own band phase
must then match the drift the timestamps predict.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from .model import (
    MIN_DELTA_CHI2,
    SPECTRUM_MIN_CYCLES,
    LogProfiles,
    frame_amplitudes,
    frame_rss,
    harmonics_at,
    lstsq_rss,
)

AMBIGUITY_DELTA_CHI2 = 25.0      # a second minimum this close: d is aliased
PHASE_TOLERANCE = 0.01           # flicker phases (cycles) closer than this count as one
PHASE_RMS_MAX = 0.05             # frames' own band phases vs the timestamps' prediction (cycles rms)
COARSE_FRAMES = 120              # consecutive frames used for the grid of candidates


def drift_design(data: LogProfiles, nu: float, k_count: int, derivative: bool = False) -> np.ndarray:
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


def drift_model(data: LogProfiles, nu: float, coef: np.ndarray, k_count: int) -> np.ndarray:
    """The projected, weighted drift model (frames, rows) with amplitudes coef at ν."""
    return data.project(np.tensordot(coef, drift_design(data, nu, k_count), axes=1))


def profile_rss(data: LogProfiles, nu: float, k_count: int) -> tuple[float, np.ndarray]:
    """(RSS, amplitudes) of the drift model at ν with its best K harmonics (linear in them)."""
    columns = data.project(drift_design(data, nu, k_count)).reshape(2 * k_count, -1)
    return lstsq_rss(columns, data.yp.ravel())


def refine(data: LogProfiles, nu0: float, coef0: np.ndarray, k_count: int) -> dict:
    """ν and the amplitudes by Levenberg-Marquardt from (nu0, coef0): nu, coef, rss, sigma2, the
    σ of ν from the Jacobian scaled by the residual variance, and whether it converged."""
    target = data.yp.ravel()

    def residual(p):
        return target - drift_model(data, p[0], p[1:], k_count).ravel()

    def jacobian(p):
        jac = np.empty((target.size, len(p)))
        jac[:, 0] = -data.project(np.tensordot(p[1:], drift_design(data, p[0], k_count, True), axes=1)).ravel()
        jac[:, 1:] = -data.project(drift_design(data, p[0], k_count)).reshape(2 * k_count, -1).T
        return jac

    fit = least_squares(residual, np.concatenate([[nu0], coef0]), jac=jacobian, x_scale="jac", method="lm",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    rss = float(fit.fun @ fit.fun)
    dof = max(1, target.size - data.nuisance_dof() - len(fit.x))
    sigma2 = rss / dof
    cov = np.linalg.pinv(fit.jac.T @ fit.jac) * sigma2
    return {"nu": float(fit.x[0]), "coef": fit.x[1:], "rss": rss, "sigma2": sigma2,
            "std_fit_nu": float(math.sqrt(max(cov[0, 0], 0.0))), "converged": bool(fit.success)}


def local_minima(values: np.ndarray) -> np.ndarray:
    """Indices of the local minima of values, the ends included when they hold the global minimum."""
    inner = np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:])) + 1
    ends = [i for i in (0, len(values) - 1) if len(values) > 1 and values[i] == values.min()]
    return np.unique(np.concatenate([inner, np.array(ends, dtype=int)]))


def distinct_phases(phase0: np.ndarray) -> int:
    """How many different flicker phases (cycles, mod 1; PHASE_TOLERANCE apart) the frames have."""
    x = np.sort(np.mod(phase0, 1.0))
    if len(x) == 0:
        return 0
    gaps = np.diff(np.concatenate([x, [x[0] + 1.0]]))
    return max(1, int(np.sum(gaps > PHASE_TOLERANCE)))


def _candidates(data: LogProfiles, nu_lo: float, nu_hi: float, sign: int, k_count: int) -> tuple[list, np.ndarray,
                                                                                                  np.ndarray]:
    """(candidates (ν, RSS with all harmonics) best first, the grid of ν, its fundamental-only RSS):
    a grid over ±[nu_lo, nu_hi] (one sign when sign != 0) on the first COARSE_FRAMES frames, its
    six deepest local minima refined by a bounded search with k_count harmonics on all frames."""
    span = data.span
    step = 0.08 / span
    positive = np.arange(nu_lo, nu_hi + 0.5 * step, step)
    grid = np.concatenate([-positive[::-1] if sign <= 0 else [], positive if sign >= 0 else []])
    coarse = data.subset(np.arange(min(data.frames, COARSE_FRAMES))) if data.frames > COARSE_FRAMES else data
    rss1 = np.array([profile_rss(coarse, nu, 1)[0] for nu in grid])
    minima = sorted(local_minima(rss1), key=lambda i: rss1[i])[:6]
    candidates: list = []
    for i in minima:
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        res = minimize_scalar(lambda x: profile_rss(data, x, k_count)[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-3 / span})
        if all(abs(res.x - c[0]) > 0.3 / span for c in candidates):
            candidates.append((float(res.x), float(res.fun)))
    candidates.sort(key=lambda c: c[1])
    return candidates, grid, rss1


def _phase_consistency(data: LogProfiles, fit: dict, k_count: int) -> tuple[float, np.ndarray, float]:
    """(the joint fit's F against free per-frame phases at the same ν, each frame's own band phase
    off the timestamps' prediction (cycles), their rms weighted by amplitude): the timestamps and
    the frequency must fit the bands."""
    rss_free = float(np.sum(frame_rss(data, fit["nu"], k_count)))
    extra = 2 * k_count * (data.frames - 1)
    dof_free = max(1, data.frames * data.rows_used - data.nuisance_dof() - 2 * k_count * data.frames)
    joint_f = ((fit["rss"] - rss_free) / extra) / (rss_free / dof_free) if extra > 0 and rss_free > 0 else 0.0
    free = frame_amplitudes(data, fit["nu"])                          # (2, frames)
    measured = free[0] - 1j * free[1]
    predicted = (fit["coef"][0] - 1j * fit["coef"][1]) * np.exp(2j * np.pi * data.phase0)
    weight = np.abs(measured)
    offsets = np.angle(measured / np.where(predicted == 0, 1.0, predicted)) / (2 * np.pi)
    phase_rms = float(np.sqrt(np.sum(weight * offsets ** 2) / max(weight.sum(), 1e-300)))
    return float(joint_f), offsets, phase_rms


def _block_spread(data: LogProfiles, nu: float, k_count: int) -> tuple[np.ndarray, float]:
    """(ν of contiguous blocks of frames, the σ of their mean) — contiguous: interleaving can give
    every block the same flicker phase when the rates are commensurate. Three blocks at least."""
    span = data.span
    groups = min(6, data.frames // 3)
    subset_nu = []
    if groups >= 3:
        for block in np.array_split(np.arange(data.frames), groups):
            sub = data.subset(block)
            if distinct_phases(sub.phase0) < 2:
                continue
            res = minimize_scalar(lambda x, d=sub: profile_rss(d, x, k_count)[0],
                                  bounds=(nu - 0.2 / span, nu + 0.2 / span), method="bounded",
                                  options={"xatol": 1e-5 / span})
            subset_nu.append(float(res.x))
    subset_nu = np.array(subset_nu)
    std = float(np.std(subset_nu, ddof=1) / math.sqrt(len(subset_nu))) if len(subset_nu) >= 3 else float("nan")
    return subset_nu, std


def _refusal(data: LogProfiles, out: dict, candidates: list, k_count: int) -> dict:
    """ok=False with the reason when the drift fit is no evidence of flicker, aliased, off the
    timestamps, or too short to tell bands from the scene ({} when it stands); failed_check names
    which: evidence, alias, phase, periods."""
    nu, delta_chi2 = out["nu"], out["delta_chi2"]
    ambiguity = out["ambiguity_delta_chi2"]
    if delta_chi2 < MIN_DELTA_CHI2 + 4 * 2 * k_count:
        return {"ok": False, "failed_check": "evidence",
                "reason": f"no flicker found (the fit lowers chi2 by only {delta_chi2:.0f})"}
    if ambiguity is not None and ambiguity < AMBIGUITY_DELTA_CHI2:
        alias = candidates[1][0]
        return {"ok": False, "failed_check": "alias", "alias_nu": alias, "reason": f"aliased: {nu:.6g} and {alias:.6g} cycles/row fit about "
                                                          f"equally well (delta chi2 {ambiguity:.1f})"}
    if out["phase_rms_cycles"] > PHASE_RMS_MAX:
        return {"ok": False, "failed_check": "phase", "reason": "the band phases do not drift as the timestamps and the frequency predict "
                                       f"(each frame's own band phase is off by {out['phase_rms_cycles']:.3f} cycles "
                                       f"rms; joint fit {out['joint_vs_free_f']:.1f}x worse per amplitude than free "
                                       "phases): inexact timestamps or frequency, or a moving scene"}
    if data.detrend == "smooth" and abs(nu) * data.span < SPECTRUM_MIN_CYCLES:
        return {"ok": False, "failed_check": "periods", "reason": f"{abs(nu) * data.span:.2f} periods per frame and no phase drift between "
                                       "frames: bands cannot be told from scene structure"}
    return {}


def phase_drift_estimate(data: LogProfiles, nu_lo: float, nu_hi: float, kmax: int, sign: int) -> dict:
    """One phase for all frames through their timestamps, ν in ±[nu_lo, nu_hi] (sign > 0 / < 0:
    one side only), at most kmax harmonics: a dict with method, ok, and nu, its σ (std_fit_nu,
    std_spread_nu), the amplitudes and the tests' numbers, or the reason it is not ok.

    With few distinct flicker phases Q among the frames, harmonic k' of another ν' reproduces
    harmonic k of the true one when k' ≡ ±k (mod Q) and k'ν' = ±kν (the whole-cycle alternatives
    of the drift between frames): every local minimum is a candidate, and the best must win."""
    out: dict = {"method": "phase-drift", "ok": False}
    q = distinct_phases(data.phase0)
    out["distinct_phases"] = q
    if q < 2:
        out["reason"] = ("every frame has the same flicker phase: no drift between frames (frame rate and "
                         "flicker commensurate)")
        return out
    k_count = harmonics_at(nu_hi, kmax)
    candidates, grid, rss1 = _candidates(data, nu_lo, nu_hi, sign, k_count)
    out["grid_nu"], out["grid_rss"] = grid, rss1
    _, coef0 = profile_rss(data, candidates[0][0], k_count)
    fit = refine(data, candidates[0][0], coef0, k_count)
    out["candidates_nu"] = [c[0] for c in candidates]
    second = candidates[1][1] if len(candidates) > 1 else np.inf
    out["ambiguity_delta_chi2"] = float((second - fit["rss"]) / fit["sigma2"]) if np.isfinite(second) else None
    delta_chi2 = (data.null_rss() - fit["rss"]) / fit["sigma2"]
    out.update(ok=True, nu=fit["nu"], std_fit_nu=fit["std_fit_nu"], coef=fit["coef"], harmonics=k_count,
               delta_chi2=float(delta_chi2), rss=fit["rss"], sigma2=fit["sigma2"], converged=fit["converged"])
    joint_f, offsets, phase_rms = _phase_consistency(data, fit, k_count)
    out["joint_vs_free_f"] = joint_f
    out["phase_offsets_cycles"] = offsets
    out["phase_rms_cycles"] = phase_rms
    subset_nu, std_spread = _block_spread(data, fit["nu"], k_count)
    out["per_frame_nu"] = subset_nu
    out["spread_label"] = "frame block"
    out["std_spread_nu"] = std_spread
    out.update(_refusal(data, out, candidates, k_count))
    return out
