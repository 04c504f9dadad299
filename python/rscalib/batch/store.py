"""The results store: one SQLite file, DIR/results.sqlite, a row per job, written as each job finishes.

SQLite because it is one file next to the results, needs no server, takes a reader (`rscalib batch
--status`) while the batch writes (WAL mode), and every commit survives a killed batch: `--resume`
reads it to run only what is missing. Only the batch's driver process writes it (the workers return
their outcome to it), so there is never more than one writer, even on a cluster.
"""
from __future__ import annotations

import json
import sqlite3
import threading
import time
from pathlib import Path
from typing import Optional

from ..errors import InputError

STORE_FILE = "results.sqlite"

# A job's status. The first four are the command's own answer (its exit code 0, 4, 3, 2): kept by
# --resume while the inputs are unchanged. The last three are not answers and are run again.
OK, NOT_TRUSTED, UNDETERMINED, BAD_INPUT = "ok", "not_trusted", "undetermined", "bad_input"
FAILED, KILLED, LOST = "failed", "killed", "lost"     # exit 1 / a signal or a limit / the worker died
QUEUED, RUNNING = "queued", "running"
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


class ResultStore:
    """DIR/results.sqlite. Thread-safe within one process (Dask's event callbacks write from its loop)."""

    def __init__(self, path, create: bool = False):
        self.path = Path(path)
        if not create and not self.path.is_file():
            raise InputError(f"no batch results in {self.path.parent} ({STORE_FILE} not found)")
        self._lock = threading.Lock()
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
