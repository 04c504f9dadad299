"""mrcal camera models (.cameramodel) and corner files (corners.vnl).

A .cameramodel is a Python dict literal (mrcal reads it with ast.literal_eval; `#` starts a
comment): lensmodel, intrinsics, imagersize [w h], extrinsics rt_cam_ref (6), and optionally
valid_intrinsics_region and optimization_inputs. Pixels follow OpenCV's convention and
LENSMODEL_OPENCVn is cv2.projectPoints with the first n of k1 k2 p1 p2 k3 k4 k5 k6 (...). rscalib
reads LENSMODEL_PINHOLE, OPENCV4, OPENCV5 and OPENCV8 (with k4..k6 = 0); it writes OPENCV4 or
OPENCV5. mrcal has no model equal to OpenCV's fisheye, so a pinhole-equidistant camera is not
written (its detections still are).

corners.vnl is mrcal's corner cache (mrcal-calibrate-cameras --corners-cache, and
mrcal.compute_chessboard_corners): `filename x y level` rows, the W x H grid points of each image
in a row-major order, x fastest; a missing point is `- -` with level `-`; level 0 = weight 1.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Optional

import numpy as np

from ..._core import CameraModel
from ..._version import __version__
from ...errors import InputError
from ..safe_parse import load_python_literal, one_line, shown
from .common import RADTAN, CameraFile, camera_from_opencv, numeric_array, supported

# lensmodel -> number of distortion values after fx fy cx cy
MRCAL_READ_MODELS = {"LENSMODEL_PINHOLE": 0, "LENSMODEL_OPENCV4": 4, "LENSMODEL_OPENCV5": 5,
                     "LENSMODEL_OPENCV8": 8}


def is_mrcal(data) -> bool:
    """A parsed file is an mrcal model when it has intrinsics and a lensmodel (or, in files of
    mrcal 1.x, a distortion_model named DISTORTION_...)."""
    if not isinstance(data, dict) or "intrinsics" not in data:
        return False
    model = data.get("lensmodel", data.get("distortion_model"))
    return "lensmodel" in data or (isinstance(model, str) and model.startswith(("LENSMODEL_", "DISTORTION_")))


def parse_mrcal(path: Path, text: str):
    """The Python dict literal of a .cameramodel (mrcal reads it with ast.literal_eval; `#` starts
    a comment, also inside the dict, but not inside a string)."""
    data = load_python_literal(text, path, "an mrcal .cameramodel (a Python dict literal)")
    if not isinstance(data, dict):
        raise InputError(f"{shown(path)}: not an mrcal .cameramodel (a Python dict literal)")
    return data


def read_mrcal(path: Path, data: dict) -> CameraFile:
    """The camera of a parsed .cameramodel (parse_mrcal)."""
    model = data.get("lensmodel", data.get("distortion_model", ""))
    if not isinstance(model, str):
        raise InputError(f"{shown(path)}: lensmodel must be a name such as LENSMODEL_OPENCV8, not "
                         f"{type(model).__name__} {one_line(str(model))[:40]}")
    model = model.replace("DISTORTION", "LENSMODEL")
    if model not in MRCAL_READ_MODELS:
        raise InputError(f"{shown(path)}: lensmodel '{one_line(model)[:60]}' is not supported; supported: "
                         f"{supported(MRCAL_READ_MODELS)}")
    if "intrinsics" not in data or "imagersize" not in data:
        raise InputError(f"{shown(path)}: fields intrinsics and imagersize [w, h] are needed")
    try:
        intrinsics = numeric_array(data["intrinsics"], "intrinsics").reshape(-1)
        size = numeric_array(data["imagersize"], "imagersize").reshape(-1)
        if size.size != 2:
            raise InputError(f"imagersize needs 2 values [w, h], has {size.size}")
        count = 4 + MRCAL_READ_MODELS[model]
        if intrinsics.size != count:
            raise InputError(f"{model} needs {count} intrinsics, has {intrinsics.size}")
        dist = np.zeros(5)
        dist[:min(5, count - 4)] = intrinsics[4:9]
        if count > 9 and np.any(intrinsics[9:] != 0):
            raise InputError(f"{model} with k4, k5, k6 != 0 is not supported (rscalib's pinhole-radtan has "
                             "k1 k2 p1 p2 k3)")
        fx, fy, cx, cy = intrinsics[:4]
        k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
        camera = camera_from_opencv(k, dist, size[0], size[1], RADTAN, fields=("intrinsics", "intrinsics"),
                                    size_fields=("imagersize (w)", "imagersize (h)"))
    except InputError as error:
        raise InputError(f"{shown(path)}: {error}") from None
    notes = []
    extrinsics = data.get("extrinsics")
    if extrinsics is not None and np.any(numeric_array(extrinsics, f"{shown(path)}: extrinsics") != 0):
        notes.append(f"{shown(path)}: the extrinsics (rt_cam_ref) are not used")
    return CameraFile(camera, None, "mrcal", notes)


def _numbers(values) -> str:
    return "[ " + ", ".join(f"{float(v):.17g}" for v in values) + ", ]"


def write_mrcal_cameramodel(camera: CameraModel, path, note: str = "") -> None:
    """LENSMODEL_OPENCV5 (OPENCV4 when k3 = 0) with identity extrinsics. InputError for
    pinhole-equidistant (mrcal has no such model)."""
    if camera.model != RADTAN:
        raise InputError(f"mrcal has no lens model equal to {camera.model} (OpenCV's fisheye); "
                         "a .cameramodel is written for pinhole-radtan only")
    p = np.asarray(camera.params, dtype=np.float64)
    lensmodel, values = ("LENSMODEL_OPENCV4", p[:8]) if p[8] == 0 else ("LENSMODEL_OPENCV5", p[:9])
    lines = [f"# written by rscalib {__version__}" + (f": {note}" if note else ""),
             "# intrinsics: fx fy cx cy k1 k2 p1 p2" + (" k3" if lensmodel.endswith("5") else ""),
             "{",
             f"    'lensmodel':  '{lensmodel}',",
             f"    'intrinsics': {_numbers(values)},",
             f"    'imagersize': [ {int(camera.width)}, {int(camera.height)}, ],",
             "    'extrinsics': [ 0, 0, 0, 0, 0, 0, ],",
             "}", ""]
    Path(path).write_text("\n".join(lines))


def regular_grid(points_m: np.ndarray, tolerance_m: float = 1e-9) -> Optional[tuple[int, int, float]]:
    """(W, H, spacing_m) when the target points are the W x H grid mrcal's chessboard model
    assumes (point j W + i at (i, j) * spacing, equal spacing in x and y), else None."""
    points = np.asarray(points_m, dtype=np.float64)
    if points.ndim != 2 or len(points) < 4:
        return None
    width = int(np.sum(np.abs(points[:, 1] - points[0, 1]) <= tolerance_m))
    if width < 2 or len(points) % width:
        return None
    height = len(points) // width
    spacing = float(points[1, 0] - points[0, 0])
    if spacing <= 0:
        return None
    j, i = np.divmod(np.arange(len(points)), width)
    expected = np.c_[i * spacing, j * spacing] + points[0, :2]
    if np.max(np.abs(points[:, :2] - expected)) > tolerance_m or np.any(np.abs(points[:, 2]) > tolerance_m):
        return None
    return width, height, spacing


def write_corners_vnl(path, frame_names: list, frame_index: np.ndarray, point_id: np.ndarray, uv: np.ndarray,
                      points_m: np.ndarray) -> int:
    """mrcal's corners.vnl of detections (frame of each observation, target point id, pixel) of a
    target whose points form a regular grid (regular_grid). frame_names: one name per frame (no
    spaces; mrcal matches them against its image globs). Returns the number of images written.
    InputError when the target is not such a grid (AprilGrid: gaps between tags)."""
    grid = regular_grid(points_m)
    if grid is None:
        raise InputError("mrcal's corners.vnl needs a target of equally spaced points in a full grid "
                         "(a checkerboard with equal row and column spacing, a symmetric circle grid, ChArUco)")
    width, height, _ = grid
    rows = [f"## written by rscalib {__version__}: target grid {width} x {height}, pixels in OpenCV's convention",
            "# filename x y level"]
    frames = 0
    frame_index = np.asarray(frame_index)
    order = np.argsort(frame_index, kind="stable")  # one pass over the observations, not one per frame
    bounds = np.searchsorted(frame_index[order], np.arange(len(frame_names) + 1))
    for f, name in enumerate(frame_names):
        mine = order[bounds[f]:bounds[f + 1]]
        if not len(mine):
            continue
        table = np.full((width * height, 2), np.nan)
        table[point_id[mine]] = uv[mine]
        safe = re.sub(r"\s", "_", str(name))
        if np.isfinite(table).all():   # a whole grid (tracked frames): one format call for the frame
            line = safe.replace("%", "%%") + " %.6f %.6f 0"
            rows.append("\n".join([line] * len(table)) % tuple(table.ravel().tolist()))
        else:  # Python floats format several times faster than NumPy scalars (u != u: NaN, not detected)
            rows.extend(f"{safe} - - -" if u != u else f"{safe} {u:.6f} {v:.6f} 0" for u, v in table.tolist())
        frames += 1
    Path(path).write_text("\n".join(rows) + "\n")
    return frames
