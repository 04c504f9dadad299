"""Each observation's score of d (RsSolverOptions.line_delay_score, the C++ Schur pass): checked
against a re-solve with one corner moved (finite differences) and against the Schur variance."""
import numpy as np

from rscalib import CameraModel
from rscalib.linedelay.spline import calibrate_line_delay
from rscalib.observations import Observations
from rscalib.sim.target_observations import simulate_default

FIXED = dict(adaptive_knots=False, num_segments=40, noise_model="video", pixel_sigma=0.3,
             standardise_errors=False)


def _scenario():
    sim = simulate_default(line_delay_s=30e-6, duration_s=2.0, seed=5)
    c = sim.camera
    return sim.observations, CameraModel(c.model, c.params, c.width, c.height)


def test_scores_predict_the_change_of_d_when_one_corner_moves():
    obs, camera = _scenario()
    base = calibrate_line_delay(obs, camera, line_delay_score=True, **FIXED)
    score = base.line_delay_score
    assert score.shape == base.used_observations.uv.shape
    used = base.used_observations
    k = int(np.argmax(np.abs(score[:, 1])))   # the most influential row coordinate (v)
    step_px = 0.2
    uv = used.uv.copy()
    uv[k, 1] += step_px
    moved = calibrate_line_delay(Observations(used.frame_times_s, used.frame_index, used.point_id, uv,
                                              used.target_points, used.image_size), camera, **FIXED)
    # d_hat - d = -sum s_i with s_i = (J_i g) r_i, r_i = +-e_i / sigma: moving y by dy changes d by -s dy / e
    predicted = -score[k, 1] * step_px / base.residual_px[k, 1]
    observed = moved.line_delay_s - base.line_delay_s
    assert abs(observed) > 0
    assert abs(observed - predicted) < 0.02 * abs(observed)


def test_scores_sum_to_zero_and_their_squares_to_the_schur_variance():
    obs, camera = _scenario()
    r = calibrate_line_delay(obs, camera, line_delay_score=True, **FIXED)
    s = r.line_delay_score
    spread = np.sqrt(np.sum(s ** 2))
    assert abs(np.sum(s)) < 0.05 * spread              # the gradient in d vanishes at the optimum
    # white noise: sum s_i^2 estimates the variance of d, less what the fit absorbs
    ratio = np.sum(s ** 2) / r.solver_line_delay_std_s ** 2
    assert 0.8 < ratio < 1.15, ratio
    off = calibrate_line_delay(obs, camera, **FIXED)
    assert off.line_delay_score.size == 0 and off.line_delay_s == r.line_delay_s
