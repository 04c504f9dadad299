"""End-to-end tests of the line-delay engine (Oth et al. 2013; docs/formulation.md) on simulated rolling-shutter video.

Ground truth comes from rscalib.sim.target_observations (exact RS projections through OpenCV, independent of the
C++ core): the true line delay, the true trajectory and the true detection noise. Each simulation
has a fixed seed, so the tests are deterministic.
"""
import math

import numpy as np
import pytest

import rscalib
from rscalib import InputError
from rscalib.linedelay import spline as linedelay
from rscalib.linedelay.noise import estimate_pixel_sigma, grid_line_quadruples
from rscalib.linedelay.options import LineDelayOptions
from rscalib.sim import target_observations as simulate

FPS = 30.0
DURATION_S = 15.0
NOISE_PX = 0.3
CAMERA = rscalib.CameraModel("pinhole-radtan",
                             np.array([500.0, 502.0, 321.0, 238.5, -0.1, 0.05, 5e-4, -3e-4, 0.0]),
                             640, 480)
ROWS = 480
NOMINAL_DELAY_S = 1.0 / (FPS * ROWS)


def simulate_video(line_delay_s, seed, duration_s=DURATION_S, noise_px=NOISE_PX, trajectory=None):
    return simulate.simulate_observations(CAMERA, line_delay_s, fps=FPS, duration_s=duration_s,
                                          noise_px=noise_px, seed=seed, trajectory=trajectory)


def handheld(duration_s, seed, **kwargs):
    """The simulator's default framing (target centre, stand-off), with extra options."""
    points = simulate.checkerboard_points()
    center = 0.5 * (points.min(axis=0) + points.max(axis=0))
    return simulate.HandheldTrajectory(duration_s=duration_s, seed=seed, target_center_m=center,
                                       distance_m=simulate.standoff_distance_m(CAMERA, points), **kwargs)


def camera_centres(rotation, translation):
    """c = -R^T p for stacks R (n, 3, 3), p (n, 3)."""
    return -np.einsum("nji,nj->ni", rotation, translation)


# --------------------------------------------------------------------------------------------------
# Calibration recovers d


_CALIBRATIONS = {}


def calibrated(line_delay_s, seed):
    """(simulation, result), computed once per (d, seed) for the whole module."""
    key = (line_delay_s, seed)
    if key not in _CALIBRATIONS:
        sim = simulate_video(line_delay_s, seed)
        _CALIBRATIONS[key] = (sim, linedelay.calibrate_line_delay(sim.observations, CAMERA))
    return _CALIBRATIONS[key]


@pytest.mark.parametrize("line_delay_us, seed", [(15.0, 1), (30.0, 2), (60.0, 3), (137.0, 4)])
def test_calibration_recovers_line_delay(line_delay_us, seed):
    d = line_delay_us * 1e-6
    sim, result = calibrated(d, seed)
    obs = sim.observations
    d_hat, std = result.line_delay_s, result.line_delay_std_s
    context = (f"d = {d * 1e6:.3f} us, d_hat = {d_hat * 1e6:.4f} us, sigma_d = {std * 1e6:.4f} us, "
               f"warnings = {result.warnings}")

    assert math.isfinite(std) and std > 0, context
    assert abs(d_hat - d) <= 0.01 * d, context
    assert abs(d_hat - d) <= 3.0 * std, context
    # sigma_d is a real uncertainty, not a vanishing number: a few x 0.1 us for this setup.
    assert 1e-8 < std < 1e-6, context

    assert result.rows == ROWS
    assert result.readout_time_s == pytest.approx(d_hat * ROWS, rel=1e-12)
    assert 0.8 <= result.normalised_cost <= 1.2, context
    assert result.pixel_sigma == pytest.approx(NOISE_PX, rel=0.10)
    assert result.pixel_sigma_source == "grid third differences"
    assert result.converged, context
    assert result.determined, context
    assert result.warnings == []
    assert result.frames_used == result.frames_total == obs.num_frames
    assert result.observations == obs.num_observations
    assert result.initial_line_delay_s == pytest.approx(NOMINAL_DELAY_S)
    # The raw residuals are at the noise level.
    assert result.rms_px == pytest.approx(NOISE_PX, rel=0.15)
    assert result.residual_px.shape == (obs.num_observations, 2)
    # Observation times are t_i + v d_hat with the measured v.
    np.testing.assert_allclose(result.observation_time_s,
                               obs.frame_times_s[obs.frame_index] + obs.uv[:, 1] * d_hat, rtol=0, atol=1e-9)
    # The knots of the final spline and its per-segment statistics agree.
    assert len(result.knots) - 1 == result.num_segments
    assert result.num_segments == len(result.segment_cost) == len(result.segment_count)
    assert int(np.sum(result.segment_count)) == result.observations
    assert result.history and result.history[-1].line_delay_s == d_hat


def test_zero_line_delay_is_estimated_as_zero():
    sim = simulate_video(0.0, seed=5)
    result = linedelay.calibrate_line_delay(sim.observations, CAMERA)
    context = f"d_hat = {result.line_delay_s * 1e6:.4f} us, sigma_d = {result.line_delay_std_s * 1e6:.4f} us"
    assert result.determined, context
    assert math.isfinite(result.line_delay_std_s) and result.line_delay_std_s > 0, context
    assert abs(result.line_delay_s) <= 3.0 * result.line_delay_std_s, context
    assert 0.8 <= result.normalised_cost <= 1.2


# --------------------------------------------------------------------------------------------------
# Observability


def test_static_camera_does_not_determine_line_delay():
    duration = 8.0
    trajectory = handheld(duration, seed=6, amplitude=0.0)
    sim = simulate_video(30e-6, seed=6, duration_s=duration, trajectory=trajectory)
    result = linedelay.calibrate_line_delay(sim.observations, CAMERA)
    std = result.line_delay_std_s
    assert result.determined is False
    assert any("line delay" in w and "not determined" in w for w in result.warnings), result.warnings
    # Large: at least 5 % of the nominal full-frame delay (the engine's rule) and far above what a
    # moving camera gives with the same setup (~0.1 us).
    _, moving = calibrated(30e-6, 2)
    large = std >= 0.05 * NOMINAL_DELAY_S and std > 20 * moving.line_delay_std_s
    assert (not math.isfinite(std)) or large, f"sigma_d = {std} s for a static camera"
    assert result.summary_dict()["determined"] is False


# --------------------------------------------------------------------------------------------------
# Adaptive knots


def test_knot_adaptation_puts_knots_where_motion_is_fast():
    duration = 12.0
    # A truly calm first half (5 % of the hand-held amplitude), the full motion in the second.
    trajectory = handheld(duration, seed=4, amplitude_profile=simulate.calm_then_wild(duration, calm=0.05))
    sim = simulate_video(30e-6, seed=4, duration_s=duration, trajectory=trajectory)
    result = linedelay.calibrate_line_delay(sim.observations, CAMERA)
    knots = np.asarray(result.knots)
    assert knots[0] == pytest.approx(0.0) and knots[-1] >= duration - 1e-9
    # Density of breakpoints away from the tanh transition (0.5 s each side of the midpoint).
    half = 0.5 * duration
    calm = np.count_nonzero((knots > 0.0) & (knots < half - 0.5)) / (half - 0.5)
    wild = np.count_nonzero((knots > half + 0.5) & (knots < duration)) / (half - 0.5)
    history = [(r.segments, r.segments_split) for r in result.history]
    assert wild >= 1.5 * calm, f"knots per second: calm {calm:.2f}, wild {wild:.2f}; rounds {history}"
    assert len(result.history) > 1, history
    assert result.history[0].segments_split > 0, history
    assert result.num_segments > result.history[0].segments
    # Still a good calibration.
    assert abs(result.line_delay_s - 30e-6) <= 3 * result.line_delay_std_s
    assert 0.8 <= result.normalised_cost <= 1.2


# --------------------------------------------------------------------------------------------------
# Continuous-time localisation (Oth et al. 2013 §5.1)


def test_localization_beats_global_shutter_pnp():
    d = 60e-6
    sim = simulate_video(d, seed=7, duration_s=12.0)
    result = linedelay.localize(sim.observations, CAMERA, d)
    assert result.line_delay_s == d  # held fixed
    used = result.used_observations
    times = used.frame_times_s
    truth = camera_centres(*sim.trajectory.pose_cw(times))

    rs = camera_centres(*rscalib.poses_at(result.trajectory, times))
    poses = result.frame_poses
    assert poses.ok.all() and len(poses.ok) == len(times)
    rotation_gs = np.stack([rscalib.rotation_vector_to_matrix(v) for v in poses.rotation_vector])
    gs = camera_centres(rotation_gs, poses.translation)

    rs_error = np.linalg.norm(rs - truth, axis=1).mean()
    gs_error = np.linalg.norm(gs - truth, axis=1).mean()
    assert rs_error * 4.0 < gs_error, \
        f"mean position error RS {rs_error * 1e3:.2f} mm, GS {gs_error * 1e3:.2f} mm"
    assert rs_error < 2e-3, f"RS mean position error {rs_error * 1e3:.2f} mm"
    assert 0.8 <= result.normalised_cost <= 1.2


# --------------------------------------------------------------------------------------------------
# Bad input


@pytest.fixture(scope="module")
def small_sim():
    return simulate_video(30e-6, seed=8, duration_s=2.0)


def test_camera_size_must_match_observations(small_sim):
    other = rscalib.CameraModel("pinhole-radtan", CAMERA.params, 1280, 720)
    with pytest.raises(InputError):
        linedelay.calibrate_line_delay(small_sim.observations, other)
    with pytest.raises(InputError):
        linedelay.localize(small_sim.observations, other, 30e-6)


@pytest.mark.parametrize("sigma", [-0.3, 0.0])
def test_pixel_sigma_must_be_positive(small_sim, sigma):
    with pytest.raises(InputError):
        linedelay.calibrate_line_delay(small_sim.observations, CAMERA, LineDelayOptions(pixel_sigma_px=sigma))


def test_too_few_observations(small_sim):
    obs = small_sim.observations
    keep = np.zeros(obs.num_frames, dtype=bool)
    keep[:3] = True
    with pytest.raises(InputError):
        linedelay.calibrate_line_delay(obs.subset_frames(keep), CAMERA)
    # Plenty of frames but only 5 points in total.
    few = rscalib.Observations(obs.frame_times_s, obs.frame_index[:5], obs.point_id[:5], obs.uv[:5],
                               obs.target_points, obs.image_size)
    with pytest.raises(InputError):
        linedelay.calibrate_line_delay(few, CAMERA)


def test_localize_rejects_non_finite_line_delay(small_sim):
    with pytest.raises(InputError):
        linedelay.localize(small_sim.observations, CAMERA, float("nan"))


# --------------------------------------------------------------------------------------------------
# Pixel noise from the data (rscalib.linedelay.noise)


def test_grid_line_quadruples_of_a_9x6_grid():
    points = simulate.checkerboard_points(9, 6)
    quads = grid_line_quadruples(points)
    assert quads.shape == (6 * (9 - 3) + 9 * (6 - 3), 4) == (63, 4)
    # Every quadruple is four collinear, equally spaced points.
    p = points[quads]
    np.testing.assert_allclose(p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], atol=1e-12)
    np.testing.assert_allclose(p[:, 3] - p[:, 2], p[:, 2] - p[:, 1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(p[:, 1] - p[:, 0], axis=1), 0.04, atol=1e-12)
    assert len({tuple(q) for q in quads}) == 63


@pytest.mark.parametrize("noise_px", [0.3, 1.0])
def test_pixel_sigma_estimated_from_the_grid(noise_px):
    sim = simulate_video(60e-6, seed=9, duration_s=4.0, noise_px=noise_px)
    sigma = estimate_pixel_sigma(sim.observations)
    assert sigma is not None
    assert sigma == pytest.approx(noise_px, rel=0.10)


# --------------------------------------------------------------------------------------------------
# The solver's image velocities (used by the report's plots)


def test_solver_image_velocities_match_finite_differences_of_the_projection():
    """result.image_velocity_px_s is d(uv)/dt that the solver computed for A (by a Jet in time);
    the oracle is central differences of the projection through the estimated trajectory."""
    sim, result = calibrated(30e-6, 2)
    t = result.observation_time_s
    traj = result.trajectory
    inside = (t > traj.t_begin + 1e-3) & (t < traj.t_end - 1e-3)
    points_w = result.used_observations.points_w()
    h_s = 1e-5
    uv = []
    for dt in (-h_s, h_s):
        rotations, translations = rscalib.poses_at(traj, t[inside] + dt)
        uv.append(CAMERA.project(np.einsum("nij,nj->ni", rotations, points_w[inside]) + translations))
    finite_difference = (uv[1] - uv[0]) / (2 * h_s)
    velocity = result.image_velocity_px_s[inside]
    assert velocity.shape == finite_difference.shape and np.isfinite(velocity).all()
    assert np.median(np.linalg.norm(velocity, axis=1)) > 10.0  # the camera moves: a real comparison
    np.testing.assert_allclose(velocity, finite_difference, rtol=1e-4, atol=1e-3)
