"""Tests of the cubic B-spline core (rscalib.BSpline, fit_bspline, rotation helpers, poses_at).

Oracles are independent of the code under test: SciPy's BSpline (values, derivatives, basis
functions, Boehm knot insertion), a dense least-squares solve built here with NumPy, and
scipy.spatial.transform.Rotation for rotation vectors.
"""
import copy
import pickle

import numpy as np
import pytest
import scipy.interpolate as si
from scipy.spatial.transform import Rotation

import rscalib
from rscalib import InputError

DIM = 6


def random_breakpoints(rng, num_segments, t0=0.0, t1=10.0):
    """Strictly increasing, clearly non-uniform breakpoints on [t0, t1]."""
    widths = rng.uniform(0.2, 2.0, num_segments)
    b = t0 + (t1 - t0) * np.r_[0.0, np.cumsum(widths)] / widths.sum()
    b[-1] = t1
    return b


def random_spline(rng, num_segments=12, dim=DIM, t0=0.0, t1=10.0):
    knots = np.asarray(rscalib.BSpline.clamped_knots(random_breakpoints(rng, num_segments, t0, t1)))
    control = rng.normal(size=(num_segments + 3, dim))
    return knots, control, rscalib.BSpline(knots, control)


def scipy_spline(knots, control):
    return si.BSpline(np.asarray(knots, dtype=float), np.asarray(control, dtype=float), 3)


def scipy_basis(knots, times, derivative=0):
    """(m, n) matrix of the n basis functions' derivative at times, from unit coefficients."""
    n = len(knots) - 4
    basis = si.BSpline(np.asarray(knots, dtype=float), np.eye(n), 3)
    if derivative:
        basis = basis.derivative(derivative)
    return basis(np.asarray(times, dtype=float))


def interior_times(rng, knots, count):
    return np.sort(rng.uniform(knots[0], knots[-1], count))


def assert_close_scaled(actual, expected, rtol, what=""):
    actual = np.asarray(actual)
    expected = np.asarray(expected)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    scale = max(1.0, float(np.abs(expected).max()))
    err = float(np.abs(actual - expected).max())
    assert err <= rtol * scale, f"{what}: max error {err:.3e} > {rtol:.0e} * scale {scale:.3e}"


# --------------------------------------------------------------------------- evaluation


def test_clamped_knots_layout():
    b = [0.0, 0.25, 1.0, 1.5, 3.0]
    knots = np.asarray(rscalib.BSpline.clamped_knots(b))
    np.testing.assert_array_equal(knots, np.r_[[0.0] * 4, [0.25, 1.0, 1.5], [3.0] * 4])
    spline = rscalib.BSpline(knots, np.zeros((len(b) + 2, 2)))
    assert spline.num_control_points == len(b) + 2
    assert spline.num_segments == len(b) - 1
    assert spline.dimension == 2
    assert spline.t_begin == 0.0 and spline.t_end == 3.0
    np.testing.assert_array_equal(spline.breakpoints, b)
    np.testing.assert_array_equal(spline.knots, knots)
    with pytest.raises(InputError):
        rscalib.BSpline.clamped_knots([0.0, 1.0, 1.0, 2.0])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_values_and_derivatives_match_scipy(seed):
    rng = np.random.default_rng(seed)
    knots, control, spline = random_spline(rng, num_segments=15)
    reference = scipy_spline(knots, control)
    times = np.r_[knots[0], interior_times(rng, knots, 2000), knots[-1]]
    for derivative in range(4):
        expected = reference.derivative(derivative)(times) if derivative else reference(times)
        got = spline.evaluate(times, derivative=derivative)
        assert got.shape == (times.size, DIM)
        assert_close_scaled(got, expected, 1e-10, f"derivative {derivative}")


def test_derivatives_0_to_2_at_interior_knots_match_scipy():
    # Value, first and second derivatives are continuous at simple knots: no side ambiguity.
    rng = np.random.default_rng(7)
    knots, control, spline = random_spline(rng, num_segments=10)
    reference = scipy_spline(knots, control)
    at_knots = np.unique(knots)
    for derivative in range(3):
        expected = reference.derivative(derivative)(at_knots) if derivative else reference(at_knots)
        assert_close_scaled(spline.evaluate(at_knots, derivative=derivative), expected, 1e-10,
                            f"derivative {derivative} at knots")


def test_scalar_evaluate_returns_vector_and_matches_array_path():
    rng = np.random.default_rng(3)
    knots, control, spline = random_spline(rng)
    reference = scipy_spline(knots, control)
    for t in [0.0, 1.2345, 5, float(knots[6]), np.float64(7.5), 10.0]:
        for derivative in range(4):
            value = spline.evaluate(t, derivative)
            assert value.shape == (DIM,), f"evaluate({t!r}) has shape {value.shape}"
            row = spline.evaluate(np.array([float(t)]), derivative=derivative)
            assert row.shape == (1, DIM)
            np.testing.assert_array_equal(value, row[0])
        assert_close_scaled(spline.evaluate(t), reference(float(t)), 1e-10, f"value at {t}")


def test_dimension_one_and_two_dimensional_time_arrays():
    rng = np.random.default_rng(4)
    knots, control, spline = random_spline(rng, num_segments=5, dim=1)
    reference = scipy_spline(knots, control)
    times = interior_times(rng, knots, 12)
    assert_close_scaled(spline.evaluate(times), reference(times), 1e-10, "1-D spline")
    assert spline.evaluate(times).shape == (12, 1)


# --------------------------------------------------------------------------- basis


def test_basis_weights_reproduce_evaluate_and_scipy_basis():
    rng = np.random.default_rng(5)
    knots, control, spline = random_spline(rng, num_segments=9)
    times = np.r_[knots[0], interior_times(rng, knots, 200), np.unique(knots)[1:-1], knots[-1]]
    design = si.BSpline.design_matrix(times, knots, 3).toarray()
    basis_d = [scipy_basis(knots, times, k) for k in range(3)]
    for i, t in enumerate(times):
        span, weights = spline.basis(float(t))
        weights = np.asarray(weights)
        assert weights.shape == (3, 4)
        assert 3 <= span <= spline.num_control_points - 1
        assert knots[span] <= t <= knots[span + 1] and knots[span + 1] > knots[span]
        assert span - 3 == spline.segment_at(float(t)) and span == spline.span_at(float(t))
        active = control[span - 3:span + 1]
        for k in range(3):
            assert_close_scaled(weights[k] @ active, spline.evaluate(float(t), k), 1e-10,
                                f"basis derivative {k} at t={t}")
        # Weights of the active control points against SciPy's basis functions; all other
        # basis functions vanish there.
        np.testing.assert_allclose(weights[0], design[i, span - 3:span + 1], rtol=0, atol=1e-12)
        assert abs(weights[0].sum() - 1.0) < 1e-12
        others = np.delete(design[i], np.arange(span - 3, span + 1))
        assert np.abs(others).max(initial=0.0) < 1e-12
        for k in (1, 2):
            scale = max(1.0, np.abs(basis_d[k][i]).max())
            np.testing.assert_allclose(weights[k], basis_d[k][i, span - 3:span + 1], rtol=0,
                                       atol=1e-10 * scale)


def test_basis_outside_domain_raises():
    rng = np.random.default_rng(6)
    _, _, spline = random_spline(rng)
    with pytest.raises(InputError):
        spline.basis(spline.t_end + 1e-3)
    with pytest.raises(InputError):
        spline.span_at(spline.t_begin - 1e-3)


# --------------------------------------------------------------------------- knot insertion


def test_knot_insertion_keeps_curve_and_matches_scipy_boehm():
    rng = np.random.default_rng(8)
    knots, control, spline = random_spline(rng, num_segments=8)
    times = np.r_[knots[0], interior_times(rng, knots, 3000), knots[-1]]
    before = [spline.evaluate(times, derivative=d) for d in range(3)]
    existing = float(np.unique(knots)[3])  # an interior knot, present once
    inserts = [float(t) for t in rng.uniform(knots[0] + 0.1, knots[-1] - 0.1, 5)] + [existing]
    reference = scipy_spline(knots, control)
    n = spline.num_control_points
    for t in inserts:
        spline.insert_knot(t)
        n += 1
        assert spline.num_control_points == n
        assert len(spline.knots) == n + 4
        reference = si.insert(t, reference)
        np.testing.assert_allclose(spline.knots, reference.t, rtol=0, atol=0)
        assert_close_scaled(spline.control_points, reference.c[:n], 1e-12, f"control points after {t}")
        for d in range(3):
            assert_close_scaled(spline.evaluate(times, derivative=d), before[d], 1e-12,
                                f"derivative {d} after inserting {t}")
    # The existing knot is now double; the breakpoints are unchanged by that insertion.
    assert np.count_nonzero(np.asarray(spline.knots) == existing) == 2
    assert spline.num_segments == len(spline.breakpoints) - 1 + 1  # one zero-length segment


def test_knot_insertion_rejects_bad_times():
    rng = np.random.default_rng(9)
    _, _, spline = random_spline(rng, num_segments=4)
    n = spline.num_control_points
    for t in [spline.t_begin, spline.t_end, spline.t_begin - 1.0, spline.t_end + 0.5, float("nan")]:
        with pytest.raises(InputError):
            spline.insert_knot(t)
    assert spline.num_control_points == n
    # A knot already present twice cannot be added a third time (documented: keeps C1).
    t = float(spline.breakpoints[2])
    spline.insert_knot(t)
    with pytest.raises(InputError):
        spline.insert_knot(t)
    assert spline.num_control_points == n + 1


# --------------------------------------------------------------------------- fitting


def quadrature_nodes(knots, per_span=4):
    """Gauss-Legendre nodes and weights on every non-empty knot span (exact to degree 7)."""
    x, w = np.polynomial.legendre.leggauss(per_span)
    breaks = np.unique(knots)
    nodes, weights = [], []
    for a, b in zip(breaks[:-1], breaks[1:]):
        nodes.append(0.5 * (b - a) * x + 0.5 * (a + b))
        weights.append(0.5 * (b - a) * w)
    return np.concatenate(nodes), np.concatenate(weights)


def acceleration_energy(knots, control):
    """Integral of |x''(t)|^2 per dimension, from SciPy second derivatives."""
    t, w = quadrature_nodes(knots, per_span=6)
    acc = scipy_spline(knots, control).derivative(2)(t)
    return (w[:, None] * acc**2).sum(axis=0)


def test_fit_recovers_control_points_from_noise_free_samples():
    rng = np.random.default_rng(10)
    knots, control, _ = random_spline(rng, num_segments=10)
    times = np.sort(rng.uniform(knots[0], knots[-1], 400))
    samples = scipy_spline(knots, control)(times)
    fitted = rscalib.fit_bspline(knots, times, samples)
    assert isinstance(fitted, rscalib.BSpline)
    np.testing.assert_array_equal(fitted.knots, knots)
    assert_close_scaled(fitted.control_points, control, 1e-9, "recovered control points")
    # A tiny penalty on a curve barely moves it; sample weights of 2 change nothing when exact.
    weighted = rscalib.fit_bspline(knots, times, samples, sample_weight=list(np.full(times.size, 2.0)))
    assert_close_scaled(weighted.control_points, control, 1e-9, "weighted fit")


def test_acceleration_penalty_makes_fit_smoother():
    rng = np.random.default_rng(11)
    knots = np.asarray(rscalib.BSpline.clamped_knots(np.linspace(0.0, 6.0, 31)))
    times = np.linspace(0.0, 6.0, 360)
    truth = np.c_[np.sin(times), np.cos(1.3 * times), 0.2 * times, np.sin(0.7 * times),
                  np.cos(times) ** 2, 0.1 * times**2]
    samples = truth + rng.normal(scale=0.05, size=truth.shape)
    plain = rscalib.fit_bspline(knots, times, samples)
    smooth = rscalib.fit_bspline(knots, times, samples, acceleration_weight=[1e-2])
    e_plain = acceleration_energy(knots, plain.control_points)
    e_smooth = acceleration_energy(knots, smooth.control_points)
    assert np.all(e_smooth < 0.5 * e_plain), (e_smooth, e_plain)
    # ... and it fits the noise less: residual larger, error to the truth smaller.
    res_plain = np.abs(plain.evaluate(times) - samples).mean()
    res_smooth = np.abs(smooth.evaluate(times) - samples).mean()
    assert res_smooth > res_plain
    assert np.abs(smooth.evaluate(times) - truth).mean() < np.abs(plain.evaluate(times) - truth).mean()


def test_penalised_fit_matches_dense_least_squares():
    rng = np.random.default_rng(12)
    breakpoints = random_breakpoints(rng, 14, 0.0, 5.0)
    knots = np.asarray(rscalib.BSpline.clamped_knots(breakpoints))
    n = len(knots) - 4
    times = np.sort(rng.uniform(0.0, 5.0, 150))
    samples = np.c_[np.sin(2 * times), np.cos(times), times, np.sin(times) * times,
                    np.exp(-times), np.ones_like(times)] + rng.normal(scale=0.02, size=(times.size, DIM))
    lambdas = np.array([1e-4, 1e-3, 1e-2, 0.0, 0.1, 1.0])
    sample_weight = rng.uniform(0.5, 2.0, times.size)
    fitted = rscalib.fit_bspline(knots, times, samples, acceleration_weight=list(lambdas),
                                 sample_weight=list(sample_weight))

    design = si.BSpline.design_matrix(times, knots, 3).toarray()  # (m, n)
    q_t, q_w = quadrature_nodes(knots, per_span=5)
    second = scipy_basis(knots, q_t, 2)  # (q, n)
    penalty = second.T @ (q_w[:, None] * second)  # int B_i'' B_j'' dt
    expected = np.empty((n, DIM))
    for d in range(DIM):
        normal = design.T @ (sample_weight[:, None] * design) + lambdas[d] * penalty
        rhs = design.T @ (sample_weight * samples[:, d])
        expected[:, d] = np.linalg.solve(normal, rhs)
    assert_close_scaled(fitted.control_points, expected, 1e-8, "penalised fit vs dense solve")


def test_singular_fit_raises_with_message():
    knots = np.asarray(rscalib.BSpline.clamped_knots(np.linspace(0.0, 10.0, 11)))
    # No samples in [3, 7): four empty spans, so the basis function on [3, 7] is free.
    times = np.r_[np.linspace(0.0, 2.9, 60), np.linspace(7.0, 10.0, 60)]
    samples = np.c_[np.sin(times), times]
    with pytest.raises(InputError, match="singular"):
        rscalib.fit_bspline(knots, times, samples)
    # Fewer samples than control points.
    with pytest.raises(InputError, match="singular"):
        rscalib.fit_bspline(knots, np.linspace(0.0, 10.0, 5), np.zeros((5, 2)))
    # The acceleration penalty makes the same problem well posed.
    fitted = rscalib.fit_bspline(knots, times, samples, acceleration_weight=[1e-3])
    assert np.all(np.isfinite(fitted.control_points))
    assert np.abs(fitted.evaluate(times)[:, 1] - times).max() < 0.05


def test_fit_rejects_bad_input():
    knots = np.asarray(rscalib.BSpline.clamped_knots(np.linspace(0.0, 1.0, 4)))
    times = np.linspace(0.0, 1.0, 50)
    samples = np.zeros((50, 3))
    with pytest.raises(InputError):
        rscalib.fit_bspline(knots, times, samples[:-1])
    with pytest.raises(InputError):
        rscalib.fit_bspline(knots, np.r_[times[:-1], 1.5], samples)
    with pytest.raises(InputError):
        rscalib.fit_bspline(knots, times, samples, acceleration_weight=[1.0, 2.0])
    with pytest.raises(InputError):
        rscalib.fit_bspline(knots, times, samples, acceleration_weight=[-1.0])
    with pytest.raises(InputError):
        rscalib.fit_bspline(knots, times, samples, sample_weight=[1.0] * 49)


# --------------------------------------------------------------------------- rotations


def test_unwrap_rotation_vectors_through_pi():
    times = np.linspace(0.0, 1.0, 150)
    angle = 2.6 + 1.2 * times  # crosses pi at t ~ 0.45
    axis = np.c_[np.cos(0.3 * times), np.sin(0.3 * times), 0.5 + 0.1 * times]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    truth = angle[:, None] * axis
    wrapped = Rotation.from_rotvec(truth).as_rotvec()
    assert np.linalg.norm(wrapped, axis=1).max() <= np.pi + 1e-12
    assert np.abs(np.diff(wrapped, axis=0)).max() > 3.0  # the input does jump
    unwrapped = np.asarray(rscalib.unwrap_rotation_vectors(wrapped))
    assert unwrapped.shape == wrapped.shape
    assert np.abs(np.diff(unwrapped, axis=0)).max() < 0.05
    np.testing.assert_allclose(unwrapped, truth, rtol=0, atol=1e-9)
    for phi_in, phi_out in zip(wrapped, unwrapped):
        np.testing.assert_allclose(rscalib.rotation_vector_to_matrix(phi_out),
                                   Rotation.from_rotvec(phi_in).as_matrix(), rtol=0, atol=1e-12)


def test_unwrap_rotation_vectors_several_turns_and_first_sample_kept():
    angle = np.linspace(0.3, 14.0, 400)  # more than two full turns, passes 2*pi and 4*pi
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    truth = angle[:, None] * axis
    wrapped = Rotation.from_rotvec(truth).as_rotvec()
    unwrapped = np.asarray(rscalib.unwrap_rotation_vectors(wrapped))
    np.testing.assert_array_equal(unwrapped[0], wrapped[0])
    np.testing.assert_allclose(unwrapped, truth, rtol=0, atol=1e-9)


def test_rotation_vector_matrix_round_trip():
    rng = np.random.default_rng(13)
    for phi in np.r_[rng.normal(size=(20, 3)), [[0.0, 0.0, 0.0], [1e-9, -2e-9, 0.0]]]:
        R = rscalib.rotation_vector_to_matrix(phi)
        np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), rtol=0, atol=1e-13)
        back = rscalib.rotation_matrix_to_vector(R)
        np.testing.assert_allclose(back, Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-9)


def test_poses_at_matches_scipy_rotation():
    rng = np.random.default_rng(14)
    knots = np.asarray(rscalib.BSpline.clamped_knots(random_breakpoints(rng, 8)))
    control = np.c_[rng.normal(scale=0.5, size=(11, 3)), rng.normal(scale=1.5, size=(11, 3))]
    spline = rscalib.BSpline(knots, control)
    times = np.r_[0.0, interior_times(rng, knots, 300), 10.0]
    R, p = rscalib.poses_at(spline, times)
    assert R.shape == (times.size, 3, 3) and p.shape == (times.size, 3)
    state = scipy_spline(knots, control)(times)
    np.testing.assert_allclose(p, state[:, :3], rtol=0, atol=1e-12)
    expected_R = Rotation.from_rotvec(state[:, 3:]).as_matrix()
    np.testing.assert_allclose(R, expected_R, rtol=0, atol=1e-12)
    # x_c = R x_w + p (world to camera), not the inverse.
    points_w = rng.normal(size=(times.size, 3))
    x_c = np.einsum("nij,nj->ni", R, points_w) + p
    np.testing.assert_allclose(x_c, Rotation.from_rotvec(state[:, 3:]).apply(points_w) + state[:, :3],
                               rtol=0, atol=1e-12)
    with pytest.raises(InputError):
        rscalib.poses_at(rscalib.BSpline(knots, control[:, :3]), times)
    with pytest.raises(InputError):
        rscalib.poses_at(spline, np.array([5.0, 10.5]))


# --------------------------------------------------------------------------- errors, copies


def test_evaluation_outside_domain_raises():
    rng = np.random.default_rng(15)
    _, _, spline = random_spline(rng)
    span = spline.t_end - spline.t_begin
    for t in [spline.t_begin - 1e-6 * span, spline.t_end + 1e-6 * span, float("nan"), float("inf")]:
        with pytest.raises(InputError):
            spline.evaluate(t)
    with pytest.raises(InputError):
        spline.evaluate(np.array([1.0, 2.0, spline.t_end + 1.0]))
    for derivative in (-1, 4):
        with pytest.raises(InputError):
            spline.evaluate(1.0, derivative=derivative)
    # Rounding-level excursions past the ends are accepted (documented tolerance 1e-12).
    np.testing.assert_allclose(spline.evaluate(spline.t_end + 1e-14 * span),
                               spline.evaluate(spline.t_end), rtol=0, atol=1e-9)
    assert issubclass(InputError, ValueError)


def test_constructor_rejects_bad_knots():
    good = rscalib.BSpline.clamped_knots([0.0, 1.0, 2.0])
    control = np.zeros((5, 2))
    rscalib.BSpline(good, control)
    bad_cases = [
        (good[:-1], control),                                  # too few knots
        ([0.0, 0.0, 0.0, 0.5, 1.0, 2.0, 2.0, 2.0, 2.0], control),  # not clamped at the start
        ([0.0, 0.0, 0.0, 0.0, 1.5, 1.0, 2.0, 2.0, 2.0], control),  # decreasing
        ([0.0] * 9, control),                                  # zero-length domain
        (good, np.zeros((3, 2))),                              # too few control points
    ]
    for knots, points in bad_cases:
        with pytest.raises(InputError):
            rscalib.BSpline(knots, points)


def test_control_points_setter_and_pickle_and_copy():
    rng = np.random.default_rng(16)
    knots, control, spline = random_spline(rng)
    times = interior_times(rng, knots, 50)
    values = spline.evaluate(times, derivative=1)

    restored = pickle.loads(pickle.dumps(spline))
    assert isinstance(restored, rscalib.BSpline)
    np.testing.assert_array_equal(restored.knots, spline.knots)
    np.testing.assert_array_equal(restored.control_points, control)
    np.testing.assert_array_equal(restored.evaluate(times, derivative=1), values)

    for duplicate in (copy.copy(spline), copy.deepcopy(spline), spline.copy()):
        np.testing.assert_array_equal(duplicate.control_points, control)
        duplicate.control_points = np.zeros_like(control)
        np.testing.assert_array_equal(duplicate.evaluate(times), 0.0)
        np.testing.assert_array_equal(spline.control_points, control)  # original untouched

    # control_points is a copy: writing into it does not change the spline.
    view = spline.control_points
    view[:] = 5.0
    np.testing.assert_array_equal(spline.control_points, control)
    with pytest.raises(InputError):
        spline.control_points = np.zeros((control.shape[0] + 1, DIM))
