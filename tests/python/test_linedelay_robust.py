"""Robust loss against bad detections, and the warnings that flag them."""
import numpy as np
import pytest

import rscalib
from rscalib import simulate
from rscalib.linedelay import calibrate_line_delay


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
    result = calibrate_line_delay(obs, camera, robust_loss="huber")
    assert abs(result.line_delay_s - sim.line_delay_s) / sim.line_delay_s < 0.01
    assert abs(result.line_delay_s - sim.line_delay_s) <= 3 * result.line_delay_std_s


def test_outliers_without_robust_loss_are_flagged(corrupted):
    sim, obs, camera = corrupted
    result = calibrate_line_delay(obs, camera)
    assert result.normalised_cost > 1.5
    assert any("J/2N" in w and "huber" in w for w in result.warnings)
