"""Self-calibration from images (Civera et al. 2009; docs/sog.md): the SOG filter bank (C++,
rscalib._core.SogBank) over an image sequence through the per-frame loop of
:mod:`rscalib.selfcalib.driver` with the image front end (:mod:`rscalib.selfcalib.front_end`); the
result, and the conversion of the civera-radial model to OpenCV's."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Optional, Union

import cv2
import numpy as np

from .. import _core
from .._progress import Progress, ProgressArg
from ..errors import InputError
from ..io.video import open_source
from .driver import SelfCalibHistory, run_bank
from .front_end import FrontEndOptions, ImageFrontEnd
from .prior import PAPER_PIXEL_SIZE_MM, initial_bank, make_bank

__all__ = ["PARAM_NAMES", "GrayFrames", "SelfCalibResult", "civera_to_opencv", "read_gray_frames", "self_calibrate"]

PARAM_NAMES = ("f", "cx", "cy", "k1", "k2")


@dataclass
class SelfCalibResult:
    """Estimates (moment-matched over the bank), 99 % bounds, and the history per frame."""

    mean: np.ndarray                  # [f, cx, cy, k1 (mm^-2), k2 (mm^-4)]
    bounds_99: np.ndarray             # (5, 2)
    covariance: np.ndarray            # (5, 5)
    image_size: tuple[int, int]
    pixel_size_mm: tuple[float, float]
    gaussians_initial: int
    gaussians_left: int
    history: SelfCalibHistory
    warnings: list = field(default_factory=list)

    @property
    def frames_processed(self) -> int:
        return len(self.history)

    @property
    def frames_per_s(self) -> float:
        return self.history.frames_per_s

    @property
    def collapse_frame(self) -> Optional[int]:
        """The first frame with one Gaussian left (None if more remain)."""
        return self.history.collapse_frame

    def camera(self) -> _core.CameraModel:
        f, cx, cy, k1, k2 = self.mean
        return _core.CameraModel("civera-radial", [f, cx, cy, k1, k2], self.image_size[0], self.image_size[1],
                                 pixel_size_mm=self.pixel_size_mm)

    def summary_dict(self) -> dict:
        out = {name: float(v) for name, v in zip(PARAM_NAMES, self.mean)}
        for i, name in enumerate(PARAM_NAMES):
            out[f"{name}_bounds_99"] = [float(self.bounds_99[i, 0]), float(self.bounds_99[i, 1])]
        out.update(image_size=list(self.image_size), pixel_size_mm=list(self.pixel_size_mm),
                   frames_processed=self.frames_processed, gaussians_initial=self.gaussians_initial,
                   gaussians_left=self.gaussians_left, frames_per_s=self.frames_per_s,
                   collapse_frame=self.collapse_frame, warnings=list(self.warnings),
                   history=self.history.summary_dict())
        return out


@dataclass
class GrayFrames:
    """The readable frames of a video or image folder: ``frames`` yields (time s, grayscale image)."""

    frames: Iterator[tuple[float, np.ndarray]]
    image_size: tuple[int, int]
    timestamps_from: str                 # how the times were obtained (rscalib.io.video.FrameSource)
    frame_count_estimate: Optional[int]


def read_gray_frames(source) -> GrayFrames:
    """Open a video file or image folder (:func:`rscalib.io.video.open_source`); its image size is
    that of the first readable frame. Unreadable frames are left out."""
    opened = open_source(source)
    frames = opened.frames(gray=True)
    first = next(frames, None)
    while first is not None and first.image is None:
        first = next(frames, None)
    if first is None:
        raise InputError(f"{source}: no readable frames")
    height, width = first.image.shape[:2]

    def readable():
        yield first.time_s, first.image
        for frame in frames:
            if frame.image is not None:
                yield frame.time_s, frame.image

    return GrayFrames(readable(), (width, height), opened.timestamps_source, opened.frame_count_estimate)


def _checked_gray(frames: Iterable, width: int, height: int) -> Iterator[tuple[float, Any]]:
    """(time, image) with every image checked for its size and made grayscale (None passes through)."""
    for k, (t_s, image) in enumerate(frames):
        if image is not None:
            if image.shape[:2] != (height, width):
                raise InputError(f"frame {k} is {image.shape[1]}x{image.shape[0]}, expected {width}x{height}")
            if image.ndim == 3:
                image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        yield t_s, image


def self_calibrate(frames: Iterable, image_size: tuple[int, int], *,
                   pixel_size_mm=PAPER_PIXEL_SIZE_MM, options: Optional[_core.SogOptions] = None,
                   front_end: Union[FrontEndOptions, ImageFrontEnd, None] = None, grid: Optional[dict] = None,
                   max_frames: Optional[int] = None, progress: ProgressArg = None,
                   expected_frames: Optional[int] = None,
                   on_frame: Optional[Callable[[int, _core.SogBank, _core.SogUpdateReport], None]] = None
                   ) -> SelfCalibResult:
    """Run the SOG bank over `frames`: an iterable of (time_s, image), grayscale or BGR uint8;
    an image of None (unreadable) is skipped.

    pixel_size_mm: the sensor's pixel pitch (the distortion model's radii are in mm);
    grid: keyword arguments of rscalib.selfcalib.prior.initial_bank (ranges, counts);
    front_end: the image front end's options (for 320 px wide images, scaled to this size) or a
    ready :class:`ImageFrontEnd`;
    progress: False/None, True (a progress bar on stderr) or a callable(done, total), with
    `expected_frames` the bar's total when `max_frames` is not given;
    on_frame(k, bank, report) is called after every processed frame."""
    width, height = int(image_size[0]), int(image_size[1])
    source = front_end if isinstance(front_end, ImageFrontEnd) else ImageFrontEnd(front_end, (width, height))
    initial = initial_bank(width, height, pixel_size_mm, **(grid or {}))
    bank = make_bank(width, height, pixel_size_mm, options=options, bank=initial)
    total = max_frames if max_frames is not None else expected_frames
    with Progress(progress, total, "self-calibrating") as bar:
        def each_frame(k: int, running: _core.SogBank, report: _core.SogUpdateReport) -> None:
            bar.update(k + 1, f"f {running.calibration_mean[0]:.1f} px, {running.num_gaussians} Gaussians")
            if on_frame is not None:
                on_frame(k, running, report)

        history = run_bank(bank, _checked_gray(frames, width, height), source,
                           min_visible=source.options.min_visible,
                           max_new_per_frame=source.options.max_new_per_frame,
                           max_frames=max_frames, on_frame=each_frame)
    warnings = []
    if bank.num_gaussians > 1:
        warnings.append(f"{bank.num_gaussians} Gaussians remain: the sequence did not single out one calibration "
                        "(move more, with rotation and translation, through a textured scene)")
    used = np.median(history.features_used)
    if used < 0.5 * source.options.min_visible:
        warnings.append(f"few features matched per frame (median {used:.0f}); the scene may lack texture")
    return SelfCalibResult(
        mean=np.asarray(bank.calibration_mean), bounds_99=np.asarray(bank.calibration_bounds_99()),
        covariance=np.asarray(bank.calibration_cov), image_size=(width, height),
        pixel_size_mm=tuple(float(x) for x in np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,))),
        gaussians_initial=len(initial), gaussians_left=bank.num_gaussians, history=history, warnings=warnings)


def civera_to_opencv(camera: _core.CameraModel, samples: int = 40) -> tuple[_core.CameraModel, float]:
    """OpenCV pinhole-radtan (k1, k2, k3; no tangential terms) closest to a civera-radial camera:
    linear least squares of the radial factor over a grid of image pixels. Returns the camera and
    the largest pixel difference between the two models over that grid."""
    if camera.model != "civera-radial":
        raise InputError("civera_to_opencv needs a civera-radial camera")
    f, cx, cy, _, _ = camera.params
    w, h = camera.width, camera.height
    us, vs = np.meshgrid(np.linspace(0, w - 1, samples), np.linspace(0, h - 1, samples))
    uv_d = np.c_[us.ravel(), vs.ravel()]
    uv_u = camera.undistort(uv_d)
    x_u = (uv_u - [cx, cy]) / f
    x_d = (uv_d - [cx, cy]) / f
    r2 = np.sum(x_u ** 2, axis=1)
    keep = r2 > 1e-12
    # x_d = x_u (1 + K1 r2 + K2 r2^2 + K3 r2^3): linear in K for both coordinates
    a = np.vstack([x_u[keep, j:j + 1] * np.c_[r2[keep], r2[keep] ** 2, r2[keep] ** 3] for j in (0, 1)])
    b = np.concatenate([x_d[keep, j] - x_u[keep, j] for j in (0, 1)])
    k, *_ = np.linalg.lstsq(a, b, rcond=None)
    opencv = _core.CameraModel("pinhole-radtan", [f, f, cx, cy, k[0], k[1], 0.0, 0.0, k[2]], w, h)
    points = np.c_[x_u, np.ones(len(x_u))]
    error = np.linalg.norm(opencv.project(points) - uv_d, axis=1)
    return opencv, float(np.nanmax(error))
