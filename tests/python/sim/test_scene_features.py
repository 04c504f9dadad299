"""Tests of rscalib.sim.scene_features, the feature-level ground truth of the SOG self-calibration filter.

Oracles: the C++ camera model (rscalib.CameraModel, itself tested against a NumPy reference in
test_camera.py) for the simulator's own NumPy projection, and central differences of the analytic
trajectory for its velocities; the sequence's own ids and pixels for its measurement source.
"""
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rscalib import CameraModel
from rscalib.sim.scene_features import (
    PAPER_CAMERA,
    CiveraCamera,
    HandheldRoomMotion,
    TrueCorrespondences,
    room_points,
    simulate_sequence,
)


@pytest.fixture(scope="module")
def sequence():
    return simulate_sequence(duration_s=2.0, seed=3, noise_px=0.5)


def test_projection_matches_the_core_camera_model():
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-2, 2, 500), rng.uniform(-1.5, 1.5, 500), rng.uniform(0.5, 4, 500)]
    cam = PAPER_CAMERA
    core = CameraModel("civera-radial", cam.params, cam.width, cam.height, [cam.pixel_size_mm] * 2)
    uv, ok = cam.project(pts)
    assert ok.all()
    np.testing.assert_allclose(uv, core.project(pts), atol=1e-9)
    # Undistorting the projection gives the pinhole pixel.
    pinhole = cam.params[1:3] + cam.f * pts[:, :2] / pts[:, 2:]
    np.testing.assert_allclose(cam.undistort(uv), pinhole, atol=1e-9)
    _, ok = cam.project(np.array([[0.1, 0.2, -1.0]]))
    assert not ok[0]


def test_room_points_lie_on_the_walls():
    pts = room_points(size_m=(4.0, 2.0, 6.0), center_m=(0.0, 0.0, 1.0), density_per_m2=10, seed=1)
    half = np.array([2.0, 1.0, 3.0])
    on_face = np.isclose(np.abs(pts - [0.0, 0.0, 1.0]), half, atol=1e-12)
    assert np.all(on_face.sum(axis=1) >= 1)
    assert len(pts) == 2 * round(10 * (2 * 6 + 4 * 6 + 4 * 2))


def test_measurements_are_projections_of_the_truth(sequence):
    cam = sequence.camera
    for k in (0, 17, len(sequence) - 1):
        ids = sequence.ids[k]
        assert len(ids) > 200
        # docs/conventions.md: x_c = R_cw x_w + p_cw.
        pc = np.einsum("ij,nj->ni", sequence.R_cw[k], sequence.points_w[ids]) + sequence.p_cw[k]
        uv, ok = cam.project(pc)
        assert ok.all() and np.all(pc[:, 2] > 0)
        np.testing.assert_allclose(sequence.uv_true[k], uv, atol=1e-9)
        assert np.all((sequence.uv[k] >= 0) & (sequence.uv[k] <= [cam.width - 1, cam.height - 1]))
    noise = np.concatenate([u - t for u, t in zip(sequence.uv, sequence.uv_true)])
    assert abs(noise.std() - 0.5) < 0.02 and abs(noise.mean()) < 0.01


def test_velocities_match_the_poses():
    motion = HandheldRoomMotion(seed=5)
    t = np.linspace(0.0, 5.0, 11)
    h = 1e-4
    v, w = motion.velocities(t)
    (R1, r1), (_R0, r0) = motion.pose_wc(t + h), motion.pose_wc(t - h)
    np.testing.assert_allclose(v, (r1 - r0) / (2 * h), atol=1e-6)
    R, _ = motion.pose_wc(t)
    # Body-frame angular velocity: R(t + h) ~ R(t) exp(h w).
    step = Rotation.from_matrix(np.einsum("nji,njk->nik", R, R1)).as_rotvec() / h
    np.testing.assert_allclose(w, step, atol=1e-3)


def test_truth_in_first_camera(sequence):
    truth = sequence.truth_in_first_camera()
    np.testing.assert_allclose(truth["r"][0], 0.0, atol=1e-15)
    np.testing.assert_allclose(truth["q_wc"][0], [1, 0, 0, 0], atol=1e-12)
    k = 20
    # The same point seen from frame k in both world frames.
    p_first = truth["points"][sequence.ids[k]]
    pc_first = np.einsum("ji,nj->ni", truth["R_wc"][k], p_first - truth["r"][k])
    pc_world = np.einsum("ij,nj->ni", sequence.R_cw[k], sequence.points_w[sequence.ids[k]]) + sequence.p_cw[k]
    np.testing.assert_allclose(pc_first, pc_world, atol=1e-12)
    q = truth["q_wc"][k]
    R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    np.testing.assert_allclose(R, truth["R_wc"][k], atol=1e-12)
    assert truth["motion"].shape == (len(sequence), 13)


def test_simulation_is_deterministic():
    a = simulate_sequence(duration_s=0.5, seed=7)
    b = simulate_sequence(duration_s=0.5, seed=7)
    assert all(np.array_equal(x, y) for x, y in zip(a.uv, b.uv))
    c = simulate_sequence(camera=CiveraCamera(f=250.0, width=400, height=300), duration_s=0.2, seed=7,
                          noise_px=0.0)
    assert c.camera.width == 400
    np.testing.assert_array_equal(c.uv[0], c.uv_true[0])


def test_true_correspondences_measure_the_points_the_features_started_on(sequence):
    source = TrueCorrespondences(sequence, min_separation_px=15.0, seed=1)
    assert source.frames()[:2] == [(0.0, 0), (sequence.times_s[1], 1)]
    empty = SimpleNamespace(ids=np.zeros(0, dtype=np.int64), uv_pred=np.zeros((0, 2)))
    uv0 = source.new_features(0, 12, empty)
    assert len(uv0) == 12
    gaps = np.linalg.norm(uv0[:, None] - uv0[None], axis=2)[np.triu_indices(12, 1)]
    assert gaps.min() >= 15.0
    feature_ids = np.arange(100, 112)
    source.track(0, feature_ids, uv0)
    points = [source.feature_to_point[int(f)] for f in feature_ids]
    rows0 = [int(np.flatnonzero(sequence.ids[0] == p)[0]) for p in points]
    np.testing.assert_array_equal(sequence.uv[0][rows0], uv0)
    k = 25
    ids = np.append(feature_ids, 7)                      # 7: a feature the source never started
    uv, found = source.measure(k, ids, np.zeros((13, 2)), np.zeros((13, 2, 2)))
    for i, point in enumerate(points):
        rows = np.flatnonzero(sequence.ids[k] == point)
        assert found[i] == bool(len(rows))
        if len(rows):
            np.testing.assert_array_equal(uv[i], sequence.uv[k][rows[0]])
    assert not found[12] and np.isnan(uv[12]).all()
    # Forgotten features free their points; new ones keep away from the predicted features.
    source.forget(feature_ids[:2])
    assert set(source.feature_to_point) == set(int(f) for f in feature_ids[2:])
    predicted = SimpleNamespace(ids=feature_ids, uv_pred=uv0)
    more = source.new_features(0, 5, predicted)
    alive = uv0[2:]
    assert len(more) and np.linalg.norm(more[:, None] - alive[None], axis=2).min() >= 15.0
