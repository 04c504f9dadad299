"""The `rscalib` command line: one entry point, a subcommand per job (README: the commands).

Exit codes: 0 success; 2 bad input (one line on stderr, no traceback); 3 the data does
not determine the answer (results are still written, with the warning).
"""
from __future__ import annotations

import argparse
import sys
import warnings

from .._version import __version__
from ..errors import InputError
from . import batch, demo, flicker, intrinsics, linedelay, selfcalib, simulate
from .common import EXIT_BAD_INPUT, EXIT_OK, EXIT_UNDETERMINED  # noqa: F401  (re-exported)

# One module per subcommand: add_parser(sub) and run(args); each imports its engine only when run.
COMMAND_MODULES = [batch, demo, flicker, intrinsics, linedelay, selfcalib, simulate]


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
how to film: docs/capture.md; file formats: docs/formats.md (in the rscalib repository)
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
    return parser


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
    try:
        return int(args.func(args))
    except InputError as error:
        print(f"rscalib {args.command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("rscalib: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
