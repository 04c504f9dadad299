"""Shared pieces of the subcommands: exit codes (README: exit codes) and the range-checked
argparse converters of their options."""
from __future__ import annotations

import argparse
import re
from typing import Callable, Optional

from .. import checks

EXIT_OK = 0
EXIT_BAD_INPUT = 2       # a one-line reason on stderr, no traceback
EXIT_UNDETERMINED = 3    # results written, but the data do not determine the answer
EXIT_NOT_TRUSTED = 4     # estimated, but a check failed (the report says which); results written
EXIT_INTERNAL = 1        # an unexpected error (one line; RSCALIB_DEBUG=1 shows the traceback)

# Where a user learns how to film what each command needs; printed with every "do not trust" verdict.
# The guide is installed with the package (`rscalib guide capture`, cli/guide.py).
CAPTURE_GUIDE = "`rscalib guide capture` (how to film for each command)"


def add_force(parser: argparse.ArgumentParser) -> None:
    """--force: write into an --out folder that holds another command's results."""
    parser.add_argument("--force", action="store_true",
                        help="write into an --out folder that holds another command's results (refused without it: "
                             "the two sets of files would mix)")


# ---- argparse `type=` converters: a value out of range is one line naming the option (exit 2),
# e.g. "rscalib linedelay: error: argument --pixel-sigma: must be in [0.0001, 100] px, not 1e-300".

def number(low: Optional[float] = None, high: Optional[float] = None, unit: str = "", *,
           low_open: bool = False) -> Callable[[str], float]:
    """A converter to a finite float in [low, high] ((low, high] with low_open), NaN and inf refused."""
    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if checks.out_of_range(value, low, high, low_open):
            raise argparse.ArgumentTypeError(f"must be {checks.range_words(low, high, low_open)}{unit}, not {text}")
        return value
    return convert


def whole(low: int, high: Optional[int] = None, unit: str = "", why: str = "") -> Callable[[str], int]:
    """A converter to an int in [low, high]; `why` says where the upper bound comes from."""
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {checks.range_words(low, high)}{unit}{why}, not {text}")
        return value
    return convert


def workers(text: str) -> int:
    """Processes or threads: 1 to the usable cores (more only share the cores, and each costs memory)."""
    from ..io.limits import usable_cores

    cores = usable_cores()
    return whole(1, cores, why=f" (this machine has {cores} usable cores)")(text)


def seed(text: str) -> int:
    """A random seed: 0 to 2^32 - 1 (what every generator takes)."""
    return whole(0, 2 ** 32 - 1)(text)


def seconds_in(low: float, high: float, *, low_open: bool = False) -> Callable[[str], float]:
    """A converter to a time in seconds, optionally with a unit (30e-6, 30us, 0.03ms, 5ms, 1s), in
    [low, high] ((low, high] with low_open)."""
    def convert(text: str) -> float:
        match = re.fullmatch(r"\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*(s|ms|us|µs|ns)?\s*", text)
        if not match:
            raise argparse.ArgumentTypeError(f"not a time: {text!r} (e.g. 30e-6, 30us, 5ms)")
        try:
            value = float(match.group(1)) * _TIME_UNITS[match.group(2) or ""]
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a time: {text!r} (e.g. 30e-6, 30us, 5ms)") from None
        return number(low, high, " s", low_open=low_open)(repr(value))
    return convert


_TIME_UNITS = {"": 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


def image_size(text: str) -> str:
    """WIDTHxHEIGHT, each side 16..8192 px and at most 4096 x 4096 pixels in all (rendering memory);
    returned as given."""
    match = re.fullmatch(r"(\d+)x(\d+)", text.strip())
    if not match:
        raise argparse.ArgumentTypeError(f"must be WIDTHxHEIGHT, e.g. 640x480, not {text!r}")
    width, height = int(match.group(1)), int(match.group(2))
    if not (16 <= width <= 8192 and 16 <= height <= 8192 and width * height <= 4096 * 4096):
        raise argparse.ArgumentTypeError(f"{text}: each side 16 to 8192 px, at most {4096 * 4096} pixels")
    return text.strip()


# Ranges shared by several commands
PIXEL_SIGMA = number(1e-4, 100.0, " px")            # detection noise: 0.0001 px is beyond any detector


def line_delay(low: float, high: float, *, low_open: bool = False) -> Callable[[str], float]:
    """A converter to a line delay in s/row, given with a unit per row (30us, 0.03ms, 30000ns) or as
    a plain number in s/row (3e-5), in [low, high] ((low, high] with low_open): the one way every
    command takes a line delay."""
    def convert(text: str) -> float:
        bare = re.sub(r"\s*/\s*row\s*$", "", text.strip())   # "30us/row" reads as "30us"
        try:
            value = seconds_in(low, high, low_open=low_open)(bare)
        except argparse.ArgumentTypeError as error:
            raise argparse.ArgumentTypeError(str(error).replace("not a time", "not a line delay")
                                             .replace(" s,", " s/row,").replace("(e.g. 30e-6, 30us, 5ms)",
                                                                                "(e.g. 30us, 3e-5 s/row)")) from None
        return value
    return convert


# the library's limits (rscalib.checks): the front doors and options refuse what these refuse
LINE_DELAY = line_delay(-checks.MAX_ABS_LINE_DELAY_S, checks.MAX_ABS_LINE_DELAY_S)
ROWS = whole(1, checks.MAX_ROWS, " rows")
FRAMES = whole(1, checks.MAX_FRAMES, " frames")
FOCAL_PX = number(0.0, 1e7, " px", low_open=True)
