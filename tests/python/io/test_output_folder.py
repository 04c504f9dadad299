"""The output folder (issue #14): checked before any work starts, written as one set (result.json
last, the previous run's other files removed, files rscalib did not write kept), and a full disk
or a kill in the middle never leaves a result.json beside a partial set."""
import contextlib
import errno
import json
import os
import subprocess
from pathlib import Path

import pytest

from rscalib.cli import main
from rscalib.errors import InputError
from rscalib.io import output_folder
from rscalib.io.output_folder import LOCK, MANIFEST, check_output_folder, expected_output_bytes, output_set
from rscalib.io.results import write_result_json

MB = 1 << 20


@contextlib.contextmanager
def tmpfs(path: Path, options: str):
    """A tmpfs mounted at `path` (root only; skips the test elsewhere)."""
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)],
                                           capture_output=True).returncode != 0:
        pytest.skip("mounting a tmpfs needs root")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


# -- the check before any work --------------------------------------------------------------------------

def test_a_new_nested_folder_passes_and_nothing_is_created(tmp_path):
    out = tmp_path / "a" / "b" / "c"
    assert check_output_folder(out, 1 * MB) == out
    assert not (tmp_path / "a").exists()
    assert not list(tmp_path.iterdir())   # no probe left behind


@pytest.mark.parametrize("where, words", [("file", "is a file"), ("/dev/null", "not a folder"),
                                          ("/proc/rscalib-out", "proc file system"),
                                          ("/sys/rscalib-out", "sysfs file system"),
                                          ("under a file", "is a file"), ("dangling link", "a link to nothing"),
                                          ("", "empty")])
def test_places_that_cannot_hold_results_are_refused_in_one_line(tmp_path, where, words):
    (tmp_path / "f.txt").write_text("x")
    (tmp_path / "link").symlink_to(tmp_path / "nowhere")
    out = {"file": tmp_path / "f.txt", "under a file": tmp_path / "f.txt" / "out",
           "dangling link": tmp_path / "link"}.get(where, where)
    with pytest.raises(InputError) as error:
        check_output_folder(out)
    message = str(error.value)
    assert words in message and "\n" not in message
    if where:
        assert str(out) in message
    assert (tmp_path / "f.txt").read_text() == "x"


def test_a_read_only_file_system_is_refused(tmp_path):
    with tmpfs(tmp_path / "ro", "ro,size=1m") as ro:
        with pytest.raises(InputError, match="cannot write in .*Read-only file system"):
            check_output_folder(ro / "out")


def test_too_little_free_space_is_refused_with_the_numbers(tmp_path, monkeypatch):
    check_output_folder(tmp_path / "out", 16 * MB)
    real = output_folder.shutil.disk_usage
    monkeypatch.setattr(output_folder.shutil, "disk_usage",
                        lambda p: real(p)._replace(free=3 * MB))
    with pytest.raises(InputError, match=r"3\.0 MB free .* need about 16 MB"):
        check_output_folder(tmp_path / "out", 16 * MB)


def test_a_small_real_file_system_is_refused(tmp_path):
    with tmpfs(tmp_path / "small", "size=1m") as small:
        with pytest.raises(InputError, match="MB free"):
            check_output_folder(small / "out", expected_output_bytes(8))


def test_the_estimate_grows_with_the_input_and_ignores_nonsense(tmp_path):
    video = tmp_path / "v.bin"
    video.write_bytes(b"\0" * (10 * MB))
    assert expected_output_bytes(32, [video], per_input_byte=0.1) == 33 * MB
    assert expected_output_bytes(16, extra_bytes=float("inf")) == 16 * MB
    assert expected_output_bytes(16, extra_bytes=float("nan")) == 16 * MB
    assert expected_output_bytes(16, [tmp_path / "missing"], per_input_byte=1.0) == 16 * MB


# -- the set -------------------------------------------------------------------------------------------

def write_set(out: Path, names, marker="run"):
    """A run that writes `names` and result.json (through the real writer)."""
    with output_set(out) as staged:
        for name in names:
            (staged / name).write_text(f"{marker} {name}")
        write_result_json(staged, {"marker": marker}, command="test")


def test_a_second_run_replaces_the_first_as_a_set(tmp_path):
    out = tmp_path / "out"
    write_set(out, ["report.html", "knots_speed.png", "trajectory.csv"], "spline")
    (out / "notes.txt").write_text("mine")            # the user's own file
    write_set(out, ["report.html", "trajectory.csv"], "linear")
    assert sorted(p.name for p in out.iterdir()) == sorted([MANIFEST, LOCK, "notes.txt", "report.html",
                                                            "result.json", "trajectory.csv"])
    assert (out / "report.html").read_text() == "linear report.html"
    assert json.loads((out / "result.json").read_text())["marker"] == "linear"
    assert (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / MANIFEST).read_text())["files"] == ["report.html", "result.json", "trajectory.csv"]


def test_two_runs_into_one_folder_commit_one_after_the_other(tmp_path, monkeypatch):
    """Run A is held in the middle of moving its files into place; run B, finishing meanwhile, must
    wait for the folder's lock (it moves nothing until A is done), and the folder ends as B's whole
    set. Without the lock B's files would land between A's."""
    import threading

    out = tmp_path / "out"
    out.mkdir()
    a_moving, release = threading.Event(), threading.Event()
    moved = []   # (run, file name) in the order they were moved into `out`
    real_replace = os.replace

    def replace(source, target):
        if Path(target).parent != out:   # a write inside a staging folder, not a move into `out`
            return real_replace(source, target)
        run = threading.current_thread().name
        moved.append((run, Path(target).name))
        if run == "A" and not a_moving.is_set():
            a_moving.set()
            release.wait(timeout=30)
        return real_replace(source, target)

    monkeypatch.setattr(output_folder.os, "replace", replace)

    def run(name, files):
        with output_set(out) as staged:
            for f in files:
                (staged / f).write_text(f"{name} {f}")
            write_result_json(staged, {"marker": name}, command="test")

    a = threading.Thread(target=run, name="A", args=("A", [f"a{i}.txt" for i in range(20)] + ["shared.txt"]))
    b = threading.Thread(target=run, name="B", args=("B", [f"b{i}.txt" for i in range(20)] + ["shared.txt"]))
    a.start()
    assert a_moving.wait(timeout=30)
    b.start()
    b.join(timeout=1.0)   # B has staged its files and reached the commit by now
    assert b.is_alive() and not [name for run_, name in moved if run_ == "B"]
    release.set()
    a.join(timeout=30)
    b.join(timeout=30)
    runs = [run_ for run_, _ in moved]
    assert runs == sorted(runs)   # all of A's moves, then all of B's
    assert json.loads((out / "result.json").read_text())["marker"] == "B"
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [MANIFEST, LOCK, "result.json", "shared.txt"] + [f"b{i}.txt" for i in range(20)])
    assert (out / "shared.txt").read_text() == "B shared.txt"


def test_a_failed_run_leaves_the_previous_set_whole(tmp_path):
    out = tmp_path / "out"
    write_set(out, ["a.txt", "b.txt"], "first")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(RuntimeError):
        with output_set(out) as staged:
            (staged / "a.txt").write_text("second")
            raise RuntimeError("the solver broke")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before   # nor a staging folder


def test_a_full_disk_while_writing_is_one_line_and_no_result_json(tmp_path, monkeypatch):
    out = tmp_path / "out"
    with pytest.raises(InputError) as error:
        with output_set(out) as staged:
            (staged / "a.txt").write_text("x")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert str(error.value) == f"cannot write the outputs in {out}: No space left on device"
    assert sorted(p.name for p in out.iterdir()) == []


def test_a_really_full_disk(tmp_path):
    with tmpfs(tmp_path / "tiny", "size=256k") as tiny:
        out = tiny / "out"
        write_set(out, ["small.txt"], "first")
        with pytest.raises(InputError, match="No space left on device"):
            with output_set(out) as staged:
                (staged / "camera.yaml").write_text("x")
                (staged / "big.bin").write_bytes(b"\0" * (512 * 1024))
                write_result_json(staged, {"marker": "second"}, command="test")
        assert json.loads((out / "result.json").read_text())["marker"] == "first"
        assert not (out / "camera.yaml").exists()
        assert [p.name for p in out.iterdir() if p.name.startswith(".rscalib-staging")] == []


def test_a_kill_while_moving_the_files_in_leaves_no_result_json(tmp_path, monkeypatch):
    """The renames done in this process (as when the commit's helper cannot start) stopped half-way
    by an exception: no result.json until the next run finishes the set (test_output_kills.py has
    the kills of the real two-process commit)."""
    monkeypatch.setattr(output_folder, "_helper_argv", lambda out: ["/nonexistent/python"])
    out = tmp_path / "out"
    write_set(out, ["a.txt", "b.txt", "old_only.txt"], "first")
    real_replace, calls = os.replace, []

    def dies_on_the_second_move(src, dst):
        calls.append(dst)
        if len(calls) == 3:   # after the manifest and one file
            raise KeyboardInterrupt
        return real_replace(src, dst)

    monkeypatch.setattr(output_folder.os, "replace", dies_on_the_second_move)
    with pytest.raises(KeyboardInterrupt):
        write_set(out, ["a.txt", "b.txt"], "second")
    monkeypatch.setattr(output_folder.os, "replace", real_replace)
    assert not (out / "result.json").exists()      # the folder does not look complete
    write_set(out, ["c.txt"], "third")               # the next run still knows every file rscalib wrote
    assert sorted(p.name for p in out.iterdir()) == sorted([MANIFEST, LOCK, "c.txt", "result.json"])


def test_a_damaged_manifest_cannot_delete_outside_the_folder(tmp_path):
    out = tmp_path / "out"
    outside = tmp_path / "precious.txt"
    outside.write_text("keep")
    out.mkdir()
    (out / "sub").mkdir()
    (out / "sub" / "x").write_text("keep")
    (out / MANIFEST).write_text(json.dumps({"files": ["../precious.txt", str(outside), "sub/x", "..", ".", 5]}))
    write_set(out, ["a.txt"])
    assert outside.read_text() == "keep" and (out / "sub" / "x").read_text() == "keep"


def test_a_folder_of_the_user_in_the_way_is_refused_and_kept(tmp_path):
    out = tmp_path / "out"
    (out / "report.html").mkdir(parents=True)
    (out / "report.html" / "mine").write_text("keep")
    with pytest.raises(InputError, match="did not write"):
        write_set(out, ["report.html"])
    assert (out / "report.html" / "mine").read_text() == "keep"


def test_staging_of_a_killed_run_is_cleared(tmp_path):
    out = tmp_path / "out"
    stale = out / ".rscalib-staging-999999999-abc"   # a pid above Linux's pid_max: no such process
    stale.mkdir(parents=True)
    (stale / "half.png").write_text("x")
    write_set(out, ["a.txt"])
    assert not stale.exists()


# -- every command with --out checks it before any work --------------------------------------------------

COMMANDS = ["linedelay", "linear", "localize", "flicker", "selfcalib", "intrinsics", "simulate", "simulate --led",
            "simulate --scene", "demo", "batch"]


def commands(tmp: Path, out: str) -> dict:
    video, target, camera = tmp / "video.avi", tmp / "target.yaml", tmp / "camera.yaml"
    for path in (video, camera):
        path.write_text("not read: the output check comes first")
    target.write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.03\n"
                      "colSpacingMeters: 0.03\n")
    common = [str(video), "--target", str(target), "--camera", str(camera), "--out", out, "--quiet"]
    return {"linedelay": ["linedelay", *common], "linear": ["linedelay", *common, "--trajectory", "linear"],
            "localize": ["localize", *common], "flicker": ["flicker", str(video), "--frequency", "100", "--out", out],
            "selfcalib": ["selfcalib", str(video), "--out", out],
            "intrinsics": ["intrinsics", str(video), "--target", str(target), "--out", out],
            "simulate": ["simulate", "--out", out, "--quiet"], "simulate --led": ["simulate", "--led", "--flicker-hz",
                                                                                  "100", "--out", out, "--quiet"],
            "simulate --scene": ["simulate", "--scene", "--out", out, "--quiet"], "demo": ["demo", "--out", out],
            "batch": ["batch", str(video), "--out", out]}


@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize("bad", ["file", "/dev/null", "/proc/rscalib-out"])
def test_every_command_refuses_a_bad_out_before_any_work(tmp_path, capsys, name, bad):
    (tmp_path / "existing.txt").write_text("x")
    out = str(tmp_path / "existing.txt") if bad == "file" else bad
    assert main(commands(tmp_path, out)[name]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--out" in err and out in err and "Traceback" not in err, err
    assert (tmp_path / "existing.txt").read_text() == "x"
