"""An --out folder belongs to the command that wrote it (issue 32): another command into it is one
line and exit 2 unless --force; a re-run of the same command is accepted."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from rscalib.errors import InputError
from rscalib.io.output_folder import check_output_folder, folder_owner

CLI = [sys.executable, "-m", "rscalib.cli"]


def _result_of(folder, command):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "result.json").write_text(json.dumps({"provenance": {"command": command}}))


def test_a_folder_belongs_to_the_command_of_its_results(tmp_path):
    out = tmp_path / "out"
    check_output_folder(out, command="linedelay")                 # a new folder: anyone's, nothing created
    assert not out.exists()
    _result_of(out, "linedelay")
    check_output_folder(out, command="linedelay")                 # a re-run: its own folder
    with pytest.raises(InputError, match=r"holds the results of `rscalib linedelay`.*--force"):
        check_output_folder(out, command="selfcalib")
    assert sorted(p.name for p in out.iterdir()) == ["result.json"]   # refused: nothing changed
    check_output_folder(out, command="selfcalib", force=True)


@pytest.mark.parametrize("name, content, owner", [
    ("result.json", {"provenance": {"command": "flicker"}}, "flicker"),
    ("truth.json", {"line_delay_s": 3e-5}, "simulate"),
    ("result.json", ["not", "a", "result"], None),
])
def test_the_owner_of_a_folder_without_a_mark(tmp_path, name, content, owner):
    (tmp_path / name).write_text(json.dumps(content))
    assert folder_owner(tmp_path) == owner


def test_a_folder_of_other_files_is_anyones(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    check_output_folder(tmp_path, command="intrinsics")
    assert folder_owner(tmp_path) is None and (tmp_path / "notes.txt").read_text() == "mine"


def _simulate_led(out):
    made = subprocess.run([*CLI, "simulate", "--led", "--flicker-hz", "100", "--out", out, "--frames", "20",
                           "--size", "160x120", "--quiet"], capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr


def test_cli_refuses_another_commands_folder_unless_forced(tmp_path):
    frames, out = tmp_path / "frames", tmp_path / "sim"
    _simulate_led(frames)
    _simulate_led(out)                       # a folder of `rscalib simulate`
    flicker = [*CLI, "flicker", frames, "--frequency", "100", "--out", out, "--quiet"]
    refused = subprocess.run(flicker, capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2
    lines = [line for line in refused.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "rscalib simulate" in lines[0] and "--force" in lines[0], refused.stderr
    assert not (out / "result.json").exists()
    forced = subprocess.run([*flicker, "--force"], capture_output=True, text=True, timeout=300)
    assert forced.returncode in (0, 3, 4), forced.stderr
    assert json.loads((out / "result.json").read_text())["provenance"]["command"] == "flicker"
    assert folder_owner(out) == "flicker" and (out / "truth.json").exists()   # the simulation's files stay
    again = subprocess.run(flicker, capture_output=True, text=True, timeout=300)   # its own folder now
    assert again.returncode == forced.returncode, again.stderr
