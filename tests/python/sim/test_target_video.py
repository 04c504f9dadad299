"""The rolling-shutter renderer and `rscalib simulate` (issue 4).

The renderer is checked from outside: OpenCV detects the target in the decoded frames, and the
detections must sit on the exact rolling-shutter projection recorded in truth.json (computed by
target_observations.rs_projection's fixed point, not by the renderer) and clearly off the global-shutter projection.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from rscalib.errors import InputError
from rscalib.io.cameras import load_camera, opencv_matrices
from rscalib.io.targets import Target, as_target, load_target, target_from_dict
from rscalib.sim import target_video as render
from rscalib.sim.target_observations import default_camera, opencv_project
from rscalib.sim.target_texture import BACKGROUND, TargetTexture
from rscalib.sim.trajectories import target_trajectory

SCRIPT = Path(sys.executable).parent / ("rscalib.exe" if os.name == "nt" else "rscalib")
SB_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)

# Strong hand-held motion (about 300-700 px/s in the image) and d = 60 µs: the rolling-shutter
# and global-shutter projections differ by several pixels.
LINE_DELAY_S = 60e-6
FPS = 30.0


def cli(*args, timeout=120):
    argv = [str(SCRIPT), *args] if SCRIPT.exists() else [sys.executable, "-m", "rscalib.cli", *args]
    return subprocess.run(argv, capture_output=True, text=True, timeout=timeout)


def match_nearest(detected: np.ndarray, reference: np.ndarray, one_to_one: bool = True) -> np.ndarray:
    """Distance of each detection to its nearest reference point (detectors may order a symmetric
    pattern either way round); against the right projection the matching must be one-to-one."""
    dist = np.linalg.norm(detected[:, None, :] - reference[None, :, :], axis=2)
    dist = np.where(np.isnan(dist), np.inf, dist)
    nearest = dist.argmin(axis=1)
    if one_to_one:
        assert len(np.unique(nearest)) == len(nearest), "detections do not map one-to-one onto the target"
    return dist[np.arange(len(detected)), nearest]


def read_video(path: Path):
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    frames, stamps_ms = [], []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        stamps_ms.append(cap.get(cv2.CAP_PROP_POS_MSEC))
        frames.append(frame)
    count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
    cap.release()
    return frames, np.array(stamps_ms), count


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    out = tmp_path_factory.mktemp("render")
    rendered = render.render_video(out, line_delay_s=LINE_DELAY_S, fps=FPS, size=(640, 480), target="checkerboard",
                                   duration_s=0.3, noise=2.0, seed=4, motion=1.5, progress=False)
    frames, stamps_ms, count = read_video(rendered.video_path)
    return rendered, frames, stamps_ms, count


def test_video_container_frames_and_timestamps(clip):
    rendered, frames, stamps_ms, count = clip
    assert rendered.num_frames == 9 and rendered.codec == "FFV1"
    assert len(frames) == 9 and count == 9
    # t_i = i / fps from the container (presentation time), row 0 starts exposure then.
    np.testing.assert_allclose(stamps_ms / 1e3, np.arange(9) / FPS, atol=1e-6)
    truth = json.loads(rendered.truth_path.read_text())
    np.testing.assert_allclose(truth["frame_times_s"], np.arange(9) / FPS)
    assert frames[0].shape == (480, 640, 3)
    assert np.array_equal(frames[0][..., 0], frames[0][..., 2])  # grey video


def test_checkerboard_corners_on_exact_rolling_shutter_projection(clip):
    rendered, frames, _, _ = clip
    uv_rs, uv_gs = rendered.uv_rs(), rendered.uv_gs()
    err_rs, err_rs_subpix, err_gs = [], [], []
    for i, frame in enumerate(frames):
        grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        ok, corners = cv2.findChessboardCornersSB(grey, (9, 6), flags=SB_FLAGS)
        if not ok:
            continue
        corners = corners.reshape(-1, 2)
        refined = cv2.cornerSubPix(grey, corners.astype(np.float32).reshape(-1, 1, 2).copy(), (5, 5), (-1, -1),
                                   SUBPIX_CRITERIA).reshape(-1, 2)
        err_rs.append(match_nearest(corners, uv_rs[i]))
        err_rs_subpix.append(match_nearest(refined, uv_rs[i]))
        err_gs.append(match_nearest(corners, uv_gs[i], one_to_one=False))
    assert len(err_rs) >= 7, f"board found in only {len(err_rs)} of 9 frames"
    err_rs, err_rs_subpix, err_gs = (np.concatenate(e) for e in (err_rs, err_rs_subpix, err_gs))
    # findChessboardCornersSB alone is the more accurate detector on these images (~0.02 px);
    # cornerSubPix on top of it is looser (~0.05-0.08 px) but still well inside 0.15 px.
    assert np.median(err_rs) < 0.05, np.median(err_rs)
    assert np.percentile(err_rs, 95) < 0.1
    assert np.median(err_rs_subpix) < 0.15, np.median(err_rs_subpix)
    # The global-shutter projection (every row at t_i) is clearly farther away.
    assert np.median(err_gs) > 1.0, np.median(err_gs)
    assert np.median(err_gs) > 20 * np.median(err_rs)


def test_zero_line_delay_agrees_with_global_shutter():
    camera = default_camera((640, 480))
    target = Target.named("checkerboard")
    trajectory = target_trajectory(camera, target, 2.0, seed=4, motion=1.5)
    rng = np.random.default_rng(1)
    errors = []
    with render.RollingShutterRenderer(camera, target, trajectory, 0.0, supersample=2) as renderer:
        for t in (0.1, 0.2):
            grey = render.to_uint8(renderer.render(t), 2.0, rng)
            ok, corners = cv2.findChessboardCornersSB(grey, (9, 6), flags=SB_FLAGS)
            assert ok
            uv_rs = renderer.project_rs(t)
            np.testing.assert_allclose(uv_rs, renderer.project_rs(t, line_delay_s=0.0), atol=1e-9)
            errors.append(match_nearest(corners.reshape(-1, 2), uv_rs))
    assert np.median(np.concatenate(errors)) < 0.05


def test_truth_projection_is_the_rolling_shutter_fixed_point(clip):
    """Independent of rs_projection: re-project each point at its own row time with OpenCV."""
    rendered, _, _, _ = clip
    truth = rendered.truth
    trajectory = render.trajectory_from_truth(truth)
    K, dist = opencv_matrices(rendered.camera)
    points = np.asarray(truth["target_points_m"])
    uv = rendered.uv_rs()
    for i in (0, 8):
        t_row = truth["frame_times_s"][i] + uv[i, :, 1] * truth["line_delay_s"]
        R, p = trajectory.pose_cw(t_row)
        x_c = np.einsum("nij,nj->ni", R, points) + p
        np.testing.assert_allclose(opencv_project("pinhole-radtan", K, dist, x_c), uv[i], atol=1e-6)
    # The recorded poses are those of the rebuilt trajectory.
    R, p = trajectory.pose_cw(np.asarray(truth["poses_at_frames"]["t_s"]))
    np.testing.assert_allclose(p, truth["poses_at_frames"]["translation_m"], atol=1e-9)
    dense = truth["poses_dense"]
    assert dense["t_s"][-1] >= truth["frame_times_s"][-1] + truth["readout_time_s"]


@pytest.mark.parametrize("name, pattern, flags", [
    ("circlegrid", (7, 5), cv2.CALIB_CB_SYMMETRIC_GRID),
    ("acircles", (4, 11), cv2.CALIB_CB_ASYMMETRIC_GRID),
])
def test_circle_grids_detected_on_rolling_shutter_projection(name, pattern, flags):
    camera = default_camera((640, 480))
    target = Target.named(name)
    trajectory = target_trajectory(camera, target, 2.0, seed=4, motion=1.5)
    rng = np.random.default_rng(2)
    err_rs, err_gs = [], []
    with render.RollingShutterRenderer(camera, target, trajectory, LINE_DELAY_S, supersample=2) as renderer:
        for t in (0.1, 0.2, 0.3):
            grey = render.to_uint8(renderer.render(t), 2.0, rng)
            ok, centres = cv2.findCirclesGrid(grey, pattern, flags=flags)
            if ok:
                err_rs.append(match_nearest(centres.reshape(-1, 2), renderer.project_rs(t)))
                err_gs.append(match_nearest(centres.reshape(-1, 2), renderer.project_rs(t, line_delay_s=0.0), False))
    assert len(err_rs) >= 2
    err_rs, err_gs = np.concatenate(err_rs), np.concatenate(err_gs)
    # A blob centroid is not exactly the projected centre (perspective), so a little looser.
    assert np.median(err_rs) < 0.1, np.median(err_rs)
    assert np.median(err_gs) > 1.0


def test_aprilgrid_tags_decode_with_the_recorded_corner_ids():
    camera = default_camera((640, 480))
    target = Target.named("aprilgrid")
    trajectory = target_trajectory(camera, target, 1.0, seed=3, motion=0.0)
    corner_ids = target.aruco_corner_ids()
    assert TargetTexture(target).describe()["aruco_corner_point_ids"] == corner_ids.tolist()  # truth.json
    with render.RollingShutterRenderer(camera, target, trajectory, LINE_DELAY_S, supersample=2) as renderer:
        grey = render.to_uint8(renderer.render(0.0), 1.0, np.random.default_rng(3))
        uv = renderer.project_rs(0.0)
    params = cv2.aruco.DetectorParameters()
    params.markerBorderBits = 2  # Kalibr's tags
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)
    corners, ids, _ = detector.detectMarkers(grey)
    assert ids is not None and len(ids) >= 30, "tags not decoded (mirrored or wrong bits?)"
    assert ids.max() < 36
    for quad, tag in zip(corners, ids.ravel()):
        quad = quad.reshape(4, 2)
        nearest = np.linalg.norm(quad[:, None] - uv[None], axis=2).argmin(axis=1)
        assert np.array_equal(nearest, corner_ids[tag])
        # OpenCV's contour corners are pulled ~2 px by Kalibr's corner squares; only the mapping matters.
        assert np.all(np.linalg.norm(quad - uv[corner_ids[tag]], axis=1) < 4.0)


def test_motion_blur_centroid_is_mid_exposure():
    camera = default_camera((640, 480))
    target = Target.named("checkerboard")
    trajectory = target_trajectory(camera, target, 2.0, seed=4, motion=1.5)
    exposure_s = 0.004
    err_mid, err_start = [], []
    with render.RollingShutterRenderer(camera, target, trajectory, LINE_DELAY_S, supersample=1,
                                       exposure_s=exposure_s) as renderer:
        assert len(renderer.exposure_offsets_s(0.1)) > 1
        for t in (0.1, 0.2):
            grey = render.to_uint8(renderer.render(t), 1.0, np.random.default_rng(4))
            ok, corners = cv2.findChessboardCornersSB(grey, (9, 6), flags=SB_FLAGS)
            assert ok
            err_mid.append(match_nearest(corners.reshape(-1, 2), renderer.project_rs(t, 0.5 * exposure_s)))
            err_start.append(match_nearest(corners.reshape(-1, 2), renderer.project_rs(t), False))
    assert np.median(np.concatenate(err_mid)) < 0.1
    assert np.median(np.concatenate(err_start)) > 0.3


def test_equidistant_lens():
    camera = default_camera((640, 480), "pinhole-equidistant")
    target = Target.named("checkerboard")
    trajectory = target_trajectory(camera, target, 1.0, seed=4, motion=1.0)
    with render.RollingShutterRenderer(camera, target, trajectory, LINE_DELAY_S, supersample=2) as renderer:
        grey = render.to_uint8(renderer.render(0.2), 1.0, np.random.default_rng(5))
        ok, corners = cv2.findChessboardCornersSB(grey, (9, 6), flags=SB_FLAGS)
        assert ok
        assert np.median(match_nearest(corners.reshape(-1, 2), renderer.project_rs(0.2))) < 0.05


def test_intensity_modulation_hook_acts_per_row_time():
    camera = default_camera((160, 120))
    target = Target.named("checkerboard")
    trajectory = target_trajectory(camera, target, 1.0, motion=0.0)
    line_delay_s = 100e-6

    def flicker(t):
        return 1.0 + 0.5 * np.sin(2 * np.pi * 100.0 * t)

    with render.RollingShutterRenderer(camera, target, trajectory, line_delay_s, supersample=1) as plain, \
            render.RollingShutterRenderer(camera, target, trajectory, line_delay_s, supersample=1,
                                          intensity_modulation=flicker) as lit:
        ratio = lit.render(0.01) / plain.render(0.01)
    rows = np.arange(120)
    np.testing.assert_allclose(ratio, np.broadcast_to(flicker(0.01 + rows * line_delay_s)[:, None], ratio.shape),
                               rtol=1e-6)


def test_frames_dir_and_target_file(tmp_path):
    rendered = render.render_video(tmp_path, size="160x120", duration_s=0.1, video=False, frames_dir=True,
                                   target="circlegrid", progress=False)
    pngs = sorted(rendered.frames_dir.glob("frame_*.png"))
    assert rendered.video_path is None and len(pngs) == 3
    assert cv2.imread(str(pngs[0]), cv2.IMREAD_UNCHANGED).shape == (120, 160)
    stamps = np.loadtxt(rendered.frames_dir / "timestamps.txt")
    np.testing.assert_allclose(stamps, np.arange(3) / 30.0, atol=1e-9)
    kalibr = yaml.safe_load(rendered.target_path.read_text())
    assert kalibr == {"target_type": "circlegrid", "targetCols": 7, "targetRows": 5, "spacingMeters": 0.04,
                      "asymmetricGrid": False}
    assert load_target(rendered.target_path) == rendered.target == Target.named("circlegrid")


def test_target_validation(tmp_path):
    with pytest.raises(InputError):
        Target.named("nope")
    with pytest.raises(InputError):
        target_from_dict({"target_type": "checkerboard", "targetCols": 9})
    charuco = target_from_dict({"target_type": "charuco", "squaresX": 5, "squaresY": 4, "squareLength": 0.04,
                                "markerLength": 0.03})
    with pytest.raises(InputError, match="cannot be rendered"):
        TargetTexture(charuco)
    with pytest.raises(InputError, match="circle radius"):
        TargetTexture(Target.named("circlegrid"), circle_radius_m=0.03)
    # A Target, a built-in name or a Kalibr YAML path.
    path = tmp_path / "board.yaml"
    path.write_text(yaml.safe_dump({"target_type": "checkerboard", "targetCols": 7, "targetRows": 5,
                                    "rowSpacingMeters": 0.03, "colSpacingMeters": 0.02}))
    board = as_target(path)
    assert as_target(str(path)) == board and as_target(board) is board
    assert as_target("aprilgrid") == Target.named("aprilgrid")
    texture = TargetTexture(board)
    assert (texture.cols, texture.rows, texture.spacing_m, texture.row_pitch_m) == (7, 5, 0.02, 0.03)
    april = Target.named("aprilgrid")
    assert len(april.points_m) == 4 * 36
    # Kalibr's AprilGrid corner layout: tag 1's lower-left corner is one pitch along x.
    np.testing.assert_allclose(april.points_m[2], [TargetTexture(april).tag_pitch_m, 0.0, 0.0])
    np.testing.assert_allclose(april.points_m[2], [0.088 * 1.3, 0.0, 0.0])


def test_renderer_accepts_a_texture_with_its_own_drawing():
    camera = default_camera((160, 120))
    target = Target.named("circlegrid")
    trajectory = target_trajectory(camera, target, 1.0, motion=0.0)
    small = TargetTexture(target, circle_radius_m=0.005)
    no_margin = TargetTexture(target, margin_m=0.0)
    with render.RollingShutterRenderer(camera, target, trajectory, 0.0, supersample=1) as default, \
            render.RollingShutterRenderer(camera, small, trajectory, 0.0, supersample=1) as custom, \
            render.RollingShutterRenderer(camera, no_margin, trajectory, 0.0, supersample=1) as bare:
        assert custom.target == target
        plain = default.render(0.0)
        assert custom.render(0.0).mean() > plain.mean()  # smaller black discs
        assert np.sum(bare.render(0.0) == BACKGROUND) > np.sum(plain == BACKGROUND)  # less white paper


def test_cli_simulate_writes_video_truth_camera_target(tmp_path):
    out = tmp_path / "sim"
    result = cli("simulate", "--out", str(out), "--duration", "1")
    assert result.returncode == 0, result.stderr
    for name in ("video.avi", "truth.json", "camera.yaml", "target.yaml"):
        assert (out / name).is_file(), name
    truth = render.load_truth(out)
    assert truth["num_frames"] == 30 and truth["line_delay_s"] == pytest.approx(30e-6)
    camera_file = load_camera(out / "camera.yaml")
    assert camera_file.line_delay_s == pytest.approx(30e-6)
    assert (camera_file.camera.width, camera_file.camera.height) == (640, 480)
    np.testing.assert_allclose(camera_file.camera.params, truth["camera"]["params"])
    assert yaml.safe_load((out / "target.yaml").read_text())["target_type"] == "checkerboard"
    frames, stamps_ms, count = read_video(out / "video.avi")
    assert len(frames) == 30 and count == 30


@pytest.mark.parametrize("args, reason", [
    (["--fps", "-5"], "fps"),
    (["--size", "640by480"], "size"),
    (["--size", "0x480"], "size"),
    (["--exposure", "50ms"], "exposure"),
    (["--line-delay", "1ms"], "readout"),
    (["--target", "hexagons"], "target"),
    (["--line-delay", "abc"], "line-delay"),
])
def test_cli_bad_options_exit_2_with_one_line(tmp_path, args, reason):
    result = cli("simulate", "--out", str(tmp_path / "bad"), *args)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert reason in lines[0]
