"""A batch job's process: `python -m rscalib.cli.job COMMAND ARGS...` is `rscalib COMMAND ARGS...` (the
same rscalib.cli.main) that also dies with the worker that started it, so a killed batch leaves no
orphan jobs writing into a folder that `--resume` is about to run again. The batch runner starts it
by its module name (batch/runner.py), so batch never imports cli."""
from __future__ import annotations

import ctypes
import os
import signal
import sys

from ..batch.runner import PARENT_PID_ENV

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent() -> None:
    """Linux: SIGKILL this process when its parent thread ends (the worker thread waiting for it)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        return  # not Linux: the job may outlive a killed worker
    expected = os.environ.get(PARENT_PID_ENV)
    if expected and os.getppid() != int(expected):  # the parent died before prctl took effect
        os._exit(128 + signal.SIGKILL)


def main(argv: list) -> int:
    die_with_parent()
    from . import main as cli_main

    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
