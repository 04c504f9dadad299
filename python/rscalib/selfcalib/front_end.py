"""The image front end of self-calibration: corners where the map is thin, patches stored at
initialisation, and active search by normalised cross-correlation inside each feature's 99 %
prediction ellipse, refined to sub-pixel by ECC affine alignment (docs/formulation.md §13,
docs/sog.md §1). :class:`ImageFrontEnd` is the measurement source of
:func:`rscalib.selfcalib.driver.run_bank` for images."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

import cv2
import numpy as np

from ..errors import InputError

if TYPE_CHECKING:
    from .driver import FrameSearch

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

    def scaled(self, width: int) -> FrontEndOptions:
        """These options for images ``width`` pixels wide (the sizes above are for 320 px)."""
        scale = width / 320.0
        return FrontEndOptions(**{**self.__dict__,
                                  "patch_half_px": max(3, int(round(self.patch_half_px * max(1.0, scale ** 0.5)))),
                                  "min_separation_px": self.min_separation_px * scale,
                                  "max_search_half_px": self.max_search_half_px * scale})


class PatchStore:
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


def new_corners(image: np.ndarray, avoid_uv: np.ndarray, count: int, options: FrontEndOptions,
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


class ImageFrontEnd:
    """The measurement source of the self-calibration loop for grayscale images (frames are images):
    active search of each feature's stored patch, and new features at corners away from the
    searched ones, whose patches are cut when the bank starts them. ``options`` are for 320 px wide
    images and are scaled to ``image_size``."""

    def __init__(self, options: Optional[FrontEndOptions], image_size: tuple[int, int]) -> None:
        options = options or FrontEndOptions()
        if options.subpixel not in ("affine", "parabola"):
            raise InputError(f"front_end.subpixel must be 'affine' or 'parabola', not {options.subpixel!r}")
        self.options = options.scaled(int(image_size[0]))
        self.store = PatchStore(self.options.patch_half_px)

    def measure(self, frame: np.ndarray, ids: np.ndarray, uv_pred: np.ndarray,
                cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return active_search(frame, self.store.patches, ids, uv_pred, cov, self.options)

    def forget(self, feature_ids: np.ndarray) -> None:
        for fid in feature_ids:
            self.store.patches.pop(int(fid), None)

    def new_features(self, frame: np.ndarray, count: int, search: FrameSearch) -> np.ndarray:
        """Corners away from the predicted and the matched pixels of ``search``, where a patch can be cut."""
        avoid = np.vstack([search.uv_pred, search.uv[search.found]]) if len(search.ids) else np.zeros((0, 2))
        uv = new_corners(frame, avoid, count, self.options, self.options.patch_half_px)
        keep = [i for i, p in enumerate(uv) if self.store.cut(frame, p) is not None]
        return uv[keep] if keep else np.zeros((0, 2))

    def track(self, frame: np.ndarray, feature_ids: np.ndarray, uv: np.ndarray) -> None:
        for fid, p in zip(feature_ids, uv):
            self.store.patches[int(fid)] = self.store.cut(frame, p).copy()
