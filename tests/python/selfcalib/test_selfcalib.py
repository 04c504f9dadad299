"""Self-calibration from images (issue 5): the front end's active search, the civera -> OpenCV
conversion, and `rscalib selfcalib` on a rendered textured-room sequence."""
import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

import rscalib
from rscalib.io.camera_formats.civera import civera_to_opencv
from rscalib.io.cameras import load_camera
from rscalib.selfcalib.front_end import FrontEndOptions, active_search

CLI = [sys.executable, "-m", "rscalib.cli"]
PAPER = [194.06, 160.22, 128.87, 0.06333, 0.0139]


def textured(seed=0, shape=(240, 320)):
    rng = np.random.default_rng(seed)
    image = cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), 2.0)
    return cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def test_active_search_finds_a_shifted_patch_inside_its_ellipse_only():
    image = textured(1)
    shift = np.array([3.0, -2.0])
    moved = np.roll(np.roll(image, int(shift[1]), axis=0), int(shift[0]), axis=1)
    uv0 = np.array([[150.0, 110.0], [60.0, 70.0]])
    patches = {i: image[int(v) - 5:int(v) + 6, int(u) - 5:int(u) + 6].copy() for i, (u, v) in enumerate(uv0)}
    ids = np.array([0, 1])
    wide = np.stack([np.eye(2) * 16.0, np.eye(2) * 16.0])       # 99 % ellipse radius ~12 px
    uv, found = active_search(moved, patches, ids, uv0, wide, FrontEndOptions(subpixel="affine"))
    assert found.all()
    assert np.abs(uv - (uv0 + shift)).max() < 0.25
    narrow = np.stack([np.eye(2) * 0.3, np.eye(2) * 0.3])       # radius ~1.7 px: the match is outside
    uv, found = active_search(moved, patches, ids, uv0, narrow, FrontEndOptions(subpixel="affine"))
    # whatever is accepted lies inside the ellipse, never at the true position 3.6 px away
    radius = np.sqrt(9.21 * 0.3)
    assert np.all(np.linalg.norm(uv[found] - uv0[found], axis=1) <= radius + 0.5)
    assert np.all(np.linalg.norm(uv[found] - (uv0[found] + shift), axis=1) > 1.0)


def test_affine_refinement_locates_a_scaled_rotated_patch_better_than_the_parabola():
    # The stored patch is cut once; later views see it magnified and rotated about the feature.
    image = textured(3, shape=(240, 320))
    u0, v0 = 161, 119
    errors = {"affine": [], "parabola": []}
    for angle_deg, scale in [(6.0, 1.12), (-5.0, 0.9), (8.0, 1.15), (3.0, 1.08)]:
        warp = cv2.getRotationMatrix2D((float(u0), float(v0)), angle_deg, scale)
        warp[:, 2] += [2.4, -1.7]                     # and translated
        view = cv2.warpAffine(image, warp, (320, 240), flags=cv2.INTER_CUBIC)
        patches = {0: image[v0 - 5:v0 + 6, u0 - 5:u0 + 6].copy()}
        truth = warp @ np.array([u0, v0, 1.0])        # the patch centre in the view (oracle: the warp)
        cov = np.eye(2)[None] * 16.0
        for mode in errors:
            uv, found = active_search(view, patches, np.array([0]), truth[None] + [1.0, -1.0], cov,
                                      FrontEndOptions(subpixel=mode))
            assert found[0], mode
            errors[mode].append(np.linalg.norm(uv[0] - truth))
    assert max(errors["affine"]) < 0.15
    assert np.mean(errors["affine"]) < 0.5 * np.mean(errors["parabola"])


def test_civera_to_opencv_reproduces_the_model_and_reports_its_error():
    camera = rscalib.CameraModel("civera-radial", PAPER, 320, 240, pixel_size_mm=(0.0112, 0.0112))
    opencv, max_error = civera_to_opencv(camera)
    # independent check on points inside the central 80 % of the image
    us, vs = np.meshgrid(np.linspace(32, 288, 9), np.linspace(24, 216, 7))
    uv_d = np.c_[us.ravel(), vs.ravel()]
    rays = camera.unproject(uv_d)
    k, dist = rscalib.io.cameras.opencv_matrices(opencv)
    uv_cv = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, dist)[0].reshape(-1, 2)
    assert np.abs(uv_cv - uv_d).max() < 1.0
    assert np.abs(uv_cv - uv_d).max() <= max_error + 1e-9
    assert max_error < 10.0


@pytest.fixture(scope="module")
def room_sequence(tmp_path_factory):
    from rscalib.sim.scene_video import render_scene_sequence

    out = tmp_path_factory.mktemp("room")
    render_scene_sequence(out, num_frames=150, seed=1)
    return out


def test_selfcalib_cli_recovers_the_focal_length(room_sequence, tmp_path):
    proc = subprocess.run([*CLI, "selfcalib", room_sequence, "--out", tmp_path / "res", "--quiet"],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode in (0, 3), proc.stderr
    result = json.loads((tmp_path / "res" / "result.json").read_text())
    truth = json.loads((room_sequence / "truth.json").read_text())["camera"]["params"]
    assert abs(result["f"] - truth[0]) < 0.03 * truth[0]
    for name in ("f", "cx", "cy", "k1", "k2"):
        lo, hi = result[f"{name}_bounds_99"]
        assert lo <= result[name] <= hi
    assert result["frames_processed"] == 150
    assert result["gaussians_left"] < 108
    # the bundle adjustment over the filter's tracks is the estimate; its bounds hold the truth
    assert result["estimate_from"] == "bundle adjustment" and result["adjustment"]["estimate"][0] == result["f"]
    assert result["determined"] is (proc.returncode == 0)
    for name, value in zip(("f", "cx", "cy", "k1", "k2"), truth):
        lo, hi = result["adjustment_bounds_99"][("f", "cx", "cy", "k1", "k2").index(name)]
        assert lo <= value <= hi, (name, value, lo, hi)
    # no --line-delay: the adjustment estimated it; the render has a global shutter (0 s/row)
    assert json.loads((room_sequence / "truth.json").read_text()).get("line_delay_s", 0.0) == 0.0
    lo, hi = result["line_delay_bounds_99_s"]
    assert lo <= 0.0 <= hi and lo <= result["line_delay_estimated_s"] <= hi
    assert "line delay estimated" in proc.stdout
    assert len(result["history"]["gaussians"]) == 150
    assert result["provenance"]["command"] == "selfcalib" and result["baseline"] is None
    assert (tmp_path / "res" / "history.png").stat().st_size > 0
    camera = load_camera(tmp_path / "res" / "camera.yaml").camera
    assert camera.model == "pinhole-radtan"
    assert camera.params[0] == pytest.approx(result["f"])


def test_selfcalib_single_ekf_option_runs_one_gaussian_from_f0(room_sequence, tmp_path):
    proc = subprocess.run([*CLI, "selfcalib", room_sequence, "--out", tmp_path / "one", "--quiet", "--bank", "single",
                           "--f0", "260", "--f-sigma", "60", "--max-frames", "20", "--line-delay", "6e-5"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode in (0, 3), proc.stderr     # 20 frames need not determine f (restarts judge it)
    result = json.loads((tmp_path / "one" / "result.json").read_text())
    assert result["baseline"] == "single"
    assert result["provenance"]["inputs"]["line_delay_s"] == 6e-5   # the rolling shutter was compensated
    assert result["gaussians_initial"] == 1 and result["gaussians_left"] == 1
    assert result["history"]["mean"][0][0] != pytest.approx(result["f"])  # it moved from f0 ...
    lo, hi = result["history"]["bounds_99"][0][0]
    assert lo < 260 - 2.5 * 60 and hi > 260 + 2.5 * 60                  # ... which started as 260 +- 60


@pytest.mark.parametrize("case", ["missing source", "bad pixel size", "empty folder", "f0 without single",
                                  "negative line delay"])
def test_selfcalib_bad_input_exits_2(tmp_path, case):
    source = tmp_path / "frames"
    source.mkdir()
    extra = []
    if case == "missing source":
        source = tmp_path / "nope"
    elif case == "bad pixel size":
        cv2.imwrite(str(source / "a.png"), textured(2))
        extra = ["--pixel-size-mm", "-1"]
    elif case == "f0 without single":
        cv2.imwrite(str(source / "a.png"), textured(2))
        extra = ["--f0", "200"]
    elif case == "negative line delay":
        cv2.imwrite(str(source / "a.png"), textured(2))
        extra = ["--line-delay", "-3e-5"]
    proc = subprocess.run([*CLI, "selfcalib", source, "--out", tmp_path / "o", "--quiet", *extra],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, (case, proc.stderr)
    assert "Traceback" not in proc.stderr
    assert len([line for line in proc.stderr.splitlines() if line.strip()]) == 1
