"""Synthetic image sequences of a textured 3-D scene for the SOG self-calibration engine (Civera et
al. 2009; docs/sog.md).

A global-shutter camera (every pixel at the frame time) with known calibration — by default the
``civera-radial`` camera of Civera et al. 2009 (320×240, f 194.06 px) — moves hand-held
(:class:`rscalib.sim.trajectories.RoomWalkTrajectory`) inside a box-shaped room whose walls, floor and
ceiling carry procedural, seeded textures full of corners at several scales (good for FAST /
Shi-Tomasi features and NCC patch matching).

Rendering is by inverse mapping. Every pixel (``supersampling²`` sub-pixel samples) is unprojected
once through the camera model to a ray ``(x, y, 1)`` in the camera frame — constant across frames,
since the intrinsics are fixed. Per frame the rays are rotated to the world, intersected with all
planes, the nearest hit is kept and the texture is sampled there (trilinear mip-mapping at the
sample's footprint on the plane, so distant or grazing surfaces do not alias). Geometry is exact:
the image of a world point lies where ``CameraModel.project`` puts it, distortion included.

Conventions (docs/conventions.md): OpenCV pixels; camera x right, y down, z forward;
``x_c = R x_w + p``, camera centre ``-Rᵀ p``. The room's world frame has its origin at the centre of
the floor, z up. "Depth" is the camera-frame ``z`` of a point (so ``x_c = depth · ray``).

Outputs of :func:`render_scene_sequence`: ``frame_000000.png`` … (8-bit grey), ``timestamps.txt``
(one time in seconds per line, in file-name order) and ``truth.json`` (camera, trajectory per frame,
scene description, seed).
"""
from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence, Union

import cv2
import numpy as np

from .._core import CameraModel
from ..reference_cameras import PAPER_CAMERA_PARAMS, PAPER_IMAGE_SIZE, PAPER_PIXEL_SIZE_MM
from .target_video import to_uint8
from .trajectories import RoomWalkTrajectory, Trajectory

__all__ = [
    "PAPER_CAMERA_PARAMS",
    "PAPER_PIXEL_SIZE_MM",
    "RenderedFrames",
    "Scene",
    "SceneRenderer",
    "SceneSequence",
    "TexturedPlane",
    "default_camera",
    "load_scene_truth",
    "planes_scene",
    "procedural_texture",
    "render_scene_frames",
    "render_scene_sequence",
    "room_scene",
]

# Civera et al. 2009, §V: the calibrated 320x240 camera of their sequences.

BACKGROUND = 0.5  # grey of rays that hit nothing (only possible in open scenes)
_HIT_TOLERANCE_M = 1e-6  # planes meeting at a room edge must not leave a crack between them


def default_camera() -> CameraModel:
    """The paper's camera: civera-radial, 320×240, f 194.06 px, (Cx, Cy) = (160.22, 128.87),
    k1 0.06333 mm⁻², k2 0.0139 mm⁻⁴, pixels 0.0112 mm square."""
    return CameraModel("civera-radial", list(PAPER_CAMERA_PARAMS), *PAPER_IMAGE_SIZE,
                       pixel_size_mm=(PAPER_PIXEL_SIZE_MM, PAPER_PIXEL_SIZE_MM))


# --------------------------------------------------------------------------------------------------
# Textures and scene


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma_texels: float) -> np.ndarray:
    """Band-limited Gaussian noise with unit standard deviation (white noise blurred at sigma)."""
    noise = rng.standard_normal(shape).astype(np.float32)
    noise = cv2.GaussianBlur(noise, (0, 0), sigma_texels, borderType=cv2.BORDER_REFLECT)
    return noise / max(float(noise.std()), 1e-12)


def procedural_texture(width_m: float, height_m: float, seed: int, texels_per_m: float = 200.0,
                       shapes_per_m2: float = 60.0, size_range_m: tuple[float, float] = (0.03, 0.35)
                       ) -> np.ndarray:
    """Deterministic grey texture (rows = v, columns = u; float32 in [0, 1]) for a plane.

    Overlapping random rectangles (axis-aligned and rotated), triangles and discs of bimodal grey
    levels, log-uniform sizes in ``size_range_m`` (many corners and T-junctions at several scales),
    on top of low-contrast band-limited noise that also shows through the shapes so that flat areas
    still give unambiguous NCC matches. Texel (j, i) is centred at ((i + ½), (j + ½)) / texels_per_m m.
    """
    rng = np.random.default_rng([0x7E47, int(seed)])
    w_tx = max(2, int(round(width_m * texels_per_m)))
    h_tx = max(2, int(round(height_m * texels_per_m)))

    # Multi-octave background (1, 4, 15 cm): faint structure between the shapes.
    octaves_m, weights = (0.01, 0.04, 0.15), (0.3, 0.35, 0.35)
    noise = sum(w * _smooth_noise(rng, (h_tx, w_tx), s * texels_per_m) for s, w in zip(octaves_m, weights))

    # Base grey differs per plane so that the room's edges show as well.
    canvas = np.full((h_tx, w_tx), int(rng.uniform(95, 160)), dtype=np.uint8)
    n_shapes = rng.poisson(shapes_per_m2 * width_m * height_m)
    lo, hi = np.log(size_range_m[0]), np.log(size_range_m[1])
    sizes_m = np.sort(np.exp(rng.uniform(lo, hi, n_shapes)))[::-1]  # big first: small ones stay visible
    shift = 4  # cv2 drawing with 1/16-texel vertex precision
    scale = texels_per_m * (1 << shift)
    for size_m in sizes_m:
        centre = rng.uniform([0.0, 0.0], [width_m, height_m])
        # Bimodal grey levels: neighbouring shapes usually differ strongly (high-contrast corners).
        grey = int(rng.uniform(10, 90) if rng.uniform() < 0.5 else rng.uniform(165, 245))
        kind = rng.integers(4)
        if kind == 3:
            cv2.circle(canvas, tuple(np.round(centre * scale).astype(int)), int(0.5 * size_m * scale),
                       grey, -1, cv2.LINE_AA, shift)
            continue
        if kind == 0:  # axis-aligned rectangle of random aspect
            aspect = rng.uniform(0.4, 1.0)
            half = 0.5 * size_m * np.array([1.0, aspect])[rng.permutation(2)]
            corners = centre + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
        elif kind == 1:  # rotated rectangle
            aspect, angle = rng.uniform(0.4, 1.0), rng.uniform(0, np.pi)
            c, s = np.cos(angle), np.sin(angle)
            local = 0.5 * size_m * np.array([[-1, -aspect], [1, -aspect], [1, aspect], [-1, aspect]])
            corners = centre + local @ np.array([[c, s], [-s, c]])
        else:  # triangle: corners at several angles
            angles = np.sort(rng.uniform(0, 2 * np.pi, 3))
            corners = centre + 0.5 * size_m * np.column_stack([np.cos(angles), np.sin(angles)])
        cv2.fillConvexPoly(canvas, np.round(corners * scale).astype(np.int32), grey, cv2.LINE_AA, shift)

    texture = canvas.astype(np.float32) / 255.0 + 0.06 * noise
    # Band-limit to about a texel so level 0 of the mip pyramid does not alias either.
    texture = cv2.GaussianBlur(texture, (0, 0), 0.6, borderType=cv2.BORDER_REFLECT)
    return np.clip(texture, 0.02, 0.98).astype(np.float32)


@dataclass
class TexturedPlane:
    """A textured rectangle: points ``origin_m + s·axis_u + w·axis_v``, ``0 ≤ s ≤ size_m[0]``,
    ``0 ≤ w ≤ size_m[1]`` (metres). ``texture`` rows run along ``axis_v``, columns along ``axis_u``,
    with ``texels_per_m`` texels per metre; ``texture_seed`` documents procedural textures."""

    name: str
    origin_m: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    size_m: tuple[float, float]
    texture: np.ndarray
    texels_per_m: float
    texture_seed: Optional[int] = None

    def __post_init__(self) -> None:
        self.origin_m = np.asarray(self.origin_m, dtype=np.float64).reshape(3)
        self.axis_u = np.asarray(self.axis_u, dtype=np.float64).reshape(3)
        self.axis_v = np.asarray(self.axis_v, dtype=np.float64).reshape(3)
        self.axis_u /= np.linalg.norm(self.axis_u)
        self.axis_v /= np.linalg.norm(self.axis_v)
        if abs(self.axis_u @ self.axis_v) > 1e-9:
            raise ValueError(f"TexturedPlane {self.name}: axis_u and axis_v must be orthogonal")
        self.size_m = (float(self.size_m[0]), float(self.size_m[1]))
        self.texture = np.ascontiguousarray(self.texture, dtype=np.float32)
        if self.texture.ndim != 2 or min(self.texture.shape) < 2:
            raise ValueError(f"TexturedPlane {self.name}: texture must be a 2-D array, at least 2x2")
        self.texels_per_m = float(self.texels_per_m)

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.axis_u, self.axis_v)

    def describe(self) -> dict:
        return {"name": self.name, "origin_m": self.origin_m.tolist(), "axis_u": self.axis_u.tolist(),
                "axis_v": self.axis_v.tolist(), "size_m": list(self.size_m),
                "texels_per_m": self.texels_per_m, "texture_seed": self.texture_seed}


@dataclass
class Scene:
    """Planes in the world frame; ``background`` is the grey (0..1) where a ray hits nothing."""

    planes: list[TexturedPlane]
    background: float = BACKGROUND
    description: str = ""

    def describe(self) -> dict:
        return {"description": self.description, "background": self.background,
                "planes": [p.describe() for p in self.planes]}


def room_scene(seed: int = 0, size_m: Sequence[float] = (4.0, 3.0, 2.5), texels_per_m: float = 200.0,
               texture_fn: Optional[Callable[[float, float, int, float], np.ndarray]] = None) -> Scene:
    """A closed box room ``size_m = (length x, width y, height z)``: world origin at the centre of
    the floor, z up; six planes (floor, ceiling, four walls), each with its own seeded texture.

    ``texture_fn(width_m, height_m, seed, texels_per_m)`` makes a plane's texture (default
    :func:`procedural_texture`; e.g. photographic tiles, ``rscalib.sim.scene_realism``)."""
    texture_fn = procedural_texture if texture_fn is None else texture_fn
    lx, ly, lz = (float(s) for s in size_m)
    x0, y0 = -0.5 * lx, -0.5 * ly
    ex, ey, ez = np.eye(3)
    # (name, origin, axis_u, axis_v, size): walls are textured with v pointing down (like a picture).
    specs = [
        ("floor", (x0, y0, 0.0), ex, ey, (lx, ly)),
        ("ceiling", (x0, y0, lz), ex, ey, (lx, ly)),
        ("wall_y_min", (x0, y0, lz), ex, -ez, (lx, lz)),
        ("wall_y_max", (-x0, -y0, lz), -ex, -ez, (lx, lz)),
        ("wall_x_min", (x0, -y0, lz), -ey, -ez, (ly, lz)),
        ("wall_x_max", (-x0, y0, lz), ey, -ez, (ly, lz)),
    ]
    planes = []
    for k, (name, origin, au, av, size) in enumerate(specs):
        tex_seed = int(seed) * 16 + k  # different texture per plane, all from the one seed
        planes.append(TexturedPlane(name, origin, au, av, size,
                                    texture_fn(size[0], size[1], tex_seed, texels_per_m), texels_per_m,
                                    texture_seed=tex_seed))
    return Scene(planes, description=f"room {lx} x {ly} x {lz} m, origin at floor centre, z up")


def planes_scene(seed: int = 0, texels_per_m: float = 200.0, num_planes: int = 4) -> Scene:
    """Several free-standing textured panels at 2–4.5 m in front of a camera near the origin looking
    along +x (world z up), at seeded positions and tilts, over a floor (z = 0, x ∈ [0, 7] m) and in
    front of a back wall (x = 7 m, 20 × 8 m). Open scene: rays going up or back hit nothing."""
    rng = np.random.default_rng([0x91A5, int(seed)])
    planes = []
    ez = np.array([0.0, 0.0, 1.0])
    for k in range(num_planes):
        depth_m = rng.uniform(2.0, 4.5)
        lateral_m = rng.uniform(-1.5, 1.5)
        yaw = rng.uniform(-0.6, 0.6)  # panel normal off the viewing axis
        width_m, height_m = rng.uniform(1.0, 2.0), rng.uniform(1.0, 1.8)
        axis_u = np.array([np.sin(yaw), -np.cos(yaw), 0.0])  # to the camera's right when looking +x
        centre = np.array([depth_m, lateral_m, rng.uniform(1.0, 1.8)])
        origin = centre - 0.5 * width_m * axis_u + 0.5 * height_m * ez
        tex_seed = int(seed) * 16 + k
        planes.append(TexturedPlane(f"panel_{k}", origin, axis_u, -ez, (width_m, height_m),
                                    procedural_texture(width_m, height_m, tex_seed, texels_per_m),
                                    texels_per_m, texture_seed=tex_seed))
    # Far surroundings at half the texel density with larger shapes (they are seen from far away).
    far = dict(texels_per_m=texels_per_m / 2, shapes_per_m2=15.0, size_range_m=(0.08, 0.8))
    for name, origin, axis_u, axis_v, size, tex_seed in (
            ("back_wall", (7.0, 10.0, 8.0), (0.0, -1.0, 0.0), -ez, (20.0, 8.0), int(seed) * 16 + 14),
            ("floor", (0.0, 10.0, 0.0), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (7.0, 20.0), int(seed) * 16 + 15)):
        planes.append(TexturedPlane(name, origin, axis_u, axis_v, size,
                                    procedural_texture(size[0], size[1], tex_seed, **far), far["texels_per_m"],
                                    texture_seed=tex_seed))
    return Scene(planes, description="panels in front of a back wall, camera looking along +x, z up")


# --------------------------------------------------------------------------------------------------
# Renderer


@dataclass
class _MipAtlas:
    """All planes' mip levels in one flat array, so one vectorised gather serves every plane."""

    flat: np.ndarray          # float32, every (plane, level) image row-major, concatenated
    offset: np.ndarray        # (P, L) int64 start of each level in `flat`
    width: np.ndarray         # (P, L) int64 texels
    height: np.ndarray        # (P, L) int64
    num_levels: np.ndarray    # (P,) levels per plane (unused entries repeat the last level)


def _build_atlas(planes: Sequence[TexturedPlane], max_levels: int = 10) -> _MipAtlas:
    pyramids = []
    for plane in planes:
        levels = [plane.texture]
        while len(levels) < max_levels and min(levels[-1].shape) >= 4:
            img = levels[-1]
            h, w = img.shape
            # 2x2 box average: level l texel j is centred on level-0 texels 2^l j … 2^l (j+1) - 1.
            img = cv2.resize(img[: h - h % 2, : w - w % 2], (w // 2, h // 2), interpolation=cv2.INTER_AREA)
            levels.append(img)
        pyramids.append(levels)
    num_levels = np.array([len(lv) for lv in pyramids])
    L = int(num_levels.max())
    offset = np.zeros((len(planes), L), dtype=np.int64)
    width = np.zeros_like(offset)
    height = np.zeros_like(offset)
    chunks, pos = [], 0
    for k, levels in enumerate(pyramids):
        for l in range(L):
            img = levels[min(l, len(levels) - 1)]
            if l < len(levels):
                chunks.append(img.reshape(-1))
                offset[k, l] = pos
                pos += img.size
            else:
                offset[k, l] = offset[k, len(levels) - 1]
            height[k, l], width[k, l] = img.shape
    return _MipAtlas(np.concatenate(chunks).astype(np.float32), offset, width, height, num_levels)


@dataclass
class SurfaceHits:
    """What each ray hits: world point (…, 3) m, depth = camera-frame z (…) m, plane index (…)
    (−1: nothing, then point and depth are NaN)."""

    points_w: np.ndarray
    depth_m: np.ndarray
    plane_index: np.ndarray


class SceneRenderer:
    """Global-shutter renderer of a :class:`Scene` through a fixed camera.

    The per-sample rays (camera frame, z = 1) and their angular spacing are computed once;
    :meth:`render` then costs one small matmul, a ray–plane test per plane and a trilinear texture
    gather per sample. ``supersampling`` = n gives n×n samples per pixel on a regular sub-grid;
    ``threads`` > 1 renders chunks of samples in parallel (same image).
    """

    def __init__(self, camera: CameraModel, scene: Scene, supersampling: int = 2, threads: int = 1,
                 chunk_samples: int = 16384) -> None:
        if supersampling < 1 or threads < 1 or chunk_samples < 1:
            raise ValueError("SceneRenderer: supersampling, threads and chunk_samples must be >= 1")
        self.threads = int(threads)
        self.chunk_samples = int(chunk_samples)
        self.camera = camera
        self.scene = scene
        self.supersampling = int(supersampling)
        self.width, self.height = int(camera.width), int(camera.height)
        n = self.supersampling
        offsets = (np.arange(n) + 0.5) / n - 0.5  # sub-pixel sample positions within [-½, ½]
        # Sample order (v, sub_v, u, sub_u) so that a reshape to (H, n, W, n) averages pixels.
        v = (np.arange(self.height)[:, None] + offsets[None, :]).reshape(-1)
        u = (np.arange(self.width)[:, None] + offsets[None, :]).reshape(-1)
        uu, vv = np.meshgrid(u, v)
        uv = np.column_stack([uu.ravel(), vv.ravel()])
        rays_c = np.asarray(camera.unproject(uv), dtype=np.float64)  # (N, 3), z = 1
        self._ray_norm = np.linalg.norm(rays_c, axis=1).astype(np.float32)
        self.rays_c = rays_c.astype(np.float32)  # float32 suffices for shading (< 1e-6 m error)
        # Angle between neighbouring samples (geometric mean over u and v): the footprint that
        # picks the mip level. Changes across the image because of the distortion.
        h = 0.5 / n
        d = [np.asarray(camera.unproject(uv + off), dtype=np.float64) for off in
             ([h, 0], [-h, 0], [0, h], [0, -h])]
        d = [di / np.linalg.norm(di, axis=1, keepdims=True) for di in d]
        self._sample_angle_rad = np.sqrt(np.linalg.norm(d[0] - d[1], axis=1)
                                         * np.linalg.norm(d[2] - d[3], axis=1)).astype(np.float32)
        self._atlas = _build_atlas(scene.planes)
        P = len(scene.planes)
        self._origins = np.array([pl.origin_m for pl in scene.planes]).reshape(P, 3)
        # Columns per plane: normal, axis_u, axis_v — one matmul gives every dot product.
        self._axes = np.stack([np.stack([pl.normal, pl.axis_u, pl.axis_v], axis=1) for pl in scene.planes])
        self._sizes = np.array([pl.size_m for pl in scene.planes]).reshape(P, 2)
        self._texels_per_m = np.array([pl.texels_per_m for pl in scene.planes])

    # -- geometry -------------------------------------------------------------------------------
    def _intersect(self, rays_c: np.ndarray, R: np.ndarray, p: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Nearest hit of each ray (z = 1 in the camera frame): plane index k (−1: none), ray
        parameter t (= depth, since ray z = 1), plane coordinates s, w (m), |cos incidence|·|ray|.
        Works in the dtype of ``rays_c`` (float32 for rendering speed, float64 for exact truth)."""
        dtype = rays_c.dtype
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        p = np.asarray(p, dtype=np.float64).reshape(3)
        centre_w = -R.T @ p
        P = len(self.scene.planes)
        # d_w · a = d_c · (R a): dot products with every plane axis straight from the camera rays.
        # Columns grouped [normals | axes_u | axes_v] so each group is a contiguous (N, P) block.
        axes_c = np.einsum("ij,pjk->ikp", R, self._axes).reshape(3, 3 * P).astype(dtype)
        dots = rays_c @ axes_c
        rel = centre_w[None, :] - self._origins      # (P, 3) camera centre relative to plane origins
        rel_dots = np.einsum("pj,pjk->pk", rel, self._axes).astype(dtype)  # (P, [n·rel, u·rel, v·rel])
        return self._nearest(dots, rel_dots[:, 0], rel_dots[:, 1], rel_dots[:, 2])

    def _nearest(self, dots: np.ndarray, rel_n: np.ndarray, rel_u: np.ndarray, rel_v: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The nearest hit from the rays' dot products with the plane axes (N, 3P) and the camera
        centre's plane coordinates (P,) or per ray (N, P)."""
        dtype = dots.dtype
        P = len(self.scene.planes)
        den = dots[:, :P]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.divide(-rel_n, den)
        s = dots[:, P:2 * P] * t
        s += rel_u
        w = dots[:, 2 * P:] * t
        w += rel_v
        tol = _HIT_TOLERANCE_M
        size_u = (self._sizes[:, 0] + tol).astype(dtype)
        size_v = (self._sizes[:, 1] + tol).astype(dtype)
        # Outside the rectangle or behind the camera: push t to +inf (NaN from den = 0 fails t > 0).
        bad = ~(t > 1e-9)
        bad |= s < -tol
        bad |= s > size_u
        bad |= w < -tol
        bad |= w > size_v
        t_masked = t.copy()
        t_masked[bad] = np.inf
        k = np.argmin(t_masked, axis=1)
        rows = np.arange(len(k))
        hit = np.isfinite(t_masked[rows, k])
        k[~hit] = -1
        return k, t[rows, k], s[rows, k], w[rows, k], np.abs(den[rows, k])

    def surface(self, R: np.ndarray, p: np.ndarray, uv: Optional[np.ndarray] = None) -> SurfaceHits:
        """True world point, depth and plane seen at pixels ``uv`` (n, 2) — by default at every pixel
        centre, shaped (H, W, 3) / (H, W). Exact (no supersampling): for tests and benchmarks."""
        if uv is None:
            uu, vv = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
            uv_flat, shape = np.column_stack([uu.ravel(), vv.ravel()]), (self.height, self.width)
        else:
            uv_flat = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
            shape = np.asarray(uv).shape[:-1]
        rays = np.asarray(self.camera.unproject(uv_flat), dtype=np.float64)
        k, t, _, _, _ = self._intersect(rays, R, p)
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        p = np.asarray(p, dtype=np.float64).reshape(3)
        depth = np.where(k >= 0, t, np.nan)
        points_c = rays * depth[:, None]
        points_w = (points_c - p) @ R  # Rᵀ (x_c − p), row-wise
        return SurfaceHits(points_w.reshape(*shape, 3), depth.reshape(shape), k.reshape(shape))

    # -- shading --------------------------------------------------------------------------------
    def _sample_texture(self, k: np.ndarray, s_m: np.ndarray, w_m: np.ndarray, footprint_m: np.ndarray
                        ) -> np.ndarray:
        """Trilinear (mip-mapped) texture values for hits on planes k at plane coordinates (s, w)."""
        a = self._atlas
        tpm = self._texels_per_m[k]
        lod = np.log2(np.maximum(footprint_m * tpm, 1e-12))
        lod = np.clip(lod, 0.0, a.num_levels[k] - 1.0)
        l0 = np.floor(lod).astype(np.int64)
        frac = (lod - l0).astype(np.float32)
        l1 = np.minimum(l0 + 1, a.num_levels[k] - 1)
        return (1.0 - frac) * self._bilinear(k, l0, s_m, w_m, tpm) + frac * self._bilinear(k, l1, s_m, w_m, tpm)

    def _bilinear(self, k: np.ndarray, level: np.ndarray, s_m: np.ndarray, w_m: np.ndarray, tpm: np.ndarray
                  ) -> np.ndarray:
        a = self._atlas
        width, height = a.width[k, level], a.height[k, level]
        scale = tpm / np.exp2(level)
        # Texel centres at (i + ½) / texels-per-m; clamp = edge replicate.
        x = np.clip(s_m * scale - 0.5, 0.0, width - 1.0)
        y = np.clip(w_m * scale - 0.5, 0.0, height - 1.0)
        x0 = np.minimum(np.floor(x).astype(np.int64), width - 2)
        y0 = np.minimum(np.floor(y).astype(np.int64), height - 2)
        fx = (x - x0).astype(np.float32)
        fy = (y - y0).astype(np.float32)
        idx = a.offset[k, level] + y0 * width + x0
        f = a.flat
        top = f[idx] + fx * (f[idx + 1] - f[idx])
        bottom = f[idx + width] + fx * (f[idx + width + 1] - f[idx + width])
        return top + fy * (bottom - top)

    def _intersect_rows(self, rays_c: np.ndarray, R_rows: np.ndarray, p_rows: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_intersect` with one pose per block of rays: ``rays_c`` (B, M, 3), poses (B, 3, 3), (B, 3)."""
        dtype = rays_c.dtype
        B, M, _ = rays_c.shape
        P = len(self.scene.planes)
        centre_w = -np.einsum("bji,bj->bi", R_rows, p_rows)
        axes_c = np.einsum("bij,pjk->bikp", R_rows, self._axes).reshape(B, 3, 3 * P).astype(dtype)
        dots = np.matmul(rays_c, axes_c).reshape(B * M, 3 * P)
        rel = centre_w[:, None, :] - self._origins[None]
        rel_dots = np.repeat(np.einsum("bpj,pjk->bkp", rel, self._axes).astype(dtype), M, axis=0)  # (B M, 3, P)
        return self._nearest(dots, rel_dots[:, 0], rel_dots[:, 1], rel_dots[:, 2])

    def _shade(self, start: int, stop: int, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Texture values of samples start … stop − 1."""
        return self._shade_hits(start, stop, *self._intersect(self.rays_c[start:stop], R, p))

    def _shade_hits(self, start: int, stop: int, k: np.ndarray, t: np.ndarray, s: np.ndarray, w: np.ndarray,
                    cos_abs: np.ndarray) -> np.ndarray:
        values = np.full(len(k), self.scene.background, dtype=np.float32)
        hit = k >= 0
        # Footprint of one sample on the plane: range × angle, stretched by 1/√cos (geometric mean of
        # the foreshortened and the unforeshortened axis).
        norm = self._ray_norm[start:stop][hit]
        range_m = t[hit] * norm
        cos_inc = np.maximum(cos_abs[hit] / norm, 1e-3)
        footprint_m = range_m * self._sample_angle_rad[start:stop][hit] / np.sqrt(cos_inc)
        values[hit] = self._sample_texture(k[hit], s[hit], w[hit], footprint_m)
        return values

    def render(self, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Grey image (H, W) float32 in [0, 1] seen from pose ``x_c = R x_w + p``."""
        N = len(self.rays_c)
        values = np.empty(N, dtype=np.float32)
        # Chunks of samples keep the (samples × planes) temporaries in cache: ~1.5x faster than
        # one pass over the whole image; threads split the chunks (NumPy releases the GIL).
        starts = range(0, N, self.chunk_samples)

        def work(start: int) -> None:
            stop = min(start + self.chunk_samples, N)
            values[start:stop] = self._shade(start, stop, R, p)

        return self._run(work, starts, values)

    def _run(self, work: Callable[[int], None], starts: range, values: np.ndarray) -> np.ndarray:
        """Call ``work`` on every start (in ``threads`` threads), then average ``values`` to pixels."""
        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as pool:
                list(pool.map(work, starts))
        else:
            for start in starts:
                work(start)
        n = self.supersampling
        return values.reshape(self.height, n, self.width, n).mean(axis=(1, 3))

    def render_rows(self, R_rows: np.ndarray, p_rows: np.ndarray) -> np.ndarray:
        """Rolling shutter: grey image (H, W) float32 where pixel row v is seen from its own pose
        ``x_c = R_rows[v] x_w + p_rows[v]`` (all supersamples of the row at the row's time)."""
        R_rows = np.asarray(R_rows, dtype=np.float64).reshape(self.height, 3, 3)
        p_rows = np.asarray(p_rows, dtype=np.float64).reshape(self.height, 3)
        per_row = self.supersampling ** 2 * self.width
        values = np.empty(len(self.rays_c), dtype=np.float32)
        rows_per_call = max(1, self.chunk_samples // per_row)

        def work(row0: int) -> None:
            row1 = min(row0 + rows_per_call, self.height)
            start, stop = row0 * per_row, row1 * per_row
            rays = self.rays_c[start:stop].reshape(row1 - row0, per_row, 3)
            hits = self._intersect_rows(rays, R_rows[row0:row1], p_rows[row0:row1])
            values[start:stop] = self._shade_hits(start, stop, *hits)

        return self._run(work, range(0, self.height, rows_per_call), values)


# --------------------------------------------------------------------------------------------------
# Sequences


@dataclass
class _PosedFrames:
    """Frame times and poses ``x_c = R_cw[i] x_w + p_cw[i]``; the renderer gives per-pixel truth."""

    timestamps_s: np.ndarray
    R_cw: np.ndarray
    p_cw: np.ndarray
    camera: CameraModel
    renderer: SceneRenderer
    trajectory: Trajectory
    fps: float
    seed: int
    noise_sigma: float

    @property
    def camera_centers_w(self) -> np.ndarray:
        return -np.einsum("nji,nj->ni", self.R_cw, self.p_cw)

    def surface(self, frame: int, uv: Optional[np.ndarray] = None) -> SurfaceHits:
        """True world points / depth / plane per pixel of frame ``frame`` (see SceneRenderer.surface)."""
        return self.renderer.surface(self.R_cw[frame], self.p_cw[frame], uv)


@dataclass
class RenderedFrames(_PosedFrames):
    """Frames in memory: ``images`` (F, H, W) uint8, one per timestamp."""

    images: np.ndarray = None


@dataclass
class SceneSequence(_PosedFrames):
    """A rendered sequence on disk (``frame_paths`` in file-name order) and its truth."""

    out_dir: Path = None
    frame_paths: list = None
    truth_path: Path = None
    elapsed_s: float = 0.0


def _setup(num_frames: int, seed: int, camera: Optional[CameraModel], fps: float, t0_s: float,
           scene: Optional[Scene], trajectory: Optional[Trajectory], supersampling: int
           ) -> tuple[CameraModel, SceneRenderer, Trajectory, np.ndarray, np.ndarray, np.ndarray]:
    if num_frames < 1 or not fps > 0:
        raise ValueError("render_scene: num_frames must be >= 1 and fps > 0")
    camera = default_camera() if camera is None else camera
    scene = room_scene(seed) if scene is None else scene
    trajectory = RoomWalkTrajectory(seed=seed) if trajectory is None else trajectory
    renderer = SceneRenderer(camera, scene, supersampling)
    times_s = float(t0_s) + np.arange(int(num_frames)) / float(fps)
    R, p = trajectory.pose_cw(times_s)
    return camera, renderer, trajectory, times_s, np.asarray(R), np.asarray(p)


def _frames(renderer: SceneRenderer, R: np.ndarray, p: np.ndarray, seed: int, noise_sigma: float
            ) -> Iterator[np.ndarray]:
    for i in range(len(R)):
        # Per-frame noise stream: frame i's noise does not depend on how many frames were rendered.
        yield to_uint8(renderer.render(R[i], p[i]), noise_sigma, np.random.default_rng([0x401E, int(seed), i]))


def render_scene_frames(num_frames: int = 30, seed: int = 0, camera: Optional[CameraModel] = None, *,
                        fps: float = 30.0, t0_s: float = 0.0, scene: Optional[Scene] = None,
                        trajectory: Optional[Trajectory] = None, supersampling: int = 2, noise_sigma: float = 0.0
                        ) -> RenderedFrames:
    """Render ``num_frames`` GS frames at ``t0_s + i / fps`` into memory (see module docstring).

    camera:      default :func:`default_camera` (the paper's).
    scene:       default :func:`room_scene` (seed); trajectory: anything with ``pose_cw(t)``,
                 default :class:`RoomWalkTrajectory` (seed).
    noise_sigma: std of Gaussian noise on the 8-bit grey levels (seeded per frame).
    """
    camera, renderer, trajectory, times_s, R, p = _setup(num_frames, seed, camera, fps, t0_s, scene,
                                                         trajectory, supersampling)
    images = np.stack(list(_frames(renderer, R, p, seed, noise_sigma)))
    return RenderedFrames(times_s, R, p, camera, renderer, trajectory, float(fps), int(seed), float(noise_sigma),
                          images=images)


def render_scene_sequence(out_dir: Union[str, Path], num_frames: int = 300, seed: int = 0,
                          camera: Optional[CameraModel] = None, *, fps: float = 30.0, t0_s: float = 0.0,
                          scene: Optional[Scene] = None, trajectory: Optional[Trajectory] = None, supersampling: int = 2,
                          noise_sigma: float = 0.0) -> SceneSequence:
    """Render a sequence to ``out_dir``: ``frame_000000.png`` …, ``timestamps.txt``, ``truth.json``.

    Same arguments as :func:`render_scene_frames`; frames are written as they are rendered.
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    camera, renderer, trajectory, times_s, R, p = _setup(num_frames, seed, camera, fps, t0_s, scene,
                                                         trajectory, supersampling)
    paths = []
    for i, img in enumerate(_frames(renderer, R, p, seed, noise_sigma)):
        path = out_dir / f"frame_{i:06d}.png"
        if not cv2.imwrite(str(path), img):
            raise OSError(f"could not write {path}")
        paths.append(path)
    (out_dir / "timestamps.txt").write_text("".join(f"{t:.9f}\n" for t in times_s))

    centres = -np.einsum("nji,nj->ni", R, p)
    describe = getattr(trajectory, "describe", None)
    truth = {
        "generator": "rscalib.sim.scene_video",
        "conventions": "docs/conventions.md: x_c = R x_w + p, camera centre = -R^T p; OpenCV pixels; "
                       "global shutter (every pixel at the frame time)",
        "camera": {"model": camera.model, "params": np.asarray(camera.params).tolist(),
                   "param_names": list(camera.param_names), "width": int(camera.width),
                   "height": int(camera.height),
                   "pixel_size_mm": np.asarray(camera.pixel_size_mm).tolist()},
        "fps": float(fps), "seed": int(seed), "num_frames": int(num_frames), "t0_s": float(t0_s),
        "supersampling": renderer.supersampling, "noise_sigma": float(noise_sigma),
        "shutter": "global",
        "scene": renderer.scene.describe(),
        "trajectory_model": describe() if callable(describe) else type(trajectory).__name__,
        "frames": [{"file": path.name, "t_s": float(t), "R": Ri.tolist(), "p": pi.tolist(), "center_w": ci.tolist()}
                   for path, t, Ri, pi, ci in zip(paths, times_s, R, p, centres)],
    }
    truth_path = out_dir / "truth.json"
    truth_path.write_text(json.dumps(truth, indent=1))
    return SceneSequence(times_s, R, p, camera, renderer, trajectory, float(fps), int(seed), float(noise_sigma),
                         out_dir=out_dir, frame_paths=paths, truth_path=truth_path,
                         elapsed_s=time.perf_counter() - start)


def load_scene_truth(out_dir: Union[str, Path]) -> dict:
    """``truth.json`` of a rendered sequence with the per-frame arrays stacked: adds ``t_s`` (F,),
    ``R_cw`` (F, 3, 3), ``p_cw`` (F, 3), ``center_w`` (F, 3) and a ``camera_model`` (CameraModel)."""
    truth = json.loads((Path(out_dir) / "truth.json").read_text())
    frames = truth["frames"]
    truth["t_s"] = np.array([f["t_s"] for f in frames])
    truth["R_cw"] = np.array([f["R"] for f in frames]).reshape(-1, 3, 3)
    truth["p_cw"] = np.array([f["p"] for f in frames]).reshape(-1, 3)
    truth["center_w"] = np.array([f["center_w"] for f in frames]).reshape(-1, 3)
    cam = truth["camera"]
    kwargs = {"pixel_size_mm": tuple(cam["pixel_size_mm"])} if cam["model"] == "civera-radial" else {}
    truth["camera_model"] = CameraModel(cam["model"], cam["params"], cam["width"], cam["height"], **kwargs)
    return truth
