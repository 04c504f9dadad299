"""Every public function refuses arguments that mean nothing (issue 33): rscalib.InputError, one line,
naming the argument (or, for a path that does not exist, the path), before any work. The table of
arguments and checks is docs/reliability.md, "Public function arguments"; the checks are in
rscalib/checks.py, shared with the CLI's converters.

Each case calls the function once with one bad argument, the others valid (or valid enough that
the bad one is reached first). Sizes that cannot be held are tried in a child process under an
address-space limit, so that the code before the checks fails with MemoryError instead of taking
the machine's memory."""
from __future__ import annotations

import math
import resource
import subprocess
import sys
import warnings

import numpy as np
import pytest

import rscalib

NAN, INF = math.nan, math.inf
MISSING = "/nonexistent/rscalib-test/missing"
CAMERA = rscalib.CameraModel("pinhole-radtan", [500.0, 500.0, 320.0, 240.0, 0, 0, 0, 0, 0], 640, 480)
TARGET = rscalib.Target.named("checkerboard")
IMAGE = np.zeros((48, 64), np.uint8)
FRAMES = np.zeros((5, 48, 64))


def observations(**changed):
    fields = dict(frame_times_s=[0.0, 1 / 30], frame_index=[0, 1], point_id=[0, 1], uv=[[1.0, 2.0], [3.0, 4.0]],
                  target_points=TARGET.points_m, image_size=(640, 480))
    fields.update(changed)
    return rscalib.Observations(**fields)


def pose_spline():
    return rscalib.BSpline.uniform(0.0, 1.0, 4, 6)


OBS = observations()

# (function, argument, call, words one of which the message must hold: the argument's name by default)
CASES = [
    # the front doors
    ("calibrate_video", "video", lambda: rscalib.calibrate_video(42, TARGET, CAMERA), None),
    ("calibrate_video", "video", lambda: rscalib.calibrate_video(MISSING, TARGET, CAMERA), None),
    ("calibrate_video", "target", lambda: rscalib.calibrate_video(MISSING, 42, CAMERA), None),
    ("calibrate_video", "camera", lambda: rscalib.calibrate_video(OBS, None, 42), None),
    ("calibrate_video", "camera", lambda: rscalib.calibrate_video(OBS, None, MISSING), None),
    ("calibrate_video", "options", lambda: rscalib.calibrate_video(OBS, None, CAMERA, {"rows": 5}), None),
    ("calibrate_video", "progress", lambda: rscalib.calibrate_video(OBS, None, CAMERA, progress="yes"), None),
    ("calibrate_video", "on_round", lambda: rscalib.calibrate_video(OBS, None, CAMERA, on_round=5), None),
    ("calibrate_video", "on_detection", lambda: rscalib.calibrate_video(OBS, None, CAMERA, on_detection=5), None),
    ("localize_video", "line_delay_s", lambda: rscalib.localize_video(OBS, None, CAMERA, NAN), None),
    ("localize_video", "line_delay_s", lambda: rscalib.localize_video(OBS, None, CAMERA, 1.0), None),
    ("localize_video", "line_delay_s", lambda: rscalib.localize_video(OBS, None, CAMERA, "30us"), None),
    ("localize_video", "options",
     lambda: rscalib.localize_video(OBS, None, CAMERA, 3e-5, rscalib.LineDelayOptions()), None),
    ("self_calibrate", "source", lambda: rscalib.self_calibrate(42), None),
    ("self_calibrate", "source", lambda: rscalib.self_calibrate(MISSING), [MISSING]),
    ("self_calibrate", "options", lambda: rscalib.self_calibrate(MISSING, {"pixel_size_mm": 0.01}), None),
    ("self_calibrate", "on_frame", lambda: rscalib.self_calibrate(MISSING, on_frame=3), None),
    ("track_features", "frames", lambda: rscalib.track_features(42), None),
    ("track_features", "frames", lambda: rscalib.track_features([]), None),
    ("track_features", "frames", lambda: rscalib.track_features([(NAN, IMAGE), (1.0, IMAGE)]), None),
    ("track_features", "frames", lambda: rscalib.track_features([("a", IMAGE), (1.0, IMAGE)]), None),
    ("track_features", "frames", lambda: rscalib.track_features([(0.0, IMAGE), (0.0, IMAGE)]), None),
    ("track_features", "frames", lambda: rscalib.track_features([(0.0, IMAGE.astype(float)), (1.0, IMAGE)]), None),
    ("track_features", "options", lambda: rscalib.track_features([(0.0, IMAGE), (1.0, IMAGE)], {"x": 1}), None),
    ("track_features", "frame_count",
     lambda: rscalib.track_features([(0.0, IMAGE), (1.0, IMAGE)], frame_count=-5), None),
    ("estimate_line_delay_flicker", "frequency_hz", lambda: rscalib.estimate_line_delay_flicker(FRAMES, NAN), None),
    ("estimate_line_delay_flicker", "frequency_hz", lambda: rscalib.estimate_line_delay_flicker(FRAMES, 1e300),
     None),
    ("estimate_line_delay_flicker", "frequency_hz", lambda: rscalib.estimate_line_delay_flicker(FRAMES, True), None),
    ("estimate_line_delay_flicker", "source", lambda: rscalib.estimate_line_delay_flicker(42, 100.0), None),
    ("estimate_line_delay_flicker", "source",
     lambda: rscalib.estimate_line_delay_flicker(np.zeros((0, 48, 64)), 100.0), None),
    ("estimate_line_delay_flicker", "source",
     lambda: rscalib.estimate_line_delay_flicker(np.full((5, 48, 64), NAN), 100.0), None),
    ("estimate_line_delay_flicker", "source", lambda: rscalib.estimate_line_delay_flicker(MISSING, 100.0),
     [MISSING]),
    ("estimate_line_delay_flicker", "timestamps_s",
     lambda: rscalib.estimate_line_delay_flicker(FRAMES, 100.0, timestamps_s=[0, 1, NAN, 3, 4]), None),
    ("estimate_line_delay_flicker", "timestamps_s",
     lambda: rscalib.estimate_line_delay_flicker(FRAMES, 100.0, timestamps_s=[0, 1, 2]), None),
    ("estimate_line_delay_flicker", "timestamps_s",
     lambda: rscalib.estimate_line_delay_flicker(FRAMES, 100.0, timestamps_s=[0, 1, 1, 3, 4]), None),
    ("estimate_line_delay_flicker", "timestamps_s",
     lambda: rscalib.estimate_line_delay_flicker(FRAMES, 100.0, timestamps_s="abc"), None),
    ("calibrate_intrinsics", "source", lambda: rscalib.calibrate_intrinsics(42, TARGET), None),
    ("calibrate_intrinsics", "source", lambda: rscalib.calibrate_intrinsics([], TARGET), None),
    ("calibrate_intrinsics", "source", lambda: rscalib.calibrate_intrinsics(MISSING, TARGET), [MISSING]),
    ("calibrate_intrinsics", "target", lambda: rscalib.calibrate_intrinsics(MISSING, 42), None),
    ("calibrate_intrinsics", "options", lambda: rscalib.calibrate_intrinsics(MISSING, TARGET, {"a": 1}), None),
    # detection and its options (the cases by name)
    ("detect_video", "source", lambda: rscalib.detect_video(42, TARGET), None),
    ("detect_video", "source", lambda: rscalib.detect_video([None], TARGET), None),
    ("detect_video", "source", lambda: rscalib.detect_video(MISSING, TARGET), [MISSING]),
    ("detect_video", "target", lambda: rscalib.detect_video(MISSING, 42), None),
    ("detect_video", "options", lambda: rscalib.detect_video(MISSING, TARGET, {"workers": 1}), None),
    ("detect_video", "workers",
     lambda: rscalib.detect_video(MISSING, TARGET, rscalib.DetectOptions(workers=-1)), None),
    ("DetectOptions", "full_detection_every", lambda: rscalib.DetectOptions(full_detection_every=0), None),
    ("DetectOptions", "full_detection_every", lambda: rscalib.DetectOptions(full_detection_every=10 ** 9), None),
    ("DetectOptions", "min_points", lambda: rscalib.DetectOptions(min_points=-3), None),
    ("DetectOptions", "max_residual", lambda: rscalib.DetectOptions(max_residual=NAN), None),
    ("DetectOptions", "max_search_side_px", lambda: rscalib.DetectOptions(max_search_side_px=0), None),
    ("DetectOptions", "max_blur_px", lambda: rscalib.DetectOptions(max_blur_px=INF), None),
    ("LineDelayOptions", "rows", lambda: rscalib.LineDelayOptions(rows=10 ** 12), None),
    ("LineDelayOptions", "rows", lambda: rscalib.LineDelayOptions(rows=1e12), None),
    ("LocalizeOptions", "rows", lambda: rscalib.LocalizeOptions(rows=10 ** 12), None),
    ("FlickerOptions", "rows", lambda: rscalib.FlickerOptions(rows=1e12), None),
    # files
    ("load_camera", "path", lambda: rscalib.load_camera(42), None),
    ("load_camera", "path", lambda: rscalib.load_camera(None), None),
    ("load_camera", "path", lambda: rscalib.load_camera("/"), ["folder"]),
    ("load_camera", "path", lambda: rscalib.load_camera(MISSING), [MISSING]),
    ("load_target", "path", lambda: rscalib.load_target(None), None),
    ("load_target", "path", lambda: rscalib.load_target("/"), ["folder"]),
    ("write_camera", "camera", lambda: rscalib.write_camera("camera", MISSING), None),
    ("write_camera", "path", lambda: rscalib.write_camera(CAMERA, 42), None),
    ("write_camera", "path", lambda: rscalib.write_camera(CAMERA, MISSING + "/camera.yaml"), None),
    ("write_camera", "path", lambda: rscalib.write_camera(CAMERA, "/"), None),
    ("write_camera", "line_delay_s", lambda: rscalib.write_camera(CAMERA, "/tmp/x.yaml", line_delay_s=NAN), None),
    ("write_camera", "line_delay_s", lambda: rscalib.write_camera(CAMERA, "/tmp/x.yaml", line_delay_s=1.0), None),
    ("open_source", "source", lambda: rscalib.open_source(42), None),
    ("open_source", "source", lambda: rscalib.open_source(None), None),
    ("open_source", "source", lambda: rscalib.open_source([]), None),
    ("read_gray_frames", "source", lambda: rscalib.read_gray_frames(42), None),
    # data
    ("Observations", "frame_times_s", lambda: observations(frame_times_s=[NAN, 1.0]), None),
    ("Observations", "frame_times_s", lambda: observations(frame_times_s=[0.0, INF]), None),
    ("Observations", "target_points", lambda: observations(target_points=np.full((54, 3), NAN)), None),
    ("Observations", "image_size", lambda: observations(image_size=(0, 480)), None),
    ("Observations", "image_size", lambda: observations(image_size=(10 ** 9, 10 ** 9)), None),
    ("Observations", "image_size", lambda: observations(image_size="640x480"), None),
    ("Observations", "frame_index", lambda: observations(frame_index=[0.5, 1.0]), None),
    ("Observations", "uv", lambda: observations(uv=[[1, 2, 3], [4, 5, 6]]), None),
    ("Observations", "uv", lambda: observations(uv=[[NAN, 2], [4, 5]]), None),
    # the C++ core
    ("CameraModel", "params",
     lambda: rscalib.CameraModel("pinhole-radtan", [NAN, 500.0, 320.0, 240.0, 0, 0, 0, 0, 0], 640, 480), None),
    ("CameraModel", "width",
     lambda: rscalib.CameraModel("pinhole-radtan", [500.0, 500.0, 320.0, 240.0], 10 ** 7, 480), None),
    ("CameraModel", "params", lambda: rscalib.CameraModel("pinhole-radtan", [500.0, 500.0], 640, 480),
     ["parameters"]),
    ("poses_at", "times", lambda: rscalib.poses_at(pose_spline(), [0.5, NAN]), ["time"]),
    ("poses_at", "pose_spline", lambda: rscalib.poses_at(rscalib.BSpline.uniform(0, 1, 4, 3), [0.5]),
     ["pose spline"]),
    ("fit_bspline", "times", lambda: rscalib.fit_bspline(list(pose_spline().knots), [0.1, NAN], np.zeros((2, 6))),
     ["time"]),
    ("fit_bspline", "samples",
     lambda: rscalib.fit_bspline(list(pose_spline().knots), [0.1, 0.2], np.full((2, 6), NAN)), ["samples must"]),
    ("rotation_vector_to_matrix", "rotation_vector", lambda: rscalib.rotation_vector_to_matrix([INF, 0, 0]), None),
    ("rotation_matrix_to_vector", "rotation", lambda: rscalib.rotation_matrix_to_vector(2 * np.eye(3)), None),
    ("rotation_matrix_to_vector", "rotation", lambda: rscalib.rotation_matrix_to_vector(np.diag([1.0, 1, -1])),
     None),
    ("unwrap_rotation_vectors", "rotation_vectors",
     lambda: rscalib.unwrap_rotation_vectors(np.full((3, 3), INF)), None),
]


@pytest.mark.parametrize("function, argument, call, words", CASES,
                         ids=[f"{c[0]}-{c[1]}-{k}" for k, c in enumerate(CASES)])
def test_public_functions_refuse_bad_arguments(function, argument, call, words):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(rscalib.InputError) as error:
            call()
    message = str(error.value)
    assert "\n" not in message
    assert any(word in message for word in (words or [argument])), (argument, message)


# Sizes that cannot be held: refused from the count, before the memory is asked for. The times are a
# broadcast array (8 bytes in all), so only the function itself could allocate.
HUGE = {
    "poses_at": "rscalib.poses_at(rscalib.BSpline.uniform(0.0, 1.0, 4, 6), np.broadcast_to(0.5, (3 * 10 ** 8,)))",
    "BSpline.evaluate": "rscalib.BSpline.uniform(0.0, 1.0, 4, 6).evaluate(np.broadcast_to(0.5, (10 ** 9,)))",
}
CHILD_ADDRESS_SPACE_BYTES = 3 << 30


@pytest.mark.parametrize("function", sorted(HUGE))
def test_sizes_that_cannot_be_held_are_refused_before_allocating(function):
    result = subprocess.run([sys.executable, __file__, HUGE[function]], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]
    assert result.stdout.startswith("InputError: ") and "times" in result.stdout, result.stdout
    assert "GB" in result.stdout   # with the number


def test_unknown_rotations_stay_unknown():
    """NaN is the library's own "no pose" (a frame PnP failed on): the rotation helpers pass it through."""
    assert np.all(np.isnan(rscalib.rotation_vector_to_matrix([NAN, 0, 0])))
    unwrapped = rscalib.unwrap_rotation_vectors(np.array([[0, 0, 3.0], [NAN, NAN, NAN], [0, 0, -3.0]]))
    assert np.all(np.isnan(unwrapped[1])) and unwrapped[2, 2] == -3.0


def test_valid_values_still_pass():
    """The checks refuse only what means nothing: the edges of each range are accepted."""
    assert rscalib.DetectOptions(full_detection_every=1, min_points=1, workers=1).full_detection_every == 1
    assert rscalib.LineDelayOptions(rows=100_000).rows == 100_000
    assert rscalib.FlickerOptions(rows=1e3).rows == 1000
    assert observations(frame_index=np.array([0.0, 1.0])).frame_index.dtype == np.int64
    assert observations(uv=np.zeros((0, 2)), frame_index=[], point_id=[]).num_observations == 0
    rotation = rscalib.rotation_vector_to_matrix([0.1, -0.2, 0.3])
    np.testing.assert_allclose(rscalib.rotation_matrix_to_vector(rotation).ravel(), [0.1, -0.2, 0.3], atol=1e-12)


def _child(expression: str) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_ADDRESS_SPACE_BYTES, CHILD_ADDRESS_SPACE_BYTES))
    try:
        eval(expression, {"rscalib": rscalib, "np": np})
        print("returned")
    except rscalib.InputError as error:
        print(f"InputError: {error}")
    except MemoryError as error:
        print(f"MemoryError: {error}")


if __name__ == "__main__":
    _child(sys.argv[1])
