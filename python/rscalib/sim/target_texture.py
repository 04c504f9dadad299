"""What a printed target looks like to the rolling-shutter renderer (sim/target_video.py).

A :class:`TargetTexture` draws a :class:`rscalib.io.targets.Target` (its geometry, ids and frames are
the Target's, docs/conventions.md): the pattern printed on a white sheet, lying in the background.
:meth:`TargetTexture.albedo` is the reflectance at target points, box-filtered over each sample's
footprint on the target — exact for the axis-aligned edges of checkerboards and AprilGrids
(:class:`RectilinearTexture`), a radial ramp for circles — so that edges land where the geometry puts
them rather than on a sub-pixel lattice.

Drawing choices the target files do not record (they go to truth.json, :meth:`TargetTexture.describe`):
reflectances :data:`BLACK`, :data:`WHITE`, :data:`BACKGROUND`; the sheet margin (one square / spacing,
half a tag for AprilGrids); the circle radius (a quarter of the nearest-neighbour distance); AprilGrid
tags as Kalibr prints them (:func:`rscalib.io.targets.aprilgrid_tag_cells`) with its black squares
at the tag corners.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Optional

import numpy as np

from ..errors import InputError
from ..io.targets import APRILGRID_TAG_CELLS, Target, aprilgrid_tag_cells, as_target

__all__ = ["BACKGROUND", "BLACK", "WHITE", "RectilinearTexture", "TargetTexture", "texture_of"]

# Reflectances of the printed target and of what lies around it (fractions of full scale): not 0
# and 1, so that the noise is not clipped.
BLACK = 0.08
WHITE = 0.90
BACKGROUND = 0.45

RENDERABLE = ("checkerboard", "circlegrid", "aprilgrid")


def _ramp(x: np.ndarray) -> np.ndarray:
    """Box-filtered step: the fraction of a unit-width footprint centred at -x ... past the edge."""
    return np.clip(x + 0.5, 0.0, 1.0)


class TargetTexture:
    """The drawing of a Target: checkerboard, circle grid (symmetric or asymmetric) or AprilGrid.

    circle_radius_m: circlegrid only; default a quarter of the nearest-neighbour distance.
    margin_m:        white paper around the pattern; default one square / spacing / half a tag.

    Pattern parameters (from the Target's Kalibr fields): ``cols``, ``rows`` (inner corners, circles
    or tags), ``spacing_m`` (square width along x, circle spacing or tag size), ``row_pitch_m``
    (checkerboard square height along y), ``asymmetric``, ``tag_spacing`` (gap / tag size).
    """

    def __init__(self, target: Target, circle_radius_m: Optional[float] = None,
                 margin_m: Optional[float] = None) -> None:
        kind = target.target_type
        if kind not in RENDERABLE:
            raise InputError(f"target_type {kind!r} cannot be rendered ({', '.join(RENDERABLE)})")
        s = target.spec
        self.target = target
        self.kind = kind
        self.asymmetric = False
        self.tag_spacing = 0.0
        if kind == "checkerboard":
            self.cols, self.rows = s["targetCols"], s["targetRows"]
            self.spacing_m, self.row_pitch_m = s["colSpacingMeters"], s["rowSpacingMeters"]
        elif kind == "circlegrid":
            self.cols, self.rows = s["targetCols"], s["targetRows"]
            self.spacing_m = self.row_pitch_m = s["spacingMeters"]
            self.asymmetric = bool(s["asymmetricGrid"])
        else:
            self.cols, self.rows = s["tagCols"], s["tagRows"]
            self.spacing_m = self.row_pitch_m = s["tagSize"]
            self.tag_spacing = s["tagSpacing"]
        if circle_radius_m is not None:
            nn = self.spacing_m * (math.sqrt(2.0) if self.asymmetric else 1.0)
            if not 0 < circle_radius_m < 0.5 * nn:
                raise InputError("circle radius must be positive and less than half the circle distance")
        self.circle_radius_m = circle_radius_m
        self.margin_m = margin_m
        # Checkerboards and AprilGrids: a table of constant cells, built once.
        self._cells = None if kind == "circlegrid" else self._rectilinear()

    # -- geometry of the drawing ----------------------------------------------------------------
    @property
    def tag_pitch_m(self) -> float:
        return self.spacing_m * (1.0 + self.tag_spacing)

    @property
    def radius_m(self) -> float:
        if self.circle_radius_m is not None:
            return float(self.circle_radius_m)
        return 0.25 * self.spacing_m * (math.sqrt(2.0) if self.asymmetric else 1.0)

    def pattern_bounds_m(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) of the printed pattern (squares, circles, tags and corner squares)."""
        if self.kind == "checkerboard":
            return (-self.spacing_m, self.cols * self.spacing_m, -self.row_pitch_m, self.rows * self.row_pitch_m)
        if self.kind == "circlegrid":
            pts, rad = self.target.points_m, self.radius_m
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

    def describe(self) -> dict:
        """The Target's Kalibr fields plus the drawing details (for truth.json)."""
        d = self.target.kalibr_dict()
        d.update({"sheet_bounds_m": list(self.sheet_bounds_m()), "reflectance_black": BLACK,
                  "reflectance_white": WHITE, "reflectance_background": BACKGROUND})
        if self.kind == "circlegrid":
            d["circle_radius_m"] = self.radius_m
        if self.kind == "aprilgrid":
            d["tag_family"] = "36h11 (cv2.aruco.DICT_APRILTAG_36h11), 2-cell black border (markerBorderBits=2)"
            d["tag_drawing"] = ("cv2.aruco marker image rotated by 180 degrees, its top towards target +y "
                                "(as Kalibr's kalibr_create_target_pdf draws tags, rotation=2)")
            d["aruco_corner_point_ids"] = self.target.aruco_corner_ids().tolist()
        return d

    # -- reflectance ----------------------------------------------------------------------------
    def albedo(self, x: np.ndarray, y: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
        """Reflectance at target points (x, y), box-filtered over a footprint of wx × wy metres.

        Points off the sheet see the background; NaN coordinates count as off the sheet.
        """
        if self._cells is None:
            return self._circles(x, y, wx, wy)
        return self._cells.filtered(x, y, wx, wy)

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

    def _rectilinear(self) -> RectilinearTexture:
        """The pattern as a table of constant cells between its x and y edges."""
        sx0, sx1, sy0, sy1 = self.sheet_bounds_m()
        if self.kind == "checkerboard":
            xs = np.arange(-1, self.cols + 1) * self.spacing_m
            ys = np.arange(-1, self.rows + 1) * self.row_pitch_m
        else:
            pitch, size = self.tag_pitch_m, self.spacing_m
            cells = np.arange(APRILGRID_TAG_CELLS + 1) * size / APRILGRID_TAG_CELLS
            gap = self.tag_spacing * size

            def axis(n: int) -> np.ndarray:
                tags = (np.arange(n)[:, None] * pitch + cells[None]).ravel()
                return np.concatenate([tags, np.arange(n + 1) * pitch - gap, np.arange(n + 1) * pitch])

            xs, ys = axis(self.cols), axis(self.rows)
        # Edges closer than 1 nm are one edge (floating-point copies of the same line).
        xs, ys = (_merge_close(np.r_[a, lo, hi]) for a, lo, hi in ((xs, sx0, sx1), (ys, sy0, sy1)))
        return RectilinearTexture(xs, ys, self._lookup)

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
        white = aprilgrid_tag_cells(self.cols * self.rows)  # [tag, cell along +y, cell along +x]
        tag_id = np.where(in_tag, j * self.cols + i, 0).astype(np.int64)
        n = APRILGRID_TAG_CELLS
        col = np.clip(np.floor(lx / size * n), 0, n - 1).astype(np.int64)
        row = np.clip(np.floor(ly / size * n), 0, n - 1).astype(np.int64)
        tag_value = np.where(white[tag_id, row, col], WHITE, BLACK)
        out = np.where(in_tag, tag_value, out)
        return np.where(square, BLACK, out)


def texture_of(target: Any) -> TargetTexture:
    """A TargetTexture as given, or the default drawing of a Target, built-in name or target YAML path."""
    return target if isinstance(target, TargetTexture) else TargetTexture(as_target(target))


def _merge_close(values: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    v = np.sort(values)
    return v[np.r_[True, np.diff(v) > tol]]


class RectilinearTexture:
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
