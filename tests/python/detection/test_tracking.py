"""Checkerboard tracking (rscalib.detection.tracking): tracked corners agree with full detection and
with the rendered truth; a wrong track (a jump, an occluder, the board at the border) falls back to
full detection; detect_video gives the same result with any number of workers; the decode thread."""
from dataclasses import replace

import cv2
import numpy as np
import pytest

from rscalib.detection.detectors import Detector
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import _decoded_ahead, detect_video
from rscalib.detection.tracking import CheckerboardTracker, corners_are_saddles, detect_run, run_length
from rscalib.errors import InputError
from rscalib.io.targets import target_from_dict

K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
BOARD = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                          "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03})
CENTRE = 0.5 * (BOARD.points_m.min(0) + BOARD.points_m.max(0))
DRAWN, H_DRAWN = BOARD.draw(pixels_per_metre=2000.0, margin_m=0.01)


def homography(t_s: float, shift_px=(0.0, 0.0)) -> np.ndarray:
    """Target -> image homography of a camera swaying smoothly (several px per frame at 30 fps)."""
    r = cv2.Rodrigues(np.array([0.25 + 0.15 * np.sin(2.1 * t_s), -0.2 + 0.2 * np.sin(1.3 * t_s),
                                0.3 * np.sin(0.9 * t_s)]))[0]
    t = np.array([0.02 * np.sin(1.7 * t_s) + shift_px[0] * 0.55 / 600, 0.015 * np.cos(1.1 * t_s) + shift_px[1] * 0.55 / 600,
                  0.55]) - r @ CENTRE
    return K @ np.column_stack([r[:, 0], r[:, 1], t])


def frame(h: np.ndarray, seed: int) -> np.ndarray:
    image = cv2.warpPerspective(DRAWN, h @ np.linalg.inv(H_DRAWN), (640, 480), flags=cv2.INTER_LINEAR,
                                borderValue=110)
    image = cv2.GaussianBlur(image, (0, 0), 0.8)
    noise = np.random.default_rng(seed).normal(0, 2.0, image.shape)
    return np.clip(image + noise, 0, 255).astype(np.uint8)


def corners(h: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(BOARD.points_m[:, :2].reshape(-1, 1, 2), h).reshape(-1, 2)


@pytest.fixture(scope="module")
def sequence():
    """40 frames at 30 fps: images and the exact corners."""
    hs = [homography(k / 30.0) for k in range(40)]
    return [frame(h, seed=k) for k, h in enumerate(hs)], [corners(h) for h in hs]


def test_tracked_corners_match_full_detection_and_truth(sequence):
    images, truth = sequence
    detector = Detector(BOARD)
    full = [detector.detect(image) for image in images]
    tracked = detect_run(detector, images[:20], range(20)) + detect_run(detector, images[20:], range(20, 40))
    assert all(f.accepted for f in full) and all(t.accepted for t in tracked)
    tracker = CheckerboardTracker(detector)
    for k in range(20):
        tracker.detect(images[k], k)
    assert tracker.counts == {"full": 1, "tracked": 19, "track_rejected": 0, "left_image": 0}
    diff = np.concatenate([t.uv - f.uv for t, f in zip(tracked, full)])
    for t, f in zip(tracked, full):
        np.testing.assert_array_equal(t.point_id, f.point_id)
    distance = np.linalg.norm(diff, axis=1)
    assert np.median(distance) < 0.02 and distance.max() < 0.1, (np.median(distance), distance.max())
    assert np.all(np.abs(diff.mean(0)) < 0.005)  # no systematic offset
    # both against the rendered corners (an independent oracle): equally close
    for found in (full, tracked):
        error = np.concatenate([np.linalg.norm(d.uv - c, axis=1) for d, c in zip(found, truth)])
        assert np.median(error) < 0.1, np.median(error)


def test_a_jump_falls_back_to_full_detection(sequence):
    images, truth = sequence
    detector = Detector(BOARD)
    tracker = CheckerboardTracker(detector)
    for k in range(5):
        assert tracker.detect(images[k], k).accepted
    # frame 5 shows the board 45 px away from where the motion so far puts it
    jumped = frame(homography(5 / 30.0, shift_px=(45.0, 0.0)), seed=99)
    found = tracker.detect(jumped, 5)
    assert tracker.counts["track_rejected"] == 1 and tracker.counts["full"] == 2
    expected = detector.detect(jumped)
    assert found.accepted and expected.accepted
    np.testing.assert_array_equal(found.uv, expected.uv)
    # on the jumped board, not where the track would have put it
    assert np.linalg.norm(found.uv - corners(homography(5 / 30.0, (45.0, 0.0))), axis=1).max() < 0.5


def test_an_occluded_board_is_not_tracked(sequence):
    images, _ = sequence
    detector = Detector(BOARD)
    tracker = CheckerboardTracker(detector)
    for k in range(5):
        tracker.detect(images[k], k)
    occluded = images[5].copy()
    u, v = np.round(tracker.predict(5, occluded.shape)[22]).astype(int)
    cv2.circle(occluded, (int(u), int(v)), 25, 128, -1)  # a grey blob over a few corners
    found = tracker.detect(occluded, 5)
    assert tracker.counts["track_rejected"] == 1
    assert not found.accepted and found.reason == detector.detect(occluded).reason


def test_board_at_the_border_is_detected_not_tracked(sequence):
    images, _ = sequence
    detector = Detector(BOARD)
    tracker = CheckerboardTracker(detector)
    tracker.detect(images[0], 0)
    assert tracker.predict(1, images[0].shape) is not None
    assert tracker.predict(1, (240, 320)) is None  # the same corners in a smaller image: ring outside
    assert tracker.predict(2, images[0].shape) is None  # not the next frame: no track


def test_saddle_check(sequence):
    images, truth = sequence
    grid = truth[0].reshape(6, 9, 2)
    assert corners_are_saddles(images[0], grid)
    step = grid[0, 1] - grid[0, 0]
    assert not corners_are_saddles(images[0], grid + 0.5 * step)  # centres of squares
    moved = grid.copy()
    moved[5, 8] += 0.5 * (grid[5, 8] - grid[4, 7])  # one corner onto the edge of its square
    assert not corners_are_saddles(images[0], moved)


def test_tracking_is_part_of_the_cache_key_and_only_for_checkerboards():
    assert DetectOptions().fingerprint() != DetectOptions(full_detection_every=1).fingerprint()
    assert run_length(BOARD, DetectOptions()) == 40 and run_length(BOARD, DetectOptions(full_detection_every=1)) == 1
    # a worker holds a run's frames when they are shipped to it: at most RUN_MAX_GREY_BYTES of grey pixels
    assert run_length(BOARD, DetectOptions(), (1920, 1080)) == 40
    assert run_length(BOARD, DetectOptions(), (3840, 2160)) == 16
    assert run_length(BOARD, DetectOptions(), (6000, 4500)) == 4
    assert run_length(BOARD, DetectOptions(), (40000, 30000)) == 1
    circles = target_from_dict({"target_type": "circlegrid", "targetCols": 7, "targetRows": 5,
                                "spacingMeters": 0.035, "asymmetricGrid": False})
    assert run_length(circles, DetectOptions()) == 1


def test_detect_video_same_result_with_any_workers(sequence, tmp_path):
    images, _ = sequence
    path = tmp_path / "sway.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30.0, (640, 480), False)
    for image in images:
        writer.write(image)
    writer.release()
    options = DetectOptions(full_detection_every=8)  # 5 runs over the 40 frames
    one = detect_video(path, BOARD, replace(options, workers=1, cache=False), progress=False)
    two = detect_video(path, BOARD, replace(options, workers=2, cache=False), progress=False)
    full = detect_video(path, BOARD, replace(DetectOptions(full_detection_every=1), workers=1, cache=False), progress=False)
    assert one.frames_detected == two.frames_detected == full.frames_detected == 40
    np.testing.assert_array_equal(one.observations.uv, two.observations.uv)
    np.testing.assert_array_equal(one.frame_numbers, two.frame_numbers)
    assert np.median(np.linalg.norm(one.observations.uv - full.observations.uv, axis=1)) < 0.02


def test_decode_thread_passes_errors_and_stops_early():
    def frames():
        yield 1
        yield 2
        raise InputError("video.avi: no frame could be decoded")

    with pytest.raises(InputError, match="no frame"):
        list(_decoded_ahead(frames(), 1))
    closed = []

    def endless():
        try:
            k = 0
            while True:
                yield k
                k += 1
        finally:
            closed.append(True)

    taken = []
    for item in _decoded_ahead(endless(), 2):
        taken.append(item)
        if item == 3:
            break
    assert taken == [0, 1, 2, 3] and closed == [True]


def test_a_refinement_put_back_on_its_start_is_not_a_track(sequence, monkeypatch):
    """cornerSubPix puts a corner back on its start when it would leave its window. A tracked grid
    with such a corner was not found there, whatever the later checks say: the frame goes to full
    detection (which finds the board), and a refinement that moved every corner is kept."""
    from rscalib.detection.tracking import refinement_was_reset

    images, _ = sequence
    detector = Detector(BOARD)
    tracker = CheckerboardTracker(detector)
    for k in range(3):
        assert tracker.detect(images[k], k).accepted
    refine = tracker._refiner.refine_checkerboard

    def one_corner_reset(gray, coarse, numbered=True):
        found = refine(gray, coarse, numbered=numbered)
        uv = found.uv.copy()
        nearest = int(np.argmin(np.linalg.norm(coarse - uv[7], axis=1)))
        uv[7] = coarse[nearest]          # what cornerSubPix returns for a corner it lost
        return replace(found, uv=uv)

    monkeypatch.setattr(tracker._refiner, "refine_checkerboard", one_corner_reset)
    found = tracker.detect(images[3], 3)
    assert found.accepted and tracker.counts["track_rejected"] == 1 and tracker.counts["full"] == 2
    assert not refinement_was_reset(found.uv, tracker.extrapolate(4))
    monkeypatch.setattr(tracker._refiner, "refine_checkerboard", refine)
    assert tracker.detect(images[4], 4).accepted and tracker.counts["tracked"] == 3
    start = np.array([[10.0, 20.0], [30.0, 40.0]])
    assert refinement_was_reset(np.array([[10.3, 20.1], [30.0, 40.0]]), start)
    assert not refinement_was_reset(start + 1e-9, start)
