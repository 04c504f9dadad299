"""rscalib.io.limits: memory available, frame sizes from headers only, refusal with the numbers, and
worker counts bounded by cores and memory (issue 14). Oracles: /proc/meminfo read independently,
PNG headers written by hand (a 100000 x 100000 image whose pixels do not exist: only a reader
that never decodes can report its size), and the arithmetic of the documented constants."""
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from rscalib import InputError
from rscalib.io import limits
from rscalib.io.video import open_source


def png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG with a valid signature and IHDR for ``width`` x ``height`` (8-bit RGB) and one empty
    IDAT: its size is readable, its pixels are not."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"")) +
                     chunk(b"IEND", b""))
    return path


def meminfo_kb(field: str) -> int:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


@pytest.mark.skipif(not Path("/proc/meminfo").exists(), reason="Linux only")
def test_available_memory_is_positive_and_at_most_the_total():
    available, origin = limits.available_memory_bytes()
    assert 0 < available <= meminfo_kb("MemTotal") * 1024
    assert origin


def test_image_size_from_the_header_without_decoding(tmp_path):
    huge = png_header_only(tmp_path / "huge.png", 100_000, 70_000)
    assert limits.image_size(huge) == (100_000, 70_000)
    assert huge.stat().st_size < 100              # the pixels really are not there
    real = tmp_path / "real.png"
    cv2.imwrite(str(real), np.zeros((37, 53, 3), np.uint8))
    assert limits.image_size(real) == (53, 37)
    (tmp_path / "junk.png").write_bytes(b"not an image")
    assert limits.image_size(tmp_path / "junk.png") is None


def test_source_frame_size_is_the_largest_image(tmp_path):
    for i, (w, h) in enumerate([(640, 480), (30_000, 30_000), (800, 600)]):
        png_header_only(tmp_path / f"frame{i}.png", w, h)
    size, path = limits.source_frame_size(open_source(tmp_path))
    assert size == (30_000, 30_000) and path.name == "frame1.png"


def test_frame_memory_is_the_documented_arithmetic():
    needed = limits.frame_memory_bytes(30_000, 30_000, 6)
    assert needed == 6 * (limits.WORKER_BASE_BYTES + limits.FRAME_BYTES_PER_PIXEL * 900_000_000)


def test_check_refuses_with_both_numbers(monkeypatch):
    monkeypatch.setattr(limits, "available_memory_bytes", lambda: (8 * 2 ** 30, "MemAvailable in /proc/meminfo"))
    with pytest.raises(InputError) as error:
        limits.check_frame_memory(30_000, 30_000, 1, what="a.png: frames")
    text = str(error.value)
    needed = limits.frame_memory_bytes(30_000, 30_000, 1)
    assert f"{needed:,} bytes" in text and f"{8 * 2 ** 30:,} bytes" in text and "a.png" in text
    assert "\n" not in text
    assert limits.check_frame_memory(640, 480, 2) == limits.frame_memory_bytes(640, 480, 2)


def test_workers_bounded_by_cores_and_memory(monkeypatch):
    monkeypatch.setattr(limits, "usable_cores", lambda: 2)
    monkeypatch.setattr(limits, "available_memory_bytes", lambda: (2 ** 40, "test"))
    assert limits.worker_count(64, 640, 480) == 2
    assert limits.worker_count(None, 640, 480) == 2
    assert limits.worker_count(1, 640, 480) == 1
    per_worker = limits.frame_memory_bytes(10_000, 10_000, 1)
    monkeypatch.setattr(limits, "available_memory_bytes", lambda: (int(1.5 * per_worker / limits.MEMORY_HEADROOM), "t"))
    assert limits.worker_count(64, 10_000, 10_000) == 1


def test_bounded_workers_refuses_a_huge_source_before_decoding(tmp_path, monkeypatch):
    monkeypatch.setattr(limits, "usable_cores", lambda: 2)
    for i in range(6):
        png_header_only(tmp_path / f"still{i}.png", 100_000, 100_000)
    with pytest.raises(InputError, match="still0.png: frames of 100000x100000 px needs about"):
        limits.bounded_workers(open_source(tmp_path), 64)
    small = tmp_path / "small"
    small.mkdir()
    cv2.imwrite(str(small / "a.png"), np.zeros((48, 64), np.uint8))
    assert limits.bounded_workers(open_source(small), 64) == 2
    assert limits.bounded_workers(open_source(small), None) is None


def test_a_line_delay_solve_too_big_for_memory_is_refused_with_the_numbers(monkeypatch):
    from rscalib.linedelay.common import SOLVE_BYTES_PER_OBSERVATION, check_solve_memory

    monkeypatch.setattr(limits, "available_memory_bytes", lambda: (8 * 2**30, "test"))
    check_solve_memory(100_000)   # a minute of 30 fps video of a 9x6 board: fits
    too_many = int(8 * 2**30 / SOLVE_BYTES_PER_OBSERVATION) + 1
    with pytest.raises(InputError, match=f"{too_many:,} observed corners.*--start/--end"):
        check_solve_memory(too_many)


_FREED_KEPT = """
import ctypes, sys
from rscalib.io.limits import keep_freed_memory
if sys.argv[1] == "keep":
    assert keep_freed_memory()
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
class Info(ctypes.Structure):   # glibc's struct mallinfo2: 10 size_t fields, fordblks the 8th (free heap bytes)
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]
libc.mallinfo2.restype = Info
block = libc.malloc(20 * 2 ** 20)   # a Ceres Jacobian of a minute of video's half
ctypes.memset(block, 1, 20 * 2 ** 20)
libc.free(block)
print(libc.mallinfo2().fordblks)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_keep_freed_memory_keeps_a_freed_solver_block_for_the_next_and_the_cli_asks_for_it(monkeypatch, tmp_path):
    """glibc's own accounting (mallinfo2): after keep_freed_memory a freed 20 MB block stays in the heap
    as free memory for the next solve; without it, it goes back to the system (an mmap of its own).
    `rscalib linedelay` asks for it in its process (before it checks its input)."""
    free_bytes = {}
    for mode in ("keep", "default"):
        run = subprocess.run([sys.executable, "-c", _FREED_KEPT, mode], capture_output=True, text=True, check=True)
        free_bytes[mode] = int(run.stdout.split()[-1])
    assert free_bytes["keep"] >= 20 * 2 ** 20 > 10 * free_bytes["default"]
    calls = []
    monkeypatch.setattr(limits, "keep_freed_memory", lambda: calls.append(1) or True)
    from rscalib.cli import main
    assert main(["linedelay", "missing.mp4", "--target", "t.yaml", "--camera", "c.yaml", "--out",
                 str(tmp_path / "out")]) == 2 and calls == [1]
