"""The output folder of a command: checked before any work starts, written as a set.

- check_output_folder: --out must be a folder rscalib can create or write in, on a real file
  system (not /proc, /sys, /dev), with room for the expected outputs; otherwise InputError (exit 2)
  before detection or solving starts.
- output_set: a writer writes into a hidden staging folder inside the output folder; on success the
  files are renamed into place (same file system: each rename is atomic) with result.json last, so
  a folder with a result.json is always one complete run. The previous run's files that the new run
  does not write are removed, as listed in the manifest `.rscalib-outputs.json`; files rscalib did
  not write are never touched. A failure or an interrupt removes the staging folder and leaves the
  previous set as it was. Two runs into the same folder commit one after the other (a lock on
  `.rscalib-lock`), so the folder holds the whole set of whichever finished last.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator, Optional

from ..errors import InputError
from .results import RESULT_FILE  # the marker of a complete set

MANIFEST = ".rscalib-outputs.json"
LOCK = ".rscalib-lock"
STAGING_PREFIX = ".rscalib-staging-"
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


def check_output_folder(out, needed_bytes: int = 16 * MB, option: str = "--out") -> Path:
    """InputError (one line naming the path and the reason) unless `out` is, or can be created as,
    a writable folder with `needed_bytes` free. Creates nothing; returns the path."""
    if str(out).strip() == "":
        raise InputError(f"{option} is empty: give an output folder")
    out = Path(out)
    absolute = Path(os.path.abspath(out))
    if os.path.lexists(absolute) and not absolute.is_dir():
        kind = ("a file" if absolute.is_file() else "a link to nothing" if not absolute.exists()
                else "a device or special file")
        raise InputError(f"{option} {out}: exists and is {kind}, not a folder")
    resolved = absolute.resolve()
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
    return out


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
    """The names the previous run wrote (plain names in `out` only: a damaged manifest must not
    point outside the folder)."""
    try:
        names = json.loads((out / MANIFEST).read_text()).get("files", [])
    except (OSError, ValueError, AttributeError):
        return []
    return [n for n in names if isinstance(n, str) and n not in ("", ".", "..", MANIFEST) and "/" not in n
            and "\\" not in n and not n.startswith(STAGING_PREFIX)]


def _write_manifest(out: Path, names) -> None:
    tmp = out / f"{MANIFEST}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps({"written_by": "rscalib", "files": sorted(set(names))}, indent=1) + "\n")
    os.replace(tmp, out / MANIFEST)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        path.unlink()


def _remove_dead_staging(out: Path) -> None:
    """Staging folders of runs that were killed (their process is gone)."""
    for entry in out.glob(f"{STAGING_PREFIX}*"):
        try:
            pid = int(entry.name[len(STAGING_PREFIX):].split("-")[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(entry, ignore_errors=True)
        except (ValueError, PermissionError, OSError):
            continue


def _commit(staging: Path, out: Path, last: str) -> None:
    """Move the staged files into `out` as one set: `last` (result.json) at the end, the previous
    run's other files removed."""
    previous = set(_read_manifest(out))
    new = sorted(p.name for p in staging.iterdir())
    for name in new:
        target = out / name
        if target.is_dir() and not target.is_symlink() and name not in previous:
            raise InputError(f"{target}: a folder rscalib did not write is where an output goes; move it away")
    _write_manifest(out, previous | set(new))   # a kill from here on still knows every file rscalib wrote
    if last in new:
        _remove(out / last)   # until the new set is whole, the folder must not look complete
    for name in new:
        if name == last:
            continue
        target = out / name
        if target.is_dir() and not target.is_symlink():
            _remove(target)   # a folder of the previous run (checked above)
        os.replace(staging / name, target)
    for name in previous - set(new):
        _remove(out / name)
    _write_manifest(out, new)
    if last in new:
        os.replace(staging / last, out / last)


@contextlib.contextmanager
def _commit_lock(out: Path) -> Iterator[None]:
    """Held while a set is moved into `out`: two runs writing the same folder at once would
    otherwise interleave their files (flock: released by the kernel if the process dies)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    with open(out / LOCK, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
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
def output_set(out_dir, last: str = RESULT_FILE) -> Iterator[Path]:
    """`with output_set(out) as folder:` write every output into `folder`; on leaving, the files
    replace the previous run's set in `out` (result.json last). An error or interrupt inside
    leaves `out` as it was; an OSError becomes InputError naming the file and the reason."""
    out = Path(out_dir)
    try:
        if os.path.lexists(out) and not out.is_dir():
            raise InputError(f"{out}: exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
        _remove_dead_staging(out)
        staging = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=out))
    except OSError as error:
        raise InputError(f"cannot write in {out}: {error.strerror or error}") from None
    try:
        yield staging
        with _commit_lock(out):
            _commit(staging, out, last)
    except OSError as error:
        raise _output_error(error, staging, out) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


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
