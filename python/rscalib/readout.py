"""The sensor's readout direction in the image: one vocabulary for every command and file.

A rolling shutter exposes the sensor's rows one after another. In the image that order runs
``top-to-bottom`` (most cameras), ``bottom-to-top`` (a sensor mounted upside down, or a picture
turned by 180°), or along the columns, ``left-to-right`` / ``right-to-left`` (a portrait phone video
whose player turns the landscape sensor by 90°). The words of earlier versions (``top-down``,
``bottom-up``, ``left-right``, ``right-left``) are still read, so old scripts and manifests work.
"""
from __future__ import annotations

from .errors import InputError

TOP_TO_BOTTOM, BOTTOM_TO_TOP, LEFT_TO_RIGHT, RIGHT_TO_LEFT = (
    "top-to-bottom", "bottom-to-top", "left-to-right", "right-to-left")
READOUT_DIRECTIONS = (TOP_TO_BOTTOM, BOTTOM_TO_TOP, LEFT_TO_RIGHT, RIGHT_TO_LEFT)
ROW_DIRECTIONS = (TOP_TO_BOTTOM, BOTTOM_TO_TOP)   # along the image rows (flicker bands, simulate)
AUTO = "auto"
_EARLIER_WORDS = {"top-down": TOP_TO_BOTTOM, "bottom-up": BOTTOM_TO_TOP, "left-right": LEFT_TO_RIGHT,
                  "right-left": RIGHT_TO_LEFT}
# Gyroflow's words (its lens profile's frame_readout_direction)
GYROFLOW_WORDS = {TOP_TO_BOTTOM: "TopToBottom", BOTTOM_TO_TOP: "BottomToTop", LEFT_TO_RIGHT: "LeftToRight",
                  RIGHT_TO_LEFT: "RightToLeft"}


def readout_direction(text: str, allowed: tuple = READOUT_DIRECTIONS, auto: bool = False) -> str:
    """``text`` as one of ``allowed`` (or ``auto`` when allowed), the earlier words mapped to today's;
    InputError naming the choices otherwise."""
    word = _EARLIER_WORDS.get(str(text).strip(), str(text).strip())
    if word in allowed or (auto and word == AUTO):
        return word
    choices = ((AUTO,) if auto else ()) + tuple(allowed)
    raise InputError(f"unknown readout direction {text!r} ({', '.join(choices)})")


def check_rows_read(rows, image_lines: int, option: str = "--rows") -> None:
    """InputError when the rows read out per frame (``rows``, None: not given) are fewer than the
    image's lines along the readout: a sensor reads at least the rows it delivers (the rows read
    count the blanking too, so more is possible, fewer is not)."""
    if rows is not None and int(rows) < int(image_lines):
        raise InputError(f"{option} {rows}: fewer than the {image_lines} image rows along the readout; the rows read "
                         f"out per frame are at least the image's (blanking adds to them)")
