"""Bundle adjustment over a self-calibration run's tracks (rscalib.selfcalib.bundle, issue 11)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rscalib.selfcalib.bundle as bundle_module
from rscalib.reference_cameras import PAPER_PIXEL_SIZE_MM
from rscalib.selfcalib.bundle import TrackRecorder, build_problem, bundle_adjust, project_civera, residuals_and_jacobian
from rscalib.selfcalib.driver import run_bank
from rscalib.selfcalib.engine import sog_options
from rscalib.selfcalib.options import SelfCalibOptions
from rscalib.selfcalib.prior import make_bank
from rscalib.selfcalib.rolling_shutter import timed_frames
from rscalib.sim.scene_features import (
    PAPER_CAMERA,
    CiveraCamera,
    HandheldRoomMotion,
    TrueCorrespondences,
    simulate_sequence,
)

NOISE_PX = 0.5
LINE_DELAY_S = 60e-6        # 14 ms over 240 rows
REFERENCE_ROW = 119.5


def _recorded_run(sequence):
    source = TrueCorrespondences(sequence)
    recorder = TrackRecorder(source, unwrap=True)
    bank = make_bank(320, 240, PAPER_PIXEL_SIZE_MM, options=sog_options(SelfCalibOptions()))
    history = run_bank(bank, timed_frames(source.frames()), recorder, on_frame=recorder.on_frame)
    return history.mean[-1].copy(), recorder.tracks()


@pytest.fixture(scope="module")
def run():
    """The bank over a 4 s simulated hand-held room walk (true correspondences, 0.5 px noise), with
    its tracks recorded."""
    return _recorded_run(simulate_sequence(duration_s=4.0, seed=3, noise_px=NOISE_PX))


def _rolling_shutter(sequence, motion, line_delay_s, reference_row):
    """The same sequence seen by a rolling shutter: each point projected with the pose at its own
    row's time t + d (v - v_ref) (fixed point of the row, three passes), the same pixel noise added."""
    camera, uv_rs = sequence.camera, []
    for k, t in enumerate(sequence.times_s):
        X = sequence.points_w[sequence.ids[k]]
        uv = sequence.uv_true[k]
        for _ in range(3):
            R_wc, r_w = motion.pose_wc(t + line_delay_s * (uv[:, 1] - reference_row))
            uv = camera.project(np.einsum("nji,nj->ni", R_wc, X - r_w))[0]
        uv_rs.append(uv + (sequence.uv[k] - sequence.uv_true[k]))
    return dataclasses.replace(sequence, uv=uv_rs, uv_true=uv_rs)


@pytest.fixture(scope="module")
def rolling_run():
    """The walk of ``run`` through a rolling shutter of LINE_DELAY_S."""
    sequence = simulate_sequence(duration_s=4.0, seed=3, noise_px=NOISE_PX)
    return _recorded_run(_rolling_shutter(sequence, HandheldRoomMotion(seed=3), LINE_DELAY_S, REFERENCE_ROW))


def test_bundle_recovers_the_simulated_camera_within_its_bounds(run):
    filter_mean, tracks = run
    result = bundle_adjust(tracks, filter_mean, PAPER_PIXEL_SIZE_MM)
    truth = PAPER_CAMERA.params
    inside = (result.bounds_99[:, 0] <= truth) & (truth <= result.bounds_99[:, 1])
    assert inside.all(), (result.camera, result.bounds_99)
    assert abs(result.camera[0] / truth[0] - 1) < 0.02
    # the residuals are the simulated noise: an oracle of the model, the poses and the points
    assert result.sigma_px == pytest.approx(NOISE_PX, rel=0.15)
    assert result.keyframes == len(range(0, len(tracks.R_cw), 3))    # every 3rd recorded frame
    assert result.line_delay_s is None


def test_bundle_estimates_the_line_delay_of_a_rolling_shutter(run, rolling_run):
    """Simulated truth: the line delay inside its 99 % bounds and within 25 %, and the camera inside
    its bounds; the global-shutter adjustment of the same tracks is further from the truth."""
    filter_mean, tracks = rolling_run
    truth = PAPER_CAMERA.params
    result = bundle_adjust(tracks, filter_mean, PAPER_PIXEL_SIZE_MM, line_delay=True, reference_row=REFERENCE_ROW)
    lo, hi = result.line_delay_bounds_99_s
    assert lo <= LINE_DELAY_S <= hi, (result.line_delay_s, lo, hi)
    assert abs(result.line_delay_s / LINE_DELAY_S - 1) < 0.25
    inside = (result.bounds_99_clustered[:, 0] <= truth) & (truth <= result.bounds_99_clustered[:, 1])
    assert inside.all(), (result.camera, result.bounds_99_clustered)
    assert result.sigma_px == pytest.approx(NOISE_PX, rel=0.15)
    ignoring = bundle_adjust(tracks, filter_mean, PAPER_PIXEL_SIZE_MM)
    assert ignoring.sigma_px > result.sigma_px
    # on the global-shutter walk the estimated line delay is zero within its bounds
    still = bundle_adjust(run[1], run[0], PAPER_PIXEL_SIZE_MM, line_delay=True, reference_row=REFERENCE_ROW)
    assert still.line_delay_bounds_99_s[0] <= 0.0 <= still.line_delay_bounds_99_s[1]


@pytest.mark.parametrize("camera", [PAPER_CAMERA, CiveraCamera(f=525.06, cx=308.65, cy=236.54, k1=-7.613e-3,
                                                               k2=9.388e-4, width=640, height=480,
                                                               pixel_size_mm=0.0070216)])
def test_projection_matches_the_simulators(camera):
    rng = np.random.default_rng(5)
    points = np.c_[rng.uniform(-0.9, 0.9, (500, 2)), np.full(500, 1.2)]
    expected, ok = camera.project(points)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(project_civera(camera.params, points, camera.pixel_size_mm)[ok], expected[ok],
                               atol=1e-9)


@pytest.mark.parametrize("line_delay", [False, True])
def test_jacobian_matches_central_differences(rolling_run, line_delay):
    filter_mean, tracks = rolling_run
    problem = build_problem(tracks, filter_mean, np.array([PAPER_PIXEL_SIZE_MM] * 2), 3, 3, line_delay=line_delay,
                            reference_row=REFERENCE_ROW)
    assert problem.estimates_line_delay == line_delay
    rng = np.random.default_rng(11)
    x = problem.x_full[problem.free]
    scale = np.full(len(x), 0.01)                     # rad, m: rotations away from zero
    scale[:5] = 0.01 * np.abs(x[:5])                    # the camera by 1 %
    if line_delay:
        x[5] = 50.0                                     # µs/row
    x = x + scale * rng.standard_normal(len(x))
    _, jac = residuals_and_jacobian(problem, x)
    dense = jac.toarray()
    first_point = int(problem.free[:problem.point_offset()].sum())   # the first pose is held
    point_cols = np.arange(first_point, len(x))
    columns = np.r_[np.arange(18), rng.choice(point_cols, 12, replace=False)]
    for c in columns:
        step = 1e-6 * max(1.0, abs(x[c]))
        e = np.zeros_like(x)
        e[c] = step
        numeric = (residuals_and_jacobian(problem, x + e, False)[0] -
                   residuals_and_jacobian(problem, x - e, False)[0]) / (2 * step)
        np.testing.assert_allclose(dense[:, c], numeric, rtol=0, atol=1e-6 * max(1.0, np.abs(numeric).max()),
                                   err_msg=f"column {c}")


@pytest.mark.parametrize("max_track_frames, line_delay", [(None, False), (20, False), (None, True)])
def test_schur_complement_matches_a_dense_inverse(rolling_run, max_track_frames, line_delay):
    filter_mean, tracks = rolling_run
    problem = build_problem(tracks, filter_mean, np.array([PAPER_PIXEL_SIZE_MM] * 2), 3, 3, max_track_frames,
                            line_delay=line_delay, reference_row=REFERENCE_ROW)
    _, jac = residuals_and_jacobian(problem, problem.x_full[problem.free])
    normal = (jac.T @ jac).tocsr()
    globals_ = 6 if line_delay else 5
    dense = np.linalg.inv(normal.toarray())[:, :globals_]
    columns = bundle_module._camera_columns_of_inverse(problem, normal)
    assert columns.shape == dense.shape
    np.testing.assert_allclose(columns[:globals_], dense[:globals_], rtol=1e-6,
                               atol=1e-9 * np.abs(dense[:globals_]).max())


def test_levenberg_marquardt_finish_reaches_scipys_converged_minimum(run):
    """Three TRF evaluations and the exact LM finish land where SciPy's TRF run to convergence lands."""
    filter_mean, tracks = run
    quick = bundle_adjust(tracks, filter_mean, PAPER_PIXEL_SIZE_MM, max_nfev=3)
    full = bundle_adjust(tracks, filter_mean, PAPER_PIXEL_SIZE_MM, max_nfev=3000, ftol=1e-14, polish_steps=0)
    sigma = np.sqrt(np.diag(full.covariance))
    assert quick.extra["polish_steps"] > 0
    assert quick.step_sigma < 0.1
    np.testing.assert_array_less(np.abs(quick.camera - full.camera), 0.1 * sigma)
    # the clustered covariances are positive semi-definite and at least as wide as the model's here
    for cov in (quick.covariance_tracks, quick.covariance_clustered):
        assert np.linalg.eigvalsh(cov).min() >= -1e-12 * np.abs(cov).max()
    assert np.all(np.diag(quick.covariance_clustered) > 0)


def _fake_bundle(camera, half_width, points=60, status=1, step_sigma=0.0):
    from rscalib.selfcalib.bundle import BundleResult

    camera = np.asarray(camera, float)
    sigma = np.asarray(half_width, float) / 2.5758293035489004
    cov = np.diag(sigma ** 2)
    bounds = np.c_[camera - half_width, camera + half_width]
    return BundleResult(camera=camera, covariance=cov, bounds_99=bounds, covariance_tracks=cov, bounds_99_tracks=bounds,
                        sigma_px=0.2, keyframes=60, points=points, observations=1000, inlier_fraction=1.0, rms_px=0.2,
                        nfev=10, status=status, message="", elapsed_s=0.1, start=camera, step_sigma=step_sigma,
                        covariance_clustered=cov, bounds_99_clustered=bounds)


def test_determined_needs_a_narrow_f_with_the_drift_shift_included():
    from rscalib.selfcalib.judge import judge_bundle

    prior = np.array([[80.0, 630.0], [140.0, 180.0], [100.0, 140.0], [-0.1, 0.1], [-0.01, 0.03]])
    camera = [194.0, 160.0, 120.0, 0.06, 0.014]
    half = np.array([1.0, 1.0, 1.0, 1e-3, 1e-4])
    ba = _fake_bundle(camera, half)
    same = _fake_bundle(camera, half)
    determined, reason, bounds = judge_bundle(ba, same, "", prior, 0.02)
    assert determined and "clustered" in reason
    np.testing.assert_allclose(bounds[:, 1] - bounds[:, 0], 2 * half)
    # the pieces' adjustment 3 px away: the shift counts as one more standard error, and f is no
    # longer known to 2 %
    shifted = _fake_bundle([197.0, *camera[1:]], half)
    determined, reason, bounds = judge_bundle(ba, shifted, "", prior, 0.02)
    assert not determined and "pin f only" in reason
    np.testing.assert_allclose(bounds, prior)           # the prior's, which contain the estimate
    wide_enough = judge_bundle(ba, shifted, "", prior, 0.05)
    assert wide_enough[0]
    np.testing.assert_allclose(wide_enough[2][0, 1] - 194.0, 2.5758293035489004 * np.hypot(1 / 2.5758293035489004, 3))
    # too few tracks, not converged, no drift check, no adjustment: not determined, with the reason
    assert "feature tracks" in judge_bundle(_fake_bundle(camera, half, points=12), same, "", prior, 0.02)[1]
    assert "did not converge" in judge_bundle(_fake_bundle(camera, half, status=0, step_sigma=0.5), same, "",
                                              prior, 0.02)[1]
    assert judge_bundle(_fake_bundle(camera, half, status=0, step_sigma=0.05), same, "", prior, 0.02)[0]
    assert "over 1000 sigma" in judge_bundle(_fake_bundle(camera, half, status=0, step_sigma=1e80), same, "",
                                             prior, 0.02)[1]
    assert "drift check" in judge_bundle(ba, None, "only 3 features", prior, 0.02)[1]
    assert not judge_bundle(None, None, "no tracks", prior, 0.02)[0]
    # a line delay that reads 240 rows in more than 1.25 frames (30 fps) is no shutter: not determined
    for delay_us, lo_us, hi_us, ok in [(60.0, 50.0, 70.0, True), (300.0, 200.0, 400.0, False),
                                       (-300.0, -400.0, -200.0, False), (150.0, -10.0, 300.0, True)]:
        shutter = _fake_bundle(camera, half)
        shutter.line_delay_s, shutter.line_delay_bounds_99_s = delay_us * 1e-6, np.array([lo_us, hi_us]) * 1e-6
        shutter.extra["frame_interval_s"] = 1 / 30
        verdict = judge_bundle(shutter, same, "", prior, 0.02, image_height=240)
        assert verdict[0] is ok, (delay_us, verdict[1])
        assert ok or "does not fit" in verdict[1]
        assert judge_bundle(shutter, same, "", prior, 0.02)[0]              # without the image height: not checked
    # an estimate outside the prior widens the reported bounds to include it
    far = _fake_bundle([700.0, *camera[1:]], np.array([100.0, 1, 1, 1e-3, 1e-4]))
    assert judge_bundle(far, far, "", prior, 0.02)[2][0, 1] == 700.0


def test_points_behind_a_camera_are_dropped_with_their_observations(run):
    """A point moved behind its cameras leaves the problem; every other residual is unchanged."""
    filter_mean, tracks = run
    problem = build_problem(tracks, filter_mean, np.array([PAPER_PIXEL_SIZE_MM] * 2), 3, 3)
    x = problem.x_full[problem.free].copy()
    res, _ = residuals_and_jacobian(problem, x, False)
    counts = np.bincount(problem.obs_point)
    victim = int(np.flatnonzero(counts >= 3)[-1])
    start = int(problem.free[:problem.point_offset()].sum()) + 3 * victim   # its x, y, z are free (not the anchor)
    assert problem.free[problem.point_offset() + 3 * victim:problem.point_offset() + 3 * victim + 3].all()
    x[start:start + 3] = -50.0 * x[start:start + 3]                          # through the camera to the other side
    reduced, x_reduced, dropped = bundle_module._without_points_behind(problem, x, 3)
    assert dropped == counts[victim]
    assert reduced.num_points == problem.num_points - 1
    keep = problem.obs_point != victim
    np.testing.assert_array_equal(residuals_and_jacobian(reduced, x_reduced, False)[0],
                                  res.reshape(-1, 2)[keep].ravel())
    assert bundle_module._without_points_behind(reduced, x_reduced, 3)[2] == 0
