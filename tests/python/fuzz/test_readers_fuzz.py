"""Property tests of every file reader (issue #14): random bytes, and valid files with a field
mutated, truncated or spliced, give either a valid object or an InputError — never another
exception (a traceback for the user), never a NaN or an absurd size that passes.

Readers: target YAML (load_target, target_from_dict), camera files of every format (load_camera),
timestamps.txt (read_timestamps) and the batch manifest (load_manifest). Deterministic
(derandomize) and bounded (max_examples), a few seconds each.
"""
from __future__ import annotations

import math
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rscalib.batch.manifest import load_manifest
from rscalib.errors import InputError
from rscalib.io.camera_formats.common import MAX_ABS_LINE_DELAY_S, MAX_IMAGE_SIDE_PX
from rscalib.io.cameras import load_camera
from rscalib.io.targets import MAX_TARGET_POINTS, Target, load_target, target_from_dict
from rscalib.io.video import MAX_FRAME_INTERVAL_S, MIN_FRAME_INTERVAL_S, read_timestamps

FUZZ = settings(max_examples=400, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

# values a user (or a broken tool) puts in a field
NASTY = [".nan", ".inf", "-.inf", "-1", "0", "1e308", "1e-308", "2e9", "2000000000", "-320", "0.5", "320.5",
         "[1, 2]", "[]", "{a: 1}", "''", "\"abc\"", "abc", "true", "null", "~", "1e999", "9" * 30, "0x10", "[[1]]"]

VALID_FILES = {
    "target.yaml": "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.04\n"
                   "colSpacingMeters: 0.04\n",
    "circles.yaml": "target_type: circlegrid\ntargetCols: 4\ntargetRows: 11\nspacingMeters: 0.02\n"
                    "asymmetricGrid: true\n",
    "april.yaml": "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n",
    "charuco.yaml": "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareLength: 0.04\nmarkerLength: 0.03\n"
                    "dictionary: DICT_5X5_100\n",
    "opencv.yaml": "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
                   "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500., 0., 319.5, 0., 500., 239.5, 0., 0., 1. ]\n"
                   "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
                   "   data: [ -0.1, 0.05, 0., 0., 0. ]\nline_delay_s: 3e-05\n",
    "opencv.xml": "<?xml version=\"1.0\"?>\n<opencv_storage>\n<image_width>640</image_width>\n"
                  "<image_height>480</image_height>\n<camera_matrix type_id=\"opencv-matrix\"><rows>3</rows>"
                  "<cols>3</cols><dt>d</dt><data>500. 0. 319.5 0. 500. 239.5 0. 0. 1.</data></camera_matrix>\n"
                  "</opencv_storage>\n",
    "kalibr.yaml": "cam0:\n  camera_model: pinhole\n  intrinsics: [500.0, 500.0, 319.5, 239.5]\n"
                   "  distortion_model: radtan\n  distortion_coeffs: [-0.1, 0.05, 0.0, 0.0]\n"
                   "  resolution: [640, 480]\n  line_delay: 3.0e-05\n",
    "ros.yaml": "image_width: 640\nimage_height: 480\ncamera_name: c\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                "  data: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]\ndistortion_model: plumb_bob\n"
                "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.1, 0.05, 0, 0, 0]\n",
    "camera.cameramodel": "{\n 'lensmodel': 'LENSMODEL_OPENCV4',\n 'intrinsics': [ 500, 500, 319.5, 239.5, -0.1,"
                          " 0.05, 0, 0, ],\n 'imagersize': [ 640, 480 ],\n 'extrinsics': [0, 0, 0, 0, 0, 0],\n}\n",
    "cameras.txt": "# COLMAP\n1 OPENCV 640 480 500 500 320 240 -0.1 0.05 0 0\n",
    "lens.json": '{"calib_dimension": {"w": 640, "h": 480}, "distortion_model": "opencv_standard", '
                 '"asymmetrical": true, "frame_readout_time": 14.4, "fisheye_params": {"camera_matrix": '
                 '[[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]], "distortion_coeffs": [-0.1, 0.05, 0, 0, 0]}}\n',
}
TARGET_FILES = ("target.yaml", "circles.yaml", "april.yaml", "charuco.yaml")
CAMERA_FILES = ("opencv.yaml", "opencv.xml", "kalibr.yaml", "ros.yaml", "camera.cameramodel", "cameras.txt",
                "lens.json")


@pytest.fixture(scope="module")
def folder():
    with tempfile.TemporaryDirectory() as name:
        yield Path(name)


def mutated(text: str, data) -> str:
    """The text with one of: a number or word replaced by a nasty value, a cut, a splice of junk."""
    how = data.draw(st.sampled_from(["replace", "replace", "cut", "splice"]))
    if how == "cut":
        return text[:data.draw(st.integers(0, len(text)))]
    if how == "splice":
        at = data.draw(st.integers(0, len(text)))
        return text[:at] + data.draw(st.text(max_size=12)) + text[at:]
    import re

    tokens = list(re.finditer(r"-?[0-9][0-9.e+-]*|[A-Za-z_]+", text))
    if not tokens:
        return text + data.draw(st.sampled_from(NASTY))
    token = tokens[data.draw(st.integers(0, len(tokens) - 1))]
    return text[:token.start()] + data.draw(st.sampled_from(NASTY)) + text[token.end():]


def content(name: str, data):
    """Random bytes, or the named valid file mutated once or twice."""
    if data.draw(st.integers(0, 5)) == 0:
        return data.draw(st.binary(max_size=300))
    text = VALID_FILES[name]
    for _ in range(data.draw(st.integers(1, 2))):
        text = mutated(text, data)
    return text


def write(folder: Path, name: str, value) -> Path:
    path = folder / name
    if isinstance(value, bytes):
        path.write_bytes(value)
    else:
        path.write_text(value)
    return path


def check_target(target: Target) -> None:
    assert isinstance(target, Target)
    assert 0 < target.num_points <= MAX_TARGET_POINTS
    assert np.all(np.isfinite(target.points_m))


@FUZZ
@given(data=st.data())
def test_target_file_is_a_target_or_input_error(folder, data):
    name = data.draw(st.sampled_from(TARGET_FILES))
    path = write(folder, name, content(name, data))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unknown keys: a TargetFileWarning, not an error
        try:
            target = load_target(path)
        except InputError:
            return
    check_target(target)


FIELD_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 12, 10 ** 12), st.floats(),
                         st.text(max_size=8), st.lists(st.integers(-3, 3), max_size=3),
                         st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
TARGET_KEYS = ["target_type", "targetCols", "targetRows", "rowSpacingMeters", "colSpacingMeters", "spacingMeters",
               "asymmetricGrid", "tagCols", "tagRows", "tagSize", "tagSpacing", "squaresX", "squaresY",
               "squareLength", "markerLength", "dictionary", "legacyPattern"]


@FUZZ
@given(base=st.sampled_from(TARGET_FILES), changes=st.dictionaries(st.sampled_from(TARGET_KEYS), FIELD_VALUES,
                                                                   max_size=3))
def test_target_fields_of_any_type_are_a_target_or_input_error(base, changes):
    import yaml

    fields = {**yaml.safe_load(VALID_FILES[base]), **changes}
    try:
        target = target_from_dict(fields)
    except InputError:
        return
    check_target(target)


@FUZZ
@given(data=st.data())
def test_camera_file_is_a_camera_or_input_error(folder, data):
    name = data.draw(st.sampled_from(CAMERA_FILES))
    path = write(folder, name, content(name, data))
    try:
        loaded = load_camera(path)
    except InputError:
        return
    camera = loaded.camera
    assert 1 <= camera.width <= MAX_IMAGE_SIDE_PX and 1 <= camera.height <= MAX_IMAGE_SIDE_PX
    assert np.all(np.isfinite(camera.params)) and camera.params[0] > 0 and camera.params[1] > 0
    assert loaded.line_delay_s is None or (math.isfinite(loaded.line_delay_s)
                                           and abs(loaded.line_delay_s) <= MAX_ABS_LINE_DELAY_S)


TIME_TEXT = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-10 ** 20, 10 ** 20).map(str),
                      st.sampled_from(["nan", "inf", "", "# comment", "1,", "abc", "1e999", "0x1F"]))


@FUZZ
@given(scale=st.sampled_from([1.0, 1e3, 1e6, 1e9, 1e-4, 1e11, 1e300]), offset=st.sampled_from([0.0, 1.4e9, -5.0]),
       frames=st.integers(1, 12), junk=st.lists(st.tuples(st.integers(0, 11), TIME_TEXT), max_size=2))
def test_timestamps_are_seconds_or_input_error(folder, scale, offset, frames, junk):
    """Times at 30 fps in some unit (and sometimes a broken line): read as seconds at a plausible
    frame rate, or refused."""
    lines = [repr((offset + i / 30.0) * scale) for i in range(frames)]
    for where, text in junk:
        if where < len(lines):
            lines[where] = text
    path = write(folder, "timestamps.txt", "\n".join(lines) + "\n")
    notes: list = []
    try:
        times = read_timestamps(path, frames, notes)
    except InputError:
        return
    assert times.shape == (frames,) and np.all(np.isfinite(times))
    if frames > 1:
        assert np.all(np.diff(times) > 0)
        assert MIN_FRAME_INTERVAL_S <= np.median(np.diff(times)) <= MAX_FRAME_INTERVAL_S
    if not junk and frames > 1:  # a clean file of a 30 fps video: 1/30 s apart, whatever the unit
        assert np.median(np.diff(times)) == pytest.approx(1 / 30.0, rel=1e-6)


MANIFESTS = {
    "jobs.csv": "id,command,input,frequency,mode\na,flicker,frames,100,wide\nb,flicker,frames2,50,\n",
    "jobs.yaml": "defaults:\n  frequency: 100\njobs:\n  - command: flicker\n    input: frames\n    id: a\n"
                 "  - command: flicker\n    input: frames2\n    mode: wide\n",
}


@FUZZ
@given(data=st.data())
def test_manifest_is_jobs_or_input_error(folder, data):
    name = data.draw(st.sampled_from(sorted(MANIFESTS)))
    value = data.draw(st.binary(max_size=200)) if data.draw(st.integers(0, 5)) == 0 else \
        mutated(MANIFESTS[name], data)
    path = write(folder, name, value)
    try:
        jobs = load_manifest(path)
    except InputError:
        return
    assert jobs and all(job.argv and job.argv[0] in ("linedelay", "intrinsics", "flicker", "selfcalib")
                        for job in jobs)
    assert len({job.id for job in jobs}) == len(jobs)
