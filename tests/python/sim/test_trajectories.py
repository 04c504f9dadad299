"""rscalib.sim.trajectories: one interface for every simulated trajectory (world-to-camera and
camera-to-world poses, velocities, descriptions), and the properties of each motion."""
import numpy as np
import pytest

from rscalib.errors import InputError
from rscalib.io.targets import Target
from rscalib.sim.target_observations import default_camera
from rscalib.sim.trajectories import (
    CameraMotion,
    HandheldRoomMotion,
    HandheldTrajectory,
    RoomWalkTrajectory,
    ShiftedTrajectory,
    SinusoidBank,
    TargetFlippedTrajectory,
    Trajectory,
    calm_then_wild,
    standoff_distance_m,
    target_trajectory,
    trajectory_from_description,
)

FPS = 30.0
MOTIONS = {
    "handheld": lambda: HandheldTrajectory(duration_s=5.0, seed=2),
    "flipped": lambda: TargetFlippedTrajectory(HandheldTrajectory(duration_s=5.0, seed=3)),
    "room_walk": lambda: RoomWalkTrajectory(seed=1),
    "handheld_room": lambda: HandheldRoomMotion(seed=4),
}


@pytest.fixture(params=sorted(MOTIONS))
def motion(request) -> CameraMotion:
    return MOTIONS[request.param]()


# ---------------------------------------------------------------------------------------------------
# The interface


def test_every_motion_is_a_trajectory_with_both_frame_conventions(motion):
    assert isinstance(motion, Trajectory) and isinstance(ShiftedTrajectory(motion, 0.1), Trajectory)
    t = np.linspace(0.0, 5.0, 31)
    R_cw, p_cw = motion.pose_cw(t)
    R_wc, centre = motion.pose_wc(t)
    assert R_cw.shape == R_wc.shape == (31, 3, 3) and p_cw.shape == centre.shape == (31, 3)
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", R_cw, R_cw), np.broadcast_to(np.eye(3), R_cw.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R_cw), 1.0, atol=1e-12)
    # docs/conventions.md: x_c = R_cw x_w + p_cw; the self-calibration state: x_w = R_wc x_c + r.
    np.testing.assert_array_equal(R_wc, np.transpose(R_cw, (0, 2, 1)))
    np.testing.assert_allclose(centre, -np.einsum("nji,nj->ni", R_cw, p_cw), atol=1e-12)
    np.testing.assert_array_equal(motion.camera_center_w(t), centre)
    # Scalars and arrays alike.
    R1, p1 = motion.pose_cw(t[7])
    np.testing.assert_array_equal(R1[0], R_cw[7])
    np.testing.assert_array_equal(p1[0], p_cw[7])


def test_velocities_match_the_poses(motion):
    t = np.linspace(0.3, 4.7, 25)
    v, w = motion.velocities(t)
    h = 1e-6
    np.testing.assert_allclose(v, (motion.camera_center_w(t + h) - motion.camera_center_w(t - h)) / (2 * h),
                               atol=1e-6)
    # Camera-frame angular velocity: R_cw(t + h) ~ exp(-[w] h) R_cw(t).
    R, _ = motion.pose_cw(t)
    Rh, _ = motion.pose_cw(t + h)
    rel = np.einsum("nij,nkj->nik", Rh, R)
    w_fd = -np.stack([rel[:, 2, 1], rel[:, 0, 2], rel[:, 1, 0]], axis=1) / h
    np.testing.assert_allclose(w, w_fd, atol=1e-4)
    dR, dp = motion.pose_cw_derivative(t)
    R1, p1 = motion.pose_cw(t + 1e-3)
    R0, p0 = motion.pose_cw(t - 1e-3)
    np.testing.assert_allclose(dp, (p1 - p0) / 2e-3, atol=1e-4)
    np.testing.assert_allclose(dR, (R1 - R0) / 2e-3, atol=1e-4)


def test_shifted_trajectory_is_the_base_at_later_times(motion):
    t = np.linspace(0.0, 2.0, 5)
    shifted = ShiftedTrajectory(motion, 0.004)
    for a, b in zip(shifted.pose_cw(t), motion.pose_cw(t + 0.004)):
        np.testing.assert_array_equal(a, b)


def test_flipped_target_frame():
    base = HandheldTrajectory(duration_s=5.0, seed=3)
    flipped = TargetFlippedTrajectory(base)
    t = np.linspace(0.0, 5.0, 11)
    R, p = base.pose_cw(t)
    Rf, pf = flipped.pose_cw(t)
    np.testing.assert_array_equal(Rf, R @ np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_allclose(pf, p, atol=1e-15)
    np.testing.assert_array_equal(flipped.camera_center_w(t), base.camera_center_w(t) * [1.0, -1.0, -1.0])


def test_sinusoid_bank_peaks_are_hard_bounds():
    bank = SinusoidBank.draw(np.random.default_rng(0), 3, 4, (0.2, 3.0), [1.0, 2.0, 0.5])
    values = bank(np.arange(0.0, 100.0, 0.01))
    assert np.all(np.abs(values) <= [1.0, 2.0, 0.5])
    assert np.all(np.abs(values).max(axis=0) > 0.5 * np.array([1.0, 2.0, 0.5]))
    np.testing.assert_allclose(np.abs(bank.amplitudes).sum(axis=1), [1.0, 2.0, 0.5])


# ---------------------------------------------------------------------------------------------------
# Descriptions (truth.json) and the target videos' default trajectory


def test_description_rebuilds_the_trajectory():
    t = np.linspace(0.0, 3.0, 13)
    for trajectory in (HandheldTrajectory(duration_s=3.0, seed=5, amplitude=1.3, distance_m=0.7),
                       TargetFlippedTrajectory(HandheldTrajectory(duration_s=3.0, seed=6)),
                       HandheldTrajectory(duration_s=3.0, seed=7, freq_range_hz=(0.5, 8.0), components=5,
                                          rotation_amplitude_deg=(5.0, 5.0, 5.0))):
        rebuilt = trajectory_from_description(trajectory.describe())
        assert type(rebuilt) is type(trajectory) and rebuilt.describe() == trajectory.describe()
        for a, b in zip(rebuilt.pose_cw(t), trajectory.pose_cw(t)):
            np.testing.assert_array_equal(a, b)
    # Default options are not written (truth.json of the default trajectories is unchanged).
    assert list(HandheldTrajectory().describe()) == ["type", "flip_target_x180", "seed", "duration_s", "amplitude",
                                                     "target_center_m", "distance_m"]
    with pytest.raises(InputError):
        trajectory_from_description(HandheldTrajectory(amplitude_profile=calm_then_wild(4.0)).describe())
    with pytest.raises(InputError):
        trajectory_from_description(RoomWalkTrajectory().describe())
    assert HandheldRoomMotion().describe() == {"type": "HandheldRoomMotion"}


@pytest.mark.parametrize("name", ["checkerboard", "aprilgrid"])
def test_target_trajectory_faces_the_printed_side(name):
    camera = default_camera((640, 480))
    target = Target.named(name)
    trajectory = target_trajectory(camera, target, 2.0, seed=1)
    assert isinstance(trajectory, TargetFlippedTrajectory if name == "aprilgrid" else HandheldTrajectory)
    R, p = trajectory.pose_cw(np.linspace(0.0, 2.0, 21))
    # The target is in front of the camera, at the stand-off distance, on its printed side (Kalibr's
    # AprilGrid: +z; the others: -z).
    x_c = np.einsum("nij,j->ni", R, target.center_m()) + p
    distance = standoff_distance_m(camera, target.points_m)
    assert np.all(np.abs(x_c[:, 2] / distance - 1.0) < 0.3)
    centres = trajectory.camera_center_w(np.linspace(0.0, 2.0, 21))
    assert np.all(np.sign(centres[:, 2]) == (1.0 if name == "aprilgrid" else -1.0))


# ---------------------------------------------------------------------------------------------------
# The motions


def test_handheld_trajectory_is_smooth():
    traj = HandheldTrajectory(duration_s=10.0, seed=9, amplitude_profile=calm_then_wild(10.0))
    second_diffs = []
    for dt in (2e-3, 1e-3):
        t = np.arange(0.0, 10.0, dt)
        R, p = traj.pose_cw(t)
        x = np.concatenate([R.reshape(len(t), 9), p], axis=1)
        assert np.all(np.isfinite(x))
        first = np.max(np.abs(np.diff(x, axis=0)))
        second = np.max(np.abs(np.diff(x, n=2, axis=0)))
        assert first < 5.0 * dt  # bounded velocity: no jumps
        assert second < 200.0 * dt ** 2  # bounded acceleration: no kinks
        second_diffs.append(second)
    # Smooth functions: second differences scale as dt^2 (a kink would make them scale as dt).
    assert second_diffs[0] / second_diffs[1] == pytest.approx(4.0, rel=0.05)


def test_room_walk_is_handheld_and_stays_inside():
    traj = RoomWalkTrajectory(seed=2)
    t = np.arange(0.0, 60.0, 1.0 / FPS)
    R, p = traj.pose_cw(t)
    centres = traj.camera_center_w(t)
    speed = np.linalg.norm(np.diff(centres, axis=0), axis=1) * FPS
    rel = np.einsum("nji,njk->nik", R[:-1], R[1:])
    rate_deg = np.rad2deg(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))) * FPS
    assert 0.15 < speed.mean() < 0.5, speed.mean()
    assert 10.0 < rate_deg.mean() < 35.0, rate_deg.mean()
    # At least ~1 m from every wall, floor and ceiling (the room of scene_video.room_scene).
    assert np.all(np.abs(centres[:, 0]) < 2.0 - 1.0) and np.all(np.abs(centres[:, 1]) < 1.5 - 0.9)
    assert np.all((centres[:, 2] > 1.0) & (centres[:, 2] < 2.5 - 0.9))
    # Upright: camera y (down) has a positive component along world -z.
    assert np.all(R[:, 1, 2] < -0.8)


def test_handheld_room_motion_stays_near_its_centre_looking_along_z():
    motion = HandheldRoomMotion(seed=3, center_m=(0.1, -0.2, 0.3))
    t = np.arange(0.0, 30.0, 1.0 / FPS)
    R_wc, centre = motion.pose_wc(t)
    assert np.all(np.abs(centre - [0.1, -0.2, 0.3]) <= [0.35, 0.15, 0.3])
    # Optical axis (camera z in the world) within yaw 30 + pitch 12 degrees of world +z.
    assert np.all(R_wc[:, 2, 2] > np.cos(np.deg2rad(42.0)))
    faster = HandheldRoomMotion(seed=3, center_m=(0.1, -0.2, 0.3), speed=2.0)
    np.testing.assert_allclose(faster.camera_center_w(t[:100] / 2.0), motion.camera_center_w(t[:100]), atol=1e-12)
