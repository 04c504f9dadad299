"""The output set against a kill at every instant, and against a run whose inputs live in its
--out (issue 33).

The kill test forks a child per file operation of a run that replaces a previous set. The commit
runs in two processes (the command, then the helper that carries the plan out, io/_commit.py);
both count their file operations (os.replace, unlink, rmdir, mkdir, open, write, fsync) in one
counter, and at the k-th one a signal is sent:

- to the command (SIGINT, SIGTERM, SIGKILL): the folder must hold the previous set or the new one,
  whole, as it is (the helper, in a session of its own, finishes the renames);
- to the helper alone (SIGKILL): the command finishes the renames itself: old or new, whole;
- to both (SIGKILL: a power cut, or the whole cgroup killed): the renames may stop half-way; then
  the folder shows no result.json, and the next run (or recover_output_folder) completes the new
  set from the plan before anything else.

The user's file in the folder is never touched.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rscalib.errors import InputError
from rscalib.io import output_folder
from rscalib.io.output_folder import MANIFEST, check_output_folder, output_set
from rscalib.io.results import write_result_json

JOURNAL = ".rscalib-commit.json"   # output_folder.JOURNAL: the plan of a commit under way


def recover_output_folder(out):
    from rscalib.io.output_folder import recover_output_folder

    return recover_output_folder(out)

OLD = {"a.txt": "old a", "b.txt": "old b", "old_only.txt": "old only"}
NEW = {"a.txt": "new a", "b.txt": "new b", "new_only.txt": "new only", "sub": None}   # sub: a folder
COUNTED = ("replace", "rename", "unlink", "rmdir", "mkdir", "open", "write", "fsync")


def write_set(out: Path, files: dict, marker: str, **options) -> None:
    with output_set(out, **options) as staged:
        for name, text in files.items():
            if text is None:
                (staged / name).mkdir()
                (staged / name / "inside.txt").write_text(marker)
            else:
                (staged / name).write_text(text)
        write_result_json(staged, {"marker": marker}, command="test")


def visible(out: Path) -> dict:
    """What a reader of the folder sees: every file but rscalib's hidden ones and the user's."""
    seen = {}
    for p in sorted(out.iterdir()):
        if p.name.startswith(".rscalib") or p.name == "notes.txt":
            continue
        seen[p.name] = ("dir " + (p / "inside.txt").read_text()) if p.is_dir() else p.read_text()
    return seen


def expected(files: dict, marker: str) -> dict:
    seen = {n: (f"dir {marker}" if t is None else t) for n, t in files.items()}
    return {**seen, "result.json": marker}


def seen_with_marker(out: Path) -> dict:
    seen = visible(out)
    if "result.json" in seen:
        seen["result.json"] = json.loads(seen["result.json"])["marker"]
    return seen


# Run as the commit's helper instead of _commit.py: the same file, with its file operations counted in
# the shared counter and the signal sent at the chosen one (to the command, to itself, or to both).
HELPER_WRAPPER = """
import os, runpy, signal, sys, time
counter, step, signum, target = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
open(counter + ".helper", "w").write(str(os.getpid()))
def counted(function):
    def wrapper(*args, **kwargs):
        n = int(open(counter).read() or 0) + 1
        open(counter, "w").write(str(n))
        if n == step:
            if target in ("command", "both"):
                os.kill(os.getppid(), signum)
                time.sleep(0.05)   # the command is gone (or holds the signal) before the next step
            if target in ("helper", "both"):
                os.kill(os.getpid(), signum)
        return function(*args, **kwargs)
    return wrapper
for name in COUNTED:
    setattr(os, name, counted(getattr(os, name)))
sys.argv = sys.argv[5:]
runpy.run_path(sys.argv[0], run_name="__main__")
""".replace("COUNTED", repr(COUNTED))


@pytest.fixture(autouse=True)
def _ctrl_c_as_at_a_terminal():
    """Ctrl-C raises KeyboardInterrupt here and in the forked command, as at a terminal, even when
    pytest was started in the background of a script (SIGINT then arrives ignored, and Python
    keeps it so)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _gone(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[-1].startswith(("Z", "X"))
    except OSError:
        return True


def run_killed_at(out: Path, step: int, signum: int, target: str = "command") -> tuple:
    """Fork; the child (the command) replaces the set in `out`; at the `step`-th file operation of
    the command and its helper, `signum` goes to `target` (command, helper, both). Waits for both.
    Returns (the command's exit status, the operations counted)."""
    counter = out.parent / f"{out.name}.operations"
    counter.write_text("0")
    (out.parent / f"{out.name}.operations.helper").unlink(missing_ok=True)
    pid = os.fork()
    if pid == 0:   # the command: nothing here may return into pytest
        status = 0
        try:
            def counted(function):
                def wrapper(*args, **kwargs):
                    n = int(counter.read_text() or 0) + 1
                    counter.write_text(str(n))
                    if n == step and target in ("command", "both"):
                        os.kill(os.getpid(), signum)
                    return function(*args, **kwargs)
                return wrapper

            # the CLI's SIGTERM handler (cli._sigterm_raises): a Python exception, not the default death
            signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(143)))
            output_folder._helper_argv = lambda folder: [sys.executable, "-I", "-S", "-c", HELPER_WRAPPER, str(counter),
                                                         str(step), str(int(signum)), target,
                                                         output_folder.commit_steps.__file__, str(folder)]
            for name in COUNTED:
                setattr(os, name, counted(getattr(os, name)))
            write_set(out, NEW, "new")
        except KeyboardInterrupt:
            status = 130
        except SystemExit as error:
            status = int(error.code or 0)
        except BaseException:   # noqa: BLE001
            status = 1
        os._exit(status)
    _, status = os.waitpid(pid, 0)
    helper = out.parent / f"{out.name}.operations.helper"
    if helper.exists():   # a helper orphaned by the kill finishes on its own: wait for it
        helper_pid = int(helper.read_text())
        for _ in range(600):
            if _gone(helper_pid):
                break
            time.sleep(0.05)
    return os.waitstatus_to_exitcode(status), int(counter.read_text())


def fresh(tmp_path: Path, name: str) -> Path:
    out = tmp_path / name
    write_set(out, OLD, "old")
    (out / "notes.txt").write_text("mine")
    return out


KILLS = [("command", signal.SIGINT), ("command", signal.SIGTERM), ("command", signal.SIGKILL),
         ("helper", signal.SIGKILL), ("both", signal.SIGKILL)]


@pytest.mark.parametrize("target, signum", KILLS, ids=[f"{signal.Signals(s).name} to the {t}" for t, s in KILLS])
def test_a_kill_at_every_file_operation_leaves_the_old_set_or_the_new_one_whole(tmp_path, target, signum):
    old, new = expected(OLD, "old"), expected(NEW, "new")
    code, steps = run_killed_at(fresh(tmp_path, "count-run"), 0, signum)
    assert code == 0 and steps > 20, (code, steps)
    outcomes = {"old": 0, "new": 0, "finished by the next run": 0}
    for step in range(1, steps + 1):
        out = fresh(tmp_path, f"k{step}")
        run_killed_at(out, step, signum, target)
        seen = seen_with_marker(out)
        assert (out / "notes.txt").read_text() == "mine", step
        if seen == old:
            outcomes["old"] += 1
        elif seen == new:
            outcomes["new"] += 1
        else:
            # only killing the helper and the command at once stops the renames half-way: no result.json
            assert target == "both", (step, seen)
            assert "result.json" not in seen and (out / JOURNAL).exists(), (step, seen)
            assert recover_output_folder(out)
            assert seen_with_marker(out) == new, step
            outcomes["finished by the next run"] += 1
        # and the next run replaces whatever was there as a set
        write_set(out, {"c.txt": "third c"}, "third")
        assert seen_with_marker(out) == {"c.txt": "third c", "result.json": "third"}, step
        assert (out / "notes.txt").read_text() == "mine"
        assert not [p for p in out.iterdir() if p.name.startswith(".rscalib-staging")], step
    assert outcomes["new"] > 0 and (outcomes["old"] > 0 or target == "helper"), outcomes   # the helper: after the plan
    if target != "both":
        assert outcomes["finished by the next run"] == 0, outcomes


def test_sigint_during_the_commit_is_delivered_after_it(tmp_path, monkeypatch):
    """In one process: Ctrl-C while the files move in (here: as the helper starts) raises
    KeyboardInterrupt only once the new set is whole."""
    out = fresh(tmp_path, "out")
    finish = output_folder._finish

    def interrupted(*args):
        os.kill(os.getpid(), signal.SIGINT)
        return finish(*args)

    monkeypatch.setattr(output_folder, "_finish", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_set(out, NEW, "new")
    assert seen_with_marker(out) == expected(NEW, "new")
    assert not (out / JOURNAL).exists()


def test_the_next_run_finishes_a_commit_a_kill_left_before_it_does_anything(tmp_path):
    out = fresh(tmp_path, "out")
    steps = run_killed_at(fresh(tmp_path, "count"), 0, signal.SIGKILL)[1]
    for step in range(1, steps + 1):   # the first step that leaves a commit half done (a power cut)
        out = fresh(tmp_path, f"s{step}")
        run_killed_at(out, step, signal.SIGKILL, "both")
        if (out / JOURNAL).exists() and "result.json" not in visible(out):
            break
    else:
        pytest.fail("no step left a commit half done")
    check_output_folder(out)   # what every command does first
    assert seen_with_marker(out) == expected(NEW, "new") and not (out / JOURNAL).exists()


# -- inputs in the output folder ---------------------------------------------------------------------


def intrinsics_like_set(out: Path) -> None:
    with output_set(out) as staged:
        (staged / "camera.yaml").write_text("the camera")
        (staged / "report.html").write_text("intrinsics report")
        write_result_json(staged, {"marker": "intrinsics"}, command="intrinsics")


def test_an_input_camera_in_the_folder_is_not_removed_with_the_previous_set(tmp_path):
    out = tmp_path / "calib"
    intrinsics_like_set(out)
    camera = out / "camera.yaml"
    with output_set(out) as staged:   # linedelay --camera calib/camera.yaml --out calib
        (staged / "camera_with_line_delay.yaml").write_text("with d")
        write_result_json(staged, {"marker": "linedelay"}, command="linedelay", inputs={"camera": str(camera)})
    assert camera.read_text() == "the camera"
    assert not (out / "report.html").exists()                        # the rest of the previous set went
    assert json.loads((out / MANIFEST).read_text())["files"] == ["camera_with_line_delay.yaml", "result.json"]
    write_set(out, {"x.txt": "x"}, "later")                            # now the user's: never removed
    assert camera.read_text() == "the camera"


def test_an_output_that_would_replace_an_input_is_refused_and_nothing_changes(tmp_path):
    out = tmp_path / "calib"
    intrinsics_like_set(out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(InputError, match="would replace .*camera.yaml, an input of this run"):
        with output_set(out, inputs=[out / "camera.yaml"]) as staged:
            (staged / "camera.yaml").write_text("new camera")
            write_result_json(staged, {"marker": "again"}, command="intrinsics")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_an_input_folder_is_not_an_output_folder(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / "0001.png").write_bytes(b"png")
    with pytest.raises(InputError, match="is the input folder"):
        check_output_folder(frames, inputs=[str(frames)])
    with pytest.raises(InputError, match="holds the input image"):   # intrinsics frames/*.png --out frames
        check_output_folder(frames, inputs=[str(frames / "0001.png")])
    (frames / "video.avi").write_bytes(b"")   # a video beside its results is fine (simulate --out d; linedelay --out d)
    check_output_folder(frames, inputs=[str(frames / "video.avi")])
    with pytest.raises(InputError, match="is an input folder of this run"):
        with output_set(frames, inputs=[frames]) as staged:
            (staged / "plot.png").write_text("x")
    assert sorted(p.name for p in frames.iterdir() if not p.name.startswith(".")) == ["0001.png", "video.avi"]


def test_remove_output_set_keeps_the_users_files(tmp_path):
    from rscalib.io.output_folder import remove_output_set

    out = fresh(tmp_path, "job")
    remove_output_set(out)
    assert [p.name for p in out.iterdir() if not p.name.startswith(".rscalib-lock")] == ["notes.txt"]


# -- the commands ----------------------------------------------------------------------------------------


def rscalib(*args, timeout=240) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rscalib", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "OMP_NUM_THREADS": "1"})


def test_linedelay_out_into_the_folder_of_its_camera_keeps_the_camera(tmp_path):
    sim = tmp_path / "sim"
    done = rscalib("simulate", "--out", sim, "--duration", "1.0", "--size", "320x240", "--supersample", "1",
                   "--quiet")
    assert done.returncode == 0, done.stderr
    calib = tmp_path / "calib"
    with output_set(calib) as staged:   # what `rscalib intrinsics --out calib` leaves
        (staged / "camera.yaml").write_bytes((sim / "camera.yaml").read_bytes())
        (staged / "report.html").write_text("intrinsics report")
        write_result_json(staged, {"marker": "intrinsics"}, command="intrinsics")
    camera = (calib / "camera.yaml").read_bytes()
    argv = ["linedelay", sim / "video.avi", "--target", sim / "target.yaml", "--camera", calib / "camera.yaml",
            "--out", calib, "--no-report", "--workers", "1", "--quiet"]
    refused = rscalib(*argv)     # intrinsics' folder: another command's (issue 32)
    assert refused.returncode == 2 and "--force" in refused.stderr, refused.stderr
    done = rscalib(*argv, "--force")
    assert done.returncode in (0, 3, 4), done.stderr
    assert (calib / "camera.yaml").read_bytes() == camera
    assert (calib / "camera_with_line_delay.yaml").is_file() and not (calib / "report.html").exists()


def test_linedelay_out_equal_to_its_image_folder_is_refused_before_any_work(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(3):
        (frames / f"{i:04d}.png").write_bytes(b"")
    (frames / "timestamps.txt").write_text("0\n0.033\n0.066\n")
    target = tmp_path / "target.yaml"
    target.write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.03\n"
                      "colSpacingMeters: 0.03\n")
    camera = tmp_path / "camera.yaml"
    camera.write_text("%YAML:1.0\n---\nimage_width: 320\nimage_height: 240\ncamera_matrix: !!opencv-matrix\n"
                      "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 300., 0., 160., 0., 300., 120., 0., 0., 1. ]\n")
    before = sorted(p.name for p in frames.iterdir())
    done = rscalib("linedelay", frames, "--target", target, "--camera", camera, "--out", frames, "--quiet",
                   timeout=60)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "is the input folder" in lines[0], done.stderr
    assert sorted(p.name for p in frames.iterdir()) == before


if __name__ == "__main__":
    # The census of docs/reliability.md: what the folder holds after a kill at each file operation.
    # PYTHONPATH=python .venv/bin/python tests/python/io/test_output_kills.py
    import tempfile

    old, new = expected(OLD, "old"), expected(NEW, "new")
    for target, signum in KILLS:
        with tempfile.TemporaryDirectory() as scratch:
            tmp = Path(scratch)
            steps = run_killed_at(fresh(tmp, "count"), 0, signum)[1]
            tally: dict = {}
            for step in range(1, steps + 1):
                out = fresh(tmp, f"s{step}")
                run_killed_at(out, step, signum, target)
                seen = seen_with_marker(out)
                kind = ("old whole" if seen == old else "new whole" if seen == new else
                        "mixed, no result.json" if "result.json" not in seen else "mixed WITH result.json")
                if kind.startswith("mixed") and (out / JOURNAL).exists():
                    recover_output_folder(out)
                    kind += ", new whole after the next run" if seen_with_marker(out) == new else ", still mixed"
                if (out / "notes.txt").read_text() != "mine":
                    kind += ", the user's file changed"
                tally[kind] = tally.get(kind, 0) + 1
            print(f"{signal.Signals(signum).name} to", "both" if target == "both" else f"the {target}",
                  f"({steps} file operations):", tally)
