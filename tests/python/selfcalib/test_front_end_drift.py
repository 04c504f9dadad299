"""The image front end's track error against an independent oracle: a textured plane seen by a
camera walking towards it (issue 11, docs/sog.md §17). Frame 0 is the texture itself; frame k is
it warped by the plane's homography H_k = K (I - C_k nᵀ / d) K⁻¹ (camera centre C_k, plane
nᵀX = d in the first camera's frame), so a feature's true pixel in frame k is H_k applied to its
first pixel. Both front ends get the same predictions (truth + 1 px noise) and covariances."""
import cv2
import numpy as np
import pytest

from rscalib.errors import InputError
from rscalib.selfcalib.front_end import FrontEndOptions, ImageFrontEnd, new_corners

WIDTH, HEIGHT = 320, 240
K = np.array([[200.0, 0.0, 160.0], [0.0, 200.0, 120.0], [0.0, 0.0, 1.0]])
FRAMES = 40


def texture(seed: int = 5) -> np.ndarray:
    """Blobs at two scales: corners everywhere, smooth enough to interpolate when magnified."""
    rng = np.random.default_rng(seed)
    fine = cv2.GaussianBlur(rng.uniform(0, 1, (HEIGHT, WIDTH)).astype(np.float32), (0, 0), 1.5)
    coarse = cv2.GaussianBlur(rng.uniform(0, 1, (HEIGHT, WIDTH)).astype(np.float32), (0, 0), 4.0)
    image = fine / fine.std() + 0.7 * coarse / coarse.std()
    return cv2.normalize(image, None, 20, 235, cv2.NORM_MINMAX).astype(np.uint8)


def homographies() -> list[np.ndarray]:
    """The camera moves 45 % of the way towards a plane 2 m ahead, tilted 35° about the vertical
    axis, and 0.2 m sideways: the view magnifies 1.4x at the centre, 1.0x to 2.3x across the image (along its middle row)."""
    tilt = np.deg2rad(35.0)
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    distance = 2.0
    out = []
    for k in range(FRAMES):
        a = k / (FRAMES - 1)
        centre = np.array([0.2 * a, 0.0, 0.9 * a])
        out.append(K @ (np.eye(3) - np.outer(centre, normal) / distance) @ np.linalg.inv(K))
    return out


def apply(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    x = np.c_[uv, np.ones(len(uv))] @ H.T
    return x[:, :2] / x[:, 2:]


def track_errors(options: FrontEndOptions) -> tuple[np.ndarray, np.ndarray]:
    """Per frame: RMS error (px) of the features found and the share found."""
    rng = np.random.default_rng(11)
    base = texture()
    front_end = ImageFrontEnd(options, (WIDTH, HEIGHT))
    uv0 = new_corners(base, np.zeros((0, 2)), 60, front_end.options, 12)
    Hs = homographies()
    # features that stay 15 px inside the image to the last frame
    last = apply(Hs[-1], uv0)
    uv0 = uv0[np.all((last > 15) & (last < [WIDTH - 15, HEIGHT - 15]), axis=1)]
    ids = np.arange(len(uv0))
    front_end.track(base, ids, uv0)
    cov = np.repeat(np.eye(2)[None] * 4.0, len(ids), axis=0)
    rms, share = [], []
    for H in Hs[1:]:
        image = cv2.warpPerspective(base, H, (WIDTH, HEIGHT), flags=cv2.INTER_CUBIC)
        image = np.clip(image + rng.normal(0, 1.0, image.shape), 0, 255).astype(np.uint8)
        truth = apply(H, uv0)
        uv, found = front_end.measure(image, ids, truth + rng.normal(0, 1.0, truth.shape), cov)
        rms.append(np.sqrt(np.mean((uv[found] - truth[found]) ** 2)) if found.any() else np.nan)
        share.append(found.mean())
    return np.array(rms), np.array(share)


def test_the_oracle_magnifies_the_view_unevenly():
    last = homographies()[-1]
    def magnification(u):
        ends = apply(last, np.array([[u - 1.0, 120.0], [u + 1.0, 120.0]]))
        return np.linalg.norm(ends[1] - ends[0]) / 2.0
    assert 1.3 < magnification(160.0) < 1.6
    assert magnification(260.0) - magnification(60.0) > 1.0    # perspective across the image


@pytest.mark.parametrize("warp_model", ["affine", "homography"])
def test_tracked_front_end_does_not_drift_while_the_default_does(warp_model):
    tracked_rms, tracked_found = track_errors(FrontEndOptions(subpixel="tracked", warp_model=warp_model))
    default_rms, _ = track_errors(FrontEndOptions(subpixel="affine"))   # the default before issue 11
    assert len(tracked_rms) == FRAMES - 1
    # the error does not grow: every frame within 0.08 px (1 grey level of noise)
    assert np.nanmax(tracked_rms) < 0.08
    assert np.mean(tracked_rms[-10:]) < 0.05
    assert tracked_found[-10:].min() >= 0.7
    # the default (the patch unwarped for NCC, ECC from the identity, parabola fallback) drifts
    assert np.nanmean(default_rms[-10:]) > 3 * np.mean(tracked_rms[-10:])
    assert np.nanmean(default_rms[-10:]) > 2 * np.nanmean(default_rms[:10])


def test_unknown_front_end_modes_are_input_errors():
    with pytest.raises(InputError, match="subpixel"):
        ImageFrontEnd(FrontEndOptions(subpixel="tracking"), (WIDTH, HEIGHT))
    with pytest.raises(InputError, match="warp_model"):
        ImageFrontEnd(FrontEndOptions(subpixel="tracked", warp_model="projective"), (WIDTH, HEIGHT))
