"""Calibration targets: Kalibr-style YAML definitions and their point layouts (docs/conventions.md: target frames).

Every target point has a fixed id (its row in `Target.points_m`), so a detection is a list of
(id, pixel) pairs and partial views need no special handling downstream. Points lie on z = 0,
in metres. Layouts:

- checkerboard: inner corners, id `r * cols + c` at `(c * colSpacingMeters, r * rowSpacingMeters)`
  (docs/conventions.md: origin at the first inner corner, x along the columns, y along the rows;
  Kalibr's own code puts x along the rows — poses differ by that axis swap, intrinsics do not).
  The cell between the first four corners is black; printed views are `x right, y down`.
- circlegrid: circle centres, id `r * cols + c`; symmetric at `(c, r) * spacingMeters`;
  asymmetric at `((2c + r % 2), r) * spacingMeters` (Kalibr's and OpenCV's asymmetric layout,
  so circles of one row are 2 * spacingMeters apart; targetRows must be odd).
- aprilgrid: Kalibr's layout. Tag i sits at tag row `i // tagCols`, tag column `i % tagCols`;
  the corners form a (2 tagRows) x (2 tagCols) grid with id `r * 2 tagCols + c` at
  `x = (c // 2)(1 + tagSpacing) tagSize + (c % 2) tagSize` (same for y with r). Tag i's corners
  are `b, b + 1, b + 2 tagCols + 1, b + 2 tagCols` with `b = (i // tagCols) 4 tagCols + 2 (i % tagCols)`
  (Kalibr's order). As in Kalibr, the printed grid has tag 0 at the bottom left with y up.
- charuco (our fields, OpenCV's board): `squaresX`, `squaresY` (squares), `squareLength`,
  `markerLength` (metres), `dictionary` (an OpenCV name such as `DICT_5X5_100`), optional
  `legacyPattern` (boards made before OpenCV 4.6 with an even `squaresY`). Points are
  OpenCV's ChArUco corner ids, shifted so that corner 0 is the origin.

Built-in targets (`Target.named`, `PRESET_TARGETS`, the names `rscalib simulate --target` takes):
checkerboard, circlegrid, acircles, aprilgrid. This module holds a target's definition and
geometry; `Target.draw` makes a printable image, and rscalib.sim.target_texture draws it for the
renderer.
"""
from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import cv2
import numpy as np

from .. import checks
from ..errors import InputError
from .camera_formats.common import finite_number
from .safe_parse import load_yaml, one_line, read_text, shown

TARGET_TYPES = ("checkerboard", "circlegrid", "aprilgrid", "charuco")

# What a target file may say: lengths from 10 um to 100 m, grids of at most 1000 along a side and
# 10 000 points (detection, edges and the solver scale with the points; real boards have < 1000).
MIN_LENGTH_M, MAX_LENGTH_M = 1e-5, 100.0
MAX_GRID_SIDE = 1000
MAX_TARGET_POINTS = 10_000
# A target file is a few hundred bytes; a larger one is refused from its size before it is read.
TARGET_FILE_MAX_BYTES = 64 << 10

# Kalibr draws its tags with a 2-bit black border (OpenCV's default is 1 bit).
APRILGRID_BORDER_BITS = 2
APRILGRID_DICTIONARY = "DICT_APRILTAG_36h11"
APRILGRID_TAG_CELLS = 6 + 2 * APRILGRID_BORDER_BITS  # cells across a tag: 6x6 data inside the border

# Built-in targets (Target.named): their Kalibr YAML fields.
PRESET_TARGETS = {
    "checkerboard": {"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                     "rowSpacingMeters": 0.04, "colSpacingMeters": 0.04},
    "circlegrid": {"target_type": "circlegrid", "targetCols": 7, "targetRows": 5, "spacingMeters": 0.04,
                   "asymmetricGrid": False},
    "acircles": {"target_type": "circlegrid", "targetCols": 4, "targetRows": 11, "spacingMeters": 0.02,
                 "asymmetricGrid": True},  # OpenCV's asymmetric 4x11 pattern
    "aprilgrid": {"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": 0.088, "tagSpacing": 0.3},
}


@dataclass(frozen=True, eq=False)  # eq=False: compared and hashed by the definition (__eq__, __hash__)
class Target:
    """A planar calibration target: its definition and the geometry that follows from it.

    Build one with :func:`load_target` (a target YAML), :func:`target_from_dict`,
    :meth:`Target.named` (a built-in target) or :func:`as_target` (any of these). How a target looks
    when drawn is rscalib.sim.target_texture's business (and :meth:`draw`'s, for a printable image).

    target_type: one of TARGET_TYPES.
    spec: the defining fields, as in the YAML file (Kalibr names; see the module docstring).
    points_m: (P, 3) target points, metres, z = 0; the row index is the point id.
    grid_shape: (rows, cols) of the point grid for the full-board detectors (checkerboard,
                circlegrid, and the aprilgrid's corner grid); None for charuco.
    edge_pairs: (E, 2) ids of neighbouring points joined by a black/white edge (checkerboard,
                charuco, aprilgrid tag sides) or of neighbouring circles — used to measure blur.
    """

    target_type: str
    spec: dict
    points_m: np.ndarray = field(repr=False)
    grid_shape: Optional[tuple[int, int]]
    edge_pairs: np.ndarray = field(repr=False)

    @classmethod
    def named(cls, name: str) -> Target:
        """A built-in target (:data:`PRESET_TARGETS`): checkerboard (9x6, 40 mm), circlegrid (7x5,
        40 mm), acircles (OpenCV's asymmetric 4x11, 20 mm), aprilgrid (Kalibr's 6x6 tags of 88 mm,
        spacing 0.3)."""
        if name not in PRESET_TARGETS:
            raise InputError(f"unknown target {name!r}: use {', '.join(PRESET_TARGETS)} or a Kalibr target YAML file")
        return target_from_dict(PRESET_TARGETS[name])

    def _key(self) -> tuple:
        return (self.target_type, json.dumps(self.spec, sort_keys=True))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Target) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def num_points(self) -> int:
        return len(self.points_m)

    def center_m(self) -> np.ndarray:
        """(3,) centre of the points' bounding box."""
        return 0.5 * (self.points_m.min(axis=0) + self.points_m.max(axis=0))

    def kalibr_dict(self) -> dict:
        """The target YAML's fields (Kalibr's names; ours for charuco)."""
        return {"target_type": self.target_type, **self.spec}

    def fingerprint(self) -> str:
        """Stable hash of the definition (for detection caches)."""
        text = json.dumps({"target_type": self.target_type, **self.spec}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def describe(self) -> str:
        s = self.spec
        if self.target_type == "checkerboard":
            return (f"checkerboard {s['targetCols']}x{s['targetRows']} inner corners, "
                    f"{s['colSpacingMeters'] * 1e3:g} x {s['rowSpacingMeters'] * 1e3:g} mm squares")
        if self.target_type == "circlegrid":
            kind = "asymmetric" if s["asymmetricGrid"] else "symmetric"
            return f"{kind} circle grid {s['targetCols']}x{s['targetRows']}, spacing {s['spacingMeters'] * 1e3:g} mm"
        if self.target_type == "aprilgrid":
            return (f"aprilgrid {s['tagCols']}x{s['tagRows']} tags, tag {s['tagSize'] * 1e3:g} mm, "
                    f"spacing ratio {s['tagSpacing']:g}")
        return (f"charuco {s['squaresX']}x{s['squaresY']} squares, {s['squareLength'] * 1e3:g} mm, "
                f"markers {s['markerLength'] * 1e3:g} mm {s['dictionary']}")

    def tag_corner_ids(self) -> np.ndarray:
        """aprilgrid only: (tags, 4) point ids of each tag's corners in Kalibr's order."""
        if self.target_type != "aprilgrid":
            raise InputError("tag_corner_ids: not an aprilgrid")
        tag_cols, tag_rows = self.spec["tagCols"], self.spec["tagRows"]
        cols = 2 * tag_cols
        tag = np.arange(tag_cols * tag_rows)
        base = (tag // tag_cols) * 2 * cols + 2 * (tag % tag_cols)
        return np.column_stack([base, base + 1, base + cols + 1, base + cols])

    def aruco_corner_ids(self) -> np.ndarray:
        """aprilgrid only: (tags, 4) point ids of cv2.aruco's marker corners (top-left, top-right,
        bottom-right, bottom-left of the marker bitmap) as Kalibr prints the tags (the bitmap turned
        by 180°, see :func:`aprilgrid_tag_cells`): Kalibr's corners 1, 0, 3, 2."""
        return self.tag_corner_ids()[:, [1, 0, 3, 2]]

    def charuco_board(self):
        """charuco only: the cv2.aruco.CharucoBoard (square and marker lengths in metres)."""
        if self.target_type != "charuco":
            raise InputError("charuco_board: not a charuco target")
        return _charuco_board(self.spec)

    def draw(self, pixels_per_metre: float, margin_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """A printable image of the target (uint8, white paper) and the 3x3 homography from
        target coordinates (x, y in metres) to its pixels. Used for synthetic tests and
        benchmarks; circles get a radius of 0.3 spacing (the YAML does not say)."""
        return _draw(self, float(pixels_per_metre), float(margin_m))


def as_target(spec: Any) -> Target:
    """A Target from a Target, a built-in name (:meth:`Target.named`) or a target YAML path."""
    if isinstance(spec, Target):
        return spec
    text = str(spec)
    if isinstance(spec, Path) or text.endswith((".yaml", ".yml")) or os.sep in text:
        return load_target(text)
    return Target.named(text)


def aprilgrid_tag_cells(count: int) -> np.ndarray:
    """(count, 10, 10) bool: the white cells of AprilGrid tags 0..count-1 as printed, indexed
    ``[tag, j, i]`` with cell j along target +y and cell i along +x from the tag's corner 0.

    The cv2.aruco 36h11 marker bitmap with Kalibr's 2-cell black border, turned by 180° as
    kalibr_create_target_pdf prints its tags (its top row towards target +y). (Checked against a
    real EuRoC AprilGrid frame: same border, same corner order.)
    """
    cells = _TAG_CELLS_CACHE.get(count)
    if cells is None:
        dictionary = _aruco_dictionary(APRILGRID_DICTIONARY)
        # Turned by 180° and printed with +y up, the bitmap's row 0 lies along the tag's low-y side,
        # mirrored in x: target cell (j, i) is bitmap pixel (j, n - 1 - i).
        cells = np.stack([cv2.aruco.generateImageMarker(dictionary, k, APRILGRID_TAG_CELLS,
                                                        borderBits=APRILGRID_BORDER_BITS)[:, ::-1] > 127
                          for k in range(count)])
        cells.setflags(write=False)
        _TAG_CELLS_CACHE[count] = cells
    return cells


_TAG_CELLS_CACHE: dict = {}


class TargetFileWarning(UserWarning):
    """A target file has keys rscalib does not use (a typo, or a field of another tool)."""


# The keys each target type reads (besides target_type); others in a file are reported, not used.
# Kalibr's aprilgrid may carry codeOffset: 0 (the default) changes nothing.
KNOWN_KEYS = {
    "checkerboard": {"targetCols", "targetRows", "rowSpacingMeters", "colSpacingMeters"},
    "circlegrid": {"targetCols", "targetRows", "spacingMeters", "asymmetricGrid"},
    "aprilgrid": {"tagCols", "tagRows", "tagSize", "tagSpacing"},
    "charuco": {"squaresX", "squaresY", "squareLength", "markerLength", "dictionary", "legacyPattern"},
}


def unknown_keys(data: dict, target_type: str) -> list[str]:
    """Keys of a target file's mapping that its target type does not read."""
    known = KNOWN_KEYS.get(target_type, set()) | {"target_type"}
    extra = [str(k) for k in data if k not in known]
    if target_type == "aprilgrid" and data.get("codeOffset", 0) == 0 and "codeOffset" in extra:
        extra.remove("codeOffset")
    return extra


def load_target(path) -> Target:
    """Read a Kalibr-style target YAML; InputError with a one-line reason if it is unusable, a
    TargetFileWarning when it has keys that are not used (a typo would otherwise go unnoticed)."""
    path = checks.path(path, "path (the target file)")
    if path.is_dir():
        raise InputError(f"{shown(path)} is a folder, not a target file")
    if not path.is_file():
        raise InputError(f"target file not found: {shown(path)}")
    # safe_parse: the size before reading, no aliases, a nesting and an integer-length limit
    data = load_yaml(read_text(path, TARGET_FILE_MAX_BYTES, "target file", encoding="utf-8-sig"), path)
    try:
        target = target_from_dict(data)
    except InputError as error:
        raise InputError(one_line(f"{path}: {error}")) from None
    extra = unknown_keys(data, target.target_type)
    if extra:
        warnings.warn(one_line(f"{path}: {', '.join(extra)} not used (a {target.target_type} reads "
                               f"{', '.join(sorted(KNOWN_KEYS[target.target_type]))})"), TargetFileWarning,
                      stacklevel=2)
    return target


def target_from_dict(data: Any) -> Target:
    """Target from the fields of a target YAML (a dict)."""
    if not isinstance(data, dict):
        raise InputError("a target file must be a YAML mapping with a target_type")
    kind = data.get("target_type")
    if kind is None:
        raise InputError(f"missing field 'target_type' (one of {', '.join(TARGET_TYPES)})")
    kind = str(kind).strip().lower()
    if kind == "checkerboard":
        cols, rows = _grid_size(data, "targetCols", "targetRows", 2)
        spec = {"targetCols": cols, "targetRows": rows,
                "rowSpacingMeters": _length(data, "rowSpacingMeters"),
                "colSpacingMeters": _length(data, "colSpacingMeters")}
        r, c = np.divmod(np.arange(rows * cols), cols)
        points = np.column_stack([c * spec["colSpacingMeters"], r * spec["rowSpacingMeters"], np.zeros(r.size)])
        return Target(kind, spec, points, (rows, cols), _grid_edges(rows, cols))
    if kind == "circlegrid":
        cols, rows = _grid_size(data, "targetCols", "targetRows", 2)
        asymmetric = data.get("asymmetricGrid", False)
        if not isinstance(asymmetric, bool):
            raise InputError(f"field 'asymmetricGrid' must be true or false, not {asymmetric!r}")
        if asymmetric and rows % 2 == 0:
            # OpenCV's detector numbers even-row asymmetric grids inconsistently (rows swapped in
            # pairs), and such a grid looks the same turned by 180 degrees.
            raise InputError(f"an asymmetric circle grid needs an odd targetRows (like OpenCV's 4x11), not {rows}")
        spec = {"targetCols": cols, "targetRows": rows, "spacingMeters": _length(data, "spacingMeters"),
                "asymmetricGrid": asymmetric}
        r, c = np.divmod(np.arange(rows * cols), cols)
        x = (2 * c + r % 2) if asymmetric else c
        points = np.column_stack([x, r, np.zeros(r.size)]) * spec["spacingMeters"]
        return Target(kind, spec, points, (rows, cols), _nearest_pairs(points))
    if kind == "aprilgrid":
        tag_cols, tag_rows = _grid_size(data, "tagCols", "tagRows", 1, points_per_cell=4)
        spec = {"tagCols": tag_cols, "tagRows": tag_rows, "tagSize": _length(data, "tagSize"),
                "tagSpacing": _number(data, "tagSpacing")}
        if not 0 < spec["tagSpacing"] < 10:
            raise InputError(f"field 'tagSpacing' is the gap/tagSize ratio (e.g. 0.3), not {spec['tagSpacing']}")
        if tag_cols * tag_rows > 587:  # tag36h11 has 587 codes
            raise InputError("an aprilgrid (tag36h11) has at most 587 tags")
        rows, cols = 2 * tag_rows, 2 * tag_cols
        r, c = np.divmod(np.arange(rows * cols), cols)
        size, pitch = spec["tagSize"], (1 + spec["tagSpacing"]) * spec["tagSize"]
        points = np.column_stack([(c // 2) * pitch + (c % 2) * size, (r // 2) * pitch + (r % 2) * size,
                                  np.zeros(r.size)])
        target = Target(kind, spec, points, (rows, cols), np.zeros((0, 2), dtype=np.int64))
        corners = target.tag_corner_ids()
        sides = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 3]], corners[:, [3, 0]]])
        return Target(kind, spec, points, (rows, cols), sides)
    if kind == "charuco":
        squares_x, squares_y = _grid_size(data, "squaresX", "squaresY", 2)
        dictionary, legacy = data.get("dictionary", "DICT_5X5_100"), data.get("legacyPattern", False)
        if not isinstance(dictionary, str):
            raise InputError(f"field 'dictionary' must be an OpenCV name such as DICT_5X5_100, not {dictionary!r}")
        if not isinstance(legacy, bool):
            raise InputError(f"field 'legacyPattern' must be true or false, not {legacy!r}")
        spec = {"squaresX": squares_x, "squaresY": squares_y,
                "squareLength": _length(data, "squareLength"), "markerLength": _length(data, "markerLength"),
                "dictionary": dictionary.strip(), "legacyPattern": legacy}
        if spec["markerLength"] >= spec["squareLength"]:
            raise InputError("field 'markerLength' must be smaller than 'squareLength'")
        board = _charuco_board(spec)
        corners = np.asarray(board.getChessboardCorners(), dtype=np.float64).reshape(-1, 3)
        points = corners - corners[0]
        points[:, 2] = 0.0
        rows, cols = spec["squaresY"] - 1, spec["squaresX"] - 1
        return Target(kind, spec, points, None, _grid_edges(rows, cols))
    raise InputError(f"unknown target_type {data.get('target_type')!r} (one of {', '.join(TARGET_TYPES)})")


def _field(data: dict, name: str) -> Any:
    if name not in data or data[name] is None:
        raise InputError(f"missing field '{name}' for target_type {data.get('target_type')}")
    return data[name]


def _number(data: dict, name: str) -> float:
    return finite_number(_field(data, name), f"field '{name}'")


def _length(data: dict, name: str) -> float:
    value = _number(data, name)
    if value <= 0:
        raise InputError(f"field '{name}' must be positive (metres), not {value}")
    if not MIN_LENGTH_M <= value <= MAX_LENGTH_M:
        raise InputError(f"field '{name}' must be between {MIN_LENGTH_M:g} and {MAX_LENGTH_M:g} m, not {value:g}")
    return value


def _count(data: dict, name: str, minimum: int) -> int:
    value = _field(data, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or (isinstance(value, float) and (not np.isfinite(value) or value != int(value))):
        raise InputError(f"field '{name}' must be a whole number, not {value!r}")
    if int(value) < minimum:
        raise InputError(f"field '{name}' must be at least {minimum}, not {int(value)}")
    if int(value) > MAX_GRID_SIDE:
        raise InputError(f"field '{name}' must be at most {MAX_GRID_SIDE}, not {str(value)[:40]}")
    return int(value)


def _grid_size(data: dict, cols_name: str, rows_name: str, minimum: int, points_per_cell: int = 1
               ) -> tuple[int, int]:
    """(cols, rows) of a grid, each in range and with at most MAX_TARGET_POINTS points in all."""
    cols, rows = _count(data, cols_name, minimum), _count(data, rows_name, minimum)
    if cols * rows * points_per_cell > MAX_TARGET_POINTS:
        raise InputError(f"fields '{cols_name}' x '{rows_name}' ({cols} x {rows}) give "
                         f"{cols * rows * points_per_cell} points; at most {MAX_TARGET_POINTS}")
    return cols, rows


def _grid_edges(rows: int, cols: int) -> np.ndarray:
    """Pairs of row-major grid neighbours (horizontal then vertical)."""
    ids = np.arange(rows * cols).reshape(rows, cols)
    horizontal = np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()])
    vertical = np.column_stack([ids[:-1, :].ravel(), ids[1:, :].ravel()])
    return np.concatenate([horizontal, vertical]).astype(np.int64)


def _nearest_pairs(points: np.ndarray) -> np.ndarray:
    """Each point with every point at its nearest-neighbour distance (circle grids); a k-d tree,
    so memory grows with the points, not their square."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points[:, :2])
    nearest = tree.query(points[:, :2], k=2)[0][:, 1].min()
    pairs = sorted(tree.query_pairs(nearest * (1 + 1e-6) + 1e-8))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def _aruco_dictionary(name: str):
    value = getattr(cv2.aruco, name, None)
    if not name.startswith("DICT_") or not isinstance(value, int):
        raise InputError(f"unknown ArUco dictionary {name!r} (an OpenCV name such as DICT_5X5_100)")
    return cv2.aruco.getPredefinedDictionary(value)


def _charuco_board(spec: dict):
    dictionary = _aruco_dictionary(spec["dictionary"])
    needed = (spec["squaresX"] * spec["squaresY"]) // 2
    if needed > dictionary.bytesList.shape[0]:
        raise InputError(f"{spec['dictionary']} has {dictionary.bytesList.shape[0]} markers; "
                         f"a {spec['squaresX']}x{spec['squaresY']} ChArUco board needs {needed}")
    board = cv2.aruco.CharucoBoard((spec["squaresX"], spec["squaresY"]), spec["squareLength"],
                                   spec["markerLength"], dictionary)
    board.setLegacyPattern(spec["legacyPattern"])
    return board


def _draw(target: Target, ppm: float, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    if target.target_type == "charuco":
        return _draw_charuco(target, ppm, margin_m)
    if target.target_type == "circlegrid":
        return _draw_circlegrid(target, ppm, margin_m)
    # Checkerboards and aprilgrids are grids of axis-aligned cells: render each pixel as the
    # exact area average of the cells it overlaps (no drawing bias at the corners).
    cells = _checkerboard_cells(target, margin_m) if target.target_type == "checkerboard" \
        else _aprilgrid_cells(target, margin_m)
    return _rasterise_cells(*cells, ppm)


def _draw_charuco(target: Target, ppm: float, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    # OpenCV draws the board (on its own pixel grid, so whole-pixel squares); corner 0 is one
    # square in from the board's outer corner.
    s = target.spec
    sx, sy, square = s["squaresX"], s["squaresY"], s["squareLength"]
    square_px = max(4, int(round(square * ppm)))
    margin = int(round(margin_m * ppm))
    image = target.charuco_board().generateImage((sx * square_px + 2 * margin, sy * square_px + 2 * margin),
                                                 marginSize=margin)
    scale = square_px / square
    h = np.array([[scale, 0, margin + square_px - 0.5], [0, scale, margin + square_px - 0.5], [0, 0, 1.0]])
    return image, h


def _draw_circlegrid(target: Target, ppm: float, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    s = target.spec
    pts = target.points_m[:, :2]
    pad = s["spacingMeters"] + margin_m
    lo, hi = pts.min(0) - pad, pts.max(0) + pad
    width, height = np.ceil((hi - lo) * ppm).astype(int)
    # pixel (i, j) is centred on (i, j) (docs/conventions.md)
    h = np.array([[ppm, 0, -lo[0] * ppm - 0.5], [0, ppm, -lo[1] * ppm - 0.5], [0, 0, 1.0]])
    image = np.full((height, width), 255, np.uint8)
    shift = 4  # fixed-point bits: sub-pixel centres
    radius = int(round(0.3 * s["spacingMeters"] * ppm * (1 << shift)))
    for x, y in pts @ h[:2, :2].T + h[:2, 2]:
        cv2.circle(image, (int(round(x * (1 << shift))), int(round(y * (1 << shift)))), radius, 0,
                   thickness=-1, lineType=cv2.LINE_AA, shift=shift)
    return image, h


def _checkerboard_cells(target: Target, margin_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The cell edges along x and y (metres), the cells' grey values and whether y points up."""
    s = target.spec
    cols, rows = s["targetCols"], s["targetRows"]
    # squares from one spacing before the first corner to one after the last, plus margins
    x_edges = (np.arange(cols + 2) - 1.0) * s["colSpacingMeters"]
    y_edges = (np.arange(rows + 2) - 1.0) * s["rowSpacingMeters"]
    x_edges = np.r_[x_edges[0] - margin_m, x_edges, x_edges[-1] + margin_m]
    y_edges = np.r_[y_edges[0] - margin_m, y_edges, y_edges[-1] + margin_m]
    i, j = np.meshgrid(np.arange(cols + 1), np.arange(rows + 1))
    cells = np.where((i + j) % 2 == 0, 0.0, 255.0)  # cell (1, 1), inside the first four corners, is black
    return x_edges, y_edges, np.pad(cells, 1, constant_values=255.0), False


def _aprilgrid_cells(target: Target, margin_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """As _checkerboard_cells, for Kalibr's aprilgrid (its y points up)."""
    s = target.spec
    tag_cols, tag_rows = s["tagCols"], s["tagRows"]
    size, gap = s["tagSize"], s["tagSpacing"] * s["tagSize"]
    bits = APRILGRID_TAG_CELLS

    def edges(count: int) -> np.ndarray:
        # cells along an axis: margin, gap, tag 0's bits, gap, tag 1's bits, ..., gap, margin
        starts = np.arange(count) * (size + gap)
        inner = (starts[:, None] + np.arange(bits + 1)[None, :] * size / bits).ravel()
        end = inner[-1]
        return np.r_[-gap - margin_m, -gap, inner, end + gap, end + gap + margin_m]

    def tag_of_cell(count: int) -> np.ndarray:
        """Tag index of each cell along an axis (-1: margin or gap)."""
        tag = np.full(count * (bits + 1) + 3, -1)
        for t in range(count):
            tag[2 + t * (bits + 1): 2 + t * (bits + 1) + bits] = t
        return tag

    tag_x, tag_y = tag_of_cell(tag_cols), tag_of_cell(tag_rows)
    is_gap_x, is_gap_y = tag_x < 0, tag_y < 0
    is_gap_x[[0, -1]] = is_gap_y[[0, -1]] = False  # margins
    values = np.full((len(tag_y), len(tag_x)), 255.0)
    values[np.ix_(is_gap_y, is_gap_x)] = 0.0  # Kalibr's small squares at the tag corners
    cells = aprilgrid_tag_cells(tag_rows * tag_cols)  # [tag, j along +y, i along +x]
    for tr in range(tag_rows):
        for tc in range(tag_cols):
            values[np.ix_(tag_y == tr, tag_x == tc)] = np.where(cells[tr * tag_cols + tc], 255.0, 0.0)
    return edges(tag_cols), edges(tag_rows), values, True


def _rasterise_cells(x_edges: np.ndarray, y_edges: np.ndarray, values: np.ndarray, flip_y: bool,
                     ppm: float) -> tuple[np.ndarray, np.ndarray]:
    """The image of a grid of cells (each pixel the area average of the cells it overlaps) and its
    board-to-pixel homography."""
    lo = np.array([x_edges[0], y_edges[0]])
    hi = np.array([x_edges[-1], y_edges[-1]])
    width, height = np.ceil((hi - lo) * ppm).astype(int)
    cover_x = _coverage((x_edges - lo[0]) * ppm, width)
    if flip_y:
        # Kalibr prints y up: raster row = (hi_y - y) * ppm
        cover_y = _coverage((hi[1] - y_edges[::-1]) * ppm, height)
        values = values[::-1]
        h = np.array([[ppm, 0, -lo[0] * ppm - 0.5], [0, -ppm, hi[1] * ppm - 0.5], [0, 0, 1.0]])
    else:
        cover_y = _coverage((y_edges - lo[1]) * ppm, height)
        h = np.array([[ppm, 0, -lo[0] * ppm - 0.5], [0, ppm, -lo[1] * ppm - 0.5], [0, 0, 1.0]])
    image = cover_y @ values @ cover_x.T
    # pixels past the last edge (ceil) are paper
    image += 255.0 * (1.0 - np.outer(cover_y.sum(1), cover_x.sum(1)))
    return np.clip(np.round(image), 0, 255).astype(np.uint8), h


def _coverage(edges_px: np.ndarray, pixels: int) -> np.ndarray:
    """(pixels, cells) overlap of pixel i = [i, i + 1] (edge coordinates) with cell k =
    [edges[k], edges[k + 1]]."""
    lo = np.arange(pixels)[:, None]
    overlap = np.minimum(lo + 1, edges_px[None, 1:]) - np.maximum(lo, edges_px[None, :-1])
    return np.clip(overlap, 0.0, 1.0)
