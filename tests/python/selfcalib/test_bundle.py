"""Bundle adjustment over a self-calibration run's tracks (rscalib.selfcalib.bundle, issue 11)."""
from __future__ import annotations

import numpy as np
import pytest

import rscalib.selfcalib.bundle as bundle_module
from rscalib.selfcalib.bundle import TrackRecorder, build_problem, bundle_adjust, project_civera, residuals_and_jacobian
from rscalib.selfcalib.calibrate import default_options
from rscalib.selfcalib.driver import run_bank
from rscalib.selfcalib.prior import PAPER_PIXEL_SIZE_MM, make_bank
from rscalib.sim.scene_features import PAPER_CAMERA, CiveraCamera, TrueCorrespondences, simulate_sequence

NOISE_PX = 0.5


@pytest.fixture(scope="module")
def run():
    """The bank over a 4 s simulated hand-held room walk (true correspondences, 0.5 px noise), with
    its tracks recorded."""
    source = TrueCorrespondences(simulate_sequence(duration_s=4.0, seed=3, noise_px=NOISE_PX))
    recorder = TrackRecorder(source)
    bank = make_bank(320, 240, PAPER_PIXEL_SIZE_MM, options=default_options())
    history = run_bank(bank, source.frames(), recorder, on_frame=recorder.on_frame)
    return history.mean[-1].copy(), recorder.tracks()


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


def test_jacobian_matches_central_differences(run):
    filter_mean, tracks = run
    problem = build_problem(tracks, filter_mean, np.array([PAPER_PIXEL_SIZE_MM] * 2), 3, 3)
    rng = np.random.default_rng(11)
    x = problem.x_full[problem.free]
    scale = np.full(len(x), 0.01)                     # rad, m: rotations away from zero
    scale[:5] = 0.01 * np.abs(x[:5])                    # the camera by 1 %
    x = x + scale * rng.standard_normal(len(x))
    _, jac = residuals_and_jacobian(problem, x)
    dense = jac.toarray()
    point_cols = np.arange(problem.point_offset() - 6, len(x))   # the points (the first pose is held)
    columns = np.r_[np.arange(17), rng.choice(point_cols, 12, replace=False)]
    for c in columns:
        step = 1e-6 * max(1.0, abs(x[c]))
        e = np.zeros_like(x)
        e[c] = step
        numeric = (residuals_and_jacobian(problem, x + e, False)[0] -
                   residuals_and_jacobian(problem, x - e, False)[0]) / (2 * step)
        np.testing.assert_allclose(dense[:, c], numeric, rtol=0, atol=1e-6 * max(1.0, np.abs(numeric).max()),
                                   err_msg=f"column {c}")


@pytest.mark.parametrize("max_track_frames", [None, 20])
def test_schur_complement_matches_a_dense_inverse(run, max_track_frames):
    filter_mean, tracks = run
    problem = build_problem(tracks, filter_mean, np.array([PAPER_PIXEL_SIZE_MM] * 2), 3, 3, max_track_frames)
    _, jac = residuals_and_jacobian(problem, problem.x_full[problem.free])
    normal = (jac.T @ jac).tocsr()
    dense = np.linalg.inv(normal.toarray())[:, :5]
    columns = bundle_module._camera_columns_of_inverse(problem, normal)
    np.testing.assert_allclose(columns[:5], dense[:5], rtol=1e-6, atol=1e-9 * np.abs(dense[:5]).max())
