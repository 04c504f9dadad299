"""Files anybody may have written (issue 33): every camera, target and manifest reader refuses what
would crash, hang or exhaust the process with one InputError line, and reads the valid but unusual
files real tools write.

The cases that crashed or hung before run in a child process with a time limit, so that a segfault
(OpenCV's parser on a deeply nested file) or a hang (an alias bomb) is a test failure, not the end
of the test run. The shared helper is rscalib.io.safe_parse.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from rscalib._core import CameraModel
from rscalib.batch.manifest import load_manifest
from rscalib.cli import build_parser
from rscalib.errors import InputError
from rscalib.io.cameras import load_camera, write_camera
from rscalib.io.targets import load_target

PARSE = build_parser().parse_args   # the rows are checked with the commands' own parser (as `rscalib batch`)

CAMERA = CameraModel("pinhole-radtan", [500.0, 501.0, 319.5, 239.5, -0.1, 0.05, 0.001, -0.002, 0.0], 640, 480)
KALIBR = {"cam0": {"camera_model": "pinhole", "intrinsics": [500.0, 501.0, 319.5, 239.5],
                   "distortion_model": "radtan", "distortion_coeffs": [-0.1, 0.05, 0.001, -0.002],
                   "resolution": [640, 480]}}
ROS = {"image_width": 640, "image_height": 480, "camera_name": "c",
       "camera_matrix": {"rows": 3, "cols": 3, "data": [500.0, 0, 319.5, 0, 501.0, 239.5, 0, 0, 1]},
       "distortion_model": "plumb_bob",
       "distortion_coefficients": {"rows": 1, "cols": 5, "data": [-0.1, 0.05, 0.001, -0.002, 0.0]}}
TARGET = "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.04\ncolSpacingMeters: 0.04\n"
BILLION_LAUGHS = "l0: &l0 lol\n" + "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]\n" for i in range(1, 10))
DEEP = 100_000


def in_child(code: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
    """`code` in a fresh interpreter (same rscalib); a crash is its exit status, a hang a failure."""
    try:
        return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                              timeout=timeout_s)
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running after {timeout_s} s")


def refused_in_child(reader: str, path: Path, *words, timeout_s: float = 60.0) -> str:
    """The reader (load_camera, load_target, load_manifest) on `path` in a child: an InputError of
    one line naming the file, else the test fails (segfault, other exception, hang)."""
    done = in_child(f"""
        import sys, warnings
        warnings.simplefilter("ignore")
        from rscalib.errors import InputError
        from rscalib.io.cameras import load_camera
        from rscalib.io.targets import load_target
        from rscalib.batch.manifest import load_manifest
        try:
            {reader}({str(path)!r})
        except InputError as error:
            print("InputError:", error)
            sys.exit(0)
        print("read without an error")
        sys.exit(5)
    """, timeout_s)
    assert done.returncode == 0, f"exit {done.returncode}: {done.stdout}{done.stderr[-1500:]}"
    line = done.stdout.strip()
    assert line.startswith("InputError:") and "\n" not in line, line
    for word in words:
        assert word in line, line
    return line


# -- nesting ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, text", [
    ("deep.yaml", "[" * DEEP + "]" * DEEP),                                         # PyYAML
    ("deep_block.yaml", "cam0:\n  intrinsics:\n    " + "- " * DEEP + "1\n"),         # block sequences
    ("deep.json", '{"a": ' * DEEP + "1" + "}" * DEEP),                                # JSON
    ("deep_opencv.yaml", "%YAML:1.0\n---\nimage_width: 640\nx: " + "[" * DEEP + "]" * DEEP
     + "\n# opencv-matrix\n"),                                                      # cv2.FileStorage (YAML)
    ("deep_opencv_dashes.yaml", "%YAML:1.0\n---\nx: !!opencv-matrix\n  " + "- " * DEEP + "1\n"),
    ("deep_opencv.xml", '<?xml version="1.0"?>\n<opencv_storage>' + "<a>" * DEEP + "1" + "</a>" * DEEP
     + "</opencv_storage>\n"),                                                      # cv2.FileStorage (XML)
    ("deep.cameramodel", "{'lensmodel': " + "[" * DEEP + "]" * DEEP + "}"),           # ast.literal_eval
    ("deep_quoted.json", '{"a": ' + "[\"]\"," * DEEP + "1" + "]" * DEEP + "}"),       # quotes cannot hide brackets
])
def test_a_deeply_nested_camera_file_is_refused_not_a_crash(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    refused_in_child("load_camera", path, str(path))


def test_a_deeply_nested_target_and_manifest_are_refused(tmp_path):
    deep = 20_000   # a target file is at most 64 KiB; 20 000 levels are 20 times Python's recursion limit
    (tmp_path / "t.yaml").write_text("target_type: " + "[" * deep + "]" * deep + "\n")
    refused_in_child("load_target", tmp_path / "t.yaml", "nested more than")
    (tmp_path / "m.yaml").write_text("jobs: " + "[" * DEEP + "]" * DEEP + "\n")
    refused_in_child("load_manifest", tmp_path / "m.yaml", "nested more than")


def test_nesting_is_measured_outside_strings_and_comments():
    from rscalib.io.safe_parse import nesting_depth

    assert nesting_depth('{"a": "' + "[" * 100 + '", "b": [1, [2]]}', "json") == 3   # quoted: not nesting
    assert nesting_depth("a:\n  b:\n    - - - 1\n", "yaml") <= 8
    assert nesting_depth("<a><b/><c>1</c></a>", "xml") == 2
    assert nesting_depth("[']'" * 200 + "]" * 200, "python") >= 200


# -- aliases ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("reader, name, text, words", [
    ("load_camera", "camchain.yaml", BILLION_LAUGHS + yaml.safe_dump(KALIBR), ["alias"]),
    ("load_target", "target.yaml", BILLION_LAUGHS + TARGET, ["alias"]),
    ("load_manifest", "jobs.yaml", BILLION_LAUGHS + "jobs:\n  - {command: flicker, input: a.avi, frequency: 100, "
     "args: *l9}\n", ["expand to more than"]),
])
def test_alias_bombs_are_refused_at_once(tmp_path, reader, name, text, words):
    path = tmp_path / name
    path.write_text(text)
    refused_in_child(reader, path, *words, timeout_s=30)


def test_aliases_a_manifest_may_use_are_read(tmp_path):
    path = tmp_path / "jobs.yaml"
    path.write_text("common: &board {command: linedelay, target: board.yaml, camera: cam.yaml}\n"
                    "jobs:\n  - {<<: *board, input: a.avi, id: a}\n  - {<<: *board, input: b.avi, id: b}\n")
    a, b = load_manifest(path, PARSE)
    assert a.argv[:4] == ("linedelay", str(tmp_path / "a.avi"), "--target", str(tmp_path / "board.yaml"))
    assert b.id == "b"
    from rscalib.io.safe_parse import load_yaml

    with pytest.raises(InputError, match="inside the value it names"):
        load_yaml("a: &x [1, *x]\n", "f.yaml", aliases=True)


# -- size -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("reader, name", [("load_camera", "camera.yaml"), ("load_camera", "cameras.txt"),
                                          ("load_target", "target.yaml"), ("load_manifest", "jobs.csv")])
def test_a_1_gb_sparse_file_is_refused_from_its_size_without_reading_it(tmp_path, reader, name):
    path = tmp_path / name
    with open(path, "wb") as f:
        f.write(b"cam0:\n" if reader == "load_camera" else b"command,input\n")
        f.truncate(1 << 30)
    done = in_child(f"""
        import resource, sys
        from rscalib.errors import InputError
        from rscalib.io.cameras import load_camera
        from rscalib.io.targets import load_target
        from rscalib.batch.manifest import load_manifest
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        try:
            {reader}({str(path)!r})
        except InputError as error:
            print(error)
        print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024)
    """)
    assert done.returncode == 0, done.stderr[-1500:]
    message, grown_mb = done.stdout.strip().splitlines()
    assert "1024.0 MiB, more than" in message and str(path) in message
    assert int(grown_mb) < 50   # nothing of the gigabyte was read


def test_a_large_yaml_camera_file_is_refused_at_once_not_parsed_for_minutes(tmp_path):
    """15 MB of YAML took PyYAML's pure-Python loader 335 s (and 1.2 GB) on this machine."""
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump(KALIBR) + "  extra: [" + ", ".join(["1.2345678"] * 300_000) + "]\n")
    started = time.monotonic()
    refused_in_child("load_camera", path, "of YAML, more than the 1.0 MiB", timeout_s=60)
    assert time.monotonic() - started < 60


def test_a_fifo_or_device_is_read_at_most_to_the_cap(tmp_path):
    from rscalib.io.safe_parse import read_text

    with pytest.raises(InputError, match="more than the 1024 bytes"):
        read_text("/dev/zero", 1024, "camera file")
    assert read_text("/dev/null", 1024) == ""


# -- integers -------------------------------------------------------------------------------------------

BIG = "9" * 5000


@pytest.mark.parametrize("reader, name, text", [
    ("load_camera", "camchain.yaml", yaml.safe_dump(KALIBR).replace("- 640", f"- {BIG}")),
    ("load_camera", "camera_info.yaml", yaml.safe_dump(ROS).replace("image_width: 640", f"image_width: {BIG}")),
    ("load_camera", "lens.json", json.dumps({"calib_dimension": {"w": 640, "h": 480}, "fisheye_params": {
        "camera_matrix": [[500, 0, 320], [0, 500, 240], [0, 0, 1]], "distortion_coeffs": [0, 0, 0, 0]}}
     ).replace("640", BIG)),
    ("load_camera", "camera.cameramodel", f"{{'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [500, 500, 320, 240], "
                                          f"'imagersize': [{BIG}, 480]}}"),
    ("load_target", "target.yaml", TARGET.replace("targetCols: 9", f"targetCols: {BIG}")),
    ("load_manifest", "jobs.yaml", f"- {{command: flicker, input: a.avi, frequency: {BIG}}}\n"),
])
def test_a_5000_digit_integer_is_a_clear_input_error(tmp_path, reader, name, text):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError) as error:
        {"load_camera": load_camera, "load_target": load_target, "load_manifest": load_manifest}[reader](path)
    message = str(error.value)
    assert "\n" not in message and str(path) in message and "digits" in message and "4300" not in message, message


def test_a_5000_digit_integer_in_a_csv_manifest_is_refused_by_the_option(tmp_path):
    path = tmp_path / "jobs.csv"
    path.write_text(f"command,input,frequency\nflicker,a.avi,{BIG}\n")
    with pytest.raises(InputError, match="field 'frequency'") as error:
        load_manifest(path, PARSE)
    assert "4300" not in str(error.value)


# -- types of fields ------------------------------------------------------------------------------------


@pytest.mark.parametrize("value", ["['LENSMODEL_OPENCV4']", "{'a': 1}", "4", "None"])
def test_an_mrcal_lensmodel_that_is_not_a_name_is_refused(tmp_path, value):
    path = tmp_path / "camera.cameramodel"
    path.write_text(f"{{'lensmodel': {value}, 'intrinsics': [500, 500, 320, 240, 0, 0, 0, 0], "
                    "'imagersize': [640, 480]}\n")
    with pytest.raises(InputError, match="lensmodel") as error:
        load_camera(path)
    assert "unhashable" not in str(error.value)


@pytest.mark.parametrize("field, value, words", [
    ("intrinsics", "'500500'", "must be a list of numbers"),
    ("resolution", "{w: 640, h: 480}", "must be a list of numbers"),
    ("distortion_model", "[radtan]", "is not supported"),
    ("camera_model", "{a: 1}", "is not supported"),
])
def test_kalibr_fields_of_the_wrong_type_are_refused(tmp_path, field, value, words):
    cam = {**KALIBR["cam0"], field: yaml.safe_load(value)}
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump({"cam0": cam}))
    with pytest.raises(InputError, match=words):
        load_camera(path)


def test_ros_and_gyroflow_fields_of_the_wrong_type_are_refused(tmp_path):
    ros = json.loads(json.dumps(ROS))
    ros["camera_matrix"]["data"] = "500 0 319.5 0 501 239.5 0 0 1"
    (tmp_path / "ros.yaml").write_text(yaml.safe_dump(ros))
    with pytest.raises(InputError, match="camera_matrix.data must be a list"):
        load_camera(tmp_path / "ros.yaml")
    write_camera(CAMERA, tmp_path / "lens.json", "gyroflow", line_delay_s=3e-5)
    profile = json.loads((tmp_path / "lens.json").read_text())
    for key, value, words in [("asymmetrical", "yes", "asymmetrical must be true or false"),
                              ("frame_readout_direction", ["TopToBottom"], "frame_readout_direction must be one of")]:
        (tmp_path / "bad.json").write_text(json.dumps({**profile, key: value}))
        with pytest.raises(InputError, match=words):
            load_camera(tmp_path / "bad.json")


# -- camera matrices that are not camera matrices -----------------------------------------------------


K = [[500.0, 0.0, 319.5], [0.0, 501.0, 239.5], [0.0, 0.0, 1.0]]


@pytest.mark.parametrize("case, matrix, words", [
    ("transposed", np.array(K).T.tolist(), "transposed camera matrix"),
    ("last row 0 0 2", [K[0], K[1], [0.0, 0.0, 2.0]], "last row must be 0 0 1"),
    ("lower left", [K[0], [3.0, 501.0, 239.5], K[2]], "below the diagonal"),
    ("last row 1e-3", [K[0], K[1], [1e-3, 0.0, 1.0]], "last row must be 0 0 1"),
    ("negative fy", [K[0], [0.0, -501.0, 239.5], K[2]], "focal lengths must be positive"),
])
@pytest.mark.parametrize("fmt", ["opencv", "ros", "gyroflow"])
def test_a_camera_matrix_that_is_not_one_is_refused_with_the_reason(tmp_path, case, matrix, words, fmt):
    path = tmp_path / {"opencv": "camera.yaml", "ros": "camera_info.yaml", "gyroflow": "lens.json"}[fmt]
    if fmt == "opencv":
        data = ", ".join(f"{v!r}" for row in matrix for v in row)
        path.write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
                        f"   rows: 3\n   cols: 3\n   dt: d\n   data: [ {data} ]\n")
    elif fmt == "ros":
        path.write_text(yaml.safe_dump({**ROS, "camera_matrix": {"rows": 3, "cols": 3,
                                                                  "data": [v for row in matrix for v in row]}}))
    else:
        path.write_text(json.dumps({"calib_dimension": {"w": 640, "h": 480}, "asymmetrical": True,
                                    "distortion_model": "opencv_standard",
                                    "fisheye_params": {"camera_matrix": matrix, "distortion_coeffs": [0] * 5}}))
    with pytest.raises(InputError, match=words) as error:
        load_camera(path)
    assert "\n" not in str(error.value) and str(path) in str(error.value)


# -- valid files that were refused ----------------------------------------------------------------------


def assert_is_the_camera(path: Path) -> None:
    read = load_camera(path)
    np.testing.assert_allclose(read.camera.params, CAMERA.params, rtol=0, atol=1e-12)
    assert (read.camera.width, read.camera.height) == (640, 480)


def test_a_ros_file_in_yaml_flow_style_is_read(tmp_path):
    path = tmp_path / "camera_info.yaml"
    path.write_text(yaml.safe_dump(ROS, default_flow_style=True))
    assert path.read_text().startswith("{")
    assert_is_the_camera(path)


def test_a_kalibr_camchain_written_as_json_is_read(tmp_path):
    for name in ("camchain.json", "camchain.yaml"):
        path = tmp_path / name
        path.write_text(json.dumps(KALIBR, indent=1))
        assert_is_the_camera(path)
        assert load_camera(path).source_format == "kalibr"


def test_a_hash_inside_an_mrcal_string_is_not_a_comment(tmp_path):
    path = tmp_path / "camera.cameramodel"
    path.write_text("# an mrcal model\n{\n    'lensmodel': 'LENSMODEL_OPENCV4', # the lens\n"
                    "    'intrinsics': [ 500, 501, 319.5, 239.5, -0.1, 0.05, 0.001, -0.002, ],\n"
                    "    'imagersize': [ 640, 480, ],\n    'note': 'board #3, take # 2',\n}\n")
    assert_is_the_camera(path)


@pytest.mark.parametrize("fmt", ["opencv", "kalibr", "ros", "mrcal", "colmap", "gyroflow"])
def test_a_file_name_with_a_newline_is_read_and_written(tmp_path, fmt):
    path = tmp_path / f"my\ncamera_{fmt}.{ {'mrcal': 'cameramodel', 'colmap': 'txt', 'gyroflow': 'json'}.get(fmt, 'yaml')}"
    write_camera(CAMERA, path, fmt)
    read = load_camera(path)
    np.testing.assert_allclose(read.camera.project(np.array([[0.1, -0.2, 1.0]])),
                               CAMERA.project(np.array([[0.1, -0.2, 1.0]])), atol=1e-9)


def test_errors_about_a_file_name_with_a_newline_stay_one_line(tmp_path):
    for name, reader in [("bad\nname.yaml", load_camera), ("bad\ntarget.yaml", load_target),
                         ("bad\njobs.csv", load_manifest)]:
        (tmp_path / name).write_text("foo: [1\n")
        with pytest.raises(InputError) as error:
            reader(tmp_path / name)
        assert "\n" not in str(error.value) and "bad\\n" in str(error.value)
    target = tmp_path / "board\n1.yaml"
    target.write_text(TARGET)
    assert load_target(target).num_points == 54


# -- the command line: exit 2 and one line ----------------------------------------------------------------


def test_the_cli_exits_2_with_one_line_for_an_alias_bomb_and_a_deep_file(tmp_path):
    bomb = tmp_path / "camchain.yaml"
    bomb.write_text(BILLION_LAUGHS + yaml.safe_dump(KALIBR))
    deep = tmp_path / "deep.yaml"
    deep.write_text("[" * DEEP + "]" * DEEP)
    for camera in (bomb, deep):
        done = subprocess.run([sys.executable, "-m", "rscalib", "simulate", "--out", str(tmp_path / "s"),
                               "--camera", str(camera), "--duration", "0.2", "--quiet"],
                              capture_output=True, text=True, timeout=60)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and str(camera) in lines[0], done.stderr[-1500:]


def test_nesting_limit_is_what_real_files_need():
    from rscalib.io.safe_parse import MAX_NESTING, nesting_depth

    assert MAX_NESTING >= 16
    real = [p for p in (Path(__file__).resolve().parents[4] / "shared" / "data").rglob("*.yaml")][:50] \
        if (Path(__file__).resolve().parents[4] / "shared" / "data").is_dir() else []
    for path in real:
        assert nesting_depth(path.read_text(errors="replace"), "yaml") <= MAX_NESTING, path
