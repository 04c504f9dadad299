"""Structure-aware fuzzing of every reader of a user's file (issue 33): camera files of every format,
target files and batch manifests, built field by field and written in every syntax the readers take
(YAML block and flow, JSON, OpenCV FileStorage YAML and XML, Python literals, COLMAP lines, CSV), with
what a careless script or an attacker puts in them: deep nesting (up to 10^5 levels), YAML anchors
and aliases up to "billion laughs", integers of thousands of digits, NaN and inf, every wrong type
in every field, and valid-but-unusual syntax (flow style, comments, quoted brackets, a byte-order
mark, CRLF lines, a newline in the file name).

Each example is read in a child process (a reader server, restarted after a failure) with a time
limit and a 4 GiB address-space limit, so that a segfault, a hang or a memory blow-up is a failing
example, not the end of the test run. The property: the reader returns a valid object (finite
numbers in range) or raises InputError with one line; nothing else.

Deterministic (derandomize=True) and bounded: about a minute in `make test`. More examples by hand:
RSCALIB_FUZZ_SCALE=10 .venv/bin/python -m pytest -q tests/python/fuzz/test_untrusted_fuzz.py
"""
from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

SCALE = max(1, int(os.environ.get("RSCALIB_FUZZ_SCALE", "1")))
EXAMPLE_TIMEOUT_S = 30.0   # per example; the readers answer in milliseconds (the machine may be loaded)
CHILD_ADDRESS_SPACE_BYTES = 4 << 30
FUZZ = dict(derandomize=True, deadline=None, database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])

# The reader server: one request per line ({"reader", "path"}), one answer per line.
SERVER = textwrap.dedent(r"""
    import faulthandler, json, math, resource, sys, warnings
    faulthandler.enable()
    resource.setrlimit(resource.RLIMIT_AS, (%d, %d))
    warnings.simplefilter("ignore")
    import numpy as np
    from rscalib.errors import InputError
    from rscalib.io.cameras import load_camera
    from rscalib.io.targets import load_target
    from rscalib.batch.manifest import load_manifest

    def camera(path):
        read = load_camera(path)
        c = read.camera
        p = np.asarray(c.params, dtype=float)
        ok = (1 <= c.width <= 100000 and 1 <= c.height <= 100000 and np.all(np.isfinite(p)) and p[0] > 0
              and p[1] > 0 and (read.line_delay_s is None or (math.isfinite(read.line_delay_s)
                                                              and abs(read.line_delay_s) <= 0.01)))
        return ok, f"{read.source_format} {c.model} {c.width}x{c.height}"

    def target(path):
        t = load_target(path)
        ok = 0 < t.num_points <= 10000 and bool(np.all(np.isfinite(t.points_m)))
        return ok, f"{t.target_type} {t.num_points} points"

    def manifest(path):
        jobs = load_manifest(path)
        ok = bool(jobs) and len({j.id for j in jobs}) == len(jobs) and all(
            j.argv and j.argv[0] in ("linedelay", "intrinsics", "flicker", "selfcalib") for j in jobs)
        return ok, f"{len(jobs)} jobs"

    READERS = {"camera": camera, "target": target, "manifest": manifest}
    print("ready", flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        try:
            ok, what = READERS[request["reader"]](request["path"])
            answer = {"kind": "read" if ok else "bad value", "what": what}
        except InputError as error:
            text = str(error)
            answer = {"kind": "refused" if "\n" not in text and text else "bad message", "what": text[:300]}
        except BaseException as error:
            answer = {"kind": "other exception", "what": f"{type(error).__name__}: {str(error)[:300]}"}
        print(json.dumps(answer), flush=True)
""") % (CHILD_ADDRESS_SPACE_BYTES, CHILD_ADDRESS_SPACE_BYTES)


class ReaderServer:
    """A child interpreter that reads files on request; a crash or a hang ends it (and is reported),
    the next request starts a new one. `answers` counts the answers by reader and kind."""

    def __init__(self):
        self.process = None
        self.answers: dict = {}

    def _start(self) -> None:
        self.process = subprocess.Popen([sys.executable, "-c", SERVER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True, bufsize=1)
        assert self._line(120.0) == "ready", self._stop()

    def _line(self, timeout_s: float):
        ready, _, _ = select.select([self.process.stdout], [], [], timeout_s)
        return self.process.stdout.readline().strip() if ready else None

    def _stop(self) -> str:
        self.process.kill()
        _, err = self.process.communicate(timeout=30)
        code, self.process = self.process.returncode, None
        return f"exit {code}: {err[-2000:]}"

    def read(self, reader: str, path: Path) -> dict:
        if self.process is None:
            self._start()
        self.process.stdin.write(json.dumps({"reader": reader, "path": str(path)}) + "\n")
        self.process.stdin.flush()
        line = self._line(EXAMPLE_TIMEOUT_S)
        answer = json.loads(line) if line else {"kind": "hang or crash", "what": self._stop()}
        key = (reader, answer["kind"])
        self.answers[key] = self.answers.get(key, 0) + 1
        return answer

    def close(self) -> None:
        if self.process is not None:
            self.process.stdin.close()
            self.process.wait(30)


@pytest.fixture(scope="module")
def server():
    s = ReaderServer()
    yield s
    s.close()


@pytest.fixture(scope="module")
def folder():
    with tempfile.TemporaryDirectory() as name:
        yield Path(name)


# -- values ------------------------------------------------------------------------------------------------


class Deep:
    """`inner` inside `levels` lists (written without recursion, so 10^5 levels cost nothing to make)."""

    def __init__(self, levels: int, inner):
        self.levels, self.inner = levels, inner


class Raw:
    """Text written as it is (a 5000-digit integer, .nan, an alias)."""

    def __init__(self, text: str):
        self.text = text


NASTY_SCALARS = st.one_of(
    st.sampled_from([Raw("9" * 5000), Raw("-" + "1" * 4400), Raw("1" + "0" * 120), Raw(".nan"), Raw(".inf"),
                     Raw("-.inf"), Raw("1e999"), Raw("0x7fffffffffffffff"), Raw("0o777"), Raw("1_000"),
                     Raw("190:20:30"), Raw("2001-12-14"), Raw("~"), Raw("!!binary aGVsbG8="), Raw("'[[[[['"),
                     Raw('"]]]"'), Raw("'#not a comment'")]),
    st.none(), st.booleans(), st.integers(-10 ** 30, 10 ** 30), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12))
DEPTHS = st.sampled_from([2, 30, 63, 65, 200, 3000, 100_000, 100_000])


def nasty(valid) -> st.SearchStrategy:
    """What a field may hold instead of `valid`: a nasty scalar, a wrong container, deep nesting."""
    return st.one_of(
        NASTY_SCALARS, st.lists(NASTY_SCALARS, max_size=4),
        st.dictionaries(st.text(max_size=4), NASTY_SCALARS, max_size=3),
        st.builds(Deep, DEPTHS, st.just(valid)), st.builds(Deep, DEPTHS, st.just(valid)),
        st.builds(lambda v: [v], st.just(valid)), st.builds(lambda v: {"value": v}, st.just(valid)),
    )


def corrupted(draw, fields: dict, keep=()) -> dict:
    """`fields` with none, one or two of them (not in `keep`) replaced by a nasty value: most examples
    are valid files in unusual syntax, the rest are wrong in a field or two."""
    names = [k for k in fields if k not in keep]
    chosen = draw(st.lists(st.sampled_from(names), max_size=2, unique=True)) if draw(st.booleans()) else []
    return {k: (draw(nasty(v)) if k in chosen else v) for k, v in fields.items()}


def emit(value, syntax: str) -> str:
    """`value` as flow YAML, JSON or a Python literal (Deep and Raw as they say)."""
    if isinstance(value, Deep):
        open_, close = "[" * value.levels, "]" * value.levels
        return open_ + emit(value.inner, syntax) + close
    if isinstance(value, Raw):
        if syntax == "json":
            text = value.text
            return text if text.lstrip("-").isdigit() else json.dumps(text)
        if syntax == "python":
            text = value.text
            return text if text.lstrip("-").replace("_", "").isdigit() or text.startswith(("'", '"')) else repr(text)
        return value.text
    if isinstance(value, dict):
        items = ", ".join(f"{emit(str(k), syntax)}: {emit(v, syntax)}" for k, v in value.items())
        return "{" + items + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(emit(v, syntax) for v in value) + "]"
    if syntax == "python":
        return repr(value)
    if syntax == "json":
        return json.dumps(value)
    if isinstance(value, str):
        return json.dumps(value)   # a double-quoted YAML scalar
    if isinstance(value, float) and value != value:
        return ".nan"
    if isinstance(value, float) and value in (float("inf"), float("-inf")):
        return ".inf" if value > 0 else "-.inf"
    return json.dumps(value)


def mapping(fields: dict, syntax: str, draw) -> str:
    """A mapping of fields in `syntax`: "yaml" (block, each value flow), "flow", "json", "python"."""
    if syntax == "yaml":
        return "".join(f"{key}: {emit(value, 'yaml')}\n" for key, value in fields.items())
    inner = "json" if syntax == "json" else ("python" if syntax == "python" else "yaml")
    sep = draw(st.sampled_from([", ", ",\n  ", " ,"]))
    return "{" + sep.join(f"{emit(str(k), inner)}: {emit(v, inner)}" for k, v in fields.items()) + "}\n"


ALIAS_PRELUDES = st.sampled_from([
    "base: &b [1, 2, 3]\nagain: *b\n",
    "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]\n" for i in range(1, 10)).replace("*l0", "1"),
    "a: &a [x, *a]\n",   # an alias inside the value it names
])


def alias_prelude(draw) -> str:
    """Now and then, anchors and aliases before the fields: harmless ones, a bomb, a self-reference."""
    return draw(ALIAS_PRELUDES) if draw(st.integers(0, 3)) == 0 else ""


@st.composite
def unusual_text(draw, text: str) -> str:
    """Valid-but-unusual spellings of the same file: CRLF, a byte-order mark, comments."""
    if draw(st.integers(0, 3)) == 0 and not text.startswith("%YAML"):   # OpenCV's header stays the first line
        text = "# a comment with [[[ and ' and #\n" + text
    if draw(st.booleans()):
        text = text.replace("\n", "\r\n")
    if draw(st.integers(0, 4)) == 0:
        text = "\ufeff" + text
    if draw(st.integers(0, 7)) == 0:   # a control character or a stray byte's replacement somewhere
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.sampled_from(["\0", "\x1b", "\x85", "\ufffd", "\u2028", "\x7f"])) + text[at:]
    return text


def file_name(draw, stem: str, suffix: str) -> str:
    return draw(st.sampled_from([stem, stem + " copy", stem + "\nnewline", stem + "-é"])) + suffix


# -- camera files ---------------------------------------------------------------------------------------------

K = [[500.0, 0.0, 319.5], [0.0, 501.0, 239.5], [0.0, 0.0, 1.0]]


@st.composite
def camera_files(draw):
    fmt = draw(st.sampled_from(["kalibr", "ros", "gyroflow", "mrcal", "opencv", "colmap"]))
    if fmt == "kalibr":
        cam = corrupted(draw, {"camera_model": "pinhole", "intrinsics": [500.0, 501.0, 319.5, 239.5],
                               "distortion_model": "radtan", "distortion_coeffs": [-0.1, 0.05, 0.0, 0.0],
                               "resolution": [640, 480], "line_delay": 3e-5})
        syntax = draw(st.sampled_from(["yaml", "flow", "json"]))
        if syntax == "yaml":
            text = "cam0:\n" + textwrap.indent(mapping(cam, "yaml", draw), "  ")
        else:
            text = mapping({"cam0": cam}, syntax, draw)
        name = file_name(draw, "camchain", draw(st.sampled_from([".yaml", ".json"])))
    elif fmt == "ros":
        fields = corrupted(draw, {"image_width": 640, "image_height": 480,
                                  "camera_matrix": {"rows": 3, "cols": 3, "data": [v for row in K for v in row]},
                                  "distortion_model": "plumb_bob",
                                  "distortion_coefficients": {"rows": 1, "cols": 5, "data": [-0.1, 0.05, 0, 0, 0]}})
        text = mapping(fields, draw(st.sampled_from(["yaml", "flow", "json"])), draw)
        if draw(st.integers(0, 3)) == 0:
            text = "%YAML:1.0\n---\n" + text
        name = file_name(draw, "camera_info", ".yaml")
    elif fmt == "gyroflow":
        fields = corrupted(draw, {"calib_dimension": {"w": 640, "h": 480}, "distortion_model": "opencv_standard",
                                  "asymmetrical": True, "frame_readout_time": 14.4,
                                  "frame_readout_direction": "TopToBottom",
                                  "fisheye_params": {"camera_matrix": K, "distortion_coeffs": [0.0] * 5}})
        text = mapping(fields, "json", draw)
        name = file_name(draw, "lens", ".json")
    elif fmt == "mrcal":
        fields = corrupted(draw, {"lensmodel": "LENSMODEL_OPENCV4", "intrinsics": [500, 501, 319.5, 239.5, -0.1, 0.05, 0, 0],
                                  "imagersize": [640, 480], "extrinsics": [0] * 6,
                                  "note": draw(st.sampled_from(["board #3", "a ] and a [", "plain"]))})
        text = "# mrcal\n" + mapping(fields, "python", draw)
        name = file_name(draw, "camera", draw(st.sampled_from([".cameramodel", ".txt.cameramodel"])))
    elif fmt == "opencv":
        picked = corrupted(draw, {"data": [v for row in K for v in row], "width": 640})
        data, width = picked["data"], picked["width"]
        if draw(st.booleans()):
            text = ("%YAML:1.0\n---\n" + f"image_width: {emit(width, 'yaml')}\nimage_height: 480\n"
                    f"camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: {emit(data, 'yaml')}\n")
            name = file_name(draw, "camera", ".yaml")
        else:
            levels = draw(st.sampled_from([1, 5, 100_000]))
            text = ('<?xml version="1.0"?>\n<opencv_storage>\n' + "<a>" * (levels - 1)
                    + f"<image_width>{emit(width, 'json')}</image_width>" + "</a>" * (levels - 1)
                    + "<image_height>480</image_height>\n<camera_matrix type_id=\"opencv-matrix\"><rows>3</rows>"
                    f"<cols>3</cols><dt>d</dt><data>{' '.join(map(str, sum(K, [])))}</data></camera_matrix>\n"
                    "</opencv_storage>\n")
            name = file_name(draw, "camera", ".xml")
    else:
        params = draw(st.one_of(st.just("500 501 319.5 239.5 -0.1 0.05 0 0"), st.just("9" * 5000 + " 1 2 3 0 0 0 0"),
                                st.text(alphabet="0123456789.-e naif", max_size=40)))
        model = draw(st.sampled_from(["OPENCV", "PINHOLE", "FULL_OPENCV", "SIMPLE_RADIAL", "NOPE"]))
        text = f"# COLMAP\n1 {model} {draw(st.sampled_from(['640', '0', '9' * 5000]))} 480 {params}\n"
        name = file_name(draw, "cameras", ".txt")
    if fmt in ("kalibr", "ros") and "yaml" in name:
        text = alias_prelude(draw) + text if not text.startswith(("{", "%")) else text
    return name, draw(unusual_text(text)) if fmt not in ("opencv", "colmap") else text


@settings(max_examples=150 * SCALE, **FUZZ)
@given(case=camera_files())
def test_camera_files_are_read_or_refused_in_one_line(server, folder, case):
    name, text = case
    path = folder / name
    path.write_text(text, encoding="utf-8")
    answer = server.read("camera", path)
    note(f"{name!r}: {text[:300]!r}")
    assert answer["kind"] in ("read", "refused"), answer


# -- targets -----------------------------------------------------------------------------------------------


@st.composite
def target_files(draw):
    kind = draw(st.sampled_from(["checkerboard", "circlegrid", "aprilgrid", "charuco"]))
    fields = {"checkerboard": {"targetCols": 9, "targetRows": 6, "rowSpacingMeters": 0.04, "colSpacingMeters": 0.04},
              "circlegrid": {"targetCols": 4, "targetRows": 11, "spacingMeters": 0.02, "asymmetricGrid": True},
              "aprilgrid": {"tagCols": 6, "tagRows": 6, "tagSize": 0.088, "tagSpacing": 0.3},
              "charuco": {"squaresX": 5, "squaresY": 7, "squareLength": 0.04, "markerLength": 0.03,
                          "dictionary": "DICT_5X5_100"}}[kind]
    fields = corrupted(draw, {"target_type": kind, **fields})
    text = alias_prelude(draw) + mapping(fields, "yaml", draw) if draw(st.booleans()) else \
        mapping(fields, draw(st.sampled_from(["flow", "json"])), draw)
    return file_name(draw, "target", ".yaml"), draw(unusual_text(text))


@settings(max_examples=100 * SCALE, **FUZZ)
@given(case=target_files())
def test_target_files_are_read_or_refused_in_one_line(server, folder, case):
    name, text = case
    path = folder / name
    path.write_text(text, encoding="utf-8")
    answer = server.read("target", path)
    note(f"{name!r}: {text[:300]!r}")
    assert answer["kind"] in ("read", "refused"), answer


# -- manifests -----------------------------------------------------------------------------------------------


@st.composite
def manifests(draw):
    rows = [corrupted(draw, {"id": f"job{i}", "command": "flicker", "input": f"v{i}.avi", "frequency": 100,
                             "mode": "1080p30"}) for i in range(draw(st.integers(1, 3)))]
    if draw(st.booleans()):   # CSV: the cells as text; headers repeated, reordered, with a BOM
        columns = draw(st.permutations(["id", "command", "input", "frequency", "mode"]))
        if draw(st.integers(0, 4)) == 0:
            columns = [*columns, draw(st.sampled_from(["frequency", " frequency", "Frequency", "freq_uency"]))]
        quote = draw(st.booleans())

        def cell(value) -> str:
            text = emit(value, "yaml") if not isinstance(value, str) else value
            text = text[:6000]
            return '"' + text.replace('"', '""') + '"' if quote or "," in text or "\n" in text else text

        lines = [",".join(columns)] + [",".join(cell(row.get(c.strip(), "")) for c in columns) for row in rows]
        return file_name(draw, "jobs", ".csv"), draw(unusual_text("\n".join(lines) + "\n"))
    body = "jobs:\n" + "".join("  - " + mapping(row, "flow", draw) for row in rows)
    prelude = draw(st.sampled_from(["", "", "", "defaults: &d {frequency: 100}\nshared: *d\n",
                                    "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]\n"
                                            for i in range(1, 10)).replace("*l0", "1")]))
    return file_name(draw, "jobs", ".yaml"), draw(unusual_text(prelude + body))


@settings(max_examples=120 * SCALE, **FUZZ)
@given(case=manifests())
def test_manifests_are_jobs_or_refused_in_one_line(server, folder, case):
    name, text = case
    path = folder / name
    path.write_text(text, encoding="utf-8")
    answer = server.read("manifest", path)
    note(f"{name!r}: {text[:300]!r}")
    assert answer["kind"] in ("read", "refused"), answer


def test_the_suites_reach_both_answers(server, folder):
    """The strategies are not all refusals: valid files of each family are read, and (when the
    suites above ran) both answers came from the drawn examples."""
    (folder / "camchain.yaml").write_text("cam0:\n  intrinsics: [500, 501, 319.5, 239.5]\n  distortion_coeffs: "
                                         "[0, 0, 0, 0]\n  resolution: [640, 480]\n")
    (folder / "t.yaml").write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.04\n"
                                   "colSpacingMeters: 0.04\n")
    (folder / "m.csv").write_text("command,input,frequency\nflicker,a.avi,100\n")
    drawn = dict(server.answers)
    print("answers of the drawn examples:", sorted(drawn.items()))
    for reader in ("camera", "target", "manifest"):
        if drawn.get((reader, "refused")):   # its suite ran
            assert drawn.get((reader, "read"), 0) >= 5 and drawn[(reader, "refused")] >= 5, drawn
    for reader, name in (("camera", "camchain.yaml"), ("target", "t.yaml"), ("manifest", "m.csv")):
        assert server.read(reader, folder / name)["kind"] == "read"


def _census(reader_server, scratch: str, reader: str, strategy, count: int, kinds, tally):
    """Read `count` examples of `strategy`; count the answers (for the census below)."""
    import re

    @settings(max_examples=count * SCALE, **FUZZ)
    @given(case=strategy)
    def run(case):
        name, text = case
        path = Path(scratch) / name
        path.write_text(text, encoding="utf-8")
        answer = reader_server.read(reader, path)
        kinds[(reader, answer["kind"])] += 1
        if answer["kind"] not in ("read", "refused"):
            tally[(reader, answer["kind"], re.sub(r"\d+", "N", answer["what"].replace(scratch, ""))[:100])] += 1

    run()


if __name__ == "__main__":
    # The census of docs/reliability.md: the suites' examples (the same ones pytest draws) by answer.
    # PYTHONPATH=python .venv/bin/python tests/python/fuzz/test_untrusted_fuzz.py
    import collections

    tally, kinds = collections.Counter(), collections.Counter()
    with tempfile.TemporaryDirectory() as scratch:
        reader_server = ReaderServer()
        for family, strategy, count in (("camera", camera_files(), 150), ("target", target_files(), 100),
                                        ("manifest", manifests(), 120)):
            _census(reader_server, scratch, family, strategy, count, kinds, tally)
        reader_server.close()
    for key in sorted(kinds):
        print(*key, kinds[key])
    for key, n in tally.most_common():
        print(n, *key)
