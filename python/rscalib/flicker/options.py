"""Every option of the flicker job, with its default: the one place a default is written.

`rscalib flicker` fills :class:`FlickerOptions` from the flags a user typed; the Python front door
:func:`rscalib.flicker.pipeline.estimate_line_delay_flicker` takes the same object; the engine reads
the fields it needs. ``dataclasses.replace(options, field=value)`` changes one.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from typing import Optional, Union

from .. import checks
from ..errors import InputError
from ..readout import AUTO, ROW_DIRECTIONS, readout_direction

METHODS = ("auto", "spectrum", "phase-drift")
DETRENDS = ("auto", "frames", "smooth")
REGIONS = ("auto", "all")


@dataclass(frozen=True)
class FlickerOptions:
    """How `rscalib flicker` estimates the line delay from the bands of a flickering light
    (docs/formulation.md, flicker).

    The method: row profiles of column strips, the strips and rows with bands chosen; the phase
    drift through the frame timestamps (both signs of d) cross-checked by the bands' spectrum (|d|,
    each frame its own phase); the estimate refused when they disagree, when the fit leaves periodic
    structure, or when sigma exceeds a quarter of d."""

    rows: Optional[int] = None                 # sensor rows read out, for the readout time and the blanking
    #                                            (None: the image height)
    roi: Union[None, str, tuple] = None        # (x, y, w, h) px, or "x,y,w,h": the region whose columns are
    #                                            averaged (None: chosen, see `region`)
    region: str = "auto"                       # without roi: auto (the strips and rows with bands, overlays
    #                                            masked) | all (every strip)
    max_frames: Optional[int] = None           # the first N readable frames (None: all)
    method: str = "auto"                       # auto (phase drift with timestamps, cross-checked by the
    #                                            spectrum) | spectrum | phase-drift
    detrend: str = "auto"                      # the scene: auto | frames (constant over frames) | smooth
    #                                            (a polynomial of poly_degree per frame)
    harmonics: int = 12                        # harmonics of the band waveform at most (square-ish waves)
    poly_degree: int = 3                       # the smooth detrend's Legendre degree
    max_line_delay_s: Optional[float] = None   # the largest |d| searched, s/row (None: a frame's readout
    #                                            fits in its frame interval)
    readout: str = AUTO                        # auto (the phase drift tells; without timestamps top-to-bottom
    #                                            is assumed and said) | top-to-bottom | bottom-to-top (d < 0)

    def __post_init__(self) -> None:
        check_flicker_options(self)


def _whole(value, name: str, low: int, high: Optional[int] = None) -> int:
    """value as an int in [low, high] (a float with a whole value is one); InputError otherwise."""
    return checks.whole(value, name, low, high)


def roi_box(roi) -> Optional[tuple]:
    """(x, y, w, h) as ints from "x,y,w,h" or a sequence of four numbers (None stays None);
    InputError for anything else. Whether it fits the image is checked when the frames are read."""
    if roi is None:
        return None
    parts = roi.replace(" ", "").split(",") if isinstance(roi, str) else roi
    try:
        x, y, w, h = (int(round(float(c))) for c in parts)
    except (TypeError, ValueError):
        raise InputError(f"bad region {roi!r}: give x,y,w,h in pixels") from None
    if w <= 0 or h <= 0 or x < 0 or y < 0:
        raise InputError(f"bad region {roi!r}: x, y must be >= 0 and w, h positive (pixels)")
    return x, y, w, h


def check_flicker_options(options: FlickerOptions) -> None:
    """InputError (one line) for options that mean nothing; normalises rows, roi, max_frames,
    harmonics, poly_degree to ints and the readout words to rscalib.readout's."""
    def put(name, value):
        object.__setattr__(options, name, value)

    if options.rows is not None:
        put("rows", _whole(options.rows, "rows", 1, checks.MAX_ROWS))   # the CLI's --rows
    put("roi", roi_box(options.roi))
    if options.region not in REGIONS:
        raise InputError(f"unknown region choice {options.region!r} ({', '.join(REGIONS)})")
    if options.max_frames is not None:
        put("max_frames", _whole(options.max_frames, "max frames", 1, checks.MAX_FRAMES))
    if options.method not in METHODS:
        raise InputError(f"unknown method {options.method!r} ({', '.join(METHODS)})")
    if options.detrend not in DETRENDS:
        raise InputError(f"unknown detrend {options.detrend!r} ({', '.join(DETRENDS)})")
    put("harmonics", _whole(options.harmonics, "harmonics", 1))
    put("poly_degree", _whole(options.poly_degree, "the detrend's polynomial degree", 0))
    if options.max_line_delay_s is not None:
        limit = options.max_line_delay_s
        if isinstance(limit, bool) or not isinstance(limit, numbers.Real) or not (math.isfinite(limit) and limit > 0):
            raise InputError(f"the largest line delay searched must be a positive number of s/row, not {limit!r}")
    put("readout", readout_direction(options.readout, ROW_DIRECTIONS, auto=True))


def option_names() -> tuple:
    """The field names of FlickerOptions (the CLI and the architecture test read them)."""
    return tuple(f.name for f in fields(FlickerOptions))
