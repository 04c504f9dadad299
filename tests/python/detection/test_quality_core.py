"""The blur measure's core halves (rscalib._core.edge_profile_maps, edge_width_from_profiles)
against the numpy formulation they replaced, written out here: the same numbers to the bit, on
random edges (some degenerate, short or outside the image) and random profiles."""
import numpy as np
import pytest

from rscalib import _core
from rscalib.detection.quality import _PROFILE_S


def numpy_maps(a, b, circles: bool, fraction: float):
    length = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
    ok = length > 1e-6
    a, b, length = a[ok], b[ok], length[ok]
    t = (b - a) / length[:, None]
    if circles:
        centre = np.concatenate([a, b]) + np.concatenate([t, -t]) * (np.concatenate([length, length]) * fraction)[:, None]
        direction = np.concatenate([t, -t])
        half = np.concatenate([length, length]) * fraction
    else:
        centre = 0.5 * (a + b)
        direction = np.column_stack([-t[:, 1], t[:, 0]])
        half = length * fraction
    half = np.minimum(half, 16.0)
    keep = half >= 1.5
    centre, direction, half = centre[keep], direction[keep], half[keep]
    s = _PROFILE_S[None, :] * half[:, None]
    return ((centre[:, 0:1] + s * direction[:, 0:1]).astype(np.float32),
            (centre[:, 1:2] + s * direction[:, 1:2]).astype(np.float32), half)


def numpy_width(profiles, half):
    samples = profiles.shape[1]
    profiles = profiles.astype(np.float64)
    profiles = (profiles[:, :-2] + profiles[:, 1:-1] + profiles[:, 2:]) / 3.0
    step = 2.0 * half / (samples - 1)
    ends = max(2, samples // 12)
    contrast = np.abs(profiles[:, -ends:].mean(1) - profiles[:, :ends].mean(1))
    slope = np.abs(np.diff(profiles, axis=1)).max(1) / step
    valid = (contrast > 20.0) & (slope > 0)
    if not valid.any():
        return float("nan")
    return float(np.percentile(np.maximum(contrast[valid] / slope[valid] - step[valid], 0.0), 75))


@pytest.mark.parametrize("circles, fraction", [(False, 0.4), (False, 0.15), (True, 0.25)])
def test_profile_maps_are_numpys_to_the_bit(circles, fraction):
    rng = np.random.default_rng(7)
    for _ in range(200):
        m = int(rng.integers(1, 120))
        a = rng.uniform(-50, 700, (m, 2))
        b = a + rng.normal(0, rng.choice([0.5, 5, 40, 200]), (m, 2))
        a[rng.random(m) < 0.03] = np.nan   # a corner not found: left out
        same = rng.random(m) < 0.05        # zero-length edges are left out
        b[same] = a[same]
        expected = numpy_maps(a, b, circles, fraction)
        got = _core.edge_profile_maps(a, b, circles, fraction, _PROFILE_S, 16.0, 1.5)
        for e, g in zip(expected, got):
            assert e.shape == g.shape and np.array_equal(e, g)


def test_width_is_numpys_to_the_bit():
    rng = np.random.default_rng(3)
    ramps = np.clip(np.linspace(-3, 3, 48), -1, 1)
    for trial in range(400):
        m = int(rng.integers(1, 150))
        low, high = rng.uniform(0, 120, (m, 1)), rng.uniform(60, 255, (m, 1))
        edge = ramps[None, :] * rng.uniform(0.3, 6, (m, 1))
        profiles = np.clip(low + (high - low) * (0.5 + 0.5 * np.tanh(edge)) + rng.normal(0, 3, (m, 48)), 0, 255)
        profiles = np.round(profiles).astype(np.uint8).astype(np.float64)
        if trial % 10 == 0:
            profiles[:] = profiles[:, :1]   # flat: no edge, NaN
        half = rng.uniform(1.5, 16.0, m)
        expected = numpy_width(profiles, half)
        got = _core.edge_width_from_profiles(profiles, half, 20.0)
        assert (np.isnan(expected) and np.isnan(got)) or got == expected


def test_width_checks_its_input():
    with pytest.raises(ValueError, match="one value per profile"):
        _core.edge_width_from_profiles(np.zeros((3, 48)), np.ones(2), 20.0)
    with pytest.raises(ValueError, match="one row per edge"):
        _core.edge_profile_maps(np.zeros((3, 2)), np.zeros((2, 2)), False, 0.4, _PROFILE_S, 16.0, 1.5)
