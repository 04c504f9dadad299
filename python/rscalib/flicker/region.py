"""The region of the frames that carries flicker bands: which column strips, which rows.

Real footage rarely shows bands everywhere: an LED or diffuser lights part of the frame (dark
corners, vignetting), text or a measurement box is overlaid, an out-of-focus blob covers a side.
:func:`choose_region` keeps the strips whose own row spectrum peaks where the other strips' do
(agreement between strips), leaves out cells (row × strip) that are unlit, and masks cells that
stand out from the other strips (overlays, blobs); then it combines the strips into the row
profile, each strip scaled to the common level so that leaving a strip out of a row makes no step.
A region given by the user (``roi``) overrides the choice of strips; unlit cells are still left out.
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy.ndimage import binary_dilation, maximum_filter1d, median_filter

from .profiles import RowProfiles, combine_strips

STRONG_PEAK = 30.0       # a strip shows bands: its periodogram peak over its median
AGREE_FRACTION = 0.1     # ... and has at least this share of its peak power at the common peak
LIT_FRACTION = 0.1       # a cell is lit above black + this fraction of the black-to-bright range
OUTLIER_MADS = 6.0       # a cell whose level differs from the other strips by this many MADs is masked
LOG_FLOOR = 0.02         # log(p + floor·bright): black bands stay finite


def _log(values: np.ndarray, bright: float) -> np.ndarray:
    return np.log(np.maximum(values, 0.0) + LOG_FLOOR * bright)


def _strip_spectra(y: np.ndarray, lit: np.ndarray, temporal: bool) -> tuple[np.ndarray, np.ndarray]:
    """(freqs, power (S, F)): summed periodogram of each strip's detrended log profile."""
    frames, rows, count = y.shape
    if temporal:
        z = y - y.mean(axis=0, keepdims=True)
    else:
        x = np.linspace(-1.0, 1.0, rows)
        basis = np.polynomial.legendre.legvander(x, 3)
        z = np.empty_like(y)
        for s in range(count):
            w = lit[:, s].astype(np.float64)
            if w.sum() < 8:
                z[:, :, s] = 0.0
                continue
            coef, *_ = np.linalg.lstsq(basis * w[:, None], (y[:, :, s] * w[None, :]).T, rcond=None)
            z[:, :, s] = y[:, :, s] - (basis @ coef).T
    z = np.where(lit[None], z, 0.0)
    nfft = 1 << int(np.ceil(np.log2(4 * rows)))
    spectrum = np.fft.rfft(z * np.hanning(rows)[None, :, None], n=nfft, axis=1)
    return np.arange(spectrum.shape[1]) / nfft, np.sum(np.abs(spectrum) ** 2, axis=0).T


def _common_peak(freqs, power, span) -> tuple[np.ndarray, float, np.ndarray]:
    """(strong strips, common peak frequency, ratio of each strip's peak to its median)."""
    band = (freqs >= 2.0 / span) & (freqs <= 0.45)
    if not np.any(band):
        return np.zeros(power.shape[0], bool), float("nan"), np.zeros(power.shape[0])
    p = power[:, band]
    ratio = p.max(axis=1) / np.maximum(np.median(p, axis=1), 1e-300)
    strong = (ratio >= STRONG_PEAK) & (p.max(axis=1) > 0)
    if not np.any(strong):
        return strong, float("nan"), ratio
    common = np.sum(p[strong] / p[strong].max(axis=1, keepdims=True), axis=0)
    return strong, float(freqs[band][int(np.argmax(common))]), ratio


def _lit_cells(brightest: np.ndarray, black: float, bright: float, window: int) -> np.ndarray:
    """(rows, S) cells that light reaches within ±window rows."""
    envelope = maximum_filter1d(brightest, size=2 * window + 1, axis=0, mode="nearest")
    return envelope > black + LIT_FRACTION * (bright - black) if bright > black else np.ones_like(envelope, bool)


def _strips_with_bands(y: np.ndarray, lit: np.ndarray, frames: int, count: int, span: float) -> tuple:
    """(strips kept, the strips' common peak ν or nan, a note): the strips whose own row spectrum
    peaks strongly where the others' do (removing the scene over frames first, then per frame)."""
    strong, peak_nu = np.zeros(count, bool), float("nan")
    for temporal in ([True, False] if frames >= 3 else [False]):
        freqs, power = _strip_spectra(y, lit, temporal)
        strong, peak_nu, _ = _common_peak(freqs, power, span)
        if np.any(strong):
            break
    if not np.any(strong):
        return np.ones(count, dtype=bool), peak_nu, \
            "no strip shows clear bands (fewer than 2 periods per frame?): every lit strip used"
    near = np.abs(freqs - peak_nu) <= 1.0 / span
    at_peak = power[:, near].max(axis=1)
    band = (freqs >= 2.0 / span) & (freqs <= 0.45)
    keep = strong & (at_peak >= AGREE_FRACTION * power[:, band].max(axis=1))
    return keep, peak_nu, f"{int(keep.sum())} of {count} column strips show the same bands"


def _gains_and_masks(profiles: RowProfiles, y: np.ndarray, use: np.ndarray, keep: np.ndarray,
                     window: int) -> tuple[np.ndarray, np.ndarray]:
    """(each strip's gain to the strips' median level, the cells masked as standing out from the
    other strips: overlays, blobs)."""
    count = len(keep)
    masked = np.zeros_like(use)
    gains = np.ones(count)
    mean_y = y.mean(axis=0)                                          # (rows, S)
    if keep.sum() < 2:
        return gains, masked
    with warnings.catch_warnings():  # rows without a used cell: NaN, expected
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = np.nanmedian(np.where(use, mean_y, np.nan), axis=1)    # (rows,)
    diff = mean_y - ref[:, None]
    for s in np.flatnonzero(keep):
        cells = use[:, s] & np.isfinite(ref)
        if cells.sum() >= 8:
            gains[s] = float(np.exp(-np.median(diff[cells, s])))
    if keep.sum() < 3:
        return gains, masked
    dev = diff + np.log(gains)[None, :]
    trend = median_filter(np.where(use, dev, 0.0), size=(2 * window + 1, 1), mode="nearest")
    resid = np.where(use & np.isfinite(dev), dev - trend, np.nan)
    mad = float(np.nanmedian(np.abs(resid - np.nanmedian(resid)))) if np.any(np.isfinite(resid)) else 0.0
    if mad == 0 and profiles.strip_clipped is not None:
        # most cells clipped alike: judge by the spread of the unclipped ones
        spread = np.where(profiles.strip_clipped, np.nan, resid)
        if np.any(np.isfinite(spread)):
            mad = float(np.nanmedian(np.abs(spread - np.nanmedian(spread))))
    if np.any(np.isfinite(resid)):
        masked = np.isfinite(resid) & (np.abs(resid) > OUTLIER_MADS * 1.4826 * mad + 0.02)
        masked = binary_dilation(masked, structure=np.ones((5, 1), bool)) & use
    return gains, masked


def _region_record(profiles: RowProfiles, auto: bool, note: str, keep: np.ndarray, use: np.ndarray,
                   lit: np.ndarray, masked: np.ndarray, peak_nu: float) -> dict:
    """What was chosen, as result.json's `region`: the strips and their column spans, the bounding
    box of the rows used, the cells masked, unlit and clipped, the strips' common band period."""
    count = len(keep)
    columns = profiles.strip_columns[keep]
    spans = []
    for x0, x1 in columns.tolist():
        if spans and spans[-1][1] == x0:
            spans[-1][1] = x1
        else:
            spans.append([x0, x1])
    used_rows = np.flatnonzero(use.any(axis=1))
    v0 = int(profiles.rows_v[used_rows[0]]) if len(used_rows) else 0
    v1 = int(profiles.rows_v[used_rows[-1]]) + 1 if len(used_rows) else 0
    box = [int(columns[:, 0].min()), v0, int(columns[:, 1].max() - columns[:, 0].min()), v1 - v0] if len(columns) \
        else None
    return {"mode": "auto" if auto else "given", "note": note, "strips_used": int(keep.sum()),
            "strips_total": int(count), "columns": spans, "bounding_box_xywh": box,
            "rows_used": int(len(used_rows)), "cells_masked": int(masked.sum()),
            "cells_unlit": int((~lit & keep[None, :]).sum()),
            "rows_clipped": int(np.sum((profiles.strip_clipped & use).sum(axis=1) > 0.5 * use.sum(axis=1))),
            "common_peak_period_rows": (1.0 / peak_nu) if np.isfinite(peak_nu) and peak_nu > 0 else None}


def choose_region(profiles: RowProfiles, auto: bool = True) -> dict:
    """Choose the strips and rows with bands, set ``profiles.values`` to their combination and
    ``profiles.region`` to what was chosen; returns the region dict. ``auto`` False (a region
    given by the user): every strip is kept."""
    strips = profiles.strips.astype(np.float64)
    frames, rows, count = strips.shape
    brightest = strips.max(axis=0)                                   # (rows, S)
    black = float(np.percentile(strips, 1.0))
    bright = float(np.percentile(brightest, 99.5))
    window = max(4, rows // 16)
    lit = _lit_cells(brightest, black, bright, window)
    y = _log(strips, max(bright, 1e-12))
    keep = np.ones(count, dtype=bool)
    note = "region given" if not auto else ""
    peak_nu = float("nan")
    if auto and count > 1:
        keep, peak_nu, note = _strips_with_bands(y, lit, frames, count, float(rows))
    if np.isfinite(peak_nu) and peak_nu > 0 and 1.0 / peak_nu > window:
        # a dark band is the light off, not an unlit part of the scene: look a whole period for light
        lit = _lit_cells(brightest, black, bright, int(np.ceil(1.0 / peak_nu))) if bright > black else lit
    use = lit & keep[None, :]
    # per-strip level relative to the strips' median profile, and cells that stand out from it
    gains, masked = _gains_and_masks(profiles, y, use, keep, window)
    use = use & ~masked
    profiles.values = combine_strips(profiles, use, gains)
    region = _region_record(profiles, auto, note, keep, use, lit, masked, peak_nu)
    profiles.region = region
    return region
