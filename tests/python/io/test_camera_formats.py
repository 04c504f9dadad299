"""Camera files of other tools (rscalib.io.cameras, rscalib.io.camera_formats): every format and model
written, read back and projected (round trips), and fed to the real consumers where Debian or PyPI
has them:

- OpenCV: cv2.FileStorage and cv2.projectPoints / cv2.fisheye.projectPoints (the venv's opencv);
- mrcal: Debian's python3-mrcal (system Python; `scripts/install-system-deps.sh`): mrcal.cameramodel,
  mrcal.project, mrcal.compute_chessboard_corners on our corners.vnl, and models mrcal wrote;
- COLMAP: pycolmap from PyPI: Reconstruction.read_text on our cameras.txt, Camera.img_from_cam, and
  cameras.txt files pycolmap wrote for each model we read;
- ROS: Debian's python3-camera-calibration-parsers (the C++ camera_calibration_parsers behind
  readCalibration) on our camera_info, and on files with OpenCV's %YAML:1.0 header;
- Kalibr and Gyroflow cannot be installed from PyPI or Debian: their readers are reimplemented from
  their documented fields and equations (Kalibr's ConfigReader field checks; Gyroflow's LensProfile
  fields and its opencv_fisheye / opencv_standard distortion) and serve as the oracle, independently of
  cv2 and of rscalib's own projection.

Projections are compared to 1e-6 px (docs/formats.md has the table)."""
from __future__ import annotations

import json
import shutil
import subprocess
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from rscalib._core import CameraModel
from rscalib.errors import InputError
from rscalib.io.camera_formats.colmap import PIXEL_CENTRE_OFFSET
from rscalib.io.camera_formats.kalibr import refit_without_k3
from rscalib.io.camera_formats.mrcal import regular_grid, write_corners_vnl
from rscalib.io.cameras import CAMERA_FORMATS, load_camera, opencv_matrices, write_camera, write_camera_set

TOLERANCE_PX = 1e-6
SYSTEM_PYTHON = "/usr/bin/python3"

# The OpenCV sample camera (shared/data/opencv_stereo_chessboard README: left, 13 stills), one without
# k3, and an equidistant (fisheye) camera.
CAMERAS = {
    "radtan-k3": CameraModel("pinhole-radtan", [536.07, 536.01, 342.37, 235.53, -0.2651, -0.0466, 0.0018, -0.0003,
                                                0.2522], 640, 480),
    "radtan": CameraModel("pinhole-radtan", [520.0, 521.0, 322.0, 238.5, -0.25, 0.08, 0.001, -0.0005, 0.0], 640, 480),
    "equidistant": CameraModel("pinhole-equidistant", [380.0, 381.0, 641.0, 359.5, 0.03, -0.01, 0.004, -0.001],
                               1280, 720),
}
FILE_NAMES = {"opencv": "camera.yaml", "kalibr": "camchain.yaml", "gyroflow": "profile.json", "ros": "camera_info.yaml",
              "mrcal": "camera.cameramodel", "colmap": "cameras.txt"}


def points_for(camera: CameraModel) -> np.ndarray:
    """Camera-frame points that project all over the image, at several depths."""
    u, v = np.meshgrid(np.linspace(0, camera.width - 1, 9), np.linspace(0, camera.height - 1, 7))
    rays = camera.unproject(np.c_[u.ravel(), v.ravel()])
    rays = rays[np.all(np.isfinite(rays), axis=1)]
    return np.concatenate([rays * depth for depth in (0.5, 2.0, 7.0)])


def cv2_projection(camera: CameraModel, points: np.ndarray) -> np.ndarray:
    """The reference: OpenCV's own projection of the camera."""
    k, dist = opencv_matrices(camera)
    zero = np.zeros(3)
    if camera.model == "pinhole-equidistant":
        uv, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), zero, zero, k, dist)
    else:
        uv, _ = cv2.projectPoints(points.reshape(-1, 1, 3), zero, zero, k, dist)
    return uv.reshape(-1, 2)


def system_python_has(module: str) -> bool:
    if not Path(SYSTEM_PYTHON).exists():
        return False
    return subprocess.run([SYSTEM_PYTHON, "-c", f"import {module}"], capture_output=True).returncode == 0


def run_system_python(script: str, *args) -> str:
    done = subprocess.run([SYSTEM_PYTHON, "-c", textwrap.dedent(script), *map(str, args)], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


needs_mrcal = pytest.mark.skipif(not system_python_has("mrcal"),
                                 reason="Debian's python3-mrcal is not installed (scripts/install-system-deps.sh)")
needs_ros = pytest.mark.skipif(not system_python_has("camera_calibration_parsers"),
                               reason="Debian's python3-camera-calibration-parsers is not installed "
                                      "(scripts/install-system-deps.sh)")


# -- round trips: write -> read -> project, every format and model ---------------------------------


@pytest.mark.parametrize("name", CAMERAS)
@pytest.mark.parametrize("fmt", CAMERA_FORMATS)
def test_round_trip_projects_like_the_camera_written(fmt, name, tmp_path):
    camera = CAMERAS[name]
    path = tmp_path / FILE_NAMES[fmt]
    if fmt == "mrcal" and camera.model == "pinhole-equidistant":
        with pytest.raises(InputError, match="mrcal has no lens model"):
            write_camera(camera, path, fmt)
        return
    notes = write_camera(camera, path, fmt, line_delay_s=30e-6 if fmt in ("opencv", "kalibr", "gyroflow") else None)
    read = load_camera(path)
    assert read.camera.model == camera.model and (read.camera.width, read.camera.height) == (camera.width,
                                                                                              camera.height)
    points = points_for(camera)
    expected = camera
    if fmt == "kalibr" and name == "radtan-k3":   # Kalibr's radtan has no k3: the refitted camera is written
        expected = refit_without_k3(camera).camera
        assert notes and "refitted with k3 = 0" in notes[0]
    np.testing.assert_allclose(read.camera.project(points), cv2_projection(expected, points), atol=TOLERANCE_PX, rtol=0)
    if fmt in ("opencv", "kalibr", "gyroflow"):
        assert read.line_delay_s == pytest.approx(30e-6, rel=1e-12)


def test_the_kalibr_refit_is_far_better_than_dropping_k3():
    camera = CAMERAS["radtan-k3"]
    refit = refit_without_k3(camera)
    u, v = np.meshgrid(np.linspace(0, 639, 41), np.linspace(0, 479, 31))
    pixels = np.c_[u.ravel(), v.ravel()]
    rays = camera.unproject(pixels)
    dropped = CameraModel("pinhole-radtan", np.r_[np.asarray(camera.params)[:8], 0.0], 640, 480)
    dropped_error = np.linalg.norm(dropped.project(rays) - pixels, axis=1)
    refit_error = np.linalg.norm(refit.camera.project(rays) - pixels, axis=1)
    assert refit.max_px == pytest.approx(refit_error.max(), rel=1e-9)
    # measured: dropping k3 moves the corners 56 px; the refit 6.3 px at the extreme corner, 0.67 px rms
    assert dropped_error.max() > 40 and refit.max_px < 8 and refit.rms_px < 1.0
    assert refit.camera.params[8] == 0 and list(refit.camera.params[:4]) == list(camera.params[:4])


def test_write_camera_set_writes_every_format_and_says_what_each_is_for(tmp_path):
    done = write_camera_set(CAMERAS["radtan-k3"], tmp_path, 30e-6, fps=29.97002997, rms_px=0.2, num_images=13,
                            gyroflow={"camera_brand": "GoPro", "camera_model": "HERO9 Black", "lens_model": "Wide"})
    assert set(done.files) == {"opencv_yaml", "kalibr_camchain", "gyroflow_profile", "ros_camera_info",
                               "mrcal_cameramodel", "colmap_cameras"}
    for name in done.files.values():
        load_camera(tmp_path / name)
    assert done.details["kalibr_refit_without_k3"]["max_px"] < 8
    fisheye = write_camera_set(CAMERAS["equidistant"], tmp_path / "fe", 30e-6) if (tmp_path / "fe").mkdir() is None \
        else None
    assert "mrcal_cameramodel" not in fisheye.files and any("mrcal" in n for n in fisheye.notes)


# -- OpenCV: cv2.FileStorage -----------------------------------------------------------------------


def test_opencv_files_read_by_cv2_filestorage_project_like_the_camera(tmp_path):
    for name, camera in CAMERAS.items():
        path = tmp_path / f"{name}.yaml"
        write_camera(camera, path, "opencv", line_delay_s=30e-6)
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        fisheye = camera.model == "pinhole-equidistant"
        prefix = "fisheye_" if fisheye else ""
        k = storage.getNode(prefix + "camera_matrix").mat()
        dist = storage.getNode(prefix + "distortion_coefficients").mat().ravel()
        assert storage.getNode("camera_model").string() == camera.model
        # a generic reader of camera_matrix / distortion_coefficients finds nothing in a fisheye file
        assert storage.getNode("camera_matrix").empty() == fisheye
        assert storage.getNode("image_readout_time_s").real() == pytest.approx(30e-6 * camera.height)
        storage.release()
        points = points_for(camera)
        zero = np.zeros(3)
        project = cv2.fisheye.projectPoints if fisheye else cv2.projectPoints
        uv = project(points.reshape(-1, 1, 3), zero, zero, k, dist)[0].reshape(-1, 2)
        np.testing.assert_allclose(uv, camera.project(points), atol=TOLERANCE_PX, rtol=0)


def test_older_opencv_files_with_distortion_model_fisheye_still_read(tmp_path):
    camera = CAMERAS["equidistant"]
    k, dist = opencv_matrices(camera)
    path = tmp_path / "old.yaml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in (("image_width", 1280), ("image_height", 720), ("distortion_model", "fisheye"),
                       ("camera_matrix", k), ("distortion_coefficients", dist.reshape(1, -1))):
        storage.write(key, value)
    storage.release()
    assert load_camera(path).camera.model == "pinhole-equidistant"


# -- mrcal: Debian's python3-mrcal -----------------------------------------------------------------

MRCAL_PROJECT = """
import json, sys
import mrcal, numpy as np
model = mrcal.cameramodel(sys.argv[1])
points = np.array(json.loads(sys.argv[2]))
lensmodel, intrinsics = model.intrinsics()
print(json.dumps({"lensmodel": lensmodel, "imagersize": model.imagersize().tolist(),
                  "uv": mrcal.project(points, lensmodel, intrinsics).tolist()}))
"""


@needs_mrcal
@pytest.mark.parametrize("name", ["radtan-k3", "radtan"])
def test_mrcal_reads_our_cameramodel_and_projects_like_it(name, tmp_path):
    camera = CAMERAS[name]
    write_camera(camera, tmp_path / "camera.cameramodel", "mrcal")
    points = points_for(camera)
    out = json.loads(run_system_python(MRCAL_PROJECT, tmp_path / "camera.cameramodel", json.dumps(points.tolist())))
    assert out["lensmodel"] == ("LENSMODEL_OPENCV5" if name == "radtan-k3" else "LENSMODEL_OPENCV4")
    assert out["imagersize"] == [camera.width, camera.height]
    np.testing.assert_allclose(np.array(out["uv"]), camera.project(points), atol=TOLERANCE_PX, rtol=0)


MRCAL_WRITE = """
import sys
import mrcal, numpy as np
lensmodel, values = sys.argv[2], [float(v) for v in sys.argv[3].split(",")]
mrcal.cameramodel(intrinsics=(lensmodel, np.array(values)), imagersize=np.array([640, 480]),
                  extrinsics_rt_fromref=np.zeros(6)).write(sys.argv[1])
"""


@needs_mrcal
@pytest.mark.parametrize("lensmodel, values, supported", [
    ("LENSMODEL_PINHOLE", [500, 501, 320, 240], True),
    ("LENSMODEL_OPENCV4", [500, 501, 320, 240, -0.2, 0.05, 0.001, -0.002], True),
    ("LENSMODEL_OPENCV5", [536.07, 536.01, 342.37, 235.53, -0.2651, -0.0466, 0.0018, -0.0003, 0.2522], True),
    ("LENSMODEL_OPENCV8", [500, 501, 320, 240, -0.2, 0.05, 0.001, -0.002, 0.01, 0, 0, 0], True),
    ("LENSMODEL_OPENCV8", [500, 501, 320, 240, -0.2, 0.05, 0.001, -0.002, 0.01, 0.1, 0, 0], False),
    ("LENSMODEL_STEREOGRAPHIC", [500, 501, 320, 240], False),
    ("LENSMODEL_CAHVOR", [500, 501, 320, 240, 0.01, 0.02, 0.001, 0.0001, 0.00001], False),
])
def test_models_mrcal_wrote_load_or_exit_2_naming_what_is_supported(lensmodel, values, supported, tmp_path):
    path = tmp_path / "m.cameramodel"
    run_system_python(MRCAL_WRITE, path, lensmodel, ",".join(map(str, values)))
    if not supported:
        with pytest.raises(InputError, match=r"not supported") as error:
            load_camera(path)
        assert "\n" not in str(error.value) and str(path) in str(error.value)
        assert "LENSMODEL_OPENCV5" in str(error.value) or "k4, k5, k6" in str(error.value)
        return
    camera = load_camera(path).camera
    points = points_for(camera)
    out = json.loads(run_system_python(MRCAL_PROJECT, path, json.dumps(points.tolist())))
    np.testing.assert_allclose(camera.project(points), np.array(out["uv"]), atol=TOLERANCE_PX, rtol=0)


MRCAL_CORNERS = """
import json, sys
import mrcal
observations, indices, files = mrcal.compute_chessboard_corners(int(sys.argv[2]), int(sys.argv[3]),
                                                                 globs_per_camera=("*",), corners_cache_vnl=sys.argv[1])
print(json.dumps({"observations": observations.tolist(), "files": [str(f) for f in files]}))
"""


@needs_mrcal
def test_mrcal_reads_our_corners_vnl(tmp_path):
    rng = np.random.default_rng(3)
    width, height = 9, 6
    points = np.c_[np.tile(np.arange(width), height), np.repeat(np.arange(height), width), np.zeros(54)] * 0.04
    assert regular_grid(points) == (width, height, pytest.approx(0.04))
    frame_index, point_id, uv = [], [], []
    for f in range(3):
        ids = np.sort(rng.choice(54, size=54 - 7 * f, replace=False))   # partial views too
        frame_index += [f] * len(ids)
        point_id += list(ids)
        uv += list(rng.uniform(5, 600, size=(len(ids), 2)))
    frame_index, point_id, uv = np.array(frame_index), np.array(point_id), np.array(uv)
    names = ["left01.jpg", "frame 12", "left03.jpg"]
    assert write_corners_vnl(tmp_path / "corners.vnl", names, frame_index, point_id, uv, points) == 3
    out = json.loads(run_system_python(MRCAL_CORNERS, tmp_path / "corners.vnl", width, height))
    observations = np.array(out["observations"])
    assert observations.shape == (3, height, width, 3)
    by_name = {Path(f).name: i for i, f in enumerate(out["files"])}
    for f, name in enumerate(names):
        grid = observations[by_name[name.replace(" ", "_")]].reshape(-1, 3)
        mine = frame_index == f
        np.testing.assert_allclose(grid[point_id[mine], :2], uv[mine], atol=TOLERANCE_PX, rtol=0)
        assert np.all(grid[point_id[mine], 2] == 1.0)
        missing = np.setdiff1d(np.arange(54), point_id[mine])
        assert np.all(grid[missing, 2] < 0)


def test_corners_vnl_refuses_a_target_that_is_not_a_regular_grid(tmp_path):
    from rscalib.io.targets import Target
    grid = Target.named("aprilgrid").points_m
    with pytest.raises(InputError, match="equally spaced"):
        write_corners_vnl(tmp_path / "c.vnl", ["a"], np.zeros(4, int), np.arange(4), np.ones((4, 2)), grid)


# -- COLMAP: pycolmap ------------------------------------------------------------------------------


def _colmap_model_dir(tmp_path: Path, cameras_txt: Path) -> Path:
    model = tmp_path / "model"
    model.mkdir(exist_ok=True)
    shutil.copy(cameras_txt, model / "cameras.txt")
    (model / "images.txt").write_text("")
    (model / "points3D.txt").write_text("")
    return model


@pytest.mark.parametrize("name", CAMERAS)
def test_pycolmap_reads_our_cameras_txt_and_projects_half_a_pixel_off(name, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    camera = CAMERAS[name]
    write_camera(camera, tmp_path / "cameras.txt", "colmap")
    reconstruction = pycolmap.Reconstruction()
    reconstruction.read_text(str(_colmap_model_dir(tmp_path, tmp_path / "cameras.txt")))
    colmap_camera = reconstruction.cameras[1]
    assert colmap_camera.model.name == {"radtan-k3": "FULL_OPENCV", "radtan": "OPENCV",
                                        "equidistant": "OPENCV_FISHEYE"}[name]
    points = points_for(camera)
    uv_colmap = np.asarray(colmap_camera.img_from_cam(points))
    np.testing.assert_allclose(uv_colmap - PIXEL_CENTRE_OFFSET, camera.project(points), atol=TOLERANCE_PX, rtol=0)


COLMAP_CAMERAS = [
    ("SIMPLE_PINHOLE", [500.0, 320.5, 240.5]),
    ("PINHOLE", [500.0, 502.0, 320.5, 240.5]),
    ("SIMPLE_RADIAL", [500.0, 320.5, 240.5, -0.08]),
    ("RADIAL", [500.0, 320.5, 240.5, -0.08, 0.01]),
    ("OPENCV", [500.0, 502.0, 320.5, 240.5, -0.2, 0.05, 0.001, -0.002]),
    ("FULL_OPENCV", [500.0, 502.0, 320.5, 240.5, -0.2, 0.05, 0.001, -0.002, 0.01, 0.0, 0.0, 0.0]),
    ("OPENCV_FISHEYE", [300.0, 301.0, 320.5, 240.5, 0.03, -0.01, 0.004, -0.001]),
    ("SIMPLE_RADIAL_FISHEYE", [300.0, 320.5, 240.5, 0.03]),
    ("RADIAL_FISHEYE", [300.0, 320.5, 240.5, 0.03, -0.01]),
]


@pytest.mark.parametrize("model, params", COLMAP_CAMERAS)
def test_cameras_txt_written_by_pycolmap_loads_and_projects_like_colmap(model, params, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    reconstruction = pycolmap.Reconstruction()
    colmap_camera = pycolmap.Camera(model=model, width=640, height=480, params=params, camera_id=1)
    reconstruction.add_camera(colmap_camera)
    reconstruction.write_text(str(tmp_path))
    camera = load_camera(tmp_path / "cameras.txt").camera
    points = points_for(camera)
    points = points[points[:, 2] > 0]
    np.testing.assert_allclose(camera.project(points), np.asarray(colmap_camera.img_from_cam(points)) - 0.5,
                               atol=TOLERANCE_PX, rtol=0)


@pytest.mark.parametrize("line", ["1 FOV 640 480 500 500 320 240 0.9",
                                  "1 THIN_PRISM_FISHEYE 640 480 500 500 320 240 0 0 0 0 0 0 0 0",
                                  "1 FULL_OPENCV 640 480 500 500 320 240 -0.2 0.05 0 0 0 0.1 0 0"])
def test_colmap_models_we_cannot_hold_exit_2_naming_the_supported(line, tmp_path):
    path = tmp_path / "cameras.txt"
    path.write_text("# Camera list\n" + line + "\n")
    with pytest.raises(InputError, match=r"not supported") as error:
        load_camera(path)
    assert "\n" not in str(error.value) and str(path) in str(error.value)


# -- ROS: camera_calibration_parsers (Debian) ------------------------------------------------------

ROS_READ = """
import json, sys
import camera_calibration_parsers
name, info = camera_calibration_parsers.readCalibration(sys.argv[1])
print(json.dumps({"name": name, "K": list(info.K), "D": list(info.D), "model": info.distortion_model,
                  "width": info.width, "height": info.height, "P": list(info.P)}))
"""


@needs_ros
@pytest.mark.parametrize("name", CAMERAS)
@pytest.mark.parametrize("header", [False, True])
def test_ros_camera_calibration_parsers_reads_our_camera_info(name, header, tmp_path):
    camera = CAMERAS[name]
    path = tmp_path / "camera_info.yaml"
    write_camera(camera, path, "ros")
    if header:   # as some tools save it; both ROS and rscalib must read it
        path.write_text("%YAML:1.0\n---\n" + path.read_text())
        assert load_camera(path).camera.model == camera.model
    info = json.loads(run_system_python(ROS_READ, path))
    assert info["model"] == ("equidistant" if camera.model == "pinhole-equidistant" else "plumb_bob")
    assert (info["width"], info["height"]) == (camera.width, camera.height)
    # ROS's semantics (image_geometry): plumb_bob is cv2.projectPoints, equidistant cv2.fisheye
    k = np.array(info["K"]).reshape(3, 3)
    dist = np.array(info["D"])
    points = points_for(camera)
    project = cv2.fisheye.projectPoints if info["model"] == "equidistant" else cv2.projectPoints
    uv = project(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, dist)[0].reshape(-1, 2)
    np.testing.assert_allclose(uv, camera.project(points), atol=TOLERANCE_PX, rtol=0)
    np.testing.assert_allclose(np.array(info["P"]).reshape(3, 4)[:, :3], k)


@pytest.mark.parametrize("model, coeffs, ok", [("plumb_bob", [-0.2, 0.05, 0.001, -0.002, 0.01], True),
                                               ("rational_polynomial", [-0.2, 0.05, 0.001, -0.002, 0.01, 0, 0, 0], True),
                                               ("rational_polynomial", [-0.2, 0.05, 0, 0, 0.01, 0.3, 0, 0], False),
                                               ("equidistant", [0.03, -0.01, 0.004, -0.001], True),
                                               ("fisheye", [0.03, -0.01, 0.004, -0.001], False)])
def test_ros_camera_info_models_load_or_exit_2(model, coeffs, ok, tmp_path):
    data = {"image_width": 640, "image_height": 480, "camera_name": "cam",
            "camera_matrix": {"rows": 3, "cols": 3, "data": [500, 0, 320, 0, 501, 240, 0, 0, 1]},
            "distortion_model": model, "distortion_coefficients": {"rows": 1, "cols": len(coeffs), "data": coeffs}}
    path = tmp_path / "ost.yaml"
    path.write_text(yaml.safe_dump(data))
    if not ok:
        with pytest.raises(InputError, match="not supported"):
            load_camera(path)
        return
    camera = load_camera(path).camera
    assert camera.model == ("pinhole-equidistant" if model == "equidistant" else "pinhole-radtan")
    assert list(camera.params[4:4 + min(len(coeffs), 5)]) == coeffs[:5]


# -- Kalibr: its ConfigReader's field checks and equations, reimplemented --------------------------


def kalibr_reader(path: Path) -> dict:
    """What Kalibr's CameraParameters / ChainParameters accept (kalibr_common/ConfigReader.py): camera
    models and intrinsics counts, float focal lengths and principal point >= 0, distortion models with
    their coefficient counts, two int resolution values, a string rostopic; kalibr_camera_validator
    also reads cam_overlaps."""
    cam = yaml.safe_load(path.read_text())["cam0"]
    counts = {"pinhole": 4, "omni": 5, "eucm": 6, "ds": 6}
    assert cam["camera_model"] in counts and len(cam["intrinsics"]) == counts[cam["camera_model"]]
    fu, fv, pu, pv = cam["intrinsics"][-4:]
    assert all(isinstance(v, float) for v in (fu, fv, pu, pv)) and min(fu, fv, pu, pv) >= 0
    assert len(cam["distortion_coeffs"]) == {"radtan": 4, "equidistant": 4, "fov": 1, "none": 0}[cam["distortion_model"]]
    assert len(cam["resolution"]) == 2 and all(isinstance(v, int) for v in cam["resolution"])
    assert isinstance(cam["rostopic"], str) and isinstance(cam["cam_overlaps"], list)
    return cam


def kalibr_project(cam: dict, points: np.ndarray) -> np.ndarray:
    """aslam_cv's pinhole projection with RadialTangentialDistortion or EquidistantDistortion."""
    fu, fv, pu, pv = cam["intrinsics"]
    x, y = points[:, 0] / points[:, 2], points[:, 1] / points[:, 2]
    if cam["distortion_model"] == "radtan":
        k1, k2, p1, p2 = cam["distortion_coeffs"]
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        xd, yd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    else:
        k1, k2, k3, k4 = cam["distortion_coeffs"]
        r = np.hypot(x, y)
        theta = np.arctan(r)
        theta_d = theta * (1 + k1 * theta ** 2 + k2 * theta ** 4 + k3 * theta ** 6 + k4 * theta ** 8)
        scale = np.where(r > 1e-12, theta_d / np.maximum(r, 1e-300), 1.0)
        xd, yd = x * scale, y * scale
    return np.c_[fu * xd + pu, fv * yd + pv]


@pytest.mark.parametrize("name", CAMERAS)
def test_kalibr_reader_accepts_our_camchain_and_projects_like_the_export(name, tmp_path):
    camera = CAMERAS[name]
    path = tmp_path / "camchain.yaml"
    notes = write_camera(camera, path, "kalibr", line_delay_s=30e-6)
    cam = kalibr_reader(path)
    assert cam["cam_overlaps"] == [] and cam["line_delay"] == pytest.approx(30e-6)
    points = points_for(camera)
    expected = refit_without_k3(camera).camera if name == "radtan-k3" else camera
    np.testing.assert_allclose(kalibr_project(cam, points), cv2_projection(expected, points), atol=TOLERANCE_PX,
                               rtol=0)
    assert bool(notes) == (name == "radtan-k3")


@pytest.mark.parametrize("camera_model, intrinsics, distortion", [
    ("ds", [-0.2, 0.6, 300.0, 300.0, 320.0, 240.0], "none"),
    ("eucm", [0.6, 1.1, 300.0, 300.0, 320.0, 240.0], "none"),
    ("omni", [0.8, 300.0, 300.0, 320.0, 240.0], "radtan"),
    ("pinhole", [300.0, 300.0, 320.0, 240.0], "fov"),
])
def test_kalibr_models_we_cannot_hold_exit_2_with_the_supported_list(camera_model, intrinsics, distortion, tmp_path):
    coeffs = {"none": [], "radtan": [0.0, 0.0, 0.0, 0.0], "fov": [0.9]}[distortion]
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump({"cam0": {"camera_model": camera_model, "intrinsics": intrinsics,
                                             "distortion_model": distortion, "distortion_coeffs": coeffs,
                                             "resolution": [640, 480], "rostopic": "/cam0/image_raw"}}))
    with pytest.raises(InputError, match=r"not supported; supported: .*radtan, equidistant or none") as error:
        load_camera(path)
    assert "\n" not in str(error.value) and "unpack" not in str(error.value)


# -- Gyroflow: its LensProfile fields and distortion, reimplemented --------------------------------


def gyroflow_project(profile: dict, points: np.ndarray) -> np.ndarray:
    """Gyroflow's distort_point of opencv_fisheye and opencv_standard (k[0..4]), then the camera
    matrix (principal point from the profile only when asymmetrical)."""
    k = np.array(profile["fisheye_params"]["camera_matrix"])
    d = profile["fisheye_params"]["distortion_coeffs"]
    if not profile["asymmetrical"]:
        k[0, 2], k[1, 2] = profile["calib_dimension"]["w"] / 2, profile["calib_dimension"]["h"] / 2
    x, y = points[:, 0] / points[:, 2], points[:, 1] / points[:, 2]
    if profile["distortion_model"] == "opencv_fisheye":
        r = np.hypot(x, y)
        theta = np.arctan(r)
        theta_d = theta * (1 + d[0] * theta ** 2 + d[1] * theta ** 4 + d[2] * theta ** 6 + d[3] * theta ** 8)
        scale = np.where(r > 0, theta_d / np.where(r > 0, r, 1), 1.0)
        xd, yd = x * scale, y * scale
    else:
        r2 = x * x + y * y
        radial = 1 + d[0] * r2 + d[1] * r2 ** 2 + d[4] * r2 ** 3
        xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x)
        yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y
    return np.c_[k[0, 0] * xd + k[0, 2], k[1, 1] * yd + k[1, 2]]


@pytest.mark.parametrize("name", CAMERAS)
def test_gyroflow_profile_has_gyroflows_fields_and_projects_like_the_camera(name, tmp_path):
    camera = CAMERAS[name]
    path = tmp_path / "profile.json"
    write_camera(camera, path, "gyroflow", line_delay_s=30e-6, fps=29.97002997, num_images=17,
                 camera_brand="GoPro", camera_model="HERO9 Black", lens_model="Wide")
    profile = json.loads(path.read_text())
    # Gyroflow's load_from_data rejects a profile without these
    assert profile["calibrator_version"].startswith("rscalib ") and len(profile["fisheye_params"]["camera_matrix"]) == 3
    assert profile["calib_dimension"] == {"w": camera.width, "h": camera.height}
    assert profile["output_dimension"] is None and profile["num_images"] == 17 and profile["fps"] == 29.97
    assert not {"use_opencv_fisheye", "use_opencv_standard", "calib_params"} & set(profile)
    assert (profile["camera_brand"], profile["camera_model"], profile["lens_model"]) == ("GoPro", "HERO9 Black", "Wide")
    assert profile["name"].startswith("GoPro_HERO9 Black_Wide_")
    assert profile["frame_readout_time"] == pytest.approx(30e-6 * camera.height * 1e3)
    assert profile["frame_readout_direction"] == "TopToBottom"
    points = points_for(camera)
    np.testing.assert_allclose(gyroflow_project(profile, points), camera.project(points), atol=TOLERANCE_PX, rtol=0)


def test_gyroflow_profile_without_a_line_delay_leaves_the_readout_null(tmp_path):
    write_camera(CAMERAS["equidistant"], tmp_path / "p.json", "gyroflow")
    profile = json.loads((tmp_path / "p.json").read_text())
    assert profile["frame_readout_time"] is None and profile["distortion_model"] == "opencv_fisheye"
    assert load_camera(tmp_path / "p.json").line_delay_s is None


# -- what --camera is given: every third-party input loads or is one line of exit 2 ----------------


@pytest.mark.parametrize("text, suffix, match", [
    ("%YAML:1.0\n---\nfoo: 1\n", ".yaml", "not a camera file rscalib reads"),
    ("cam0:\n  camera_model: pinhole\n  intrinsics: [1, 2, 3]\n  distortion_model: radtan\n"
     "  distortion_coeffs: [0, 0, 0, 0]\n  resolution: [640, 480]\n", ".yaml", "intrinsics needs 4 values"),
    ("{ 'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [1, 2], 'imagersize': [640, 480], 'extrinsics': [0]*6 }",
     ".cameramodel", "not an mrcal"),
    ("hello world\n", ".txt", "not a COLMAP cameras.txt"),
    ("1 OPENCV 640 480 500 500 320\n", ".txt", "OPENCV needs 8 parameters"),
])
def test_broken_camera_files_are_one_line_errors_naming_the_file(text, suffix, match, tmp_path):
    path = tmp_path / f"camera{suffix}"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as error:
        load_camera(path)
    assert "\n" not in str(error.value) and str(path) in str(error.value)


def test_cli_exits_2_with_one_line_for_a_kalibr_double_sphere_camera(tmp_path):
    import sys
    camchain = tmp_path / "camchain.yaml"
    camchain.write_text("cam0:\n  camera_model: ds\n  intrinsics: [-0.2, 0.6, 300.0, 300.0, 320.0, 240.0]\n"
                        "  distortion_model: none\n  distortion_coeffs: []\n  resolution: [640, 480]\n")
    done = subprocess.run([sys.executable, "-m", "rscalib.cli", "simulate", "--out", str(tmp_path / "s"),
                           "--camera", str(camchain), "--duration", "0.2", "--quiet"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "double sphere" in lines[0] and "Traceback" not in done.stderr
