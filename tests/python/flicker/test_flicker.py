"""Line delay from flicker bands (`rscalib flicker`, rscalib.flicker).

Oracles: (a) frames synthesised here with numpy from the model gain 1 + A sin(2π f (t_i + v d) + φ)
on a random static scene (no renderer); (b) videos from `rscalib simulate --flicker-hz`, whose
truth.json records d and the flicker. "No flicker" is exit 3 (valid input, the data do not
determine d), bad input exit 2.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rscalib.cli import main
from rscalib.errors import InputError
from rscalib.flicker.options import FlickerOptions
from rscalib.flicker.pipeline import estimate_line_delay_flicker

SCRIPT = Path(sys.executable).parent / ("rscalib.exe" if os.name == "nt" else "rscalib")


def scene(height, width, rng):
    """A static scene with sharp-edged blocks, so its row profile is anything but flat."""
    yy, xx = np.mgrid[0:height, 0:width]
    radiance = 0.35 + 0.15 * xx / width + 0.1 * yy / height
    for _ in range(10):
        x0, y0 = rng.integers(0, width - 40), rng.integers(0, height - 40)
        radiance[y0:y0 + rng.integers(8, 40), x0:x0 + rng.integers(8, 40)] = rng.uniform(0.1, 0.8)
    return radiance


def synth(line_delay_s, frequency_hz, frames=10, fps=30.0, height=480, width=320, depth=0.3, noise=2.0,
          seed=0, scale=190.0):
    rng = np.random.default_rng(seed)
    radiance = scene(height, width, rng)
    times = np.arange(frames) / fps
    rows = np.arange(height)
    phase = rng.uniform(0, 2 * np.pi)
    images = []
    for t in times:
        gain = 1.0 + depth * np.sin(2 * np.pi * frequency_hz * (t + rows * line_delay_s) + phase)
        grey = scale * radiance * gain[:, None] + rng.normal(0.0, noise, radiance.shape)
        images.append(np.clip(np.rint(grey), 0, 255).astype(np.uint8))
    return np.array(images), times


def estimate(frames, frequency_hz, timestamps_s=None, **options):
    """The front door's FlickerResult (the engine's estimate behind the verdict)."""
    return estimate_line_delay_flicker(frames, frequency_hz, FlickerOptions(**options), timestamps_s=timestamps_s).result


def check(result, truth_s, rel_tol):
    assert result.determined, result.warnings
    assert abs(result.line_delay_s - truth_s) < rel_tol * truth_s
    assert abs(result.line_delay_s - truth_s) < 3 * result.line_delay_std_s
    assert result.line_delay_std_s < rel_tol * truth_s


# -- (a) synthetic frames, no renderer ------------------------------------------------------------------

@pytest.mark.parametrize("method", ["auto", "spectrum", "phase-drift"])
def test_led_bands_several_periods_per_frame(method):
    d = 30e-6
    images, times = synth(d, 2000.0, seed=1)  # period 16.7 rows
    result = estimate(images, 2000.0, times, method=method)
    check(result, d, 1e-5)
    assert result.period_rows == pytest.approx(1 / (2000.0 * d), rel=1e-5)
    assert result.readout_time_s == pytest.approx(result.line_delay_s * 480)
    assert result.method == ("phase-drift" if method == "auto" else method)


def test_mains_flicker_less_than_one_period_per_frame():
    # readout 7.2 ms < 10 ms period: only the phase drift between frames can pin d
    d = 15e-6
    images, times = synth(d, 100.0, frames=16, seed=2)
    result = estimate(images, 100.0, times)
    assert result.cycles_per_frame < 1.0
    assert result.method == "phase-drift"
    check(result, d, 1e-3)
    assert not result.estimates["spectrum"]["ok"]  # the spectrum alone cannot see a partial period


def test_without_timestamps_the_spectrum_is_used():
    d = 20e-6
    images, _ = synth(d, 1500.0, frames=6, fps=29.0, seed=3)
    result = estimate(images, 1500.0)
    assert result.method == "spectrum" and result.detrend == "frames"
    check(result, d, 1e-4)
    # at 30 fps every frame has the same flicker phase: the scene cannot be cancelled across frames,
    # so it falls back to a smooth per-frame detrend, less precise but still honest
    images, _ = synth(d, 1500.0, frames=6, fps=30.0, seed=3)
    result = estimate(images, 1500.0)
    assert result.detrend == "smooth"
    check(result, d, 1e-3)


def test_single_frame_uses_the_fit_uncertainty():
    d = 30e-6
    images, _ = synth(d, 3000.0, frames=1, seed=4)
    result = estimate(images[0], 3000.0)
    assert result.frames_used == 1 and result.detrend == "smooth"
    assert np.isnan(result.line_delay_std_spread_s)
    check(result, d, 1e-3)


def test_clipped_highlights_are_left_out():
    d = 30e-6
    images, times = synth(d, 1000.0, seed=5, scale=400.0)  # bright parts saturate at the flicker peaks
    assert np.mean(images == 255) > 0.05
    check(estimate(images, 1000.0, times), d, 1e-5)  # ~10x worse if clipped pixels counted


def test_commensurate_mains_flicker_is_undetermined():
    # 120 Hz at 30 fps: the same flicker phase in every frame and less than a period per frame
    images, times = synth(15e-6, 120.0, frames=12, seed=6)
    result = estimate(images, 120.0, times)
    assert not result.determined
    assert any("commensurate" in w for w in result.warnings)


def test_bad_api_input():
    images, times = synth(30e-6, 1000.0, frames=2)
    with pytest.raises(InputError):
        estimate(images, 0.0, times)
    with pytest.raises(InputError):
        estimate(images, 1000.0, times, roi=(0, 0, 400, 10))
    with pytest.raises(InputError):
        estimate(images, 1000.0, method="phase-drift")  # needs timestamps


# -- (b) rendered videos through the CLI ------------------------------------------------------------------

def simulate(out, *extra):
    code = main(["simulate", "--out", str(out), "--size", "320x240", "--duration", "0.4", "--motion", "0",
                 "--supersample", "1", "--quiet", *extra])
    assert code == 0
    return json.loads((out / "truth.json").read_text())


@pytest.mark.parametrize("frequency_hz, source", [(1000.0, "video.avi"), (100.0, "frames")])
def test_cli_on_rendered_flicker(tmp_path, capsys, frequency_hz, source):
    truth = simulate(tmp_path / "sim", "--flicker-hz", str(frequency_hz), "--flicker-depth", "0.3",
                     "--line-delay", "30us", "--frames-dir")
    assert truth["flicker"]["frequency_hz"] == frequency_hz and truth["flicker"]["depth"] == 0.3
    out = tmp_path / "out"
    code = main(["flicker", str(tmp_path / "sim" / source), "--frequency", str(frequency_hz), "--out", str(out),
                 "--quiet"])
    assert code == 0, capsys.readouterr().err
    result = json.loads((out / "result.json").read_text())
    d_true = truth["line_delay_s"]
    tolerance = 1e-4 if frequency_hz == 1000.0 else 2e-3
    assert abs(result["line_delay_s"] - d_true) < tolerance * d_true
    assert abs(result["line_delay_s"] - d_true) < 3 * result["line_delay_std_s"]
    assert result["readout_time_s"] == pytest.approx(result["line_delay_s"] * 240)
    assert result["rows"] == 240 and result["frequency_hz"] == frequency_hz and result["frames_used"] == 12
    assert result["method"] in ("spectrum", "phase-drift") and isinstance(result["warnings"], list)
    assert (out / "flicker.png").stat().st_size > 1000


# -- (c) bad input, (d) no flicker ----------------------------------------------------------------------

def run_cli(*args):
    argv = [str(SCRIPT), *args] if SCRIPT.exists() else [sys.executable, "-m", "rscalib.cli", *args]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args, reason", [
    (["missing.avi", "--frequency", "100"], "not found"),
    (["VIDEO", "--frequency", "0"], "frequency"),
    (["VIDEO", "--frequency", "100", "--roi", "0,0,5000,10"], "region"),
])
def test_cli_bad_input_exit_2_with_one_line(tmp_path, args, reason):
    video = tmp_path / "sim" / "video.avi"
    if "VIDEO" in args:
        simulate(tmp_path / "sim", "--duration", "0.1")
    args = [str(video) if a == "VIDEO" else a for a in args]
    result = run_cli("flicker", *args, "--out", str(tmp_path / "out"))
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and reason in lines[0] and "Traceback" not in result.stderr, result.stderr


def test_cli_no_flicker_exit_3_with_results(tmp_path, capsys):
    simulate(tmp_path / "sim")
    out = tmp_path / "out"
    assert main(["flicker", str(tmp_path / "sim" / "video.avi"), "--frequency", "1000", "--out", str(out),
                 "--quiet"]) == 3
    result = json.loads((out / "result.json").read_text())
    assert result["determined"] is False
    assert any("do not determine" in w and "no flicker" in w for w in result["warnings"])


def test_frames_too_big_for_memory_are_refused_before_decoding(tmp_path):
    # a header-only PNG of 60000 x 60000 px (over 10 GB to decode): refused from its header
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    path = tmp_path / "huge.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 60000, 60000, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))
    from rscalib.flicker.profiles import read_row_profiles
    with pytest.raises(InputError, match="huge.png.*memory"):
        read_row_profiles([path])
