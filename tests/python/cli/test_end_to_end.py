"""Video in, calibrated camera out: rendered rolling-shutter videos through detection, the engine
and the report (issue 4), via the CLI and the Python API."""
import json
import subprocess
import sys

import pytest

import rscalib
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video
from rscalib.io.cameras import load_camera
from rscalib.sim.target_video import render_video

CLI = [sys.executable, "-m", "rscalib.cli"]


def run_cli(*args, timeout=600):
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def checkerboard_video(tmp_path_factory):
    out = tmp_path_factory.mktemp("checkerboard_640")
    render_video(out, line_delay_s=40e-6, fps=30, size=(640, 480), target="checkerboard", duration_s=3.0,
                 seed=3, supersample=2, progress=False)
    return out


def test_linedelay_cli_on_a_rendered_checkerboard_video(checkerboard_video, tmp_path):
    sim = checkerboard_video
    truth = json.loads((sim / "truth.json").read_text())
    cache = tmp_path / "cache"
    env_args = ["--target", sim / "target.yaml", "--camera", sim / "camera.yaml"]
    proc = subprocess.run([*CLI, "linedelay", sim / "video.avi", *env_args, "--out", tmp_path / "run1"],
                          capture_output=True, text=True, timeout=600,
                          env={**__import__("os").environ, "RSCALIB_CACHE_DIR": str(cache)})
    assert proc.returncode == 0, proc.stderr
    result = json.loads((tmp_path / "run1" / "result.json").read_text())
    d, std = result["line_delay_s"], result["line_delay_std_s"]
    assert abs(d - truth["line_delay_s"]) < 0.01 * truth["line_delay_s"]
    assert abs(d - truth["line_delay_s"]) <= 3 * std
    for key in ("readout_time_s", "rows", "frames_total", "frames_used", "observations", "knots", "rms_px",
                "normalised_cost", "pixel_sigma", "converged", "warnings"):
        assert key in result
    assert result["frames_total"] == truth["num_frames"]
    assert result["rows"] == 480
    for name in ("report.html", "trajectory.csv", "camchain.yaml", "gyroflow_lens_profile.json",
                 "camera_with_line_delay.yaml"):
        assert (tmp_path / "run1" / name).stat().st_size > 0
    # the exports carry the line delay in each tool's units
    assert load_camera(tmp_path / "run1" / "camchain.yaml").line_delay_s == pytest.approx(d)
    assert load_camera(tmp_path / "run1" / "camera_with_line_delay.yaml").line_delay_s == pytest.approx(d)
    gyroflow = json.loads((tmp_path / "run1" / "gyroflow_lens_profile.json").read_text())
    assert gyroflow["frame_readout_time"] == pytest.approx(d * 480 * 1e3)
    assert gyroflow["asymmetrical"] is True
    html = (tmp_path / "run1" / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 6
    # a re-run takes the detections from the cache (said, and the same answer; no timing on a shared machine)
    again = subprocess.run([*CLI, "linedelay", sim / "video.avi", *env_args, "--out", tmp_path / "run2"],
                           capture_output=True, text=True, timeout=600,
                           env={**__import__("os").environ, "RSCALIB_CACHE_DIR": str(cache)})
    assert again.returncode == 0, again.stderr
    assert "(cached)" in again.stderr
    assert json.loads((tmp_path / "run2" / "result.json").read_text())["line_delay_s"] == pytest.approx(d, rel=1e-9)
    assert any(cache.rglob("*")), "nothing in the detection cache"


def test_the_python_front_door_gives_the_cli_answer_to_the_last_digit(checkerboard_video, tmp_path):
    """Issue 29: rscalib.calibrate_video is the command: the same line delay, sigma, verdict and files."""
    sim = checkerboard_video
    cache = tmp_path / "cache"
    proc = subprocess.run([*CLI, "linedelay", sim / "video.avi", "--target", sim / "target.yaml", "--camera",
                           sim / "camera.yaml", "--out", tmp_path / "cli", "--quiet"], capture_output=True,
                          text=True, timeout=600, env={**__import__("os").environ, "RSCALIB_CACHE_DIR": str(cache)})
    assert proc.returncode in (0, 4), proc.stderr
    cli = json.loads((tmp_path / "cli" / "result.json").read_text())
    run = rscalib.calibrate_video(sim / "video.avi", sim / "target.yaml", sim / "camera.yaml",
                                  rscalib.LineDelayOptions(detection=rscalib.DetectOptions(cache_dir=cache)))
    assert run.line_delay_s == cli["line_delay_s"] and run.line_delay_std_s == cli["line_delay_std_s"]
    assert run.verdict.to_dict() == cli["verdict"] and run.verdict.exit_code == proc.returncode
    summary = run.write(tmp_path / "api")
    api = json.loads((tmp_path / "api" / "result.json").read_text())
    for key in ("line_delay_s", "line_delay_std_s", "readout_time_s", "normalised_cost", "knots", "self_check",
                "guidance", "verdict"):
        assert api[key] == cli[key] == summary[key], key
    assert sorted(p.name for p in (tmp_path / "api").iterdir()) == sorted(p.name for p in (tmp_path / "cli").iterdir())


def test_circle_grid_720p_through_the_api(tmp_path):
    out = tmp_path / "circles"
    render_video(out, line_delay_s=25e-6, fps=30, size=(1280, 720), target="circlegrid", duration_s=2.0,
                 seed=5, supersample=2, progress=False)
    truth = json.loads((out / "truth.json").read_text())
    camera = load_camera(out / "camera.yaml").camera
    detection = detect_video(out / "video.avi", out / "target.yaml", DetectOptions(cache=False), progress=False)
    # the 16:9 frame cuts the grid off at times; circle grids have no partial views
    assert detection.frames_detected >= 0.5 * truth["num_frames"]
    run = rscalib.calibrate_video(detection, camera=camera)   # detections already made: the same front door
    err = run.line_delay_s - truth["line_delay_s"]
    assert abs(err) < 0.01 * truth["line_delay_s"]
    assert abs(err) <= 3 * run.line_delay_std_s
    assert run.verdict.claims and run.line_delay_s == run.result.line_delay_s


def test_static_camera_video_exits_3_with_results(tmp_path):
    out = tmp_path / "static"
    render_video(out, line_delay_s=30e-6, fps=30, size=(640, 480), duration_s=1.5, seed=1, motion=0.0,
                 supersample=1, progress=False)
    proc = run_cli("linedelay", out / "video.avi", "--target", out / "target.yaml", "--camera",
                   out / "camera.yaml", "--out", tmp_path / "res", "--no-cache", "--quiet")
    assert proc.returncode == 3, proc.stderr
    result = json.loads((tmp_path / "res" / "result.json").read_text())
    assert result["determined"] is False
    assert any("not determined" in w for w in result["warnings"])


@pytest.mark.parametrize("case", ["missing video", "missing target", "bad target yaml", "unreadable video",
                                  "camera size mismatch", "no detections", "bad pixel sigma"])
def test_linedelay_bad_input_exits_2_with_one_line(checkerboard_video, tmp_path, case):
    sim = checkerboard_video
    video, target, camera = sim / "video.avi", sim / "target.yaml", sim / "camera.yaml"
    extra = []
    if case == "missing video":
        video = tmp_path / "nope.avi"
    elif case == "missing target":
        target = tmp_path / "nope.yaml"
    elif case == "bad target yaml":
        target = tmp_path / "bad.yaml"
        target.write_text("target_type: checkerboard\ntargetCols: [unclosed\n")
    elif case == "unreadable video":
        video = tmp_path / "text.avi"
        video.write_text("this is not a video")
    elif case == "camera size mismatch":
        camera = tmp_path / "camera.yaml"
        rscalib.io.cameras.write_opencv_yaml(rscalib.CameraModel("pinhole-radtan", [500, 500, 400, 300], 800, 600),
                                            camera)
    elif case == "no detections":
        target = tmp_path / "wrong_size.yaml"
        target.write_text("target_type: checkerboard\ntargetCols: 4\ntargetRows: 11\n"
                          "rowSpacingMeters: 0.02\ncolSpacingMeters: 0.02\n")
    elif case == "bad pixel sigma":
        extra = ["--pixel-sigma", "-1"]
    proc = run_cli("linedelay", video, "--target", target, "--camera", camera, "--out", tmp_path / "o",
                   "--no-cache", "--quiet", *extra)
    assert proc.returncode == 2, (case, proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "error" in lines[0], proc.stderr


@pytest.mark.parametrize("cols, rows, shows", [(4, 3, "9x6"), (10, 7, "9x6"), (6, 9, None)])
def test_a_target_file_that_does_not_match_the_board_exits_2_saying_what_the_frames_show(
        checkerboard_video, tmp_path, cols, rows, shows):
    """Issue 12: a smaller board declared (OpenCV finds 4x3 sub-grids inside the 9x6 board), squares
    counted instead of inner corners (10x7): exit 2 with one line naming the board the frames show.
    Swapped cols/rows of a square checkerboard is the same board (a rotated world): it calibrates."""
    target = tmp_path / "target.yaml"
    target.write_text(f"target_type: checkerboard\ntargetCols: {cols}\ntargetRows: {rows}\n"
                      "rowSpacingMeters: 0.04\ncolSpacingMeters: 0.04\n")
    proc = run_cli("linedelay", checkerboard_video / "video.avi", "--target", target, "--camera",
                   checkerboard_video / "camera.yaml", "--out", tmp_path / "o", "--no-cache", "--quiet",
                   "--no-self-check")
    assert "Traceback" not in proc.stderr
    if shows is None:
        assert proc.returncode in (0, 4), proc.stderr
        return
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and shows in lines[0], proc.stderr


def test_static_camera_says_not_determined_without_a_number(tmp_path):
    """Issue 12: no nonsense headline ("-34148 us +- inf"): exit 3, 'not determined', no estimate."""
    out = tmp_path / "static"
    render_video(out, line_delay_s=30e-6, fps=30, size=(640, 480), duration_s=1.5, seed=2, motion=0.0,
                 supersample=1, progress=False)
    proc = run_cli("linedelay", out / "video.avi", "--target", out / "target.yaml", "--camera",
                   out / "camera.yaml", "--out", tmp_path / "res", "--no-cache", "--quiet")
    assert proc.returncode == 3, proc.stderr
    assert "not determined" in proc.stdout and "us/row" not in proc.stdout.split("report:")[0], proc.stdout
    result = json.loads((tmp_path / "res" / "result.json").read_text())
    assert result["verdict"]["status"] == "not determined" and result["verdict"]["value"] is None
    assert "Traceback" not in proc.stderr
    # no number the verdict does not stand behind leaves the tool: result.json claims none, and no file
    # for another tool is written with the line delay (issue 29)
    assert result["line_delay_s"] is None and result["readout_time_s"] is None
    assert result["not_claimed"]["line_delay_s"] is not None
    for name in ("camera_with_line_delay.yaml", "camchain.yaml", "gyroflow_lens_profile.json", "camera_info.yaml",
                 "camera.cameramodel", "cameras.txt"):
        assert not (tmp_path / "res" / name).exists(), name
    assert any("not determined" in note for note in result["export_notes"])
    html = (tmp_path / "res" / "report.html").read_text()
    assert "not determined" in html and "ms (480 rows read out)" not in html


def test_linedelay_help_documents_exit_codes_and_flags():
    proc = run_cli("linedelay", "--help")
    text = " ".join(proc.stdout.split())
    for needle in ("exit codes", "4 estimated but not trusted", "3 the video does not determine", "--start",
                   "--end", "--readout", "--min-segment-ms", "--no-self-check"):
        assert needle in text, needle
