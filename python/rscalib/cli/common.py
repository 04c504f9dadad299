"""Shared pieces of the subcommands: exit codes (README: exit codes)."""

EXIT_OK = 0
EXIT_BAD_INPUT = 2       # a one-line reason on stderr, no traceback
EXIT_UNDETERMINED = 3    # results written, but the data do not determine the answer
