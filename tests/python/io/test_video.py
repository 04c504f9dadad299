"""Frame sources (rscalib.io.video): container timestamps (constant and variable frame rate), the
fallback without timestamps, image folders with timestamps.txt, bad inputs, streaming memory."""
import struct
import tracemalloc

import cv2
import numpy as np
import pytest

from rscalib import InputError
from rscalib.io.video import _ContainerClock, open_source, read_timestamps


def gradient_frame(i, size=(160, 120)):
    """A frame whose mean grey level encodes i (so frames can be told apart after compression)."""
    w, h = size
    image = np.full((h, w, 3), (20 + 9 * i) % 256, np.uint8)
    cv2.putText(image, str(i), (10, h // 2), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
    return image


def write_avi(path, count, fps=25.0, size=(160, 120)):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert writer.isOpened()
    for i in range(count):
        writer.write(gradient_frame(i, size))
    writer.release()
    return path


# A minimal Matroska writer (MJPEG frames at chosen millisecond timecodes): cv2.VideoWriter
# can only write constant frame rates, and there is no ffmpeg binary to make a VFR file.
def _element(eid, payload):
    return eid.to_bytes((eid.bit_length() + 7) // 8, "big") + b"\x01" + len(payload).to_bytes(7, "big") + payload


def _uint(eid, value):
    return _element(eid, value.to_bytes(max(1, (value.bit_length() + 7) // 8), "big"))


def _text(eid, value):
    return _element(eid, value.encode())


def write_mkv(path, times_ms, size=(160, 120)):
    header = _element(0x1A45DFA3, _uint(0x4286, 1) + _uint(0x42F7, 1) + _uint(0x42F2, 4) + _uint(0x42F3, 8)
                      + _text(0x4282, "matroska") + _uint(0x4287, 4) + _uint(0x4285, 2))
    info = _element(0x1549A966, _uint(0x2AD7B1, 1_000_000) + _text(0x4D80, "test") + _text(0x5741, "test")
                    + _element(0x4489, struct.pack(">d", float(max(times_ms) + 40))))
    video = _element(0xE0, _uint(0xB0, size[0]) + _uint(0xBA, size[1]))
    tracks = _element(0x1654AE6B, _element(0xAE, _uint(0xD7, 1) + _uint(0x73C5, 1) + _uint(0x83, 1)
                                           + _text(0x86, "V_MJPEG") + video))
    jpegs = [cv2.imencode(".jpg", gradient_frame(i, size))[1].tobytes() for i in range(len(times_ms))]
    # SimpleBlock: track 1, timecode relative to the cluster (ms), keyframe flag, frame
    blocks = b"".join(_element(0xA3, b"\x81" + struct.pack(">hB", int(t), 0x80) + jpeg)
                      for t, jpeg in zip(times_ms, jpegs))
    cluster = _element(0x1F43B675, _uint(0xE7, 0) + blocks)
    path.write_bytes(header + _element(0x18538067, info + tracks + cluster))
    return path


def read_all(source):
    frames = list(source.frames(gray=True))
    return frames


def test_constant_rate_video_times_from_container(tmp_path):
    source = open_source(write_avi(tmp_path / "cfr.avi", 30, fps=25.0))
    assert source.kind == "video" and source.frame_count_estimate == 30 and source.fps_nominal == 25.0
    frames = read_all(source)
    assert [f.index for f in frames] == list(range(30))
    np.testing.assert_allclose([f.time_s for f in frames], np.arange(30) / 25.0, atol=1e-9)
    assert all(f.image.shape == (120, 160) and f.problem is None for f in frames)
    assert source.timestamps_source == "container" and source.warnings == []
    assert frames[3].label == "frame 3"


def test_variable_frame_rate_times_are_presentation_times(tmp_path):
    times_ms = [0, 33, 50, 100, 101, 180, 400, 433, 1000]
    source = open_source(write_mkv(tmp_path / "vfr.mkv", times_ms))
    frames = read_all(source)
    np.testing.assert_allclose([f.time_s for f in frames], np.array(times_ms) / 1e3, atol=1e-9)
    # the right picture at each time (not a resampled constant-rate stream)
    levels = [f.image[5:20, 100:150].mean() for f in frames]
    np.testing.assert_allclose(levels, [(20 + 9 * i) % 256 for i in range(len(times_ms))], atol=4)
    assert source.warnings == []


def test_non_increasing_container_times_skip_frames(tmp_path):
    source = open_source(write_mkv(tmp_path / "dup.mkv", [0, 40, 40, 80, 60, 120]))
    frames = read_all(source)
    assert [f.problem for f in frames] == [None, None, "bad_timestamp", None, "bad_timestamp", None]
    good = [f.time_s for f in frames if f.problem is None]
    np.testing.assert_allclose(good, [0, 0.04, 0.08, 0.12])
    assert any("not increasing" in w for w in source.warnings)


def test_container_without_times_falls_back_to_frame_rate(tmp_path):
    source = open_source(write_mkv(tmp_path / "notimes.mkv", [0] * 6))
    frames = read_all(source)
    fps = source.fps_nominal
    assert fps and fps > 0
    np.testing.assert_allclose([f.time_s for f in frames], np.arange(6) / fps)
    assert source.timestamps_source == "frame rate"
    assert len(source.warnings) == 1 and "no frame timestamps" in source.warnings[0]


def test_container_clock_rules():
    clock = _ContainerClock(30.0)
    assert [clock.time_of(i, ms) for i, ms in enumerate([0.0, 33.3, 66.7])] == pytest.approx([0, 0.0333, 0.0667])
    assert clock.time_of(3, 66.7) is None and clock.non_increasing == 1
    assert clock.time_of(4, float("nan")) is None
    no_times = _ContainerClock(None)  # unknown rate: one frame per second, with a warning
    assert [no_times.time_of(i, 0.0) for i in range(3)] == [0.0, 1.0, 2.0]
    assert no_times.fallback and "unknown frame rate" in no_times.warning


def test_image_folder_with_timestamps(tmp_path):
    for i in (10, 2, 1):  # file-name order compares numbers by value: 1, 2, 10
        cv2.imwrite(str(tmp_path / f"img{i}.png"), gradient_frame(i))
    (tmp_path / "notes.txt").write_text("not an image")
    (tmp_path / "timestamps.txt").write_text("# seconds\n0.5\n0.75\n\n1.25\n")
    source = open_source(tmp_path)
    assert source.kind == "images" and source.timestamps_source == "timestamps file"
    frames = read_all(source)
    assert [f.label for f in frames] == ["img1.png", "img2.png", "img10.png"]
    np.testing.assert_allclose([f.time_s for f in frames], [0.5, 0.75, 1.25])
    assert frames[0].image.ndim == 2


def test_image_folder_without_timestamps_uses_the_index(tmp_path):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i:03d}.jpg"), gradient_frame(i))
    source = open_source(tmp_path)
    assert source.timestamps_source == "frame index"
    assert [f.time_s for f in read_all(source)] == [0.0, 1.0, 2.0]


def test_image_list_glob_and_unreadable_image(tmp_path):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"a{i}.png"), gradient_frame(i))
    (tmp_path / "a3.png").write_bytes(b"broken")
    frames = read_all(open_source(str(tmp_path / "a*.png")))
    assert [f.problem for f in frames] == [None, None, None, "unreadable"]
    listed = read_all(open_source([tmp_path / "a2.png", tmp_path / "a0.png"]))
    assert [f.label for f in listed] == ["a2.png", "a0.png"]


@pytest.mark.parametrize("lines, message", [
    ("0.1\n0.2\n", "2 timestamps for 3 images"),
    ("0.1\n0.3\n0.2\n", "strictly increasing"),
    ("0.1\nsoon\n0.3\n", "not a time"),
])
def test_bad_timestamps_file(tmp_path, lines, message):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i}.png"), gradient_frame(i))
    (tmp_path / "timestamps.txt").write_text(lines)
    with pytest.raises(InputError, match=message):
        open_source(tmp_path)
    with pytest.raises(InputError, match=message):
        read_timestamps(tmp_path / "timestamps.txt", 3)


def test_bad_sources(tmp_path):
    with pytest.raises(InputError, match="not found"):
        open_source(tmp_path / "missing.mp4")
    with pytest.raises(InputError, match="no files match"):
        open_source(str(tmp_path / "*.png"))
    with pytest.raises(InputError, match="no images"):
        open_source(tmp_path)
    (tmp_path / "text.mp4").write_text("this is not a video\n" * 20)
    with pytest.raises(InputError, match="cannot open as a video"):
        open_source(tmp_path / "text.mp4")
    (tmp_path / "empty.avi").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        open_source(tmp_path / "empty.avi")
    cv2.imwrite(str(tmp_path / "x.png"), gradient_frame(0))
    video = write_avi(tmp_path / "v.avi", 3)
    with pytest.raises(InputError, match="a video must come alone"):
        open_source([tmp_path / "x.png", video])
    with pytest.raises(InputError, match="no input"):
        open_source([])


def test_content_hash_streams_the_bytes(tmp_path):
    a = write_avi(tmp_path / "a.avi", 5)
    b = tmp_path / "b.avi"
    b.write_bytes(a.read_bytes())
    assert open_source(a).content_hash() == open_source(b).content_hash()
    write_avi(tmp_path / "c.avi", 6)
    assert open_source(tmp_path / "c.avi").content_hash() != open_source(a).content_hash()


def test_streaming_memory_does_not_grow_with_length(tmp_path):
    """Reading a 640x480 video keeps about one frame alive, not the video."""
    size = (640, 480)
    path = tmp_path / "long.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, size)
    frame = gradient_frame(0, size)
    for _ in range(240):
        writer.write(frame)
    writer.release()
    tracemalloc.start()
    count = 0
    for _f in open_source(path).frames(gray=False):
        count += 1
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    frame_bytes = size[0] * size[1] * 3
    assert count == 240
    assert peak < 6 * frame_bytes, f"peak {peak / 1e6:.1f} MB for {count} frames of {frame_bytes / 1e6:.1f} MB"


def test_corrupt_video_gives_our_error_and_no_backend_noise(tmp_path):
    """OpenCV and FFmpeg print their own warnings to stderr; a bad file must give only ours."""
    import subprocess
    import sys
    full = tmp_path / "full.mp4"
    writer = cv2.VideoWriter(str(full), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (160, 120))
    for i in range(10):
        writer.write(gradient_frame(i))
    writer.release()
    truncated = tmp_path / "truncated.mp4"
    truncated.write_bytes(full.read_bytes()[: full.stat().st_size // 2])  # no moov atom
    code = ("import sys\nfrom rscalib.io.video import open_source\n"
            "try:\n    open_source(sys.argv[1])\nexcept Exception as e:\n    print(type(e).__name__, e)\n")
    result = subprocess.run([sys.executable, "-c", code, str(truncated)], capture_output=True, text=True, timeout=60)
    assert result.stdout.startswith("InputError") and "cannot open as a video" in result.stdout
    assert result.stderr == ""


def _header_only_png(width: int, height: int) -> bytes:
    """A PNG whose header declares width x height (no pixel data): enough for a decoder's size check."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


def test_image_over_opencvs_pixel_limit_is_an_input_error_naming_the_file(tmp_path):
    # cv2.imread raises (not returns None) above 2**30 pixels
    path = tmp_path / "huge.png"
    path.write_bytes(_header_only_png(40000, 40000))
    with pytest.raises(InputError, match="huge.png"):
        list(open_source([path]).frames())


def test_bits_per_pixel_from_the_container_matches_the_file_size(tmp_path):
    """The video's bitrate per pixel (the linedelay advice on re-encoded videos), against its file size
    over its duration; None for an image folder."""
    from rscalib.io.video import video_bits_per_pixel
    count, fps, size = 50, 25.0, (160, 120)
    path = write_avi(tmp_path / "v.avi", count, fps, size)
    from_size = path.stat().st_size * 8 / (count / fps) / (size[0] * size[1] * fps)
    assert video_bits_per_pixel(path) == pytest.approx(from_size, rel=0.1)
    cv2.imwrite(str(tmp_path / "a.png"), gradient_frame(0))
    assert video_bits_per_pixel(tmp_path / "a.png") is None
    assert video_bits_per_pixel(tmp_path) is None
