"""The commit of an output set, carried out by a process of its own (io/output_folder.py).

Standard library only, so that `python -I -S _commit.py OUT` starts in milliseconds: output_set
writes the plan of a commit (JOURNAL) and runs this file in a new session to carry it out while it
waits. Killing the command (SIGKILL, Ctrl-C or a signal to its process group) then does not stop
the renames half-way: the helper finishes them in milliseconds, holding the folder's lock (it
inherits the command's lock file descriptor). Only killing this helper itself, or a power cut,
leaves a commit half done; the command, if alive, then finishes it itself, else the next run into
the folder does (output_folder.recover_output_folder), from the same plan: every step of
roll_forward can be done again.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import sys
from pathlib import Path

MANIFEST = ".rscalib-outputs.json"
LOCK = ".rscalib-lock"
JOURNAL = ".rscalib-commit.json"   # the plan of a commit under way
STAGING_PREFIX = ".rscalib-staging-"


def plain_names(names) -> list:
    """Plain names in the folder only: a damaged manifest or journal must not point outside it."""
    return [n for n in names if isinstance(n, str) and n not in ("", ".", "..", MANIFEST, JOURNAL, LOCK)
            and "/" not in n and "\\" not in n and "\0" not in n and not n.startswith(STAGING_PREFIX)]


def write_atomic(path: Path, text: str) -> None:
    """`path` holds `text` whole or not at all (a temporary file, flushed to disk, renamed)."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        data = memoryview(text.encode())
        while data:
            data = data[os.write(fd, data):]
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def write_manifest(out: Path, names) -> None:
    write_atomic(out / MANIFEST, json.dumps({"written_by": "rscalib", "files": sorted(set(names))}, indent=1) + "\n")


def sync_folder(folder: Path) -> None:
    """Make the renames in `folder` durable (a power cut after the commit keeps it)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.unlink(path)


def read_journal(out: Path) -> dict:
    """The plan of the commit under way, its names checked (plain names inside `out`)."""
    plan = json.loads((out / JOURNAL).read_text())
    if not isinstance(plan, dict):
        raise ValueError("not a plan")
    staging, last = plan.get("staging"), plan.get("last")
    if not (isinstance(staging, str) and staging.startswith(STAGING_PREFIX) and "/" not in staging
            and "\\" not in staging and "\0" not in staging):
        raise ValueError("not a staging folder")
    return {"staging": staging, "new": plain_names(plan.get("new") or []),
            "remove": plain_names(plan.get("remove") or []), "last": (plain_names([last]) or [None])[0]}


def roll_forward(out: Path, plan: dict) -> None:
    """Carry out a commit's plan; each step can be done again (a commit killed half-way is finished
    by doing it all over)."""
    staging, last = out / plan["staging"], plan["last"]
    if last is not None and os.path.lexists(staging / last):
        remove(out / last)   # while the files move, the folder must not look complete
    for name in plan["new"]:
        source = staging / name
        if name == last or not os.path.lexists(source):
            continue
        target = out / name
        if target.is_dir() and not target.is_symlink():
            remove(target)   # a folder of the previous run (checked when planned)
        os.replace(source, target)
    for name in plan["remove"]:
        remove(out / name)
    write_manifest(out, plan["new"])
    if last is not None and os.path.lexists(staging / last):
        os.replace(staging / last, out / last)
    sync_folder(out)
    os.unlink(out / JOURNAL)
    shutil.rmtree(staging, ignore_errors=True)


def main(argv: list) -> int:
    """`python -I -S _commit.py OUT`: roll the plan in OUT/JOURNAL forward; signals that end a
    command (SIGINT, SIGTERM, SIGHUP) are ignored. Exit 0, or 1 with one line on stderr."""
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_IGN)
    out = Path(argv[1])
    try:
        plan = read_journal(out)
        roll_forward(out, plan)
    except (OSError, ValueError) as error:
        name = getattr(error, "filename", None)
        reason = getattr(error, "strerror", None) or str(error)
        sys.stderr.write((f"{name}: {reason}" if name else reason).replace("\n", " ") + "\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
