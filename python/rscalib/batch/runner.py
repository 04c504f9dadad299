"""Run a manifest's jobs on Dask: one task per job, each task one subprocess running the single command.

Why a subprocess per job and not `cli.main(argv)` inside the worker: a job that crashes (a segfault in
a native library, an out-of-memory kill) takes only its own process down, never the worker and the
other jobs on it; the kernel measures that process's peak memory (wait4's ru_maxrss), and a job over
its memory or time limit can be killed without killing the worker. The cost is an interpreter start
and rscalib's imports per job (~0.3 s; docs/scale.md). The job runs `rscalib.cli.main` with the row's
arguments, so it is the single command's code path and writes its usual folder, DIR/jobs/<id>/.

The driver (this process) is the only writer of the results store: workers return their outcome,
and report "running" through a Dask event, so the store works the same with a LocalCluster or with
`--scheduler tcp://...` (where the workers need rscalib installed and DIR and the inputs on a shared
file system).
"""
from __future__ import annotations

import contextlib
import hashlib
import itertools
import os
import shlex
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Callable, Optional

from .._version import __version__
from ..errors import InputError
from ..io.output_folder import remove_output_set
from ..io.safe_parse import one_line, shown
from .manifest import load_manifest
from .outcome import read_outcome
from .store import ANSWERED, LOST, QUEUED, STORE_FILE, ResultStore, check_store, driver_lock, utc_now
from .summary import INDEX_FILE, PLOT_FILE, write_index

EVENT_TOPIC = "rscalib-batch"
# The job process (rscalib.cli.job, started by its module name: batch never imports cli) dies with the
# worker thread whose process id this names.
JOB_MODULE = "rscalib.cli.job"
PARENT_PID_ENV = "RSCALIB_BATCH_PARENT_PID"
JOBS_DIR, LOGS_DIR = "jobs", "logs"
# A job's own threads: the jobs are the parallelism (workers x threads-per-worker at once), so each
# job's BLAS/OpenMP/OpenCV pools get one thread (OpenCV's matters for more than speed: with several
# threads the last bits of cv2.calibrateCameraExtended, so of `rscalib intrinsics`, vary run to run).
JOB_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                  "OPENCV_FOR_THREADS_NUM": "1"}
POLL_S = 0.1          # how often a job is checked for its end (the subprocess is reaped by polling)
MEMORY_EVERY = 5      # and every 5th check (0.5 s) its memory and time
_HASH_CHUNK_BYTES = 1 << 20


def _files(path: Path) -> list:
    """A file, or every file under a folder (sorted: the order is part of what is hashed)."""
    if path.is_dir():
        return sorted(p for p in path.rglob("*") if p.is_file())
    return [path] if path.is_file() else []


def input_stats(paths) -> list:
    """[path, bytes, mtime_ns] of every input file (None, None for a missing one): the cheap test
    that lets --resume skip a job without reading its video."""
    stats = []
    for path in map(Path, paths):
        files = _files(path)
        if not files:
            stats.append([str(path), None, None])
        for f in files:
            st = f.stat()
            stats.append([str(f), st.st_size, st.st_mtime_ns])
    return stats


def hash_inputs(paths) -> list:
    """{path, bytes, sha256} of each input; a folder's hash covers its files' names and contents."""
    hashed = []
    for path in map(Path, paths):
        digest, size = hashlib.sha256(), 0
        files = _files(path)
        for f in files:
            if path.is_dir():
                digest.update(str(f.relative_to(path)).encode() + b"\0")
            with open(f, "rb") as stream:
                for chunk in iter(lambda: stream.read(_HASH_CHUNK_BYTES), b""):
                    digest.update(chunk)
                    size += len(chunk)
        hashed.append({"path": str(path), "bytes": size if files else None,
                       "sha256": digest.hexdigest() if files else None})
    return hashed


def content_key(spec_hash: str, hashes: list) -> str:
    """The job's identity: what it runs and the bytes it reads. Equal keys give equal results."""
    text = spec_hash + "".join(f"{h['path']}={h['sha256']};" for h in hashes)
    return hashlib.sha256(text.encode()).hexdigest()


def _children_of(pid: int) -> list:
    """The child processes of pid, from /proc/<pid>/task/*/children (Linux; [] elsewhere or when gone)."""
    children = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            children += [int(c) for c in task.read_text().split()]
        except (OSError, ValueError):
            continue
    return children


def _tree(pid: int) -> list:
    """pid and all its descendants (a few small reads per process of the job, not a scan of /proc)."""
    tree, frontier = [pid], [pid]
    while frontier:
        frontier = [child for p in frontier for child in _children_of(p)]
        tree += frontier
    return tree


def _rss_bytes(pids: list) -> int:
    total = 0
    for pid in pids:
        try:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
        except (OSError, ValueError):
            continue
    return total


def _kill_tree(pid: int) -> None:
    for p in reversed(_tree(pid)):
        try:
            os.kill(p, signal.SIGKILL)
        except OSError:
            pass


def _worker_context() -> tuple:
    """(worker, its address, the memory one job may use) inside a Dask worker; (None, host, None) outside."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return None, socket.gethostname(), None
    limit = worker.memory_manager.memory_limit
    return worker, str(worker.address), (limit // max(1, worker.state.nthreads) if limit else None)


def run_job(task: dict) -> dict:
    """One job, on a worker: hash the inputs, run the command in a subprocess, read its outcome.

    Returns the store columns (never raises for a job's failure: that is an outcome). With
    `previous_content_key` equal to this run's key, returns {"unchanged": True, ...} without running."""
    hashes = hash_inputs(task["inputs"])
    key = content_key(task["spec_hash"], hashes)
    base = {"inputs": hashes, "content_key": key, "input_stats": input_stats(task["inputs"])}
    if task.get("previous_content_key") == key:
        return {**base, "unchanged": True}
    worker, where, memory_limit_bytes = _worker_context()
    out_dir, log_path = Path(task["out_dir"]), Path(task["log_path"])
    # The previous run's set (what rscalib wrote there, as its manifest lists, or a commit a killed
    # run left half done) is not this run's answer; the user's own files in the folder stay.
    remove_output_set(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    argv = [*task["argv"], "--out", str(out_dir)]
    env = {**os.environ, **JOB_THREAD_ENV, PARENT_PID_ENV: str(os.getpid())}
    started, started_utc = time.monotonic(), utc_now()
    with open(log_path, "w") as log:
        log.write(f"$ rscalib {shlex.join(argv)}\n")
        log.flush()
        process = subprocess.Popen([sys.executable, "-m", JOB_MODULE, *argv], stdout=log,
                                   stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env)
    if worker is not None:
        worker.log_event(EVENT_TOPIC, {"id": task["id"], "pid": process.pid, "worker": where,
                                       "started_utc": started_utc})
    killed_because, peak_tree_bytes, timeout_s = "", 0, task.get("timeout_s")
    for check in itertools.count():
        pid, status, usage = os.wait4(process.pid, os.WNOHANG)
        if pid:
            break
        time.sleep(POLL_S)
        if check % MEMORY_EVERY:
            continue
        tree_bytes = _rss_bytes(_tree(process.pid))
        peak_tree_bytes = max(peak_tree_bytes, tree_bytes)
        if memory_limit_bytes and tree_bytes > memory_limit_bytes and not killed_because:
            killed_because = (f"memory limit: the job used {tree_bytes / 2**20:.0f} MB, over its "
                              f"{memory_limit_bytes / 2**20:.0f} MB (--memory-limit / --threads-per-worker)")
            _kill_tree(process.pid)
        if timeout_s and time.monotonic() - started > timeout_s and not killed_because:
            killed_because = f"time limit: still running after {timeout_s:g} s (--job-timeout)"
            _kill_tree(process.pid)
    process.returncode = exit_code = os.waitstatus_to_exitcode(status)
    outcome = read_outcome(task["command"], out_dir, None if killed_because else exit_code, log_path, killed_because)
    if killed_because:
        outcome["exit_code"] = exit_code
    peak_bytes = max(usage.ru_maxrss * 1024, peak_tree_bytes)  # ru_maxrss is in KiB on Linux
    return {**base, **outcome, "wall_time_s": time.monotonic() - started, "peak_memory_mb": peak_bytes / 2**20,
            "cpu_time_s": usage.ru_utime + usage.ru_stime,  # the job and its waited-for children
            "worker": where, "pid": process.pid, "started_utc": started_utc, "finished_utc": utc_now()}


def require_dask():
    try:
        import dask  # noqa: F401
        import distributed
    except ImportError:
        raise InputError("rscalib batch runs on Dask, which is not installed: pip install 'rscalib[batch]'") from None
    return distributed


def _client(distributed, scheduler: Optional[str], workers: int, threads_per_worker: int, memory_limit) -> tuple:
    """(client, cluster): a client of the given scheduler (cluster None), or of a LocalCluster of
    `workers` processes started here."""
    import logging

    if scheduler:
        check_scheduler_address(scheduler)
        try:
            return distributed.Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError, ValueError, TypeError) as error:
            raise InputError(f"--scheduler {scheduler}: cannot connect ({one_line(str(error))})") from None
    # A crashed worker's task goes to another worker once; then it is recorded as lost, not retried forever.
    # Dask's own memory management of the workers is off: it would pause, then restart, a worker
    # whose jobs use memory (the jobs are its child processes), and every job on it would be "lost";
    # run_job enforces each job's share of --memory-limit itself and records the job as killed, with why.
    import dask

    dask.config.set({"distributed.scheduler.allowed-failures": 1, "distributed.worker.memory.target": False,
                     "distributed.worker.memory.spill": False, "distributed.worker.memory.pause": False,
                     "distributed.worker.memory.terminate": False})
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker, processes=True,
                                       memory_limit=memory_limit, dashboard_address=None,
                                       silence_logs=logging.ERROR)
    return distributed.Client(cluster), cluster


def check_scheduler_address(address: str) -> None:
    """InputError unless `address` is a Dask scheduler address (tcp://host:port, tls://..., ...);
    checked before anything is written."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port

    try:
        scheme, location = parse_address(str(address), strict=False)
        if scheme not in ("tcp", "tls", "ws", "wss", "ucx", "inproc"):
            raise ValueError(f"unknown address scheme {scheme!r}")
        if scheme != "inproc":
            host, port = parse_host_port(location)
            if not host or not port:
                raise ValueError("no host or port")
    except (ValueError, TypeError) as error:
        raise InputError(f"--scheduler {one_line(str(address))}: not a Dask scheduler address "
                         f"({one_line(str(error))}); give one such as tcp://host:8786") from None


def _written_by_the_batch(store: Optional[ResultStore]) -> set:
    """The files in DIR the batch wrote before, as its store records them (a store of an older
    rscalib recorded none: then what that batch writes is taken as its own)."""
    if store is None:
        return set()
    meta = store.meta()
    if "written_files" not in meta:
        return {INDEX_FILE, PLOT_FILE} | {r["log_path"] for r in store.rows() if r.get("log_path")}
    return set(meta["written_files"])


def claim_files(out: Path, jobs: list, store: Optional[ResultStore]) -> list:
    """The files in DIR the batch is about to write (the jobs' logs, index.html, the plot) and has
    written before; InputError, before anything is written, when one of them is already there and
    the batch did not write it: the user's files in the batch folder are never overwritten. (Job
    folders may hold the user's files: only the previous run's outputs are replaced there.)"""
    written = _written_by_the_batch(store)
    wanted = [f"{LOGS_DIR}/{job.id}.log" for job in jobs] + [INDEX_FILE, PLOT_FILE]
    for name in wanted:
        if os.path.lexists(out / name) and name not in written:
            what = f"the log of job {name[len(LOGS_DIR) + 1:-4]}" if name.startswith(LOGS_DIR) else name
            raise InputError(f"{shown(out / name)}: a file the batch did not write is where it writes {what}; "
                             "move it away (the batch never overwrites files of yours)")
    return sorted(written | set(wanted))


def plan(jobs: list, store: ResultStore, version: str) -> tuple:
    """(to run: [(job, spec_hash, previous row or None)], kept: [job]). A job is kept when its row
    has the command's answer for the same arguments and version and its input files are untouched;
    touched files with the same contents are found by the job itself (content_key) and not re-run."""
    to_run, kept = [], []
    for job in jobs:
        spec = job.spec_hash(version)
        previous = store.row(job.id)
        answered = previous is not None and previous["status"] in ANSWERED and previous["spec_hash"] == spec
        if answered and previous["input_stats"] == input_stats(job.inputs):
            kept.append(job)
        else:
            to_run.append((job, spec, previous if answered else None))
    return to_run, kept


def run_batch(manifest, out_dir, *, resume: bool = False, workers: int = 2, threads_per_worker: int = 1,
              memory_limit="auto", scheduler: Optional[str] = None, timeout_s: Optional[float] = None,
              say: Callable[[str], None] = print, parse_args: Optional[Callable[[list], object]] = None) -> dict:
    """Run every job of `manifest` not already answered in `out_dir`; returns {status: count} over the
    manifest's jobs, and writes DIR/index.html. One driver at a time (store.driver_lock). InputError,
    before anything is written, for a bad manifest or --scheduler, an existing batch without
    `resume`, a results store that is not rscalib's (left untouched), another driver running the
    batch, a file of the user's where the batch writes, no Dask. parse_args: the commands' parser
    (load_manifest checks every row with it; `rscalib batch` passes the CLI's)."""
    jobs = load_manifest(manifest, parse_args=parse_args)
    distributed = require_dask()
    if scheduler:
        check_scheduler_address(scheduler)
    out = Path(out_dir)
    store_path = out / STORE_FILE
    check_store(store_path)   # another program's file, random bytes, a damaged store: refused untouched
    out.mkdir(parents=True, exist_ok=True)
    with driver_lock(out):
        existed = check_store(store_path)
        if existed and not resume:
            raise InputError(f"{out} already holds a batch: add --resume to continue it (jobs whose inputs and "
                             "options are unchanged are not run again), or choose another --out")
        store = ResultStore(store_path) if existed else None
        try:
            to_run, kept = plan(jobs, store, __version__) if store else ([(j, j.spec_hash(__version__), None)
                                                                          for j in jobs], [])
            written = claim_files(out, [job for job, _, _ in to_run], store)
            if store is None:
                store = ResultStore(store_path, create=True)
            store.set_meta(written_files=written)
            return _run_planned(jobs, to_run, kept, store, out, manifest, distributed, workers, threads_per_worker,
                                memory_limit, scheduler, timeout_s, say)
        finally:
            if store is not None:
                store.close()


def _run_planned(jobs, to_run, kept, store, out, manifest, distributed, workers, threads_per_worker, memory_limit,
                 scheduler, timeout_s, say) -> dict:
    try:
        store.set_meta(manifest=str(Path(manifest).resolve()), driver_pid=os.getpid(), driver_host=socket.gethostname(),
                       state="running", started_utc=utc_now(), jobs=[j.id for j in jobs], rscalib_version=__version__)
        say(f"batch: {len(jobs)} jobs, {len(kept)} already done, {len(to_run)} to run")
        previous_rows, tasks = {}, []
        for job, spec, previous in to_run:
            job_out, log_path = out / JOBS_DIR / job.id, out / LOGS_DIR / f"{job.id}.log"
            if previous is not None:
                previous_rows[job.id] = previous
            store.update(job.id, row=job.row, command=job.command, mode=job.mode, argv=list(job.argv), spec_hash=spec,
                         rscalib_version=__version__, status=QUEUED, queued_utc=utc_now(), started_utc=None,
                         out_dir=str(job_out.relative_to(out)), log_path=str(log_path.relative_to(out)))
            tasks.append((job, {"id": job.id, "command": job.command, "argv": list(job.argv), "inputs": list(job.inputs),
                                "spec_hash": spec, "out_dir": str(job_out.resolve()), "log_path": str(log_path.resolve()),
                                "previous_content_key": previous and previous["content_key"], "timeout_s": timeout_s}))
        if tasks:
            _run_tasks(distributed, store, tasks, previous_rows, scheduler, workers, threads_per_worker, memory_limit, say)
        write_index(out, store.rows())
        store.set_meta(state="finished", finished_utc=utc_now())
        counts = {}
        for job in jobs:
            status = store.row(job.id)["status"]
            counts[status] = counts.get(status, 0) + 1
        return counts
    except BaseException:   # an interrupt, or an error such as a scheduler that cannot be reached
        with contextlib.suppress(Exception):
            store.set_meta(state="interrupted", finished_utc=utc_now())
        raise


def _run_tasks(distributed, store, tasks, previous_rows, scheduler, workers, threads_per_worker, memory_limit, say):
    def on_event(event) -> None:  # Dask calls this on its own thread: "job X started on worker Y"
        msg = event[1]
        store.mark_running(msg["id"], worker=msg["worker"], pid=msg["pid"], started_utc=msg["started_utc"])

    batch_tag = uuid.uuid4().hex[:8]  # task keys must be new on a long-lived scheduler
    client, cluster = _client(distributed, scheduler, workers, threads_per_worker, memory_limit)
    try:
        client.subscribe_topic(EVENT_TOPIC, on_event)
        futures = {client.submit(run_job, task, key=f"rscalib-{batch_tag}-{job.id}", pure=False): job
                   for job, task in tasks}
        for done, future in enumerate(distributed.as_completed(futures), start=1):
            job = futures[future]
            try:
                outcome = future.result()
            except Exception as error:  # noqa: BLE001 - the worker died or Dask failed: record it, go on
                outcome = {"status": LOST, "exit_code": None, "reason": f"{type(error).__name__}: {error}",
                           "finished_utc": utc_now()}
            if outcome.pop("unchanged", False):
                previous = previous_rows[job.id]
                outcome = {**outcome, "status": previous["status"], "started_utc": previous["started_utc"]}
                note = "unchanged inputs, not run again"
            else:
                outcome["runs"] = ((store.row(job.id) or {}).get("runs") or 0) + 1
                note = f"{outcome.get('wall_time_s', 0):.1f} s"
            store.update(job.id, **outcome)
            reason = outcome.get("reason") or ""
            say(f"[{done}/{len(tasks)}] {job.id}: {outcome['status']} ({note})" + (f": {reason}" if reason else ""))
        client.unsubscribe_topic(EVENT_TOPIC)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
