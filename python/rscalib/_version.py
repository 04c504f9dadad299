"""The installed package's version (one source: pyproject.toml via the package metadata)."""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rscalib")
except PackageNotFoundError:  # a source tree without metadata: the version compiled into _core
    from ._core import __version__  # noqa: F401
