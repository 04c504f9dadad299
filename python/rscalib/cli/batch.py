"""`rscalib batch`: many single commands from a manifest, on Dask (a LocalCluster here, or --scheduler),
with a results store, --resume, index.html; `rscalib batch --status DIR` prints progress.

Exit codes: 0 every job ran to an answer of its own command (its exit code 0, 2, 3 or 4: the table
says which); 1 some jobs did not finish (internal error, killed, worker lost): --resume runs them
again; 2 bad manifest or options (one line naming the file, row and field).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from .common import EXIT_INTERNAL, EXIT_OK, add_force, number, whole, workers


def add_parser(sub) -> None:
    p = sub.add_parser("batch", help="run a manifest of jobs (linedelay, intrinsics, flicker, selfcalib) on Dask",
                       description="Run one single command per manifest row (CSV or YAML: command, input, id, mode "
                                   "and the command's options by flag name) on a Dask cluster, each in its own "
                                   "process, writing DIR/jobs/<id>/ (the command's usual folder), DIR/logs/<id>.log, "
                                   "the results store DIR/results.sqlite (a row per job, written as jobs finish) and "
                                   "DIR/index.html. Needs the batch extra: pip install 'rscalib[batch]'.",
                       epilog="exit codes: 0 every job ran to its command's answer (see the table); 1 some jobs did "
                              "not finish (internal error, killed, worker lost): --resume runs them again; 2 bad "
                              "manifest or options")
    p.add_argument("manifest", nargs="?", metavar="MANIFEST", help="the jobs: a .csv or .yaml manifest")
    p.add_argument("--out", metavar="DIR", help="batch folder (created)")
    add_force(p)
    p.add_argument("--status", metavar="DIR", help="print the progress of the batch in DIR (done / running / failed) "
                                                   "and exit")
    p.add_argument("--resume", action="store_true",
                   help="continue the batch in DIR: run only the jobs without an answer, or whose inputs, options "
                        "or rscalib version changed")
    p.add_argument("--workers", type=workers, default=2, metavar="N", help="Dask worker processes of the local cluster (2)")
    p.add_argument("--threads-per-worker", type=whole(1, 64), default=1, metavar="T",
                   help="jobs at once per worker (1); each job's own threads are capped at 1")
    p.add_argument("--memory-limit", default="auto", metavar="BYTES",
                   help="memory per worker, e.g. 4GB (auto: the machine's memory / workers); a job over its share "
                        "(limit / threads-per-worker) is killed and recorded")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="an existing Dask scheduler instead of a local cluster (workers need rscalib and the "
                        "inputs and DIR on a shared file system; --workers, --threads-per-worker and "
                        "--memory-limit are then the cluster's own)")
    p.add_argument("--job-timeout", type=number(0.0, 1e7, " s", low_open=True), default=None, metavar="S", help="kill a job running longer than S "
                                                                                "seconds (no limit)")
    p.set_defaults(func=run)


def _memory_limit(text: str):
    word = text.strip().lower()
    if word == "auto":
        return "auto"
    if word in ("none", "0"):
        return 0  # no limit
    from dask.utils import parse_bytes

    try:
        return parse_bytes(text)
    except (ValueError, TypeError):
        raise InputError(f"--memory-limit: '{text}' is not a size such as 4GB or 512MiB") from None


def run(args: argparse.Namespace) -> int:
    from ..batch.summary import status_lines

    if args.status:
        if args.manifest or args.out:
            raise InputError("--status DIR takes no MANIFEST or --out")
        for line in status_lines(args.status):
            print(line)
        return EXIT_OK
    if not args.manifest or not args.out:
        raise InputError("give a MANIFEST and --out DIR (or --status DIR)")
    if args.workers < 1 or args.threads_per_worker < 1:
        raise InputError("--workers and --threads-per-worker must be at least 1")
    if args.job_timeout is not None and not args.job_timeout > 0:
        raise InputError("--job-timeout must be positive")
    from ..batch.runner import run_batch
    from ..io.output_folder import check_output_folder, expected_output_bytes

    check_output_folder(args.out, expected_output_bytes(64), command=args.command, force=args.force)   # the store, index.html, the first jobs' outputs
    from ..batch.store import ANSWERED
    from ..batch.summary import INDEX_FILE, summary_line

    counts = run_batch(args.manifest, args.out, resume=args.resume, workers=args.workers,
                       threads_per_worker=args.threads_per_worker, memory_limit=_memory_limit(args.memory_limit),
                       scheduler=args.scheduler, timeout_s=args.job_timeout,
                       say=lambda line: print(line, file=sys.stderr), parse_args=args.parse_args)
    print(summary_line(counts))
    print(f"summary: {Path(args.out) / INDEX_FILE}")
    return EXIT_OK if all(status in ANSWERED for status in counts) else EXIT_INTERNAL
