"""Workers that decode their own segment of a video (detection.pipeline): the segments tile the
video in whole runs, a segment's seek is verified against the frame its predecessor decoded
next, and the detections are exactly those of one sequential pass (also when a seek lands
elsewhere: then the video is decoded in the main process)."""
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from rscalib.detection import pipeline
from rscalib.detection.detectors import Detector
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video, segment_plan
from rscalib.detection.tracking import RunDetector
from rscalib.io import video as video_module
from rscalib.io.targets import target_from_dict
from rscalib.io.video import VideoSegment, frame_digest, open_source

K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
BOARD = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                          "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03})
CENTRE = 0.5 * (BOARD.points_m.min(0) + BOARD.points_m.max(0))
OPTIONS = DetectOptions(full_detection_every=8)
FRAMES = 72  # 9 runs of 8: enough for segments on 2 workers (4 runs per worker)


def image(k: int, drawn: np.ndarray, h_drawn: np.ndarray) -> np.ndarray:
    """Frame k of a camera swaying in front of the board; the board leaves the image for a few frames."""
    t_s = k / 30.0
    r = cv2.Rodrigues(np.array([0.25 + 0.15 * np.sin(2.1 * t_s), -0.2 + 0.2 * np.sin(1.3 * t_s),
                                0.3 * np.sin(0.9 * t_s)]))[0]
    t = np.array([0.02 * np.sin(1.7 * t_s) + 0.25 * max(0.0, np.sin(2.5 * t_s)) ** 4, 0.015 * np.cos(1.1 * t_s),
                  0.55]) - r @ CENTRE
    h = K @ np.column_stack([r[:, 0], r[:, 1], t])
    warped = cv2.warpPerspective(drawn, h @ np.linalg.inv(h_drawn), (640, 480), flags=cv2.INTER_LINEAR, borderValue=110)
    noise = np.random.default_rng(k).normal(0, 2.0, warped.shape)
    return np.clip(cv2.GaussianBlur(warped, (0, 0), 0.8) + noise, 0, 255).astype(np.uint8)


def write_video(folder, codec: str):
    drawn, h_drawn = BOARD.draw(pixels_per_metre=2000.0, margin_m=0.01)
    path = folder / ("sway.avi" if codec == "FFV1" else "sway.mp4")
    writer = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*codec), 30.0, (640, 480), False)
    for k in range(FRAMES):
        writer.write(image(k, drawn, h_drawn))
    writer.release()
    return path


@pytest.fixture(scope="module", params=["FFV1", "mp4v"])
def video(request, tmp_path_factory):
    """The same 72 frames, lossless (FFV1, every frame a key frame) or MPEG-4 Part 2 (inter frames:
    a seek decodes from the key frame before)."""
    return write_video(tmp_path_factory.mktemp("seg"), request.param)


@pytest.fixture(scope="module")
def mpeg4(tmp_path_factory):
    return write_video(tmp_path_factory.mktemp("seg"), "mp4v")


class InProcessPool:
    """The part of ProcessPoolExecutor the pipeline uses, run here (so a test can patch it)."""

    def submit(self, function, *args):
        future = Future()
        future.set_result(function(*args))
        return future


class _NoBar:
    def update(self, done):
        pass


def one_pass(path):
    return pipeline._decode_here(open_source(path), None, RunDetector(Detector(BOARD, OPTIONS), 8), 8, 1, _NoBar())


def by_segments(path, monkeypatch):
    monkeypatch.setattr(pipeline, "_WORKER_DETECTOR", Detector(BOARD, OPTIONS))
    frames = open_source(path)
    plan = segment_plan(frames.frame_count_estimate, 2, 8)
    return pipeline._detect_segments(frames, plan, InProcessPool(), 8, 2, _NoBar())


def assert_same(a, b):
    assert a.total == b.total == FRAMES and a.size == b.size
    assert a.dropped == b.dropped
    assert a.numbers == b.numbers and a.labels == b.labels
    np.testing.assert_array_equal(a.times, b.times)
    for ids_a, ids_b, uv_a, uv_b in zip(a.ids, b.ids, a.uvs, b.uvs):
        np.testing.assert_array_equal(ids_a, ids_b)
        np.testing.assert_array_equal(uv_a, uv_b)


def test_segment_plan_tiles_the_video_in_whole_runs():
    plan = segment_plan(1800, 2, 20)
    assert plan[0][0] == 0 and plan[-1][1] is None  # the last segment reads to the end (counts may be off)
    assert all(stop == start for (_, stop), (start, _) in zip(plan, plan[1:]))
    assert all(start % 20 == 0 for start, _ in plan) and len(plan) >= 8
    assert segment_plan(100, 2, 20) is None and segment_plan(1800, 1, 20) is None and segment_plan(None, 2, 20) is None
    assert max(stop - start for start, stop in segment_plan(100000, 2, 20)[:-1]) == 300  # bounded tasks


def test_a_seek_is_verified_by_the_frame_before_it(video):
    sequential = [(f.time_s, frame_digest(f.image)) for f in open_source(video).frames(gray=True)]
    assert len(sequential) == FRAMES and len(set(d for _, d in sequential)) == FRAMES  # frames tell apart
    first = VideoSegment(video, 30.0, 0, 24)
    second = VideoSegment(video, 30.0, 24, 48)
    frames = list(first.frames()) + list(second.frames())
    assert [(f.time_s, frame_digest(f.image)) for f in frames] == sequential[:48]
    assert first.after == sequential[24] == second.first and second.after == sequential[48]
    assert first.last_time_s == sequential[23][0] and first.non_increasing == 0
    tail = VideoSegment(video, 30.0, 64, None)
    assert len(list(tail.frames())) == FRAMES - 64 and tail.after is None


def test_segments_detect_exactly_as_one_pass(video, monkeypatch):
    segments = by_segments(video, monkeypatch)
    assert segments is not None  # verified: used
    reference = one_pass(video)
    assert_same(segments, reference)
    assert 40 < len(reference.ids) < FRAMES and reference.dropped["no_target"] > 0  # the board leaves the image


def test_a_seek_that_lands_elsewhere_is_not_used(mpeg4, monkeypatch):
    video = mpeg4
    open_capture = video_module._open_capture

    class LandsOneLater:
        """A capture whose frame seek lands on the next frame (as some files do)."""

        def __init__(self, path, decoder_threads=None):
            self.capture = open_capture(path, decoder_threads=decoder_threads)

        def set(self, prop, value):
            return self.capture.set(prop, value + 1 if prop == cv2.CAP_PROP_POS_FRAMES else value)

        def __getattr__(self, name):
            return getattr(self.capture, name)

    monkeypatch.setattr(video_module, "_open_capture", LandsOneLater)
    assert by_segments(video, monkeypatch) is None
    # detect_video then decodes in this process and gives the one-pass result
    monkeypatch.setattr(pipeline, "_start_pool", lambda workers, target, options: _Pool())
    handed = HandedOn()
    result = detect_video(video, BOARD, replace(OPTIONS, workers=2, cache=False), progress=False, on_frames=handed)
    reference = detect_video(video, BOARD, replace(OPTIONS, workers=1, cache=False), progress=False)
    # the first segment's frames were handed on before the second failed its check: given again from 0
    assert handed.starts[0] == 0 and handed.starts.count(0) == 2
    handed.assert_is(reference)
    np.testing.assert_array_equal(result.observations.uv, reference.observations.uv)
    np.testing.assert_array_equal(result.frame_numbers, reference.frame_numbers)
    assert result.dropped == reference.dropped


class HandedOn:
    """detect_video's on_frames, kept as its contract says: frames from `start` replace those after it."""

    def __init__(self):
        self.times, self.ids, self.uvs, self.starts = [], [], [], []

    def __call__(self, start, times, ids, uvs):
        assert 0 <= start <= len(self.times) and len(times) == len(ids) == len(uvs) > 0
        self.starts.append(start)
        del self.times[start:], self.ids[start:], self.uvs[start:]
        self.times += times
        self.ids += ids
        self.uvs += uvs

    def assert_is(self, result):
        observations = result.observations
        np.testing.assert_array_equal(self.times, observations.frame_times_s)
        assert len(self.ids) == observations.num_frames
        for rows, ids, uv in zip(observations.frame_slices(), self.ids, self.uvs):
            np.testing.assert_array_equal(ids, observations.point_id[rows])
            np.testing.assert_array_equal(uv, observations.uv[rows])


def test_on_frames_hands_on_the_accepted_frames_as_they_arrive(video):
    """With workers decoding their own segments, each segment's accepted frames are handed on when it
    arrives (the line-delay job's PnP runs meanwhile); in one process, all at the end. Either way they
    are the result's frames, in order."""
    segments = HandedOn()
    result = detect_video(video, BOARD, replace(OPTIONS, workers=2, cache=False), progress=False, on_frames=segments)
    segments.assert_is(result)
    assert len(segments.starts) > 2 and segments.starts == sorted(set(segments.starts))
    here = HandedOn()
    detect_video(video, BOARD, replace(OPTIONS, workers=1, cache=False), progress=False, on_frames=here)
    here.assert_is(result)
    assert here.starts == [0]


class _Pool(InProcessPool):
    def shutdown(self, wait=True, cancel_futures=False):
        pass


def test_worker_processes_give_the_one_pass_result(video):
    """The real thing: 2 spawned workers decoding their own segments."""
    two = detect_video(video, BOARD, replace(OPTIONS, workers=2, cache=False), progress=False)
    one = detect_video(video, BOARD, replace(OPTIONS, workers=1, cache=False), progress=False)
    assert two.frames_total == one.frames_total == FRAMES and two.dropped == one.dropped
    np.testing.assert_array_equal(two.observations.uv, one.observations.uv)
    np.testing.assert_array_equal(two.observations.frame_times_s, one.observations.frame_times_s)
    np.testing.assert_array_equal(two.frame_numbers, one.frame_numbers)


def test_a_board_leaving_the_image_costs_no_full_detection_and_loses_no_frame(mpeg4):
    video = mpeg4
    """Frames where the board is seen in part, with a corner beyond the border, are no_target
    without a full detection; the accepted frames and their ids are full detection's."""
    frames = [f.image for f in open_source(video).frames(gray=True)]
    full = Detector(BOARD, DetectOptions(full_detection_every=1))
    runs = RunDetector(Detector(BOARD, OPTIONS), 8)
    trackers, differences = [], []
    for k, gray in enumerate(frames):
        tracked = runs.detect(gray, k)
        trackers += [runs._tracker] if k % 8 == 0 else []
        expected = full.detect(gray)
        assert tracked.accepted == expected.accepted, k
        if expected.accepted:
            np.testing.assert_array_equal(tracked.point_id, expected.point_id)
            differences.append(np.linalg.norm(tracked.uv - expected.uv, axis=1))
    assert sum(tracker.counts["left_image"] for tracker in trackers) >= 2
    # tracked corners: full detection's to within its noise (as in test_tracking.py)
    differences = np.concatenate(differences)
    assert np.median(differences) < 0.02 and differences.max() < 0.1


DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"
PHONE_VIDEO = DATA / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"


@pytest.mark.skipif(not PHONE_VIDEO.is_file(), reason="shared fixtures ../shared/data not present")
def test_a_phone_video_is_decoded_in_verified_segments():
    """A real phone video (H.264, variable frame timing): every segment's seek is verified and
    the segments give the frames and times of one sequential pass."""
    check_segments_against_one_pass(PHONE_VIDEO)


def check_segments_against_one_pass(path):
    source = open_source(path)
    sequential = [(f.index, f.time_s, frame_digest(f.image)) for f in source.frames(gray=True)]
    plan = segment_plan(source.frame_count_estimate, 2, 20)
    assert plan is not None and len(plan) >= 4
    previous, last_time_s, decoded = None, None, []
    for start, stop in plan:
        segment = VideoSegment(path, source.fps_nominal, start, stop)
        frames = [(f.index, f.time_s, frame_digest(f.image)) for f in segment.frames()]
        record = {"frames": frames, "first": segment.first, "after": segment.after, "size": None,
                  "no_container_times": segment.no_container_times}
        assert pipeline._continues(previous, record, last_time_s, None), start
        decoded += frames
        previous, last_time_s = record, segment.last_time_s
    assert decoded == sequential


@pytest.mark.parametrize("cores, threads", [(2, 1), (8, 4)])
def test_segment_workers_decode_with_the_cores_they_leave(mpeg4, monkeypatch, cores, threads):
    """Two workers on 2 cores decode with one FFmpeg thread each (its frame threads on busy cores cost
    CPU), on 8 cores with 4 each (a memory-bounded worker count leaves cores to decoding); the
    detections are those of one sequential pass either way."""
    sequential = one_pass(mpeg4)
    plan = segment_plan(open_source(mpeg4).frame_count_estimate, 2, 8)
    open_capture, opened = video_module._open_capture, []

    def recording(path, decoder_threads=None):
        opened.append(decoder_threads)
        return open_capture(path, decoder_threads=decoder_threads)

    monkeypatch.setattr(pipeline, "usable_cores", lambda: cores)
    monkeypatch.setattr(video_module, "_open_capture", recording)
    assert_same(by_segments(mpeg4, monkeypatch), sequential)
    # each segment's capture, and the one this process opens to read the video's header
    assert opened.count(threads) == len(plan) >= 2 and len(opened) == len(plan) + 1
