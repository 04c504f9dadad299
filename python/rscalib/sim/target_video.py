"""Rolling-shutter video renderer: image rows drawn at their own exposure times.

Every output pixel ``(u, v)`` of the frame stamped ``t_i`` is rendered by inverse mapping at the
row time ``t = t_i + v * d`` (docs/conventions.md): the pixel is unprojected through the camera
(lens distortion included) to a ray, the ray is intersected with the target plane z = 0 using the
pose ``T_cw(t)`` (world point ``X = Rᵀ(λ ray − p)``), and the target's texture
(:class:`rscalib.sim.target_texture.TargetTexture`) is sampled there. Anti-aliasing: each pixel is
the mean of ``supersample²`` sub-pixel samples, each with the row time of its own sub-row, and each
sample box-filters the texture over its own footprint on the target. Motion blur: the mean over
``exposure_samples`` times spread over ``[t, t + exposure_s]`` (a row's exposure *starts* at its row
time). Noise: Gaussian on the 8-bit intensities.

The corners of a rendered frame therefore sit at the exact rolling-shutter projection
``v = v_proj(T_cw(t_i + v d) P)`` of the target points, which is what ``truth.json`` records
(computed with :func:`rscalib.sim.target_observations.rs_projection`, independent of this renderer).

Targets are :class:`rscalib.io.targets.Target` (world = target frame, docs/conventions.md); the
default trajectory is :func:`rscalib.sim.trajectories.target_trajectory` (for Kalibr's AprilGrid,
seen from its printed z > 0 side).
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
from ..io.cameras import opencv_matrices, write_opencv_yaml
from ..io.targets import Target
from .target_observations import default_camera, rs_projection
from .target_texture import TargetTexture, texture_of
from .trajectories import ShiftedTrajectory, Trajectory, target_trajectory, trajectory_from_description

__all__ = [
    "RenderedVideo",
    "RollingShutterRenderer",
    "load_truth",
    "render_video",
    "to_uint8",
    "trajectory_from_truth",
    "truth_uv",
]

# Frame i of the video is stamped i / fps (row 0 starts exposure then).
VIDEO_NAME = "video.avi"
MAX_EXPOSURE_SAMPLES = 64


# --------------------------------------------------------------------------------------------------
# Renderer


class RollingShutterRenderer:
    """Renders frames of a rolling-shutter camera moving along ``trajectory`` in front of ``target``.

    camera:            rscalib.CameraModel (its unprojection maps every sub-pixel to a ray, once).
    target:            a Target (drawn by its default TargetTexture), a TargetTexture, a built-in
                       target name or a target YAML path.
    trajectory:        a :class:`~rscalib.sim.trajectories.Trajectory` (``pose_cw(t) -> (R (n,3,3),
                       p (n,3))``, vectorised over t).
    line_delay_s:      d; row v (continuous, px) starts exposure at t_i + v d.
    supersample:       n × n sub-pixel samples per pixel, each at its own sub-row time.
    exposure_s:        exposure per row; 0 = instantaneous.
    exposure_samples:  times per sub-pixel over the exposure (midpoints of equal slices); None =
                       enough that the target points move ≤ ½ px between them (per frame, ≤ 64).
    intensity_modulation: optional f(t_s) -> gain (array in, array out), multiplying the scene
                       radiance at each sample time: the hook for a flickering light.
    workers:           threads over row blocks (numpy releases the GIL); default min(4, cpus).
    """

    def __init__(self, camera: CameraModel, target: Union[Target, TargetTexture, str, Path], trajectory: Trajectory,
                 line_delay_s: float,
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
        self.texture = texture_of(target)
        self.target = self.texture.target
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
        self._points = self.target.points_m
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
        shifted = ShiftedTrajectory(self.trajectory, time_offset_s)
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
            return self.texture.albedo(x, y, wx, wy)


def _abs_diff(a: np.ndarray, axis: int) -> np.ndarray:
    """|forward difference| along axis, the last entry repeated (same shape as a)."""
    d = np.abs(np.diff(a, axis=axis))
    if a.shape[axis] < 2:
        return np.zeros_like(a)
    last = d[-1:] if axis == 0 else d[:, -1:]
    return np.concatenate([d, last], axis=axis)


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
    target: Target
    trajectory: Trajectory
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
        return truth_uv(self.truth, "uv_rs")

    def uv_gs(self) -> np.ndarray:
        """(frames, points, 2) global-shutter projections (every row at t_i)."""
        return truth_uv(self.truth, "uv_gs")


def truth_uv(truth: dict, which: str = "uv_rs") -> np.ndarray:
    """(frames, points, 2) projections recorded in a truth.json (NaN where not visible): ``uv_rs``
    (exact rolling shutter), ``uv_gs`` (every row at t_i) or ``uv_rs_mid_exposure``."""
    nested = truth["projections"][which]
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
                 target: Union[str, Path, Target, TargetTexture] = "checkerboard", duration_s: float = 5.0,
                 exposure_s: float = 0.0, noise: float = 2.0, seed: int = 0, *,
                 camera: Optional[CameraModel] = None, trajectory: Optional[Trajectory] = None, motion: float = 1.0,
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
        (:func:`~rscalib.sim.target_observations.default_camera`); ignored when ``camera`` is given.
        target: built-in name (:meth:`Target.named`), Kalibr YAML path, Target or TargetTexture. exposure_s: per-row
        exposure (motion blur), ≤ 1/fps. noise: σ of Gaussian intensity noise in 8-bit grey levels.
        seed: the default trajectory and the noise. motion: amplitude of the default hand-held
        trajectory. trajectory: anything with a vectorised ``pose_cw(t)``, overriding the default.
        intensity_modulation: f(t) -> gain on the scene radiance (flicker hook).
        flicker_hz, flicker_depth, flicker_phase_rad: a light flickering as gain
        1 + depth·sin(2π f t + phase) (instead of intensity_modulation); recorded in truth.json.
        supersample, exposure_samples, workers: see :class:`RollingShutterRenderer`.
    """
    _check_render_arguments(fps, duration_s, line_delay_s, exposure_s, noise, motion)
    flicker, intensity_modulation = _flicker(flicker_hz, flicker_depth, flicker_phase_rad, intensity_modulation)
    if camera is None:
        camera = default_camera(_parse_size(size))
    if abs(line_delay_s) * camera.height > 1.0 / fps:
        raise InputError(f"readout time {abs(line_delay_s) * camera.height * 1e3:.3g} ms (line delay x "
                         f"{camera.height} rows) exceeds the frame period {1e3 / fps:.3g} ms")
    texture = texture_of(target)
    target = texture.target
    num_frames = int(math.floor(duration_s * fps + 1e-9))
    if num_frames < 1:
        raise InputError(f"duration {duration_s} s at {fps} fps gives no frame")
    if trajectory is None:
        trajectory = target_trajectory(camera, target, duration_s, seed, motion)

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
    renderer = RollingShutterRenderer(camera, texture, trajectory, line_delay_s, supersample=supersample,
                                      exposure_s=exposure_s, exposure_samples=exposure_samples,
                                      intensity_modulation=intensity_modulation, workers=workers)
    try:
        uv_rs, uv_gs, uv_mid, render_seconds = _render_frames(renderer, frame_times, noise, rng, writer, frames_dir,
                                                              line_delay_s, exposure_s, progress)
    finally:
        renderer.close()
        if writer is not None:
            writer.release()
    if frames_dir is not None:
        (frames_dir / "timestamps.txt").write_text("".join(f"{t:.9f}\n" for t in frame_times))

    camera_path = out_dir / "camera.yaml"
    write_opencv_yaml(camera, camera_path, line_delay_s=line_delay_s)
    target_path = out_dir / "target.yaml"
    target_path.write_text(yaml.safe_dump(target.kalibr_dict(), sort_keys=False))

    truth = _truth(camera, texture, trajectory, frame_times, uv_rs, uv_gs, uv_mid, line_delay_s=line_delay_s, fps=fps,
                   duration_s=duration_s, noise=noise, exposure_s=exposure_s, exposure_samples=exposure_samples,
                   supersample=supersample, seed=seed, motion=motion, intensity_modulation=intensity_modulation,
                   flicker=flicker, video_path=video_path, used_codec=used_codec, frames_dir=frames_dir,
                   dense_rate_hz=dense_rate_hz)
    truth_path = out_dir / "truth.json"
    truth_path.write_text(_compact_json(truth))
    return RenderedVideo(out_dir=out_dir, video_path=video_path, frames_dir=frames_dir, truth_path=truth_path,
                         camera_path=camera_path, target_path=target_path, camera=camera, target=target,
                         trajectory=trajectory, line_delay_s=float(line_delay_s), fps=float(fps),
                         frame_times_s=frame_times, truth=truth, render_seconds=render_seconds, codec=used_codec)


def _check_render_arguments(fps: float, duration_s: float, line_delay_s: float, exposure_s: float, noise: float,
                            motion: float) -> None:
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


def _flicker(flicker_hz: Optional[float], depth: float, phase_rad: float,
             intensity_modulation: Optional[Callable[[np.ndarray], np.ndarray]]) -> tuple[Optional[dict], Optional[Callable]]:
    """(truth.json's "flicker", the gain f(t) on the radiance): a flickering light's, else the given
    modulation unchanged (flicker None)."""
    if flicker_hz is None:
        return None, intensity_modulation
    if intensity_modulation is not None:
        raise InputError("give a flicker frequency or an intensity modulation, not both")
    if not (math.isfinite(flicker_hz) and flicker_hz > 0):
        raise InputError(f"flicker frequency must be positive (got {flicker_hz})")
    if not (math.isfinite(depth) and 0 <= depth < 1):
        raise InputError(f"flicker depth must be in [0, 1) (got {depth})")
    if not math.isfinite(phase_rad):
        raise InputError("flicker phase must be finite")
    flicker = {"frequency_hz": float(flicker_hz), "depth": float(depth), "phase_rad": float(phase_rad),
               "gain": "1 + depth * sin(2 pi frequency_hz t + phase_rad), t = row time (s); "
                       "radiance above full scale clips"}

    def flicker_gain(t: np.ndarray) -> np.ndarray:
        return 1.0 + depth * np.sin(2.0 * np.pi * flicker_hz * t + phase_rad)
    return flicker, flicker_gain


def _render_frames(renderer: RollingShutterRenderer, frame_times: np.ndarray, noise: float, rng, writer,
                   frames_dir: Optional[Path], line_delay_s: float, exposure_s: float,
                   progress: bool) -> tuple[list, list, list, float]:
    """Every frame rendered and written, with its true projections: (uv_rs, uv_gs, uv_mid, seconds)."""
    uv_rs, uv_gs, uv_mid = [], [], []
    render_started = time.perf_counter()
    camera = renderer.camera
    with Progress(progress, len(frame_times), f"rendering {camera.width}x{camera.height}") as bar:
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
    return uv_rs, uv_gs, uv_mid, time.perf_counter() - render_started


def _truth(camera: CameraModel, texture: TargetTexture, trajectory: Trajectory, frame_times: np.ndarray, uv_rs: list,
           uv_gs: list, uv_mid: list, *, line_delay_s: float, fps: float, duration_s: float, noise: float,
           exposure_s: float, exposure_samples: Optional[int], supersample: int, seed: int, motion: float,
           intensity_modulation: Optional[Callable], flicker: Optional[dict], video_path: Optional[Path],
           used_codec: str, frames_dir: Optional[Path], dense_rate_hz: float) -> dict:
    """truth.json of a rendered video: what was rendered, its trajectory and the exact projections."""
    target = texture.target
    readout_end = abs(line_delay_s) * camera.height + exposure_s
    dense_times = np.arange(0.0, frame_times[-1] + readout_end + 1.0 / dense_rate_hz, 1.0 / dense_rate_hz)
    projections = {"uv_rs": uv_rs, "uv_gs": uv_gs,
                   "definition": "uv_rs: exact rolling-shutter projection, v = v_proj(T_cw(t_i + v d) P) "
                                 "(start of the row's exposure); uv_gs: every row at t_i; null = not visible"}
    if exposure_s > 0:
        projections["uv_rs_mid_exposure"] = uv_mid
        projections["definition"] += "; uv_rs_mid_exposure: at t_i + v d + exposure/2 (blur centroid)"
    return {
        "generator": "rscalib.sim.target_video",
        "line_delay_s": float(line_delay_s),
        "readout_time_s": float(line_delay_s) * camera.height,
        "fps": float(fps),
        "duration_s": float(duration_s),
        "num_frames": len(frame_times),
        "frame_times_s": [float(t) for t in frame_times],
        "image_size": [int(camera.width), int(camera.height)],
        "camera": {"model": camera.model, "params": [float(v) for v in camera.params],
                   "width": int(camera.width), "height": int(camera.height)},
        "target": texture.describe(),
        "target_points_m": target.points_m.tolist(),
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
        "trajectory": _describe(trajectory),
        "poses_at_frames": _pose_samples(trajectory, frame_times),
        "poses_dense": dict(_pose_samples(trajectory, dense_times), rate_hz=float(dense_rate_hz)),
        "projections": projections,
        "conventions": "docs/conventions.md: x_c = R x_w + p, rotation_vector = log(R); OpenCV pixels",
    }


def _describe(trajectory: Trajectory) -> dict:
    """truth.json's "trajectory": its own description (enough to rebuild a default one)."""
    describe = getattr(trajectory, "describe", None)
    return describe() if callable(describe) else {"type": type(trajectory).__name__}


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


def trajectory_from_truth(truth: dict) -> Trajectory:
    """Rebuild the analytic trajectory recorded in a truth.json (default trajectories only)."""
    try:
        return trajectory_from_description(truth.get("trajectory", {}))
    except InputError as error:
        raise InputError(f"truth.json: {error}") from None
