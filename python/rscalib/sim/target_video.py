"""Rolling-shutter video renderer: image rows drawn at their own exposure times.

Every output pixel ``(u, v)`` of the frame stamped ``t_i`` is rendered by inverse mapping at the
row time ``t = t_i + v * d`` (docs/conventions.md): the pixel is unprojected through the camera
(lens distortion included) to a ray, the ray is intersected with the target plane z = 0 using the
pose ``T_cw(t)`` (world point ``X = Rᵀ(λ ray − p)``), and a procedural target texture is sampled
there. Anti-aliasing: each pixel is the mean of ``supersample²`` sub-pixel samples, each with the row
time of its own sub-row, and each sample box-filters the texture over its own footprint on the
target (exact for the axis-aligned edges of checkerboards and AprilGrids, a radial ramp for
circles), so edges land where the geometry puts them rather than on a sub-pixel lattice. Motion
blur: the mean over ``exposure_samples`` times spread over ``[t, t + exposure_s]`` (a row's
exposure *starts* at its row time). Noise: Gaussian on the 8-bit intensities.

The corners of a rendered frame therefore sit at the exact rolling-shutter projection
``v = v_proj(T_cw(t_i + v d) P)`` of the target points, which is what ``truth.json`` records
(computed with :func:`rscalib.sim.target_observations.rs_projection`, independent of this renderer).

Target frames (world = target): checkerboard and circle grids as in docs/conventions.md (x along
the columns, y along the rows, camera on the z < 0 side). The AprilGrid uses Kalibr's frame (origin
at the bottom-left corner of tag 0, y up the printed page), which is seen from the z > 0 side; the
default trajectory is turned by 180° about x for it so the camera still faces the printed side.
"""
from __future__ import annotations

import json
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence, Union

import cv2
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from .._core import CameraModel, unwrap_rotation_vectors
from .._progress import Progress
from ..errors import InputError
from ..io.cameras import opencv_matrices
from .target_observations import HandheldTrajectory, rs_projection, standoff_distance_m

__all__ = [
    "RenderTarget",
    "RenderedVideo",
    "RollingShutterRenderer",
    "default_camera",
    "default_trajectory",
    "load_truth",
    "render_video",
    "to_uint8",
    "trajectory_from_truth",
]

# Reflectances of the printed target and of what lies around it (fractions of full scale): not 0
# and 1, so that the noise is not clipped.
BLACK = 0.08
WHITE = 0.90
BACKGROUND = 0.45

# Frame i of the video is stamped i / fps (row 0 starts exposure then).
VIDEO_NAME = "video.avi"
# Kalibr's AprilGrid tags: 6x6 data cells inside a 2-cell black border (OpenCV's default is 1).
TAG_BORDER_BITS = 2
TAG_CELLS = 6 + 2 * TAG_BORDER_BITS
MAX_EXPOSURE_SAMPLES = 64


# --------------------------------------------------------------------------------------------------
# Targets


def _ramp(x: np.ndarray) -> np.ndarray:
    """Box-filtered step: the fraction of a unit-width footprint centred at -x ... past the edge."""
    return np.clip(x + 0.5, 0.0, 1.0)


@dataclass(frozen=True)
class RenderTarget:
    """A printed planar target: geometry (Kalibr's fields) plus what the renderer needs to draw it.

    kind:          "checkerboard", "circlegrid" or "aprilgrid".
    cols, rows:    inner corners (checkerboard), circles (circlegrid; for an asymmetric grid the
                   circles per row), tags (aprilgrid).
    spacing_m:     checkerboard column spacing (square width, along x); circle spacing (Kalibr's
                   spacingMeters); AprilGrid tag size (edge to edge of the black border).
    row_spacing_m: checkerboard row spacing (square height, along y); default = spacing_m.
    asymmetric:    circlegrid only: OpenCV/Kalibr asymmetric layout, point (r, c) at
                   ((2c + r % 2) s, r s).
    tag_spacing:   aprilgrid only: gap between tags as a fraction of the tag size (Kalibr).
    circle_radius_m: circlegrid only; default a quarter of the nearest-neighbour distance.
    margin_m:      white paper around the pattern; default one square / spacing / half a tag.

    Point ids: checkerboard and circles ``r * cols + c``; AprilGrid Kalibr's 2·rows × 2·cols corner
    grid, id ``r * 2 cols + c`` at ``(c//2 · P + c%2 · size, r//2 · P + r%2 · size)`` with pitch
    ``P = size (1 + tag_spacing)``.
    """

    kind: str = "checkerboard"
    cols: int = 9
    rows: int = 6
    spacing_m: float = 0.04
    row_spacing_m: Optional[float] = None
    asymmetric: bool = False
    tag_spacing: float = 0.3
    circle_radius_m: Optional[float] = None
    margin_m: Optional[float] = None

    def __post_init__(self) -> None:
        if self.kind not in ("checkerboard", "circlegrid", "aprilgrid"):
            raise InputError(f"unknown target type {self.kind!r} (checkerboard, circlegrid, aprilgrid)")
        if int(self.cols) < 1 or int(self.rows) < 1:
            raise InputError("target columns and rows must be >= 1")
        if self.kind == "checkerboard" and (self.cols < 2 or self.rows < 2):
            raise InputError("a checkerboard needs at least 2x2 inner corners")
        if not (self.spacing_m > 0 and (self.row_spacing_m is None or self.row_spacing_m > 0)):
            raise InputError("target spacing must be positive")
        if self.kind == "aprilgrid":
            if not 0 < self.tag_spacing <= 1:
                raise InputError("aprilgrid tagSpacing must be in (0, 1]")
            if self.cols * self.rows > 587:
                raise InputError("an AprilGrid (36h11) has at most 587 tags")
        if self.kind == "circlegrid":
            nn = self.spacing_m * (math.sqrt(2.0) if self.asymmetric else 1.0)
            if self.circle_radius_m is not None and not 0 < self.circle_radius_m < 0.5 * nn:
                raise InputError("circle radius must be positive and less than half the circle distance")

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def named(cls, name: str) -> RenderTarget:
        """Built-in targets: checkerboard (9x6, 40 mm), circlegrid (7x5, 40 mm), acircles (OpenCV's
        asymmetric 4x11, 20 mm) and aprilgrid (Kalibr's 6x6 tags of 88 mm, spacing 0.3)."""
        presets = {
            "checkerboard": cls("checkerboard", 9, 6, 0.04),
            "circlegrid": cls("circlegrid", 7, 5, 0.04),
            "acircles": cls("circlegrid", 4, 11, 0.02, asymmetric=True),
            "aprilgrid": cls("aprilgrid", 6, 6, 0.088, tag_spacing=0.3),
        }
        if name not in presets:
            raise InputError(f"unknown target {name!r}: use {', '.join(presets)} or a Kalibr target YAML file")
        return presets[name]

    @classmethod
    def from_kalibr(cls, data: dict, source: str = "target") -> RenderTarget:
        """From Kalibr's target YAML fields (a dict as loaded from the file)."""
        if not isinstance(data, dict) or "target_type" not in data:
            raise InputError(f"{source}: a Kalibr target needs 'target_type'")
        kind = str(data["target_type"]).strip()
        try:
            if kind == "checkerboard":
                return cls(kind, int(data["targetCols"]), int(data["targetRows"]),
                           float(data["colSpacingMeters"]), float(data["rowSpacingMeters"]))
            if kind == "circlegrid":
                return cls(kind, int(data["targetCols"]), int(data["targetRows"]), float(data["spacingMeters"]),
                           asymmetric=bool(data.get("asymmetricGrid", False)))
            if kind == "aprilgrid":
                return cls(kind, int(data["tagCols"]), int(data["tagRows"]), float(data["tagSize"]),
                           tag_spacing=float(data["tagSpacing"]))
        except (KeyError, TypeError, ValueError) as error:
            raise InputError(f"{source}: incomplete {kind} target ({error})") from None
        raise InputError(f"{source}: target_type {kind!r} cannot be rendered (checkerboard, circlegrid, aprilgrid)")

    @classmethod
    def from_file(cls, path) -> RenderTarget:
        path = Path(path)
        if not path.is_file():
            raise InputError(f"target file not found: {path}")
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as error:
            raise InputError(f"{path}: not valid YAML ({str(error).splitlines()[0]})") from None
        return cls.from_kalibr(data, str(path))

    @classmethod
    def parse(cls, spec: Union[str, RenderTarget, Path, Any]) -> RenderTarget:
        """A RenderTarget, a built-in name, a Kalibr target YAML path, or a rscalib.io.targets.Target."""
        if isinstance(spec, RenderTarget):
            return spec
        if hasattr(spec, "target_type") and isinstance(getattr(spec, "spec", None), dict):
            return cls.from_kalibr({"target_type": spec.target_type, **spec.spec})
        spec_str = str(spec)
        if isinstance(spec, Path) or spec_str.endswith((".yaml", ".yml")) or os.sep in spec_str:
            return cls.from_file(spec_str)
        return cls.named(spec_str)

    # -- geometry -------------------------------------------------------------------------------
    @property
    def row_pitch_m(self) -> float:
        return float(self.row_spacing_m if self.row_spacing_m is not None else self.spacing_m)

    @property
    def tag_pitch_m(self) -> float:
        return self.spacing_m * (1.0 + self.tag_spacing)

    @property
    def radius_m(self) -> float:
        if self.circle_radius_m is not None:
            return float(self.circle_radius_m)
        return 0.25 * self.spacing_m * (math.sqrt(2.0) if self.asymmetric else 1.0)

    def points(self) -> np.ndarray:
        """(P, 3) target points on z = 0 (ids as in the class docstring)."""
        if self.kind == "aprilgrid":
            r, c = np.divmod(np.arange(4 * self.rows * self.cols), 2 * self.cols)
            x = (c // 2) * self.tag_pitch_m + (c % 2) * self.spacing_m
            y = (r // 2) * self.tag_pitch_m + (r % 2) * self.spacing_m
        else:
            r, c = np.divmod(np.arange(self.rows * self.cols), self.cols)
            if self.kind == "circlegrid" and self.asymmetric:
                x, y = (2 * c + r % 2) * self.spacing_m, r * self.spacing_m
            elif self.kind == "circlegrid":
                x, y = c * self.spacing_m, r * self.spacing_m
            else:
                x, y = c * self.spacing_m, r * self.row_pitch_m
        return np.column_stack([x, y, np.zeros(len(x))]).astype(np.float64)

    def pattern_bounds_m(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) of the printed pattern (squares, circles, tags and corner squares)."""
        if self.kind == "checkerboard":
            return (-self.spacing_m, self.cols * self.spacing_m, -self.row_pitch_m, self.rows * self.row_pitch_m)
        if self.kind == "circlegrid":
            pts, rad = self.points(), self.radius_m
            return (pts[:, 0].min() - rad, pts[:, 0].max() + rad, pts[:, 1].min() - rad, pts[:, 1].max() + rad)
        gap = self.tag_spacing * self.spacing_m
        return (-gap, self.cols * self.tag_pitch_m, -gap, self.rows * self.tag_pitch_m)

    def sheet_bounds_m(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) of the white sheet the pattern is printed on."""
        if self.margin_m is not None:
            m = float(self.margin_m)
        else:
            m = {"checkerboard": self.spacing_m, "circlegrid": self.spacing_m,
                 "aprilgrid": 0.5 * self.spacing_m}[self.kind]
        x0, x1, y0, y1 = self.pattern_bounds_m()
        return (x0 - m, x1 + m, y0 - m, y1 + m)

    def center_m(self) -> np.ndarray:
        pts = self.points()
        return 0.5 * (pts.min(axis=0) + pts.max(axis=0))

    def kalibr_dict(self) -> dict:
        """Kalibr's target YAML fields."""
        if self.kind == "checkerboard":
            return {"target_type": "checkerboard", "targetCols": int(self.cols), "targetRows": int(self.rows),
                    "rowSpacingMeters": float(self.row_pitch_m), "colSpacingMeters": float(self.spacing_m)}
        if self.kind == "circlegrid":
            return {"target_type": "circlegrid", "targetCols": int(self.cols), "targetRows": int(self.rows),
                    "spacingMeters": float(self.spacing_m), "asymmetricGrid": bool(self.asymmetric)}
        return {"target_type": "aprilgrid", "tagCols": int(self.cols), "tagRows": int(self.rows),
                "tagSize": float(self.spacing_m), "tagSpacing": float(self.tag_spacing)}

    def to_dict(self) -> dict:
        """Kalibr fields plus the drawing details (for truth.json)."""
        d = self.kalibr_dict()
        d.update({"sheet_bounds_m": list(self.sheet_bounds_m()), "reflectance_black": BLACK,
                  "reflectance_white": WHITE, "reflectance_background": BACKGROUND})
        if self.kind == "circlegrid":
            d["circle_radius_m"] = self.radius_m
        if self.kind == "aprilgrid":
            d["tag_family"] = "36h11 (cv2.aruco.DICT_APRILTAG_36h11), 2-cell black border (markerBorderBits=2)"
            d["tag_drawing"] = ("cv2.aruco marker image rotated by 180 degrees, its top towards target +y "
                                "(as Kalibr's kalibr_create_target_pdf draws tags, rotation=2)")
            d["aruco_corner_point_ids"] = _aruco_corner_point_ids(self).tolist()
        return d

    # -- texture --------------------------------------------------------------------------------
    def albedo(self, x: np.ndarray, y: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
        """Reflectance at target points (x, y), box-filtered over a footprint of wx × wy metres.

        Points off the sheet see the background; NaN coordinates count as off the sheet.
        """
        if self.kind == "circlegrid":
            return self._circles(x, y, wx, wy)
        return self._texture().filtered(x, y, wx, wy)

    def _sheet_cover(self, x, y, wx, wy) -> np.ndarray:
        """Box-filtered indicator of the white sheet."""
        x0, x1, y0, y1 = self.sheet_bounds_m()
        return (_ramp((x - x0) / wx) * _ramp((x1 - x) / wx)) * (_ramp((y - y0) / wy) * _ramp((y1 - y) / wy))

    def _circles(self, x, y, wx, wy) -> np.ndarray:
        s, rad = self.spacing_m, self.radius_m
        width = 0.5 * (wx + wy)
        cover = np.zeros(np.shape(x), dtype=np.result_type(x))
        # Nearest circle: in a symmetric grid the rounded lattice cell; in an asymmetric grid it can
        # sit in either neighbouring row, so take the larger coverage of the two (discs do not overlap).
        if self.asymmetric:
            base = np.floor(y / s)
            candidates = (base, base + 1)
        else:
            candidates = (np.round(y / s),)
        for r in candidates:
            r = np.clip(np.nan_to_num(r, nan=-1e6), 0, self.rows - 1)
            shift = (r % 2) if self.asymmetric else 0.0
            step = 2.0 if self.asymmetric else 1.0
            c = np.clip(np.round((x / s - shift) / step), 0, self.cols - 1)
            cx, cy = (step * c + shift) * s, r * s
            dist = np.hypot(x - cx, y - cy)
            cover = np.maximum(cover, _ramp((rad - dist) / width))
        paper = WHITE - (WHITE - BLACK) * cover
        sheet = np.nan_to_num(self._sheet_cover(x, y, wx, wy))
        return sheet * paper + (1.0 - sheet) * BACKGROUND

    def _texture(self) -> _RectilinearTexture:
        """The pattern as a table of constant cells between its x and y edges (built once)."""
        texture = _TEXTURE_CACHE.get(self)
        if texture is not None:
            return texture
        sx0, sx1, sy0, sy1 = self.sheet_bounds_m()
        if self.kind == "checkerboard":
            xs = np.arange(-1, self.cols + 1) * self.spacing_m
            ys = np.arange(-1, self.rows + 1) * self.row_pitch_m
        else:
            pitch, size = self.tag_pitch_m, self.spacing_m
            cells = np.arange(TAG_CELLS + 1) * size / TAG_CELLS
            gap = self.tag_spacing * size

            def axis(n: int) -> np.ndarray:
                tags = (np.arange(n)[:, None] * pitch + cells[None]).ravel()
                return np.concatenate([tags, np.arange(n + 1) * pitch - gap, np.arange(n + 1) * pitch])

            xs, ys = axis(self.cols), axis(self.rows)
        # Edges closer than 1 nm are one edge (floating-point copies of the same line).
        xs, ys = (_merge_close(np.r_[a, lo, hi]) for a, lo, hi in ((xs, sx0, sx1), (ys, sy0, sy1)))
        texture = _RectilinearTexture(xs, ys, self._lookup)
        _TEXTURE_CACHE[self] = texture
        return texture

    def _lookup(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Unfiltered reflectance at (x, y) (piecewise constant between the breakpoints)."""
        sx0, sx1, sy0, sy1 = self.sheet_bounds_m()
        on_sheet = (x >= sx0) & (x < sx1) & (y >= sy0) & (y < sy1)
        out = np.where(on_sheet, WHITE, BACKGROUND)
        if self.kind == "checkerboard":
            i = np.floor(x / self.spacing_m)
            j = np.floor(y / self.row_pitch_m)
            inside = (i >= -1) & (i <= self.cols - 1) & (j >= -1) & (j <= self.rows - 1)
            # Square (i, j) is black when i + j is even: the squares at the pattern's top-left and
            # around the origin corner diagonally are black.
            black = inside & ((i + j) % 2 == 0)
            return np.where(black, BLACK, out)
        pitch, size = self.tag_pitch_m, self.spacing_m
        i = np.floor(x / pitch)
        j = np.floor(y / pitch)
        lx, ly = x - i * pitch, y - j * pitch
        in_tag = (lx < size) & (ly < size) & (i >= 0) & (i < self.cols) & (j >= 0) & (j < self.rows)
        square = (lx >= size) & (ly >= size) & (i >= -1) & (i < self.cols) & (j >= -1) & (j < self.rows)
        bits = _tag_bits(self.cols * self.rows)
        tag_id = np.where(in_tag, j * self.cols + i, 0).astype(np.int64)
        n = TAG_CELLS
        col = np.clip(np.floor(lx / size * n), 0, n - 1).astype(np.int64)
        row = np.clip(n - 1 - np.floor(ly / size * n), 0, n - 1).astype(np.int64)  # image row 0 at the top (+y)
        tag_value = np.where(bits[tag_id, row, col], WHITE, BLACK)
        out = np.where(in_tag, tag_value, out)
        return np.where(square, BLACK, out)


_TEXTURE_CACHE: dict = {}
_TAG_BITS_CACHE: dict = {}


def _tag_bits(count: int) -> np.ndarray:
    """(count, 10, 10) bool: white cells of 36h11 tags 0..count-1 as drawn on the target.

    cv2.aruco's marker image with Kalibr's 2-cell black border around the 6x6 data, rotated by
    180° as kalibr_create_target_pdf draws its tags (np.rot90(code, 2)); row 0 = top of the printed
    tag. (Checked against a real EuRoC AprilGrid frame: same border, same corner order.)
    """
    bits = _TAG_BITS_CACHE.get(count)
    if bits is None:
        dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
        bits = np.stack([np.rot90(dictionary.generateImageMarker(k, TAG_CELLS, borderBits=TAG_BORDER_BITS) > 127, 2)
                         for k in range(count)])
        _TAG_BITS_CACHE[count] = bits
    return bits


def _aruco_corner_point_ids(target: RenderTarget) -> np.ndarray:
    """(tags, 4) target point ids of cv2.aruco's corners 0..3 (the marker image's top-left,
    top-right, bottom-right, bottom-left) for each tag as drawn by :meth:`RenderTarget._lookup`."""
    # Marker image corner (col, row) in cell units, rotated by 180° then placed with row 0 at +y:
    # image corner (a, b) (0 or 1: left/right, top/bottom) lands at tag-local x = (1 - a) size,
    # y = b size.
    ids = np.zeros((target.rows * target.cols, 4), dtype=np.int64)
    for k in range(target.rows * target.cols):
        j, i = divmod(k, target.cols)
        for n, (a, b) in enumerate([(0, 0), (1, 0), (1, 1), (0, 1)]):
            cx, cy = 1 - a, b      # 0 = low side, 1 = high side of the tag
            ids[k, n] = (2 * j + cy) * 2 * target.cols + 2 * i + cx
    return ids


def _merge_close(values: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    v = np.sort(values)
    return v[np.r_[True, np.diff(v) > tol]]


class _RectilinearTexture:
    """A piecewise-constant texture whose edges are the lines x = xs[k] and y = ys[k].

    Cell (i, j) spans xs[i-1] <= x < xs[i], ys[j-1] <= y < ys[j] (cell 0 and the last cell are
    unbounded); ``table[i, j]`` is its value. Box filter over a footprint narrower than the smallest
    cell: only the nearest x edge and the nearest y edge can cross it, so the filtered value is the
    area-weighted mean of the four cells around their crossing — exact, whatever the pattern.
    """

    def __init__(self, xs: np.ndarray, ys: np.ndarray, lookup: Callable) -> None:
        self.xs, self.ys = xs, ys

        def centres(b: np.ndarray) -> np.ndarray:
            return np.r_[b[0] - 1.0, 0.5 * (b[:-1] + b[1:]), b[-1] + 1.0]

        cx, cy = centres(xs), centres(ys)
        self.table = lookup(cx[:, None] + 0 * cy[None], 0 * cx[:, None] + cy[None]).astype(np.float32)
        self._flat = self.table.ravel()
        self._xs32, self._ys32 = xs.astype(np.float32), ys.astype(np.float32)  # same dtype as the samples
        self._stride = self.table.shape[1]

    @staticmethod
    def _nearest_edge(edges: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index k of the nearest edge and its coordinate."""
        i = np.searchsorted(edges, x)
        lo = np.clip(i - 1, 0, len(edges) - 1)
        hi = np.clip(i, 0, len(edges) - 1)
        k = np.where(np.abs(x - edges[lo]) < np.abs(edges[hi] - x), lo, hi)
        return k, edges[k]

    def filtered(self, x: np.ndarray, y: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
        kx, bx = self._nearest_edge(self._xs32 if x.dtype == np.float32 else self.xs, x)
        ky, by = self._nearest_edge(self._ys32 if y.dtype == np.float32 else self.ys, y)
        ax = _ramp((bx - x) / wx)  # share of the footprint in cell kx (below the edge), rest in kx + 1
        ay = _ramp((by - y) / wy)
        base = kx * self._stride + ky
        t = self._flat
        low_x = ay * t[base] + (1.0 - ay) * t[base + 1]
        high_x = ay * t[base + self._stride] + (1.0 - ay) * t[base + self._stride + 1]
        value = ax * low_x + (1.0 - ax) * high_x
        return np.where(np.isfinite(value), value, BACKGROUND)


# --------------------------------------------------------------------------------------------------
# Camera and trajectory


def default_camera(size: Sequence[int] = (640, 480), model: str = "pinhole-radtan") -> CameraModel:
    """simulate.simulate_default's camera (640x480, f = 500 px, k1 = -0.1, k2 = 0.05), with the focal
    length scaled by width / 640 for other sizes and the principal point at the image centre.
    ``pinhole-equidistant`` gives a fisheye-model camera with the same f and mild k1..k4."""
    width, height = int(size[0]), int(size[1])
    f = 500.0 * width / 640.0
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    if model == "pinhole-radtan":
        return CameraModel(model, [f, f, cx, cy, -0.1, 0.05, 0.0, 0.0, 0.0], width, height)
    if model == "pinhole-equidistant":
        return CameraModel(model, [f, f, cx, cy, -0.02, 0.01, 0.0, 0.0], width, height)
    raise InputError(f"unknown camera model {model!r} (pinhole-radtan, pinhole-equidistant)")


class TargetFlippedTrajectory:
    """A trajectory expressed in a target frame turned by 180° about x (x_v = x, y_v = -y, z_v = -z).

    Kalibr's AprilGrid frame has y up the printed page, so the printed side faces +z; the hand-held
    trajectory looks from -z. Composing with this fixed rotation keeps the camera on the printed side.
    """

    _FLIP = np.diag([1.0, -1.0, -1.0])

    def __init__(self, base: Any) -> None:
        self.base = base

    def pose_cw(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, p = self.base.pose_cw(t_s)
        return R @ self._FLIP, p

    def __getattr__(self, name: str) -> Any:  # duration_s, seed, ... of the base trajectory
        if name == "base":  # not yet set (copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.base, name)


def default_trajectory(camera: CameraModel, target: RenderTarget, duration_s: float, seed: int = 0,
                       motion: float = 1.0) -> Any:
    """simulate.HandheldTrajectory looking at the target centre from the stand-off at which the
    target fills about half the image; ``motion`` scales its amplitude (0 = static camera)."""
    pts = target.points()
    center = target.center_m()
    distance = standoff_distance_m(camera, pts)
    if target.kind == "aprilgrid":
        center = center * np.array([1.0, -1.0, 1.0])
        return TargetFlippedTrajectory(HandheldTrajectory(duration_s=duration_s, seed=seed, amplitude=motion,
                                                          target_center_m=center, distance_m=distance))
    return HandheldTrajectory(duration_s=duration_s, seed=seed, amplitude=motion, target_center_m=center,
                              distance_m=distance)


def _trajectory_description(trajectory: Any) -> dict:
    """Enough to rebuild a default trajectory (see :func:`trajectory_from_truth`)."""
    flipped = isinstance(trajectory, TargetFlippedTrajectory)
    base = trajectory.base if flipped else trajectory
    if type(base) is not HandheldTrajectory or base.amplitude_profile is not None:
        return {"type": type(base).__name__}
    return {"type": "HandheldTrajectory", "flip_target_x180": flipped, "seed": base.seed,
            "duration_s": base.duration_s, "amplitude": base.amplitude,
            "target_center_m": base.target_center_m.tolist(), "distance_m": base.distance_m}


def trajectory_from_truth(truth: dict) -> Any:
    """Rebuild the analytic trajectory recorded in a truth.json (default trajectories only)."""
    d = truth.get("trajectory", {})
    if d.get("type") != "HandheldTrajectory":
        raise InputError("truth.json: the trajectory is not a default HandheldTrajectory; use its samples")
    base = HandheldTrajectory(duration_s=d["duration_s"], seed=d["seed"], amplitude=d["amplitude"],
                              target_center_m=d["target_center_m"], distance_m=d["distance_m"])
    return TargetFlippedTrajectory(base) if d.get("flip_target_x180") else base


# --------------------------------------------------------------------------------------------------
# Renderer


class RollingShutterRenderer:
    """Renders frames of a rolling-shutter camera moving along ``trajectory`` in front of ``target``.

    camera:            rscalib.CameraModel (its unprojection maps every sub-pixel to a ray, once).
    trajectory:        anything with ``pose_cw(t) -> (R (n,3,3), p (n,3))``, vectorised over t.
    line_delay_s:      d; row v (continuous, px) starts exposure at t_i + v d.
    supersample:       n × n sub-pixel samples per pixel, each at its own sub-row time.
    exposure_s:        exposure per row; 0 = instantaneous.
    exposure_samples:  times per sub-pixel over the exposure (midpoints of equal slices); None =
                       enough that the target points move ≤ ½ px between them (per frame, ≤ 64).
    intensity_modulation: optional f(t_s) -> gain (array in, array out), multiplying the scene
                       radiance at each sample time: the hook for a flickering light.
    workers:           threads over row blocks (numpy releases the GIL); default min(4, cpus).
    """

    def __init__(self, camera: CameraModel, target: RenderTarget, trajectory: Any, line_delay_s: float,
                 supersample: int = 3, exposure_s: float = 0.0, exposure_samples: Optional[int] = None,
                 intensity_modulation: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                 workers: Optional[int] = None, block_rows: Optional[int] = None) -> None:
        if not 1 <= int(supersample) <= 8:
            raise InputError("supersample must be 1..8")
        if not exposure_s >= 0:
            raise InputError("exposure must be >= 0")
        if exposure_samples is not None and int(exposure_samples) < 1:
            raise InputError("exposure samples must be >= 1")
        self.camera = camera
        self.target = target
        self.trajectory = trajectory
        self.line_delay_s = float(line_delay_s)
        self.supersample = int(supersample)
        self.exposure_s = float(exposure_s)
        self.exposure_samples = None if exposure_samples is None else int(exposure_samples)
        self.intensity_modulation = intensity_modulation
        self.width, self.height = int(camera.width), int(camera.height)
        self.workers = max(1, int(workers if workers is not None else min(4, os.cpu_count() or 1)))
        # ~100k samples per block keeps the temporaries in cache-friendly sizes.
        self.block_rows = int(block_rows or max(1, 100_000 // (self.width * self.supersample ** 2)))
        self._points = target.points()
        self._K, self._dist = opencv_matrices(camera)
        self._rays = self._ray_grid()
        self._pool = ThreadPoolExecutor(self.workers) if self.workers > 1 else None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> RollingShutterRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _ray_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Normalised ray (x, y) of every sub-pixel sample, (H·n, W·n) float32 each.

        Sub-pixel k of n sits at offset (k + ½)/n − ½ from the pixel centre, so the samples tile the
        pixel's area [u−½, u+½] (docs/conventions.md)."""
        n = self.supersample
        u = (np.arange(self.width * n) + 0.5) / n - 0.5
        v = (np.arange(self.height * n) + 0.5) / n - 0.5
        rays_x = np.empty((len(v), len(u)), dtype=np.float32)
        rays_y = np.empty_like(rays_x)
        # Unproject a band of rows at a time to bound the temporary memory of a large frame.
        band = max(1, 400_000 // len(u))
        for v0 in range(0, len(v), band):
            vv = v[v0:v0 + band]
            uv = np.column_stack([np.tile(u, len(vv)), np.repeat(vv, len(u))])
            ray = np.asarray(self.camera.unproject(uv)).reshape(len(vv), len(u), 3)
            rays_x[v0:v0 + band] = ray[..., 0]
            rays_y[v0:v0 + band] = ray[..., 1]
        return rays_x, rays_y

    def sub_row_v(self) -> np.ndarray:
        """Continuous row coordinate of each sub-row (H·n,)."""
        n = self.supersample
        return (np.arange(self.height * n) + 0.5) / n - 0.5

    def exposure_offsets_s(self, t_frame_s: float) -> np.ndarray:
        """Sample times within the exposure, relative to the row time (midpoints of equal slices)."""
        if self.exposure_s <= 0:
            return np.zeros(1)
        k = self.exposure_samples
        if k is None:
            # Consecutive blur copies at most ½ px apart: each copy is already box-filtered over its
            # pixel, so the sum of copies is then a smooth ramp, like the continuous blur.
            uv0 = self.project_rs(t_frame_s, 0.0)
            uv1 = self.project_rs(t_frame_s, self.exposure_s)
            travel = np.nanmax(np.linalg.norm(uv1 - uv0, axis=1), initial=0.0)
            k = int(np.clip(np.ceil(2.0 * travel), 1, MAX_EXPOSURE_SAMPLES))
        return (np.arange(k) + 0.5) / k * self.exposure_s

    def project_rs(self, t_frame_s: float, time_offset_s: float = 0.0, line_delay_s: Optional[float] = None,
                   ) -> np.ndarray:
        """Exact rolling-shutter projection (P, 2) of the target points in the frame stamped t_frame_s
        (NaN where not projectable): the fixed point v = v_proj(T_cw(t + v d + offset) P)."""
        d = self.line_delay_s if line_delay_s is None else float(line_delay_s)
        pts = self._points
        shifted = _ShiftedTrajectory(self.trajectory, time_offset_s)
        uv, valid = rs_projection(shifted, self.camera.model, self._K, self._dist, pts,
                                   np.full(len(pts), float(t_frame_s)), d)
        uv = uv.copy()
        uv[~valid] = np.nan
        return uv

    def render(self, t_frame_s: float) -> np.ndarray:
        """Noise-free frame (H, W) float64 in [0, 1] (fractions of full scale)."""
        n = self.supersample
        v_sub = self.sub_row_v()
        offsets = self.exposure_offsets_s(t_frame_s)
        # One vectorised pose evaluation for all sub-rows and exposure samples of the frame.
        times = (t_frame_s + v_sub * self.line_delay_s)[None, :] + offsets[:, None]  # (K, H·n)
        R, p = self.trajectory.pose_cw(times.ravel())
        R = R.reshape(len(offsets), -1, 3, 3)
        p = p.reshape(len(offsets), -1, 3)
        gain = None
        if self.intensity_modulation is not None:
            gain = np.broadcast_to(np.asarray(self.intensity_modulation(times), dtype=np.float64), times.shape)
        image = np.empty((self.height, self.width))

        def block(v0: int) -> None:
            v1 = min(self.height, v0 + self.block_rows)
            s0, s1 = v0 * n, v1 * n
            acc = None
            for k in range(len(offsets)):
                value = self._shade(s0, s1, R[k, s0:s1], p[k, s0:s1])
                if gain is not None:
                    value *= gain[k, s0:s1, None]
                acc = value if acc is None else acc + value
            acc /= len(offsets)
            image[v0:v1] = acc.reshape(v1 - v0, n, self.width, n).mean(axis=(1, 3))

        starts = range(0, self.height, self.block_rows)
        if self._pool is None:
            for v0 in starts:
                block(v0)
        else:
            list(self._pool.map(block, starts))
        return image

    def _shade(self, s0: int, s1: int, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Texture values of the sub-pixel samples of sub-rows s0..s1 with one pose per sub-row."""
        rx = self._rays[0][s0:s1]
        ry = self._rays[1][s0:s1]
        # float32 per sample: half the memory traffic of float64, and its ~1e-7 relative error is
        # ~1e-4 px on the target at any sensible distance.
        col = lambda a: a[:, None].astype(np.float32)  # noqa: E731  (per-sub-row coefficient)
        # Ray r = (x, y, 1) in the camera; Rᵀ r in the world: A_j = x R_0j + y R_1j + R_2j.
        ax = rx * col(R[:, 0, 0]) + ry * col(R[:, 1, 0]) + col(R[:, 2, 0])
        ay = rx * col(R[:, 0, 1]) + ry * col(R[:, 1, 1]) + col(R[:, 2, 1])
        az = rx * col(R[:, 0, 2]) + ry * col(R[:, 1, 2]) + col(R[:, 2, 2])
        b = np.einsum("sij,si->sj", R, p)  # Rᵀ p; the world point is X = λ Rᵀ r − Rᵀ p
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = col(b[:, 2]) / az          # z = 0 on the target plane
            hit = lam > 0                    # plane in front of the camera (NaN rays fail too)
            x = np.where(hit, lam * ax - col(b[:, 0]), np.float32(np.nan))
            y = np.where(hit, lam * ay - col(b[:, 1]), np.float32(np.nan))
            # Footprint of one sample on the target: the bounding box of its parallelogram, from
            # differences to the neighbouring samples (the filter width; it does not move edges).
            wx = _abs_diff(x, 1) + _abs_diff(x, 0)
            wy = _abs_diff(y, 1) + _abs_diff(y, 0)
            wx = np.where(np.isfinite(wx), wx, np.float32(1.0)) + np.float32(1e-9)
            wy = np.where(np.isfinite(wy), wy, np.float32(1.0)) + np.float32(1e-9)
            return self.target.albedo(x, y, wx, wy)


def _abs_diff(a: np.ndarray, axis: int) -> np.ndarray:
    """|forward difference| along axis, the last entry repeated (same shape as a)."""
    d = np.abs(np.diff(a, axis=axis))
    if a.shape[axis] < 2:
        return np.zeros_like(a)
    last = d[-1:] if axis == 0 else d[:, -1:]
    return np.concatenate([d, last], axis=axis)


class _ShiftedTrajectory:
    """``pose_cw(t + offset)``: projections at a fixed time into the exposure."""

    def __init__(self, base: Any, offset_s: float) -> None:
        self.base, self.offset_s = base, float(offset_s)

    def pose_cw(self, t_s):
        return self.base.pose_cw(np.asarray(t_s, dtype=np.float64) + self.offset_s)


# --------------------------------------------------------------------------------------------------
# Video output


@dataclass
class RenderedVideo:
    """What :func:`render_video` wrote, and the ground truth (the content of truth.json)."""

    out_dir: Path
    video_path: Optional[Path]
    frames_dir: Optional[Path]
    truth_path: Path
    camera_path: Path
    target_path: Path
    camera: CameraModel
    target: RenderTarget
    trajectory: Any
    line_delay_s: float
    fps: float
    frame_times_s: np.ndarray
    truth: dict = field(repr=False)
    render_seconds: float = 0.0
    codec: str = ""

    @property
    def num_frames(self) -> int:
        return len(self.frame_times_s)

    @property
    def frames_per_second_rendered(self) -> float:
        return self.num_frames / self.render_seconds if self.render_seconds > 0 else float("nan")

    def uv_rs(self) -> np.ndarray:
        """(frames, points, 2) exact rolling-shutter projections (NaN where not visible)."""
        return _uv_array(self.truth["projections"]["uv_rs"])

    def uv_gs(self) -> np.ndarray:
        """(frames, points, 2) global-shutter projections (every row at t_i)."""
        return _uv_array(self.truth["projections"]["uv_gs"])


def _uv_array(nested: list) -> np.ndarray:
    return np.array([[[np.nan, np.nan] if p is None else p for p in frame] for frame in nested], dtype=np.float64)


def _uv_list(uv: np.ndarray) -> list:
    """Per point [u, v] or None (NaN) — JSON has no NaN."""
    return [None if not np.all(np.isfinite(row)) else [round(float(row[0]), 6), round(float(row[1]), 6)]
            for row in uv]


def _open_writer(path_stem: Path, fps: float, size: tuple[int, int], codec: str):
    """(writer, path, codec): FFV1 (lossless) in AVI, else MJPG (lossy; OpenCV's FFmpeg writer
    does not take a quality setting).

    AVI rather than MKV: OpenCV's MKV output rounds presentation times to whole milliseconds (frame
    1 at 33 ms instead of 33.33 ms), an error of ~10 rows of readout; AVI stamps frame i at i/fps."""
    choices = [("FFV1", []), ("MJPG", [])]
    if codec != "auto":
        choices = [c for c in choices if c[0] == codec.upper()]
        if not choices:
            raise InputError(f"unknown codec {codec!r} (auto, ffv1, mjpg)")
    path = path_stem.with_suffix(".avi")
    for fourcc, params in choices:
        writer = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*fourcc), float(fps), size,
                                 [cv2.VIDEOWRITER_PROP_IS_COLOR, 0, *params])
        if writer.isOpened():
            return writer, path, fourcc
        writer.release()
    raise InputError(f"OpenCV cannot write {path.name} with {' or '.join(c[0] for c in choices)} "
                     "(is OpenCV built with FFmpeg?)")


def to_uint8(image: np.ndarray, noise: float = 0.0, rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """Radiance in [0, 1] → 8-bit grey with Gaussian noise of σ = noise grey levels."""
    grey = image * 255.0
    if noise > 0:
        rng = rng if rng is not None else np.random.default_rng()
        grey = grey + rng.normal(0.0, noise, size=grey.shape)
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)


def _pose_samples(trajectory: Any, times_s: np.ndarray) -> dict:
    R, p = trajectory.pose_cw(times_s)
    rotvec = unwrap_rotation_vectors(Rotation.from_matrix(R).as_rotvec())
    return {"t_s": [float(t) for t in times_s],
            "rotation_vector": np.round(np.asarray(rotvec), 12).tolist(),
            "translation_m": np.round(p, 12).tolist()}


def _parse_size(size: Union[str, Sequence[int]]) -> tuple[int, int]:
    if isinstance(size, str):
        parts = size.lower().replace("×", "x").split("x")
        try:
            width, height = (int(p) for p in parts)
        except ValueError:
            raise InputError(f"bad image size {size!r}: use WIDTHxHEIGHT, e.g. 640x480") from None
    else:
        try:
            width, height = (int(s) for s in size)
        except (TypeError, ValueError):
            raise InputError(f"bad image size {size!r}: give (width, height)") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise InputError(f"bad image size {width}x{height}: each side must be 16..8192 px")
    return width, height


def render_video(out_dir, line_delay_s: float = 30e-6, fps: float = 30.0,
                 size: Union[str, Sequence[int]] = (640, 480),
                 target: Union[str, RenderTarget, Path] = "checkerboard", duration_s: float = 5.0,
                 exposure_s: float = 0.0, noise: float = 2.0, seed: int = 0, *,
                 camera: Optional[CameraModel] = None, trajectory: Any = None, motion: float = 1.0,
                 supersample: int = 3, exposure_samples: Optional[int] = None, video: bool = True,
                 frames_dir: Union[None, bool, str, Path] = None, codec: str = "auto",
                 intensity_modulation: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                 flicker_hz: Optional[float] = None, flicker_depth: float = 0.3, flicker_phase_rad: float = 0.0,
                 dense_rate_hz: float = 200.0, workers: Optional[int] = None,
                 progress: bool = True) -> RenderedVideo:
    """Render a rolling-shutter video of a target with its ground truth.

    Writes to ``out_dir``: ``video.avi`` (FFV1, lossless; MJPG if FFV1 is unavailable), frame i
    stamped i / fps = t_i; ``truth.json``; ``camera.yaml`` (OpenCV FileStorage, with the true line
    delay); ``target.yaml`` (Kalibr). ``frames_dir`` (True = ``out_dir/frames``) also writes
    ``frame_000000.png …`` and ``timestamps.txt`` (one time in seconds per line, in file order).

    line_delay_s: d (s/row), |d|·rows must fit in a frame period. fps, duration_s: frames at
        t_i = i / fps for i < floor(duration·fps). size: (w, h) or "WxH" for the default camera
        (:func:`default_camera`); ignored when ``camera`` is given. target: name
        (:meth:`RenderTarget.named`), Kalibr YAML path or RenderTarget. exposure_s: per-row
        exposure (motion blur), ≤ 1/fps. noise: σ of Gaussian intensity noise in 8-bit grey levels.
        seed: the default trajectory and the noise. motion: amplitude of the default hand-held
        trajectory. trajectory: anything with a vectorised ``pose_cw(t)``, overriding the default.
        intensity_modulation: f(t) -> gain on the scene radiance (flicker hook).
        flicker_hz, flicker_depth, flicker_phase_rad: a light flickering as gain
        1 + depth·sin(2π f t + phase) (instead of intensity_modulation); recorded in truth.json.
        supersample, exposure_samples, workers: see :class:`RollingShutterRenderer`.
    """
    for name, value in (("fps", fps), ("duration", duration_s)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number (got {value})")
    if not math.isfinite(line_delay_s):
        raise InputError("line delay must be finite")
    if not (math.isfinite(exposure_s) and exposure_s >= 0):
        raise InputError(f"exposure must be >= 0 (got {exposure_s})")
    if exposure_s > 1.0 / fps:
        raise InputError(f"exposure {exposure_s * 1e3:.3g} ms exceeds the frame period {1e3 / fps:.3g} ms")
    if not (math.isfinite(noise) and noise >= 0):
        raise InputError(f"noise must be >= 0 grey levels (got {noise})")
    if not (math.isfinite(motion) and motion >= 0):
        raise InputError(f"motion amplitude must be >= 0 (got {motion})")
    flicker = None
    if flicker_hz is not None:
        if intensity_modulation is not None:
            raise InputError("give a flicker frequency or an intensity modulation, not both")
        if not (math.isfinite(flicker_hz) and flicker_hz > 0):
            raise InputError(f"flicker frequency must be positive (got {flicker_hz})")
        if not (math.isfinite(flicker_depth) and 0 <= flicker_depth < 1):
            raise InputError(f"flicker depth must be in [0, 1) (got {flicker_depth})")
        if not math.isfinite(flicker_phase_rad):
            raise InputError("flicker phase must be finite")
        flicker = {"frequency_hz": float(flicker_hz), "depth": float(flicker_depth),
                   "phase_rad": float(flicker_phase_rad),
                   "gain": "1 + depth * sin(2 pi frequency_hz t + phase_rad), t = row time (s); "
                           "radiance above full scale clips"}

        def flicker_gain(t: np.ndarray) -> np.ndarray:
            return 1.0 + flicker_depth * np.sin(2.0 * np.pi * flicker_hz * t + flicker_phase_rad)
        intensity_modulation = flicker_gain
    if camera is None:
        camera = default_camera(_parse_size(size))
    if abs(line_delay_s) * camera.height > 1.0 / fps:
        raise InputError(f"readout time {abs(line_delay_s) * camera.height * 1e3:.3g} ms (line delay x "
                         f"{camera.height} rows) exceeds the frame period {1e3 / fps:.3g} ms")
    target = RenderTarget.parse(target)
    num_frames = int(math.floor(duration_s * fps + 1e-9))
    if num_frames < 1:
        raise InputError(f"duration {duration_s} s at {fps} fps gives no frame")
    if trajectory is None:
        trajectory = default_trajectory(camera, target, duration_s, seed, motion)

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if frames_dir is True:
        frames_dir = out_dir / "frames"
    frames_dir = Path(frames_dir) if frames_dir else None
    if frames_dir is not None:
        frames_dir.mkdir(parents=True, exist_ok=True)
    frame_times = np.arange(num_frames) / float(fps)
    rng = np.random.default_rng([0x52454E, int(seed)])  # a stream of its own: noise only

    writer, video_path, used_codec = (None, None, "")
    if video:
        writer, video_path, used_codec = _open_writer(out_dir / Path(VIDEO_NAME).stem, fps,
                                                      (camera.width, camera.height), codec)
    renderer = RollingShutterRenderer(camera, target, trajectory, line_delay_s, supersample=supersample,
                                      exposure_s=exposure_s, exposure_samples=exposure_samples,
                                      intensity_modulation=intensity_modulation, workers=workers)
    uv_rs, uv_gs, uv_mid = [], [], []
    render_started = time.perf_counter()
    try:
        with Progress(progress, num_frames, f"rendering {camera.width}x{camera.height}") as bar:
            for i, t in enumerate(frame_times):
                frame = to_uint8(renderer.render(t), noise, rng)
                if writer is not None:
                    writer.write(frame)
                if frames_dir is not None:
                    cv2.imwrite(str(frames_dir / f"frame_{i:06d}.png"), frame)
                uv_rs.append(_uv_list(renderer.project_rs(t)))
                uv_gs.append(_uv_list(renderer.project_rs(t, line_delay_s=0.0)))
                if exposure_s > 0:
                    uv_mid.append(_uv_list(renderer.project_rs(t, 0.5 * exposure_s)))
                bar.advance()
    finally:
        renderer.close()
        if writer is not None:
            writer.release()
    render_seconds = time.perf_counter() - render_started
    if frames_dir is not None:
        (frames_dir / "timestamps.txt").write_text("".join(f"{t:.9f}\n" for t in frame_times))

    from ..io.cameras import write_opencv_yaml

    camera_path = out_dir / "camera.yaml"
    write_opencv_yaml(camera, camera_path, line_delay_s=line_delay_s)
    target_path = out_dir / "target.yaml"
    target_path.write_text(yaml.safe_dump(target.kalibr_dict(), sort_keys=False))

    readout_end = abs(line_delay_s) * camera.height + exposure_s
    dense_times = np.arange(0.0, frame_times[-1] + readout_end + 1.0 / dense_rate_hz, 1.0 / dense_rate_hz)
    projections = {"uv_rs": uv_rs, "uv_gs": uv_gs,
                   "definition": "uv_rs: exact rolling-shutter projection, v = v_proj(T_cw(t_i + v d) P) "
                                 "(start of the row's exposure); uv_gs: every row at t_i; null = not visible"}
    if exposure_s > 0:
        projections["uv_rs_mid_exposure"] = uv_mid
        projections["definition"] += "; uv_rs_mid_exposure: at t_i + v d + exposure/2 (blur centroid)"
    truth = {
        "generator": "rscalib.sim.target_video",
        "line_delay_s": float(line_delay_s),
        "readout_time_s": float(line_delay_s) * camera.height,
        "fps": float(fps),
        "duration_s": float(duration_s),
        "num_frames": num_frames,
        "frame_times_s": [float(t) for t in frame_times],
        "image_size": [int(camera.width), int(camera.height)],
        "camera": {"model": camera.model, "params": [float(v) for v in camera.params],
                   "width": int(camera.width), "height": int(camera.height)},
        "target": target.to_dict(),
        "target_points_m": target.points().tolist(),
        "noise_grey_levels": float(noise),
        "exposure_s": float(exposure_s),
        "exposure_samples": exposure_samples,
        "supersample": int(supersample),
        "seed": int(seed),
        "motion_amplitude": float(motion),
        "intensity_modulation": None if intensity_modulation is None else getattr(
            intensity_modulation, "__name__", "custom"),
        "flicker": flicker,
        "video": None if video_path is None else {"file": video_path.name, "codec": used_codec,
                                                  "frame_timestamps": "frame i at i / fps"},
        "frames_dir": None if frames_dir is None else str(frames_dir),
        "trajectory": _trajectory_description(trajectory),
        "poses_at_frames": _pose_samples(trajectory, frame_times),
        "poses_dense": dict(_pose_samples(trajectory, dense_times), rate_hz=float(dense_rate_hz)),
        "projections": projections,
        "conventions": "docs/conventions.md: x_c = R x_w + p, rotation_vector = log(R); OpenCV pixels",
    }
    truth_path = out_dir / "truth.json"
    truth_path.write_text(_compact_json(truth))
    return RenderedVideo(out_dir=out_dir, video_path=video_path, frames_dir=frames_dir, truth_path=truth_path,
                         camera_path=camera_path, target_path=target_path, camera=camera, target=target,
                         trajectory=trajectory, line_delay_s=float(line_delay_s), fps=float(fps),
                         frame_times_s=frame_times, truth=truth, render_seconds=render_seconds, codec=used_codec)


def _compact_json(data: dict) -> str:
    """One top-level key per line, each value on one line: readable keys, no line per number."""
    items = (f" {json.dumps(k)}: {json.dumps(v, separators=(',', ':'))}" for k, v in data.items())
    return "{\n" + ",\n".join(items) + "\n}\n"


def load_truth(path) -> dict:
    """truth.json of a rendered video (a folder or the file itself)."""
    path = Path(path)
    if path.is_dir():
        path = path / "truth.json"
    if not path.is_file():
        raise InputError(f"truth file not found: {path}")
    return json.loads(path.read_text())
