"""Intrinsic calibration (rscalib.intrinsics and `rscalib intrinsics`): OpenCV's real stills
against the reference in ../shared/data, synthetic videos through known radtan and equidistant
cameras, view selection, output files, and every exit-2 path of the command."""
import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video
from rscalib.detection.result import DetectionResult
from rscalib.intrinsics.calibrate import calibrate_detections, select_views
from rscalib.intrinsics.options import IntrinsicsOptions
from rscalib.io.cameras import load_camera
from rscalib.io.targets import target_from_dict
from rscalib.observations import Observations

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"
STILLS = sorted((DATA / "opencv_stereo_chessboard").glob("left*.jpg"))
needs_data = pytest.mark.skipif(not STILLS, reason="shared fixtures ../shared/data not present")
SCRIPT = Path(sys.executable).parent / "rscalib"

OPENCV_BOARD = {"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                "rowSpacingMeters": 0.025, "colSpacingMeters": 0.025}
# README of opencv_stereo_chessboard: cv2 default flags, cornerSubPix 11x11
REFERENCE = {"fx": 536.07, "fy": 536.01, "cx": 342.37, "cy": 235.53, "rms": 0.408}


def rscalib(*args, cache_dir=None):
    command = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "rscalib.cli"]
    env = dict(os.environ)
    if cache_dir is not None:
        env["RSCALIB_CACHE_DIR"] = str(cache_dir)
    return command + [str(a) for a in args], env


def run(*args, cache_dir=None, timeout=120):
    command, env = rscalib(*args, cache_dir=cache_dir)
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)


def write_target(path, spec):
    path.write_text("".join(f"{k}: {v}\n" for k, v in spec.items()))
    return path


# -- synthetic views through a known camera --------------------------------------------------------


class Camera:
    """Renders the printed target through a pinhole camera with lens distortion by inverse
    mapping: pixel -> undistorted ray -> target plane -> board image."""

    def __init__(self, model, k, dist, size=(640, 480)):
        self.model, self.k, self.dist, self.size = model, np.asarray(k, float), np.asarray(dist, float), size
        u, v = np.meshgrid(np.arange(size[0], dtype=np.float64), np.arange(size[1], dtype=np.float64))
        pixels = np.stack([u, v], -1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 50, 1e-12)
        if model == "pinhole-equidistant":
            rays = cv2.fisheye.undistortPoints(pixels, self.k, self.dist, criteria=criteria)
        else:
            rays = cv2.undistortPointsIter(pixels, self.k, self.dist, None, None, criteria)
        self.rays = np.concatenate([rays.reshape(-1, 2), np.ones((rays.shape[0], 1))], axis=1)

    def render(self, target, rvec, tvec, board):
        image, h_board = board
        r = cv2.Rodrigues(np.asarray(rvec, float))[0]
        # einsum, not @: BLAS threads fighting OpenCV's for 2 cores made this 10x slower
        rt_ray, rt_t = np.einsum("nj,jk->nk", self.rays, r), r.T @ tvec
        scale = rt_t[2] / rt_ray[:, 2]  # the ray meets z = 0
        world = scale[:, None] * rt_ray[:, :2] - rt_t[:2]
        uv = np.einsum("nj,kj->nk", world, h_board[:2, :2]) + h_board[:2, 2]
        bad = (scale <= 0) | ~np.isfinite(scale)
        uv[bad] = -10
        maps = uv.reshape(self.size[1], self.size[0], 2).astype(np.float32)
        return cv2.remap(image, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=110)

    def project(self, points, rvec, tvec):
        if self.model == "pinhole-equidistant":
            return cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, self.k, self.dist)[0].reshape(-1, 2)
        return cv2.projectPoints(points, rvec, tvec, self.k, self.dist)[0].reshape(-1, 2)


def view_poses(target, count, seed, distance=(0.45, 0.7)):
    """Poses that face the printed side, tilted up to ~35 degrees, the target spread over the image."""
    rng = np.random.default_rng(seed)
    centre = 0.5 * (target.points_m.min(0) + target.points_m.max(0))
    poses = []
    for _ in range(count):
        rvec = np.r_[rng.uniform(-0.6, 0.6, 2), rng.uniform(-0.4, 0.4)]
        r = cv2.Rodrigues(rvec)[0]
        offset = np.r_[rng.uniform(-0.12, 0.12), rng.uniform(-0.08, 0.08), rng.uniform(*distance)]
        poses.append((rvec, offset - r @ centre))
    return poses


def blurred_board(target, pixels_per_metre):
    image, h = target.draw(pixels_per_metre, margin_m=0.02)
    return cv2.GaussianBlur(image, (0, 0), 0.7), h  # mild anti-aliasing before resampling


# -- the OpenCV stills -----------------------------------------------------------------------------


@needs_data
def test_opencv_stills_against_the_reference():
    """The README's reference (fx 536.07, cx 342.37, cy 235.53) comes from cornerSubPix with a
    half-window of 11 px, which on these 22-37 px squares reaches into neighbouring squares: it is
    reproduced exactly with subpix_window_px=11 (same RMS 0.408 px). rscalib's default window (a
    quarter of the grid step) fits the same images to RMS 0.18 px; its principal point agrees with
    the reference within 2 px and its focal length is ~3 px (0.6 %) lower — as with windows 3-9 px,
    and as with findChessboardCornersSB's own corners (f 532.2 px), i.e. the bias is the
    reference's, not ours."""
    target = target_from_dict(OPENCV_BOARD)
    detections = detect_video(STILLS, target, DetectOptions(workers=1, cache=False), progress=False)
    assert detections.frames_total == 13 and detections.frames_detected == 13 and detections.dropped == {}
    assert detections.timestamps == "frame index"
    result = calibrate_detections(detections)
    p = dict(zip(result.param_names, result.params))
    std = dict(zip(result.param_names, result.param_std))
    assert abs(p["cx"] - REFERENCE["cx"]) < 2.0 and abs(p["cy"] - REFERENCE["cy"]) < 2.0
    assert abs(p["fx"] - REFERENCE["fx"]) < 4.0 and abs(p["fy"] - REFERENCE["fy"]) < 4.0
    assert abs(p["fx"] - 533.0) < 1.0 and abs(p["fy"] - 533.0) < 1.0
    assert result.rms_px < 0.25
    assert len(result.view_rms_px) == 13 and result.view_rms_px.max() < 0.4
    assert 0.1 < std["fx"] < 1.5 and 0.1 < std["cx"] < 1.5 and std["k1"] < 0.02
    assert result.view_labels[0] == "left01.jpg"

    sample = detect_video(STILLS, target, replace(DetectOptions(subpix_window_px=11), workers=1, cache=False), progress=False)
    reproduced = calibrate_detections(sample)
    q = dict(zip(reproduced.param_names, reproduced.params))
    for name in ("fx", "fy", "cx", "cy"):
        assert abs(q[name] - REFERENCE[name]) < 0.2, (name, q[name])
    assert abs(reproduced.rms_px - REFERENCE["rms"]) < 0.01


# -- synthetic cameras -----------------------------------------------------------------------------


RADTAN = Camera("pinhole-radtan", [[520.0, 0, 322.0], [0, 521.0, 238.5], [0, 0, 1]],
                [-0.25, 0.08, 0.001, -0.0005, 0.0])
CHECKERBOARD = target_from_dict({"target_type": "checkerboard", "targetCols": 8, "targetRows": 6,
                                 "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03})


@pytest.fixture(scope="module")
def radtan_video(tmp_path_factory):
    folder = tmp_path_factory.mktemp("radtan")
    board = blurred_board(CHECKERBOARD, 1500)
    path = folder / "calib.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, RADTAN.size, False)
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 100)
    for rvec, tvec in view_poses(CHECKERBOARD, 48, seed=3):
        writer.write(RADTAN.render(CHECKERBOARD, rvec, tvec, board))
    writer.release()
    return path, write_target(folder / "target.yaml", {**CHECKERBOARD.spec, "target_type": "checkerboard"})


def test_video_calibration_recovers_the_camera(radtan_video, tmp_path):
    path, target_file = radtan_video
    out = tmp_path / "out"
    result = run("intrinsics", path, "--target", target_file, "--out", out, "--max-views", 20, "--quiet",
                 cache_dir=tmp_path / "cache")
    assert result.returncode == 0, result.stderr
    assert "RMS" in result.stdout and "fx" in result.stdout
    summary = json.loads((out / "result.json").read_text())
    # rolling shutter (issue 12): only frames still enough are used, at least MIN_STILL_VIEWS (12)
    assert 12 <= summary["views_used"] <= 20 and summary["frames_total"] == 48
    assert summary["views_available"] == summary["frames_detected"] >= 40
    assert summary["timestamps"] == "container"
    p, std = summary["parameters"], summary["std"]
    assert abs(p["fx"] - 520.0) < 2.0 and abs(p["fy"] - 521.0) < 2.0
    assert abs(p["cx"] - 322.0) < 2.0 and abs(p["cy"] - 238.5) < 2.0
    assert abs(p["k1"] + 0.25) < 0.02
    assert summary["rms_px"] < 0.3
    assert all(0 < std[k] < 2.0 for k in ("fx", "fy", "cx", "cy"))
    assert len(summary["views"]) == summary["views_used"] and all("time_s" in v and v["rms_px"] < 1 for v in summary["views"])
    camera = load_camera(out / "camera.yaml").camera
    assert camera.model == "pinhole-radtan" and (camera.width, camera.height) == (640, 480)
    np.testing.assert_allclose(camera.params[:4], [p["fx"], p["fy"], p["cx"], p["cy"]])
    # a second run reuses the cached detections
    again = run("intrinsics", path, "--target", target_file, "--out", tmp_path / "again", "--max-views", 20,
                "--quiet", cache_dir=tmp_path / "cache")
    assert again.returncode == 0 and "(cached)" in again.stdout
    assert json.loads((tmp_path / "again" / "result.json").read_text())["detections_from_cache"] is True


def test_view_selection_prefers_sharp_spread_views(radtan_video):
    path, _ = radtan_video
    detections = detect_video(path, CHECKERBOARD, DetectOptions(workers=1, cache=False), progress=False)
    n = detections.observations.num_frames
    # pretend half of the frames are soft: they should not be picked
    soft = np.arange(n) % 2 == 1
    detections.blur_px = np.where(soft, 6.0, 1.5)
    chosen = select_views(detections, 10)
    assert len(chosen) == 10 and len(np.unique(chosen)) == 10
    assert not soft[chosen].any()
    centres = np.array([detections.observations.uv[s].mean(0) for s in detections.observations.frame_slices()])
    sharp = np.nonzero(~soft)[0]
    assert centres[chosen].std(0).sum() >= 0.9 * centres[sharp[:10]].std(0).sum()
    assert len(select_views(detections, 1000)) == n


def test_fisheye_model(tmp_path):
    camera = Camera("pinhole-equidistant", [[300.0, 0, 321.0], [0, 300.5, 241.0], [0, 0, 1]],
                    [0.05, -0.02, 0.01, -0.003])
    target = CHECKERBOARD
    board = blurred_board(target, 1500)
    for i, (rvec, tvec) in enumerate(view_poses(target, 16, seed=5, distance=(0.25, 0.4))):
        cv2.imwrite(str(tmp_path / f"{i:02d}.png"), camera.render(target, rvec, tvec, board))
    detections = detect_video(tmp_path, target, DetectOptions(workers=1, cache=False), progress=False)
    assert detections.frames_detected >= 12
    result = calibrate_detections(detections, IntrinsicsOptions(model="pinhole-equidistant"))
    p = dict(zip(result.param_names, result.params))
    std = dict(zip(result.param_names, result.param_std))
    assert result.param_names == ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"]
    assert abs(p["fx"] - 300.0) < 1.5 and abs(p["fy"] - 300.5) < 1.5
    assert abs(p["cx"] - 321.0) < 1.5 and abs(p["cy"] - 241.0) < 1.5
    assert abs(p["k1"] - 0.05) < 0.02
    assert result.rms_px < 0.3
    assert all(np.isfinite(v) and v > 0 for v in std.values())
    assert std["fx"] < 2.0
    assert result.camera.model == "pinhole-equidistant"


def test_too_few_views_is_bad_input():
    from rscalib import InputError
    target = CHECKERBOARD
    points = target.points_m
    obs = Observations(np.array([0.0, 1.0]), np.repeat([0, 1], len(points)), np.tile(np.arange(len(points)), 2),
                       np.random.default_rng(0).uniform(0, 400, (2 * len(points), 2)), points, (640, 480))
    detections = DetectionResult(obs, 5, 2, {"no_target": 3}, False, (640, 480), np.array([0, 4]),
                                 ["frame 0", "frame 4"], np.array([1.0, 1.0]), "container")
    with pytest.raises(InputError, match="only 2 view"):
        calibrate_detections(detections)
    empty = Observations(np.zeros(0), np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)), points, (640, 480))
    none = DetectionResult(empty, 5, 0, {"no_target": 5}, False, (640, 480), np.zeros(0, int), [], np.zeros(0),
                           "container")
    with pytest.raises(InputError, match="not found in any of 5 frames"):
        calibrate_detections(none)
    with pytest.raises(InputError, match="unknown model"):
        calibrate_detections(detections, IntrinsicsOptions(model="civera-radial"))


# -- the command line ------------------------------------------------------------------------------


@needs_data
def test_cli_on_the_opencv_stills(tmp_path):
    target = write_target(tmp_path / "board.yaml", OPENCV_BOARD)
    result = run("intrinsics", *STILLS, "--target", target, "--out", tmp_path / "out", cache_dir=tmp_path / "c")
    assert result.returncode == 0, result.stderr
    assert "13 frames, 13 with the target" in result.stdout
    summary = json.loads((tmp_path / "out" / "result.json").read_text())
    assert summary["model"] == "pinhole-radtan" and summary["views_used"] == 13
    assert set(summary["parameters"]) == {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"}
    assert summary["target"]["targetCols"] == 9 and summary["dropped"] == {}
    assert [v["label"] for v in summary["views"]][:2] == ["left01.jpg", "left02.jpg"]
    camera = load_camera(tmp_path / "out" / "camera.yaml").camera
    assert abs(camera.params[0] - summary["parameters"]["fx"]) < 1e-9
    # a quoted pattern works too (shells without globbing)
    quoted = run("intrinsics", str(STILLS[0].parent / "left*.jpg"), "--target", target, "--out", tmp_path / "q",
                 "--quiet", cache_dir=tmp_path / "c")
    assert quoted.returncode == 0, quoted.stderr


def _synthetic_stills(folder: Path, count: int = 4) -> list:
    """Views of OPENCV_BOARD (pinhole warps of its drawing) when the shared fixtures are absent."""
    folder.mkdir()
    target = target_from_dict(OPENCV_BOARD)
    k = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    centre = 0.5 * (target.points_m.min(0) + target.points_m.max(0))
    paths = []
    for i in range(count):
        r = cv2.Rodrigues(np.array([0.25 * np.cos(i), 0.25 * np.sin(i), 0.1 * i]))[0]
        t = np.array([0.0, 0.0, 0.45]) - r @ centre
        board, h_board = target.draw(pixels_per_metre=1500.0, margin_m=0.02)
        h_image = k @ np.column_stack([r[:, 0], r[:, 1], t])
        image = cv2.warpPerspective(board, h_image @ np.linalg.inv(h_board), (640, 480), borderValue=110)
        paths.append(str(folder / f"view{i}.png"))
        cv2.imwrite(paths[-1], image)
    return paths


def _bad_inputs(tmp):
    """(name, argv) of commands that must exit 2 with a one-line reason."""
    good = write_target(tmp / "good.yaml", OPENCV_BOARD)
    wrong_size = write_target(tmp / "wrong.yaml", {**OPENCV_BOARD, "targetCols": 8, "targetRows": 5})
    (tmp / "syntax.yaml").write_text("target_type: checkerboard\ntargetCols: [9\n")
    missing_field = write_target(tmp / "missing.yaml", {"target_type": "checkerboard", "targetCols": 9})
    (tmp / "notvideo.mp4").write_text("not a video\n" * 50)
    (tmp / "empty").mkdir()
    (tmp / "afile").write_text("x")
    blank = tmp / "blank"
    blank.mkdir()
    for i in range(4):
        cv2.imwrite(str(blank / f"{i}.png"), np.full((120, 160), 128, np.uint8))
    stills = [str(p) for p in STILLS[:4]] or _synthetic_stills(tmp / "stills")
    out = tmp / "out"
    return {
        "missing input": ["intrinsics", tmp / "nope.mp4", "--target", good, "--out", out],
        "unreadable video": ["intrinsics", tmp / "notvideo.mp4", "--target", good, "--out", out],
        "empty folder": ["intrinsics", tmp / "empty", "--target", good, "--out", out],
        "missing target file": ["intrinsics", *stills, "--target", tmp / "nope.yaml", "--out", out],
        "bad yaml": ["intrinsics", *stills, "--target", tmp / "syntax.yaml", "--out", out],
        "missing yaml field": ["intrinsics", *stills, "--target", missing_field, "--out", out],
        "wrong target size": ["intrinsics", *stills, "--target", wrong_size, "--out", out],
        "no detections": ["intrinsics", blank, "--target", good, "--out", out],
        "out is a file": ["intrinsics", *stills, "--target", good, "--out", tmp / "afile"],
        "max views too small": ["intrinsics", *stills, "--target", good, "--out", out, "--max-views", 1],
        "unknown model": ["intrinsics", *stills, "--target", good, "--out", out, "--model", "civera-radial"],
        "missing --target": ["intrinsics", *stills, "--out", out],
    }


@pytest.fixture(scope="module")
def bad_input_runs(tmp_path_factory):
    """Run every bad-input command at once (each is a separate process)."""
    tmp = tmp_path_factory.mktemp("bad")
    processes = {}
    for name, argv in _bad_inputs(tmp).items():
        command, env = rscalib(*argv, "--quiet", cache_dir=tmp / "cache")
        processes[name] = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    results = {}
    for name, process in processes.items():
        stdout, stderr = process.communicate(timeout=120)
        results[name] = (process.returncode, stdout, stderr)
    return results


EXPECTED_WORDS = {
    "missing input": "not found", "unreadable video": "cannot open as a video", "empty folder": "no images",
    "missing target file": "target file not found", "bad yaml": "not valid YAML",
    "missing yaml field": "targetRows", "wrong target size": "not found in any of 4 frames",
    "no detections": "not found in any of 4 frames", "out is a file": "not a folder",
    "max views too small": "--max-views", "unknown model": "civera-radial", "missing --target": "--target",
}


@pytest.mark.parametrize("name", list(EXPECTED_WORDS))
def test_cli_bad_input_exits_2_with_one_line(bad_input_runs, name):
    code, stdout, stderr = bad_input_runs[name]
    assert code == 2, (name, code, stderr)
    assert "Traceback" not in stderr + stdout
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, (name, stderr)
    assert EXPECTED_WORDS[name] in lines[0], (name, lines[0])
