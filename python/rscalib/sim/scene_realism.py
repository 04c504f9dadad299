"""A realistic mode of the textured-room renderer: what a phone does to a self-calibration walk.

The clean renderer (:mod:`rscalib.sim.scene_video`) draws a global-shutter camera over procedural
textures with Gaussian noise and lossless PNGs: engine 2's best case. This module renders the same
rooms the way a hand-held phone records them (issue 11), reusing the phone model of the target-video
realism (:mod:`rscalib.sim.realism`: capture times, sensor noise, H.264):

- **photographic textures**: every wall, floor and ceiling is a mosaic of tiles cut from real frames
  (the stills and the phone video in ``../shared/data/`` beside the repository, or
  ``$RSCALIB_SHARED_DATA``) — real texture, repeated patterns (chessboards), blur and compression
  artefacts of the originals. Read at render time, never copied; when the folder is absent the
  procedural texture is used and ``truth.json`` says so;
- **rolling shutter**: pixel row ``v`` is exposed from ``t + v · line_delay`` (default 30 µs/row at
  640×480, i.e. a 14.4 ms readout at any height);
- **motion blur**: each row is the mean of ``exposure_samples`` renders spread over the exposure;
- **auto-exposure**: a slow gain drift and one or two smooth steps (saturation clips);
- **sensor noise and vignetting** (read + shot noise of :func:`rscalib.sim.realism.sensor_image`,
  cos⁴ fall-off scaled to ``vignetting`` at the corner);
- **variable frame timing**: jitter, dropped frames and timestamp noise
  (:func:`rscalib.sim.realism.capture_times`); ``timestamps.txt`` has the recorded times;
- **H.264 at phone bitrates** (:func:`rscalib.sim.realism.encode_decode`; OpenCV MPEG-4 when no
  ffmpeg binary is available — recorded in ``truth.json``);
- three **motion styles** (:data:`MOTION_STYLES`): ``walk-forward``, ``look-around`` (mostly rotation)
  and ``sideways-dolly`` (mostly sideways translation in front of a wall: f weakly observable).

Cameras: 320×240 is the paper's (``scene_video.default_camera``); 640×480 is a phone's — the S3
phone of ``real_selfcalib_s3phone`` (f 525.06 px, c (308.65, 236.54), k1 −7.613e-3 mm⁻²,
k2 9.388e-4 mm⁻⁴, 0.0070216 mm pixels), in the paper's Civera model.
"""
from __future__ import annotations

import functools
import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional, Union

import cv2
import numpy as np

from .._core import CameraModel
from ..errors import InputError
from ..reference_cameras import PHONE_CAMERA_PARAMS, PHONE_PIXEL_SIZE_MM
from .realism import RealismOptions, capture_times, encode_decode, sensor_image
from .scene_video import SceneRenderer, default_camera, procedural_texture, room_scene
from .trajectories import RoomWalkTrajectory

__all__ = ["MOTION_STYLES", "PHONE_CAMERA_PARAMS", "PHONE_PIXEL_SIZE_MM", "ROOM_SIZE_M", "PhotoTiles",
           "RealisticScene", "SceneRealism", "StyledRoomMotion", "auto_exposure_gains", "camera_for_size",
           "photo_tiles", "render_realistic_scene", "shared_data_dir"]

MOTION_STYLES = ("walk-forward", "look-around", "sideways-dolly")
ROOM_SIZE_M = (7.0, 4.0, 2.6)  # long enough to walk 4 m towards a wall
SHARED_DATA_ENV = "RSCALIB_SHARED_DATA"
_VIDEO_FRAME_STEP = 40  # frames of the phone video used as photographs
# Tiles per source folder: half natural desk texture, half calibration targets (repeated patterns).
_FOLDER_WEIGHTS = {"real_selfcalib_s3phone": 0.5, "opencv_stereo_chessboard": 0.2, "aprilgrid_real_frames": 0.15,
                   "kalibr_test_targets": 0.15}


def camera_for_size(width: int, height: int) -> CameraModel:
    """320×240: the paper's camera; 640×480: the S3 phone's (module docstring)."""
    if (width, height) == (320, 240):
        return default_camera()
    if (width, height) == (640, 480):
        return CameraModel("civera-radial", list(PHONE_CAMERA_PARAMS), 640, 480,
                           pixel_size_mm=(PHONE_PIXEL_SIZE_MM, PHONE_PIXEL_SIZE_MM))
    raise InputError(f"no realistic camera for {width}x{height} (320x240 or 640x480)")


# --------------------------------------------------------------------------------------------------
# Photographic textures


def shared_data_dir() -> Optional[Path]:
    """``$RSCALIB_SHARED_DATA`` if set, else ``../shared/data`` beside the repository; None when absent."""
    env = os.environ.get(SHARED_DATA_ENV)
    path = Path(env) if env else Path(__file__).resolve().parents[3].parent / "shared" / "data"
    return path if path.is_dir() else None


@functools.lru_cache(maxsize=4)
def _photographs(data_dir: str) -> tuple[tuple[str, np.ndarray], ...]:
    """(name, grey float32 image in [0, 1]) of every still and of every 40th frame of every video."""
    root = Path(data_dir)
    found = []
    for folder in ("opencv_stereo_chessboard", "aprilgrid_real_frames", "kalibr_test_targets",
                   "real_selfcalib_s3phone"):
        for path in sorted((root / folder).glob("*")):
            suffix = path.suffix.lower()
            if suffix in (".jpg", ".jpeg", ".png"):
                image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
                if image is not None:
                    found.append((f"{folder}/{path.name}", image.astype(np.float32) / 255.0))
            elif suffix in (".mp4", ".mov", ".avi"):
                capture = cv2.VideoCapture(str(path))
                index = 0
                while True:
                    ok, image = capture.read()
                    if not ok:
                        break
                    if index % _VIDEO_FRAME_STEP == 0:
                        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
                        found.append((f"{folder}/{path.name}#{index}", grey.astype(np.float32) / 255.0))
                    index += 1
                capture.release()
    return tuple(found)


@dataclass
class PhotoTiles:
    """Plane textures cut from photographs: a grid of square tiles, each a random crop of a random
    photograph (half of them frames of the phone's desk video, half calibration targets) (random scale 0.6–1.4, flips, quarter turns, contrast and brightness), ``tile_m``
    metres on a side."""

    photographs: tuple
    tile_m: tuple[float, float] = (0.35, 0.8)

    def _pick(self, rng: np.random.Generator) -> np.ndarray:
        """A photograph: its folder first (weights :data:`_FOLDER_WEIGHTS`), then one of the folder's."""
        folders = sorted({name.split("/")[0] for name, _ in self.photographs})
        weights = np.array([_FOLDER_WEIGHTS.get(f, 0.15) for f in folders])
        folder = folders[rng.choice(len(folders), p=weights / weights.sum())]
        mine = [image for name, image in self.photographs if name.split("/")[0] == folder]
        return mine[rng.integers(len(mine))]

    def __call__(self, width_m: float, height_m: float, seed: int, texels_per_m: float) -> np.ndarray:
        rng = np.random.default_rng([0x9407, int(seed)])
        w_tx = max(2, int(round(width_m * texels_per_m)))
        h_tx = max(2, int(round(height_m * texels_per_m)))
        tile = max(8, int(round(rng.uniform(*self.tile_m) * texels_per_m)))
        canvas = np.empty((h_tx, w_tx), dtype=np.float32)
        for y0 in range(0, h_tx, tile):
            for x0 in range(0, w_tx, tile):
                photo = self._pick(rng)
                side = min(int(round(tile * rng.uniform(0.6, 1.4))), *photo.shape)
                r0 = rng.integers(photo.shape[0] - side + 1)
                c0 = rng.integers(photo.shape[1] - side + 1)
                crop = cv2.resize(photo[r0:r0 + side, c0:c0 + side], (tile, tile), interpolation=cv2.INTER_AREA)
                crop = np.rot90(crop, rng.integers(4))
                if rng.uniform() < 0.5:
                    crop = crop[:, ::-1]
                crop = 0.5 + rng.uniform(0.7, 1.1) * (crop - 0.5) + rng.uniform(-0.1, 0.1)
                h, w = min(tile, h_tx - y0), min(tile, w_tx - x0)
                canvas[y0:y0 + h, x0:x0 + w] = crop[:h, :w]
        # Band-limit to about a texel (like the procedural texture) so mip level 0 does not alias.
        canvas = cv2.GaussianBlur(canvas, (0, 0), 0.6, borderType=cv2.BORDER_REFLECT)
        return np.clip(canvas, 0.02, 0.98).astype(np.float32)


def photo_tiles(data_dir: Optional[Union[str, Path]] = None) -> Optional[PhotoTiles]:
    """Photographic tiles from ``data_dir`` (default :func:`shared_data_dir`); None when it holds none."""
    data_dir = shared_data_dir() if data_dir is None else Path(data_dir)
    if data_dir is None or not Path(data_dir).is_dir():
        return None
    photographs = _photographs(str(Path(data_dir).resolve()))
    return PhotoTiles(photographs) if photographs else None


# --------------------------------------------------------------------------------------------------
# Motion styles


class StyledRoomMotion(RoomWalkTrajectory):
    """A :class:`RoomWalkTrajectory` (rotation wander, tremor) in a :data:`ROOM_SIZE_M` room plus a
    style's path of the camera centre:

    - ``walk-forward``: walking towards the +x wall (≤ 4.2 m, ≤ 0.45 m/s) with a step bob
      (2 cm at 1.8 Hz) and sway (2.5 cm at 0.9 Hz), looking ahead (yaw ±20°, pitch ±8°);
    - ``look-around``: standing (±5 cm), turning the head (yaw ±70°, pitch ±15°): mostly rotation;
    - ``sideways-dolly``: sliding 2.6 m to the right at constant speed in front of the +x wall,
      1.9–2.9 m away, barely rotating (yaw ±4°, pitch ±3°): f is weakly observable.
    """

    def __init__(self, style: str, seed: int, duration_s: float) -> None:
        if style not in MOTION_STYLES:
            raise InputError(f"unknown motion style {style!r} ({', '.join(MOTION_STYLES)})")
        rng = np.random.default_rng([0x57E1, int(seed), MOTION_STYLES.index(style)])
        self.style, self.duration_s = style, float(duration_s)
        self.bob_phase = rng.uniform(0, 2 * np.pi, 2)
        if style == "walk-forward":
            yaw0 = rng.uniform(-10.0, 10.0)
            super().__init__(seed, center_m=(-2.6, rng.uniform(-0.7, 0.7), 1.5),
                             position_amplitude_m=(0.04, 0.06, 0.02), yaw_amplitude_deg=20.0,
                             pitch_amplitude_deg=8.0, roll_amplitude_deg=3.0, yaw0_deg=yaw0)
            heading = np.deg2rad(yaw0)
            self.velocity_m_s = min(0.45, 4.2 / self.duration_s) * np.array([np.cos(heading), np.sin(heading), 0.0])
            self.start_offset_m = np.zeros(3)
        elif style == "look-around":
            super().__init__(seed, center_m=(rng.uniform(-1.5, 1.5), rng.uniform(-0.8, 0.8), 1.5),
                             position_amplitude_m=(0.05, 0.05, 0.02), yaw_amplitude_deg=70.0,
                             pitch_amplitude_deg=15.0, roll_amplitude_deg=5.0)
            self.velocity_m_s = np.zeros(3)
            self.start_offset_m = np.zeros(3)
        else:
            yaw0 = rng.uniform(-8.0, 8.0)
            super().__init__(seed, center_m=(rng.uniform(0.6, 1.6), 0.0, 1.4),
                             position_amplitude_m=(0.02, 0.02, 0.01), yaw_amplitude_deg=4.0,
                             pitch_amplitude_deg=3.0, roll_amplitude_deg=2.0, yaw0_deg=yaw0)
            right = np.array([np.sin(np.deg2rad(yaw0)), -np.cos(np.deg2rad(yaw0)), 0.0])
            self.velocity_m_s = 2.6 / self.duration_s * right
            self.start_offset_m = -1.3 * right

    def _pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, centre = super()._pose(t_s)
        t = np.asarray(t_s, dtype=np.float64).reshape(-1, 1)
        path = self.start_offset_m + t * self.velocity_m_s
        if self.style == "walk-forward":
            heading = self.velocity_m_s / max(np.linalg.norm(self.velocity_m_s), 1e-12)
            side = np.array([-heading[1], heading[0], 0.0])
            path = path + 0.02 * np.sin(2 * np.pi * 1.8 * t + self.bob_phase[0]) * np.array([0.0, 0.0, 1.0]) \
                + 0.025 * np.sin(2 * np.pi * 0.9 * t + self.bob_phase[1]) * side
        return R, centre + path

    def describe(self) -> dict:
        return super().describe() | {"type": "StyledRoomMotion", "style": self.style,
                                     "duration_s": self.duration_s, "velocity_m_s": self.velocity_m_s.tolist(),
                                     "start_offset_m": self.start_offset_m.tolist()}


# --------------------------------------------------------------------------------------------------
# Exposure


def auto_exposure_gains(times_s: np.ndarray, rng: np.random.Generator, drift: float, steps: int,
                        step_max: float, ramp_s: float = 0.2) -> tuple[np.ndarray, list]:
    """Per-frame gain of an auto-exposure: ``1 + drift · sin`` (0.05–0.2 Hz) times ``steps`` smooth
    steps (factor ``exp(±U(step_max / 3, step_max))``, smoothstep over ``ramp_s``) at random times
    in the middle 60 % of the sequence. Returns (gains, the steps as [time, factor])."""
    t = np.asarray(times_s, dtype=np.float64)
    span = max(t[-1] - t[0], 1e-9)
    gain = 1.0 + drift * np.sin(2 * np.pi * rng.uniform(0.05, 0.2) * (t - t[0]) + rng.uniform(0, 2 * np.pi))
    changes = []
    for _ in range(int(steps)):
        at = t[0] + rng.uniform(0.2, 0.8) * span
        factor = float(np.exp(rng.choice([-1.0, 1.0]) * rng.uniform(step_max / 3, step_max)))
        x = np.clip((t - at) / ramp_s, 0.0, 1.0)
        gain *= factor ** (x * x * (3 - 2 * x))
        changes.append([float(at), factor])
    return gain, changes


def _cos4_vignette(camera: CameraModel, strength: float) -> np.ndarray:
    """Natural (cos⁴) fall-off of the camera, rescaled to lose ``strength`` at the darkest corner."""
    uu, vv = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    rays = np.asarray(camera.unproject(np.column_stack([uu.ravel(), vv.ravel()])), dtype=np.float64)
    loss = 1.0 - (1.0 / np.linalg.norm(rays, axis=1)) ** 4
    return (1.0 - strength * loss / max(loss.max(), 1e-12)).reshape(camera.height, camera.width)


# --------------------------------------------------------------------------------------------------
# Sequences


def _phone_defaults() -> RealismOptions:
    return RealismOptions(exposure_fraction=0.25, exposure_samples=3, screen=False, vignetting=0.25,
                          jitter_s=2e-3, drop_probability=0.03, timestamp_noise_s=0.2e-3)


@dataclass
class SceneRealism:
    """What the phone does to a room walk (module docstring). ``phone``: the shared phone model
    (exposure, noise, vignetting, bitrate, frame timing, codec; its screen and stabilisation
    fields are not used here)."""

    textures: str = "photo"                  # photo (procedural when the shared data are absent) | procedural
    line_delay_s: Optional[float] = None     # None: 30 µs/row at 480 rows, i.e. 14.4 ms / height
    ae_drift: float = 0.08                   # slow auto-exposure gain wobble (fraction)
    ae_steps: int = 2                        # auto-exposure steps
    ae_step_max: float = 0.35                # largest step, log gain
    brightness: float = 0.85                 # mean exposure level before the gain
    supersampling: int = 1                   # the exposure samples also smooth edges
    texels_per_m: float = 200.0              # texture resolution of the room's planes
    room_size_m: tuple = ROOM_SIZE_M         # length x, width y, height z
    data_dir: Optional[str] = None           # photographs (default: shared_data_dir())
    phone: RealismOptions = field(default_factory=_phone_defaults)

    def line_delay_for(self, height: int) -> float:
        return 30e-6 * 480.0 / height if self.line_delay_s is None else float(self.line_delay_s)


@dataclass
class RealisticScene:
    """What :func:`render_realistic_scene` wrote: frames (``frame_*.png`` + ``timestamps.txt``) and
    ``truth.json`` in ``out_dir``; ``video.mp4`` is the compressed stream."""

    out_dir: Path
    truth: dict
    camera: CameraModel
    elapsed_s: float


def render_realistic_scene(out_dir: Union[str, Path], style: str = "look-around", size: tuple[int, int] = (320, 240),
                           num_frames: int = 200, seed: int = 0, *, fps: float = 30.0,
                           realism: Optional[SceneRealism] = None, camera: Optional[CameraModel] = None,
                           threads: int = 1) -> RealisticScene:
    """Render a phone-like room sequence (module docstring) into ``out_dir``: frame_000000.png …
    (the decoded frames), timestamps.txt (recorded times of the frames kept), video.mp4, truth.json
    (camera in the Civera model, line delay, exposure, gains, capture and recorded times, the pose
    at each frame's first-row exposure start, scene, textures used, codec used)."""
    started = time.perf_counter()
    realism = realism or SceneRealism()
    phone = realism.phone
    camera = camera_for_size(*size) if camera is None else camera
    width, height = int(camera.width), int(camera.height)
    line_delay = realism.line_delay_for(height)
    exposure_s = phone.exposure_fraction / fps
    if line_delay * height + exposure_s > 1.0 / fps + 1e-12:
        raise InputError("readout time plus exposure exceed the frame period")
    duration_s = num_frames / fps
    rng = np.random.default_rng([0x5CE7E, int(seed)])
    textures_used, tiles = "procedural", None
    if realism.textures == "photo":
        tiles = photo_tiles(realism.data_dir)
        textures_used = (f"photo ({len(tiles.photographs)} photographs)" if tiles is not None
                         else "procedural (no photographs: shared data not found)")
    elif realism.textures != "procedural":
        raise InputError(f"unknown textures {realism.textures!r} (photo, procedural)")
    scene = room_scene(seed, size_m=realism.room_size_m, texels_per_m=realism.texels_per_m, texture_fn=tiles if tiles is not None else procedural_texture)
    trajectory = StyledRoomMotion(style, seed, duration_s)
    renderer = SceneRenderer(camera, scene, realism.supersampling, threads=threads)

    times, recorded = capture_times(num_frames, fps, rng, phone)
    gains, steps = auto_exposure_gains(times, rng, realism.ae_drift, realism.ae_steps, realism.ae_step_max)
    vignette = _cos4_vignette(camera, phone.vignetting)
    samples = max(1, int(phone.exposure_samples)) if exposure_s > 0 else 1
    offsets = (np.arange(samples) + 0.5) / samples * exposure_s
    row_times = np.arange(height) * line_delay
    frames = []
    for i, t in enumerate(times):
        radiance = np.zeros((height, width), dtype=np.float32)
        for off in offsets:
            R_rows, p_rows = trajectory.pose_cw(t + off + row_times)
            radiance += renderer.render_rows(R_rows, p_rows)
        radiance *= np.float32(realism.brightness * gains[i] / samples)
        frames.append(sensor_image(np.minimum(radiance, 1.0), np.random.default_rng([0x5CE7F, int(seed), i]),
                                   phone, vignette))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    decoded, codec = encode_decode(frames, fps, phone.bits_per_pixel, out / "video.mp4", phone.codec,
                                   phone.h264_profile)
    names = []
    for i, image in enumerate(decoded):
        names.append(f"frame_{i:06d}.png")
        if not cv2.imwrite(str(out / names[-1]), image):
            raise OSError(f"could not write {out / names[-1]}")
    (out / "timestamps.txt").write_text("".join(f"{t:.9f}\n" for t in recorded))
    R0, p0 = trajectory.pose_cw(times)
    truth = {
        "generator": "rscalib.sim.scene_realism",
        "conventions": "docs/conventions.md: x_c = R x_w + p; OpenCV pixels; rolling shutter: row v exposed from "
                       "t_s + v * line_delay_s for exposure_s; R, p at t_s (row 0, start of exposure)",
        "camera": {"model": camera.model, "params": np.asarray(camera.params).tolist(),
                   "param_names": list(camera.param_names), "width": width, "height": height,
                   "pixel_size_mm": np.asarray(camera.pixel_size_mm).tolist()},
        "style": style, "seed": int(seed), "fps": float(fps), "num_frames_rendered": len(times),
        "num_frames_requested": int(num_frames), "shutter": "rolling", "line_delay_s": line_delay,
        "readout_time_s": line_delay * height, "exposure_s": exposure_s, "exposure_samples": samples,
        "supersampling": renderer.supersampling, "textures": textures_used, "codec_used": codec,
        "auto_exposure": {"gains": np.round(gains, 6).tolist(), "steps": steps},
        "realism": asdict(realism),
        "scene": scene.describe(),
        "trajectory_model": trajectory.describe(),
        "frames": [{"file": name, "t_s": float(t), "recorded_t_s": float(tr), "R": Ri.tolist(), "p": pi.tolist()}
                   for name, t, tr, Ri, pi in zip(names, times, recorded, R0, p0)],
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    return RealisticScene(out, truth, camera, time.perf_counter() - started)
