"""Feature-level simulation for the SOG self-calibration filter (no images).

A civera-radial camera (default: the paper's 320x240 camera) moves hand-held (smooth, global shutter)
inside a room whose walls, floor and ceiling carry random 3-D points. Every frame gives the noisy
distorted pixels of the visible points with their true ids, plus the true trajectory.
:class:`TrueCorrespondences` plays the role of the image front end in the self-calibration loop (it
knows the true correspondences) so the filter can be tested and benchmarked in isolation. docs/sog.md §11.

Conventions (docs/conventions.md): OpenCV pixels; camera x right, y down, z forward;
``x_c = R_cw x_w + p_cw``. The filter's world is the first camera frame; :meth:`SogSequence.truth_in_first_camera`
expresses the truth there. The projection here is a NumPy reference implementation of the
civera-radial model (Civera et al. 2009, eq. 9–13; docs/formulation.md §10: Newton on the radial
polynomial), independent of the C++ core.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from ..reference_cameras import PAPER_CAMERA_PARAMS, PAPER_IMAGE_SIZE, PAPER_PIXEL_SIZE_MM
from .trajectories import HandheldRoomMotion

__all__ = [
    "CiveraCamera",
    "PAPER_CAMERA",
    "HandheldRoomMotion",
    "SogSequence",
    "room_points",
    "simulate_sequence",
    "TrueCorrespondences",
]


# --------------------------------------------------------------------------------------------------
# Camera


@dataclass(frozen=True)
class CiveraCamera:
    """civera-radial camera: ``[f, cx, cy, k1 (mm^-2), k2 (mm^-4)]``, image size, pixel size (mm)."""

    f: float = PAPER_CAMERA_PARAMS[0]
    cx: float = PAPER_CAMERA_PARAMS[1]
    cy: float = PAPER_CAMERA_PARAMS[2]
    k1: float = PAPER_CAMERA_PARAMS[3]
    k2: float = PAPER_CAMERA_PARAMS[4]
    width: int = PAPER_IMAGE_SIZE[0]
    height: int = PAPER_IMAGE_SIZE[1]
    pixel_size_mm: float = PAPER_PIXEL_SIZE_MM

    @property
    def params(self) -> np.ndarray:
        return np.array([self.f, self.cx, self.cy, self.k1, self.k2], dtype=np.float64)

    def undistort(self, uv_d: np.ndarray) -> np.ndarray:
        """Distorted -> undistorted pixels (closed form)."""
        d = np.asarray(uv_d, dtype=np.float64).reshape(-1, 2) - [self.cx, self.cy]
        rd2 = np.sum((self.pixel_size_mm * d) ** 2, axis=1, keepdims=True)
        return [self.cx, self.cy] + d * (1.0 + self.k1 * rd2 + self.k2 * rd2 ** 2)

    def project(self, points_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame points (n, 3) -> distorted pixels (n, 2) and a validity mask (n,).

        Invalid: behind the camera, or the radial polynomial not invertible there.
        """
        x = np.asarray(points_c, dtype=np.float64).reshape(-1, 3)
        front = x[:, 2] > 1e-9
        z = np.where(front, x[:, 2], 1.0)
        off_u = self.f * x[:, :2] / z[:, None]
        ru = self.pixel_size_mm * np.linalg.norm(off_u, axis=1)
        # Newton on g(r) = r (1 + k1 r^2 + k2 r^4) - ru from r = ru (from above for k1, k2 >= 0).
        rd = ru.copy()
        for _ in range(60):
            r2 = rd * rd
            g = rd * (1.0 + r2 * (self.k1 + self.k2 * r2)) - ru
            dg = 1.0 + r2 * (3.0 * self.k1 + 5.0 * self.k2 * r2)
            rd = rd - g / np.where(dg > 0, dg, 1.0)
        r2 = rd * rd
        g = rd * (1.0 + r2 * (self.k1 + self.k2 * r2)) - ru
        dg = 1.0 + r2 * (3.0 * self.k1 + 5.0 * self.k2 * r2)
        ok = front & (np.abs(g) <= 1e-12 * np.maximum(1.0, ru)) & (dg > 0) & (rd >= 0)
        scale = np.where(ru > 1e-300, rd / np.where(ru > 1e-300, ru, 1.0), 1.0)
        uv = np.array([self.cx, self.cy]) + off_u * scale[:, None]
        return uv, ok


PAPER_CAMERA = CiveraCamera()


# --------------------------------------------------------------------------------------------------
# Scene (the motion, HandheldRoomMotion, is in sim/trajectories.py)


def room_points(size_m: Sequence[float] = (6.0, 2.7, 6.0), center_m: Sequence[float] = (0.0, -0.1, 0.5),
                density_per_m2: float = 40.0, seed: int = 0) -> np.ndarray:
    """Random points on the six faces of a box room (world frame, y down), uniform per area.

    size_m: extent along x, y, z; center_m: the room's centre. Returns (P, 3) float64.
    """
    rng = np.random.default_rng([0x50C, int(seed)])
    size = np.asarray(size_m, dtype=np.float64)
    center = np.asarray(center_m, dtype=np.float64)
    pts = []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        count = int(round(density_per_m2 * size[a] * size[b]))
        for side in (-0.5, 0.5):
            p = np.empty((count, 3))
            p[:, axis] = side * size[axis]
            p[:, a] = rng.uniform(-0.5, 0.5, count) * size[a]
            p[:, b] = rng.uniform(-0.5, 0.5, count) * size[b]
            pts.append(p + center)
    return np.concatenate(pts)


# --------------------------------------------------------------------------------------------------
# Sequence


@dataclass
class SogSequence:
    """Per-frame measurements and the truth that produced them.

    ids[k] (m_k,) ids of the points visible in frame k (rows of ``points_w``); uv[k] (m_k, 2) their
    noisy distorted pixels; uv_true[k] the noise-free ones. Truth per frame: ``R_wc`` (F, 3, 3),
    ``r_w`` (F, 3) camera centre, ``v_w`` (F, 3), ``omega_c`` (F, 3) angular velocity in the camera.
    """

    camera: CiveraCamera
    times_s: np.ndarray
    points_w: np.ndarray
    ids: list
    uv: list
    uv_true: list
    R_wc: np.ndarray
    r_w: np.ndarray
    v_w: np.ndarray
    omega_c: np.ndarray
    noise_px: float

    def __len__(self) -> int:
        return len(self.times_s)

    @property
    def R_cw(self) -> np.ndarray:
        return np.transpose(self.R_wc, (0, 2, 1))

    @property
    def p_cw(self) -> np.ndarray:
        """Translation of ``x_c = R_cw x_w + p_cw`` (docs/conventions.md)."""
        return -np.einsum("nij,nj->ni", self.R_cw, self.r_w)

    def truth_in_first_camera(self) -> dict:
        """Truth in the filter's world (the first camera frame): ``r`` (F, 3), ``q_wc`` (F, 4, w
        first), ``R_wc`` (F, 3, 3), ``v`` (F, 3), ``omega_c`` (F, 3), ``points`` (P, 3), and the
        13-D motion states ``motion`` (F, 13) = [r, q, v, w] as the filter stores them."""
        R0 = self.R_wc[0]
        r = np.einsum("ji,nj->ni", R0, self.r_w - self.r_w[0])
        R = np.einsum("ji,njk->nik", R0, self.R_wc)
        v = np.einsum("ji,nj->ni", R0, self.v_w)
        xyzw = Rotation.from_matrix(R).as_quat()
        q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
        q *= np.where(q[:, :1] < 0, -1.0, 1.0)
        points = (self.points_w - self.r_w[0]) @ R0
        motion = np.concatenate([r, q, v, self.omega_c], axis=1)
        return {"r": r, "q_wc": q, "R_wc": R, "v": v, "omega_c": self.omega_c.copy(),
                "points": points, "motion": motion}


def simulate_sequence(camera: CiveraCamera = PAPER_CAMERA, duration_s: float = 8.0, fps: float = 30.0,
                      noise_px: float = 0.5, seed: int = 0, points_w: Optional[np.ndarray] = None,
                      motion: Optional[Any] = None, border_px: float = 4.0,
                      min_depth_m: float = 0.2) -> SogSequence:
    """Simulate ``floor(duration_s * fps)`` frames at ``t_k = k / fps``.

    points_w: scene (P, 3); default :func:`room_points` (seeded). motion: anything with
    ``pose_wc(t)`` and ``velocities(t)``; default :class:`HandheldRoomMotion` (seeded).
    A point is visible when in front (depth > min_depth_m) and its true and noisy pixels lie at
    least ``border_px`` inside the image. Noise: independent N(0, noise_px^2) on u and v.
    """
    if not fps > 0 or not duration_s > 0:
        raise ValueError("simulate_sequence: fps and duration_s must be > 0")
    if points_w is None:
        points_w = room_points(seed=seed)
    points_w = np.asarray(points_w, dtype=np.float64).reshape(-1, 3)
    if motion is None:
        motion = HandheldRoomMotion(seed=seed)
    n = int(np.floor(duration_s * fps + 1e-9))
    t = np.arange(n) / fps
    R_wc, r_w = motion.pose_wc(t)
    v_w, omega_c = motion.velocities(t)
    rng = np.random.default_rng([0x5EED, int(seed)])
    lo = border_px
    hi = np.array([camera.width - 1 - border_px, camera.height - 1 - border_px])
    ids, uvs, uvs_true = [], [], []
    for k in range(n):
        pc = (points_w - r_w[k]) @ R_wc[k]  # R_cw (X - r)
        front = pc[:, 2] > min_depth_m
        uv_true, ok = camera.project(np.where(front[:, None], pc, [0.0, 0.0, 1.0]))
        noisy = uv_true + rng.normal(0.0, noise_px, size=uv_true.shape) if noise_px > 0 else uv_true.copy()
        inside = lambda uv: np.all((uv >= lo) & (uv <= hi), axis=1)  # noqa: E731
        keep = np.flatnonzero(front & ok & inside(uv_true) & inside(noisy))
        ids.append(keep)
        uvs.append(noisy[keep])
        uvs_true.append(uv_true[keep])
    return SogSequence(camera=camera, times_s=t, points_w=points_w, ids=ids, uv=uvs, uv_true=uvs_true,
                       R_wc=R_wc, r_w=r_w, v_w=v_w, omega_c=omega_c, noise_px=float(noise_px))


# --------------------------------------------------------------------------------------------------
# The front end's role, with known correspondences


class TrueCorrespondences:
    """The measurement source of the self-calibration loop (``rscalib.selfcalib.driver.run_bank``) for a
    simulated sequence: frames are frame indices (:meth:`frames`), and each feature is identified
    with the scene point it started on.

    measure: a predicted feature is found when its point is visible in the frame, at the point's
    noisy pixel (the bank's gate plays the search ellipse). new_features: visible points not yet in
    the map, in a seeded random order, at least ``min_separation_px`` from each other and from the
    predicted features still in the map. ``feature_to_point`` maps bank feature ids to rows of
    ``sequence.points_w``.
    """

    def __init__(self, sequence: SogSequence, *, min_separation_px: float = 20.0, seed: int = 0) -> None:
        self.sequence = sequence
        self.min_separation_px = float(min_separation_px)
        self.feature_to_point: dict[int, int] = {}
        self._mapped_points: set[int] = set()
        self._rng = np.random.default_rng([0xF00D, int(seed)])
        self._started: np.ndarray = np.zeros(0, dtype=np.int64)

    def frames(self) -> list[tuple[float, int]]:
        """(time s, frame index) of every frame."""
        return [(float(t), k) for k, t in enumerate(self.sequence.times_s)]

    def measure(self, frame: int, ids: np.ndarray, uv_pred: np.ndarray,
                cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        row_of = {int(p): i for i, p in enumerate(self.sequence.ids[frame])}
        uv = np.full((len(ids), 2), np.nan)
        found = np.zeros(len(ids), dtype=bool)
        for i, fid in enumerate(ids):
            row = row_of.get(self.feature_to_point.get(int(fid), -1))
            if row is not None:
                uv[i] = self.sequence.uv[frame][row]
                found[i] = True
        return uv, found

    def forget(self, feature_ids: np.ndarray) -> None:
        for fid in feature_ids:
            self._mapped_points.discard(self.feature_to_point.pop(int(fid)))

    def new_features(self, frame: int, count: int, search: Any) -> np.ndarray:
        """``search``: the frame's active search (``ids``, ``uv_pred`` of the predicted features)."""
        frame_ids, frame_uv = self.sequence.ids[frame], self.sequence.uv[frame]
        taken = [search.uv_pred[i] for i in range(len(search.ids)) if int(search.ids[i]) in self.feature_to_point]
        candidates = [i for i in self._rng.permutation(len(frame_ids)) if int(frame_ids[i]) not in self._mapped_points]
        chosen = []
        for i in candidates:
            if len(chosen) >= count:
                break
            p = frame_uv[i]
            if all(np.hypot(*(p - q)) >= self.min_separation_px for q in taken):
                chosen.append(i)
                taken.append(p)
        self._started = frame_ids[chosen]
        return frame_uv[chosen]

    def track(self, frame: int, feature_ids: np.ndarray, uv: np.ndarray) -> None:
        for fid, point in zip(feature_ids, self._started):
            self.feature_to_point[int(fid)] = int(point)
            self._mapped_points.add(int(point))
