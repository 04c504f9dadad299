"""The front door of the flicker job: frames of a flickering light -> the line delay with its
verdict, and the files. `rscalib flicker`, `rscalib batch` and the experiments all run
:func:`estimate_line_delay_flicker`; ``rscalib.estimate_line_delay_flicker`` is this one.

    the frames (a video, an image folder, image files, arrays; rscalib.flicker.profiles) -> row
    profiles of column strips -> the strips and rows with bands (region.py) -> the estimators and
    their checks (engine.py: spectrum.py, phase_drift.py over model.py) -> the verdict (judge.py)
    -> FlickerRun, whose .write(out_dir) writes what the CLI writes (report.py).

Never prints: progress goes through `progress` (rscalib._progress: True for a bar on stderr, or a
callable (done, total)).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from .. import checks
from .._progress import ProgressArg
from ..errors import InputError
from ..io.video import FrameSource
from ..verdict import Verdict
from .engine import estimate_from_profiles
from .judge import judge_flicker
from .options import FlickerOptions
from .profiles import RowProfiles, read_row_profiles
from .region import choose_region
from .result import FlickerResult


@dataclass
class FlickerRun:
    """What :func:`estimate_line_delay_flicker` returns: the line delay with its verdict, the
    estimate behind it, and :meth:`write` for the files `rscalib flicker` writes.

    result: the engine's estimate (FlickerResult: every estimator, check, the region, the blanking);
    options: those it ran with; inputs: the source and frequency as result.json's provenance records
    them."""

    result: FlickerResult
    verdict: Verdict
    options: FlickerOptions
    inputs: dict

    command = "flicker"

    @property
    def line_delay_s(self) -> Optional[float]:
        """The line delay in s/row (negative: bottom-to-top readout), None when the frames do not
        determine it (no number is claimed)."""
        return self.verdict.value

    @property
    def line_delay_std_s(self) -> Optional[float]:
        return self.verdict.std

    @property
    def readout_time_s(self) -> Optional[float]:
        """|line_delay_s| x rows read out (None when not determined)."""
        return None if self.line_delay_s is None else abs(self.line_delay_s) * self.result.rows

    def summary(self) -> dict:
        """The result.json fields (without the files and the provenance): the estimate's and the
        verdict block. Not determined: line_delay_s, line_delay_std_s, readout_time_s (and the other
        forms of the estimate) are null, the unclaimed estimate under not_claimed."""
        from .report import run_summary

        return run_summary(self)

    def write(self, out_dir) -> dict:
        """Write what `rscalib flicker` writes into out_dir, as one set (result.json last): result.json,
        the plots (flicker.png, and flicker_search.png when the phase drift ran) and report.html.
        Returns the result.json dict (without its provenance)."""
        from .report import write_flicker_run

        return write_flicker_run(self, out_dir)


def _described(source: Any) -> Any:
    """The source as result.json records it: paths as strings, arrays by their shape."""
    if isinstance(source, (str, Path)):
        return str(source)
    if isinstance(source, RowProfiles):
        return f"row profiles of {source.values.shape[0]} frames"
    if isinstance(source, np.ndarray):
        return f"array {'x'.join(str(n) for n in source.shape)} {source.dtype}"
    if isinstance(source, (list, tuple)) and source and all(isinstance(s, (str, Path)) for s in source):
        return [str(s) for s in source]
    if isinstance(source, (list, tuple)):
        return f"{len(source)} frames given as arrays"
    return type(source).__name__


def _check_source(source: Any) -> None:
    """InputError naming `source` for what estimate_line_delay_flicker cannot read: another type, an
    empty array, pixels that are not numbers or not finite."""
    if isinstance(source, (RowProfiles, FrameSource)):
        return
    if isinstance(source, np.ndarray) or (isinstance(source, (list, tuple)) and source
                                          and all(isinstance(item, np.ndarray) for item in source)):
        for frame in [source] if isinstance(source, np.ndarray) else source:
            if frame.size == 0:
                raise InputError(f"source: an empty array of frames (shape {frame.shape})")
            if frame.dtype.kind not in "uif":
                raise InputError(f"source: frames must hold numbers (pixel values), not {frame.dtype}")
            if frame.dtype.kind == "f" and not np.all(np.isfinite(frame)):
                raise InputError("source: the frames hold NaN or infinite pixel values")
        return
    checks.source(source, "source", also_words="a FrameSource, arrays (N, H, W) or a list of them, or RowProfiles")


def estimate_line_delay_flicker(source: Any, frequency_hz: float, options: Optional[FlickerOptions] = None, *,
                                timestamps_s: Optional[Sequence[float]] = None,
                                progress: ProgressArg = False) -> FlickerRun:
    """The line delay d (s/row) from the bands of a light flickering at ``frequency_hz``, with its
    verdict (`rscalib flicker`).

    source: a video file, an image folder (with an optional timestamps.txt), an image file or a list
        of them, a FrameSource, arrays (H, W) / (N, H, W) / (N, H, W, C) or a list of arrays, or
        RowProfiles already read (see :func:`rscalib.flicker.profiles.read_row_profiles`).
    frequency_hz: of the light's intensity (twice the mains frequency for mains lamps: 100 or 120 Hz;
        an LED's PWM frequency).
    options: FlickerOptions (None: the method's defaults).
    timestamps_s: the frames' row-0 times, for arrays or to replace a source's own (videos and
        folders with timestamps.txt carry theirs); without any, only the spectrum can be used.
    The result's .line_delay_s, .verdict and .write(out_dir) are what the command prints and writes."""
    started = time.perf_counter()
    # the CLI's --frequency range (rscalib.checks), the source and the times before any frame is read
    checks.number(frequency_hz, "frequency_hz (the flicker frequency)", 0.0, checks.MAX_FREQUENCY_HZ, " Hz",
                  low_open=True)
    if options is None:
        options = FlickerOptions()
    elif not isinstance(options, FlickerOptions):
        raise InputError(f"options must be a FlickerOptions, not {type(options).__name__} (frame timestamps go "
                         "in timestamps_s=)")
    _check_source(source)
    if timestamps_s is not None:
        timestamps_s = checks.increasing_times(timestamps_s, "timestamps_s")
    checks.progress(progress)
    profiles = source if isinstance(source, RowProfiles) else read_row_profiles(
        source, timestamps_s, roi=options.roi, max_frames=options.max_frames, progress=progress)
    if profiles.strips is not None and not profiles.region:
        choose_region(profiles, auto=(options.region == "auto" and profiles.roi is None))
    result = estimate_from_profiles(profiles, frequency_hz, options)
    result.plot["seconds"] = time.perf_counter() - started
    inputs = {"source": _described(source), "frequency_hz": float(frequency_hz)}
    return FlickerRun(result, judge_flicker(result, options.readout), options, inputs)
