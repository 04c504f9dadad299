"""The `rscalib` command line: one entry point, a subcommand per job (README: the commands).

Exit codes: 0 success; 2 bad input (one line on stderr, no traceback); 3 the data does
not determine the answer (results are still written, with the warning).
"""
from __future__ import annotations

import argparse
import sys

from .._version import __version__
from ..errors import InputError
from . import batch, demo, flicker, intrinsics, linedelay, selfcalib, simulate
from .common import EXIT_BAD_INPUT, EXIT_OK, EXIT_UNDETERMINED  # noqa: F401  (re-exported)

# One module per subcommand: add_parser(sub) and run(args); each imports its engine only when run.
COMMAND_MODULES = [batch, demo, flicker, intrinsics, linedelay, selfcalib, simulate]


class _Parser(argparse.ArgumentParser):
    """argparse exits with 2 on usage errors already; keep its message to one line."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="rscalib", description="Camera calibration from video: rolling-shutter line delay "
                     "and self-calibration.")
    parser.add_argument("--version", action="version", version=f"rscalib {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for module in COMMAND_MODULES:
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
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
