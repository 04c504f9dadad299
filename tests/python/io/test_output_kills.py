"""The output set against a kill at every instant, and against a run whose inputs live in its
--out (issue 33).

The kill test forks a child per file operation of a run that replaces a previous set: the child
counts its file operations (os.replace, unlink, rmdir, mkdir, open, write, fsync) and sends itself
SIGINT, SIGTERM or SIGKILL at the k-th; then the folder is checked. SIGINT and SIGTERM must leave the
previous set or the new one, whole, as they are; SIGKILL can stop the few milliseconds of renames
half-way, and then the folder must show no result.json until the next run (or
recover_output_folder) completes the new set from what the killed run left. The user's file in the
folder is never touched.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
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


def run_killed_at(out: Path, step: int, signum: int) -> tuple:
    """Fork; the child replaces the set in `out` and signals itself at its `step`-th file operation.
    Returns (the child's exit status, the operations it counted)."""
    counter = out.parent / f"{out.name}.operations"
    pid = os.fork()
    if pid == 0:   # the child: nothing here may return into pytest
        status = 0
        try:
            count = [0]

            def counted(function):
                def wrapper(*args, **kwargs):
                    count[0] += 1
                    counter.write_text(str(count[0])) if step == 0 else None
                    if count[0] == step:
                        os.kill(os.getpid(), signum)
                    return function(*args, **kwargs)
                return wrapper

            # the CLI's SIGTERM handler (cli._sigterm_raises): a Python exception, not the default death
            signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(143)))
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
    steps = int(counter.read_text()) if step == 0 else None
    return os.waitstatus_to_exitcode(status), steps


def fresh(tmp_path: Path, name: str) -> Path:
    out = tmp_path / name
    write_set(out, OLD, "old")
    (out / "notes.txt").write_text("mine")
    return out


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL],
                         ids=["SIGINT", "SIGTERM", "SIGKILL"])
def test_a_kill_at_every_file_operation_leaves_the_old_set_or_the_new_one_whole(tmp_path, signum):
    old, new = expected(OLD, "old"), expected(NEW, "new")
    code, steps = run_killed_at(fresh(tmp_path, "count-run"), 0, signum)
    assert code == 0 and steps > 20, (code, steps)
    outcomes = {"old": 0, "new": 0, "finished by the next run": 0}
    for step in range(1, steps + 1):
        out = fresh(tmp_path, f"k{step}")
        code, _ = run_killed_at(out, step, signum)
        seen = seen_with_marker(out)
        assert (out / "notes.txt").read_text() == "mine", step
        if seen == old:
            outcomes["old"] += 1
        elif seen == new:
            outcomes["new"] += 1
        else:
            # only SIGKILL can stop the commit between its first and last rename: then no result.json
            assert signum == signal.SIGKILL, (step, seen)
            assert "result.json" not in seen and (out / JOURNAL).exists(), (step, seen)
            assert recover_output_folder(out)
            assert seen_with_marker(out) == new, step
            outcomes["finished by the next run"] += 1
        # and the next run replaces whatever was there as a set
        write_set(out, {"c.txt": "third c"}, "third")
        assert seen_with_marker(out) == {"c.txt": "third c", "result.json": "third"}, step
        assert (out / "notes.txt").read_text() == "mine"
        assert not [p for p in out.iterdir() if p.name.startswith(".rscalib-staging")], step
    assert outcomes["old"] > 0 and outcomes["new"] > 0, outcomes
    if signum != signal.SIGKILL:   # a held signal arrives after the commit: the new set is whole
        assert outcomes["finished by the next run"] == 0


def test_sigint_during_the_commit_is_delivered_after_it(tmp_path, monkeypatch):
    """In one process: Ctrl-C while the files move in raises KeyboardInterrupt only once the new set
    is whole."""
    out = fresh(tmp_path, "out")
    real, moves = os.replace, []

    def replace(source, target):
        moves.append(Path(target).name)
        if len(moves) == 3:
            os.kill(os.getpid(), signal.SIGINT)
        return real(source, target)

    monkeypatch.setattr(output_folder.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        write_set(out, NEW, "new")
    monkeypatch.setattr(output_folder.os, "replace", real)
    assert seen_with_marker(out) == expected(NEW, "new")
    assert not (out / JOURNAL).exists()


def test_the_next_run_finishes_a_commit_a_kill_left_before_it_does_anything(tmp_path):
    out = fresh(tmp_path, "out")
    steps = run_killed_at(fresh(tmp_path, "count"), 0, signal.SIGKILL)[1]
    for step in range(1, steps + 1):   # the first step that leaves a commit half done
        out = fresh(tmp_path, f"s{step}")
        run_killed_at(out, step, signal.SIGKILL)
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
    done = rscalib("linedelay", sim / "video.avi", "--target", sim / "target.yaml", "--camera", calib / "camera.yaml",
                   "--out", calib, "--no-report", "--workers", "1", "--quiet")
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
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        with tempfile.TemporaryDirectory() as scratch:
            tmp = Path(scratch)
            steps = run_killed_at(fresh(tmp, "count"), 0, signum)[1]
            tally: dict = {}
            for step in range(1, steps + 1):
                out = fresh(tmp, f"s{step}")
                run_killed_at(out, step, signum)
                seen = seen_with_marker(out)
                kind = ("old whole" if seen == old else "new whole" if seen == new else
                        "mixed, no result.json" if "result.json" not in seen else "mixed WITH result.json")
                if kind.startswith("mixed") and (out / JOURNAL).exists():
                    recover_output_folder(out)
                    kind += ", new whole after the next run" if seen_with_marker(out) == new else ", still mixed"
                if (out / "notes.txt").read_text() != "mine":
                    kind += ", the user's file changed"
                tally[kind] = tally.get(kind, 0) + 1
            print(signal.Signals(signum).name, f"{steps} file operations:", tally)
