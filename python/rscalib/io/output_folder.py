"""The output folder of a command: checked before any work starts, written as a set.

- check_output_folder: --out must be a folder rscalib can create or write in, on a real file
  system (not /proc, /sys, /dev), with room for the expected outputs, and not an input folder;
  otherwise InputError (exit 2) before detection or solving starts. Given the command, the folder
  must also be its own: one that holds another command's results (its result.json's provenance, a
  batch store, a simulation's truth.json) is refused unless forced: their files would mix.
- output_set: a writer writes into a hidden staging folder inside the output folder; on success the
  set is committed: the plan (which files move in, which of the previous run's files go) is written
  to `.rscalib-commit.json`, then carried out with result.json last, so a folder with a result.json
  is always one complete run. The previous run's files that the new run does not write are
  removed, as listed in the manifest `.rscalib-outputs.json`; files rscalib did not write, and the
  run's own inputs (a --camera file an earlier run wrote there), are never touched.

What a kill leaves, at any instant: before the plan is written, the previous set, whole (the
staging folder is removed, or by the next run if the process was killed). Once it is written, the
renames are carried out by a helper process in a session of its own (io/_commit.py, standard
library only), holding the folder's lock, while the command waits with SIGINT, SIGTERM and SIGHUP
held: a signal to the command or its process group, SIGKILL included, does not stop them, and the
folder goes from the previous set to the new one, whole. If the helper cannot start or dies, the
command finishes the renames itself. Only both killed at once (a power cut, the whole cgroup)
leaves a commit half done: no result.json, and the plan, from which the next run into the folder
(check_output_folder, output_set) or recover_output_folder finishes the new set before anything
else. Two runs into the same folder commit one after the other (a lock on `.rscalib-lock`), so the
folder holds the whole set of whichever finished last.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Iterator, Optional

from ..errors import InputError
from . import _commit as commit_steps
from ._commit import JOURNAL, LOCK, MANIFEST, STAGING_PREFIX, plain_names, read_journal, remove, roll_forward
from .results import RESULT_FILE  # the marker of a complete set

__all__ = ["JOURNAL", "LOCK", "MANIFEST", "STAGING_PREFIX", "check_output_folder", "expected_output_bytes",
           "folder_owner", "input_bytes", "output_set", "recover_output_folder", "remove_output_set"]

# which command wrote the folder: what its files say (folder_owner); nothing is added to mark it

MB = 1 << 20

# file systems that hold no results (kernel views, devices)
_PSEUDO_FILESYSTEMS = {"proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "debugfs", "tracefs",
                       "securityfs", "pstore", "bpf", "configfs", "fusectl", "mqueue", "binfmt_misc", "autofs"}


def _mount_type(path: Path) -> Optional[str]:
    """The file system type of the mount holding `path` (Linux /proc/self/mounts; None elsewhere)."""
    try:
        lines = Path("/proc/self/mounts").read_text().splitlines()
    except OSError:
        return None
    best, best_type = "", None
    text = str(path)
    for line in lines:
        fields = line.split()
        if len(fields) < 3:
            continue
        point = fields[1].encode().decode("unicode_escape")  # \040 for spaces
        inside = text == point or text.startswith(point.rstrip("/") + "/")
        if inside and len(point) >= len(best):
            best, best_type = point, fields[2]
    return best_type


def _existing_ancestor(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if os.path.lexists(candidate):
            return candidate
    return Path("/")


def folder_owner(out) -> Optional[str]:
    """The command whose results `out` holds, from its files: a result.json's provenance, a batch
    store, a simulation's truth.json; None for a folder without rscalib results."""
    out = Path(out)
    try:
        data = json.loads((out / RESULT_FILE).read_text()) if (out / RESULT_FILE).is_file() else None
    except (OSError, ValueError):
        data = None
    provenance = data.get("provenance") if isinstance(data, dict) else None
    command = provenance.get("command") if isinstance(provenance, dict) else None
    if isinstance(command, str) and command:
        return command
    if (out / "results.sqlite").is_file():
        return "batch"
    if (out / "truth.json").is_file():
        return "simulate"
    return None


def check_output_folder(out, needed_bytes: int = 16 * MB, option: str = "--out", inputs=(),
                        command: Optional[str] = None, force: bool = False) -> Path:
    """InputError (one line naming the path and the reason) unless `out` is, or can be created as,
    a writable folder with `needed_bytes` free, and is none of the `inputs` (an image folder given
    as --out would get the outputs among its frames). With `command`: InputError when the folder
    holds another command's results (unless `force`). Creates nothing (it finishes a commit a killed
    run left half done: recover_output_folder); returns the path."""
    if str(out).strip() == "":
        raise InputError(f"{option} is empty: give an output folder")
    out = Path(out)
    absolute = Path(os.path.abspath(out))
    if os.path.lexists(absolute) and not absolute.is_dir():
        kind = ("a file" if absolute.is_file() else "a link to nothing" if not absolute.exists()
                else "a device or special file")
        raise InputError(f"{option} {out}: exists and is {kind}, not a folder")
    resolved = absolute.resolve()
    from .video import IMAGE_EXTENSIONS

    for item in inputs or ():
        if os.path.isdir(item) and _resolved(item) == resolved:
            raise InputError(f"{option} {out}: is the input folder {item}; give the outputs a folder of their own")
        if os.path.isfile(item) and Path(item).suffix.lower() in IMAGE_EXTENSIONS \
                and _resolved(Path(item).parent) == resolved:
            raise InputError(f"{option} {out}: holds the input image {item}; the outputs (plots are images too) "
                             "would join the input images: give them a folder of their own")
    fs_type = _mount_type(resolved)
    if fs_type in _PSEUDO_FILESYSTEMS:
        raise InputError(f"{option} {out}: on the {fs_type} file system, which holds no files; give a folder on a disk")
    ancestor = _existing_ancestor(resolved)
    if not ancestor.is_dir():
        raise InputError(f"{option} {out}: {ancestor} is a file, so the folder cannot be created")
    try:  # the one sure test of writing (root ignores mode bits; a read-only mount does not)
        probe = tempfile.mkdtemp(prefix=".rscalib-probe-", dir=ancestor)
        os.rmdir(probe)
    except OSError as error:
        raise InputError(f"{option} {out}: cannot write in {ancestor} ({error.strerror})") from None
    free = shutil.disk_usage(ancestor).free
    if free < needed_bytes:
        raise InputError(f"{option} {out}: {free / MB:.1f} MB free on its file system, the outputs need about "
                         f"{needed_bytes / MB:.0f} MB")
    if (resolved / JOURNAL).exists():
        recover_output_folder(resolved)
    if command is not None:
        _check_owner(out, resolved, command, force, option)
    return out


def _check_owner(out: Path, resolved: Path, command: str, force: bool, option: str) -> None:
    owner = folder_owner(resolved) if resolved.is_dir() else None
    if owner is not None and owner != command and not force:
        raise InputError(f"{option} {out}: holds the results of `rscalib {owner}`; give `rscalib {command}` a folder "
                         f"of its own, or --force to write into it anyway (the files of `rscalib {owner}` that "
                         f"`rscalib {command}` also writes are replaced)")


def input_bytes(paths) -> int:
    """Bytes of the input files (a folder: the files in it); for output size estimates."""
    total = 0
    for item in paths if isinstance(paths, (list, tuple)) else [paths]:
        path = Path(item)
        try:
            if path.is_file():
                total += path.stat().st_size
            elif path.is_dir():
                total += sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        except OSError:
            continue  # the command reports unreadable inputs itself
    return total


def _read_manifest(out: Path) -> list:
    """The names the previous run wrote."""
    try:
        names = json.loads((out / MANIFEST).read_text()).get("files", [])
    except (OSError, ValueError, AttributeError):
        return []
    return plain_names(names) if isinstance(names, list) else []


def _journal_staging(out: Path) -> Optional[str]:
    try:
        return read_journal(out).get("staging")
    except (OSError, ValueError):
        return None


def _remove_dead_staging(out: Path) -> None:
    """Staging folders of runs that were killed (their process is gone), except one an
    unfinished commit still needs (its journal names it)."""
    needed = _journal_staging(out) if (out / JOURNAL).exists() else None
    for entry in out.glob(f"{STAGING_PREFIX}*"):
        if entry.name == needed:
            continue
        try:
            pid = int(entry.name[len(STAGING_PREFIX):].split("-")[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(entry, ignore_errors=True)
        except (ValueError, PermissionError, OSError):
            continue


# -- the commit ----------------------------------------------------------------------------------------
#
# A commit is planned in full (_plan), then the plan is written (JOURNAL: the commit point), then
# carried out by a helper process (_finish; _commit.roll_forward). Before the journal exists the
# previous set is untouched; once it exists the new set is decided, and whoever holds the lock can
# finish it from the journal (the next run into the folder does, before anything else:
# recover_output_folder). The module docstring says what a kill leaves at each instant.


def _resolved(path) -> Optional[Path]:
    try:
        return Path(os.path.abspath(path)).resolve()
    except (OSError, RuntimeError, ValueError):
        return None


def _input_paths(staging: Path, last: str, inputs) -> set:
    """The run's input files and folders, resolved: `inputs` and those its result.json records
    (provenance input_files), so that no command has to list them twice."""
    paths = [p for p in inputs or ()]
    try:
        recorded = json.loads((staging / last).read_text()).get("provenance", {}).get("input_files", {})
    except (OSError, ValueError, AttributeError):
        recorded = {}
    for records in (recorded.values() if isinstance(recorded, dict) else ()):
        for record in records if isinstance(records, list) else [records]:
            if isinstance(record, dict) and isinstance(record.get("path"), str):
                paths.append(record["path"])
    return {r for r in map(_resolved, paths) if r is not None}


def _holds(path: Path, inputs: set) -> Optional[Path]:
    """The input that is `path` or lies inside it, if any."""
    here = _resolved(path)
    if here is None:
        return None
    for item in inputs:
        if item == here or here in item.parents:
            return item
    return None


def _plan(staging: Path, out: Path, last: str, inputs) -> dict:
    """What the commit will do; InputError (nothing changed) when it cannot be done: an output
    would replace an input of the run, or a folder rscalib did not write is where an output goes."""
    previous = set(_read_manifest(out))
    new = sorted(p.name for p in staging.iterdir())
    known = _input_paths(staging, last, inputs)
    if _resolved(out) in known:
        raise InputError(f"{out}: is an input folder of this run; give the outputs a folder of their own")
    kept = set()
    for name in sorted(previous | set(new)):
        held = _holds(out / name, known) if os.path.lexists(out / name) else None
        if held is None:
            continue
        if name in new:
            raise InputError(f"{out / name}: the new {name} would replace {held}, an input of this run; "
                             "give another folder")
        kept.add(name)   # an earlier run's file this run reads: now the user's, never removed
    for name in new:
        target = out / name
        if target.is_dir() and not target.is_symlink() and name not in previous:
            raise InputError(f"{target}: a folder rscalib did not write is where an output goes; move it away")
    return {"staging": staging.name, "new": new, "remove": sorted(previous - set(new) - kept),
            "last": last if last in new else None}


def _commit(staging: Path, out: Path, last: str, inputs=(), lock_fd: Optional[int] = None) -> None:
    """Move the staged files into `out` as one set: `last` (result.json) at the end, the previous
    run's other files removed (not an input of this run). The plan is written first, then carried
    out by a helper process (_finish)."""
    plan = _plan(staging, out, last, inputs)
    with _signals_held():
        commit_steps.write_atomic(out / JOURNAL, json.dumps(plan) + "\n")   # the commit point
        commit_steps.sync_folder(out)
        _finish(out, plan, lock_fd)


def _helper_argv(out: Path) -> list:
    """The command line of the process that carries a commit out (a test may wrap it)."""
    return [sys.executable, "-I", "-S", commit_steps.__file__, str(out)]


def _finish(out: Path, plan: dict, lock_fd: Optional[int]) -> None:
    """Carry out a written plan in a process of its own session, holding the folder's lock (it
    inherits `lock_fd`): a signal to this process or its process group, even SIGKILL, does not stop
    it half-way. If it cannot start, or fails, or is killed, this process finishes the plan itself."""
    helper = None
    if os.name == "posix" and lock_fd is not None and sys.executable:
        try:
            helper = subprocess.Popen(_helper_argv(out), start_new_session=True, pass_fds=(lock_fd,),
                                      stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        except OSError:
            helper = None
    if helper is not None:
        _, error = helper.communicate()
        if helper.returncode == 0 and not (out / JOURNAL).exists():
            return
    roll_forward(out, plan)   # no helper, or it failed (the same error comes again, as an OSError)


def _recover(out: Path) -> bool:
    """Finish a commit that a killed run left half done (under the lock); True if there was one."""
    if not (out / JOURNAL).exists():
        return False
    try:
        plan = read_journal(out)
    except (OSError, ValueError):
        os.unlink(out / JOURNAL)   # not ours, or damaged: nothing can be finished from it
        return False
    if (out / plan["staging"]).is_dir():
        with _signals_held():
            roll_forward(out, plan)
    else:
        os.unlink(out / JOURNAL)
    return True


def recover_output_folder(out_dir) -> bool:
    """Finish a commit of an output set that was killed (SIGKILL, a power cut) half-way: the new
    set is completed from its staging folder. Every run into the folder does this first; call it
    to read a folder that a killed run left. True when there was one to finish."""
    out = Path(out_dir)
    if not (out / JOURNAL).exists():
        return False
    try:
        with _commit_lock(out):
            return _recover(out)
    except OSError as error:
        raise InputError(f"cannot finish the interrupted outputs in {out}: {error.strerror or error}") from None


def remove_output_set(out_dir) -> None:
    """Remove what rscalib wrote in `out_dir`: the files its manifest lists (a half-done commit
    finished first), the manifest, staging folders of runs that are gone. The user's files stay.
    (A batch job's folder before the job runs again: the previous answer must not be read as
    this run's.)"""
    out = Path(out_dir)
    if not out.is_dir() or out.is_symlink():
        return
    with _commit_lock(out):
        _recover(out)
        for name in _read_manifest(out):
            remove(out / name)
        if os.path.lexists(out / MANIFEST):
            os.unlink(out / MANIFEST)
    _remove_dead_staging(out)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP wait until the block is done, then are delivered (the main
    thread only: Python runs signal handlers there; elsewhere nothing is changed)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held, previous = [], {}

    def hold(signum, frame) -> None:
        if signum not in held:
            held.append(signum)

    for signum in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if signum is None or signal.getsignal(signum) is None:   # a handler set outside Python: leave it
            continue
        previous[signum] = signal.signal(signum, hold)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in held:
            signal.raise_signal(signum)


@contextlib.contextmanager
def _commit_lock(out: Path) -> Iterator[Optional[int]]:
    """Held while a set is moved into `out`: two runs writing the same folder at once would
    otherwise interleave their files (flock: released by the kernel when every process holding it,
    the commit's helper included, has ended). Yields the lock's file descriptor."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield None
        return
    with open(out / LOCK, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield handle.fileno()
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _output_error(error: OSError, staging: Path, out: Path) -> InputError:
    """An OSError of writing, as one line naming the file (its final name) and the reason."""
    reason = error.strerror or str(error)
    name = error.filename
    if name is not None:
        try:
            name = out / Path(name).relative_to(staging)
        except ValueError:
            name = Path(name)
        return InputError(f"cannot write {name}: {reason}")
    return InputError(f"cannot write the outputs in {out}: {reason}")


@contextlib.contextmanager
def output_set(out_dir, last: str = RESULT_FILE, inputs=()) -> Iterator[Path]:
    """`with output_set(out) as folder:` write every output into `folder`; on leaving, the files
    replace the previous run's set in `out` (result.json last). An error or interrupt inside
    leaves `out` as it was; an OSError becomes InputError naming the file and the reason.

    inputs: the run's input files and folders (those its result.json records are added): an input
    is never removed with the previous set, an output that would replace one is refused, and an
    input folder cannot be `out`."""
    out = Path(out_dir)
    try:
        if os.path.lexists(out) and not out.is_dir():
            raise InputError(f"{out}: exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
        if (out / JOURNAL).exists():
            with _commit_lock(out):
                _recover(out)
        _remove_dead_staging(out)
        staging = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=out))
    except OSError as error:
        raise InputError(f"cannot write in {out}: {error.strerror or error}") from None
    try:
        yield staging
        with _commit_lock(out) as lock_fd:
            _commit(staging, out, last, inputs, lock_fd)
    except OSError as error:
        raise _output_error(error, staging, out) from None
    finally:
        if not (out / JOURNAL).exists() or _journal_staging(out) != staging.name:
            shutil.rmtree(staging, ignore_errors=True)   # kept only for a commit left to finish


def expected_output_bytes(base_mb: float, inputs=(), per_input_byte: float = 0.0, extra_bytes: float = 0.0) -> int:
    """A generous estimate of what a command writes: `base_mb` (plots, reports, camera files) plus
    `per_input_byte` of the inputs' size (trajectories, corners.vnl grow with the frames) plus
    `extra_bytes` (e.g. rendered frames); a non-finite part counts as nothing (the command's own
    checks refuse such options with their reason)."""
    total = base_mb * MB
    for part in (per_input_byte * input_bytes(inputs) if per_input_byte else 0.0, extra_bytes):
        if part == part and part not in (float("inf"), float("-inf")):
            total += max(0.0, part)
    return int(min(total, 1 << 62))
