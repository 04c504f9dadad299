"""Tests of the SOG self-calibration bank (rscalib._core.SogBank) and its initial grid.

Oracles: a NumPy implementation (written here) of the measurement function with finite-difference
Jacobians and scipy's multivariate normal for the weight update; the simulator's ground truth
(rscalib.sim.scene_features) for consistency (NEES) and convergence, run through the per-frame loop
(rscalib.selfcalib.driver) with the simulator's known correspondences.
"""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2, multivariate_normal

from rscalib import InputError, _core
from rscalib.selfcalib.driver import run_bank
from rscalib.selfcalib.prior import initial_bank, make_bank
from rscalib.sim.scene_features import PAPER_CAMERA, CiveraCamera, TrueCorrespondences, simulate_sequence

PAPER_SIGMAS = np.array([7.5, 10 / 3, 10 / 3, 0.02, 0.00225])
TRUTH = PAPER_CAMERA.params


def small_bank(f_values, options=None, weights=None):
    means = np.tile(TRUTH, (len(f_values), 1))
    means[:, 0] = f_values
    covs = np.tile(np.diag(PAPER_SIGMAS ** 2), (len(f_values), 1, 1))
    w = np.full(len(f_values), 1.0 / len(f_values)) if weights is None else np.asarray(weights)
    return _core.SogBank(options or _core.SogOptions(), means, covs, w, (320, 240), 0.0112)


def track(bank, seq, *, min_visible=20, max_new_per_frame=10, min_separation_px=20.0, on_frame=None):
    """Run the bank over a simulated sequence through the self-calibration loop."""
    source = TrueCorrespondences(seq, min_separation_px=min_separation_px)
    return run_bank(bank, source.frames(), source, min_visible=min_visible, max_new_per_frame=max_new_per_frame,
                    on_frame=on_frame)


# ------------------------------------------------------------------------------------ initial grid


def test_initial_bank_is_the_papers_grid():
    bank = initial_bank(320, 240, 0.0112)
    assert len(bank) == 108
    f, cx, cy, k1, k2 = bank.means.T
    np.testing.assert_allclose(np.unique(f), np.arange(100.0, 611.0, 30.0))
    np.testing.assert_allclose(np.unique(k1), [0.0, 0.08])
    np.testing.assert_allclose(np.unique(k2), [0.0, 0.009, 0.018])
    np.testing.assert_allclose(cx, 159.5)
    np.testing.assert_allclose(cy, 119.5)
    sig = np.sqrt(np.diagonal(bank.covs, axis1=1, axis2=2))
    np.testing.assert_allclose(sig[0], [7.5, 10 / 3, 10 / 3, 0.02, 0.00225])
    np.testing.assert_allclose(bank.weights.sum(), 1.0)


def test_initial_bank_scales_with_the_image():
    # Twice the pixels on the same sensor: f doubles, pixel size halves, k ranges stay.
    big = initial_bank(640, 480, 0.0056)
    np.testing.assert_allclose(np.unique(big.means[:, 0]), 2 * np.arange(100.0, 611.0, 30.0))
    np.testing.assert_allclose(np.unique(big.means[:, 3]), [0.0, 0.08])
    np.testing.assert_allclose(big.means[0, 1:3], [319.5, 239.5])
    # Same pixels on a sensor twice as large: k1 / 4, k2 / 16.
    large = initial_bank(320, 240, 0.0224)
    np.testing.assert_allclose(np.unique(large.means[:, 3]), [0.0, 0.02])
    np.testing.assert_allclose(np.unique(large.means[:, 4]), [0.0, 0.018 / 32, 0.018 / 16])
    custom = initial_bank(320, 240, f_range=(150, 250), f_count=5, k1_count=1, k2_count=1)
    assert len(custom) == 5
    with pytest.raises(InputError):
        initial_bank(320, 240, -1.0)


# ---------------------------------------------------------------------------------------- the API


def test_bank_api_shapes_and_errors():
    bank = make_bank(320, 240)
    assert bank.num_gaussians == 108 and bank.frame == 0
    assert bank.calibration_means.shape == (108, 5) and bank.calibration_covs.shape == (108, 5, 5)
    np.testing.assert_allclose(bank.weights.sum(), 1.0)
    assert bank.calibration_bounds_99().shape == (5, 2)
    ids = bank.add_features(np.array([[100.0, 100.0], [200.0, 150.0]]))
    np.testing.assert_array_equal(ids, [0, 1])
    assert bank.num_features == 2 and bank.state_dim == 18 + 12
    bank.predict(1 / 30)
    pid, uv, cov = bank.predict_measurements()
    assert pid.shape == (2,) and uv.shape == (2, 2) and cov.shape == (2, 2, 2)
    report = bank.update(pid, uv, np.array([True, False]))
    assert report.used.tolist() == [True, False] and report.num_used == 1
    np.testing.assert_array_equal(bank.feature_match_counts, [[1, 1], [1, 0]])
    bank.remove_features(np.array([0]))
    np.testing.assert_array_equal(bank.feature_ids, [1])
    with pytest.raises(InputError):
        bank.update(np.array([5]), np.zeros((1, 2)))
    with pytest.raises(InputError):
        bank.update(np.array([1]), np.zeros((2, 2)))
    with pytest.raises(InputError):
        _core.SogBank(_core.SogOptions(), np.zeros((2, 5)), np.zeros((2, 5, 5)), np.ones(2), (320, 240), 0.0112)
    with pytest.raises(InputError):
        _core.SogBank(_core.SogOptions(), np.ones((2, 4)), np.zeros((2, 5, 5)), np.ones(2), (320, 240), 0.0112)


def test_threads_do_not_change_the_result():
    seq = simulate_sequence(duration_s=1.0, seed=5)
    results = []
    for threads in (1, 2):
        options = _core.SogOptions()
        options.num_threads = threads
        bank = make_bank(320, 240, options=options)
        track(bank, seq)
        results.append((bank.log_weights, bank.calibration_means, bank.gaussian_ids))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    np.testing.assert_array_equal(results[0][1], results[1][1])
    assert results[0][2] == results[1][2]


# ------------------------------------------------------------------- weights against a direct computation


def reference_measurement(x, offsets, is_xyz):
    """h(x) stacked for all features, in NumPy (Civera et al. 2009, eq. 9–13; docs/sog.md §5)."""
    cam = CiveraCamera(*x[:5])
    r, q = x[5:8], x[8:12]
    R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    out = []
    for off, xyz in zip(offsets, is_xyz):
        y = x[off:off + 6]
        if xyz:
            a = y[:3] - r
        else:
            th, ph, rho = y[3:6]
            a = np.array([np.cos(ph) * np.sin(th), -np.sin(ph), np.cos(ph) * np.cos(th)]) + rho * (y[:3] - r)
        uv, ok = cam.project((R.T @ a)[None])
        assert ok[0]
        out.append(uv[0])
    return np.concatenate(out)


def direct_log_likelihood(x, P, offsets, is_xyz, z, sigma):
    h0 = reference_measurement(x, offsets, is_xyz)
    H = np.zeros((len(h0), len(x)))
    for i in range(len(x)):
        step = 1e-6 * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += step
        xm[i] -= step
        H[:, i] = (reference_measurement(xp, offsets, is_xyz) - reference_measurement(xm, offsets, is_xyz)) / (2 * step)
    S = H @ P @ H.T + sigma ** 2 * np.eye(len(h0))
    return multivariate_normal(mean=h0, cov=S).logpdf(z)


def started_bank(seq, f_values, n_features, options=None):
    """A bank that has seen frame 0 (features added there) and predicted frame 1."""
    options = options or _core.SogOptions()
    bank = small_bank(f_values, options)
    truth = seq.truth_in_first_camera()
    cov = np.zeros((13, 13))
    cov[7:, 7:] = np.eye(6) * 0.1 ** 2
    bank.set_camera_state(truth["motion"][0], cov)
    pick = np.linspace(0, len(seq.ids[0]) - 1, n_features).astype(int)
    ids = bank.add_features(seq.uv[0][pick])
    bank.predict(seq.times_s[1] - seq.times_s[0])
    row = {p: i for i, p in enumerate(seq.ids[1])}
    rows = [row[p] for p in seq.ids[0][pick]]
    return bank, ids, seq.uv[1][rows]


def test_weight_update_equals_direct_computation():
    seq = simulate_sequence(duration_s=0.2, seed=1)
    options = _core.SogOptions()
    options.gate_chi2 = 0.0  # use every measurement
    bank, ids, z = started_bank(seq, [180.0, 194.06, 210.0], 8, options)
    prior = bank.weights
    offsets, is_xyz = bank.feature_offsets, bank.feature_is_xyz
    direct = [direct_log_likelihood(bank.state(i), bank.covariance(i), offsets, is_xyz, z.ravel(),
                                    options.pixel_sigma) for i in range(3)]
    report = bank.update(ids, z)
    assert report.num_used == 8
    np.testing.assert_allclose(report.log_likelihoods, direct, rtol=1e-6)
    expected = prior * np.exp(np.array(direct) - max(direct))
    np.testing.assert_allclose(bank.weights, expected / expected.sum(), rtol=1e-5)


def test_log_space_is_finite_for_200_dimensional_innovations():
    # 100 features (200-D innovations) and filters far more confident than the data (0.05 px for
    # 0.5 px noise): N(nu; 0, S) < exp(-745) is zero in a double for both, so a linear-space
    # weight update would give 0/0.
    seq = simulate_sequence(duration_s=0.2, seed=2)
    options = _core.SogOptions()
    options.gate_chi2 = 0.0
    options.prune = False
    options.pixel_sigma = 0.05
    bank = small_bank([150.0, 194.06], options)
    reports = []
    track(bank, seq, min_visible=100, max_new_per_frame=100, min_separation_px=8.0,
          on_frame=lambda k, b, r: reports.append(r))
    big = [r for r in reports if r.num_used >= 100]
    assert len(big) >= 3
    for r in big:
        m = 2 * r.num_used
        log_det = -2 * r.log_likelihoods - r.nis - m * np.log(2 * np.pi)
        assert np.all(np.isfinite(r.log_likelihoods)) and np.all(np.isfinite(log_det))
        assert np.all(r.log_likelihoods < -745.0)  # np.exp gives 0
    assert np.all(np.isfinite(bank.log_weights))
    np.testing.assert_allclose(np.exp(bank.log_weights).sum(), 1.0)


# ----------------------------------------------------------------------------------- the filter at work


def test_pruning_removes_the_wrong_gaussians_and_keeps_the_right_one():
    seq = simulate_sequence(duration_s=6.0, seed=0)
    bank = small_bank([150.0, 194.06, 240.0])
    history = track(bank, seq)
    assert bank.gaussian_ids == [1]
    assert 0 < history.collapse_frame < len(seq)
    assert abs(bank.calibration_mean[0] / TRUTH[0] - 1) < 0.01


def nees(error, cov):
    return float(error @ np.linalg.solve(cov, error))


def test_single_ekf_with_the_true_calibration_is_consistent():
    # Measurement noise as the filter assumes it; scale-free quantities (calibration, orientation):
    # monocular position carries the unobservable scale, whose drift the EKF does not bound.
    options = _core.SogOptions()
    seq = simulate_sequence(duration_s=6.0, seed=4, noise_px=options.pixel_sigma)
    truth = seq.truth_in_first_camera()
    bank = small_bank([TRUTH[0]], options)
    cov = np.zeros((13, 13))
    cov[7:, 7:] = np.eye(6) * 0.1 ** 2
    bank.set_camera_state(truth["motion"][0], cov)
    calib, orient = [], []

    def on_frame(k, b, report):
        x, P = b.state(0), b.covariance(0)
        calib.append(nees(x[:5] - TRUTH, P[:5, :5]))
        q, qt = x[8:12], truth["q_wc"][k]
        # Orientation error as a rotation vector in the camera frame, covariance through its Jacobian.
        rot_t = Rotation.from_quat([qt[1], qt[2], qt[3], qt[0]])
        err = lambda qq: (rot_t.inv() * Rotation.from_quat([qq[1], qq[2], qq[3], qq[0]])).as_rotvec()  # noqa: E731
        e0 = err(q)
        J = np.column_stack([(err(q + 1e-7 * d) - e0) / 1e-7 for d in np.eye(4)])
        orient.append(nees(e0, J @ P[8:12, 8:12] @ J.T) if k > 0 else 0.0)

    track(bank, seq, on_frame=on_frame)
    calib, orient = np.array(calib[10:]), np.array(orient[10:])
    assert calib.mean() < chi2.ppf(0.99, 5) and np.mean(calib < chi2.ppf(0.999, 5)) > 0.95
    assert orient.mean() < chi2.ppf(0.99, 3) and np.mean(orient < chi2.ppf(0.999, 3)) > 0.95


def test_108_gaussian_bank_self_calibrates():
    seq = simulate_sequence(duration_s=10.0, seed=0)
    bank = make_bank(320, 240, 0.0112)
    counts_before_guard = []

    def on_frame(k, b, report):
        if not b.pruning_active:
            counts_before_guard.append(b.num_gaussians)

    history = track(bank, seq, on_frame=on_frame)
    # The guard holds every Gaussian until the calibration is observable.
    assert len(counts_before_guard) >= 10 and set(counts_before_guard) == {108}
    assert bank.num_gaussians < 5
    final = history.mean[-1]
    bounds = history.bounds_99[-1]
    assert abs(final[0] / TRUTH[0] - 1) < 0.02
    assert np.all((bounds[:, 0] <= TRUTH) & (TRUTH <= bounds[:, 1])), (final, bounds)
