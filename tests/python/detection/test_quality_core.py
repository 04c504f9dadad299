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


def numpy_saddles(values, even):
    """The tracker's saddle decision as numpy wrote it (values: (n, 4) grey levels at the samples)."""
    diagonal_bright = values[:, :2].min(1) - values[:, 2:].max(1)
    anti_bright = values[:, 2:].min(1) - values[:, :2].max(1)
    convention = np.where(even, diagonal_bright, anti_bright)
    other = np.where(even, anti_bright, diagonal_bright)
    gap = convention if np.median(convention) >= np.median(other) else other
    contrast = np.median(values.max(1) - values.min(1))
    return bool(contrast >= 20.0 and gap.min() >= 0.25 * contrast)


def numpy_saddle_points(grid):
    """The four sample places of each corner of a (rows, cols, 2) grid, as numpy computed them."""
    along_cols, along_rows = np.gradient(grid, axis=1), np.gradient(grid, axis=0)
    diagonal, anti = along_cols + along_rows, along_cols - along_rows
    points = np.stack([grid + 0.3 * diagonal, grid - 0.3 * diagonal, grid + 0.3 * anti, grid - 0.3 * anti],
                      axis=2).reshape(-1, 4, 2).astype(np.float32)
    return points[..., 0], points[..., 1]


def test_saddle_places_and_decision_are_numpys():
    rng = np.random.default_rng(11)
    decisions = []
    for trial in range(300):
        rows, cols = int(rng.integers(2, 9)), int(rng.integers(2, 12))
        step = rng.uniform(5, 60)
        r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
        grid = np.stack([c * step, r * step * rng.uniform(0.6, 1.4)], axis=2) + rng.uniform(0, 300, 2)
        grid += rng.normal(0, rng.choice([0.01, 0.5, 3.0]), grid.shape)
        expected = numpy_saddle_points(grid)
        got = _core.saddle_sample_points(grid.reshape(-1, 2), rows, cols, 0.3)
        assert all(np.array_equal(e, g) for e, g in zip(expected, got))
        even = ((r + c) % 2 == 0).ravel()
        bright, dark = rng.uniform(120, 255), rng.uniform(0, 110)
        values = np.where(even[:, None], [[bright, bright, dark, dark]], [[dark, dark, bright, bright]])
        if trial % 2:
            values = values[:, [2, 3, 0, 1]]   # the other colour convention
        values = np.clip(values + rng.normal(0, rng.choice([1, 20, 60]), values.shape), 0, 255).round()
        decision = _core.corners_are_saddles(values, even, 20.0, 0.25)
        assert decision == numpy_saddles(values, even)
        decisions.append(decision)
    assert 0 < sum(decisions) < len(decisions)   # both answers were tested
