"""The results store: one SQLite file, DIR/results.sqlite, a row per job, written as each job finishes.

SQLite because it is one file next to the results, needs no server, takes a reader (`rscalib batch
--status`) while the batch writes (WAL mode), and every commit survives a killed batch: `--resume`
reads it to run only what is missing. Only the batch's driver process writes it (the workers return
their outcome to it), so there is never more than one writer, even on a cluster.
"""
from __future__ import annotations

import contextlib
import json
import os
import socket
import sqlite3
import threading
import time
import urllib.parse
from pathlib import Path
from typing import Iterator, Optional

from ..errors import InputError
from ..io.safe_parse import one_line, shown

STORE_FILE = "results.sqlite"

# A job's status. The first four are the command's own answer (its exit code 0, 4, 3, 2): kept by
# --resume while the inputs are unchanged. The last three are not answers and are run again.
OK, NOT_TRUSTED, UNDETERMINED, BAD_INPUT = "ok", "not_trusted", "undetermined", "bad_input"
FAILED, KILLED, LOST = "failed", "killed", "lost"     # exit 1 / a signal or a limit / the worker died
QUEUED, RUNNING = "queued", "running"
# What --status calls a queued or running job whose driver is gone (never stored: --resume runs it).
INTERRUPTED = "interrupted"
ANSWERED = (OK, NOT_TRUSTED, UNDETERMINED, BAD_INPUT)
NOT_ANSWERED = (FAILED, KILLED, LOST)
STATUS_OF_EXIT_CODE = {0: OK, 4: NOT_TRUSTED, 3: UNDETERMINED, 2: BAD_INPUT}

# column -> SQLite type; JSON columns hold lists or dicts
COLUMNS = {
    "id": "TEXT PRIMARY KEY", "row": "INTEGER", "command": "TEXT", "mode": "TEXT",
    "argv": "TEXT",               # JSON: the single command's arguments (without --out)
    "inputs": "TEXT",             # JSON: [{path, bytes, sha256}] as hashed by the job
    "input_stats": "TEXT",        # JSON: [[path, bytes, mtime_ns]]: the quick "unchanged?" check
    "spec_hash": "TEXT",          # command + arguments + version
    "content_key": "TEXT",        # spec_hash + the inputs' sha256: "the same job on the same data"
    "rscalib_version": "TEXT", "status": "TEXT", "exit_code": "INTEGER", "reason": "TEXT", "verdict": "TEXT",
    "value_name": "TEXT", "value": "REAL", "value_std": "REAL",   # the headline number and its sigma
    "headline": "TEXT",           # JSON: the command's main numbers with their sigmas
    "wall_time_s": "REAL", "cpu_time_s": "REAL", "peak_memory_mb": "REAL", "worker": "TEXT", "pid": "INTEGER",
    "queued_utc": "TEXT", "started_utc": "TEXT", "finished_utc": "TEXT",
    "runs": "INTEGER",            # how many times this job has been run in this folder
    "out_dir": "TEXT", "log_path": "TEXT",
}
JSON_COLUMNS = ("argv", "inputs", "input_stats", "headline")


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


SQLITE_HEADER = b"SQLite format 3\0"


def _damaged(path: Path, error: Exception) -> InputError:
    return InputError(f"{shown(path)}: not a readable rscalib batch store ({error}); rscalib leaves it as it is")


def _check_ours(db: sqlite3.Connection, path: Path) -> None:
    """InputError unless the database holds rscalib's jobs and meta tables (any other SQLite file
    is somebody else's and is not touched)."""
    try:
        tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        columns = {r[1] for r in db.execute("PRAGMA table_info(jobs)")} if "jobs" in tables else set()
    except sqlite3.DatabaseError as error:
        raise _damaged(path, error) from None
    if "meta" not in tables or not {"id", "status", "argv"} <= columns:
        raise InputError(f"{shown(path)}: a SQLite file that is not an rscalib batch store (no jobs and meta tables "
                         f"of rscalib); rscalib leaves it as it is: choose another --out")


def _read_only_connection(path: Path) -> sqlite3.Connection:
    """A connection that changes nothing: `immutable` (no -wal or -shm file is made) unless a
    write-ahead log is there (a driver is running, or was killed) to be read with `mode=ro`."""
    uri = "file:" + urllib.parse.quote(str(path.resolve()))
    last = None
    pending = os.path.exists(f"{path}-wal")
    for query in ("?mode=ro", "?immutable=1") if pending else ("?immutable=1",):
        try:
            db = sqlite3.connect(uri + query, uri=True, timeout=30, check_same_thread=False)
            db.execute("SELECT name FROM sqlite_master LIMIT 1").fetchall()
            return db
        except sqlite3.DatabaseError as error:
            last = error
    raise _damaged(path, last)


def check_store(path) -> bool:
    """Before anything is written: False when there is no store at `path` (or an empty file: a
    driver killed as it created it), True when it is an rscalib store; InputError, leaving the
    file untouched, for anything else (another program's SQLite file, random bytes, a damaged store)."""
    path = Path(path)
    if not os.path.lexists(path):
        return False
    if not path.is_file():
        raise InputError(f"{shown(path)}: is not a file; rscalib's batch store must be a file")
    try:
        with open(path, "rb") as handle:
            header = handle.read(len(SQLITE_HEADER))
    except OSError as error:
        raise InputError(f"{shown(path)}: cannot read it ({error.strerror or error})") from None
    if not header:
        return False
    if header != SQLITE_HEADER:
        raise InputError(f"{shown(path)}: not an rscalib batch store (not a SQLite file); rscalib leaves it as it "
                         "is: choose another --out")
    db = _read_only_connection(path)
    try:
        _check_ours(db, path)
        db.execute("SELECT COUNT(*) FROM jobs").fetchone()
        integrity = db.execute("PRAGMA quick_check").fetchone()
    except sqlite3.DatabaseError as error:
        raise _damaged(path, error) from None
    finally:
        db.close()
    if not integrity or integrity[0] != "ok":
        raise _damaged(path, f"integrity check: {integrity[0] if integrity else 'no answer'}")
    return True


class ResultStore:
    """DIR/results.sqlite. Thread-safe within one process (Dask's event callbacks write from its loop).

    create: make the store when there is none (the driver); read_only: never write (--status,
    which must not change a store, nor take a lock a driver needs). A file that is not an rscalib
    store is refused untouched (check_store)."""

    def __init__(self, path, create: bool = False, read_only: bool = False):
        self.path = Path(path)
        exists = check_store(self.path)
        if not exists and (read_only or not create):
            raise InputError(f"no batch results in {shown(self.path.parent)} ({STORE_FILE} not found)")
        self._lock = threading.Lock()
        self.read_only = read_only
        if read_only:
            self._db = _read_only_connection(self.path)
            self._db.row_factory = sqlite3.Row
            return
        for what in ([self.path] if exists else []) + [self.path.parent]:
            if not os.access(what, os.W_OK):
                raise InputError(f"{shown(what)}: read-only; the batch store must be writable (--status reads it)")
        try:
            self._db = sqlite3.connect(str(self.path), timeout=30, check_same_thread=False)
            self._db.row_factory = sqlite3.Row
            with self._lock, self._db:
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("CREATE TABLE IF NOT EXISTS jobs ("
                                 + ", ".join(f'"{c}" {t}' for c, t in COLUMNS.items()) + ")")
                self._db.execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT)")
                present = {r[1] for r in self._db.execute("PRAGMA table_info(jobs)")}
                for column in COLUMNS.keys() - present:  # a store written by an older rscalib: add what is new
                    self._db.execute(f'ALTER TABLE jobs ADD COLUMN "{column}" {COLUMNS[column]}')
        except sqlite3.DatabaseError as error:
            raise _damaged(self.path, error) from None

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def _decode(self, row: sqlite3.Row) -> dict:
        record = dict(row)
        for column in JSON_COLUMNS:
            if record.get(column) is not None:
                record[column] = json.loads(record[column])
        return record

    def row(self, job_id: str) -> Optional[dict]:
        with self._lock:
            found = self._db.execute('SELECT * FROM jobs WHERE id = ?', (job_id,)).fetchone()
        return self._decode(found) if found else None

    def rows(self) -> list:
        with self._lock:
            found = self._db.execute('SELECT * FROM jobs ORDER BY "row", id').fetchall()
        return [self._decode(r) for r in found]

    def update(self, job_id: str, **values) -> None:
        """Insert or update the job's row with these columns (a commit each: a kill loses nothing written)."""
        unknown = set(values) - set(COLUMNS)
        if unknown:
            raise KeyError(f"not a results column: {sorted(unknown)}")
        values = {k: (json.dumps(v) if k in JSON_COLUMNS and v is not None else v) for k, v in values.items()}
        names = ", ".join(f'"{k}"' for k in values)
        marks = ", ".join("?" for _ in values)
        updates = ", ".join(f'"{k}" = excluded."{k}"' for k in values)
        with self._lock, self._db:
            self._db.execute(f'INSERT INTO jobs (id, {names}) VALUES (?, {marks}) '
                             f'ON CONFLICT(id) DO UPDATE SET {updates}', (job_id, *values.values()))

    def mark_running(self, job_id: str, **values) -> None:
        """queued -> running (an event from the worker); never over a row that has already finished."""
        sets = ", ".join(f'"{k}" = ?' for k in values)
        with self._lock, self._db:
            self._db.execute(f'UPDATE jobs SET status = ?, {sets} WHERE id = ? AND status = ?',
                             (RUNNING, *values.values(), job_id, QUEUED))

    def set_meta(self, **values) -> None:
        with self._lock, self._db:
            self._db.executemany("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)",
                                 [(k, json.dumps(v)) for k, v in values.items()])

    def meta(self) -> dict:
        with self._lock:
            found = self._db.execute("SELECT key, value FROM meta").fetchall()
        return {k: json.loads(v) for k, v in found}

    def counts(self) -> dict:
        """status -> number of jobs."""
        with self._lock:
            found = self._db.execute("SELECT status, COUNT(*) FROM jobs GROUP BY status").fetchall()
        return {status: n for status, n in found}


# -- one driver at a time ------------------------------------------------------------------------------

DRIVER_LOCK = ".rscalib-batch.lock"
# A second driver waits this long for the lock before it is refused: --status takes a shared lock
# for a moment to tell whether a driver is alive.
DRIVER_LOCK_WAIT_S = 2.0


@contextlib.contextmanager
def driver_lock(out_dir) -> Iterator[None]:
    """Held by the batch's driver for its whole run (flock on DIR/.rscalib-batch.lock: the kernel
    releases it when the driver dies, however it dies, so a killed driver leaves no stale lock).
    InputError naming the driver that holds it when another one is running this batch."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    path = Path(out_dir) / DRIVER_LOCK
    try:
        handle = open(path, "a+")
    except OSError as error:
        raise InputError(f"{shown(path)}: cannot lock the batch ({error.strerror or error})") from None
    try:
        deadline = time.monotonic() + DRIVER_LOCK_WAIT_S
        while True:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    handle.seek(0)
                    holder = handle.read(300).strip() or "a driver"
                    raise InputError(f"{shown(out_dir)}: another rscalib batch is running this batch ({one_line(holder)}); "
                                     "one driver at a time: wait for it to end or stop it") from None
                time.sleep(0.05)
        handle.seek(0)
        handle.truncate()
        handle.write(f"pid {os.getpid()} on {socket.gethostname()} since {utc_now()}\n")
        handle.flush()
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
    finally:
        handle.close()


def driver_running(out_dir) -> Optional[bool]:
    """Whether a driver holds DIR's lock now (None: no lock file to tell, e.g. a batch of an older
    rscalib). Reads only: a shared lock taken for a moment, on a file opened read-only."""
    try:
        import fcntl
    except ImportError:
        return None
    try:
        fd = os.open(Path(out_dir) / DRIVER_LOCK, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return None
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)
