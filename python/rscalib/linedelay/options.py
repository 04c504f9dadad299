"""Every option of the line-delay job, with its default: the one place a default is written.

`rscalib linedelay` fills :class:`LineDelayOptions` from the flags a user typed; the Python front
door :func:`rscalib.calibrate_video` takes the same object; the engine functions read the fields
they need. ``dataclasses.replace(options, field=value)`` changes one.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Optional, Union

from .. import checks
from ..detection.options import DetectOptions
from ..errors import InputError
from ..readout import AUTO, READOUT_DIRECTIONS, readout_direction

BASELINES = ("linear",)          # the paper's comparison: per-frame poses interpolated (Hedborg et al. 2012)
ROBUST_LOSSES = ("none", "huber", "cauchy")
LOCALIZE_MODELS = ("rs-spline", "gs-pnp")


@dataclass(frozen=True)
class LineDelayOptions:
    """How `rscalib linedelay` estimates the line delay (docs/formulation.md).

    The method: detections -> per-frame PnP -> a cubic B-spline trajectory with adaptive knots and
    the line delay, solved jointly (Oth et al. 2013), checked on the video's two halves."""

    # --- the method
    baseline: Optional[str] = None           # None: the method; "linear": the per-frame-pose baseline
    rows: Optional[int] = None               # sensor rows read out (None: the image height)
    pixel_sigma_px: Optional[float] = None   # detection noise (None: estimated from the target grid)
    robust_loss: str = "none"                # against bad detections: none | huber | cauchy
    max_rounds: int = 8                      # knot-adaptation rounds at most
    min_segment_s: Optional[float] = None    # shortest knot segment (None: half a frame, at most 1/60 s)
    readout: str = AUTO                      # readout direction, or auto (top-to-bottom / rotation metadata)
    start_s: Optional[float] = None          # use the frames from this time on
    end_s: Optional[float] = None            # ... up to this time
    self_check: bool = True                  # solve the video's two halves apart and widen sigma by their rule
    refine_intrinsics: bool = False          # the camera file a prior, refined with the line delay (§14)
    intrinsics_prior: Union[None, str, Path] = None   # `rscalib intrinsics` result.json as that prior
    # --- ablations of the method (the paper's comparisons; experiments)
    uniform_knots: Optional[int] = None      # N equal segments, no knot adaptation
    standardise_errors: bool = True          # weigh errors by A R A^T (paper §3.5)
    motion_prior: bool = True                # the acceleration penalty (paper §4.1)
    # --- detection (workers, cache, detector settings)
    detection: DetectOptions = DetectOptions()

    def __post_init__(self) -> None:
        check_line_delay_options(self)


@dataclass(frozen=True)
class LocalizeOptions:
    """How `rscalib localize` estimates the trajectory with a known line delay (paper §5.1)."""

    model: str = "rs-spline"                 # rs-spline: continuous-time; gs-pnp: per-frame PnP, for comparison
    rows: Optional[int] = None
    pixel_sigma_px: Optional[float] = None
    robust_loss: str = "none"
    max_rounds: int = 8
    detection: DetectOptions = DetectOptions()

    def __post_init__(self) -> None:
        if self.model not in LOCALIZE_MODELS:
            raise InputError(f"unknown localization model {self.model!r}; one of {', '.join(LOCALIZE_MODELS)}")
        _check_common(self)


def _check_common(options) -> None:
    if options.robust_loss not in ROBUST_LOSSES:
        raise InputError(f"unknown robust loss {options.robust_loss!r} ({', '.join(ROBUST_LOSSES)})")
    if options.rows is not None:
        if not isinstance(options.rows, int) or isinstance(options.rows, bool):
            raise InputError(f"rows must be a positive whole number, not {options.rows!r}")
        checks.whole(options.rows, "rows", 1, checks.MAX_ROWS, " rows")   # the CLI's --rows
    if options.pixel_sigma_px is not None and not 1e-4 <= float(options.pixel_sigma_px) <= 100.0:
        raise InputError(f"the pixel sigma must be in [0.0001, 100] px, not {options.pixel_sigma_px!r}")
    if not (isinstance(options.max_rounds, int) and 1 <= options.max_rounds <= 100):
        raise InputError(f"max_rounds must be 1 to 100, not {options.max_rounds!r}")
    if not isinstance(options.detection, DetectOptions):
        raise InputError("detection must be an rscalib.DetectOptions")


def check_line_delay_options(options: LineDelayOptions) -> None:
    """InputError (one line) for options that mean nothing, or that do not go together."""
    _check_common(options)
    if options.baseline is not None and options.baseline not in BASELINES:
        raise InputError(f"unknown baseline {options.baseline!r} (none, {', '.join(BASELINES)})")
    object.__setattr__(options, "readout", readout_direction(options.readout, READOUT_DIRECTIONS, auto=True))
    if options.min_segment_s is not None and not float(options.min_segment_s) > 0:
        raise InputError("the shortest knot segment must be positive")
    for name in ("start_s", "end_s"):
        value = getattr(options, name)
        if value is not None and not float("-inf") < float(value) < float("inf"):
            raise InputError(f"{name} must be a finite number of seconds")
    if options.uniform_knots is not None and not (isinstance(options.uniform_knots, int) and options.uniform_knots >= 1):
        raise InputError(f"uniform knots must be at least 1, not {options.uniform_knots!r}")
    if options.baseline == "linear":
        spline_only = [name for name, used in (("uniform knots", options.uniform_knots is not None),
                                               ("unstandardised errors", not options.standardise_errors),
                                               ("no motion prior", not options.motion_prior),
                                               ("refine intrinsics", options.refine_intrinsics)) if used]
        if spline_only:
            raise InputError(f"{', '.join(spline_only)}: only for the spline trajectory (the linear baseline has no "
                             "knots, no motion prior, unstandardised errors and a known camera)")
    if options.intrinsics_prior is not None and not options.refine_intrinsics:
        raise InputError("an intrinsics prior is only used with refine_intrinsics (--refine-intrinsics)")


def option_names(options_class) -> tuple:
    """The field names of an options class (the CLI and the architecture test read them)."""
    return tuple(f.name for f in fields(options_class))
