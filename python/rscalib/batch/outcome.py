"""What a finished job says: its status, headline number with sigma, verdict and reason, read from
the exit code, the job's result.json and its log — the same files a user of the single command reads."""
from __future__ import annotations

import json
import math
import signal
from pathlib import Path
from typing import Optional

from ..io.results import RESULT_FILE
from .store import FAILED, KILLED, STATUS_OF_EXIT_CODE

Z_99 = 2.5758293035489  # two-sided 99 % of a normal: selfcalib's bounds are +-Z_99 sigma


def _number(value) -> Optional[float]:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def _linedelay(result: dict) -> tuple:
    verdict = result.get("verdict") or {}
    headline = {k: result.get(k) for k in ("line_delay_s", "line_delay_std_s", "readout_time_s", "normalised_cost",
                                           "rms_px", "frames_used", "observations")}
    return "line_delay_s", result.get("line_delay_s"), result.get("line_delay_std_s"), headline, \
        verdict.get("status"), "; ".join(verdict.get("reasons") or [])


def _flicker(result: dict) -> tuple:
    headline = {k: result.get(k) for k in ("line_delay_s", "line_delay_std_s", "readout_time_s", "method",
                                           "frames_used", "readout_direction")}
    return "line_delay_s", result.get("line_delay_s"), result.get("line_delay_std_s"), headline, \
        "determined" if result.get("determined") else "undetermined", result.get("reason") or ""


def _selfcalib(result: dict) -> tuple:
    headline = {}
    for name in ("f", "cx", "cy", "k1", "k2"):
        headline[name] = result.get(name)
        headline[f"{name}_bounds_99"] = result.get(f"{name}_bounds_99")
    bounds = result.get("f_bounds_99") or [None, None]
    sigma = (bounds[1] - bounds[0]) / (2 * Z_99) if None not in bounds else None
    return "f_px", result.get("f"), sigma, headline, \
        "determined" if result.get("determined") else "undetermined", result.get("reason") or ""


def _intrinsics(result: dict) -> tuple:
    parameters, std = result.get("parameters") or {}, result.get("std") or {}
    headline = {"model": result.get("model"), "rms_px": result.get("rms_px"), "views_used": result.get("views_used"),
                **{k: v for k, v in parameters.items()}, **{f"{k}_std": v for k, v in std.items()}}
    return "fx_px", parameters.get("fx"), std.get("fx"), headline, "calibrated", "; ".join(result.get("warnings") or [])


HEADLINES = {"linedelay": _linedelay, "flicker": _flicker, "selfcalib": _selfcalib, "intrinsics": _intrinsics}


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
    if result is not None:
        value_name, value, value_std, headline, verdict, reason = HEADLINES[command](result)
        record.update(value_name=value_name, value=_number(value), value_std=_number(value_std), headline=headline,
                      verdict=verdict, reason=reason if exit_code in (3, 4) else "")
    if exit_code not in (0, 3, 4) or not record["reason"] and exit_code != 0:
        record["reason"] = error_line(log_path)
    return record
