"""Robust loss against bad detections, and the warnings that flag them."""
import numpy as np
import pytest

import rscalib
from rscalib.linedelay.options import LineDelayOptions
from rscalib.linedelay.spline import calibrate_line_delay
from rscalib.sim import target_observations as simulate


@pytest.fixture(scope="module")
def corrupted():
    sim = simulate.simulate_default(line_delay_s=40e-6, duration_s=10.0, seed=11, noise_px=0.3)
    obs = sim.observations
    rng = np.random.default_rng(5)
    bad = rng.choice(obs.num_observations, size=obs.num_observations // 50, replace=False)  # 2 % outliers
    uv = obs.uv.copy()
    uv[bad] += rng.normal(0.0, 8.0, size=(len(bad), 2))
    corrupted = rscalib.Observations(obs.frame_times_s, obs.frame_index, obs.point_id, uv, obs.target_points,
                                     obs.image_size)
    camera = rscalib.CameraModel(sim.camera.model, sim.camera.params, 640, 480)
    return sim, corrupted, camera


def test_huber_loss_recovers_the_line_delay_despite_outliers(corrupted):
    sim, obs, camera = corrupted
    result = calibrate_line_delay(obs, camera, LineDelayOptions(robust_loss="huber"))
    assert abs(result.line_delay_s - sim.line_delay_s) / sim.line_delay_s < 0.01
    assert abs(result.line_delay_s - sim.line_delay_s) <= 3 * result.line_delay_std_s


def test_outliers_without_robust_loss_are_flagged(corrupted):
    sim, obs, camera = corrupted
    result = calibrate_line_delay(obs, camera)
    assert result.normalised_cost > 1.5
    assert any("J/2N" in w and "huber" in w for w in result.warnings)


def _shaky(seed: int, duration_s: float = 4.0):
    camera = simulate.SimCamera("pinhole-radtan", np.array([500.0, 500.0, 319.5, 239.5, -0.1, 0.05, 0, 0, 0]), 640, 480)
    points = simulate.checkerboard_points()
    trajectory = simulate.HandheldTrajectory(duration_s=duration_s, seed=seed, freq_range_hz=(0.5, 8.0),
                                             target_center_m=0.5 * (points.min(axis=0) + points.max(axis=0)),
                                             distance_m=simulate.standoff_distance_m(camera, points))
    sim = simulate.simulate_observations(camera, 30e-6, fps=30.0, duration_s=duration_s, noise_px=0.3, seed=seed,
                                         trajectory=trajectory)
    return sim, rscalib.CameraModel(camera.model, camera.params, 640, 480)


def test_hand_shake_is_followed_with_knots_down_to_one_frame():
    # 0.5-8 Hz shake: a 2-frame knot floor left J/2N ~ 75 and d several % off with a 0.15 % sigma.
    sim, camera = _shaky(seed=1)
    result = calibrate_line_delay(sim.observations, camera, LineDelayOptions(pixel_sigma_px=0.3))
    assert result.normalised_cost < 1.2
    assert abs(result.line_delay_s - 30e-6) / 30e-6 < 0.01
    assert abs(result.line_delay_s - 30e-6) <= 3 * result.line_delay_std_s


def test_knots_at_the_floor_that_still_fit_badly_are_flagged():
    sim, camera = _shaky(seed=1)
    result = calibrate_line_delay(sim.observations, camera, LineDelayOptions(pixel_sigma_px=0.3, min_segment_s=1.0 / 30.0))
    assert result.normalised_cost > 1.5
    assert any("shortest allowed length" in w for w in result.warnings)
