"""The one writer of result.json: every command's summary plus the version and provenance that
let a reader tell which code, on what input, made it."""
from __future__ import annotations

import json
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any, Optional

from .._version import __version__

RESULT_FILE = "result.json"


def _plain(value: Any) -> Any:
    """JSON-safe: non-finite floats become null (NaN/Infinity are not JSON); NumPy scalars and
    arrays become Python numbers and lists; paths become strings."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):  # NumPy scalar or array
        return _plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def provenance(command: str, inputs: Optional[dict] = None) -> dict:
    """Which code made a result, when, on what: version, command, inputs, Python, platform."""
    return {"rscalib_version": __version__, "command": command,
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "inputs": _plain(inputs or {}), "python": platform.python_version(),
            "platform": f"{sys.platform}-{platform.machine()}"}


def write_result_json(out_dir, summary: dict, command: str, inputs: Optional[dict] = None) -> Path:
    """Write out_dir/result.json: `summary` with a "provenance" entry; atomically, so a reader never
    sees half a file and an interrupted run leaves the previous result whole."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = _plain({**summary, "provenance": provenance(command, inputs)})
    path = out / RESULT_FILE
    tmp = out / f".{RESULT_FILE}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)
    return path
