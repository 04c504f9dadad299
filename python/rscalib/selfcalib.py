"""Sequential self-calibration from images (SPEC §4; Civera et al. 2009): the image front end of
the SOG filter bank — corners where the map is thin, patches stored at initialisation, active
search by normalised cross-correlation inside each feature's 99 % prediction ellipse — plus the
result, its history, and the conversion of the civera-radial model to OpenCV's.
The filter itself is C++ (rscalib._core.SogBank, docs/sog.md)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable, Optional

import cv2
import numpy as np

from . import _core
from .errors import InputError
from .sog_bank import PAPER_PIXEL_SIZE_MM, initial_bank, make_bank

PARAM_NAMES = ("f", "cx", "cy", "k1", "k2")
CHI2_2DOF_99 = 9.210340371976184


@dataclass
class FrontEndOptions:
    """Image front end (sizes for 320x240; scaled with the image width)."""

    patch_half_px: int = 5            # 11x11 patches, as in Civera's code
    ncc_threshold: float = 0.8
    min_visible: int = 20             # add features while fewer were used in the update
    max_new_per_frame: int = 10
    min_separation_px: float = 20.0   # new corners away from predicted features
    max_search_half_px: float = 60.0  # cap the ellipse's bounding box (first frames span f widely)
    corner_quality: float = 0.01
    # "affine": refine each NCC peak by ECC alignment of the patch under an affine warp (the stored
    # patch is never re-cut, so scale/rotation changes as the camera moves would otherwise bias the
    # match); "parabola": parabola through the NCC peak only.
    subpixel: str = "affine"
    max_refine_shift_px: float = 1.5


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


class _PatchStore:
    def __init__(self, half: int):
        self.half = half
        self.patches: dict[int, np.ndarray] = {}

    def cut(self, image: np.ndarray, uv: np.ndarray) -> Optional[np.ndarray]:
        u, v = int(round(uv[0])), int(round(uv[1]))
        h = self.half
        if u - h < 0 or v - h < 0 or u + h >= image.shape[1] or v + h >= image.shape[0]:
            return None
        patch = image[v - h:v + h + 1, u - h:u + h + 1]
        return patch if patch.std() > 2.0 else None   # flat patches cannot be matched


def _subpixel_peak(scores: np.ndarray, x: int, y: int) -> tuple[float, float]:
    """Parabola through the peak and its neighbours in each direction."""
    dx = dy = 0.0
    if 0 < x < scores.shape[1] - 1:
        a, b, c = scores[y, x - 1], scores[y, x], scores[y, x + 1]
        den = a - 2 * b + c
        dx = 0.5 * (a - c) / den if den < 0 else 0.0
    if 0 < y < scores.shape[0] - 1:
        a, b, c = scores[y - 1, x], scores[y, x], scores[y + 1, x]
        den = a - 2 * b + c
        dy = 0.5 * (a - c) / den if den < 0 else 0.0
    return float(np.clip(dx, -0.5, 0.5)), float(np.clip(dy, -0.5, 0.5))


def _refine_affine(image: np.ndarray, patch: np.ndarray, u: float, v: float, margin: int = 3
                   ) -> Optional[tuple[float, float]]:
    """Enhanced-correlation (ECC) alignment of ``patch`` near (u, v) under an affine warp; the
    refined position of the patch centre, or None when ECC fails or the warp is implausible."""
    h = patch.shape[0] // 2
    size = 2 * (h + margin) + 1
    x0, y0 = int(round(u)) - h - margin, int(round(v)) - h - margin
    if x0 < 0 or y0 < 0 or x0 + size > image.shape[1] or y0 + size > image.shape[0]:
        return None
    region = image[y0:y0 + size, x0:x0 + size].astype(np.float32)
    warp = np.array([[1.0, 0.0, u - h - x0], [0.0, 1.0, v - h - y0]], np.float32)
    try:
        _, warp = cv2.findTransformECC(patch.astype(np.float32), region, warp, cv2.MOTION_AFFINE,
                                       (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-4), None, 1)
    except cv2.error:   # ECC did not converge (e.g. a patch turned flat)
        return None
    if not 0.6 < abs(float(np.linalg.det(warp[:, :2]))) < 1.7:
        return None
    centre = warp.astype(np.float64) @ np.array([h, h, 1.0])
    return float(centre[0] + x0), float(centre[1] + y0)


def active_search(image: np.ndarray, patches: dict, ids: np.ndarray, uv_pred: np.ndarray, cov: np.ndarray,
                  options: FrontEndOptions) -> tuple[np.ndarray, np.ndarray]:
    """NCC match of each feature's patch inside its 99 % ellipse: (uv (n, 2), found (n,))."""
    n = len(ids)
    uv = np.full((n, 2), np.nan)
    found = np.zeros(n, dtype=bool)
    height, width = image.shape
    for i in range(n):
        patch = patches.get(int(ids[i]))
        if patch is None:
            continue
        half = patch.shape[0] // 2
        c = cov[i]
        if not np.all(np.isfinite(c)):
            continue
        extent = np.minimum(np.sqrt(CHI2_2DOF_99 * np.diag(c)), options.max_search_half_px)
        u0, v0 = uv_pred[i]
        x_lo = max(int(math.floor(u0 - extent[0])) - half, 0)
        x_hi = min(int(math.ceil(u0 + extent[0])) + half, width - 1)
        y_lo = max(int(math.floor(v0 - extent[1])) - half, 0)
        y_hi = min(int(math.ceil(v0 + extent[1])) + half, height - 1)
        if x_hi - x_lo + 1 < patch.shape[1] or y_hi - y_lo + 1 < patch.shape[0]:
            continue
        region = image[y_lo:y_hi + 1, x_lo:x_hi + 1]
        scores = cv2.matchTemplate(region, patch, cv2.TM_CCOEFF_NORMED)
        # centres of the candidate windows, and the ellipse test on them
        ys, xs = np.mgrid[0:scores.shape[0], 0:scores.shape[1]]
        du = xs + x_lo + half - u0
        dv = ys + y_lo + half - v0
        info = np.linalg.inv(c + 1e-9 * np.eye(2))
        inside = info[0, 0] * du * du + 2 * info[0, 1] * du * dv + info[1, 1] * dv * dv <= CHI2_2DOF_99
        scores = np.where(inside, scores, -1.0)
        y, x = np.unravel_index(int(np.argmax(scores)), scores.shape)
        if scores[y, x] < options.ncc_threshold:
            continue
        sx, sy = _subpixel_peak(scores, x, y)
        uv[i] = (x + x_lo + half + sx, y + y_lo + half + sy)
        found[i] = True
        if options.subpixel == "affine":
            refined = _refine_affine(image, patch, uv[i, 0], uv[i, 1])
            if refined is not None and math.hypot(refined[0] - uv[i, 0], refined[1] - uv[i, 1]) \
                    <= options.max_refine_shift_px:
                uv[i] = refined
    return uv, found


def _new_corners(image: np.ndarray, avoid_uv: np.ndarray, count: int, options: FrontEndOptions,
                 half: int) -> np.ndarray:
    mask = np.zeros(image.shape, dtype=np.uint8)
    border = half + 2
    mask[border:-border, border:-border] = 255
    for u, v in avoid_uv:
        if np.isfinite(u) and np.isfinite(v):
            cv2.circle(mask, (int(round(u)), int(round(v))), int(options.min_separation_px), 0, -1)
    corners = cv2.goodFeaturesToTrack(image, maxCorners=count, qualityLevel=options.corner_quality,
                                      minDistance=options.min_separation_px, mask=mask)
    return np.zeros((0, 2)) if corners is None else corners.reshape(-1, 2).astype(np.float64)


def self_calibrate(frames: Iterable, image_size: tuple[int, int], *,
                   pixel_size_mm=PAPER_PIXEL_SIZE_MM, options: Optional[_core.SogOptions] = None,
                   front_end: Optional[FrontEndOptions] = None, grid: Optional[dict] = None,
                   max_frames: Optional[int] = None,
                   progress: Optional[Callable[[int, _core.SogBank], None]] = None) -> SelfCalibResult:
    """Run the SOG bank over `frames`: an iterable of (time_s, grayscale uint8 image).

    pixel_size_mm: the sensor's pixel pitch (the distortion model's radii are in mm);
    grid: keyword arguments of rscalib.sog_bank.initial_bank (ranges, counts);
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
    store = _PatchStore(fe.patch_half_px)
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
            new_uv = _new_corners(image, avoid, needed if k == 0 else min(needed, fe.max_new_per_frame), fe,
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
