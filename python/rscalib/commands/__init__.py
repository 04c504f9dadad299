"""Subcommands of the `rscalib` CLI: one module each, with add_parser(subparsers).

A module's parser sets `func(args) -> exit code`; rscalib.cli turns InputError into exit 2.
"""
from . import demo
from . import linedelay

COMMAND_MODULES = [demo, linedelay]
