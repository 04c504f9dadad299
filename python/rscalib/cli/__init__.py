"""The `rscalib` command line: one entry point, a subcommand per job (README: the commands).

Exit codes: 0 success; 2 bad input (one line on stderr, no traceback; also an output folder that
cannot be written, and running out of memory); 3 the data does not determine the answer (results
are still written, with the warning); 1 an internal error (one line; RSCALIB_DEBUG=1 shows the
traceback); 130 Ctrl-C, 143 SIGTERM (detection workers stopped, no partial result.json).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import warnings

from .._version import __version__
from ..errors import InputError
from . import batch, demo, flicker, guide, intrinsics, linedelay, selfcalib, simulate
from .common import EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_OK, EXIT_UNDETERMINED  # noqa: F401  (re-exported)

EXIT_INTERRUPTED = 130   # Ctrl-C (128 + SIGINT)
EXIT_TERMINATED = 143    # SIGTERM (128 + SIGTERM)
EXIT_BROKEN_PIPE = 141   # the reader of stdout went away (128 + SIGPIPE), e.g. `rscalib ... | head`

# One module per subcommand: add_parser(sub) and run(args); each imports its engine only when run.
COMMAND_MODULES = [batch, demo, flicker, guide, intrinsics, linedelay, selfcalib, simulate]


WORKFLOW = """\
a typical session (each command: `rscalib COMMAND --help`):
  rscalib intrinsics stills/ --target target.yaml --out calib
      intrinsics and distortion from 15-40 sharp stills of the target (calib/camera.yaml)
  rscalib linedelay video.mp4 --target target.yaml --camera calib/camera.yaml --out result
      the rolling-shutter line delay from 5-60 s of hand-held video of the target; result/report.html
      has the verdict, and the camera files for OpenCV, Kalibr, Gyroflow, ROS, mrcal and COLMAP
  rscalib localize video.mp4 --target target.yaml --camera result/camera_with_line_delay.yaml --out traj
      the camera's trajectory with that line delay (trajectory.csv, TUM trajectory)
no target? `rscalib flicker` measures the line delay from a flickering light, `rscalib selfcalib` the
focal length and distortion from a walk through a textured scene. Try it first: `rscalib demo`.
--camera reads OpenCV, Kalibr, ROS camera_info, mrcal .cameramodel, COLMAP cameras.txt and Gyroflow files.
how to film: `rscalib guide capture`; file formats: `rscalib guide formats`
"""


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """rscalib's warnings (e.g. an unknown key in a target file) as one line, without source lines."""
    print(f"rscalib: warning: {message}", file=sys.stderr if file is None else file)


class _Parser(argparse.ArgumentParser):
    """argparse exits with 2 on usage errors already; keep its message to one line."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="rscalib", description="Camera calibration from video: intrinsics, the "
                     "rolling-shutter line delay, and self-calibration without a target.", epilog=WORKFLOW,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"rscalib {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for module in COMMAND_MODULES:
        module.add_parser(sub)
    # `rscalib batch` checks every manifest row with this parser: handed over, not imported (batch
    # never imports cli, which would be a circle)
    parser.set_defaults(parse_args=lambda argv: build_parser().parse_args(argv))
    return parser


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that detection workers and partial outputs are cleaned up."""


@contextlib.contextmanager
def _sigterm_raises():
    """SIGTERM -> Terminated (exit 143) while a command runs; a second SIGTERM kills at once."""
    def handler(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _one_line(error: Exception) -> tuple[int, str]:
    """(exit code, one line) for an error that is not InputError."""
    text = " ".join(str(error).split())
    if isinstance(error, MemoryError):
        return EXIT_BAD_INPUT, ("error: out of memory" + (f" ({text})" if text else "") + ": the input or options "
                                "need more memory than this machine has (fewer --workers, a shorter input or a "
                                "smaller size)")
    if isinstance(error, OSError):
        where = " -> ".join(str(f) for f in (error.filename, error.filename2) if f is not None)
        reason = error.strerror or text or type(error).__name__
        return EXIT_BAD_INPUT, f"error: {where}: {reason}" if where else f"error: {reason}"
    return EXIT_INTERNAL, (f"internal error: {type(error).__name__}: {text} "
                           "(set RSCALIB_DEBUG=1 for the traceback; please report it)")


def main(argv: list[str] | None = None) -> int:
    from ..io.results import set_command_line

    parser = build_parser()
    args = parser.parse_args(argv)
    set_command_line(["rscalib", *(sys.argv[1:] if argv is None else argv)])
    warnings.showwarning = _one_line_warning
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        print("rscalib: error: a COMMAND is required", file=sys.stderr)
        return EXIT_BAD_INPUT
    with _sigterm_raises():
        try:
            return int(args.func(args))
        except InputError as error:
            print(f"rscalib {args.command}: error: {error}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except KeyboardInterrupt:
            print("rscalib: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except Terminated:
            print("rscalib: terminated", file=sys.stderr)
            return EXIT_TERMINATED
        except BrokenPipeError:
            # not bad input: the reader closed the pipe. Stdout goes to /dev/null so that the
            # interpreter's final flush cannot fail again; nothing is said (as a killed `cat` says nothing).
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return EXIT_BROKEN_PIPE
        except Exception as error:  # noqa: BLE001 - the last line of defence: never a traceback for a user
            if os.environ.get("RSCALIB_DEBUG"):
                raise
            code, line = _one_line(error)
            print(f"rscalib {args.command}: {line}", file=sys.stderr)
            return code


if __name__ == "__main__":
    sys.exit(main())
