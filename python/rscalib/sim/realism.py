"""A realistic mode of the target-video renderer: what a phone does to a calibration video.

The clean renderer (rscalib.sim.target_video) draws every row at its own time with exact
geometry, Gaussian noise and a lossless codec: the estimator's best case, not the world. This
module renders the same rolling-shutter geometry and then degrades it the way a hand-held phone
recording of a board on a laptop screen is degraded (issue 12):

- **motion blur** over a real exposure (a fraction of the frame period), sampled in time;
- **a target shown on a screen**: grey blacks and dim whites, brightness falling off across the
  screen (viewing angle), instead of black ink on white paper;
- **lens vignetting** and **sensor noise that depends on brightness** (read noise plus shot noise,
  variance ``read² + gain · grey``);
- **frame-time jitter** (frames captured at irregular times), **dropped frames**, and
  **timestamp noise** (the recorded time of a frame differs from its capture time);
- optionally **electronic stabilisation**: a small, smooth per-frame similarity warp of the image
  (which the rolling-shutter model does not know about);
- **H.264 as a phone records it** (libx264 through the ffmpeg binary of the ``imageio-ffmpeg``
  package when it is installed; otherwise OpenCV's MPEG-4 part 2, recorded as such in truth.json).
  The defaults copy the one real phone recording we have (``../shared/data/real_selfcalib_s3phone``:
  Baseline profile, P frames only, a key frame every second, 2.02 Mbit/s at 640×480 and 30 fps,
  i.e. 0.22 bit/pixel); lower bitrates stand for videos re-encoded by a messaging app.

The decoded frames are written as PNG with ``timestamps.txt`` (the recorded, noisy times: a phone's
container carries per-frame times, which AVI cannot), so `rscalib linedelay OUT/frames` sees what a
user's decoder would. ``truth.json`` keeps the true capture times and the exact rolling-shutter
projections (after the stabilisation warp) of the target points.
"""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np
import yaml

from .._core import CameraModel
from .._progress import Progress
from ..errors import InputError
from ..io.cameras import write_opencv_yaml
from ..io.targets import Target, as_target
from .target_observations import default_camera
from .target_texture import BLACK, WHITE, TargetTexture
from .target_video import RollingShutterRenderer
from .trajectories import target_trajectory

__all__ = ["MOTION_STYLES", "RealismOptions", "RealisticVideo", "ScreenTexture", "motion_trajectory",
           "render_realistic_video"]

# Motion styles of the benchmark: (frequency range Hz, amplitude of HandheldTrajectory).
MOTION_STYLES = {
    "handheld": ((0.2, 3.0), 1.0),     # the default hand-held wobble
    "shake": ((0.8, 6.0), 0.45),       # small, fast shaking (tremor-like)
    "sweep": ((0.1, 1.0), 1.0),        # slow, wide sweeps
    "near-static": ((0.2, 3.0), 0.03),  # a camera held as still as a hand can
}


@dataclass
class RealismOptions:
    """What the phone does. Defaults: a mid-range phone indoors, board on a laptop screen."""

    exposure_fraction: float = 0.3      # exposure = this x frame period (motion blur); 0 = none
    exposure_samples: int = 6           # times sampled over the exposure
    read_noise: float = 1.5             # grey levels
    shot_gain: float = 0.05             # variance per grey level: sigma^2 = read^2 + gain * grey
    screen: bool = True                 # the target is shown on a screen
    screen_black: float = 0.12          # radiance of a black / white screen pixel (full scale 1)
    screen_white: float = 0.80
    screen_falloff: float = 0.25        # brightness drop at the screen's edges (viewing angle)
    vignetting: float = 0.3             # brightness drop at the image corners
    bits_per_pixel: float = 0.22        # video bitrate / (width * height * fps): the S3 phone's 2.0 Mbit/s at 640x480x30
    h264_profile: str = "baseline"      # the S3 phone's: no B frames (x264 "high" adds them)
    jitter_s: float = 0.3e-3            # sigma of the capture time around i / fps
    drop_probability: float = 0.01      # frames the phone skipped
    timestamp_noise_s: float = 0.05e-3  # sigma of recorded time - capture time
    stabilisation_px: float = 0.0       # sigma of the per-frame stabilisation shift (0 = off)
    stabilisation_deg: float = 0.0      # sigma of its rotation
    codec: str = "auto"                 # auto (h264, else mpeg4) | h264 | mpeg4 | none (lossless)


class ScreenTexture(TargetTexture):
    """A target shown on a screen: ink and paper become dim black and white pixels, darker towards
    the screen's edges (seen off-axis)."""

    def __init__(self, target: Target, black: float = 0.12, white: float = 0.80, falloff: float = 0.25) -> None:
        super().__init__(target)
        self.black, self.white, self.falloff = float(black), float(white), float(falloff)
        x0, x1, y0, y1 = self.sheet_bounds_m()
        self._centre = (0.5 * (x0 + x1), 0.5 * (y0 + y1))
        self._half = (0.5 * (x1 - x0), 0.5 * (y1 - y0))

    def albedo(self, x, y, wx, wy):
        a = (super().albedo(x, y, wx, wy) - BLACK) / (WHITE - BLACK)
        rx = (x - self._centre[0]) / self._half[0]
        ry = (y - self._centre[1]) / self._half[1]
        gain = np.clip(1.0 - self.falloff * 0.5 * (rx * rx + ry * ry), 0.3, 1.0)
        gain = np.where(np.isfinite(gain), gain, 1.0)
        return ((self.black + (self.white - self.black) * np.clip(a, 0.0, 1.0)) * gain).astype(np.float32)

    def describe(self) -> dict:
        return super().describe() | {"shown_on_screen": {"black": self.black, "white": self.white,
                                                         "falloff": self.falloff}}


def motion_trajectory(camera: CameraModel, target: Target, duration_s: float, seed: int, style: str):
    """The hand-held motion of a benchmark style (MOTION_STYLES) in front of the target."""
    if style not in MOTION_STYLES:
        raise InputError(f"unknown motion style {style!r} ({', '.join(MOTION_STYLES)})")
    freq, amplitude = MOTION_STYLES[style]
    return target_trajectory(camera, target, duration_s, seed, motion=amplitude, freq_range_hz=freq)


@dataclass
class RealisticVideo:
    """What render_realistic_video wrote: frames/ (PNG + timestamps.txt), video.mp4, truth.json,
    camera.yaml, target.yaml."""

    out_dir: Path
    frames_dir: Path
    video_path: Optional[Path]
    truth_path: Path
    camera_path: Path
    target_path: Path
    camera: CameraModel
    line_delay_s: float
    codec: str
    truth: dict = field(repr=False)
    render_seconds: float = 0.0


def capture_times(num_frames: int, fps: float, rng: np.random.Generator, options: RealismOptions
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(capture times, recorded timestamps) of the frames kept: frame i near i / fps with jitter,
    some frames dropped, the recorded time off by the timestamp noise. Capture times increase."""
    t = np.arange(num_frames) / fps + rng.normal(0.0, options.jitter_s, num_frames)
    keep = rng.uniform(size=num_frames) >= options.drop_probability
    keep[0] = True
    t = np.maximum.accumulate(t[keep])
    recorded = t + rng.normal(0.0, options.timestamp_noise_s, len(t))
    recorded = np.maximum.accumulate(recorded)
    return t, recorded


def stabilisation_warps(num_frames: int, size: tuple[int, int], rng: np.random.Generator,
                        options: RealismOptions) -> np.ndarray:
    """(n, 2, 3) smooth per-frame similarity warps about the image centre (identity when off): an
    electronic stabiliser's residual correction (a slowly wandering shift and roll)."""
    warps = np.tile(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), (num_frames, 1, 1))
    if options.stabilisation_px <= 0 and options.stabilisation_deg <= 0:
        return warps
    kernel = np.exp(-0.5 * (np.arange(-8, 9) / 3.0) ** 2)
    kernel /= np.sqrt((kernel ** 2).sum())

    def smooth(sigma: float) -> np.ndarray:
        return np.convolve(rng.normal(0.0, sigma, num_frames + 16), kernel, mode="valid")[:num_frames]

    dx, dy = smooth(options.stabilisation_px), smooth(options.stabilisation_px)
    angle = smooth(options.stabilisation_deg)
    centre = ((size[0] - 1) / 2.0, (size[1] - 1) / 2.0)
    for i in range(num_frames):
        m = cv2.getRotationMatrix2D(centre, float(angle[i]), 1.0)
        m[:, 2] += (dx[i], dy[i])
        warps[i] = m
    return warps


def sensor_image(radiance: np.ndarray, rng: np.random.Generator, options: RealismOptions,
                 vignette: np.ndarray) -> np.ndarray:
    """Radiance [0, 1] -> 8-bit grey: vignetting, then read + shot noise (variance read² + gain·grey)."""
    grey = radiance * vignette * 255.0
    sigma = np.sqrt(options.read_noise ** 2 + options.shot_gain * np.maximum(grey, 0.0))
    grey = grey + rng.standard_normal(grey.shape) * sigma
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)


def _vignette(width: int, height: int, strength: float) -> np.ndarray:
    u = (np.arange(width) - (width - 1) / 2.0) / ((width - 1) / 2.0)
    v = (np.arange(height) - (height - 1) / 2.0) / ((width - 1) / 2.0)
    r2 = v[:, None] ** 2 + u[None, :] ** 2
    corner = 1.0 + ((height - 1) / (width - 1)) ** 2
    return 1.0 - strength * r2 / corner


def _ffmpeg() -> Optional[str]:
    try:
        import imageio_ffmpeg  # optional: a static ffmpeg with libx264
        return imageio_ffmpeg.get_ffmpeg_exe()
    except Exception:  # noqa: BLE001 - not installed, or no binary for this platform
        return shutil.which("ffmpeg")


def encode_decode(frames: Sequence[np.ndarray], fps: float, bits_per_pixel: float, path: Path,
                  codec: str = "auto", h264_profile: str = "baseline") -> tuple[list[np.ndarray], str]:
    """Compress the grey frames as a phone would (H.264 of `h264_profile`, bitrate = bits_per_pixel
    · w · h · fps, GOP of one second) into `path`, and decode them again: (decoded frames, codec used)."""
    if codec == "none":
        return list(frames), "none"
    height, width = frames[0].shape
    bitrate = int(bits_per_pixel * width * height * fps)
    exe = _ffmpeg() if codec in ("auto", "h264") else None
    if exe is not None:
        encode = [exe, "-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray",
                  "-s", f"{width}x{height}", "-r", f"{fps:.6f}", "-i", "-", "-c:v", "libx264", "-preset", "fast", "-profile:v", h264_profile,
                  "-b:v", str(bitrate), "-maxrate", str(int(1.5 * bitrate)), "-bufsize", str(2 * bitrate),
                  "-g", str(max(1, int(round(fps)))), "-pix_fmt", "yuv420p", str(path)]
        done = subprocess.run(encode, input=b"".join(f.tobytes() for f in frames), capture_output=True)
        if done.returncode == 0:
            decode = [exe, "-hide_banner", "-loglevel", "error", "-i", str(path), "-f", "rawvideo",
                      "-pix_fmt", "gray", "-"]
            raw = subprocess.run(decode, capture_output=True, check=True).stdout
            out = np.frombuffer(raw, dtype=np.uint8).reshape(-1, height, width)
            if len(out) == len(frames):
                return [f.copy() for f in out], f"h264 (libx264 {h264_profile}, {bitrate / 1e6:.2f} Mbit/s)"
        if codec == "h264":
            raise InputError(f"ffmpeg could not encode H.264: {done.stderr.decode(errors='replace')[:200]}")
    elif codec == "h264":
        raise InputError("H.264 needs an ffmpeg binary (pip install imageio-ffmpeg)")
    # Fallback: MPEG-4 part 2 (DCT blocks and motion compensation too), OpenCV's default bitrate.
    writer = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"mp4v"), float(fps),
                             (width, height), [cv2.VIDEOWRITER_PROP_IS_COLOR, 0])
    if not writer.isOpened():
        raise InputError("OpenCV cannot write MPEG-4 video (is it built with FFmpeg?)")
    for f in frames:
        writer.write(f)
    writer.release()
    capture = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, image = capture.read()
        if not ok:
            break
        out.append(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image)
    capture.release()
    if len(out) != len(frames):
        raise InputError(f"decoding {path.name} gave {len(out)} frames for {len(frames)}")
    return out, "mpeg4 (OpenCV mp4v)"


def _uv_lists(frames: list) -> list:
    return [[None if not np.all(np.isfinite(p)) else [round(float(p[0]), 6), round(float(p[1]), 6)] for p in uv]
            for uv in frames]


_IDENTITY_WARP = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _sensor_frames(renderer: RollingShutterRenderer, times: np.ndarray, warps: np.ndarray, rng: np.random.Generator,
                   options: RealismOptions, vignette: np.ndarray, exposure_s: float, size_wh: tuple,
                   progress: bool) -> tuple[list, list, list]:
    """Each frame as the sensor and the stabiliser give it, with the targets' exact projections at
    the start and the middle of each row's exposure (after the stabilisation warp)."""
    frames, uv_rs, uv_rs_mid = [], [], []
    with Progress(progress, len(times), f"rendering {size_wh[0]}x{size_wh[1]} (realistic)") as bar:
        for i, t in enumerate(times):
            image = sensor_image(renderer.render(float(t)), rng, options, vignette)
            uv = renderer.project_rs(float(t))
            uv_mid = renderer.project_rs(float(t), 0.5 * exposure_s)
            if not np.allclose(warps[i], _IDENTITY_WARP):
                image = cv2.warpAffine(image, warps[i], size_wh, flags=cv2.INTER_LINEAR,
                                       borderMode=cv2.BORDER_REFLECT)
                uv = uv @ warps[i][:, :2].T + warps[i][:, 2]
                uv_mid = uv_mid @ warps[i][:, :2].T + warps[i][:, 2]
            frames.append(image)
            uv_rs.append(uv)
            uv_rs_mid.append(uv_mid)
            bar.advance()
    return frames, uv_rs, uv_rs_mid


def _projections_truth(uv_rs: list, uv_rs_mid: list) -> dict:
    return {"uv_rs": _uv_lists(uv_rs), "uv_rs_mid_exposure": _uv_lists(uv_rs_mid),
            "definition": "uv_rs: exact rolling-shutter projection at the capture time (start of the row's "
                          "exposure), after the stabilisation warp; uv_rs_mid_exposure: at the middle of the "
                          "exposure (where a blurred corner is found); null = not visible"}


def render_realistic_video(out_dir, line_delay_s: float = 30e-6, fps: float = 30.0,
                           size: Union[str, Sequence[int]] = (640, 480), target: Union[str, Path, Target] = "checkerboard",
                           duration_s: float = 8.0, seed: int = 0, motion_style: str = "handheld", *,
                           options: Optional[RealismOptions] = None, camera: Optional[CameraModel] = None,
                           supersample: int = 2, workers: Optional[int] = None,
                           progress: bool = False) -> RealisticVideo:
    """Render a rolling-shutter video of a target as a phone would record it (module docstring).

    Writes OUT/frames (PNG + timestamps.txt: the decoded frames and their recorded times),
    OUT/video.mp4 (the compressed stream), OUT/truth.json, OUT/camera.yaml (true intrinsics and line
    delay), OUT/target.yaml. seed: the motion, the times, the noise and the warps."""
    options = options or RealismOptions()
    if not (math.isfinite(fps) and fps > 0 and math.isfinite(duration_s) and duration_s > 0):
        raise InputError("fps and duration must be positive")
    if camera is None:
        if isinstance(size, str):
            size = tuple(int(s) for s in size.lower().split("x"))
        camera = default_camera(size)
    exposure_s = options.exposure_fraction / fps
    if abs(line_delay_s) * camera.height + exposure_s > 1.0 / fps + 1e-12:
        raise InputError("readout time plus exposure exceed the frame period")
    target = as_target(target)
    trajectory = motion_trajectory(camera, target, duration_s, seed, motion_style)
    texture = (ScreenTexture(target, options.screen_black, options.screen_white, options.screen_falloff)
               if options.screen else TargetTexture(target))
    rng = np.random.default_rng([0x5245414C, int(seed)])
    num_frames = int(math.floor(duration_s * fps + 1e-9))
    times, recorded = capture_times(num_frames, fps, rng, options)
    size_wh = (int(camera.width), int(camera.height))
    warps = stabilisation_warps(len(times), size_wh, rng, options)
    vignette = _vignette(*size_wh, options.vignetting)

    out = Path(out_dir)
    frames_dir = out / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    renderer = RollingShutterRenderer(camera, texture, trajectory, line_delay_s, supersample=supersample,
                                      exposure_s=exposure_s,
                                      exposure_samples=options.exposure_samples if exposure_s > 0 else None,
                                      workers=workers)
    try:
        frames, uv_rs, uv_rs_mid = _sensor_frames(renderer, times, warps, rng, options, vignette, exposure_s,
                                                  size_wh, progress)
    finally:
        renderer.close()
    video_path = out / "video.mp4"
    decoded, codec = encode_decode(frames, fps, options.bits_per_pixel, video_path, options.codec,
                                   options.h264_profile)
    for i, image in enumerate(decoded):
        cv2.imwrite(str(frames_dir / f"frame_{i:06d}.png"), image)
    (frames_dir / "timestamps.txt").write_text("".join(f"{t:.9f}\n" for t in recorded))
    camera_path = out / "camera.yaml"
    write_opencv_yaml(camera, camera_path, line_delay_s=line_delay_s)
    target_path = out / "target.yaml"
    target_path.write_text(yaml.safe_dump(target.kalibr_dict(), sort_keys=False))
    truth = {
        "generator": "rscalib.sim.realism",
        "line_delay_s": float(line_delay_s),
        "readout_time_s": float(line_delay_s) * camera.height,
        "fps": float(fps), "duration_s": float(duration_s), "seed": int(seed), "motion_style": motion_style,
        "image_size": list(size_wh),
        "camera": {"model": camera.model, "params": [float(v) for v in camera.params]},
        "target": texture.describe(),
        "realism": asdict(replace(options)) | {"exposure_s": exposure_s, "codec_used": codec},
        "supersample": int(supersample),
        "capture_times_s": [float(t) for t in times],
        "recorded_times_s": [float(t) for t in recorded],
        "stabilisation_warps": warps.round(9).tolist() if not np.allclose(warps, _IDENTITY_WARP) else None,
        "trajectory": trajectory.describe(),
        "projections": _projections_truth(uv_rs, uv_rs_mid),
    }
    truth_path = out / "truth.json"
    truth_path.write_text(json.dumps(truth, separators=(",", ":")))
    return RealisticVideo(out, frames_dir, video_path if video_path.exists() else None, truth_path, camera_path,
                          target_path, camera, float(line_delay_s), codec, truth, time.perf_counter() - started)
