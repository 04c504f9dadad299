"""help(rscalib) shows the curated API first (issue 32): its first screen names every job's front door
and its options class, and every name it shows there is public and importable."""
from __future__ import annotations

import pydoc
import re

import pytest

import rscalib

FRONT_DOORS = {"calibrate_video": "linedelay", "localize_video": "localize", "self_calibrate": "selfcalib",
               "estimate_line_delay_flicker": "flicker", "calibrate_intrinsics": "intrinsics"}


def test_help_shows_the_front_doors_on_its_first_screen():
    first_screen = "\n".join(pydoc.render_doc(rscalib, renderer=pydoc.plaintext).splitlines()[:30])
    for name, command in FRONT_DOORS.items():
        assert re.search(rf"rscalib\.{name}\(.*# rscalib {command}\b", first_screen), name
    shown = set(re.findall(r"rscalib\.([A-Za-z_]+)", first_screen))
    assert shown <= set(rscalib.__all__), shown - set(rscalib.__all__)
    for name in shown:
        assert getattr(rscalib, name) is not None


def test_every_public_name_resolves():
    for name in rscalib.__all__:
        assert getattr(rscalib, name) is not None, name
    assert {"LineDelayOptions", "SelfCalibOptions", "FlickerOptions", "IntrinsicsOptions", "Verdict"} <= set(
        rscalib.__all__)


@pytest.mark.parametrize("cls, field, value", [
    ("LineDelayOptions", "rows", -1), ("LineDelayOptions", "pixel_sigma_px", float("nan")),
    ("LineDelayOptions", "robust_loss", "bogus"), ("LineDelayOptions", "max_rounds", 0),
    ("LocalizeOptions", "model", "bogus"), ("SelfCalibOptions", "pixel_size_mm", -1.0),
    ("SelfCalibOptions", "line_delay_s", 1.0), ("SelfCalibOptions", "max_frames", -3),
    ("FlickerOptions", "rows", 0), ("FlickerOptions", "roi", (1, 2)), ("FlickerOptions", "readout", "sideways"),
    ("DetectOptions", "workers", -2), ("TrackOptions", "target_tracks", -5), ("TrackOptions", "reid_ratio", 1.5),
    ("TrackOptions", "fb_max_px", float("inf")), ("TrackOptions", "ransac_method", "lmeds"),
    ("TrackOptions", "anchor", "yes"),
    ("SelfCalibOptions", "pixel_size_mm", "0.007"), ("SelfCalibOptions", "ransac_hypotheses", -1),
    ("SelfCalibOptions", "ransac_hypotheses", 2.5), ("SelfCalibOptions", "restarts", "no"),
    ("SelfCalibOptions", "f_range_px", (100.0,)), ("SelfCalibOptions", "f_range_px", ("a", "b")),
    ("SelfCalibOptions", "line_delay_from", 42), ("SelfCalibOptions", "sprt_alpha", "0.1"),
    ("SelfCalibOptions", "robust_loss_scale_px", None), ("SelfCalibOptions", "determined_within", [0.02]),
    ("FrontEndOptions", "patch_half_px", 0), ("FrontEndOptions", "ncc_threshold", 1.5),
    ("FrontEndOptions", "min_visible", -1), ("FrontEndOptions", "max_search_half_px", float("nan")),
    ("FrontEndOptions", "max_warp_scale", 0.5), ("FrontEndOptions", "corner_quality", "high"),
])
def test_options_refuse_values_that_mean_nothing(cls, field, value):
    """The public options classes check their values as the CLI's converters do: InputError, one line."""
    with pytest.raises(rscalib.InputError) as error:
        _options_class(cls)(**{field: value})
    assert "\n" not in str(error.value)


def _options_class(name):
    if name == "FrontEndOptions":   # not on the package face: SelfCalibOptions(front_end=...)
        from rscalib.selfcalib.options import FrontEndOptions
        return FrontEndOptions
    return getattr(rscalib, name)


def test_selfcalib_options_f0_and_sigma_are_checked_for_the_single_baseline():
    for bad in (-5.0, float("nan"), "500"):
        with pytest.raises(rscalib.InputError, match="f0_px"):
            rscalib.SelfCalibOptions(baseline="single", f0_px=bad)
    assert rscalib.SelfCalibOptions(baseline="single", f0_px=500.0, f_sigma_px=50.0).f0_px == 500.0


def test_track_options_defaults_are_valid():
    assert rscalib.TrackOptions().scaled((320, 240)).target_tracks > 0
