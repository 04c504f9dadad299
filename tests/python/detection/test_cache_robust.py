"""The detection cache under damage (issue #14): a truncated, random or tampered .npz, or a valid
file with wrong contents, is discarded with one line naming it and detection runs again; two
processes writing and reading the same entry at once never see a broken file."""
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

import rscalib
from rscalib.detection.cache import arrays_checksum, load_cache, save_cache
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video
from rscalib.detection.result import DetectionResult
from rscalib.io.targets import target_from_dict
from rscalib.observations import Observations

CHECKERBOARD = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                                 "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03})
# the folder holding the rscalib this test imported (the installed package in CI, python/ when developing):
# a child process must run the same code, and the source tree has no built _core
PYTHON_DIR = Path(rscalib.__file__).resolve().parents[1]


def synthetic_result(frames=5, seed=0) -> DetectionResult:
    """A detection result of `frames` frames with every corner seen (made-up numbers)."""
    rng = np.random.default_rng(seed)
    n = len(CHECKERBOARD.points_m)
    obs = Observations(frame_times_s=np.arange(frames) / 30.0, frame_index=np.repeat(np.arange(frames), n),
                       point_id=np.tile(np.arange(n), frames), uv=rng.uniform(0, 400, (frames * n, 2)),
                       target_points=CHECKERBOARD.points_m, image_size=(640, 480))
    return DetectionResult(obs, frames + 2, frames, {"no_target": 2}, False, (640, 480),
                           np.arange(frames, dtype=np.int64) * 2, [f"frame {2 * i}" for i in range(frames)],
                           rng.uniform(1, 2, frames), "container", ["a warning"])


def rewrite(path: Path, change, fix_checksum: bool) -> None:
    """Rewrite a cache file with its arrays changed by `change(arrays)`; the checksum recomputed
    (a consistent-looking file with wrong contents) or kept (tampering the checksum catches)."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(bytes(arrays.pop("meta")).decode())
    change(arrays)
    if fix_checksum:
        meta["checksum"] = arrays_checksum(arrays)
    np.savez(path, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)


def test_round_trip_keeps_every_field(tmp_path):
    path = tmp_path / "entry.npz"
    original = synthetic_result()
    save_cache(path, original)
    problems = []
    loaded = load_cache(path, CHECKERBOARD, problems)
    assert problems == [] and loaded.from_cache
    np.testing.assert_array_equal(loaded.observations.uv, original.observations.uv)
    np.testing.assert_array_equal(loaded.frame_numbers, original.frame_numbers)
    np.testing.assert_array_equal(loaded.blur_px, original.blur_px)
    assert (loaded.frames_total, loaded.dropped, loaded.frame_labels, loaded.warnings) == \
        (original.frames_total, original.dropped, original.frame_labels, original.warnings)


def _truncate(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _random_bytes(path):
    path.write_bytes(np.random.default_rng(3).integers(0, 256, 4000, dtype=np.uint8).tobytes())


def _no_meta(path):
    np.savez(path, uv=np.zeros((3, 2)))


def _bad_meta_json(path):
    rewrite(path, lambda a: None, fix_checksum=False)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["meta"] = np.frombuffer(b"{not json", np.uint8)
    np.savez(path, **arrays)


def _zip_entry_damaged(path):
    with zipfile.ZipFile(path) as z:
        members = {name: z.read(name) for name in z.namelist()}
    members["uv.npy"] = members["uv.npy"][:100]
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)


DAMAGE = {
    "truncated": (_truncate, "unreadable"),
    "random bytes": (_random_bytes, "unreadable"),
    "no meta": (_no_meta, "unreadable"),
    "meta not JSON": (_bad_meta_json, "unreadable"),
    "array entry cut short": (_zip_entry_damaged, "unreadable"),
    "swapped arrays (old checksum)": (
        lambda p: rewrite(p, lambda a: a.update(frame_times_s=a["blur_px"], blur_px=a["frame_times_s"]), False),
        "checksum"),
    "a corner moved (old checksum)": (
        lambda p: rewrite(p, lambda a: a["uv"].__setitem__((0, 0), 1.0), False), "checksum"),
    "no checksum (older rscalib)": (
        lambda p: _strip_checksum(p), "without a checksum"),
    "arrays of the wrong length": (
        lambda p: rewrite(p, lambda a: a.update(blur_px=a["blur_px"][:-1]), True), "differ in length"),
    "NaN corner": (
        lambda p: rewrite(p, lambda a: a["uv"].__setitem__((3, 1), np.nan), True), "NaN"),
    "point id beyond the target": (
        lambda p: rewrite(p, lambda a: a["point_id"].__setitem__(0, 999), True), "do not fit the target"),
    "times not increasing": (
        lambda p: rewrite(p, lambda a: a.update(frame_times_s=a["frame_times_s"][::-1].copy()), True),
        "increasing"),
    "frame index beyond the frames": (
        lambda p: rewrite(p, lambda a: a["frame_index"].__setitem__(-1, 77), True), "out of range"),
}


def _strip_checksum(path):
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(bytes(arrays.pop("meta")).decode())
    del meta["checksum"]
    np.savez(path, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)


@pytest.mark.parametrize("case", list(DAMAGE))
def test_a_damaged_entry_is_discarded_with_one_line_naming_it(tmp_path, case):
    damage, why = DAMAGE[case]
    path = tmp_path / "entry.npz"
    save_cache(path, synthetic_result())
    damage(path)
    problems = []
    assert load_cache(path, CHECKERBOARD, problems) is None
    assert len(problems) == 1 and str(path) in problems[0] and "\n" not in problems[0]
    assert why in problems[0], problems[0]
    assert not path.exists()   # removed: the next run does not trip over it again


def write_board_frames(folder: Path, count=6) -> Path:
    """`count` views of the checkerboard as PNGs with timestamps.txt (a small image folder)."""
    folder.mkdir()
    board, h_board = CHECKERBOARD.draw(pixels_per_metre=1500, margin_m=0.01)
    rng = np.random.default_rng(2)
    for i in range(count):
        angle = rng.uniform(-0.2, 0.2)
        shift = rng.uniform(-20, 20, 2)
        h = np.array([[np.cos(angle), -np.sin(angle), 130 + shift[0]], [np.sin(angle), np.cos(angle), 110 + shift[1]],
                      [0, 0, 1]]) @ np.diag([0.8, 0.8, 1.0])
        image = cv2.warpPerspective(board, h, (640, 480), borderValue=110)
        cv2.imwrite(str(folder / f"{i:03d}.png"), image)
    (folder / "timestamps.txt").write_text("".join(f"{i / 30:.6f}\n" for i in range(count)))
    return folder


def test_detect_video_runs_again_after_a_bad_entry_and_says_so(tmp_path):
    frames = write_board_frames(tmp_path / "frames")
    cache = tmp_path / "cache"
    first = detect_video(frames, CHECKERBOARD, DetectOptions(workers=1, cache_dir=cache), progress=False)
    assert first.frames_detected == 6 and not first.from_cache
    (entry,) = cache.glob("*.npz")
    rewrite(entry, lambda a: a["uv"].__setitem__((0, 0), a["uv"][0, 0] + 5.0), fix_checksum=False)
    again = detect_video(frames, CHECKERBOARD, DetectOptions(workers=1, cache_dir=cache), progress=False)
    assert not again.from_cache
    np.testing.assert_array_equal(again.observations.uv, first.observations.uv)   # not the tampered corner
    assert any(str(entry) in w and "discarded" in w for w in again.warnings), again.warnings
    third = detect_video(frames, CHECKERBOARD, DetectOptions(workers=1, cache_dir=cache), progress=False)
    assert third.from_cache and not any("discarded" in w for w in third.warnings)


HAMMER = """
import sys
import numpy as np
sys.path.insert(0, {tests!r})
from test_cache_robust import CHECKERBOARD, synthetic_result
from rscalib.detection.cache import load_cache, save_cache
path, seed = sys.argv[1], int(sys.argv[2])
import pathlib
path = pathlib.Path(path)
mine = synthetic_result(frames=40, seed=seed)
bad = 0
for i in range(60):
    save_cache(path, mine)
    problems = []
    loaded = load_cache(path, CHECKERBOARD, problems)
    bad += len(problems)
    if loaded is not None:   # one of the two writers' whole result, never a mix
        uv = loaded.observations.uv
        ok = any(np.array_equal(uv, synthetic_result(frames=40, seed=s).observations.uv) for s in (1, 2))
        bad += 0 if ok else 1
print(bad)
"""


def test_two_processes_share_one_entry_safely(tmp_path):
    """Two processes save and load the same cache entry 60 times each, at once: every load is a
    whole result of one of them, never a damaged or mixed file."""
    path = tmp_path / "shared.npz"
    script = HAMMER.format(tests=str(Path(__file__).parent))
    env = {"PYTHONPATH": str(PYTHON_DIR), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    runs = [subprocess.Popen([sys.executable, "-c", script, str(path), str(seed)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env) for seed in (1, 2)]
    outputs = [run.communicate(timeout=120) for run in runs]
    for run, (out, err) in zip(runs, outputs):
        assert run.returncode == 0, err
        assert out.strip() == "0", (out, err)
    assert load_cache(path, CHECKERBOARD) is not None
    assert not list(tmp_path.glob(".*tmp*"))   # no temporary files left behind
