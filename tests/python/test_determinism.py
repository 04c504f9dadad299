"""Determinism (issue 14): the same input and options give bit-identical result.json numbers across
runs, across `--workers 1` and `--workers 2` (linedelay's and intrinsics' detection processes), and across the
self-calibration bank's thread count. Inputs are small `rscalib simulate` renders; detection runs
with --no-cache so the second run recomputes. Only wall times and provenance (when, which command
line) may differ; every other leaf of result.json, numbers and texts, must be equal (floats with ==:
JSON keeps a float's every bit)."""
import json
import re
import subprocess
import sys

import numpy as np
import pytest

CLI = [sys.executable, "-m", "rscalib.cli"]
# Leaves that legitimately change from run to run: wall times and the provenance of the run.
VOLATILE = re.compile(r"(_time_s|elapsed_s|frames_per_s|\.provenance\.(command_line|created_utc))$")


def run(*args, ok=(0, 3), env=None):
    proc = subprocess.run(CLI + [str(a) for a in args], capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode in ok, proc.stderr
    return proc


def leaves(value, path=""):
    if isinstance(value, dict):
        for key, item in value.items():
            yield from leaves(item, f"{path}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from leaves(item, f"{path}[{i}]")
    else:
        yield path, value


def stable_leaves(folder):
    data = json.loads((folder / "result.json").read_text())
    return {path: value for path, value in leaves(data) if not VOLATILE.search(re.sub(r"\[\d+\]", "", path))}


def assert_identical(a, b, headline):
    first, second = stable_leaves(a), stable_leaves(b)
    assert first.keys() == second.keys()
    differ = [path for path in first if first[path] != second[path]]
    assert not differ, [(p, first[p], second[p]) for p in differ[:5]]
    floats = [p for p, v in first.items() if isinstance(v, float)]
    assert f".{headline}" in first and len(floats) >= 20   # the comparison covers the results


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    root = tmp_path_factory.mktemp("renders")
    run("simulate", "--out", root / "video", "--duration", "2.2", "--size", "320x240", "--supersample", "1",
        "--seed", "5", "--workers", "1", "--quiet", ok=(0,))
    run("simulate", "--led", "--flicker-hz", "100", "--out", root / "led", "--frames", "12", "--seed", "5", "--quiet",
        ok=(0,))
    run("simulate", "--scene", "--out", root / "scene", "--duration", "1.5", "--seed", "5", "--quiet", ok=(0,))
    run("simulate", "--out", root / "stills", "--line-delay", "0", "--duration", "2", "--fps", "5", "--supersample",
        "1", "--frames-dir", "--no-video", "--size", "320x240", "--seed", "5", "--quiet", ok=(0,))
    (root / "stills" / "frames" / "timestamps.txt").unlink()
    return root


def test_linedelay_identical_across_runs_and_worker_counts(renders, tmp_path):
    video = renders / "video"
    for workers in (1, 2):
        run("linedelay", video / "video.avi", "--target", video / "target.yaml", "--camera", video / "camera.yaml",
            "--out", tmp_path / f"w{workers}", "--workers", workers, "--no-cache", "--quiet")
    assert_identical(tmp_path / "w1", tmp_path / "w2", "line_delay_s")


def test_intrinsics_identical_across_worker_counts(renders, tmp_path):
    stills = renders / "stills"
    for workers in (1, 2):
        run("intrinsics", stills / "frames", "--target", stills / "target.yaml", "--out", tmp_path / f"w{workers}",
            "--workers", workers, "--no-cache", "--quiet", ok=(0, 3, 4))
    assert_identical(tmp_path / "w1", tmp_path / "w2", "parameters.fx")


@pytest.mark.parametrize("command", ["intrinsics", "selfcalib", "linedelay"])
def test_a_batch_jobs_thread_caps_change_no_number(renders, tmp_path, command):
    """A batch job runs its command with every thread pool capped at one (batch.runner.JOB_THREAD_ENV);
    the single command a user types runs with the machine's defaults. Both must give the same numbers
    (issue 33: intrinsics differed in 45 of 103 numbers, selfcalib in 66 of 5582)."""
    import os

    from rscalib.batch.runner import JOB_THREAD_ENV

    argv = {"intrinsics": ["intrinsics", renders / "stills" / "frames", "--target", renders / "stills" / "target.yaml",
                           "--no-cache"],
            "selfcalib": ["selfcalib", renders / "scene", "--pixel-size-mm", "0.0112", "--no-restarts"],
            "linedelay": ["linedelay", renders / "video" / "video.avi", "--target", renders / "video" / "target.yaml",
                          "--camera", renders / "video" / "camera.yaml", "--no-cache"]}[command]
    default_env = {k: v for k, v in os.environ.items() if k not in JOB_THREAD_ENV}
    run(*argv, "--out", tmp_path / "single", "--quiet", ok=(0, 3, 4), env=default_env)
    run(*argv, "--out", tmp_path / "job", "--quiet", ok=(0, 3, 4), env={**default_env, **JOB_THREAD_ENV})
    headline = {"intrinsics": "parameters.fx", "selfcalib": "f", "linedelay": "line_delay_s"}[command]
    assert_identical(tmp_path / "single", tmp_path / "job", headline)


def test_flicker_identical_across_runs(renders, tmp_path):
    for name in ("a", "b"):
        run("flicker", renders / "led", "--frequency", "100", "--out", tmp_path / name, "--quiet")
    assert_identical(tmp_path / "a", tmp_path / "b", "line_delay_s")


def test_selfcalib_identical_across_runs(renders, tmp_path):
    for name in ("a", "b"):
        run("selfcalib", renders / "scene", "--out", tmp_path / name, "--pixel-size-mm", "0.0112", "--no-restarts",
            "--quiet")
    assert_identical(tmp_path / "a", tmp_path / "b", "f")


def test_selfcalib_identical_across_bank_threads(renders):
    from rscalib.io.video import read_gray_frames
    from rscalib.selfcalib.engine import calibrate_frames, sog_options
    from rscalib.selfcalib.options import SelfCalibOptions

    video = read_gray_frames(renders / "scene")
    frames = list(video.frames)[:30]
    results = []
    for threads in (1, 2):
        options = sog_options(SelfCalibOptions())
        options.num_threads = threads
        results.append(calibrate_frames(frames, video.image_size, SelfCalibOptions(pixel_size_mm=0.0112, restarts=False),
                                        sog=options))
    one, two = results
    assert one.gaussians_left > 0 and len(one.history) == 30
    np.testing.assert_array_equal(one.mean, two.mean)
    np.testing.assert_array_equal(one.covariance, two.covariance)
    np.testing.assert_array_equal(one.history.mean, two.history.mean)
    np.testing.assert_array_equal(one.history.gaussians, two.history.gaussians)
