"""Issue 12: the realistic renderer mode (rscalib.sim.realism) — what it writes, and that its
degradations are there (oracle: the exact rolling-shutter projections in truth.json and OpenCV's
corner detector)."""
import json

import cv2
import numpy as np
import pytest

from rscalib.io.video import open_source
from rscalib.sim.realism import RealismOptions, capture_times, render_realistic_video, sensor_image


@pytest.fixture(scope="module")
def phone(tmp_path_factory):
    out = tmp_path_factory.mktemp("phone")
    return render_realistic_video(out, line_delay_s=30e-6, fps=30, size=(640, 480), duration_s=1.0, seed=5,
                                  options=RealismOptions(drop_probability=0.1, stabilisation_px=0.5),
                                  supersample=1, workers=1)


def test_writes_frames_with_recorded_times_and_the_truth(phone):
    truth = json.loads(phone.truth_path.read_text())
    frames = list(open_source(phone.frames_dir).frames(gray=True))
    assert len(frames) == len(truth["capture_times_s"]) < 30          # some frames dropped
    recorded = np.array([f.time_s for f in frames])
    capture = np.array(truth["capture_times_s"])
    assert np.all(np.diff(recorded) > 0)
    assert 0 < np.std(recorded - capture) < 0.5e-3                    # timestamp noise
    assert truth["realism"]["codec_used"] and truth["stabilisation_warps"] is not None


def test_detected_corners_sit_near_the_true_projection(phone):
    truth = json.loads(phone.truth_path.read_text())
    frames = list(open_source(phone.frames_dir).frames(gray=True))
    errors = []
    # a blurred corner is found at the middle of its exposure
    for frame, uv in zip(frames, truth["projections"]["uv_rs_mid_exposure"]):
        ok, corners = cv2.findChessboardCorners(frame.image, (9, 6))
        if not ok:
            continue
        corners = cv2.cornerSubPix(frame.image, corners, (5, 5), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 1e-3)).reshape(-1, 2)
        uv = np.array([p if p is not None else [np.nan, np.nan] for p in uv])
        d = np.linalg.norm(corners[:, None] - uv[None], axis=2)
        errors.append(np.nanmin(d, axis=1))
    assert len(errors) >= 0.5 * len(frames)
    errors = np.concatenate(errors)
    # degraded (blur, compression, screen, noise) but unbiased to a fraction of a pixel
    assert 0.02 < np.median(errors) < 0.6


def test_noise_grows_with_brightness():
    rng = np.random.default_rng(0)
    opts = RealismOptions()
    dark = sensor_image(np.full((200, 200), 0.1), rng, opts, np.ones((200, 200))).astype(float)
    bright = sensor_image(np.full((200, 200), 0.8), rng, opts, np.ones((200, 200))).astype(float)
    assert bright.std() > 1.5 * dark.std()


def test_capture_times_jitter_and_drop():
    rng = np.random.default_rng(1)
    t, recorded = capture_times(300, 30.0, rng, RealismOptions(drop_probability=0.05))
    assert 250 < len(t) < 300 and np.all(np.diff(t) > 0)
    gaps = np.diff(t) * 30
    assert np.any(gaps > 1.5) and np.std(gaps[gaps < 1.5]) > 0.003
