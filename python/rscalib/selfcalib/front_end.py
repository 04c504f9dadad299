"""The image front end of self-calibration: corners where the map is thin, patches stored at
initialisation, and active search by normalised cross-correlation inside each feature's 99 %
prediction ellipse, refined to sub-pixel by ECC affine alignment (docs/formulation.md §13,
docs/sog.md §1); FrontEndOptions.subpixel "tracked" (the default) also keeps each feature's warp
between frames (no drift as the view magnifies).
:class:`ImageFrontEnd` is the measurement source of :func:`rscalib.selfcalib.driver.run_bank` for
images."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Optional

import cv2
import numpy as np

from .options import FrontEndOptions

if TYPE_CHECKING:
    from .driver import FrameSearch

CHI2_2DOF_99 = 9.210340371976184


def _shift(du: float, dv: float) -> np.ndarray:
    return np.array([[1.0, 0.0, du], [0.0, 1.0, dv], [0.0, 0.0, 1.0]])


class WarpedTemplate:
    """A feature's first view, ``reference`` (float32, square, centred on the feature's first pixel),
    and ``warp`` (3x3, fixing the origin): offsets around the feature in that view -> offsets in the
    view it was last matched in; affine or a homography (subpixel "tracked")."""

    def __init__(self, reference: np.ndarray) -> None:
        self.reference = reference
        self.warp = np.eye(3)

    @property
    def half(self) -> int:
        return self.reference.shape[0] // 2

    def search_patch(self, half: int) -> np.ndarray:
        """The reference as the last match saw it: warped by ``warp``, (2 half + 1)² pixels."""
        to_patch = _shift(half, half) @ self.warp @ _shift(-self.half, -self.half)
        return cv2.warpPerspective(self.reference, to_patch, (2 * half + 1, 2 * half + 1), flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)

    def refine(self, image: np.ndarray, u: float, v: float, options: FrontEndOptions, margin: int = 3
               ) -> Optional[tuple[float, float]]:
        """ECC alignment of the reference's central (2 refine_half_px + 1)² pixels near (u, v), started
        from ``warp``; the refined centre (and ``warp`` updated), or None when ECC fails, the warp is
        implausible or moved the centre more than max_refine_shift_px."""
        rh, r = options.refine_half_px, self.half
        template = self.reference[r - rh:r + rh + 1, r - rh:r + rh + 1]
        reach = int(math.ceil(rh * np.linalg.norm(self.warp[:2, :2], 2) * 1.2)) + margin
        x0, y0 = max(int(round(u)) - reach, 0), max(int(round(v)) - reach, 0)
        x1, y1 = min(int(round(u)) + reach, image.shape[1] - 1), min(int(round(v)) + reach, image.shape[0] - 1)
        if x1 - x0 < 2 * rh or y1 - y0 < 2 * rh:
            return None
        region = image[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
        homography = options.warp_model == "homography"
        start = _shift(u - x0, v - y0) @ self.warp @ _shift(-rh, -rh)   # template pixels -> region pixels
        try:
            _, found = cv2.findTransformECC(
                template, region, (start if homography else start[:2]).astype(np.float32),
                cv2.MOTION_HOMOGRAPHY if homography else cv2.MOTION_AFFINE,
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-4), None, 1)
        except cv2.error:
            return None
        found = found.astype(np.float64) if homography else np.vstack([found.astype(np.float64), [0.0, 0.0, 1.0]])
        centre = found @ [rh, rh, 1.0]
        if not centre[2] > 0:
            return None
        centre_u, centre_v = centre[:2] / centre[2] + [x0, y0]
        warp = _shift(x0 - centre_u, y0 - centre_v) @ found @ _shift(rh, rh)
        warp /= warp[2, 2]
        linear = warp[:2, :2]          # the warp's Jacobian at the feature
        scales = np.linalg.svd(linear, compute_uv=False)
        change = np.linalg.svd(linear @ np.linalg.inv(self.warp[:2, :2]), compute_uv=False)
        if (np.linalg.det(linear) <= 0 or scales[0] > options.max_warp_scale or scales[1] < 1 / options.max_warp_scale
                or change[0] > options.max_warp_change or change[1] < 1 / options.max_warp_change
                or np.linalg.norm(warp[2, :2]) * rh > 0.25):    # the template's far side would fold
            return None
        if math.hypot(centre_u - u, centre_v - v) > options.max_refine_shift_px:
            return None
        self.warp = warp
        return float(centre_u), float(centre_v)


class PatchStore:
    """Each feature's patch (uint8, (2 half + 1)²), or with ``reference_half`` its
    :class:`WarpedTemplate` of that half size."""

    def __init__(self, half: int, reference_half: Optional[int] = None):
        self.half = half
        self.reference_half = reference_half
        self.patches: dict[int, object] = {}

    def cut(self, image: np.ndarray, uv: np.ndarray) -> Optional[np.ndarray]:
        u, v = int(round(uv[0])), int(round(uv[1]))
        h = self.half
        if u - h < 0 or v - h < 0 or u + h >= image.shape[1] or v + h >= image.shape[0]:
            return None
        patch = image[v - h:v + h + 1, u - h:u + h + 1]
        return patch if patch.std() > 2.0 else None   # flat patches cannot be matched

    def add(self, image: np.ndarray, feature_id: int, uv: np.ndarray) -> None:
        if self.reference_half is None:
            self.patches[feature_id] = self.cut(image, uv).copy()
            return
        size = 2 * self.reference_half + 1    # sub-pixel centre; beyond the image edge: replicated
        self.patches[feature_id] = WarpedTemplate(cv2.getRectSubPix(image, (size, size), (float(uv[0]), float(uv[1])),
                                                                    patchType=cv2.CV_32F))


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


def _ncc_peak(image: np.ndarray, patch: np.ndarray, uv_pred: np.ndarray, c: np.ndarray, options: FrontEndOptions
              ) -> Optional[tuple[float, float]]:
    """The NCC peak of ``patch`` inside the 99 % ellipse (covariance ``c``) around ``uv_pred``, with the
    parabola's sub-pixel offset; None below ncc_threshold or when the search window is too small."""
    height, width = image.shape
    half = patch.shape[0] // 2
    extent = np.minimum(np.sqrt(CHI2_2DOF_99 * np.diag(c)), options.max_search_half_px)
    u0, v0 = uv_pred
    x_lo = max(int(math.floor(u0 - extent[0])) - half, 0)
    x_hi = min(int(math.ceil(u0 + extent[0])) + half, width - 1)
    y_lo = max(int(math.floor(v0 - extent[1])) - half, 0)
    y_hi = min(int(math.ceil(v0 + extent[1])) + half, height - 1)
    if x_hi - x_lo + 1 < patch.shape[1] or y_hi - y_lo + 1 < patch.shape[0]:
        return None
    region = image[y_lo:y_hi + 1, x_lo:x_hi + 1]
    scores = cv2.matchTemplate(region.astype(patch.dtype, copy=False), patch, cv2.TM_CCOEFF_NORMED)
    # centres of the candidate windows, and the ellipse test on them
    ys, xs = np.mgrid[0:scores.shape[0], 0:scores.shape[1]]
    du = xs + x_lo + half - u0
    dv = ys + y_lo + half - v0
    info = np.linalg.inv(c + 1e-9 * np.eye(2))
    inside = info[0, 0] * du * du + 2 * info[0, 1] * du * dv + info[1, 1] * dv * dv <= CHI2_2DOF_99
    scores = np.where(inside, scores, -1.0)
    y, x = np.unravel_index(int(np.argmax(scores)), scores.shape)
    if scores[y, x] < options.ncc_threshold:
        return None
    sx, sy = _subpixel_peak(scores, x, y)
    return x + x_lo + half + sx, y + y_lo + half + sy


def active_search(image: np.ndarray, patches: dict, ids: np.ndarray, uv_pred: np.ndarray, cov: np.ndarray,
                  options: FrontEndOptions) -> tuple[np.ndarray, np.ndarray]:
    """NCC match of each feature's patch inside its 99 % ellipse: (uv (n, 2), found (n,))."""
    n = len(ids)
    uv = np.full((n, 2), np.nan)
    found = np.zeros(n, dtype=bool)
    for i in range(n):
        patch = patches.get(int(ids[i]))
        if patch is None or not np.all(np.isfinite(cov[i])):
            continue
        if isinstance(patch, WarpedTemplate):
            peak = _ncc_peak(image, patch.search_patch(options.patch_half_px), uv_pred[i], cov[i], options)
            refined = None if peak is None else patch.refine(image, peak[0], peak[1], options)
            if refined is not None:
                uv[i], found[i] = refined, True
            continue
        peak = _ncc_peak(image, patch, uv_pred[i], cov[i], options)
        if peak is None:
            continue
        uv[i] = peak
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
        self.options = options.scaled(int(image_size[0]))
        # "tracked": the reference covers the search patch down to half scale (moving away)
        reference_half = 2 * max(self.options.patch_half_px, self.options.refine_half_px) + 1 \
            if self.options.subpixel == "tracked" else None
        self.store = PatchStore(self.options.patch_half_px, reference_half)


    def measure(self, frame: np.ndarray, ids: np.ndarray, uv_pred: np.ndarray,
                cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return active_search(frame, self.store.patches, ids, uv_pred, cov, self.options)

    def forget(self, feature_ids: np.ndarray) -> None:
        for fid in feature_ids:
            self.store.patches.pop(int(fid), None)

    def new_features(self, frame: np.ndarray, count: int, search: FrameSearch) -> np.ndarray:
        """Corners away from the predicted and the matched pixels of ``search``, where a patch can be cut."""
        avoid = np.vstack([search.uv_pred, search.uv[search.found]]) if len(search.ids) else np.zeros((0, 2))
        half = self.options.patch_half_px if self.store.reference_half is None \
            else max(self.options.patch_half_px, self.options.refine_half_px)
        uv = new_corners(frame, avoid, count, self.options, half)
        keep = [i for i, p in enumerate(uv) if self.store.cut(frame, p) is not None]
        return uv[keep] if keep else np.zeros((0, 2))

    def track(self, frame: np.ndarray, feature_ids: np.ndarray, uv: np.ndarray) -> None:
        for fid, p in zip(feature_ids, uv):
            self.store.add(frame, int(fid), p)
