"""The one writer of result.json: every command's summary plus the version and provenance that
let a reader tell which code, on what input, made it: the command line, each input file with its
SHA-256, the camera and target as rscalib read them, and the rows read out."""
from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import platform
import shlex
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Optional

from .._version import __version__
from ..errors import InputError
from .cameras import load_camera
from .targets import load_target

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


_command_line: Optional[list] = None


def set_command_line(argv: Optional[list]) -> None:
    """The command line the provenance records (the CLI sets it; None for the Python API)."""
    global _command_line
    _command_line = None if argv is None else [str(a) for a in argv]


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def file_record(path) -> Optional[dict]:
    """{path, bytes, sha256} of a file; for a folder, the files in it (not below) and one SHA-256
    over their names and contents; None when nothing is there."""
    path = Path(path)
    if path.is_file():
        return {"path": str(path), "bytes": path.stat().st_size, "sha256": _sha256(path)}
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
        digest = hashlib.sha256()
        for p in files:
            digest.update(f"{p.name}\0{_sha256(p)}\n".encode())
        return {"path": str(path), "files": len(files), "bytes": sum(p.stat().st_size for p in files),
                "sha256": digest.hexdigest()}
    return None


def _paths(value) -> list:
    if isinstance(value, (list, tuple)):
        return [v for item in value for v in _paths(item)]
    if isinstance(value, (str, Path)) and str(value) and len(str(value)) < 4096:
        return [value]
    return []


def _as_read(role: str, path) -> Optional[dict]:
    """The camera or target of an input file as rscalib reads it (None for other roles)."""
    try:
        if role == "camera":
            read = load_camera(path)
            return {"format": read.source_format, "model": read.camera.model,
                    "params": list(read.camera.params), "param_names": list(read.camera.param_names),
                    "width": int(read.camera.width), "height": int(read.camera.height),
                    "line_delay_s": read.line_delay_s}
        if role == "target":
            with warnings.catch_warnings():   # the command has warned about this file already
                warnings.simplefilter("ignore")
                return load_target(path).kalibr_dict()
    except InputError as error:
        return {"error": str(error)}
    return None


def provenance(command: str, inputs: Optional[dict] = None, rows: Optional[int] = None) -> dict:
    """Which code made a result, when, on what: version, command (and command line), the inputs as
    given, each input file's SHA-256, the camera and target as read, the rows read out (if the
    command has them), Python and platform."""
    inputs = inputs if isinstance(inputs, dict) else ({"inputs": inputs} if inputs else {})
    files, as_read = {}, {}
    for role, value in inputs.items():
        records = [r for r in (file_record(p) for p in _paths(value)) if r is not None]
        if records:
            files[role] = records[0] if len(records) == 1 and not isinstance(value, (list, tuple)) else records
        if role in ("camera", "target") and isinstance(value, (str, Path)) and Path(value).is_file():
            as_read[role] = _as_read(role, value)
    record = {"rscalib_version": __version__, "command": command,
              "command_line": shlex.join(_command_line) if _command_line else None,
              "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "inputs": _plain(inputs), "input_files": _plain(files)}
    for role, value in as_read.items():
        record[f"{role}_as_read"] = _plain(value)
    if rows is not None:
        record["rows"] = int(rows)
    record |= {"python": platform.python_version(), "platform": f"{sys.platform}-{platform.machine()}"}
    return record


def write_result_json(out_dir, summary: dict, command: str, inputs: Optional[dict] = None) -> Path:
    """Write out_dir/result.json: `summary` with a "provenance" entry; atomically, so a reader never
    sees half a file and an interrupted run leaves the previous result whole."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = summary.get("rows") if isinstance(summary.get("rows"), numbers.Integral) else None
    data = _plain({**summary, "provenance": provenance(command, inputs, rows)})
    path = out / RESULT_FILE
    tmp = out / f".{RESULT_FILE}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)
    return path
