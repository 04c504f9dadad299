"""Tests of the camera models (rscalib.CameraModel) and the OpenCV conversions.

Oracles: cv2.projectPoints / cv2.fisheye.projectPoints for the pinhole models, a NumPy
implementation (written here, from docs/conventions.md) of Civera's radial model, and central finite
differences of project() for the Jacobians.
"""
import pickle

import cv2
import numpy as np
import pytest

import rscalib
from rscalib import CameraModel, InputError
from rscalib.io.cameras import camera_from_opencv, opencv_matrices

# The camera of Civera et al. 2009: 320x240, pixel 0.0112 mm.
CIVERA_PARAMS = [194.06, 160.22, 128.87, 0.06333, 0.0139]
CIVERA_PIXEL_MM = [0.0112, 0.0112]


def radtan_camera(rng):
    fx = rng.uniform(400.0, 700.0)
    params = [fx, fx * rng.uniform(0.98, 1.02), rng.uniform(300.0, 340.0), rng.uniform(220.0, 260.0),
              rng.uniform(-0.3, 0.1), rng.uniform(-0.1, 0.15), rng.uniform(-2e-3, 2e-3),
              rng.uniform(-2e-3, 2e-3), rng.uniform(-0.05, 0.05)]
    return CameraModel("pinhole-radtan", params, 640, 480)


def equidistant_camera(rng):
    fx = rng.uniform(250.0, 400.0)
    params = [fx, fx * rng.uniform(0.98, 1.02), rng.uniform(300.0, 340.0), rng.uniform(220.0, 260.0),
              rng.uniform(-0.05, 0.1), rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02),
              rng.uniform(-0.01, 0.01)]
    return CameraModel("pinhole-equidistant", params, 640, 480)


def civera_camera():
    return CameraModel("civera-radial", CIVERA_PARAMS, 320, 240, CIVERA_PIXEL_MM)


def random_points(rng, count, half_fov_x, half_fov_y):
    z = rng.uniform(0.5, 5.0, count)
    x = np.tan(rng.uniform(-half_fov_x, half_fov_x, count)) * z
    y = np.tan(rng.uniform(-half_fov_y, half_fov_y, count)) * z
    return np.c_[x, y, z]


def pixel_grid(width, height, step):
    u, v = np.meshgrid(np.arange(0.0, width, step), np.arange(0.0, height, step))
    return np.c_[u.ravel(), v.ravel()]


# --------------------------------------------------------------------------- OpenCV agreement


@pytest.mark.parametrize("seed", range(6))
def test_radtan_projection_matches_cv2(seed):
    rng = np.random.default_rng(seed)
    camera = radtan_camera(rng)
    K, dist = opencv_matrices(camera)
    assert dist.shape == (5,)
    points = random_points(rng, 500, np.radians(35), np.radians(27))
    expected, _ = cv2.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
    got = camera.project(points)
    assert got.shape == (500, 2)
    np.testing.assert_allclose(got, expected.reshape(-1, 2), rtol=0, atol=1e-9)


def test_radtan_with_4_and_8_parameters_matches_cv2():
    rng = np.random.default_rng(20)
    points = random_points(rng, 200, np.radians(30), np.radians(25))
    for params in ([520.0, 515.0, 320.5, 241.0],
                   [520.0, 515.0, 320.5, 241.0, -0.21, 0.07, 1.5e-3, -8e-4]):
        camera = CameraModel("pinhole-radtan", params, 640, 480)
        assert camera.params.shape == (9,)
        np.testing.assert_array_equal(camera.params[:len(params)], params)
        np.testing.assert_array_equal(camera.params[len(params):], 0.0)
        K = np.array([[params[0], 0, params[2]], [0, params[1], params[3]], [0, 0, 1.0]])
        dist = np.r_[params[4:], np.zeros(9 - len(params))][:5]
        expected, _ = cv2.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
        np.testing.assert_allclose(camera.project(points), expected.reshape(-1, 2), rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_equidistant_projection_matches_cv2_fisheye(seed):
    rng = np.random.default_rng(100 + seed)
    camera = equidistant_camera(rng)
    K, dist = opencv_matrices(camera)
    assert dist.shape == (4,)
    points = random_points(rng, 500, np.radians(60), np.radians(50))
    points = np.r_[points, [[0.0, 0.0, 2.0], [1e-9, -1e-9, 1.0]]]  # on and next to the axis
    expected, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(camera.project(points), expected.reshape(-1, 2), rtol=0, atol=1e-9)


def test_single_point_gives_single_pixel():
    camera = radtan_camera(np.random.default_rng(1))
    uv = camera.project(np.array([0.1, -0.2, 2.0]))
    assert uv.shape == (2,)
    np.testing.assert_array_equal(uv, camera.project(np.array([[0.1, -0.2, 2.0]]))[0])
    assert camera.unproject(uv).shape == (3,)


# --------------------------------------------------------------------------- round trips


def all_cameras(rng):
    return [radtan_camera(rng), equidistant_camera(rng), civera_camera()]


@pytest.mark.parametrize("seed", range(3))
def test_unproject_of_project_is_normalised_point(seed):
    rng = np.random.default_rng(200 + seed)
    for camera in all_cameras(rng):
        if camera.model == "civera-radial":
            points = random_points(rng, 300, np.radians(35), np.radians(28))
        else:
            points = random_points(rng, 300, np.radians(30), np.radians(24))
        ray = camera.unproject(camera.project(points))
        assert ray.shape == (300, 3)
        np.testing.assert_array_equal(ray[:, 2], 1.0)
        np.testing.assert_allclose(ray, points / points[:, 2:], rtol=0, atol=1e-9, err_msg=camera.model)


@pytest.mark.parametrize("seed", range(3))
def test_project_of_unproject_is_identity_over_the_image(seed):
    rng = np.random.default_rng(300 + seed)
    for camera in all_cameras(rng):
        uv = pixel_grid(camera.width, camera.height, 16.0) + rng.uniform(0, 1, 2)
        ray = camera.unproject(uv)
        assert np.all(np.isfinite(ray)), camera.model
        np.testing.assert_allclose(camera.project(ray), uv, rtol=0, atol=1e-9, err_msg=camera.model)
        # Any depth along the ray projects to the same pixel.
        np.testing.assert_allclose(camera.project(3.7 * ray), uv, rtol=0, atol=1e-9, err_msg=camera.model)


def test_fisheye_pixel_beyond_90_degrees_unprojects_to_nan():
    camera = CameraModel("pinhole-equidistant", [100.0, 100.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0], 640, 480)
    # theta_d = 2 rad > pi/2 with no distortion: no ray in front of the camera.
    ray = camera.unproject(np.array([320.0 + 200.0, 240.0]))
    assert np.all(np.isnan(ray))


# --------------------------------------------------------------------------- Jacobians


def numeric_jacobians(camera, points, h_point=1e-6):
    n = len(points)
    params = np.asarray(camera.params)
    d_point = np.empty((n, 2, 3))
    for j in range(3):
        step = np.zeros(3)
        step[j] = h_point
        d_point[:, :, j] = (camera.project(points + step) - camera.project(points - step)) / (2 * h_point)
    d_params = np.empty((n, 2, params.size))
    for j in range(params.size):
        h = 1e-6 * max(1.0, abs(params[j]))
        plus, minus = params.copy(), params.copy()
        plus[j] += h
        minus[j] -= h
        cam_plus = CameraModel(camera.model, plus, camera.width, camera.height, camera.pixel_size_mm)
        cam_minus = CameraModel(camera.model, minus, camera.width, camera.height, camera.pixel_size_mm)
        d_params[:, :, j] = (cam_plus.project(points) - cam_minus.project(points)) / (2 * h)
    return d_point, d_params


@pytest.mark.parametrize("seed", range(2))
def test_jacobians_match_finite_differences(seed):
    rng = np.random.default_rng(400 + seed)
    for camera in all_cameras(rng):
        points = random_points(rng, 40, np.radians(30), np.radians(24))
        points = np.r_[points, [[0.0, 0.0, 1.5]]]  # on the optical axis
        uv, d_point, d_params = camera.project_with_jacobians(points)
        num_params = len(camera.params)
        assert d_point.shape == (len(points), 2, 3)
        assert d_params.shape == (len(points), 2, num_params)
        np.testing.assert_allclose(uv, camera.project(points), rtol=0, atol=1e-10)
        fd_point, fd_params = numeric_jacobians(camera, points)
        scale_point = np.abs(fd_point).max()
        np.testing.assert_allclose(d_point, fd_point, rtol=0, atol=1e-6 * scale_point,
                                   err_msg=f"{camera.model} d/dpoint")
        for j in range(num_params):
            scale = max(1.0, np.abs(fd_params[:, :, j]).max())
            np.testing.assert_allclose(d_params[:, :, j], fd_params[:, :, j], rtol=0, atol=1e-6 * scale,
                                       err_msg=f"{camera.model} d/d{camera.param_names[j]}")


def test_jacobians_known_values_pinhole():
    # Without distortion: u = fx x/z + cx, so du/dx = fx/z, du/dz = -fx x/z^2, du/dfx = x/z.
    camera = CameraModel("pinhole-radtan", [500.0, 400.0, 320.0, 240.0], 640, 480)
    X = np.array([[0.2, -0.1, 2.0]])
    _, d_point, d_params = camera.project_with_jacobians(X)
    np.testing.assert_allclose(d_point[0], [[250.0, 0.0, -25.0], [0.0, 200.0, 10.0]], rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(d_params[0, :, :4], [[0.1, 0.0, 1.0, 0.0], [0.0, -0.05, 0.0, 1.0]],
                               rtol=1e-14, atol=1e-14)


# --------------------------------------------------------------------------- civera-radial


def civera_undistort_ref(uv_d, params=CIVERA_PARAMS, pixel_mm=CIVERA_PIXEL_MM):
    f, cx, cy, k1, k2 = params
    du, dv = uv_d[:, 0] - cx, uv_d[:, 1] - cy
    rd2 = (pixel_mm[0] * du) ** 2 + (pixel_mm[1] * dv) ** 2
    s = 1.0 + k1 * rd2 + k2 * rd2**2
    return np.c_[cx + du * s, cy + dv * s]


def civera_distort_ref(uv_u, params=CIVERA_PARAMS, pixel_mm=CIVERA_PIXEL_MM):
    """Undistorted -> distorted: r_u = r_d (1 + k1 r_d^2 + k2 r_d^4) solved for r_d by bisection
    (monotonic for k1, k2 >= 0, and r_d <= r_u), then two Newton polishing steps."""
    f, cx, cy, k1, k2 = params
    du, dv = uv_u[:, 0] - cx, uv_u[:, 1] - cy
    ru = np.hypot(pixel_mm[0] * du, pixel_mm[1] * dv)
    g = lambda r: r * (1.0 + k1 * r**2 + k2 * r**4) - ru  # noqa: E731
    lo, hi = np.zeros_like(ru), ru.copy()
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        below = g(mid) < 0
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    rd = 0.5 * (lo + hi)
    for _ in range(2):
        rd = rd - g(rd) / (1.0 + 3 * k1 * rd**2 + 5 * k2 * rd**4)
    scale = np.where(ru > 0, rd / np.where(ru > 0, ru, 1.0), 1.0)
    return np.c_[cx + du * scale, cy + dv * scale]


def test_civera_reference_is_self_consistent():
    uv = pixel_grid(320, 240, 10.0)
    np.testing.assert_allclose(civera_distort_ref(civera_undistort_ref(uv)), uv, rtol=0, atol=1e-10)
    # Barrel distortion in this model: undistorted pixels are further from the centre.
    r_d = np.hypot(uv[:, 0] - 160.22, uv[:, 1] - 128.87)
    r_u = np.hypot(*(civera_undistort_ref(uv) - [160.22, 128.87]).T)
    assert np.all(r_u >= r_d) and r_u.max() > 1.5 * r_d.max()


def test_civera_undistort_distort_project_match_reference():
    camera = civera_camera()
    uv_d = pixel_grid(320, 240, 4.0) + 0.37
    uv_d = np.r_[uv_d, [[160.22, 128.87], [0.0, 0.0], [319.0, 239.0]]]
    uv_u_ref = civera_undistort_ref(uv_d)
    np.testing.assert_allclose(camera.undistort(uv_d), uv_u_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(camera.distort(uv_u_ref), uv_d, rtol=0, atol=1e-9)
    np.testing.assert_allclose(camera.distort(camera.undistort(uv_d)), uv_d, rtol=0, atol=1e-9)

    # distort on an undistorted-pixel grid (not built from distorted pixels) against bisection.
    uv_u = pixel_grid(600, 500, 7.0) - [140.0, 130.0]
    np.testing.assert_allclose(camera.distort(uv_u), civera_distort_ref(uv_u), rtol=0, atol=1e-9)

    # project: camera-frame points along the rays of the grid pixels, at random depths.
    f, cx, cy = CIVERA_PARAMS[:3]
    depth = np.random.default_rng(5).uniform(0.5, 5.0, len(uv_d))
    points = np.c_[(uv_u_ref[:, 0] - cx) / f * depth, (uv_u_ref[:, 1] - cy) / f * depth, depth]
    np.testing.assert_allclose(camera.project(points), uv_d, rtol=0, atol=1e-9)
    ray = camera.unproject(uv_d)
    np.testing.assert_allclose(ray, points / depth[:, None], rtol=0, atol=1e-12)


def test_civera_single_pixel_and_other_models_refuse_distort():
    camera = civera_camera()
    uv = np.array([20.0, 30.0])
    assert camera.undistort(uv).shape == (2,)
    np.testing.assert_allclose(camera.undistort(uv), civera_undistort_ref(uv[None])[0], rtol=0, atol=1e-9)
    radtan = radtan_camera(np.random.default_rng(0))
    with pytest.raises(InputError):
        radtan.distort(uv)
    with pytest.raises(InputError):
        radtan.undistort(uv)


def test_civera_non_invertible_distortion_gives_nan():
    # k1 < 0: r_d (1 + k1 r_d^2) peaks at r_d = 1/sqrt(-3 k1); beyond its maximum r_u has no r_d.
    camera = CameraModel("civera-radial", [200.0, 160.0, 120.0, -0.5, 0.0], 320, 240, [0.0112, 0.0112])
    r_max_mm = (1 / np.sqrt(1.5)) * (1 - 0.5 / 1.5)
    far = 160.0 + 1.5 * r_max_mm / 0.0112
    assert np.all(np.isnan(camera.distort(np.array([far, 120.0]))))
    assert np.all(np.isnan(camera.project(np.array([(far - 160.0) / 200.0, 0.0, 1.0]))))
    near = np.array([[160.0 + 0.3 * r_max_mm / 0.0112, 120.0]])
    back = camera.undistort(camera.distort(near))
    np.testing.assert_allclose(back, near, rtol=0, atol=1e-9)


def civera_distort_on_first_branch(params, pixel_mm, uv_u):
    """Reference for any k1, k2: the root r_d of r_d (1 + k1 r_d^2 + k2 r_d^4) = r_u on the branch
    [0, r_peak) where that function increases from 0 (r_peak: first zero of its derivative);
    None when r_u is beyond the branch's maximum (no invertible distorted pixel)."""
    f, cx, cy, k1, k2 = params
    d = (np.asarray(uv_u, dtype=float) - [cx, cy])
    ru = np.hypot(pixel_mm[0] * d[0], pixel_mm[1] * d[1])
    g = lambda r: r * (1.0 + k1 * r**2 + k2 * r**4)  # noqa: E731
    r = np.linspace(0.0, 20.0, 200001)
    decreasing = np.nonzero(1.0 + 3 * k1 * r**2 + 5 * k2 * r**4 <= 0)[0]
    r_peak = r[decreasing[0]] if decreasing.size else r[-1]
    if ru >= g(r_peak):
        return None
    lo, hi = 0.0, r_peak
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) < ru else (lo, mid)
    return np.array([cx, cy]) + d * (0.5 * (lo + hi) / ru)


@pytest.mark.parametrize("k1, k2, uv_u", [
    # k1 > 0, k2 < 0: Newton started at r_d = r_u overshoots; a root exists on the increasing branch.
    (0.2866337314082037, -0.02487633235792068, [398.99563135, 131.23865569]),
    (0.10883090293682163, -0.002060835864481775, [-153.53333346, 499.96051358]),
    (0.3, -0.025, [420.0, 120.0]),
    (0.3, -0.025, [400.0, 120.0]),
])
def test_civera_distort_with_negative_k2_inverts_undistort(k1, k2, uv_u):
    params = [200.0, 160.0, 120.0, k1, k2]
    camera = CameraModel("civera-radial", params, 320, 240, [0.0112, 0.0112])
    expected = civera_distort_on_first_branch(params, [0.0112, 0.0112], uv_u)
    assert expected is not None  # these undistorted pixels do have a distorted pixel
    got = camera.distort(np.array(uv_u))
    # Whatever distort returns, a finite answer must map back onto the input ...
    if np.all(np.isfinite(got)):
        np.testing.assert_allclose(camera.undistort(got), uv_u, rtol=0, atol=1e-9,
                                   err_msg=f"distort({uv_u}) = {got} is not an inverse of undistort")
    # ... and here it must be the root on the increasing branch (a NaN would be wrong as well).
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)


def test_civera_distort_random_coefficients_finite_results_are_inverses():
    # Only signs where Newton from r_d = r_u is safe (k2 >= 0), many k1 of either sign.
    rng = np.random.default_rng(77)
    for _ in range(50):
        params = [200.0, 160.0, 120.0, rng.uniform(-0.5, 0.5), rng.uniform(0.0, 0.1)]
        camera = CameraModel("civera-radial", params, 320, 240, [0.0112, 0.0112])
        uv = np.c_[rng.uniform(-300, 600, 100), rng.uniform(-300, 500, 100)]
        got = camera.distort(uv)
        ok = np.all(np.isfinite(got), axis=1)
        np.testing.assert_allclose(camera.undistort(got[ok]), uv[ok], rtol=0, atol=1e-8)
        if params[3] >= 0:  # monotonic everywhere: always invertible
            assert ok.all()


# --------------------------------------------------------------------------- bad input, conversions


def test_bad_input_raises_input_error():
    with pytest.raises(InputError, match="unknown camera model"):
        CameraModel("pinhole-fancy", [500.0, 500.0, 320.0, 240.0], 640, 480)
    with pytest.raises(InputError, match="parameters"):
        CameraModel("pinhole-radtan", [500.0, 500.0, 320.0, 240.0, 0.1, 0.2], 640, 480)
    with pytest.raises(InputError, match="parameters"):
        CameraModel("pinhole-equidistant", [500.0, 500.0, 320.0, 240.0, 0.1], 640, 480)
    with pytest.raises(InputError, match="parameters"):
        CameraModel("civera-radial", [194.0, 160.0, 120.0, 0.06], 320, 240, CIVERA_PIXEL_MM)
    with pytest.raises(InputError, match="pixel size"):
        CameraModel("civera-radial", CIVERA_PARAMS, 320, 240)
    with pytest.raises(InputError):
        CameraModel("civera-radial", CIVERA_PARAMS, 320, 240, [0.0112, -0.0112])
    with pytest.raises(InputError):
        CameraModel("pinhole-radtan", [500.0, 500.0, 320.0, np.nan], 640, 480)
    with pytest.raises(InputError):
        CameraModel("pinhole-radtan", [-500.0, 500.0, 320.0, 240.0], 640, 480)
    with pytest.raises(InputError):
        CameraModel("pinhole-radtan", [500.0, 500.0, 320.0, 240.0], 0, 480)
    camera = radtan_camera(np.random.default_rng(0))
    with pytest.raises(InputError):
        camera.project(np.zeros((4, 2)))
    with pytest.raises(InputError):
        camera.unproject(np.zeros((4, 3)))
    assert issubclass(InputError, ValueError)


def test_points_behind_the_camera_give_nan():
    rng = np.random.default_rng(1)
    points = np.array([[0.1, 0.2, -1.0], [0.0, 0.0, 0.0], [0.3, -0.1, 0.0], [0.1, 0.1, 1.0]])
    for camera in all_cameras(rng):
        uv = camera.project(points)
        assert np.all(np.isnan(uv[:3])), camera.model
        assert np.all(np.isfinite(uv[3])), camera.model
        uv_j, d_point, d_params = camera.project_with_jacobians(points)
        assert np.all(np.isnan(uv_j[:3])) and np.all(np.isnan(d_point[:3])) and np.all(np.isnan(d_params[:3]))
        assert np.all(np.isfinite(d_point[3])) and np.all(np.isfinite(d_params[3]))


def test_camera_from_opencv_round_trip():
    K = np.array([[512.0, 0.0, 318.2], [0.0, 509.5, 242.7], [0.0, 0.0, 1.0]])
    for dist in ([-0.2, 0.05, 1e-3, -2e-4, 0.01], [-0.2, 0.05, 1e-3, -2e-4],
                 [-0.2, 0.05, 1e-3, -2e-4, 0.01, 0.0, 0.0, 0.0]):
        camera = camera_from_opencv(K, np.array(dist), 640, 480)
        assert camera.model == "pinhole-radtan" and (camera.width, camera.height) == (640, 480)
        K2, dist2 = opencv_matrices(camera)
        np.testing.assert_array_equal(K2, K)
        np.testing.assert_array_equal(dist2, np.r_[dist, np.zeros(5)][:5])
    fisheye_dist = np.array([0.05, -0.01, 0.003, -0.001])
    camera = camera_from_opencv(K, fisheye_dist.reshape(4, 1), 640, 480, model="pinhole-equidistant")
    K2, dist2 = opencv_matrices(camera)
    np.testing.assert_array_equal(K2, K)
    np.testing.assert_array_equal(dist2, fisheye_dist)
    with pytest.raises(InputError):
        camera_from_opencv(K, [-0.2, 0.05, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0], 640, 480)  # rational term
    with pytest.raises(InputError):
        camera_from_opencv(K, [0.1, 0.2, 0.3], 640, 480, model="pinhole-equidistant")
    with pytest.raises(InputError):
        camera_from_opencv(np.array([[500.0, 2.0, 320], [0, 500, 240], [0, 0, 1]]), [0.0] * 4, 640, 480)
    with pytest.raises(InputError):
        opencv_matrices(civera_camera())


def test_camera_pickles():
    rng = np.random.default_rng(2)
    points = random_points(rng, 20, 0.4, 0.3)
    for camera in all_cameras(rng):
        restored = pickle.loads(pickle.dumps(camera))
        assert isinstance(restored, CameraModel)
        assert restored.model == camera.model
        assert (restored.width, restored.height) == (camera.width, camera.height)
        np.testing.assert_array_equal(restored.params, camera.params)
        np.testing.assert_array_equal(restored.pixel_size_mm, camera.pixel_size_mm)
        np.testing.assert_array_equal(restored.project(points), camera.project(points))
        assert restored.param_names == camera.param_names
        assert camera.model in repr(camera)
    assert rscalib.CameraModel is CameraModel
