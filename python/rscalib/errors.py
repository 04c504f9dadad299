"""Exceptions of the public API."""
from ._core import InputError  # C++ rscalib::InputError arrives as this (a ValueError)

__all__ = ["InputError"]
