"""Realistic flicker footage: what an LED or mains lamp looks like through a rolling shutter.

Row v of frame i integrates the light over its exposure ``[t_i + v d, t_i + v d + E]``
(docs/conventions.md; d < 0 is a bottom-to-top readout). :class:`FlickerLight` is the light: a
square wave (on for ``duty`` of each period, off at ``off_level``) or a sine, box-averaged over the
exposure in closed form, so a short exposure gives crisp bands and a long one soft, low-contrast
bands with a duty cycle set by the exposure. :func:`render_flicker_frames` draws frames of a lamp
or diffuser seen by such a camera, with what real footage has: the lamp filling only part of the
frame (a disk), vignetting, clipping at full scale and at black (``brightness`` > 1 saturates),
a black level, a text overlay and an out-of-focus blob, noise and JPEG compression. It is
independent of the target renderer (:mod:`rscalib.sim.target_video`), and records its truth.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import cv2
import numpy as np

from ..errors import InputError

__all__ = ["FlickerLight", "FlickerScene", "render_flicker_frames", "write_flicker_sequence"]


@dataclass
class FlickerLight:
    """A light whose intensity repeats at ``frequency_hz``: relative intensity 1 when on, ``off_level``
    when off. ``waveform`` "square" (on for ``duty`` of each period, starting at phase 0) or
    "sine" (1 + depth sin, depth = (1 - off_level) / 2 about the mean). ``phase`` in cycles."""

    frequency_hz: float
    duty: float = 0.5
    off_level: float = 0.0
    waveform: str = "square"
    phase: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.frequency_hz) and self.frequency_hz > 0):
            raise InputError(f"flicker frequency must be positive (got {self.frequency_hz})")
        if not 0.0 < self.duty < 1.0:
            raise InputError(f"duty cycle must be in (0, 1) (got {self.duty})")
        if not 0.0 <= self.off_level < 1.0:
            raise InputError(f"off level must be in [0, 1) (got {self.off_level})")
        if self.waveform not in ("square", "sine"):
            raise InputError(f"unknown waveform {self.waveform!r} (square, sine)")

    def _integral(self, x: np.ndarray) -> np.ndarray:
        """∫_0^x g(u) du in cycles (x in cycles)."""
        if self.waveform == "sine":
            depth = 0.5 * (1.0 - self.off_level)
            mean = 1.0 - depth
            return mean * x - depth * (np.cos(2 * np.pi * x) - 1.0) / (2 * np.pi)
        whole = np.floor(x)
        frac = x - whole
        per_cycle = self.duty + self.off_level * (1.0 - self.duty)
        return whole * per_cycle + np.minimum(frac, self.duty) + self.off_level * np.maximum(frac - self.duty, 0.0)

    def gain(self, t_s: np.ndarray, exposure_s: float = 0.0) -> np.ndarray:
        """Mean relative intensity over [t, t + exposure] (the value at t when exposure is 0)."""
        x = self.frequency_hz * np.asarray(t_s, dtype=np.float64) + self.phase
        if exposure_s <= 0:
            if self.waveform == "sine":
                depth = 0.5 * (1.0 - self.off_level)
                return 1.0 - depth + depth * np.sin(2 * np.pi * x)
            return np.where(np.mod(x, 1.0) < self.duty, 1.0, self.off_level)
        width = self.frequency_hz * exposure_s
        return (self._integral(x + width) - self._integral(x)) / width


@dataclass
class FlickerScene:
    """What the camera sees, in fractions of full scale. ``lamp``: "flat" (the light fills the frame),
    "disk" (a lit disk of ``lamp_radius`` × the image height, centred, on a dark surround), or
    "partial" (the light covers the rows/columns fraction ``coverage`` from the left). ``brightness``:
    the level of the light when on (> 1 saturates); ``ambient``: unflickering light on the lit part;
    ``black_level``: the sensor pedestal; ``vignetting``: relative fall-off at the corners;
    ``overlay_text``: drawn in white at the top; ``blob``: an out-of-focus bright blob on the right."""

    lamp: str = "flat"
    lamp_radius: float = 0.45
    coverage: float = 0.6
    brightness: float = 0.8
    ambient: float = 0.0
    black_level: float = 0.0
    vignetting: float = 0.0
    overlay_text: Optional[str] = None
    blob: bool = False
    texture: float = 0.0          # relative scene texture (a static pattern under the light)

    def layers(self, width: int, height: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lit (H, W) reflectance under the light, steady (H, W) light not modulated, overlay mask)."""
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
        if self.lamp == "flat":
            lit = np.ones((height, width))
        elif self.lamp == "disk":
            r = np.hypot(xx - 0.5 * (width - 1), yy - 0.5 * (height - 1)) / height
            lit = np.clip((self.lamp_radius - r) * height / 6.0 + 0.5, 0.0, 1.0)  # a soft edge of ~6 px
        elif self.lamp == "partial":
            lit = (xx < self.coverage * width).astype(np.float64)
        else:
            raise InputError(f"unknown lamp {self.lamp!r} (flat, disk, partial)")
        if self.texture > 0:
            rng = np.random.default_rng([0x464C, seed])
            pattern = cv2.GaussianBlur(rng.normal(0.0, 1.0, (height, width)), (0, 0), 6.0)
            lit = lit * np.clip(1.0 + self.texture * pattern / max(pattern.std(), 1e-12), 0.05, None)
        if self.vignetting > 0:
            r2 = ((xx - 0.5 * width) ** 2 + (yy - 0.5 * height) ** 2) / (0.25 * (width ** 2 + height ** 2))
            lit = lit * (1.0 - self.vignetting * r2)
        steady = np.zeros((height, width))
        if self.blob:
            cx, cy, s = 0.92 * width, 0.6 * height, 0.25 * max(width, height)
            steady += 0.5 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * s * s))
        overlay = np.zeros((height, width), dtype=np.float64)
        if self.overlay_text:
            scale = max(0.4, height / 300.0)
            thick = max(1, int(round(scale * 2)))
            cv2.putText(overlay, self.overlay_text, (int(0.3 * width), int(0.25 * height)),
                        cv2.FONT_HERSHEY_SIMPLEX, scale, 1.0, thick, cv2.LINE_AA)
            x0, y0 = int(0.45 * width), int(0.55 * height)
            cv2.rectangle(overlay, (x0, y0), (x0 + int(0.28 * width), y0 + int(0.12 * height)), 1.0, -1)
        return lit, steady, overlay


def render_flicker_frames(light: FlickerLight, scene: FlickerScene, size: Sequence[int], line_delay_s: float,
                          frame_times_s: Sequence[float], exposure_s: float = 0.0, noise: float = 1.0,
                          jpeg_quality: Optional[int] = None, seed: int = 0) -> tuple[np.ndarray, dict]:
    """(frames (N, H, W) uint8, truth) of ``scene`` under ``light`` seen by a rolling shutter:
    row v of frame i exposed over [t_i + v d, t_i + v d + exposure]; Gaussian noise of ``noise``
    grey levels; clipped to 0..255; optionally JPEG-compressed at ``jpeg_quality``."""
    width, height = (int(s) for s in size)
    if width < 1 or height < 16:
        raise InputError(f"bad size {width}x{height}")
    if not math.isfinite(line_delay_s) or line_delay_s == 0:
        raise InputError("line delay must be finite and non-zero")
    times = np.asarray(frame_times_s, dtype=np.float64)
    lit, steady, overlay = scene.layers(width, height, seed)
    rng = np.random.default_rng([0x4C45, seed])
    rows = np.arange(height, dtype=np.float64)
    frames = []
    for t in times:
        g = light.gain(t + rows * line_delay_s, exposure_s)                    # (H,)
        radiance = scene.black_level + lit * (scene.ambient + scene.brightness * g[:, None]) + steady
        radiance = np.where(overlay > 0, np.maximum(radiance, overlay), radiance)
        grey = radiance * 255.0
        if noise > 0:
            grey = grey + rng.normal(0.0, noise, grey.shape)
        frame = np.clip(np.rint(grey), 0, 255).astype(np.uint8)
        if jpeg_quality is not None:
            ok, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
            frame = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
        frames.append(frame)
    truth = {"generator": "rscalib.sim.flicker_light", "line_delay_s": float(line_delay_s),
             "readout": "bottom-to-top" if line_delay_s < 0 else "top-to-bottom",
             "frequency_hz": light.frequency_hz, "duty": light.duty, "off_level": light.off_level,
             "waveform": light.waveform, "phase_cycles": light.phase, "exposure_s": float(exposure_s),
             "frame_times_s": times.tolist(), "size": [width, height], "noise_grey_levels": float(noise),
             "jpeg_quality": jpeg_quality, "scene": dict(scene.__dict__),
             "clipped_fraction": float(np.mean([(f >= 255).mean() + (f == 0).mean() for f in frames]))}
    return np.array(frames), truth


def write_flicker_sequence(out_dir, light: FlickerLight, scene: FlickerScene, size: Sequence[int],
                           line_delay_s: float, frame_times_s: Sequence[float], exposure_s: float = 0.0,
                           noise: float = 1.0, jpeg_quality: Optional[int] = None, seed: int = 0,
                           timestamps: bool = True) -> dict:
    """Render with :func:`render_flicker_frames` and write ``frame_000000.png`` … (``.jpg`` when
    ``jpeg_quality`` is given: the file holds the compressed bytes), ``timestamps.txt`` (row-0 times,
    seconds; left out when ``timestamps`` is False, as for frames whose times are unknown) and
    ``truth.json``. Returns the truth."""
    import json
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frames, truth = render_flicker_frames(light, scene, size, line_delay_s, frame_times_s, exposure_s=exposure_s,
                                          noise=noise, jpeg_quality=None, seed=seed)
    for stale in [*out.glob("frame_*.png"), *out.glob("frame_*.jpg"), out / "timestamps.txt"]:
        stale.unlink(missing_ok=True)
    for i, frame in enumerate(frames):
        if jpeg_quality is None:
            cv2.imwrite(str(out / f"frame_{i:06d}.png"), frame)
        else:
            cv2.imwrite(str(out / f"frame_{i:06d}.jpg"), frame, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
    truth["jpeg_quality"] = jpeg_quality
    times = np.asarray(frame_times_s, dtype=np.float64)
    if timestamps:
        (out / "timestamps.txt").write_text("".join(f"{t:.9f}\n" for t in times))
    truth["timestamps_written"] = bool(timestamps)
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth
