"""The initial Sum-of-Gaussians bank of the self-calibration filter (Civera et al. 2009, §V).

For 320x240 images the paper covers ``f`` in [100, 610] px with 18 Gaussians 30 px apart (sigma 7.5
px = spacing / 4), ``k1`` in [0, 0.08] mm^-2 with 2 and ``k2`` in [0, 0.018] mm^-4 with 3 Gaussians
(every combination: 108), and the principal point with one Gaussian at the image centre with sigma
10/3 px. Means are spaced evenly over each range, ends included (for ``f`` that reproduces the paper's
18 x 30 px exactly), and each sigma is a quarter of its spacing. docs/sog.md §10.

Scaling to other images: pixel quantities (``f``, the principal point sigma) scale with the image
diagonal relative to 400 px (320x240); the distortion ranges scale with the sensor's half diagonal in
mm, ``r``, relative to the paper's 0.0112 mm x 200 px = 2.24 mm, as ``(2.24 / r)^2`` for ``k1`` and
``(2.24 / r)^4`` for ``k2`` — so that ``k1 r^2`` and ``k2 r^4`` at the image corner span the same
range as in the paper.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Optional, Sequence, Union

import numpy as np

from .._core import SogBank, SogOptions
from ..errors import InputError
from ..reference_cameras import PAPER_PIXEL_SIZE_MM

__all__ = ["InitialBank", "initial_bank", "make_bank", "single_gaussian_grid"]

_PAPER_DIAGONAL_PX = 400.0
_PAPER_HALF_DIAGONAL_MM = PAPER_PIXEL_SIZE_MM * 200.0


@dataclass
class InitialBank:
    """Initial Gaussians: ``means`` (N, 5) [f, cx, cy, k1, k2], ``covs`` (N, 5, 5), ``weights`` (N,)."""

    means: np.ndarray
    covs: np.ndarray
    weights: np.ndarray

    def __len__(self) -> int:
        return len(self.means)


def _grid(lo: float, hi: float, count: int, sigma_fraction: float) -> tuple[np.ndarray, float]:
    if count < 1:
        raise InputError("initial_bank: every grid needs at least one Gaussian")
    if count == 1:
        # One Gaussian covering the range: its half-width is two sigma.
        return np.array([0.5 * (lo + hi)]), max(0.25 * (hi - lo), 1e-12)
    means = np.linspace(lo, hi, count)
    return means, sigma_fraction * (means[1] - means[0])


def _pixel_pair(pixel_size_mm: Union[float, Sequence[float]]) -> np.ndarray:
    p = np.broadcast_to(np.asarray(pixel_size_mm, dtype=np.float64).reshape(-1), (2,)).copy()
    if not np.all(p > 0):
        raise InputError("pixel_size_mm must be positive")
    return p


def initial_bank(width: int, height: int, pixel_size_mm: Union[float, Sequence[float]] = PAPER_PIXEL_SIZE_MM, *,
                 f_range: Optional[tuple[float, float]] = None, f_count: int = 18,
                 k1_range: Optional[tuple[float, float]] = None, k1_count: int = 2,
                 k2_range: Optional[tuple[float, float]] = None, k2_count: int = 3,
                 principal_point: Optional[tuple[float, float]] = None,
                 principal_sigma_px: Optional[float] = None,
                 sigma_fraction: float = 0.25) -> InitialBank:
    """The paper's grid of Gaussians, scaled to a ``width`` x ``height`` image.

    Ranges given explicitly are used as they are (px, mm^-2, mm^-4); ``None`` means the paper's
    range scaled to this image (module docstring). ``principal_point`` defaults to the image centre
    ((w - 1) / 2, (h - 1) / 2) in OpenCV's pixel convention. Weights are uniform.
    """
    if width <= 0 or height <= 0:
        raise InputError("initial_bank: image size must be positive")
    pixel = _pixel_pair(pixel_size_mm)
    scale_px = np.hypot(width, height) / _PAPER_DIAGONAL_PX
    half_diag_mm = np.hypot(pixel[0] * width, pixel[1] * height) / 2.0
    scale_r2 = (_PAPER_HALF_DIAGONAL_MM / half_diag_mm) ** 2
    if f_range is None:
        f_range = (100.0 * scale_px, 610.0 * scale_px)
    if k1_range is None:
        k1_range = (0.0, 0.08 * scale_r2)
    if k2_range is None:
        k2_range = (0.0, 0.018 * scale_r2 ** 2)
    if principal_point is None:
        principal_point = ((width - 1) / 2.0, (height - 1) / 2.0)
    if principal_sigma_px is None:
        principal_sigma_px = 10.0 / 3.0 * scale_px
    f_means, f_sigma = _grid(*f_range, f_count, sigma_fraction)
    k1_means, k1_sigma = _grid(*k1_range, k1_count, sigma_fraction)
    k2_means, k2_sigma = _grid(*k2_range, k2_count, sigma_fraction)
    means = np.array([[f, principal_point[0], principal_point[1], k1, k2]
                      for f, k1, k2 in product(f_means, k1_means, k2_means)], dtype=np.float64)
    sigmas = np.array([f_sigma, principal_sigma_px, principal_sigma_px, k1_sigma, k2_sigma])
    covs = np.broadcast_to(np.diag(sigmas ** 2), (len(means), 5, 5)).copy()
    weights = np.full(len(means), 1.0 / len(means))
    return InitialBank(means=means, covs=covs, weights=weights)


def single_gaussian_grid(width: int, height: int,
                         pixel_size_mm: Union[float, Sequence[float]] = PAPER_PIXEL_SIZE_MM, *,
                         f_range: Optional[tuple[float, float]] = None, f0: Optional[float] = None,
                         f_sigma: Optional[float] = None) -> dict:
    """:func:`initial_bank` keyword arguments for one Gaussian, a single EKF (the baseline the paper
    compares against): ``f0`` (default: the middle of the f range) with sigma ``f_sigma`` (default: a
    quarter of the range), principal point and distortion at the middle of their ranges."""
    grid = {} if f_range is None else {"f_range": tuple(f_range)}
    default = initial_bank(width, height, pixel_size_mm, **grid)
    f_lo, f_hi = default.means[:, 0].min(), default.means[:, 0].max()
    f0 = 0.5 * (f_lo + f_hi) if f0 is None else f0
    f_sigma = 0.25 * (f_hi - f_lo) if f_sigma is None else f_sigma
    if not f0 > 0 or not f_sigma > 0:
        raise InputError("f0 and f_sigma must be positive")
    # _grid gives a count-1 grid the range's middle and sigma range/4.
    return {**grid, "f_range": (f0 - 2 * f_sigma, f0 + 2 * f_sigma), "f_count": 1, "k1_count": 1, "k2_count": 1}


def make_bank(width: int, height: int, pixel_size_mm: Union[float, Sequence[float]] = PAPER_PIXEL_SIZE_MM,
              options: Optional[SogOptions] = None, bank: Optional[InitialBank] = None,
              **grid) -> SogBank:
    """A ready :class:`rscalib._core.SogBank` over :func:`initial_bank` (``grid`` is passed on)."""
    if bank is None:
        bank = initial_bank(width, height, pixel_size_mm, **grid)
    if options is None:
        options = SogOptions()
    return SogBank(options, bank.means, bank.covs, bank.weights, (int(width), int(height)),
                         _pixel_pair(pixel_size_mm))
