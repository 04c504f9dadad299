"""The batch folder is the user's too (issue 33): one driver at a time, --status reads only and
knows a killed driver, a store that is not rscalib's is refused untouched, the user's files in jobs/
and logs/ are never removed or overwritten, and the manifest and options are checked before
anything runs."""
from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import sqlite3
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

import rscalib
from rscalib.batch.manifest import load_manifest
from rscalib.batch.runner import run_job
from rscalib.batch.store import QUEUED, RUNNING, STORE_FILE, ResultStore
from rscalib.batch.summary import status_lines
from rscalib.errors import InputError

pytest.importorskip("distributed")

PACKAGE_PARENT = str(Path(rscalib.__file__).resolve().parents[1])


@pytest.fixture
def package_on_path(monkeypatch):
    """Job subprocesses import the same rscalib as this test."""
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (PACKAGE_PARENT, os.environ.get("PYTHONPATH")) if p))


def environment() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (PACKAGE_PARENT, os.environ.get("PYTHONPATH"))
                                                         if p), "OMP_NUM_THREADS": "1"}


def rscalib_cli(*args, timeout=180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rscalib", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=environment())


def one_line_error(done: subprocess.CompletedProcess, *words) -> str:
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-2000:]
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


def driver_lock(out):
    from rscalib.batch.store import driver_lock

    return driver_lock(out)


def driver_running(out):
    from rscalib.batch.store import driver_running

    return driver_running(out)


def fingerprint(path: Path) -> tuple:
    st = path.stat()
    return hashlib.sha256(path.read_bytes()).hexdigest(), st.st_size, st.st_mtime_ns, stat.S_IMODE(st.st_mode)


def flicker_manifest(folder: Path, frequency: int = 100, name: str = "m.csv") -> Path:
    manifest = folder / name
    manifest.write_text(f"id,command,input,frequency\nclip,flicker,missing.avi,{frequency}\n")
    return manifest


def a_store(folder: Path, state: str = "running", driver_pid: int = None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    store = ResultStore(folder / STORE_FILE, create=True)
    store.update("a", row=1, command="flicker", status=RUNNING, worker="tcp://w", pid=1, started_utc="t")
    store.update("b", row=2, command="flicker", status=QUEUED)
    store.update("c", row=3, command="flicker", status="ok", value=1e-5, value_name="line_delay_s")
    store.set_meta(state=state, driver_pid=driver_pid or os.getpid(), driver_host=os.uname().nodename,
                   started_utc="t0")
    store.close()


# -- one driver at a time --------------------------------------------------------------------------------


def test_a_second_driver_is_refused_in_one_line_while_one_runs(tmp_path):
    out = tmp_path / "batch"
    out.mkdir()
    manifest = flicker_manifest(tmp_path)
    with driver_lock(out):   # a driver running this batch
        started = time.monotonic()
        done = rscalib_cli("batch", manifest, "--out", out, "--resume")
        one_line_error(done, "another rscalib batch is running this batch", f"pid {os.getpid()}")
        assert time.monotonic() - started < 60
        assert not (out / STORE_FILE).exists()
        assert driver_running(out) is True


def test_a_killed_drivers_lock_is_not_stale(tmp_path):
    out = tmp_path / "batch"
    out.mkdir()
    child = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom rscalib.batch.store import driver_lock\n"
                              "with driver_lock(sys.argv[1]):\n    print('locked', flush=True)\n    time.sleep(600)\n",
                              str(out)], stdout=subprocess.PIPE, text=True, env=environment())
    assert child.stdout.readline().strip() == "locked"
    assert driver_running(out) is True
    child.send_signal(signal.SIGKILL)
    child.wait(30)
    assert driver_running(out) is False
    with driver_lock(out):   # at once: the kernel released the dead driver's lock
        pass


# -- --status -----------------------------------------------------------------------------------------------


def test_status_after_a_killed_driver_says_interrupted_not_running(tmp_path):
    out = tmp_path / "batch"
    # the driver's pid is a live process (pid reuse, or the pid of this test): the lock tells the truth
    a_store(out, driver_pid=os.getpid())
    (out / ".rscalib-batch.lock").write_text("pid 1 on host since t\n")
    lines = status_lines(out)
    assert "running 0, queued 0, interrupted 2" in lines[0], lines
    assert "stopped without finishing" in lines[1] and "2 jobs interrupted" in lines[1], lines
    assert "  a: interrupted (its driver is gone) on tcp://w" in lines
    with driver_lock(out):   # while a driver runs, its jobs are running
        lines = status_lines(out)
        assert "running 1, queued 1" in lines[0] and "the batch is running" in lines[1], lines


def test_status_changes_nothing(tmp_path):
    out = tmp_path / "batch"
    a_store(out, state="finished")
    before = {p.name: fingerprint(p) for p in out.iterdir()}
    done = rscalib_cli("batch", "--status", out)
    assert done.returncode == 0 and "3 jobs: done 1" in done.stdout, done.stderr
    assert {p.name: fingerprint(p) for p in out.iterdir()} == before


@contextlib.contextmanager
def read_only_folder(folder: Path):
    """`folder` made read-only as it is: a read-only tmpfs for root (whom file modes do not stop),
    file modes otherwise."""
    if os.geteuid() != 0:
        modes = {p: p.stat().st_mode for p in [folder, *folder.iterdir()]}
        for p in modes:
            p.chmod(modes[p] & ~0o222)
        try:
            yield
        finally:
            for p, mode in modes.items():
                p.chmod(mode)
        return
    saved = {p.name: p.read_bytes() for p in folder.iterdir()}
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(folder)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs")
    try:
        for name, data in saved.items():
            (folder / name).write_bytes(data)
        assert subprocess.run(["mount", "-o", "remount,ro", str(folder)], capture_output=True).returncode == 0
        yield
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def test_status_reads_a_read_only_store_and_a_driver_refuses_it(tmp_path):
    out = tmp_path / "batch"
    a_store(out, state="finished")
    with read_only_folder(out):
        done = rscalib_cli("batch", "--status", out)
        assert done.returncode == 0 and "3 jobs: done 1" in done.stdout, done.stderr
        resumed = rscalib_cli("batch", flicker_manifest(tmp_path), "--out", out, "--resume")
        assert resumed.returncode == 2 and "Traceback" not in resumed.stderr, resumed.stderr
        assert len(resumed.stderr.strip().splitlines()) == 1, resumed.stderr


def foreign_sqlite(path: Path) -> None:
    with sqlite3.connect(str(path)) as db:
        db.execute("CREATE TABLE photos (name TEXT, taken TEXT)")
        db.execute("INSERT INTO photos VALUES ('a.jpg', '2020')")
    db.close()


@pytest.mark.parametrize("kind", ["foreign sqlite", "random bytes", "damaged store", "text"])
def test_a_store_that_is_not_ours_is_refused_untouched(tmp_path, kind):
    out = tmp_path / "batch"
    out.mkdir()
    store = out / STORE_FILE
    if kind == "foreign sqlite":
        foreign_sqlite(store)
    elif kind == "random bytes":
        store.write_bytes(os.urandom(8192))
    elif kind == "damaged store":
        a_store(out, state="finished")
        data = bytearray(store.read_bytes())
        data[100:4000] = os.urandom(3900)   # the header survives, the schema does not
        store.write_bytes(bytes(data))
        for extra in out.glob(f"{STORE_FILE}-*"):
            extra.unlink()
    else:
        store.write_text("id,status\n")
    before = {p.name: fingerprint(p) for p in out.iterdir()}
    status = rscalib_cli("batch", "--status", out)
    one_line_error(status, str(store))
    resumed = rscalib_cli("batch", flicker_manifest(tmp_path), "--out", out, "--resume")
    one_line_error(resumed, str(store))
    assert {p.name: fingerprint(p) for p in out.iterdir()} == before


# -- the user's files -------------------------------------------------------------------------------------


def test_a_rerun_of_a_job_keeps_the_users_notes_in_its_folder(tmp_path, package_on_path):
    job = load_manifest(flicker_manifest(tmp_path))[0]
    task = {"id": job.id, "command": job.command, "argv": list(job.argv), "inputs": list(job.inputs),
            "spec_hash": job.spec_hash("test"), "out_dir": str(tmp_path / "jobs" / job.id),
            "log_path": str(tmp_path / "logs" / f"{job.id}.log"), "timeout_s": None}
    from rscalib.io.output_folder import output_set
    from rscalib.io.results import write_result_json

    job_dir = tmp_path / "jobs" / job.id
    with output_set(job_dir) as staged:   # a previous run's answer
        (staged / "flicker.png").write_text("plot")
        write_result_json(staged, {"line_delay_s": 1e-5}, command="flicker")
    (job_dir / "notes.txt").write_text("my notes")
    outcome = run_job(task)
    assert outcome["status"] == "bad_input"
    assert (job_dir / "notes.txt").read_text() == "my notes"
    assert not (job_dir / "result.json").exists() and not (job_dir / "flicker.png").exists()


def test_resume_after_an_option_change_keeps_notes_and_logs_of_the_user(tmp_path):
    out = tmp_path / "batch"
    first = rscalib_cli("batch", flicker_manifest(tmp_path, 100), "--out", out, "--workers", "1")
    assert first.returncode == 0, first.stderr
    (out / "jobs" / "clip").mkdir(parents=True, exist_ok=True)
    (out / "jobs" / "clip" / "notes.txt").write_text("my notes")
    (out / "logs" / "mine.txt").write_text("my log")
    log = (out / "logs" / "clip.log").read_text()
    assert log.startswith("$ rscalib flicker")
    changed = rscalib_cli("batch", flicker_manifest(tmp_path, 120), "--out", out, "--resume", "--workers", "1")
    assert changed.returncode == 0 and "1 to run" in changed.stderr, changed.stderr
    assert (out / "jobs" / "clip" / "notes.txt").read_text() == "my notes"
    assert (out / "logs" / "mine.txt").read_text() == "my log"
    assert "--frequency 120" in (out / "logs" / "clip.log").read_text()   # its own log: replaced


def test_a_users_file_where_the_batch_writes_is_refused_not_overwritten(tmp_path):
    for name in ("logs/clip.log", "index.html"):
        out = tmp_path / name.replace("/", "_")
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("mine")
        done = rscalib_cli("batch", flicker_manifest(tmp_path), "--out", out, "--workers", "1")
        one_line_error(done, str(out / name), "did not write")
        assert (out / name).read_text() == "mine" and not (out / STORE_FILE).exists()


# -- manifest and options ------------------------------------------------------------------------------------


def test_a_csv_manifest_with_a_duplicate_column_is_refused(tmp_path):
    for header in ("command,input,frequency,frequency", "command,input,pixel_size_mm, pixel-size-mm"):
        manifest = tmp_path / "m.csv"
        manifest.write_text(f"{header}\nflicker,a.avi,100,200\n")
        with pytest.raises(InputError, match="repeats column 3") as error:
            load_manifest(manifest)
        assert "line 1" in str(error.value)


def test_a_csv_manifest_with_a_byte_order_mark_is_read(tmp_path):
    manifest = tmp_path / "m.csv"
    manifest.write_bytes("\ufeffid,command,input,frequency\r\nclip,flicker,a.avi,100\r\n".encode("utf-8"))
    job, = load_manifest(manifest)
    assert job.id == "clip" and job.argv[:2] == ("flicker", str(tmp_path / "a.avi"))


@pytest.mark.parametrize("address", ["not-an-address", "http://host:8786", "tcp://", "::::"])
def test_a_scheduler_that_is_not_an_address_is_one_line(tmp_path, address):
    out = tmp_path / "batch"
    done = rscalib_cli("batch", flicker_manifest(tmp_path), "--out", out, "--scheduler", address, timeout=60)
    one_line_error(done, "--scheduler", "not a Dask scheduler address")
    assert not (out / STORE_FILE).exists()


def test_a_memory_limit_that_kills_every_job_says_killed_and_why(tmp_path):
    data = tmp_path / "data"
    done = rscalib_cli("simulate", "--out", data, "--duration", "2", "--size", "320x240", "--supersample", "1",
                       "--quiet")
    assert done.returncode == 0, done.stderr
    manifest = tmp_path / "m.csv"
    manifest.write_text("id,command,input,target,camera\n"
                        + "".join(f"v{i},linedelay,data/video.avi,data/target.yaml,data/camera.yaml\n" for i in range(2)))
    out = tmp_path / "batch"
    done = rscalib_cli("batch", manifest, "--out", out, "--workers", "1", "--memory-limit", "60MB", timeout=300)
    assert done.returncode == 1, done.stderr
    with sqlite3.connect(f"file:{out / STORE_FILE}?mode=ro", uri=True) as db:
        rows = db.execute("SELECT id, status, reason FROM jobs ORDER BY id").fetchall()
    assert [(r[0], r[1]) for r in rows] == [("v0", "killed"), ("v1", "killed")], rows
    assert all(r[2].startswith("memory limit: the job used") for r in rows), rows
