"""Interrupts and the CLI's last line of defence (issue #14).

`rscalib linedelay` on a small rendered video (long enough for the workers to decode their own segments
of it) is stopped in the middle of detection by SIGTERM,
Ctrl-C (SIGINT to the process group, as a terminal sends it) or SIGKILL: the exit code is 143 / 130
(SIGKILL: the kernel's), no traceback is printed, no detection worker survives (read from /proc),
and no result.json is written. In process: any exception becomes one line and an exit code."""
from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import rscalib
import rscalib.cli.flicker
from rscalib.cli import main

# the folder holding the rscalib this test imported (the installed package in CI, python/ when developing):
# a child process must run the same code, and the source tree has no built _core
PYTHON_DIR = Path(rscalib.__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def rscalib_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(PYTHON_DIR) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("RSCALIB_DEBUG", None)
    return env


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    # 11 s, 330 frames: at least 4 runs of 40 frames per worker, so the workers decode their own segments
    subprocess.run([sys.executable, "-m", "rscalib", "simulate", "--out", str(out), "--duration", "11",
                    "--supersample", "1", "--quiet"], check=True, env=rscalib_env(), timeout=300)
    return out


def children(pid: int) -> list[int]:
    """Processes whose parent is `pid` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat[stat.rindex(")") + 2:].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def running(pid: int) -> bool:
    """Alive and not a zombie (an exited orphan nobody has reaped yet is gone for our purpose)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def start_linedelay(video: Path, out: Path, logs: Path, quiet: bool = True) -> subprocess.Popen:
    """`rscalib linedelay` with 2 detection workers and no cache; output to files (a surviving
    worker holding a pipe would hang the test instead of failing it)."""
    argv = [sys.executable, "-m", "rscalib", "linedelay", str(video / "video.avi"), "--target",
            str(video / "target.yaml"), "--camera", str(video / "camera.yaml"), "--out", str(out), "--no-cache",
            "--workers", "2"] + (["--quiet"] if quiet else [])
    # A shell starts background jobs with SIGINT ignored, and an ignored signal stays ignored across
    # exec (Python then installs no KeyboardInterrupt handler): give the child the default, as a
    # terminal's foreground job has, whatever this test process inherited.
    inherited = signal.getsignal(signal.SIGINT)
    if inherited == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return subprocess.Popen(argv, stdout=open(logs / "stdout", "w"), stderr=open(logs / "stderr", "w"),
                                env=rscalib_env(), start_new_session=True)
    finally:
        if inherited == signal.SIG_IGN:
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def wait_for_workers(process: subprocess.Popen, count: int = 2, timeout_s: float = 120.0) -> list[int]:
    """The spawned processes of `process` once `count` detection workers run (plus the resource tracker)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        kids = children(process.pid)
        workers = [k for k in kids if b"spawn_main" in Path(f"/proc/{k}/cmdline").read_bytes()]
        if len(workers) >= count:
            return kids
        assert process.poll() is None, "rscalib ended before its workers started"
        time.sleep(0.05)
    raise AssertionError("the detection workers did not start")


def survivors(pids: list[int], within_s: float) -> list[int]:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline and any(running(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if running(p)]


def test_the_video_is_detected_in_worker_segments(video):
    """The interrupts below hit workers that decode their own segments (issue 17), not only the
    frames-shipped path."""
    import cv2

    from rscalib.detection.options import DetectOptions
    from rscalib.detection.pipeline import segment_plan
    from rscalib.detection.tracking import run_length
    from rscalib.io.targets import load_target

    capture = cv2.VideoCapture(str(video / "video.avi"))
    frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    capture.release()
    assert segment_plan(frames, 2, run_length(load_target(video / "target.yaml"), DetectOptions())) is not None


@pytest.mark.parametrize("how, exit_code, last_line", [("SIGTERM", 143, "rscalib: terminated"),
                                                       ("Ctrl-C", 130, "rscalib: interrupted"),
                                                       ("SIGKILL", -signal.SIGKILL, None)])
def test_a_run_stopped_in_detection_takes_its_workers_and_writes_nothing(video, tmp_path, how, exit_code, last_line):
    out = tmp_path / "out"
    process = start_linedelay(video, out, tmp_path)
    spawned = []
    try:
        spawned = wait_for_workers(process)
        time.sleep(0.3)   # detection under way
        if how == "Ctrl-C":
            os.killpg(process.pid, signal.SIGINT)   # a terminal sends it to the whole group
        else:
            process.send_signal(getattr(signal, how))
        assert process.wait(timeout=30) == exit_code
        assert survivors(spawned, within_s=3.0) == []
    finally:
        for pid in [process.pid, *spawned]:   # never leave our own processes behind, even when failing
            if running(pid):
                os.kill(pid, signal.SIGKILL)
    err = (tmp_path / "stderr").read_text()
    assert "Traceback" not in err, err
    if last_line is not None:
        assert err.strip().splitlines()[-1] == last_line
    assert not (out / "result.json").exists()


def test_sigterm_during_the_solve_is_exit_143_and_writes_nothing(video, tmp_path):
    out = tmp_path / "out"
    process = start_linedelay(video, out, tmp_path, quiet=False)
    try:
        deadline = time.monotonic() + 300
        while "estimating trajectory" not in (tmp_path / "stderr").read_text():   # detection is over
            assert process.poll() is None and time.monotonic() < deadline, (tmp_path / "stderr").read_text()
            time.sleep(0.05)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 143
    finally:
        if running(process.pid):
            os.kill(process.pid, signal.SIGKILL)
    err = (tmp_path / "stderr").read_text()
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "rscalib: terminated", err
    assert not (out / "result.json").exists()


# -- the last line of defence, in process ------------------------------------------------------------------

def failing_with(monkeypatch, error: BaseException) -> list[str]:
    def run(args):
        raise error
    monkeypatch.setattr(rscalib.cli.flicker, "run", run)
    return ["flicker", "in.avi", "--frequency", "100", "--out", "o"]


@pytest.mark.parametrize("error, code, words", [
    (RuntimeError("solver state\nbroken"), 1, "internal error: RuntimeError: solver state broken (set RSCALIB_DEBUG=1"),
    (MemoryError(), 2, "error: out of memory: the input or options need more memory"),
    (OSError(errno.EACCES, "Permission denied", "/data/x.png"), 2, "error: /data/x.png: Permission denied"),
    (OSError(errno.ENOSPC, "No space left on device"), 2, "error: No space left on device"),
    (KeyboardInterrupt(), 130, "rscalib: interrupted"),
])
def test_every_error_is_one_line_and_an_exit_code(monkeypatch, capsys, error, code, words):
    monkeypatch.delenv("RSCALIB_DEBUG", raising=False)
    assert main(failing_with(monkeypatch, error)) == code
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and words in err and "Traceback" not in err, err


def test_rscalib_debug_shows_the_traceback(monkeypatch):
    monkeypatch.setenv("RSCALIB_DEBUG", "1")
    with pytest.raises(RuntimeError, match="broken"):
        main(failing_with(monkeypatch, RuntimeError("broken")))


def test_sigterm_in_process_is_exit_143_and_the_handler_is_restored(monkeypatch, capsys):
    def run(args):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)   # the handler interrupts this
        return 0
    monkeypatch.setattr(rscalib.cli.flicker, "run", run)
    before = signal.getsignal(signal.SIGTERM)
    assert main(["flicker", "in.avi", "--frequency", "100", "--out", "o"]) == 143
    assert capsys.readouterr().err.strip() == "rscalib: terminated"
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_full_disk_in_the_writer_is_exit_2_and_the_previous_result_stays(tmp_path, monkeypatch, capsys):
    """A real `rscalib flicker` run whose result.json write fails with ENOSPC: exit 2 naming the
    folder, and the previous run's result.json and plot are still there, unchanged."""
    frames = tmp_path / "led"
    assert main(["simulate", "--led", "--flicker-hz", "1000", "--frames", "4", "--size", "160x120",
                 "--out", str(frames), "--quiet"]) == 0
    out = tmp_path / "result"
    assert main(["flicker", str(frames), "--frequency", "1000", "--out", str(out), "--quiet"]) in (0, 3)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "result.json" in before and "flicker.png" in before
    capsys.readouterr()

    import rscalib.flicker.report as report

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(report, "write_result_json", full_disk)
    assert main(["flicker", str(frames), "--frequency", "1000", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"rscalib flicker: error: cannot write the outputs in {out}: No space left on device"
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
