"""The installed package's version: compiled into _core from CMakeLists.txt's project version, which
tests/python/cli/test_cli.py keeps equal to pyproject.toml's (the package metadata; reading that cost
25 ms of every import, the detection workers' too)."""
from ._core import __version__  # noqa: F401
