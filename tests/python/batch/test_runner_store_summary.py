"""The batch's pieces without a cluster: what --resume keeps (plan), one job run in a subprocess with its
outcome and limits (run_job), the store's rules, index.html and --status."""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

import rscalib
from rscalib.batch.manifest import load_manifest
from rscalib.batch.runner import hash_inputs, input_stats, plan, run_job
from rscalib.batch.store import QUEUED, RUNNING, STORE_FILE, ResultStore
from rscalib.batch.summary import format_value, status_lines, write_index
from rscalib.errors import InputError


@pytest.fixture
def package_on_path(monkeypatch):
    """Job subprocesses import the same rscalib as this test."""
    parent = str(Path(rscalib.__file__).resolve().parents[1])
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (parent, os.environ.get("PYTHONPATH")) if p))


def one_job(tmp_path, row: str):
    manifest = tmp_path / "m.csv"
    manifest.write_text("id,command,input,frequency\n" + row + "\n")
    return load_manifest(manifest)[0]


def task_of(job, tmp_path, **extra) -> dict:
    return {"id": job.id, "command": job.command, "argv": list(job.argv), "inputs": list(job.inputs),
            "spec_hash": job.spec_hash("test"), "out_dir": str(tmp_path / "jobs" / job.id),
            "log_path": str(tmp_path / "logs" / f"{job.id}.log"), "timeout_s": None, **extra}


def test_hashes_cover_a_folder_names_and_contents(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "a.png").write_bytes(b"1")
    first = hash_inputs([tmp_path / "d", tmp_path / "missing"])
    assert first[0]["bytes"] == 1 and first[1] == {"path": str(tmp_path / "missing"), "bytes": None, "sha256": None}
    (tmp_path / "d" / "a.png").rename(tmp_path / "d" / "b.png")
    assert hash_inputs([tmp_path / "d"])[0]["sha256"] != first[0]["sha256"]
    assert input_stats([tmp_path / "missing"]) == [[str(tmp_path / "missing"), None, None]]


def test_plan_keeps_answered_jobs_with_untouched_inputs(tmp_path):
    (tmp_path / "a.avi").write_bytes(b"video")
    job = one_job(tmp_path, "a,flicker,a.avi,100")
    store = ResultStore(tmp_path / STORE_FILE, create=True)
    assert plan([job], store, "1") == ([(job, job.spec_hash("1"), None)], [])
    answered = dict(status="ok", spec_hash=job.spec_hash("1"), input_stats=input_stats(job.inputs), content_key="k")
    store.update(job.id, **answered)
    assert plan([job], store, "1") == ([], [job])
    assert plan([job], store, "2")[1] == []                      # another version: run again
    store.update(job.id, status="killed")
    assert plan([job], store, "1")[1] == []                      # no answer: run again
    store.update(job.id, status="ok")
    os.utime(tmp_path / "a.avi", ns=(0, 0))                      # touched: the job compares the contents
    (to_run, _, previous), = plan([job], store, "1")[0]
    assert to_run is job and previous["content_key"] == "k"
    store.close()


def test_run_job_records_a_bad_input_and_recognises_unchanged_inputs(tmp_path, package_on_path):
    job = one_job(tmp_path, "nothing,flicker,missing.avi,100")
    outcome = run_job(task_of(job, tmp_path))
    assert outcome["status"] == "bad_input" and outcome["exit_code"] == 2
    assert outcome["reason"] == f"rscalib flicker: error: not found: {tmp_path / 'missing.avi'}"
    assert outcome["peak_memory_mb"] > 1 and outcome["wall_time_s"] > 0
    log = (tmp_path / "logs" / "nothing.log").read_text()
    assert log.startswith("$ rscalib flicker ") and "error: not found" in log
    again = run_job(task_of(job, tmp_path, previous_content_key=outcome["content_key"]))
    assert again["unchanged"] and "status" not in again


def test_run_job_kills_a_job_over_its_time_limit(tmp_path, package_on_path):
    task = task_of(one_job(tmp_path, "slow,flicker,x.avi,100"), tmp_path, timeout_s=0.5)
    task["command"], task["argv"] = "simulate", ["simulate", "--duration", "60", "--quiet"]  # a slow command
    started = time.monotonic()
    outcome = run_job(task)
    assert time.monotonic() - started < 20
    assert outcome["status"] == "killed" and outcome["reason"].startswith("time limit") and outcome["exit_code"] == -9


def test_store_running_never_overwrites_an_answer(tmp_path):
    store = ResultStore(tmp_path / STORE_FILE, create=True)
    store.update("a", status=QUEUED, argv=["flicker", "x"])
    store.mark_running("a", pid=12, worker="w", started_utc="t")
    assert store.row("a")["status"] == RUNNING and store.row("a")["argv"] == ["flicker", "x"]
    store.update("a", status="ok")
    store.mark_running("a", pid=13, worker="w", started_utc="t2")  # a late event
    assert store.row("a")["status"] == "ok" and store.row("a")["pid"] == 12
    with pytest.raises(KeyError):
        store.update("a", colour="red")
    store.close()
    with pytest.raises(InputError, match="no batch results"):
        ResultStore(tmp_path / "elsewhere" / STORE_FILE)


def _table(page: str) -> tuple[list, dict]:
    """The index's header and its rows by job id, read with the standard library's HTML parser."""
    from html.parser import HTMLParser

    class Table(HTMLParser):
        def __init__(self):
            super().__init__()
            self.rows, self.cell = [], None

        def handle_starttag(self, tag, attrs):
            if tag == "tr":
                self.rows.append([])
            elif tag in ("td", "th"):
                self.cell = ""

        def handle_endtag(self, tag):
            if tag in ("td", "th") and self.cell is not None:
                self.rows[-1].append(self.cell.strip())
                self.cell = None

        def handle_data(self, data):
            if self.cell is not None:
                self.cell += data

    parser = Table()
    parser.feed(page)
    header, *rows = [r for r in parser.rows if r]
    return header, {r[0]: r for r in rows}


def test_index_and_status(tmp_path):
    store = ResultStore(tmp_path / STORE_FILE, create=True)
    rows = [("a", "m1", "linedelay", "ok", 3.01e-5, 1e-7), ("b", "m1", "linedelay", "not_trusted", 2.9e-5, 3e-7),
            ("c", "m2", "flicker", "ok", 2.0e-5, 1e-9), ("d", "m2", "linedelay", "bad_input", None, None),
            ("e", "", "selfcalib", "killed", None, None), ("f", "m2", "linedelay", RUNNING, None, None)]
    for i, (job_id, mode, command, status, value, std) in enumerate(rows):
        store.update(job_id, row=i + 1, mode=mode, command=command, status=status, value=value, value_std=std,
                     value_name="line_delay_s" if value else None, reason="why" if status in ("bad_input", "killed")
                     else None, out_dir=f"jobs/{job_id}", log_path=f"logs/{job_id}.log")
    (tmp_path / "jobs" / "a").mkdir(parents=True)
    (tmp_path / "jobs" / "a" / "report.html").write_text("")
    store.set_meta(state="running", driver_pid=os.getpid(), driver_host=os.uname().nodename)
    index = write_index(tmp_path, store.rows()).read_text()
    assert 'href="jobs/a/report.html"' in index and "<th>" in index and "sort" in index
    assert "6 jobs: done 4 (ok 2, not_trusted 1, bad_input 1), running 1, queued 0, failed 1 (killed 1)" in index
    assert (tmp_path / "line_delay_by_mode.png").stat().st_size > 0
    assert format_value(store.row("a")) == "d = 30.1 ± 0.1 µs/row"
    header, cells = _table(index)
    for name in header[5:9]:                          # the number columns: one unit each, in the header
        assert name.endswith(("(µs/row)", "(px)")), header
    a = dict(zip(header, cells["a"]))
    assert a["line delay (µs/row)"] == "30.1" and a["σ line delay (µs/row)"] == "0.1" and a["f (px)"] == ""
    lines = status_lines(tmp_path)
    assert "running 1" in lines[0] and "the batch is running" in lines[1]
    assert "  e: killed: why" in lines and "  d: bad_input: why" in lines
    store.set_meta(driver_pid=2 ** 22 + 1)  # a pid that is not running: the batch was killed
    lines = status_lines(tmp_path)
    assert "stopped without finishing (its driver is gone; 1 jobs interrupted)" in lines[1]
    assert "running 0, queued 0, interrupted 1" in lines[0] and "  f: interrupted (its driver is gone)" in lines
    store.close()
