"""`rscalib batch` end to end (issue 18): 12 jobs on rendered data (4 line-delay videos in two camera
modes, 3 flicker clips, intrinsics stills, a self-calibration walk, and 3 bad inputs: a cut-off video,
a missing camera file, a missing video) on a LocalCluster of 2 worker processes. One job is killed midway, then the whole batch is killed; --resume
runs only what is missing; every answer equals the single command's, bit for bit.
"""
from __future__ import annotations

import json
import os
import re
import signal
import sqlite3
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

import rscalib
from rscalib.batch.runner import JOB_THREAD_ENV

pytest.importorskip("distributed")

PACKAGE_PARENT = Path(rscalib.__file__).resolve().parents[1]
ANSWERED = ("ok", "not_trusted", "undetermined", "bad_input")
# result.json entries that differ between two runs of the same command: clocks and cache hits
VOLATILE = ("provenance", "created_utc", "frames_per_s", "elapsed_s", "detections_from_cache", "from_cache")
VICTIM = "ld-30fps-1"  # the job killed midway (first row: it starts first)


def environment(cache: Path) -> dict:
    # The batch caps each job's threads at one (JOB_THREAD_ENV); the single commands run the same way,
    # because `rscalib intrinsics` is bit-reproducible only with OpenCV on one thread.
    env = {**os.environ, **JOB_THREAD_ENV}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(PACKAGE_PARENT), env.get("PYTHONPATH")) if p)
    env["RSCALIB_CACHE_DIR"] = str(cache)  # detections are never shared between the batch and the references
    return env


def rscalib_cli(args, env, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rscalib", *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=kwargs.pop("timeout", 120), **kwargs)


def parallel(function, items) -> list:
    with ThreadPoolExecutor(2) as pool:
        return list(pool.map(function, items))


def render(data: Path, env: dict) -> list:
    """Render the data; returns the manifest rows (id, command, input, mode, target, camera, frequency, max-frames)."""
    small = ["--size", "320x240", "--supersample", "1", "--quiet"]
    sims, rows = [], []
    for k, (fps, delay) in enumerate([(30, "30us"), (30, "30us"), (25, "20us"), (25, "20us")]):
        name = f"ld-{fps}fps-{k % 2 + 1}"
        sims.append(["--out", data / name, "--duration", "1.5", "--fps", fps, "--line-delay", delay, "--seed", k + 1])
        rows.append([name, "linedelay", f"{name}/video.avi", f"320x240@{fps}", f"{name}/target.yaml",
                     f"{name}/camera.yaml", "", ""])
    for hz in (1000, 700, 1200):
        sims.append(["--out", data / f"led{hz}", "--flicker-hz", hz, "--motion", "0", "--duration", "0.5"])
        rows.append([f"flicker-{hz}", "flicker", f"led{hz}/video.avi", "320x240@30", "", "", hz, ""])
    sims.append(["--out", data / "stills", "--line-delay", "0", "--duration", "4", "--fps", "5", "--frames-dir",
                 "--no-video"])
    rows.append(["intrinsics", "intrinsics", "stills/frames", "", "stills/target.yaml", "", "", ""])
    sims.append(["--scene", "--out", data / "room", "--duration", "1"])
    rows.append(["selfcalib", "selfcalib", "room", "", "", "", "", 20])
    for done in parallel(lambda args: rscalib_cli(["simulate", *args, *small], env), sims):
        assert done.returncode == 0, done.stderr
    (data / "stills" / "frames" / "timestamps.txt").unlink()  # stills have no times
    # Bad inputs: a cut-off video, a camera file that is not there, a video that is not there.
    (data / "truncated.avi").write_bytes((data / "ld-30fps-1" / "video.avi").read_bytes()[:4096])
    board = ["ld-30fps-1/target.yaml", "ld-30fps-1/camera.yaml"]
    rows.append(["bad-truncated", "linedelay", "truncated.avi", "320x240@30", *board, "", ""])
    rows.append(["bad-camera", "linedelay", "ld-30fps-2/video.avi", "320x240@30", board[0], "no_such_camera.yaml",
                 "", ""])
    rows.append(["bad-missing", "linedelay", "missing.avi", "320x240@30", *board, "", ""])
    return rows


def user_argv(row, data: Path, out: Path) -> list:
    """The single command as a user would type it for this manifest row."""
    job_id, command, source, _mode, target, camera, frequency, max_frames = row
    argv = [command, data / source]
    for flag, value in (("--target", target and data / target), ("--camera", camera and data / camera),
                        ("--frequency", frequency), ("--max-frames", max_frames)):
        if value:
            argv += [flag, value]
    return [*argv, "--out", out / job_id, "--quiet"]


def rows_of(store: Path) -> dict:
    if not store.exists():
        return {}
    with sqlite3.connect(str(store), timeout=30) as db:
        db.row_factory = sqlite3.Row
        try:
            return {r["id"]: dict(r) for r in db.execute("SELECT * FROM jobs")}
        except sqlite3.OperationalError:  # created, tables not yet
            return {}


def leaves(value, path=""):
    """(path, value) of every number, string, bool or null, without the entries that vary run to run."""
    if isinstance(value, dict):
        for key, item in value.items():
            if key not in VOLATILE and not key.endswith("_time_s"):
                yield from leaves(item, f"{path}/{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from leaves(item, f"{path}[{i}]")
    else:
        yield path, value


def job_processes(out: Path) -> list:
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            text = cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if "rscalib.cli.job" in text and str(out) in text:
            found.append(text)
    return found


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="kills and process checks use Linux /proc")
def test_batch_on_two_workers_resumes_after_a_kill_and_matches_the_single_commands(tmp_path):
    data, out, ref = tmp_path / "data", tmp_path / "batch", tmp_path / "single"
    batch_env, ref_env = environment(tmp_path / "cache-batch"), environment(tmp_path / "cache-single")
    rows = render(data, batch_env)
    assert len(rows) >= 12
    manifest = data / "manifest.csv"
    header = "id,command,input,mode,target,camera,frequency,max-frames\n"
    manifest.write_text(header + "".join(",".join(map(str, r)) + "\n" for r in rows))
    store = out / "results.sqlite"

    # 1. Run; kill one job midway, then kill the whole batch (kill -9 of the driver) with jobs left.
    log = open(tmp_path / "run1.log", "w")
    driver = subprocess.Popen([sys.executable, "-m", "rscalib", "batch", manifest, "--out", out, "--workers", "2"],
                              env=batch_env, stdout=log, stderr=subprocess.STDOUT)
    victim_killed, deadline = False, time.monotonic() + 120
    while driver.poll() is None and time.monotonic() < deadline:
        jobs = rows_of(store)
        victim = jobs.get(VICTIM, {})
        if not victim_killed and victim.get("status") == "running" and victim.get("pid"):
            os.kill(victim["pid"], signal.SIGKILL)
            victim_killed = True
        answered = [j for j in jobs.values() if j["status"] in ANSWERED]
        if victim.get("status") == "killed" and len(answered) >= 4:
            driver.send_signal(signal.SIGKILL)
            break
        time.sleep(0.02)
    driver.wait(30)
    log.close()
    assert victim_killed and driver.returncode == -signal.SIGKILL, (tmp_path / "run1.log").read_text()
    for _ in range(100):  # the jobs die with their workers (no orphans writing into DIR)
        if not job_processes(out):
            break
        time.sleep(0.1)
    assert job_processes(out) == []
    before = rows_of(store)
    assert before[VICTIM]["status"] == "killed" and "SIGKILL" in before[VICTIM]["reason"]
    answered_before = {k: j for k, j in before.items() if j["status"] in ANSWERED}
    assert 4 <= len(answered_before) < len(rows)
    status = rscalib_cli(["batch", "--status", out], batch_env)
    assert status.returncode == 0 and "stopped without finishing" in status.stdout, status.stdout
    left = len(rows) - len(answered_before) - 1   # queued or running when the driver died (the victim: killed)
    assert f"running 0, queued 0, interrupted {left}," in status.stdout.splitlines()[0], status.stdout

    # 2. --resume runs what is missing (the killed job, the queued and running ones), nothing else.
    resumed = rscalib_cli(["batch", manifest, "--out", out, "--resume"], batch_env)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(rows)} jobs, {len(answered_before)} already done, {len(rows) - len(answered_before)} to run" \
        in resumed.stderr
    after = rows_of(store)
    for job_id, job in answered_before.items():
        assert (after[job_id]["runs"], after[job_id]["started_utc"]) == (1, job["started_utc"]), job_id
    assert after[VICTIM]["runs"] == 2
    assert all(j["status"] in ANSWERED for j in after.values()), {k: j["status"] for k, j in after.items()}
    again = rscalib_cli(["batch", manifest, "--out", out, "--resume"], batch_env)
    assert again.returncode == 0 and f"{len(rows)} already done, 0 to run" in again.stderr

    # 3. Every job equals its single command: exit code and result.json (bit for bit), or the same error.
    singles = parallel(lambda row: rscalib_cli(user_argv(row, data, ref), ref_env), rows)
    for row, single in zip(rows, singles):
        job = after[row[0]]
        assert job["exit_code"] == single.returncode, (row[0], single.stderr)
        if row[0].startswith("bad-"):
            assert job["status"] == "bad_input"
            assert job["reason"] == single.stderr.strip().splitlines()[-1]
            assert "error:" in job["reason"]
            continue
        batch_result = json.loads((out / "jobs" / row[0] / "result.json").read_text())
        single_result = json.loads((ref / row[0] / "result.json").read_text())
        assert dict(leaves(batch_result)) == dict(leaves(single_result)), row[0]
        if job["value"] is not None and row[1] != "selfcalib":
            assert job["value_std"] is not None and job["value_std"] > 0
    assert after["ld-30fps-2"]["value_name"] == "line_delay_s"
    assert after["ld-30fps-2"]["value"] == json.loads((ref / "ld-30fps-2" / "result.json").read_text())["line_delay_s"]

    # 4. The summary: every job in the table, the plot, links to reports and logs.
    index = (out / "index.html").read_text()
    assert all(f"<td>{r[0]}</td>" in index for r in rows)
    assert (out / "line_delay_by_mode.png").stat().st_size > 0
    assert 'href="jobs/ld-25fps-1/report.html"' in index and 'href="logs/bad-truncated.log"' in index
    assert re.search(r"12 jobs: done 12 \(", index)
