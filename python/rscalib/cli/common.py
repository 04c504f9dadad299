"""Shared pieces of the subcommands: exit codes (README: exit codes)."""

EXIT_OK = 0
EXIT_BAD_INPUT = 2       # a one-line reason on stderr, no traceback
EXIT_UNDETERMINED = 3    # results written, but the data do not determine the answer
EXIT_NOT_TRUSTED = 4     # estimated, but a check failed (the report says which); results written
EXIT_INTERNAL = 1        # an unexpected error (one line; RSCALIB_DEBUG=1 shows the traceback)

# Where a user learns how to film what each command needs; printed with every "do not trust" verdict.
CAPTURE_GUIDE = "docs/capture.md (in the rscalib repository): how to film for each command"
