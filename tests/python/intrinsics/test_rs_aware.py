"""Issue 12: intrinsics that know about the rolling shutter (still-enough frames) and pick a model the
data support (no k3 when the board never reaches the corners). Oracle: cv2.projectPoints."""
import cv2
import numpy as np
import pytest

from rscalib.detection.result import DetectionResult
from rscalib.intrinsics.calibrate import calibrate_detections, still_frames
from rscalib.observations import Observations

K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
DIST = np.array([-0.1, 0.05, 0.0, 0.0, 0.0])


def _board():
    xs, ys = np.meshgrid(np.arange(9) * 0.03, np.arange(6) * 0.03)
    return np.c_[xs.ravel() - 0.12, ys.ravel() - 0.075, np.zeros(54)]


def _detections(poses, times, numbers, noise=0.05, seed=0):
    rng = np.random.default_rng(seed)
    pts = _board()
    uv, fi, pid = [], [], []
    for f, (rvec, tvec) in enumerate(poses):
        img, _ = cv2.projectPoints(pts, np.asarray(rvec, float), np.asarray(tvec, float), K, DIST)
        uv.append(img.reshape(-1, 2) + rng.normal(0, noise, (54, 2)))
        fi.append(np.full(54, f))
        pid.append(np.arange(54))
    obs = Observations(frame_times_s=np.asarray(times, float), frame_index=np.concatenate(fi),
                       point_id=np.concatenate(pid), uv=np.concatenate(uv), target_points=pts, image_size=(640, 480))
    n = len(poses)
    return DetectionResult(obs, n, n, {}, False, (640, 480), np.asarray(numbers), [f"frame {i}" for i in numbers],
                           np.ones(n), "frame rate")


def _centred_views(n=30, seed=1):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-0.35, 0.35, 3), np.r_[rng.uniform(-0.03, 0.03, 2), rng.uniform(0.45, 0.6)])
            for _ in range(n)]


def test_k3_is_not_fitted_when_the_board_stays_in_the_centre():
    det = _detections(_centred_views(), np.arange(30) * 10.0, np.arange(30) * 10)
    result = calibrate_detections(det)
    assert result.params[8] == 0.0
    assert any("k3 not fitted" in w for w in result.warnings)
    assert result.params[0] == pytest.approx(500, rel=0.02)


def test_still_frames_are_chosen_from_a_moving_video():
    # 60 consecutive frames at 30 fps: the first 30 nearly still (15 px/s), the last 30 sweeping (300 px/s)
    poses, x = [], 0.0
    for i in range(60):
        x += 0.0005 if i < 30 else (0.01 if (i // 8) % 2 else -0.01)
        poses.append(((0.2 * np.sin(i / 10.0), 0.1, 0.0), (x - 0.02, 0.0, 0.5)))
    det = _detections(poses, np.arange(60) / 30.0, np.arange(60))
    warnings = []
    still = still_frames(det, warnings)
    assert still is not None
    assert still[:29].sum() >= 20 and still[31:].sum() == 0
    assert warnings and "still enough" in warnings[0]


def test_stills_are_not_judged():
    det = _detections(_centred_views(12), np.arange(12) * 10.0, np.arange(12) * 10)
    assert still_frames(det, []) is None
