"""What `rscalib linedelay` and `rscalib intrinsics` ship for other tools (issue 15): every camera
format, corners.vnl, the TUM trajectory, the two readout times, provenance in result.json and the
report (links, one line per file), on a short rendered video."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rscalib.io.cameras import load_camera
from rscalib.sim.target_video import render_video

CLI = [sys.executable, "-m", "rscalib.cli"]


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("exports")
    render_video(out, line_delay_s=30e-6, fps=30, size=(640, 480), target="checkerboard", duration_s=2.0,
                 seed=5, supersample=2, progress=False)
    return out


@pytest.fixture(scope="module")
def linedelay_run(video, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "result"
    proc = subprocess.run([*CLI, "linedelay", video / "video.avi", "--target", video / "target.yaml", "--camera",
                           video / "camera.yaml", "--out", out, "--rows", "500", "--no-self-check", "--quiet",
                           "--camera-brand", "Acme", "--camera-model", "Cam 1", "--lens-model", "Wide"],
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "RSCALIB_CACHE_DIR": str(out.parent / "cache")})
    assert proc.returncode in (0, 4), proc.stderr
    return out


def test_linedelay_names_its_two_readout_times_apart(linedelay_run):
    result = json.loads((linedelay_run / "result.json").read_text())
    d = result["line_delay_s"]
    assert result["rows"] == 500
    assert result["readout_time_s"] == pytest.approx(d * 500, rel=1e-12)
    assert result["image_readout_time_s"] == pytest.approx(d * 480, rel=1e-12)
    gyroflow = json.loads((linedelay_run / "gyroflow_lens_profile.json").read_text())
    assert gyroflow["frame_readout_time"] == pytest.approx(d * 480 * 1e3, rel=1e-12)
    assert gyroflow["name"].startswith("Acme_Cam 1_Wide_640x480-30.00fps") and gyroflow["fps"] == 30.0
    camera = load_camera(linedelay_run / "camera_with_line_delay.yaml")
    assert camera.line_delay_s == pytest.approx(d)


def test_linedelay_writes_every_format_and_the_tum_trajectory(linedelay_run):
    result = json.loads((linedelay_run / "result.json").read_text())
    files = result["files"]
    for role in ("opencv_yaml", "kalibr_camchain", "gyroflow_profile", "ros_camera_info", "mrcal_cameramodel",
                 "colmap_cameras", "mrcal_corners", "trajectory_csv", "trajectory_tum"):
        assert (linedelay_run / files[role]).is_file(), role
    reference = load_camera(linedelay_run / "camera_with_line_delay.yaml").camera
    for role in ("ros_camera_info", "mrcal_cameramodel", "colmap_cameras", "gyroflow_profile"):
        camera = load_camera(linedelay_run / files[role]).camera
        np.testing.assert_allclose(camera.params, reference.params, atol=1e-9)
    # trajectory.csv (world-to-camera) and TUM (camera-to-world), read as their formats say
    header = (linedelay_run / "trajectory.csv").read_text().splitlines()[0]
    assert header.startswith("t_s,world_to_camera_p_x_m")
    csv = np.loadtxt(linedelay_run / "trajectory.csv", delimiter=",", skiprows=1)
    tum = np.loadtxt(linedelay_run / "trajectory_tum.txt")
    np.testing.assert_array_equal(csv[:, 0], tum[:, 0])
    rotation_cw = Rotation.from_rotvec(csv[:, 4:7])
    rotation_wc = Rotation.from_quat(tum[:, 4:8])            # TUM: qx qy qz qw
    np.testing.assert_allclose((rotation_wc * rotation_cw).magnitude(), 0, atol=1e-6)
    centres = -rotation_cw.inv().apply(csv[:, 1:4])
    np.testing.assert_allclose(tum[:, 1:4], centres, atol=1e-6)
    # each frame at its row 0 and at the middle of its image readout
    d = result["line_delay_s"]
    times = csv[:, 0]
    assert np.any(np.isclose(np.diff(times), 240 * d, atol=1e-7))


def test_result_json_and_the_report_carry_the_provenance(linedelay_run, video):
    result = json.loads((linedelay_run / "result.json").read_text())
    provenance = result["provenance"]
    assert provenance["command_line"].startswith("rscalib linedelay ") and "--rows 500" in provenance["command_line"]
    for role in ("video", "target", "camera"):
        record = provenance["input_files"][role]
        assert len(record["sha256"]) == 64 and record["bytes"] > 0
    assert provenance["camera_as_read"]["model"] == "pinhole-radtan"
    assert provenance["target_as_read"]["target_type"] == "checkerboard"
    assert provenance["rows"] == 500
    report = (linedelay_run / "report.html").read_text()
    assert "Provenance" in report and provenance["input_files"]["video"]["sha256"][:16] in report
    for name in ("camchain.yaml", "camera_info.yaml", "cameras.txt", "corners.vnl", "trajectory_tum.txt"):
        assert f'<a href="{name}">{name}</a>: ' in report
    assert any("refitted" in note for note in result["export_notes"]) == bool(
        load_camera(video / "camera.yaml").camera.params[8])


def test_intrinsics_writes_the_camera_for_every_tool_and_a_gyroflow_profile(video, tmp_path):
    frames = tmp_path / "frames"
    render_video(frames, line_delay_s=0.0, fps=5, size=(640, 480), target="checkerboard", duration_s=4.0,
                 seed=8, supersample=2, progress=False, video=False, frames_dir=True)
    source = frames / "frames"
    (source / "timestamps.txt").unlink(missing_ok=True)
    proc = subprocess.run([*CLI, "intrinsics", source, "--target", frames / "target.yaml", "--out", tmp_path / "calib",
                           "--quiet", "--camera-brand", "Acme", "--lens-model", "Wide", "--no-cache"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    calib = tmp_path / "calib"
    result = json.loads((calib / "result.json").read_text())
    for role in ("opencv_yaml", "kalibr_camchain", "gyroflow_profile", "ros_camera_info", "colmap_cameras",
                 "mrcal_corners"):
        assert (calib / result["files"][role]).is_file(), role
    profile = json.loads((calib / "gyroflow_lens_profile.json").read_text())
    assert profile["frame_readout_time"] is None and profile["num_images"] == result["views_used"]
    assert profile["camera_brand"] == "Acme" and profile["lens_model"] == "Wide"
    assert result["provenance"]["input_files"]["target"]["sha256"]


def test_the_report_shows_the_camera_check_next_to_the_camera_file(linedelay_run):
    """report.html: the camera file's intrinsics next to those the video prefers (the camera check of
    result.json's diagnosis), and how far d moved when they were freed."""
    result = json.loads((linedelay_run / "result.json").read_text())
    check = result["diagnosis"]["evidence"]["camera_check"]
    page = (linedelay_run / "report.html").read_text()
    assert "Camera check: does the video agree with the camera file?" in page
    for name, given, refit in zip(check["param_names"], check["params_file"], check["params_refined"]):
        assert f"<tr><td>{name}</td><td>{given:.6g}</td><td>{refit:.6g}</td></tr>" in page
    assert f"moved the line delay by {check['shift_sigma']:+.2f} of its σ" in page
    assert f"focal length {check['focal_change_fraction'] * 100:+.2f} %" in page.lower()
