"""The batch manifest: CSV and YAML rows into single-command argv; bad rows are one line naming the
file, row and field (exit 2)."""
from __future__ import annotations

import textwrap

import pytest

from rscalib.batch.manifest import load_manifest
from rscalib.cli import build_parser, main
from rscalib.errors import InputError

PARSE = build_parser().parse_args   # the rows are checked with the commands' own parser (as `rscalib batch`)


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text).lstrip())
    return path


def test_csv_rows_become_the_single_commands_with_paths_from_the_manifest_folder(tmp_path):
    manifest = write(tmp_path, "m.csv", """
        id,command,input,mode,target,camera,frequency,no-self-check
        a,linedelay,videos/a.avi,1080p30,board.yaml,cam.yaml,,true
        ,flicker,led/clip.mp4,,,,1000,
        """)
    a, b = load_manifest(manifest, PARSE)
    assert a.id == "a" and a.mode == "1080p30" and a.row == 1
    assert a.argv == ("linedelay", str(tmp_path / "videos/a.avi"), "--target", str(tmp_path / "board.yaml"),
                      "--camera", str(tmp_path / "cam.yaml"), "--no-self-check", "--workers", "1", "--quiet")
    assert a.inputs == (str(tmp_path / "videos/a.avi"), str(tmp_path / "board.yaml"), str(tmp_path / "cam.yaml"))
    assert b.id == "flicker-led-clip" and b.mode == ""
    assert b.argv == ("flicker", str(tmp_path / "led/clip.mp4"), "--frequency", "1000", "--quiet")
    assert a.command_argv("out/a")[-2:] == ["--out", "out/a"]
    assert a.spec_hash("1.0") != a.spec_hash("1.1")


def test_yaml_with_defaults_lists_and_flags(tmp_path):
    manifest = write(tmp_path, "m.yaml", """
        defaults:
          target: board.yaml
        jobs:
          - {id: stills, command: intrinsics, input: [s1, s2], max_views: 30}
          - {command: selfcalib, input: room, f-range: [100, 600], no-restarts: true, target: null}
        """)
    stills, walk = load_manifest(manifest, PARSE)
    assert stills.argv == ("intrinsics", str(tmp_path / "s1"), str(tmp_path / "s2"), "--target",
                           str(tmp_path / "board.yaml"), "--max-views", "30", "--workers", "1", "--quiet")
    assert walk.argv == ("selfcalib", str(tmp_path / "room"), "--f-range", "100", "600", "--no-restarts", "--quiet")


@pytest.mark.parametrize("rows, expected", [
    ("command,input\nlinedelays,a.avi\n", "row 1 (line 2): field 'command': 'linedelays' is not one of"),
    ("command,input\nflicker,\n", "row 1 (line 2): field 'input': missing"),
    ("command,input,frequency,frequncy\nflicker,a.avi,1,2\n", "field 'frequncy': unrecognized arguments: --frequncy 2"),
    ("command,input,frequency\nflicker,a.avi,fast\n", "field 'frequency': argument --frequency: not a number"),
    ("command,input\nflicker,a.avi\n", "field 'frequency': the following arguments are required: --frequency"),
    ("command,input,out\nflicker,a.avi,x\n", "field 'out': is set by the batch"),
    ("id,command,input,frequency\nx,flicker,a.avi,1\nx,flicker,b.avi,1\n", "row 2 (line 3): field 'id': 'x' is "
                                                                             "also the id of row 1"),
    ("id,command,input,frequency\n../x,flicker,a.avi,1\n", "field 'id': '../x' must be letters"),
    ("command,input\nlinedelay,a.avi;b.avi\n", "field 'input': linedelay takes one video"),
    ("input\na.avi\n", "line 1: the header needs a 'command' column"),
    ("command,input\n", "no jobs"),
])
def test_a_bad_row_names_the_file_row_and_field(tmp_path, rows, expected):
    manifest = tmp_path / "m.csv"
    manifest.write_text(rows)
    with pytest.raises(InputError) as error:
        load_manifest(manifest, PARSE)
    assert str(error.value).startswith(f"{manifest}: ") and expected in str(error.value), str(error.value)


def test_yaml_problems_and_other_files(tmp_path):
    with pytest.raises(InputError, match=r"m.yaml: row 2: a job is a mapping"):
        load_manifest(write(tmp_path, "m.yaml", "- {command: flicker, input: a, frequency: 1}\n- flicker\n"), PARSE)
    with pytest.raises(InputError, match="not valid YAML"):
        load_manifest(write(tmp_path, "n.yaml", "jobs: [\n"), PARSE)
    with pytest.raises(InputError, match="a .csv or .yaml file"):
        load_manifest(write(tmp_path, "m.txt", "x"), PARSE)
    with pytest.raises(InputError, match="manifest not found"):
        load_manifest(tmp_path / "none.csv", PARSE)


def test_the_command_line_says_one_line_and_exits_2(tmp_path, capsys):
    manifest = write(tmp_path, "m.csv", "command,input\nselfcalib,room\nlinedelay,v.avi\n")
    assert main(["batch", str(manifest), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "m.csv: row 2 (line 3): field 'target'" in err, err
    assert not (tmp_path / "out").exists()
    assert main(["batch", "--out", str(tmp_path / "out")]) == 2
    assert "give a MANIFEST and --out DIR" in capsys.readouterr().err
