"""What a finished job says: its status, headline number with sigma, verdict and reason, read from
the exit code, the job's result.json (its verdict block, the same for every command) and its log —
the same files a user of the single command reads."""
from __future__ import annotations

import json
import signal
from pathlib import Path
from typing import Optional

from ..io.results import RESULT_FILE
from ..verdict import Verdict
from .store import FAILED, KILLED, STATUS_OF_EXIT_CODE


def _from_verdict(result: dict) -> Optional[dict]:
    """The store's columns from a result.json's verdict block (every command writes the same one:
    rscalib.verdict.Verdict); None when the block is missing or not one."""
    try:
        verdict = Verdict.from_dict(result.get("verdict"))
    except ValueError:
        return None
    return {"value_name": verdict.quantity or None, "value": verdict.value, "value_std": verdict.std,
            "headline": verdict.to_dict(), "verdict": verdict.status, "reason": "; ".join(verdict.reasons)}


def error_line(log_path) -> str:
    """The command's one-line reason: its last 'error:' line, else the log's last line."""
    try:
        lines = [line.strip() for line in Path(log_path).read_text(errors="replace").splitlines() if line.strip()]
    except OSError:
        return ""
    errors = [line for line in lines if "error:" in line]
    return (errors or lines or [""])[-1]


def _signal_name(exit_code: Optional[int]) -> str:
    try:
        return signal.Signals(-exit_code).name
    except (TypeError, ValueError):
        return "a signal"


def read_outcome(command: str, out_dir, exit_code: Optional[int], log_path, killed_because: str = "") -> dict:
    """Store columns for a job that ended with `exit_code` (None: killed, `killed_because` says why)."""
    if exit_code is None or exit_code < 0:
        return {"status": KILLED, "exit_code": exit_code, "reason": killed_because or f"killed by {_signal_name(exit_code)}"}
    status = STATUS_OF_EXIT_CODE.get(exit_code, FAILED)
    record = {"status": status, "exit_code": exit_code, "reason": ""}
    result = None
    path = Path(out_dir) / RESULT_FILE
    if exit_code != 2 and path.is_file():  # a bad-input run may leave nothing, or a stale half
        try:
            result = json.loads(path.read_text())
        except (OSError, ValueError):
            result = None
    columns = None if result is None else _from_verdict(result)
    if columns is not None:
        if exit_code not in (3, 4):
            columns["reason"] = ""
        record.update(columns)
    if exit_code not in (0, 3, 4) or not record["reason"] and exit_code != 0:
        record["reason"] = error_line(log_path)
    return record
