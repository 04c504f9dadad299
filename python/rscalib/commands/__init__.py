"""Subcommands of the `rscalib` CLI: one module each, with add_parser(subparsers).

A module's parser sets `func(args) -> exit code`; rscalib.cli turns InputError into exit 2.
"""
from . import demo
from . import flicker
from . import intrinsics
from . import linedelay
from . import selfcalib
from . import simulate

COMMAND_MODULES = [demo, flicker, intrinsics, linedelay, selfcalib, simulate]
