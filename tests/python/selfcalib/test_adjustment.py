"""The C++ (Ceres) self-calibration bundle adjustment through rscalib.selfcalib.adjustment (docs/sog.md §22).

Oracles: the simulated truth (rscalib.sim.scene_features) and the SciPy adjustment
(scipy_reference_bundle.bundle_adjust beside this file, the product's former engine) on the same
observations.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import os
import pathlib
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rscalib import _core
from rscalib.errors import InputError
from rscalib.selfcalib.adjustment import KeyframeTracks, adjust, anchored_points
from rscalib.selfcalib.prior import PAPER_PIXEL_SIZE_MM
from rscalib.sim.scene_features import PAPER_CAMERA, HandheldRoomMotion, simulate_sequence


def _load_reference():
    """The SciPy reference adjustment beside this file (a test module, not in the package)."""
    path = pathlib.Path(__file__).with_name("scipy_reference_bundle.py")
    spec = importlib.util.spec_from_file_location("scipy_reference_bundle", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module     # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


_reference = _load_reference()
FeatureTracks, build_problem = _reference.FeatureTracks, _reference.build_problem
bundle_adjust, track_velocity = _reference.bundle_adjust, _reference.track_velocity

NOISE_PX = 0.5
LINE_DELAY_S = 60e-6
REFERENCE_ROW = 119.5
KEYFRAME_STEP = 3
START = np.array([185.0, 155.0, 124.0, 0.03, 0.0])   # a generic start: f 5 % short, centre 5 px off


def _camera(params) -> _core.CameraModel:
    return _core.CameraModel("civera-radial", np.asarray(params, float), 320, 240,
                             [PAPER_PIXEL_SIZE_MM, PAPER_PIXEL_SIZE_MM])


def _rolling_shutter(sequence, motion, line_delay_s, reference_row):
    """Each point seen at its own row's time t + d (v - v_ref) (fixed point, three passes)."""
    camera, uv_rs = sequence.camera, []
    for k, t in enumerate(sequence.times_s):
        X = sequence.points_w[sequence.ids[k]]
        uv = sequence.uv_true[k]
        for _ in range(3):
            R_wc, r_w = motion.pose_wc(t + line_delay_s * (uv[:, 1] - reference_row))
            uv = camera.project(np.einsum("nji,nj->ni", R_wc, X - r_w))[0]
        uv_rs.append(uv + (sequence.uv[k] - sequence.uv_true[k]))
    return dataclasses.replace(sequence, uv=uv_rs, uv_true=uv_rs)


def _feature_tracks(sequence, seed: int = 0, every: int = 1) -> FeatureTracks:
    """The simulated pixels as recorded tracks (of every ``every``-th room point), with poses (2 cm,
    0.6°) and points (5 %) perturbed from the truth: a start like the filter's."""
    rng = np.random.default_rng(seed)
    R_cw, p_cw = sequence.R_cw, sequence.p_cw
    frames = range(len(sequence))
    turn = Rotation.from_rotvec(rng.normal(0, 0.01, (len(sequence), 3))).as_matrix()
    kept = [ids % every == 0 for ids in sequence.ids]
    seen = np.unique(np.concatenate([ids[k] for ids, k in zip(sequence.ids, kept)]))
    return FeatureTracks(
        frame=np.concatenate([np.full(k.sum(), f) for f, k in zip(frames, kept)]),
        feature_id=np.concatenate([ids[k] for ids, k in zip(sequence.ids, kept)]).astype(np.int64),
        uv=np.concatenate([uv[k] for uv, k in zip(sequence.uv, kept)]),
        R_cw={k: turn[k] @ R_cw[k] for k in frames},
        p_cw={k: p_cw[k] + rng.normal(0, 0.02, 3) for k in frames},
        points={int(i): sequence.points_w[i] * (1 + 0.05 * rng.standard_normal()) for i in seen},
        t_s={k: float(sequence.times_s[k]) for k in frames})


def _same_problem(tracks: FeatureTracks, line_delay: bool):
    """SciPy's problem (bundle.build_problem) and the same observations as KeyframeTracks."""
    problem = build_problem(tracks, START, np.array([PAPER_PIXEL_SIZE_MM] * 2), KEYFRAME_STEP, 3,
                            line_delay=line_delay, reference_row=REFERENCE_ROW)
    _, _, p, X = problem.unpack(problem.x_full[problem.free])
    poses = np.c_[p, Rotation.from_matrix(problem.R0).as_rotvec()]
    velocity = np.zeros_like(problem.uv)
    if problem.shutter is not None:   # the shift per µs/row back to px/s
        rows = (problem.uv[:, 1] - REFERENCE_ROW) * 1e-6
        velocity = np.divide(problem.shutter, rows[:, None], out=velocity, where=rows[:, None] != 0)
    keyframe_tracks = KeyframeTracks(keyframe_poses=poses, keyframe=problem.obs_pose, point=problem.obs_point,
                                     uv_px=problem.uv, image_velocity_px_s=velocity, points_w=X)
    return problem, keyframe_tracks


def _keyframe_tracks(tracks: FeatureTracks) -> KeyframeTracks:
    """Every 3rd frame a keyframe, features seen in >= 3 keyframes, velocities from the tracks."""
    frames = np.array(sorted(tracks.R_cw))
    keyframes = frames[::KEYFRAME_STEP]
    velocity = track_velocity(tracks)
    on_key = np.isin(tracks.frame, keyframes)
    ids, counts = np.unique(tracks.feature_id[on_key], return_counts=True)
    keep = on_key & np.isin(tracks.feature_id, ids[counts >= 3])
    kept_ids = ids[counts >= 3]
    R = np.array([tracks.R_cw[int(k)] for k in keyframes])
    p = np.array([tracks.p_cw[int(k)] for k in keyframes])
    return KeyframeTracks(keyframe_poses=np.c_[p, Rotation.from_matrix(R).as_rotvec()],
                          keyframe=np.searchsorted(keyframes, tracks.frame[keep]),
                          point=np.searchsorted(kept_ids, tracks.feature_id[keep]),
                          uv_px=tracks.uv[keep], image_velocity_px_s=velocity[keep],
                          points_w=np.array([tracks.points[int(i)] for i in kept_ids]))


@pytest.fixture(scope="module")
def walk():
    """A 4 s hand-held room walk, global shutter, 0.5 px noise ."""
    return simulate_sequence(duration_s=4.0, seed=3, noise_px=NOISE_PX)


@pytest.fixture(scope="module")
def rolling_walk(walk):
    return _rolling_shutter(walk, HandheldRoomMotion(seed=3), LINE_DELAY_S, REFERENCE_ROW)


@pytest.fixture(scope="module")
def clean_rolling_walk(walk, rolling_walk):
    """The rolling-shutter pixels without their noise: velocities a front end measures well."""
    noise = [uv - uv_true for uv, uv_true in zip(walk.uv, walk.uv_true)]
    return dataclasses.replace(rolling_walk, uv=[uv - n for uv, n in zip(rolling_walk.uv, noise)])


def _inside(bounds, truth):
    return (bounds[:, 0] <= truth) & (truth <= bounds[:, 1])


# ------------------------------------------------------------------------------- the SciPy oracle


@pytest.mark.parametrize("line_delay", [False, True])
def test_matches_the_scipy_adjustment_on_the_same_tracks(walk, rolling_walk, line_delay):
    """Same observations, same start, same loss family: the cameras agree within a small fraction
    of their sigma, and so do the covariances (SciPy's loss is per pixel coordinate, Ceres' per
    observation: the weights differ slightly, so the bars are 0.1 sigma and 3 %; measured 0.03 sigma
    and 1 %)."""
    tracks = _feature_tracks(rolling_walk if line_delay else walk, seed=1, every=4)
    scipy_result = bundle_adjust(tracks, START, PAPER_PIXEL_SIZE_MM, keyframe_step=KEYFRAME_STEP, line_delay=line_delay,
                                 reference_row=REFERENCE_ROW)
    problem, keyframe_tracks = _same_problem(tracks, line_delay)
    assert problem.estimates_line_delay == line_delay
    result = adjust(keyframe_tracks, _camera(START), estimate_line_delay=line_delay, reference_row=REFERENCE_ROW)
    assert result.converged, result.message
    assert result.dropped_observations == 0
    sigma = np.sqrt(np.diag(scipy_result.covariance))
    np.testing.assert_array_less(np.abs(result.camera_params - scipy_result.camera), 0.1 * sigma)
    np.testing.assert_allclose(np.sqrt(np.diag(result.covariance_model))[:5], sigma, rtol=0.03)
    np.testing.assert_allclose(np.sqrt(np.diag(result.covariance_two_way))[:5],
                               np.sqrt(np.diag(scipy_result.covariance_clustered)), rtol=0.03)
    assert result.sigma_px == pytest.approx(scipy_result.sigma_px, rel=0.02)
    if line_delay:
        d_sigma = np.sqrt(scipy_result.covariance_globals[5, 5]) * 1e-6     # its globals are in µs/row
        assert abs(result.line_delay_s - scipy_result.line_delay_s) < 0.1 * d_sigma


def test_least_squares_matches_scipy_to_a_thousandth_of_sigma(walk):
    """With the robust loss out of reach (scale 1e4 px) both solve plain least squares: one minimum."""
    tracks = _feature_tracks(walk, seed=2, every=4)
    scipy_result = bundle_adjust(tracks, START, PAPER_PIXEL_SIZE_MM, keyframe_step=KEYFRAME_STEP, loss_scale_px=1e4,
                                 max_nfev=300, ftol=1e-12)
    _, keyframe_tracks = _same_problem(tracks, False)
    result = adjust(keyframe_tracks, _camera(START), loss="none")
    sigma = np.sqrt(np.diag(scipy_result.covariance))
    np.testing.assert_array_less(np.abs(result.camera_params - scipy_result.camera), 1e-3 * sigma)
    np.testing.assert_allclose(result.covariance_model[:5, :5], scipy_result.covariance, rtol=1e-3,
                               atol=1e-6 * np.abs(scipy_result.covariance).max())
    np.testing.assert_allclose(result.covariance_tracks[:5, :5], scipy_result.covariance_tracks, rtol=1e-3,
                               atol=1e-6 * np.abs(scipy_result.covariance_tracks).max())


# ------------------------------------------------------------------------------- the truth


def test_truth_inside_the_bounds_of_a_rolling_shutter_walk(rolling_walk, clean_rolling_walk):
    """Every room point tracked (60k observations) through a 60 µs/row shutter, velocities from the
    tracks' noise-free pixels: the camera and the line delay inside their two-way 99 % bounds, d within
    5 %; the residuals back to the simulated noise. (Velocities from the noisy pixels' two-frame
    differences bias d low by 3 %, 4 of its sigmas here: errors in the regressor, docs/sog.md §22.)"""
    tracks = _keyframe_tracks(_feature_tracks(rolling_walk, seed=3))
    velocity = _keyframe_tracks(_feature_tracks(clean_rolling_walk, seed=3)).image_velocity_px_s
    result = adjust(dataclasses.replace(tracks, image_velocity_px_s=velocity), _camera(START),
                    estimate_line_delay=True)
    assert result.converged, result.message
    truth = np.r_[PAPER_CAMERA.params, LINE_DELAY_S]
    assert _inside(result.bounds_99_two_way, truth).all(), (result.estimate, result.bounds_99_two_way)
    assert abs(result.line_delay_s / LINE_DELAY_S - 1) < 0.05
    assert result.sigma_px == pytest.approx(NOISE_PX, rel=0.05)
    assert result.names == ["f", "cx", "cy", "k1", "k2", "line_delay_s"]
    # the world points: the anchored ones converted back, in front of their anchors
    assert np.isfinite(result.points_w).all()


def test_zero_line_delay_inside_its_bounds_on_a_global_shutter(walk):
    tracks = _keyframe_tracks(_feature_tracks(walk, seed=4))
    result = adjust(tracks, _camera(START), estimate_line_delay=True)
    truth = np.r_[PAPER_CAMERA.params, 0.0]
    assert _inside(result.bounds_99_two_way, truth).all(), (result.estimate, result.bounds_99_two_way)
    # held at zero instead: the line delay's rows are zero and the camera still inside
    held = adjust(tracks, _camera(START))
    assert held.line_delay_s == 0.0 and not held.covariance_two_way[5].any()
    assert _inside(held.bounds_99_two_way[:5], PAPER_CAMERA.params).all()
    # the arrays are the caller's (the binding's are read-only views into the C++ result)
    for array in (held.keyframe_poses, held.points_anchored, held.covariance_two_way, held.residuals_px, held.inlier):
        assert array.flags.writeable


def test_a_line_delay_prior_and_held_parameters(rolling_walk):
    tracks = _keyframe_tracks(_feature_tracks(rolling_walk, seed=5))
    free = adjust(tracks, _camera(START), estimate_line_delay=True)
    prior = adjust(tracks, _camera(START), line_delay_prior=(LINE_DELAY_S, 0.1e-6))
    assert prior.estimates_line_delay
    # the prior's information adds to the data's (its pixel sigma, 0.5 px, is about the residuals' here)
    combined = 1 / np.sqrt(1 / free.covariance_model[5, 5] + 1 / 0.1e-6 ** 2)
    assert np.sqrt(prior.covariance_model[5, 5]) == pytest.approx(combined, rel=0.1)
    assert abs(prior.line_delay_s - LINE_DELAY_S) < 0.5e-6
    held = adjust(tracks, _camera(np.r_[START[0], PAPER_CAMERA.params[1:3], START[3:]]), free_params=["f", "k1", "k2"],
                  estimate_line_delay=True)
    np.testing.assert_array_equal(held.camera_params[1:3], PAPER_CAMERA.params[1:3])
    assert held.covariance_model[1, 1] == 0.0 and held.covariance_model[0, 0] > 0.0



def test_a_capped_free_solve_goes_on_bounded_to_the_same_answer(rolling_walk):
    """The points free for 2 iterations only (docs/sog.md §25), then held in their range from where
    they are: the same camera and line delay as the uncapped free solve, to 0.1 of their sigma, the
    camera's truth inside its bounds, and the result says how it was solved."""
    tracks = _keyframe_tracks(_feature_tracks(rolling_walk, seed=6))
    free = adjust(tracks, _camera(START), estimate_line_delay=True)
    assert free.converged and not free.solved_with_bounds and free.iterations > 2
    capped = adjust(tracks, _camera(START), estimate_line_delay=True, max_free_iterations=2)
    assert capped.converged, capped.message
    assert capped.solved_with_bounds and "iteration cap" in capped.message
    sigma = np.sqrt(np.diag(free.covariance_model))[:6]
    np.testing.assert_array_less(np.abs(capped.estimate - free.estimate), 0.1 * sigma)
    # the camera's truth inside (d from noisy velocities is biased low here, capped or not: see above)
    assert _inside(capped.bounds_99_two_way[:5], PAPER_CAMERA.params).all(), (capped.estimate, capped.bounds_99_two_way)

def test_anchored_points_put_each_point_in_its_first_keyframe():
    poses = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [-0.5, 0.0, 0.0, 0.0, 0.2, 0.0]])
    points_w = np.array([[0.2, 0.1, 2.0], [0.0, 0.0, -3.0], [1.0, -0.5, 4.0]])
    anchor, abr = anchored_points(poses, np.array([1, 0, 0, 1]), np.array([0, 0, 2, 2]), points_w)
    np.testing.assert_array_equal(anchor, [0, 0, 0])          # point 1 never observed: anchor 0
    np.testing.assert_allclose(abr[0], [0.1, 0.05, 0.5])
    assert abr[1, 2] == 0.0                                    # behind its anchor: at infinity
    x_c = Rotation.from_rotvec(poses[1, 3:]).apply(points_w[0]) + poses[1, :3]
    anchor1, abr1 = anchored_points(poses, np.array([1]), np.array([0]), points_w[:1])
    assert anchor1[0] == 1
    np.testing.assert_allclose(abr1[0], [x_c[0] / x_c[2], x_c[1] / x_c[2], 1 / x_c[2]])


# ------------------------------------------------------------------------------- errors


def _small_problem():
    """Two keyframes 0.5 m apart looking at a 5 x 4 grid 3 m ahead."""
    camera = _camera(PAPER_CAMERA.params)
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-0.6, 0.6, 4)), -1).reshape(-1, 2)
    points_w = np.c_[grid, np.full(len(grid), 3.0)]
    poses = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [-0.5, 0.0, 0.0, 0.0, 0.05, 0.0],
                      [-0.2, 0.1, 0.1, 0.02, -0.03, 0.0]])
    keyframe, point, uv = [], [], []
    for k, pose in enumerate(poses):
        x_c = Rotation.from_rotvec(pose[3:]).apply(points_w) + pose[:3]
        keyframe += [k] * len(points_w)
        point += list(range(len(points_w)))
        uv.append(camera.project(x_c))
    args = dict(camera=camera, keyframe_poses=poses, observation_keyframe=np.array(keyframe),
                observation_point=np.array(point), uv_px=np.concatenate(uv),
                image_velocity_px_s=np.zeros((len(keyframe), 2)))
    anchor, abr = anchored_points(poses, args["observation_keyframe"], args["observation_point"], points_w)
    return dict(args, point_anchor=anchor, points=abr)


def test_the_binding_solves_a_small_problem_exactly():
    args = _small_problem()
    result = _core.solve_bundle(**args, free_intrinsics=[True, False, False, False, False])
    assert result.converged and result.final_cost < 1e-16
    np.testing.assert_allclose(result.camera_params, PAPER_CAMERA.params, rtol=1e-9)


@pytest.mark.parametrize("change, words", [
    (dict(observation_keyframe=np.full(60, 7)), "is outside 0..2"),
    (dict(observation_point=np.arange(60) * 1.0), "must be a 1-D array of integers"),
    (dict(uv_px=np.full((60, 2), np.nan)), "uv_px has a NaN"),
    (dict(uv_px=np.zeros((60, 3))), "uv_px must have shape (n, 2)"),
    (dict(keyframe_poses=np.zeros((3, 5))), "keyframe_poses must have shape (n, 6)"),
    (dict(image_velocity_px_s=np.zeros((59, 2))), "one row per observation"),
    (dict(point_anchor=np.zeros(3, np.int64)), "point_anchor has 3 entries for 20 points"),
    (dict(free_intrinsics=[False] * 5), "nothing global to estimate"),
    (dict(estimate_line_delay=True), "every image velocity is zero"),
    (dict(line_delay_prior=(30e-6, 0.0)), "positive, finite sigma"),
])
def test_binding_errors_are_input_errors_with_the_reason(change, words):
    with pytest.raises(InputError) as error:
        _core.solve_bundle(**dict(_small_problem(), **change))
    assert words in str(error.value)


def test_a_problem_larger_than_the_machine_is_refused_before_it_is_built():
    """One point seen from every keyframe links them all: the reduced camera matrix (6 x 6 blocks of
    8 bytes, twice) would need more than the machine's memory."""
    memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    count = int(np.sqrt(2 * memory / 576)) + 1000
    poses = np.c_[np.linspace(0, 1, count), np.zeros((count, 5))]
    uv = np.full((count, 2), 160.0)
    with pytest.raises(InputError, match="GB, more than the"):
        _core.solve_bundle(_camera(PAPER_CAMERA.params), poses, np.arange(count), np.zeros(count, np.int64), uv,
                           np.zeros_like(uv), np.zeros(1, np.int64), np.array([[0.0, 0.0, 0.5]]))


def test_option_and_wrapper_errors_are_input_errors():
    options = _core.BundleOptions()
    with pytest.raises(InputError, match="num_threads"):
        options.num_threads = 0
    options.robust_loss = "tukey"
    with pytest.raises(InputError, match="robust_loss"):
        _core.solve_bundle(**_small_problem(), options=options)
    tracks = KeyframeTracks(keyframe_poses=np.zeros((2, 6)), keyframe=np.zeros(3, np.int64),
                            point=np.zeros(3, np.int64), uv_px=np.zeros((3, 2)))
    with pytest.raises(InputError, match="give points_w"):
        adjust(tracks, _camera(START))
    with pytest.raises(InputError, match="not parameters of civera-radial"):
        adjust(dataclasses.replace(tracks, points_w=np.ones((1, 3))), _camera(START), free_params=["fx"])
    with pytest.raises(InputError, match="point indices"):
        adjust(dataclasses.replace(tracks, points_w=np.ones((1, 3)), point=np.array([0, 1, 2])), _camera(START))
