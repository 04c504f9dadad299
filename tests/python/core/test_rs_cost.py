"""Tests of the rolling-shutter reprojection cost and the error standardisation (Oth et al. 2013 eq. 6-21; docs/formulation.md §3-4).

Oracles are independent of the code under test: the pose comes from rscalib.poses_at (cross-checked
against SciPy's rotation vectors), projection from cv2.projectPoints / cv2.fisheye.projectPoints,
Jacobians from central finite differences, and the error covariance A R A^T from a Monte Carlo
simulation of noisy rolling-shutter measurements built here with NumPy and OpenCV.
"""
import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import rscalib
from rscalib import _core
from rscalib.io.cameras import opencv_matrices

RADTAN = rscalib.CameraModel("pinhole-radtan",
                             np.array([505.0, 498.0, 322.0, 241.0, -0.12, 0.06, 1.5e-3, -8e-4, -0.01]),
                             640, 480)
EQUIDISTANT = rscalib.CameraModel("pinhole-equidistant",
                                  np.array([420.0, 425.0, 318.0, 243.0, 0.05, -0.02, 0.01, -0.002]),
                                  640, 480)


# --------------------------------------------------------------------------------------------------
# Oracles


def project_cv(camera, points_c):
    """Pixels of camera-frame points (n, 3) with OpenCV."""
    k, dist = opencv_matrices(camera)
    pts = np.ascontiguousarray(points_c, dtype=np.float64).reshape(-1, 1, 3)
    zero = np.zeros(3)
    if camera.model == "pinhole-equidistant":
        uv, _ = cv2.fisheye.projectPoints(pts, zero, zero, k, dist)
    else:
        uv, _ = cv2.projectPoints(pts, zero, zero, k, dist)
    return uv.reshape(-1, 2)


def spline_projection(trajectory, camera, point_w, t):
    """pi(T_cw(t) P) from rscalib.poses_at and OpenCV."""
    rotation, translation = rscalib.poses_at(trajectory, np.array([t], dtype=np.float64))
    point_c = rotation[0] @ point_w + translation[0]
    assert point_c[2] > 0.1
    return project_cv(camera, point_c[None])[0]


def random_pose_spline(rng, num_segments=7, t0=100.0, t1=101.4):
    """6-D pose spline [p; phi] with non-uniform knots: the camera ~0.6 m in front of the target
    (x_c = R x_w + p, p ~ (0, 0, 0.6)), small rotation vectors."""
    widths = rng.uniform(0.5, 1.5, num_segments)
    breakpoints = t0 + (t1 - t0) * np.r_[0.0, np.cumsum(widths)] / widths.sum()
    breakpoints[-1] = t1
    knots = rscalib.BSpline.clamped_knots(breakpoints)
    n = num_segments + 3
    control = np.empty((n, 6))
    control[:, :3] = np.array([0.0, 0.0, 0.6]) + rng.normal(0.0, 0.03, size=(n, 3))
    control[:, 3:] = rng.normal(0.0, 0.12, size=(n, 3))
    return rscalib.BSpline(knots, control)


def random_target_point(rng):
    return np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.09, 0.09), 0.0])


def random_sqrt_information(rng):
    """An upper-triangular weight like the standardisation's, non-trivial in every entry used."""
    return np.array([[rng.uniform(1.5, 3.0), rng.uniform(-0.8, 0.8)], [0.0, rng.uniform(1.5, 3.0)]])


def span_interval(trajectory, span):
    knots = np.asarray(trajectory.knots)
    return float(knots[span]), float(knots[span + 1])


def residual_only(trajectory, span, camera, frame_time, uv, point_w, d, w):
    residual, _ = _core.evaluate_rs_cost(trajectory, span, camera, frame_time, uv, point_w, d, w)
    return np.asarray(residual, dtype=np.float64).reshape(2)


def with_control_point(trajectory, row, col, delta):
    """Copy of the spline with control_points[row, col] += delta."""
    perturbed = trajectory.copy()
    control = np.array(perturbed.control_points)
    control[row, col] += delta
    perturbed.control_points = control
    return perturbed


# --------------------------------------------------------------------------------------------------
# Residual and Jacobians


@pytest.mark.parametrize("camera, seed", [(RADTAN, 1), (RADTAN, 2), (RADTAN, 3), (EQUIDISTANT, 4)],
                         ids=["radtan-1", "radtan-2", "radtan-3", "equidistant"])
def test_rs_cost_residual_and_jacobians(camera, seed):
    rng = np.random.default_rng(seed)
    trajectory = random_pose_spline(rng)
    point_w = random_target_point(rng)
    d = rng.uniform(20e-6, 80e-6)
    w = random_sqrt_information(rng)
    for span in (3, 5, trajectory.num_control_points - 1):  # first, an interior and the last span
        start, end = span_interval(trajectory, span)
        t = start + rng.uniform(0.2, 0.8) * (end - start)
        # A measurement near (not at) the projection, in rows typical of a 480-row frame.
        uv = spline_projection(trajectory, camera, point_w, t) + rng.normal(0.0, 2.0, 2)
        frame_time = t - uv[1] * d

        residual, jacobians = _core.evaluate_rs_cost(trajectory, span, camera, frame_time, uv, point_w,
                                                     d, w)
        residual = np.asarray(residual).reshape(2)
        # The residual: W (y - pi(T_cw(t_i + v d) P)) with the measured v in the time.
        expected = w @ (uv - spline_projection(trajectory, camera, point_w, frame_time + uv[1] * d))
        np.testing.assert_allclose(residual, expected, rtol=0, atol=1e-8 * max(1.0, np.abs(expected).max()))

        assert len(jacobians) == 5
        shapes = [np.asarray(j).shape for j in jacobians]
        assert shapes == [(2, 6)] * 4 + [(2, 1)], shapes

        # d r / d c_j: central differences on the spline's control points (rows span-3 .. span).
        h = 1e-6
        for j in range(4):
            numeric = np.empty((2, 6))
            for k in range(6):
                plus = residual_only(with_control_point(trajectory, span - 3 + j, k, h), span, camera,
                                     frame_time, uv, point_w, d, w)
                minus = residual_only(with_control_point(trajectory, span - 3 + j, k, -h), span, camera,
                                      frame_time, uv, point_w, d, w)
                numeric[:, k] = (plus - minus) / (2 * h)
            analytic = np.asarray(jacobians[j])
            scale = max(1.0, np.abs(numeric).max())
            assert np.abs(analytic - numeric).max() <= 1e-6 * scale, \
                f"span {span}, d r / d c{j}:\n{analytic}\nvs finite differences\n{numeric}"
            assert np.abs(numeric).max() > 1.0  # every control point of the span matters

        # d r / d line delay: flows through the time t_i + v d (paper eq. 13-14).
        hd = 1e-9
        numeric_d = (residual_only(trajectory, span, camera, frame_time, uv, point_w, d + hd, w)
                     - residual_only(trajectory, span, camera, frame_time, uv, point_w, d - hd, w)) / (2 * hd)
        analytic_d = np.asarray(jacobians[4]).reshape(2)
        assert np.abs(numeric_d).max() > 1e3  # a moving camera: d matters
        np.testing.assert_allclose(analytic_d, numeric_d, rtol=0, atol=1e-6 * np.abs(numeric_d).max())
        # ... and it is v times the image velocity (chain rule through t): -W v d/dt pi.
        ht = 1e-6
        velocity = (spline_projection(trajectory, camera, point_w, t + ht)
                    - spline_projection(trajectory, camera, point_w, t - ht)) / (2 * ht)
        np.testing.assert_allclose(analytic_d, -uv[1] * (w @ velocity), rtol=1e-5,
                                   atol=1e-5 * np.abs(analytic_d).max())


def test_poses_at_matches_rotation_vector_convention():
    """The oracle's pose: x_c = exp([phi]x) x_w + p with [p; phi] from the spline."""
    rng = np.random.default_rng(9)
    trajectory = random_pose_spline(rng)
    times = np.linspace(trajectory.t_begin, trajectory.t_end, 7)
    rotation, translation = rscalib.poses_at(trajectory, times)
    state = np.asarray(trajectory.evaluate(times))
    np.testing.assert_allclose(translation, state[:, :3], atol=1e-14)
    np.testing.assert_allclose(rotation, Rotation.from_rotvec(state[:, 3:]).as_matrix(), atol=1e-12)


def test_rs_cost_rejects_bad_span():
    rng = np.random.default_rng(5)
    trajectory = random_pose_spline(rng)
    args = (RADTAN, 100.5, np.array([320.0, 240.0]), random_target_point(rng), 30e-6, np.eye(2))
    with pytest.raises(rscalib.InputError):
        _core.evaluate_rs_cost(trajectory, 2, *args)
    with pytest.raises(rscalib.InputError):
        _core.evaluate_rs_cost(trajectory, trajectory.num_control_points, *args)


# --------------------------------------------------------------------------------------------------
# Span keeping: a residual attached to a span continues that span's cubic past its ends


@pytest.mark.parametrize("side", ["after-end", "before-start"])
def test_rs_cost_keeps_its_span_across_a_knot(side):
    rng = np.random.default_rng(11)
    trajectory = random_pose_spline(rng)
    camera = RADTAN
    point_w = random_target_point(rng)
    d = 40e-6
    w = np.eye(2)
    span = 5
    start, end = span_interval(trajectory, span)
    if side == "after-end":
        knot, true_span, direction = end, span + 1, 1.0
    else:
        knot, true_span, direction = start, span - 1, -1.0
    uv = spline_projection(trajectory, camera, point_w, knot) + np.array([1.5, -2.0])
    length = end - start

    def difference(delta):
        t = knot + direction * delta
        frame_time = t - uv[1] * d
        kept = residual_only(trajectory, span, camera, frame_time, uv, point_w, d, w)
        true = residual_only(trajectory, true_span, camera, frame_time, uv, point_w, d, w)
        # The true span is the spline itself.
        oracle = uv - spline_projection(trajectory, camera, point_w, frame_time + uv[1] * d)
        np.testing.assert_allclose(true, oracle, rtol=0, atol=1e-8)
        return float(np.linalg.norm(kept - true))

    deltas = length * np.array([0.04, 0.02, 0.01, 0.005])
    diffs = np.array([difference(delta) for delta in deltas])
    # C2 continuity at the knot: the two cubics differ by c (t - knot)^3 -> halving delta gives 1/8.
    assert diffs[0] > 1e-6, diffs  # the third derivative does jump: the test can see a wrong span
    ratios = diffs[:-1] / diffs[1:]
    assert np.all((ratios > 7.0) & (ratios < 9.0)), f"differences {diffs}, ratios {ratios}"
    # Continuity itself: no jump at the knot.
    assert difference(1e-9 * length) < 1e-10
    assert difference(0.0) < 1e-10


# --------------------------------------------------------------------------------------------------
# Error standardisation: A and W


def test_error_noise_map_exact_form():
    rng = np.random.default_rng(21)
    for _ in range(20):
        d = rng.uniform(-100e-6, 200e-6)
        velocity = rng.uniform(-3000.0, 3000.0, 2)
        a = np.asarray(_core.error_noise_map(d, velocity))
        expected = np.array([[1.0, -d * velocity[0]], [0.0, 1.0 - d * velocity[1]]])
        np.testing.assert_allclose(a, expected, rtol=0, atol=1e-15)
    identity = np.asarray(_core.error_noise_map(0.0, np.array([500.0, -700.0])))
    np.testing.assert_array_equal(identity, np.eye(2))


def test_standardisation_weight_whitens_a_r_a_transpose():
    rng = np.random.default_rng(22)
    for _ in range(50):
        d = rng.uniform(0.0, 150e-6)
        velocity = rng.uniform(-4000.0, 4000.0, 2)
        sigma = rng.uniform(0.1, 2.0)
        max_gain = 0.8
        if d * velocity[1] > max_gain:
            continue
        w, clamped = _core.standardisation_weight(d, velocity, sigma, max_gain)
        w = np.asarray(w)
        assert not clamped
        a = np.asarray(_core.error_noise_map(d, velocity))
        information = np.linalg.inv(sigma ** 2 * a @ a.T)
        np.testing.assert_allclose(w.T @ w, information, rtol=1e-10, atol=1e-12 * np.abs(information).max())
    # d = 0: plain R = sigma^2 I.
    w, clamped = _core.standardisation_weight(0.0, np.array([800.0, 900.0]), 0.5, 0.8)
    np.testing.assert_allclose(np.asarray(w).T @ np.asarray(w), np.eye(2) / 0.25, atol=1e-12)
    assert not clamped


@pytest.mark.parametrize("gain", [0.85, 0.999, 1.0, 3.0])
def test_standardisation_weight_clamps_the_rs_gain(gain):
    d, sigma, max_gain = 100e-6, 0.4, 0.8
    velocity = np.array([1200.0, gain / d])
    w, clamped = _core.standardisation_weight(d, velocity, sigma, max_gain)
    w = np.asarray(w)
    assert clamped
    assert np.all(np.isfinite(w))
    # The weight of the clamped map: d v_dot replaced by max_gain, so det A = 1 - max_gain.
    a_clamped = np.asarray(_core.error_noise_map(d, np.array([velocity[0], max_gain / d])))
    information = np.linalg.inv(sigma ** 2 * a_clamped @ a_clamped.T)
    np.testing.assert_allclose(w.T @ w, information, rtol=1e-10)
    # Just below the cap nothing is clamped.
    _, clamped_below = _core.standardisation_weight(d, np.array([1200.0, 0.79 / d]), sigma, max_gain)
    assert not clamped_below


# --------------------------------------------------------------------------------------------------
# Monte Carlo: Cov(e) = A R A^T (paper eq. 19-21)


class FastRotation:
    """Analytic T_cw(t): the camera, ~0.6 m in front of the target, turns quickly about its own
    centre (angular velocity plus acceleration, mostly about its x and y axes) while the centre
    drifts: x_c = R(t) (x_w - c(t)), i.e. p = -R c."""

    def __init__(self, omega, alpha, velocity, c0=(0.01, -0.02, -0.6)):
        self.omega = np.asarray(omega, dtype=np.float64)
        self.alpha = np.asarray(alpha, dtype=np.float64)
        self.velocity = np.asarray(velocity, dtype=np.float64)
        self.c0 = np.asarray(c0, dtype=np.float64)

    def pose_cw(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        rotvec = self.omega * t[:, None] + 0.5 * self.alpha * t[:, None] ** 2
        rotation = Rotation.from_rotvec(rotvec).as_matrix()
        center = self.c0 + self.velocity * t[:, None]
        return rotation, -np.einsum("nij,nj->ni", rotation, center)


def project_at(trajectory, camera, point_w, times):
    rotation, translation = trajectory.pose_cw(times)
    points_c = np.einsum("nij,j->ni", rotation, point_w) + translation
    assert np.all(points_c[:, 2] > 0.3)
    return project_cv(camera, points_c)


@pytest.mark.parametrize("omega, expect_sign", [((-4.0, 6.0, 0.3), +1), ((4.0, -6.5, -0.2), -1)],
                         ids=["point-moves-down", "point-moves-up"])
def test_error_covariance_is_a_r_a_transpose(omega, expect_sign):
    camera = RADTAN
    d = 100e-6       # large, so the effect is well above the Monte-Carlo error
    sigma = 0.5
    samples = 20000
    trajectory = FastRotation(omega, alpha=(3.0, -2.0, 1.0), velocity=(0.05, -0.03, 0.02))
    point_w = np.array([0.03, -0.02, 0.0])
    frame_time = 0.01

    # Exact RS projection: v = v_proj(T(t_i + v d) P), by fixed-point iteration (contraction d v_dot).
    v = project_at(trajectory, camera, point_w, [frame_time])[0, 1]
    for _ in range(200):
        v_new = project_at(trajectory, camera, point_w, [frame_time + v * d])[0, 1]
        if abs(v_new - v) < 1e-12:
            break
        v = v_new
    y_true = project_at(trajectory, camera, point_w, [frame_time + v * d])[0]
    assert abs(y_true[1] - v) < 1e-9
    assert 50 < y_true[0] < 590 and 50 < y_true[1] < 430  # inside the image

    # Image velocity at the observation time, central differences.
    t_obs = frame_time + y_true[1] * d
    h = 1e-6
    ends = project_at(trajectory, camera, point_w, [t_obs + h, t_obs - h])
    velocity = (ends[0] - ends[1]) / (2 * h)
    gain = d * velocity[1]
    assert expect_sign * gain >= 0.1, f"d * v_dot = {gain}: too slow to see the effect"
    assert abs(d * velocity[0]) >= 0.2  # large enough to tell where the off-diagonal term sits

    # Noisy measurements and their errors e = y - pi(T(t_i + v_meas d) P).
    rng = np.random.default_rng(123)
    y = y_true + rng.normal(0.0, sigma, size=(samples, 2))
    e = y - project_at(trajectory, camera, point_w, frame_time + y[:, 1] * d)
    empirical = np.cov(e.T)

    a = np.asarray(_core.error_noise_map(d, velocity))
    predicted = a @ (sigma ** 2 * np.eye(2)) @ a.T
    scale = np.sqrt(np.outer(np.diag(predicted), np.diag(predicted)))
    relative = np.abs(empirical - predicted) / scale
    assert relative.max() < 0.03, f"empirical\n{empirical}\npredicted A R A^T\n{predicted}"
    assert np.abs(e.mean(axis=0)).max() < 6 * sigma / np.sqrt(samples)  # unbiased to first order

    # The test can fail: R itself, the opposite sign and the transposed coupling (u-noise moving
    # v) are all clearly rejected.
    du, dv = d * velocity
    for wrong in (np.eye(2), np.array([[1.0, du], [0.0, 1.0 + dv]]), np.array([[1.0, 0.0], [-du, 1.0 - dv]])):
        other = sigma ** 2 * wrong @ wrong.T
        assert (np.abs(empirical - other) / scale).max() > 0.1, wrong

    # The standardisation weight whitens the Monte-Carlo errors.
    w, clamped = _core.standardisation_weight(d, velocity, sigma, 0.8)
    assert not clamped
    whitened = e @ np.asarray(w).T
    np.testing.assert_allclose(np.cov(whitened.T), np.eye(2), atol=0.03)
