"""Grey frames from the decoder's luma plane (rscalib.io.video.luma_plan): used only where the first
frame shows the plane to be OpenCV's own BGR -> grey of the frame (the oracle here), limited range
stretched as OpenCV stretches it; anything else (packed colour, 16-bit) goes through BGR as before."""
import cv2
import numpy as np
import pytest

from rscalib.detection.detectors import Detector
from rscalib.detection.options import DetectOptions
from rscalib.detection.tracking import RunDetector
from rscalib.io import video as video_module
from rscalib.io.targets import target_from_dict
from rscalib.io.video import LumaPlan, VideoSegment, luma_plan, open_source, stretch_limited_range

SIZE = (320, 240)
FRAMES = 24


def pattern(k: int) -> np.ndarray:
    """Frame k: a checkerboard on a grey ramp (the full 0-255 range, so the range is told apart),
    moving a pixel a frame, with coloured squares in one corner."""
    y, x = np.mgrid[0:SIZE[1], 0:SIZE[0]]
    ramp = (x * 255 // (SIZE[0] - 1)).astype(np.uint8)
    board = (((x + k) // 20 + y // 20) % 2 * 255).astype(np.uint8)
    grey = np.where((y > 40) & (y < 200) & (x > 60) & (x < 260), board, ramp)
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    bgr[:30, :30] = (200, 40, 40)
    bgr[:30, 30:60] = (30, 160, 60)
    return bgr


def write(path, fourcc: str, is_color: bool = True, depth=None):
    params = [cv2.VIDEOWRITER_PROP_IS_COLOR, int(is_color)] + ([] if depth is None else
                                                                [cv2.VIDEOWRITER_PROP_DEPTH, depth])
    writer = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*fourcc), 30.0, SIZE, params)
    if not writer.isOpened():
        pytest.skip(f"OpenCV cannot write {fourcc} here")
    for k in range(FRAMES):
        frame = pattern(k)
        if not is_color:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            if depth == cv2.CV_16U:
                frame = frame.astype(np.uint16) * 257
        writer.write(frame)
    writer.release()
    return path


def grey_frames(path, luma: bool):
    return [f.image for f in open_source(path).frames(gray=True, luma=luma)]


def test_the_stretch_is_the_limited_range_formula():
    values = np.arange(256, dtype=np.uint8).reshape(16, 16)
    expected = np.clip(np.round((values.astype(float) - 16.0) * 255.0 / 219.0), 0, 255)
    np.testing.assert_array_equal(stretch_limited_range(values), expected)
    np.testing.assert_array_equal(video_module.LIMITED_TO_FULL_RANGE, expected.ravel())


def test_mpeg4_grey_comes_from_the_stretched_luma_plane(tmp_path):
    path = write(tmp_path / "v.mp4", "mp4v")
    plan = luma_plan(path)
    assert plan is not None and plan.limited_range and plan.frame_size == SIZE
    through_bgr, from_luma = grey_frames(path, False), grey_frames(path, True)
    unstretched = [f.image for f in VideoSegment(path, 30.0, 0, None, luma=LumaPlan(
        plan.pixel_format, plan.frame_size, False)).frames()]
    assert len(through_bgr) == len(from_luma) == len(unstretched) == FRAMES
    for a, b, plane in zip(through_bgr, from_luma, unstretched):
        assert b.shape == a.shape and b.dtype == np.uint8
        difference = np.abs(a.astype(int) - b.astype(int))
        # swscale's BGR conversion rounds with a bias of about a level, and chroma rounds: nothing more
        assert difference.mean() < 1.5 and np.percentile(difference, 99) <= 3
        # the plane as is would be far off: the range check has something to tell apart
        assert np.abs(a.astype(int) - plane.astype(int)).mean() > 3


def test_a_grey_lossless_video_reads_identically(tmp_path):
    path = write(tmp_path / "v.avi", "FFV1", is_color=False)
    plan = luma_plan(path)
    assert plan is not None and not plan.limited_range
    for a, b in zip(grey_frames(path, False), grey_frames(path, True)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kind", ["packed colour", "16-bit grey"])
def test_planes_that_are_not_8_bit_luma_go_through_bgr(tmp_path, kind):
    path = write(tmp_path / "v.avi", "FFV1", is_color=kind == "packed colour",
                 depth=None if kind == "packed colour" else cv2.CV_16U)
    assert luma_plan(path) is None
    through_bgr, asked_for_luma = grey_frames(path, False), grey_frames(path, True)
    assert len(through_bgr) == FRAMES
    for a, b in zip(through_bgr, asked_for_luma):
        np.testing.assert_array_equal(a, b)


def test_a_capture_whose_decoder_differs_from_the_plan_goes_through_bgr(tmp_path):
    path = write(tmp_path / "v.mp4", "mp4v")
    plan = luma_plan(path)
    wrong = LumaPlan(plan.pixel_format + 1, plan.frame_size, plan.limited_range)
    segment = [f.image for f in VideoSegment(path, 30.0, 0, None, luma=wrong).frames()]
    for a, b in zip(grey_frames(path, False), segment):
        np.testing.assert_array_equal(a, b)


def test_segments_read_the_luma_frames_of_one_pass(tmp_path):
    path = write(tmp_path / "v.mp4", "mp4v")
    plan = luma_plan(path)
    one_pass = grey_frames(path, True)
    first, second = VideoSegment(path, 30.0, 0, 12, luma=plan), VideoSegment(path, 30.0, 12, None, luma=plan)
    segments = [f.image for f in first.frames()] + [f.image for f in second.frames()]
    assert len(segments) == FRAMES
    for a, b in zip(one_pass, segments):
        np.testing.assert_array_equal(a, b)
    assert first.after == second.first   # the seek check compares luma frames with luma frames


def test_the_per_frame_warning_is_silenced_and_the_log_level_restored(tmp_path, capfd):
    path = write(tmp_path / "v.mp4", "mp4v")
    level = cv2.utils.logging.getLogLevel()
    assert len(grey_frames(path, True)) == FRAMES
    assert "8UC1" not in capfd.readouterr().err
    assert cv2.utils.logging.getLogLevel() == level


def test_detections_from_luma_match_those_through_bgr(tmp_path):
    """The corners of the same frames, grey from the luma plane and through BGR, within 0.05 px."""
    board = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                              "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03})
    drawn, h_drawn = board.draw(pixels_per_metre=2000.0, margin_m=0.01)
    k_matrix = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    centre = 0.5 * (board.points_m.min(0) + board.points_m.max(0))
    path = tmp_path / "board.mp4"
    writer = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (640, 480), False)
    for k in range(16):
        r = cv2.Rodrigues(np.array([0.25 + 0.01 * k, -0.2, 0.02 * k]))[0]
        t = np.array([0.003 * k, 0.0, 0.55]) - r @ centre
        h = k_matrix @ np.column_stack([r[:, 0], r[:, 1], t])
        warped = cv2.warpPerspective(drawn, h @ np.linalg.inv(h_drawn), (640, 480), borderValue=110)
        writer.write(cv2.GaussianBlur(warped, (0, 0), 0.8))
    writer.release()
    assert luma_plan(path) is not None

    def corners(luma: bool):
        runs = RunDetector(Detector(board, DetectOptions()), 8)
        return [runs.detect(f.image, f.index) for f in open_source(path).frames(gray=True, luma=luma)]

    through_bgr, from_luma = corners(False), corners(True)
    assert [d.reason for d in through_bgr] == [d.reason for d in from_luma]
    accepted = [(a, b) for a, b in zip(through_bgr, from_luma) if a.reason is None]
    assert len(accepted) >= 12
    for a, b in accepted:
        np.testing.assert_array_equal(a.point_id, b.point_id)
        assert np.abs(a.uv - b.uv).max() < 0.05


@pytest.mark.parametrize("pix_fmt, expected", [("yuvj420p", "full"), ("yuv420p", "limited"),
                                                ("yuv420p10le", None)])
def test_h264_pixel_formats(tmp_path, pix_fmt, expected):
    """Phones' H.264: full range (yuvj420p) read as is, limited range stretched, 10-bit through BGR."""
    import subprocess

    ffmpeg = pytest.importorskip("imageio_ffmpeg", reason="H.264 pixel formats need an ffmpeg binary")
    source = write(tmp_path / "source.avi", "FFV1")
    path = tmp_path / f"{pix_fmt}.mp4"
    done = subprocess.run([ffmpeg.get_ffmpeg_exe(), "-loglevel", "error", "-y", "-i", str(source), "-c:v", "libx264",
                           "-pix_fmt", pix_fmt, str(path)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"this ffmpeg cannot encode {pix_fmt}")
    plan = luma_plan(path)
    assert (None if plan is None else ("limited" if plan.limited_range else "full")) == expected
    for a, b in zip(grey_frames(path, False), grey_frames(path, True)):
        difference = np.abs(a.astype(int) - b.astype(int))
        assert difference.mean() < 1.5 and np.percentile(difference, 99) <= 3
