"""Tests of rscalib.sim.target_observations: the rolling-shutter ground truth the line-delay engine is judged by.

Oracles are independent of the module under test: K and the distortion vector are built here from
the documented parameter layout, and projection is done here with cv2.projectPoints /
cv2.fisheye.projectPoints.
"""
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from rscalib.observations import Observations
from rscalib.sim.target_observations import (
    SimCamera,
    checkerboard_points,
    simulate_default,
    simulate_observations,
)
from rscalib.sim.trajectories import HandheldTrajectory, calm_then_wild

RADTAN = SimpleNamespace(model="pinhole-radtan",
                         params=np.array([500.0, 505.0, 319.5, 239.5, -0.1, 0.05, 1e-3, -5e-4, 0.0]),
                         width=640, height=480)
EQUIDISTANT = SimpleNamespace(model="pinhole-equidistant",
                              params=np.array([420.0, 420.0, 321.0, 238.0, 0.05, -0.02, 0.01, -0.002]),
                              width=640, height=480)


def oracle_project(camera, points_c):
    """Pixels of camera-frame points, straight from OpenCV."""
    fx, fy, cx, cy = camera.params[:4]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)
    pts = np.asarray(points_c, dtype=np.float64).reshape(-1, 1, 3)
    if camera.model == "pinhole-equidistant":
        uv, _ = cv2.fisheye.projectPoints(pts, np.zeros(3), np.zeros(3), K, camera.params[4:8].copy())
    else:
        uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, camera.params[4:9].copy())
    return uv.reshape(-1, 2)


def oracle_project_at(camera, trajectory, points_w, t_s):
    R, p = trajectory.pose_cw(t_s)
    xc = np.einsum("nij,nj->ni", R, points_w) + p
    assert np.all(xc[:, 2] > 0)
    return oracle_project(camera, xc)


def frame_time_of(sim):
    o = sim.observations
    return o.frame_times_s[o.frame_index]


def image_speed_px_s(sim):
    """Speed of each tracked point between consecutive video frames, with the frame time of the pair."""
    o = sim.observations
    frame = sim.video_frame_index[o.frame_index]
    key = frame * len(o.target_points) + o.point_id
    pos = {k: i for i, k in enumerate(key)}
    nxt = np.array([pos.get(k + len(o.target_points), -1) for k in key])
    has = nxt >= 0
    speed = np.linalg.norm(sim.uv_true[nxt[has]] - sim.uv_true[has], axis=1) * sim.fps
    return speed, frame_time_of(sim)[has]


def test_checkerboard_points_layout():
    pts = checkerboard_points(cols=9, rows=6, spacing_m=0.04)
    assert pts.shape == (54, 3)
    assert np.all(pts[:, 2] == 0)
    r, c = 4, 7
    np.testing.assert_allclose(pts[r * 9 + c], [c * 0.04, r * 0.04, 0.0], atol=1e-15)
    np.testing.assert_allclose(pts[-1], [8 * 0.04, 5 * 0.04, 0.0], atol=1e-15)


@pytest.mark.parametrize("camera", [RADTAN, EQUIDISTANT], ids=["radtan", "equidistant"])
def test_rolling_shutter_fixed_point_holds(camera):
    d = 60e-6
    sim = simulate_observations(camera, d, duration_s=6.0, noise_px=0.0, seed=3)
    o = sim.observations
    assert o.num_observations > 0.8 * 180 * 54
    t_exposure = frame_time_of(sim) + sim.uv_true[:, 1] * d  # own noise-free row, not the field
    uv = oracle_project_at(camera, sim.trajectory, o.points_w(), t_exposure)
    assert np.max(np.abs(uv - sim.uv_true)) < 1e-8
    np.testing.assert_allclose(sim.exposure_times_s, t_exposure, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(o.uv, sim.uv_true)  # noise_px = 0


def test_rolling_shutter_differs_from_global_shutter():
    d = 60e-6
    sim = simulate_observations(RADTAN, d, duration_s=8.0, noise_px=0.0, seed=1)
    o = sim.observations
    t_i = frame_time_of(sim)
    uv_gs = oracle_project_at(RADTAN, sim.trajectory, o.points_w(), t_i)
    shift = sim.uv_true - uv_gs
    assert np.median(np.linalg.norm(shift, axis=1)) > 1.0
    # The RS shift is (v d) times the image velocity at the middle of [t_i, t_i + v d] (to third
    # order): checks the sign and size of the time offset independently of the fixed-point test.
    h = 1e-5
    t_mid = t_i + 0.5 * sim.uv_true[:, 1] * d
    uv_dot = (oracle_project_at(RADTAN, sim.trajectory, o.points_w(), t_mid + h)
              - oracle_project_at(RADTAN, sim.trajectory, o.points_w(), t_mid - h)) / (2 * h)
    predicted = sim.uv_true[:, 1:2] * d * uv_dot
    residual = np.linalg.norm(shift - predicted, axis=1)
    assert np.median(residual) < 0.01 * np.median(np.linalg.norm(shift, axis=1))

    sim0 = simulate_observations(RADTAN, 0.0, duration_s=8.0, noise_px=0.0, seed=1)
    o0 = sim0.observations
    uv_gs0 = oracle_project_at(RADTAN, sim0.trajectory, o0.points_w(), frame_time_of(sim0))
    assert np.max(np.abs(sim0.uv_true - uv_gs0)) < 1e-9
    np.testing.assert_array_equal(sim0.exposure_times_s, frame_time_of(sim0))


def test_noise_statistics():
    noise_px = 0.5
    sim = simulate_observations(RADTAN, 30e-6, duration_s=15.0, noise_px=noise_px, seed=5)
    err = sim.observations.uv - sim.uv_true
    assert len(err) > 20000
    std = err.std(axis=0)
    assert np.all(np.abs(std / noise_px - 1.0) < 0.03), std
    assert np.all(np.abs(err.mean(axis=0)) < 0.02), err.mean(axis=0)
    assert abs(np.corrcoef(err[:, 0], err[:, 1])[0, 1]) < 0.05


def test_observations_inside_image_and_well_formed():
    # Wild motion so that points do leave the image and the dropping logic is exercised.
    traj = HandheldTrajectory(duration_s=10.0, seed=2, amplitude=3.0, target_center_m=(0.16, 0.10, 0.0),
                              distance_m=0.5)
    border_px = 5.0
    sim = simulate_observations(RADTAN, 40e-6, duration_s=10.0, noise_px=1.0, seed=2, trajectory=traj,
                                border_px=border_px, t0_s=2.0)
    o = sim.observations
    assert isinstance(o, Observations)
    assert o.image_size == (640, 480)
    assert o.num_observations < 300 * 54  # something was dropped
    for uv in (o.uv, sim.uv_true):
        assert np.all(uv >= border_px)
        assert np.all(uv[:, 0] <= 640 - 1 - border_px) and np.all(uv[:, 1] <= 480 - 1 - border_px)
    assert np.all(np.bincount(o.frame_index, minlength=o.num_frames) >= 4)
    np.testing.assert_allclose(o.frame_times_s, 2.0 + sim.video_frame_index / 30.0, atol=1e-12)
    # Every kept frame's points really are all the in-view points of that frame: none lost.
    assert len(sim.uv_true) == len(sim.exposure_times_s) == o.num_observations


def test_dropped_points_are_really_outside():
    traj = HandheldTrajectory(duration_s=6.0, seed=4, amplitude=3.0, target_center_m=(0.16, 0.10, 0.0),
                              distance_m=0.5)
    d = 40e-6
    sim = simulate_observations(RADTAN, d, duration_s=6.0, noise_px=0.0, seed=4, trajectory=traj,
                                min_points_per_frame=1)
    o = sim.observations
    pts = checkerboard_points()
    frame, pid = np.divmod(np.arange(180 * len(pts)), len(pts))
    kept = np.zeros(len(frame), dtype=bool)
    kept[sim.video_frame_index[o.frame_index] * len(pts) + o.point_id] = True
    assert 0 < kept.sum() < len(kept)
    # Independent RS solve for the dropped points: plain fixed-point iteration (a contraction with
    # factor d * dv/dt << 1) instead of the module's Newton.
    t_i, pw = frame[~kept] / 30.0, pts[pid[~kept]]
    uv = oracle_project_at(RADTAN, traj, pw, t_i)
    for _ in range(10):
        uv = oracle_project_at(RADTAN, traj, pw, t_i + uv[:, 1] * d)
    inside = (uv[:, 0] >= 1e-6) & (uv[:, 0] <= 639 - 1e-6) & (uv[:, 1] >= 1e-6) & (uv[:, 1] <= 479 - 1e-6)
    assert not np.any(inside), uv[inside][:5]


def test_same_seed_same_output_different_seed_different():
    a = simulate_default(duration_s=3.0, seed=7)
    b = simulate_default(duration_s=3.0, seed=7)
    c = simulate_default(duration_s=3.0, seed=8)
    np.testing.assert_array_equal(a.observations.uv, b.observations.uv)
    np.testing.assert_array_equal(a.uv_true, b.uv_true)
    np.testing.assert_array_equal(a.observations.point_id, b.observations.point_id)
    n = min(len(a.uv_true), len(c.uv_true))
    assert np.median(np.abs(a.uv_true[:n] - c.uv_true[:n])) > 1.0


def test_static_camera_gives_identical_frames():
    traj = HandheldTrajectory(duration_s=4.0, seed=1, amplitude=0.0)
    sim = simulate_observations(RADTAN, 50e-6, duration_s=4.0, noise_px=0.0, seed=1, trajectory=traj)
    o = sim.observations
    assert o.num_frames == 120
    uv = sim.uv_true.reshape(o.num_frames, -1, 2)
    assert uv.shape[1] == 54
    assert np.max(np.abs(uv - uv[0])) < 1e-12


def test_static_camera_looks_at_target_upright():
    center = (0.16, 0.10, 0.0)
    traj = HandheldTrajectory(seed=0, amplitude=0.0, target_center_m=center, distance_m=0.6)
    uv = oracle_project_at(RADTAN, traj, np.array([center, [0.30, 0.10, 0.0], [0.16, 0.18, 0.0]]),
                           np.zeros(3))
    np.testing.assert_allclose(uv[0], RADTAN.params[2:4], atol=1e-9)  # centre on the optical axis
    # Roughly upright and unmirrored: target x goes right, target y goes down in the image.
    assert uv[1, 0] - uv[0, 0] > 50 and abs(uv[1, 1] - uv[0, 1]) < 0.5 * (uv[1, 0] - uv[0, 0])
    assert uv[2, 1] - uv[0, 1] > 30 and abs(uv[2, 0] - uv[0, 0]) < 0.5 * (uv[2, 1] - uv[0, 1])
    R, p = traj.pose_cw(np.array([0.0]))
    assert np.linalg.norm(R[0].T @ -p[0] - center) == pytest.approx(0.6, abs=1e-12)


def test_default_motion_is_hand_like_and_keeps_target_in_view():
    sim = simulate_default(duration_s=15.0, seed=0)
    o = sim.observations
    assert o.num_frames == 450
    assert o.num_observations > 0.9 * 450 * 54
    speed, _ = image_speed_px_s(sim)
    assert 100 < np.median(speed) < 1000
    w = np.linalg.norm(sim.trajectory.velocities(np.arange(0, 15, 0.01))[1], axis=1)
    assert np.degrees(np.median(w)) > 10


def test_calm_then_wild_profile_concentrates_motion_in_second_half():
    duration_s = 12.0
    traj = HandheldTrajectory(duration_s=duration_s, seed=6, amplitude_profile=calm_then_wild(duration_s),
                              target_center_m=(0.16, 0.10, 0.0), distance_m=0.5)
    sim = simulate_observations(RADTAN, 30e-6, duration_s=duration_s, seed=6, trajectory=traj)
    speed, t = image_speed_px_s(sim)
    calm = np.median(speed[t < 0.4 * duration_s])
    wild = np.median(speed[t > 0.6 * duration_s])
    assert wild > 3.0 * calm, (calm, wild)
    assert calm > 0  # calm, not frozen


def test_sim_camera_matches_namespace_camera():
    cam = SimCamera("pinhole-radtan", [500.0, 500.0, 319.5, 239.5, -0.1, 0.05, 0.0, 0.0, 0.0], 640, 480)
    ns = SimpleNamespace(model=cam.model, params=cam.params.copy(), width=640, height=480)
    a = simulate_observations(cam, 30e-6, duration_s=2.0, seed=1)
    b = simulate_observations(ns, 30e-6, duration_s=2.0, seed=1)
    np.testing.assert_array_equal(a.observations.uv, b.observations.uv)
    d = simulate_default(duration_s=2.0, seed=1)
    np.testing.assert_array_equal(a.observations.uv, d.observations.uv)
