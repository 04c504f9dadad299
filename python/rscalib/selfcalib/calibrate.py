"""Sequential self-calibration from images (SPEC §4; Civera et al. 2009): the image front end of
the SOG filter bank — corners where the map is thin, patches stored at initialisation, active
search by normalised cross-correlation inside each feature's 99 % prediction ellipse — plus the
result, its history, and the conversion of the civera-radial model to OpenCV's.
The filter itself is C++ (rscalib._core.SogBank, docs/sog.md)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Iterable, Optional

import cv2
import numpy as np

from .. import _core
from ..errors import InputError
from .front_end import FrontEndOptions, PatchStore, active_search, new_corners
from .prior import PAPER_PIXEL_SIZE_MM, initial_bank, make_bank

PARAM_NAMES = ("f", "cx", "cy", "k1", "k2")


@dataclass
class SelfCalibResult:
    """Estimates (moment-matched over the bank), 99 % bounds and the history per frame."""

    mean: np.ndarray                  # [f, cx, cy, k1 (mm^-2), k2 (mm^-4)]
    bounds_99: np.ndarray             # (5, 2)
    covariance: np.ndarray            # (5, 5)
    image_size: tuple[int, int]
    pixel_size_mm: tuple[float, float]
    frames_processed: int
    gaussians_initial: int
    gaussians_left: int
    frames_per_s: float
    collapse_frame: Optional[int]     # first frame with one Gaussian left
    history_frame: np.ndarray         # (K,)
    history_mean: np.ndarray          # (K, 5)
    history_bounds: np.ndarray        # (K, 5, 2)
    history_gaussians: np.ndarray     # (K,)
    history_features: np.ndarray      # (K,) features used in the update
    warnings: list = field(default_factory=list)

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
                   history={"frame": self.history_frame.tolist(),
                            "mean": self.history_mean.tolist(),
                            "bounds_99": self.history_bounds.tolist(),
                            "gaussians": self.history_gaussians.tolist(),
                            "features_used": self.history_features.tolist()})
        return out


def self_calibrate(frames: Iterable, image_size: tuple[int, int], *,
                   pixel_size_mm=PAPER_PIXEL_SIZE_MM, options: Optional[_core.SogOptions] = None,
                   front_end: Optional[FrontEndOptions] = None, grid: Optional[dict] = None,
                   max_frames: Optional[int] = None,
                   progress: Optional[Callable[[int, _core.SogBank], None]] = None) -> SelfCalibResult:
    """Run the SOG bank over `frames`: an iterable of (time_s, grayscale uint8 image).

    pixel_size_mm: the sensor's pixel pitch (the distortion model's radii are in mm);
    grid: keyword arguments of rscalib.selfcalib.prior.initial_bank (ranges, counts);
    progress(frame_index, bank) is called after every frame."""
    width, height = int(image_size[0]), int(image_size[1])
    fe = front_end or FrontEndOptions()
    if fe.subpixel not in ("affine", "parabola"):
        raise InputError(f"front_end.subpixel must be 'affine' or 'parabola', not {fe.subpixel!r}")
    scale = width / 320.0
    fe = FrontEndOptions(**{**fe.__dict__,
                            "patch_half_px": max(3, int(round(fe.patch_half_px * max(1.0, scale ** 0.5)))),
                            "min_separation_px": fe.min_separation_px * scale,
                            "max_search_half_px": fe.max_search_half_px * scale})
    initial = initial_bank(width, height, pixel_size_mm, **(grid or {}))
    bank = make_bank(width, height, pixel_size_mm, options=options, bank=initial)
    store = PatchStore(fe.patch_half_px)
    hist_frame, hist_mean, hist_bounds, hist_ng, hist_nf = [], [], [], [], []
    collapse = None
    t_prev = None
    processed = 0
    filter_time = 0.0
    started = time.perf_counter()
    for k, (t_s, image) in enumerate(frames):
        if max_frames is not None and k >= max_frames:
            break
        if image is None:
            continue
        if image.shape[:2] != (height, width):
            raise InputError(f"frame {k} is {image.shape[1]}x{image.shape[0]}, expected {width}x{height}")
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        t0 = time.perf_counter()
        if t_prev is not None:
            dt = float(t_s - t_prev)
            if not dt > 0:
                raise InputError(f"frame times must increase (frame {k}: dt = {dt} s)")
            bank.predict(dt)
        ids, uv_pred, cov = bank.predict_measurements()
        filter_time += time.perf_counter() - t0
        uv, found = active_search(image, store.patches, ids, uv_pred, cov, fe)
        t0 = time.perf_counter()
        report = bank.update(ids, uv, found)
        filter_time += time.perf_counter() - t0
        for fid in report.deleted_feature_ids:
            store.patches.pop(int(fid), None)
        needed = fe.min_visible - int(report.num_used)
        if needed > 0:
            avoid = np.vstack([uv_pred, uv[found]]) if len(ids) else np.zeros((0, 2))
            new_uv = new_corners(image, avoid, needed if k == 0 else min(needed, fe.max_new_per_frame), fe,
                                  fe.patch_half_px)
            keep = [i for i, p in enumerate(new_uv) if store.cut(image, p) is not None]
            if keep:
                new_uv = new_uv[keep]
                new_ids = bank.add_features(new_uv)
                for fid, p in zip(new_ids, new_uv):
                    store.patches[int(fid)] = store.cut(image, p).copy()
        t_prev = t_s
        processed += 1
        hist_frame.append(k)
        hist_mean.append(np.asarray(bank.calibration_mean))
        hist_bounds.append(np.asarray(bank.calibration_bounds_99()))
        hist_ng.append(bank.num_gaussians)
        hist_nf.append(int(report.num_used))
        if collapse is None and bank.num_gaussians == 1:
            collapse = k
        if progress:
            progress(k, bank)
    if processed == 0:
        raise InputError("no frames to process")
    elapsed = time.perf_counter() - started
    warnings = []
    if bank.num_gaussians > 1:
        warnings.append(f"{bank.num_gaussians} Gaussians remain: the sequence did not single out one calibration "
                        "(move more, with rotation and translation, through a textured scene)")
    if np.median(hist_nf) < 0.5 * fe.min_visible:
        warnings.append(f"few features matched per frame (median {np.median(hist_nf):.0f}); the scene may lack texture")
    return SelfCalibResult(
        mean=np.asarray(bank.calibration_mean), bounds_99=np.asarray(bank.calibration_bounds_99()),
        covariance=np.asarray(bank.calibration_cov), image_size=(width, height),
        pixel_size_mm=tuple(float(x) for x in np.broadcast_to(np.asarray(pixel_size_mm, float).reshape(-1), (2,))),
        frames_processed=processed, gaussians_initial=len(initial), gaussians_left=bank.num_gaussians,
        frames_per_s=processed / elapsed if elapsed > 0 else float("inf"), collapse_frame=collapse,
        history_frame=np.asarray(hist_frame), history_mean=np.asarray(hist_mean),
        history_bounds=np.asarray(hist_bounds), history_gaussians=np.asarray(hist_ng),
        history_features=np.asarray(hist_nf), warnings=warnings)


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
