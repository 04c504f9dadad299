"""The adjustment stage of self-calibration (docs/sog.md §24): its start (keyframes.py), its verdict
(judge.judge_adjustment), its self-check's widening and the --line-delay-from prior.

Oracles: OpenCV's triangulation, SciPy's quaternions, simulated truth, and the Verdict block an
`rscalib linedelay` run writes (rscalib.verdict.Verdict.to_dict)."""
from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rscalib import _core
from rscalib.errors import InputError
from rscalib.selfcalib.engine import _widened, line_delay_prior
from rscalib.selfcalib.judge import MAX_READOUT_FRAMES, MIN_BUNDLE_POINTS, judge_adjustment
from rscalib.selfcalib.keyframes import FilterPoses, adjustment_start, halves, subset, triangulate
from rscalib.selfcalib.tracks import KeyframeObservations
from rscalib.verdict import NOT_DETERMINED, TRUSTED, Z_99, Verdict

WIDTH, HEIGHT = 320, 240
CAMERA = _core.CameraModel("civera-radial", [200.0, 160.0, 120.0, 0.0, 0.0], WIDTH, HEIGHT, [0.01, 0.01])


def _poses(count: int, seed: int = 0) -> np.ndarray:
    """(count, 6) [p; phi] T_cw: a camera sliding along x and turning a little, looking down +z."""
    rng = np.random.default_rng(seed)
    phi = rng.normal(0, 0.05, (count, 3))
    centres = np.c_[np.linspace(-0.5, 0.5, count), rng.normal(0, 0.05, (count, 2))]
    p = -np.einsum("nij,nj->ni", Rotation.from_rotvec(phi).as_matrix(), centres)
    return np.c_[p, phi]


def _scene(count_points: int = 40, count_views: int = 6, seed: int = 0):
    rng = np.random.default_rng(seed)
    points = np.c_[rng.uniform(-1, 1, (count_points, 2)), rng.uniform(3, 6, count_points)]
    return points, _poses(count_views, seed)


def _in_camera(points_w, pose):
    return Rotation.from_rotvec(pose[3:]).as_matrix() @ points_w.T + pose[:3, None]


def test_triangulate_agrees_with_opencv():
    points, poses = _scene()
    rays, views, point = [], [], []
    for k, pose in enumerate(poses):
        x_c = _in_camera(points, pose).T
        rays.append(x_c / x_c[:, 2:])
        views += [k] * len(points)
        point += list(range(len(points)))
    rays = np.concatenate(rays)
    ours = triangulate(rays, np.array(views), np.array(point), poses)
    # OpenCV from the first and last views only (its DLT takes two): exact rays agree to round-off
    P0, P1 = (np.c_[Rotation.from_rotvec(p[3:]).as_matrix(), p[:3]] for p in (poses[0], poses[-1]))
    n = len(points)
    X = cv2.triangulatePoints(P0, P1, rays[:n, :2].T.copy(), rays[-n:, :2].T.copy())
    np.testing.assert_allclose(ours, (X[:3] / X[3]).T, atol=1e-6)
    np.testing.assert_allclose(ours, points, atol=1e-6)


def test_triangulate_marks_a_point_behind_a_camera():
    points, poses = _scene(count_points=3, count_views=2)
    rays = np.concatenate([(_in_camera(points, p).T / _in_camera(points, p).T[:, 2:]) for p in poses])
    rays[0, :2] *= -1                                  # point 0's first ray now points the other way:
    rays[0, 2] = 1.0                                   # no point in front of both cameras fits it
    out = triangulate(rays, np.repeat([0, 1], 3), np.tile([0, 1, 2], 2), poses)
    assert np.all(np.isnan(out[0])) and np.all(np.isfinite(out[1:]))
    np.testing.assert_allclose(out[1:], points[1:], atol=1e-6)


def test_filter_poses_from_the_banks_quaternions():
    rng = np.random.default_rng(1)
    R_wc = Rotation.random(5, random_state=2)
    r_w = rng.normal(size=(5, 3))
    q_xyzw = R_wc.as_quat()
    states = np.c_[r_w, q_xyzw[:, 3], q_xyzw[:, :3], rng.normal(size=(5, 6))]   # + velocities, ignored
    poses = FilterPoses.from_states(list(states))
    np.testing.assert_allclose(poses.R_cw, R_wc.inv().as_matrix(), atol=1e-12)
    # x_c = R_cw x_w + p_cw puts the camera centre r_w at the origin
    np.testing.assert_allclose(np.einsum("nij,nj->ni", poses.R_cw, r_w) + poses.p_cw, 0, atol=1e-12)


def _observations(points, poses, keyframes, seen_in=None) -> KeyframeObservations:
    uv, frame, track = [], [], []
    for k, pose in zip(keyframes, poses):
        x_c = _in_camera(points, pose).T
        ids = np.arange(len(points)) if seen_in is None else np.flatnonzero(seen_in[:, list(keyframes).index(k)])
        uv.append(np.asarray(CAMERA.project(x_c[ids])))
        frame += [k] * len(ids)
        track += list(ids + 100)
    n = len(frame)
    return KeyframeObservations(np.array(frame), 0.1 * np.array(frame, float), np.array(track), np.concatenate(uv),
                                np.zeros((n, 2)), np.array(keyframes), np.ones(n))


class _TruePoses:
    def __init__(self, keyframes, poses):
        self.index = {int(k): p for k, p in zip(keyframes, poses)}

    def states(self, frames):
        return np.array([self.index[int(f)] for f in frames])


def test_adjustment_start_recovers_the_scene_from_true_poses():
    points, poses = _scene(count_points=30, count_views=5, seed=3)
    keyframes = [0, 3, 6, 9, 12]
    obs = _observations(points, poses, keyframes)
    start = adjustment_start(obs, _TruePoses(keyframes, poses), CAMERA)
    np.testing.assert_allclose(start.points_w, points, atol=1e-4)
    np.testing.assert_allclose(start.keyframe_poses, poses)
    assert set(start.keyframe) == set(range(5)) and start.point.max() == 29


def test_halves_keep_their_own_keyframes_and_long_enough_tracks():
    points, poses = _scene(count_points=20, count_views=8, seed=4)
    keyframes = list(range(0, 16, 2))
    seen = np.ones((20, 8), bool)
    seen[:5, 1:] = False                    # tracks 100-104: one keyframe only
    seen[5:10, :4] = False                  # tracks 105-109: the second half only
    obs = _observations(points, poses, keyframes, seen)
    first, second = halves(obs, min_keyframes=3)
    assert set(first.frame) <= set(keyframes[:4]) and set(second.frame) <= set(keyframes[4:])
    assert list(first.keyframes) == keyframes[:4] and list(second.keyframes) == keyframes[4:]
    assert not set(range(100, 110)) & set(first.track_id)
    assert set(range(105, 110)) <= set(second.track_id) and not set(range(100, 105)) & set(second.track_id)
    for part in (first, second):
        _, counts = np.unique(part.track_id, return_counts=True)
        assert counts.min() >= 3


def test_subset_keeps_the_longest_tracks():
    points, poses = _scene(count_points=20, count_views=8, seed=5)
    seen = np.ones((20, 8), bool)
    seen[10:, 4:] = False                   # tracks 110-119 seen in 4 keyframes, 100-109 in 8
    obs = _observations(points, poses, list(range(8)), seen)
    few = subset(obs, tracks=10, min_keyframes=3)
    assert set(few.track_id) == set(range(100, 110))
    assert list(few.keyframes) == list(range(8))


# ---------------------------------------------------------------------------------- the verdict


PRIOR = np.array([[100.0, 400.0], [140.0, 180.0], [100.0, 140.0], [-0.1, 0.1], [-0.1, 0.1]])


def _adjustment(f=200.0, f_half=2.0, converged=True, covariance_ok=True, points=100, line_delay=None):
    camera = np.array([f, 160.0, 120.0, 0.0, 0.0])
    bounds = np.c_[camera - [f_half, 1, 1, 0.01, 0.01], camera + [f_half, 1, 1, 0.01, 0.01]]
    d = 0.0 if line_delay is None else line_delay[0]
    d_bounds = [d, d] if line_delay is None else list(line_delay[1])
    return SimpleNamespace(camera_params=camera, bounds_99_two_way=np.r_[bounds, [d_bounds]],
                           point_anchor=np.zeros(points, int), dropped_points=0, points_out_of_range=0,
                           converged=converged,
                           step_sigma=12.0, message="no convergence", covariance_ok=covariance_ok,
                           estimates_line_delay=line_delay is not None, line_delay_s=d,
                           keyframe_poses=np.zeros((40, 6)), sigma_px=0.4)


def test_judge_adjustment_determined_when_f_is_pinned():
    determined, reason, bounds = judge_adjustment(_adjustment(f_half=2.0), "", PRIOR, 0.02, HEIGHT, 1 / 30)
    assert determined and "100 tracks" in reason
    np.testing.assert_allclose(bounds[0], [198.0, 202.0])


def test_judge_adjustment_reports_the_datas_bounds_when_too_wide():
    determined, reason, bounds = judge_adjustment(_adjustment(f_half=10.0), "", PRIOR, 0.02, HEIGHT, 1 / 30)
    assert not determined and "+-5.0 %" in reason
    np.testing.assert_allclose(bounds[0], [190.0, 210.0])


@pytest.mark.parametrize("case, words", [
    (dict(converged=False), "did not converge"),
    (dict(f=450.0), "outside the focal lengths"),
    (dict(covariance_ok=False), "covariance"),
    (dict(points=MIN_BUNDLE_POINTS - 1), f"only {MIN_BUNDLE_POINTS - 1} feature tracks"),
    # a 99 % interval all above 1.25 frame intervals / 240 rows = 174 us/row: no shutter reads that slowly
    (dict(line_delay=(300e-6, (250e-6, 350e-6))), "frame intervals"),
])
def test_judge_adjustment_falls_back_to_the_prior(case, words):
    determined, reason, bounds = judge_adjustment(_adjustment(**case), "", PRIOR, 0.02, HEIGHT, 1 / 30)
    assert not determined and words in reason, reason
    np.testing.assert_array_equal(bounds, PRIOR)


def test_judge_adjustment_a_possible_readout_is_no_problem():
    limit = MAX_READOUT_FRAMES / 30 / HEIGHT
    adj = _adjustment(line_delay=(0.5 * limit, (0.4 * limit, 1.1 * limit)))
    assert judge_adjustment(adj, "", PRIOR, 0.02, HEIGHT, 1 / 30)[0]


def test_judge_adjustment_cuts_what_the_data_allow_to_the_prior():
    determined, reason, bounds = judge_adjustment(_adjustment(f_half=300.0), "", PRIOR, 0.02, HEIGHT, 1 / 30)
    assert not determined and "hardly moved" in reason
    np.testing.assert_allclose(bounds[0], [PRIOR[0, 0], PRIOR[0, 1]])     # [-100, 500] cut to [100, 400]
    np.testing.assert_allclose(bounds[1], [159.0, 161.0])                 # inside the box: the data's


def test_judge_adjustment_without_an_adjustment():
    determined, reason, bounds = judge_adjustment(None, "no track spans 3 keyframes", PRIOR, 0.02, HEIGHT)
    assert not determined and "no track spans" in reason
    np.testing.assert_array_equal(bounds, PRIOR)


@dataclasses.dataclass
class _Covariance:      # what _widened reads and replaces of an AdjustmentResult
    covariance_two_way: np.ndarray
    estimate: np.ndarray
    bounds_99_two_way: np.ndarray


def test_widened_scales_sigma_per_parameter():
    adj = _Covariance(np.diag([4.0, 1.0, 9.0]), np.array([10.0, 0.0, 1.0]), np.zeros((3, 2)))
    out = _widened(adj, np.array([1.0, 3.0, 1.5]))
    np.testing.assert_allclose(np.sqrt(np.diag(out.covariance_two_way)), [2.0, 3.0, 4.5])
    np.testing.assert_allclose(out.bounds_99_two_way[:, 1] - out.estimate, Z_99 * np.array([2.0, 3.0, 4.5]))
    np.testing.assert_allclose(out.estimate - out.bounds_99_two_way[:, 0], Z_99 * np.array([2.0, 3.0, 4.5]))


# ------------------------------------------------------------------------------ --line-delay-from


def _linedelay_result(tmp_path, verdict: Verdict, rows=HEIGHT):
    path = tmp_path / "result.json"
    path.write_text(json.dumps({"verdict": verdict.to_dict(), "rows": rows}))
    return path


def test_line_delay_prior_reads_a_linedelay_verdict(tmp_path):
    verdict = Verdict(TRUSTED, "ok", (), quantity="line_delay_s", value=30e-6, std=0.2e-6, unit="s/row")
    assert line_delay_prior(_linedelay_result(tmp_path, verdict), HEIGHT) == pytest.approx((30e-6, 0.2e-6))


def test_line_delay_prior_refuses_what_it_cannot_use(tmp_path):
    claimed = Verdict(TRUSTED, "ok", (), quantity="line_delay_s", value=30e-6, std=0.2e-6, unit="s/row")
    with pytest.raises(InputError, match="per row of 480 rows"):
        line_delay_prior(_linedelay_result(tmp_path, claimed, rows=480), HEIGHT)
    unclaimed = Verdict(NOT_DETERMINED, "no", ("too little motion",), quantity="line_delay_s")
    with pytest.raises(InputError, match="claims no line delay"):
        line_delay_prior(_linedelay_result(tmp_path, unclaimed), HEIGHT)
    other = Verdict(TRUSTED, "ok", (), quantity="f_px", value=500.0, std=1.0, unit="px")
    with pytest.raises(InputError, match="not the result.json"):
        line_delay_prior(_linedelay_result(tmp_path, other), HEIGHT)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="not a readable"):
        line_delay_prior(tmp_path / "bad.json", HEIGHT)
