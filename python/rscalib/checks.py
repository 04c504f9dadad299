"""The checks of the public functions' arguments: one place for the ranges and the words.

Each check returns the value converted (a float, an int, a Path, an array) or raises
:class:`rscalib.InputError` with one line that names the argument, e.g. "line_delay_s must be in
[-0.01, 0.01] s/row, not 1.0". The CLI's argparse converters (cli/common.py) apply the same range
rule (:func:`out_of_range`) with the same words (:func:`range_words`) and the same limits below, so
a value the command refuses the library refuses too (docs/reliability.md, "Public function arguments").
"""
from __future__ import annotations

import math
import numbers
import os
from pathlib import Path
from typing import Any, Optional

import numpy as np

from .errors import InputError

# Limits shared by the CLI, the options classes, the camera files and the front doors.
MAX_ROWS = 100_000                 # sensor rows read out
MAX_IMAGE_SIDE_PX = 100_000        # a camera file's or an image's side
MAX_FRAMES = 10_000_000            # frames of one video
MAX_ABS_LINE_DELAY_S = 0.01        # 10 ms a row: a 100-row sensor read in a second
MAX_FREQUENCY_HZ = 1e6             # a flickering light's


def range_words(low: Optional[float], high: Optional[float], low_open: bool = False) -> str:
    """"in [low, high]", ">= low", "<= high" or "finite": what a range check asks for."""
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}]"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    return "finite" if high is None else f"<= {high:g}"


def out_of_range(value: float, low: Optional[float], high: Optional[float], low_open: bool = False) -> bool:
    """Whether `value` is NaN, infinite or outside [low, high] ((low, high] with low_open)."""
    too_low = low is not None and (value <= low if low_open else value < low)
    return not math.isfinite(value) or too_low or (high is not None and value > high)


def number(value: Any, name: str, low: Optional[float] = None, high: Optional[float] = None, unit: str = "", *,
           low_open: bool = False) -> float:
    """A real number (not a bool or text), finite, in [low, high], as a float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{name} must be a number, not {_shown(value)}")
    number_ = float(value)
    if out_of_range(number_, low, high, low_open):
        finite = "" if math.isfinite(number_) else "a finite number "
        raise InputError(f"{name} must be {finite}{range_words(low, high, low_open)}{unit}, not {number_!r}")
    return number_


def whole(value: Any, name: str, low: int, high: Optional[int] = None, unit: str = "") -> int:
    """A whole number (an int, or a float with a whole value; not a bool) in [low, high], as an int."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or \
            (not isinstance(value, numbers.Integral) and not (math.isfinite(value) and float(value).is_integer())):
        raise InputError(f"{name} must be a whole number, not {_shown(value)}")
    if value < low or (high is not None and value > high):
        raise InputError(f"{name} must be {range_words(low, high)}{unit}, not {value!r}")
    return int(value)


def line_delay(value: Any, name: str = "line_delay_s") -> float:
    """A line delay in s/row: finite, at most MAX_ABS_LINE_DELAY_S in magnitude (the CLI's LINE_DELAY)."""
    return number(value, name, -MAX_ABS_LINE_DELAY_S, MAX_ABS_LINE_DELAY_S, " s/row")


def image_size(value: Any, name: str = "image_size") -> tuple[int, int]:
    """(width, height): two whole numbers of pixels in 1..MAX_IMAGE_SIDE_PX."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise InputError(f"{name} must be (width, height) in pixels, not {_shown(value)}")
    return (whole(value[0], f"{name} (width)", 1, MAX_IMAGE_SIDE_PX, " px"),
            whole(value[1], f"{name} (height)", 1, MAX_IMAGE_SIDE_PX, " px"))


def path(value: Any, name: str) -> Path:
    """A file-system path (str or os.PathLike), as a Path; whether it exists is the reader's check."""
    if not isinstance(value, (str, os.PathLike)) or (isinstance(value, str) and not value.strip()):
        raise InputError(f"{name} must be a file or folder path, not {_shown(value)}")
    return Path(value)


def instance(value: Any, name: str, kinds: tuple, words: str) -> Any:
    """`value` when it is one of `kinds`; else InputError "<name> must be <words>, not <type>"."""
    if not isinstance(value, kinds):
        raise InputError(f"{name} must be {words}, not {_shown(value)}")
    return value


def source(value: Any, name: str, also: tuple = (), also_words: str = "") -> Any:
    """A frame source: a path (video, image folder, image file, glob) or a non-empty list of image paths,
    or one of the objects `also` (e.g. detections already made); other types are refused here, before
    any file is opened. Whether the paths exist is open_source's check."""
    if isinstance(value, also) if also else False:
        return value
    words = "a video file, an image folder or a list of image files" + (f", {also_words}" if also_words else "")
    if isinstance(value, (str, os.PathLike)):
        path(value, name)
        return value
    if isinstance(value, (list, tuple)):
        if not value:
            raise InputError(f"{name} is empty: no input images or video given (give {words})")
        for item in value:
            if not isinstance(item, (str, os.PathLike)):
                raise InputError(f"{name} must be {words}, not a list holding {_shown(item)}")
        return value
    raise InputError(f"{name} must be {words}, not {_shown(value)}")


def optional_callable(value: Any, name: str) -> Any:
    """None or a callable (a callback)."""
    if value is not None and not callable(value):
        raise InputError(f"{name} must be a function or None, not {_shown(value)}")
    return value


def progress(value: Any, name: str = "progress") -> Any:
    """A progress argument (rscalib._progress): True/False/None, or a callable (done, total)."""
    if value is not None and not isinstance(value, bool) and not callable(value):
        raise InputError(f"{name} must be True, False, None or a function (done, total), not {_shown(value)}")
    return value


def finite_array(value: Any, name: str, *, columns: Optional[int] = None, min_rows: int = 0) -> np.ndarray:
    """float64 array of numbers: 1-D, or (n, columns) when columns is given; no NaN or infinity."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be an array of numbers, not {_shown(value)}") from None
    if columns is None and array.ndim != 1:
        raise InputError(f"{name} must be a 1-D array, not of shape {array.shape}")
    if columns is not None and not (array.ndim == 2 and array.shape[1] == columns) and array.size:
        raise InputError(f"{name} must be an (n, {columns}) array, not of shape {array.shape}")
    if columns is not None and not array.size:
        array = array.reshape(0, columns)
    if len(array) < min_rows:
        raise InputError(f"{name} needs at least {min_rows} values, has {len(array)}")
    if not np.all(np.isfinite(array)):
        finite = np.isfinite(array).reshape(len(array), -1).all(axis=1)
        where = "index" if array.ndim == 1 else "row"
        raise InputError(f"{name} has a NaN or infinite value (at {where} {int(np.argmin(finite))})")
    return array


def index_array(value: Any, name: str) -> np.ndarray:
    """int64 1-D array of whole numbers (integers, or floats with whole values)."""
    array = np.asarray(value)
    if array.dtype.kind not in "iuf" and array.size:
        raise InputError(f"{name} must be whole numbers, not {array.dtype}")
    if array.dtype.kind == "f" and array.size and not np.all(np.isfinite(array) & (array == np.round(array))):
        raise InputError(f"{name} must be whole numbers (indices), not fractions or NaN")
    return np.ascontiguousarray(array, dtype=np.int64).reshape(-1)


def increasing_times(value: Any, name: str, count: Optional[int] = None) -> np.ndarray:
    """Times in seconds: a 1-D array of finite numbers, strictly increasing (and `count` of them)."""
    times = finite_array(value, name)
    if count is not None and len(times) != count:
        raise InputError(f"{name}: {len(times)} times for {count} frames")
    if np.any(np.diff(times) <= 0):
        k = int(np.argmax(np.diff(times) <= 0)) + 1
        raise InputError(f"{name} must increase strictly: {float(times[k])!r} s at index {k} after "
                         f"{float(times[k - 1])!r} s")
    return times


def _shown(value: Any) -> str:
    """A value in a message: its type for objects, a short repr for numbers and text."""
    if value is None or isinstance(value, (bool, numbers.Number, str, bytes)):
        text = repr(value)
        return text if len(text) <= 40 else text[:37] + "..."
    return f"a {type(value).__name__}"
