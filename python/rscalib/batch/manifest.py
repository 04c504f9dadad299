"""The batch manifest: one job per row (CSV) or per entry (YAML), read into the argv of a single command.

A row has `command` (linedelay, intrinsics, flicker, selfcalib), `input` (the command's video, image folder
or, for intrinsics, several separated by ';'), optional `id` (default: command and input path), optional
`mode` (the camera mode the summary groups by), optional `args` (raw extra flags) and any option of the
command by its flag name (`target`, `camera`, `frequency`, `pixel-size-mm`...). Relative paths are
relative to the manifest's folder. YAML may give `defaults:` shared by every job of `jobs:`.

Every row is checked with the command's own parser before anything runs, so a typo is one line
(exit 2) naming the file, row and field, not a failed job an hour later.
"""
from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from ..errors import InputError
from ..io.safe_parse import load_yaml, one_line, read_text

# command -> its options that name input files (hashed and resolved like `input`)
INPUT_OPTIONS = {"linedelay": ("target", "camera"), "intrinsics": ("target",), "flicker": (), "selfcalib": ()}
COMMANDS = tuple(INPUT_OPTIONS)
PATH_OPTIONS = ("target", "camera", "cache-dir")    # resolved against the manifest's folder
RESERVED = ("out", "quiet")                         # the batch sets these
META_FIELDS = ("id", "command", "input", "mode", "args")
# Commands whose detection starts a process per core unless told: in a batch the jobs are the parallelism.
DETECTION_COMMANDS = ("linedelay", "intrinsics")
_ID_CHARS = re.compile(r"[^A-Za-z0-9._-]+")
# 10 000 jobs of a few hundred bytes each are a few MB; a larger file is refused before it is read.
MANIFEST_MAX_BYTES = 64 * 2 ** 20
# YAML is read by pure Python (seconds per MB): a YAML manifest of ~20 000 jobs; larger ones as CSV.
MANIFEST_YAML_MAX_BYTES = 4 * 2 ** 20


@dataclass(frozen=True)
class Job:
    """One row: the single command `rscalib <argv> --out <folder>` and what identifies it."""

    id: str
    row: int                 # 1-based, in manifest order
    command: str
    mode: str                # camera mode for the summary ("" when not given)
    inputs: tuple            # absolute paths of every input file or folder (input, target, camera)
    argv: tuple              # the single command's arguments without --out (ends with --quiet)

    def command_argv(self, out_dir) -> list:
        return [*self.argv, "--out", str(out_dir)]

    def spec_hash(self, version: str) -> str:
        """What the job is, without the inputs' contents: command, arguments (absolute paths), version."""
        text = json.dumps({"argv": list(self.argv), "version": version}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()


def load_manifest(path, parse_args: Optional[Callable[[list], object]] = None) -> list:
    """Jobs of a CSV or YAML manifest; InputError naming the file, row and field on any problem.
    parse_args: the commands' argument parser (argparse's parse_args of `rscalib`); with it every row
    is checked as the command would check it (`rscalib batch` passes the CLI's; batch never imports
    cli), without it only the manifest's own fields are."""
    try:
        return _load_manifest(Path(path), parse_args)
    except InputError as error:
        raise InputError(one_line(str(error))) from None


def _load_manifest(path: Path, parse_args) -> list:
    if not path.is_file():
        raise InputError(f"manifest not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        rows = _csv_rows(path)
    elif suffix in (".yaml", ".yml"):
        rows = _yaml_rows(path)
    else:
        raise InputError(f"{path}: a manifest is a .csv or .yaml file")
    if not rows:
        raise InputError(f"{path}: no jobs")
    jobs, seen = [], {}
    for number, (where, fields) in enumerate(rows, start=1):
        job = _job(path, number, where, fields, parse_args)
        if job.id in seen:
            raise InputError(f"{path}: {where}: field 'id': '{job.id}' is also the id of row {seen[job.id]}"
                             + ("" if "id" in fields else " (give each row an id)"))
        seen[job.id] = number
        jobs.append(job)
    return jobs


def _text(path: Path) -> str:
    """The manifest's text: UTF-8, with or without the byte-order mark spreadsheet programs write."""
    try:
        return read_text(path, MANIFEST_MAX_BYTES, "manifest", encoding="utf-8-sig", errors="strict")
    except InputError as error:
        if "not UTF-8" in str(error):
            raise InputError(f"{error}; a manifest is a .csv or .yaml text file") from None
        raise


def _field_name(name: str) -> str:
    """A column or key as the manifest means it: `--pixel_size_mm ` is `pixel-size-mm`."""
    return name.strip().lstrip("-").replace("_", "-")


def _csv_rows(path: Path) -> list:
    reader = csv.DictReader(io.StringIO(_text(path), newline=""))
    try:
        if not reader.fieldnames or "command" not in [n.strip() for n in reader.fieldnames]:
            raise InputError(f"{path}: line 1: the header needs a 'command' column (and 'input')")
        seen = {}
        for column, name in enumerate(reader.fieldnames, start=1):
            key = _field_name(name)
            if key and key in seen:
                raise InputError(f"{path}: line 1: column {column} '{name.strip()}' repeats column {seen[key]} "
                                 f"'{reader.fieldnames[seen[key] - 1].strip()}' (one column per field)")
            seen[key] = column
        rows = []
        for record in reader:
            if None in record:
                raise InputError(f"{path}: line {reader.line_num}: more cells than header columns")
            fields = {k.strip(): (v or "").strip() for k, v in record.items()}
            if any(fields.values()):
                rows.append((f"row {len(rows) + 1} (line {reader.line_num})", fields))
    except csv.Error as error:
        raise InputError(f"{path}: line {reader.line_num}: not CSV ({error})") from None
    return rows


def _yaml_rows(path: Path) -> list:
    # aliases are allowed (a manifest may share values with &name / *name), within a size budget
    data = load_yaml(_text(path), path, aliases=True, max_bytes=MANIFEST_YAML_MAX_BYTES)
    defaults = {}
    if isinstance(data, dict):
        defaults = data.get("defaults") or {}
        data = data.get("jobs")
        if not isinstance(defaults, dict):
            raise InputError(f"{path}: field 'defaults': a mapping of fields shared by every job")
    if not isinstance(data, list):
        raise InputError(f"{path}: a list of jobs, or a mapping with 'jobs:' (and optional 'defaults:')")
    rows = []
    for number, entry in enumerate(data, start=1):
        if not isinstance(entry, dict):
            raise InputError(f"{path}: row {number}: a job is a mapping of fields (command, input, ...)")
        rows.append((f"row {number}", {**{str(k): v for k, v in defaults.items()},
                                       **{str(k): v for k, v in entry.items()}}))
    return rows


def _is_blank(value) -> bool:
    return value is None or (isinstance(value, str) and not value.strip())


def _resolve(base: Path, value) -> str:
    path = Path(str(value))
    try:
        path = path.expanduser()
    except RuntimeError:  # ~user of no such user: a plain name
        pass
    return str((base / path).resolve())


def _option_args(flag: str, value, is_path: bool, base: Path) -> list:
    """One manifest field -> its command-line words. true/false are flags; lists are several values."""
    if isinstance(value, bool) or (isinstance(value, str) and value.strip().lower() in ("true", "false")):
        return [flag] if value is True or str(value).strip().lower() == "true" else []
    if isinstance(value, (list, tuple)):
        return [flag, *(str(v) for v in value)]
    if is_path:
        return [flag, _resolve(base, value)]
    if isinstance(value, str):
        return [flag, *shlex.split(value)]
    return [flag, str(value)]


def _job(path: Path, number: int, where: str, fields: dict, parse_args) -> Job:
    base = path.parent

    def bad(field: str, message: str) -> InputError:
        return InputError(f"{path}: {where}: field '{field}': {message}")

    fields = {_field_name(k): v for k, v in fields.items() if k is not None}
    for name, value in fields.items():
        if "\0" in str(value):
            raise bad(name, "has a NUL character (not a path or a value)")
    command = str(fields.get("command") or "").strip()
    if command not in INPUT_OPTIONS:
        raise bad("command", f"'{command}' is not one of {', '.join(COMMANDS)}" if command else "missing")
    raw_input = fields.get("input")
    if _is_blank(raw_input):
        raise bad("input", "missing (the video, image folder or stills of this job)")
    items = raw_input if isinstance(raw_input, list) else str(raw_input).split(";")
    if isinstance(raw_input, dict) or not all(isinstance(item, (str, int, float)) for item in items):
        raise bad("input", f"a path, or a list of paths for intrinsics, not {raw_input!r}")
    inputs = [_resolve(base, item.strip() if isinstance(item, str) else item) for item in items
              if not _is_blank(item)]
    if len(inputs) > 1 and command != "intrinsics":
        raise bad("input", f"{command} takes one video or image folder (got {len(inputs)})")
    argv = [command, *inputs]
    input_paths = list(inputs)
    for name, value in fields.items():
        if name in META_FIELDS or _is_blank(value):
            continue
        if name in RESERVED:
            raise bad(name, "is set by the batch (each job writes to DIR/jobs/<id>/)")
        if isinstance(value, dict) or (isinstance(value, (list, tuple))
                                       and not all(isinstance(v, (str, int, float)) for v in value)):
            raise bad(name, f"a value or a list of values, not {value!r}")
        words = _option_args(f"--{name}", value, name in PATH_OPTIONS, base)
        argv += words
        if name in INPUT_OPTIONS[command] and len(words) == 2:
            input_paths.append(words[1])
    if not _is_blank(fields.get("args")):
        argv += shlex.split(str(fields["args"]))
    if command in DETECTION_COMMANDS and "--workers" not in argv:
        argv += ["--workers", "1"]
    argv.append("--quiet")
    if parse_args is not None:
        _check_with_parser(argv, bad, parse_args)
    job_id = str(fields.get("id") or "").strip()
    if job_id:
        if _ID_CHARS.search(job_id) or job_id.startswith("."):
            raise bad("id", f"'{job_id}' must be letters, digits, '.', '_' or '-' (it names a folder)")
    else:
        stem = "-".join(Path(p).with_suffix("").name for p in inputs[:1])
        parent = Path(inputs[0]).parent.name if inputs else ""
        job_id = _ID_CHARS.sub("_", f"{command}-{parent}-{stem}" if parent else f"{command}-{stem}")
    mode = "" if _is_blank(fields.get("mode")) else str(fields["mode"]).strip()
    return Job(job_id, number, command, mode, tuple(input_paths), tuple(argv))


def _check_with_parser(argv: list, bad, parse_args: Callable[[list], object]) -> None:
    """Parse the row with the command's own parser; its complaint becomes one line naming the field."""
    messages = io.StringIO()
    try:
        with contextlib.redirect_stderr(messages), contextlib.redirect_stdout(io.StringIO()):
            parse_args([*argv, "--out", "."])
    except SystemExit:
        text = messages.getvalue().strip().splitlines()
        message = text[-1].split("error: ", 1)[-1] if text else "not accepted by the command"
        flag = re.search(r"--([A-Za-z0-9-]+)", message)  # the option argparse names, if any
        raise bad(flag.group(1) if flag else "input", message) from None
