"""Tests of the `rscalib` command line: version, help, exit codes, the demo.

The installed console script is run as a subprocess (falling back to `python -m rscalib.cli`
when the script is not next to the interpreter, e.g. in a system-wide install).
"""
import os
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

import rscalib

SCRIPT = Path(sys.executable).parent / ("rscalib.exe" if os.name == "nt" else "rscalib")


def command(*args):
    if SCRIPT.exists():
        return [str(SCRIPT), *args]
    return [sys.executable, "-m", "rscalib.cli", *args]


def run(*args, timeout=60):
    return subprocess.run(command(*args), capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("launcher", ["script", "module"])
def test_version(launcher):
    argv = command("--version") if launcher == "script" else [sys.executable, "-m", "rscalib.cli", "--version"]
    result = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == f"rscalib {version('rscalib')}"
    assert rscalib.__version__ == version("rscalib")


def test_help_lists_subcommands():
    result = run("--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: rscalib")
    assert "demo" in result.stdout
    assert "--version" in result.stdout
    assert result.stderr == ""


def test_subcommand_help():
    result = run("demo", "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: rscalib demo")


def test_unknown_subcommand_is_bad_input():
    result = run("frobnicate")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert "frobnicate" in lines[0] and "error" in lines[0]
    assert result.stdout == ""


def test_unknown_option_is_bad_input():
    result = run("demo", "--no-such-option")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "--no-such-option" in lines[0], result.stderr


def test_no_subcommand_exits_2_without_traceback():
    result = run()
    assert result.returncode == 2
    assert "Traceback" not in result.stderr + result.stdout
    assert "demo" in result.stdout + result.stderr  # tells the user what the commands are


def test_demo_runs():
    result = run("demo", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert f"rscalib {version('rscalib')} demo" in result.stdout
    assert len(result.stdout.splitlines()) >= 3


def test_simulate_scene_writes_a_self_calibration_sequence(tmp_path):
    """`simulate --scene`: PNG frames, timestamps.txt and truth.json with the paper's camera, which
    `selfcalib` reads as an image folder."""
    import json

    out = tmp_path / "room"
    result = run("simulate", "--scene", "--out", str(out), "--duration", "0.2", "--fps", "20", "--quiet",
                 timeout=300)
    assert result.returncode == 0, result.stderr
    frames = sorted(out.glob("frame_*.png"))
    assert len(frames) == 4
    times = [float(t) for t in (out / "timestamps.txt").read_text().split()]
    assert times == pytest.approx([0.0, 0.05, 0.1, 0.15])
    truth = json.loads((out / "truth.json").read_text())
    assert truth["camera"]["model"] == "civera-radial"
    assert truth["camera"]["params"][0] == pytest.approx(194.06)
    assert (truth["camera"]["width"], truth["camera"]["height"]) == (320, 240)
    bad = run("simulate", "--scene", "--out", str(tmp_path / "x"), "--duration", "0")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
