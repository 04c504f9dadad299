"""Readout direction and part of the video: what `--readout` and `--start/--end` do to the data.

The solver assumes the sensor reads image rows from top to bottom (row v at t_i + v d). For any
other direction the detections, the camera and the target are mapped to an equivalent top-down
problem: a flipped or transposed image of a flipped or transposed board is the same geometry seen
by a camera whose frame is reflected the same way (the reflection cancels in R' = F R F, a proper
rotation), so d comes out per sensor row. Lens parameters follow the reflection (radial terms
stay, the tangential p1/p2 change sign or swap).

    top-to-bottom   (u, v)            rows = height
    bottom-to-top   (u, H - 1 - v)    rows = height
    left-to-right   (v, u)            rows = width (a portrait phone video: sensor rows are image columns)
    right-to-left   (v, W - 1 - u)    rows = width
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from .._core import CameraModel
from ..errors import InputError
from ..observations import Observations
from ..readout import BOTTOM_TO_TOP, LEFT_TO_RIGHT, READOUT_DIRECTIONS, RIGHT_TO_LEFT, TOP_TO_BOTTOM, readout_direction


def _mirror(obs: Observations, camera: CameraModel, axis: int) -> tuple[Observations, CameraModel]:
    """Mirror the image along u (axis 0) or v (axis 1): pixels, the target's matching axis, the
    principal point and, for pinhole-radtan, the tangential term of that axis (p2 for u, p1 for v)."""
    size = obs.image_size
    uv = obs.uv.copy()
    uv[:, axis] = (size[axis] - 1) - uv[:, axis]
    sign = np.ones(3)
    sign[axis] = -1.0
    pts = obs.target_points * sign
    p = list(camera.params)
    p[2 + axis] = (size[axis] - 1) - p[2 + axis]
    tangential = 7 - axis
    if camera.model == "pinhole-radtan" and len(p) > tangential:
        p[tangential] = -p[tangential]
    return _with(obs, uv, pts, tuple(size)), CameraModel(camera.model, p, camera.width, camera.height)


def _transpose(obs: Observations, camera: CameraModel) -> tuple[Observations, CameraModel]:
    w, h = obs.image_size
    uv = obs.uv[:, ::-1].copy()
    pts = obs.target_points[:, [1, 0, 2]].copy()
    p = list(camera.params)
    p[0], p[1], p[2], p[3] = p[1], p[0], p[3], p[2]
    if camera.model == "pinhole-radtan" and len(p) > 7:
        p[6], p[7] = p[7], p[6]
    return _with(obs, uv, pts, (h, w)), CameraModel(camera.model, p, camera.height, camera.width)


def _with(obs: Observations, uv, points, size) -> Observations:
    return Observations(frame_times_s=obs.frame_times_s, frame_index=obs.frame_index, point_id=obs.point_id,
                        uv=uv, target_points=points, image_size=size)


def to_top_to_bottom(observations: Observations, camera: CameraModel, readout: str
                ) -> tuple[Observations, CameraModel]:
    """The observations and camera of the equivalent top-to-bottom problem (module docstring)."""
    readout = readout_direction(readout, READOUT_DIRECTIONS)
    if readout == TOP_TO_BOTTOM:
        return observations, camera
    if camera.model not in ("pinhole-radtan", "pinhole-equidistant"):
        raise InputError(f"--readout {readout} needs a pinhole-radtan or pinhole-equidistant camera")
    if readout == BOTTOM_TO_TOP:
        return _mirror(observations, camera, axis=1)
    if readout == LEFT_TO_RIGHT:
        return _transpose(observations, camera)
    return _transpose(*_mirror(observations, camera, axis=0))


def time_window(observations: Observations, start_s: Optional[float], end_s: Optional[float]) -> Observations:
    """The frames with start_s <= t <= end_s (seconds of the video's own timestamps)."""
    if start_s is None and end_s is None:
        return observations
    t = observations.frame_times_s
    lo = -np.inf if start_s is None else float(start_s)
    hi = np.inf if end_s is None else float(end_s)
    if not lo < hi:
        raise InputError("--start must be before --end")
    keep = (t >= lo) & (t <= hi)
    if keep.sum() < 4:
        raise InputError(f"only {int(keep.sum())} frames with the target between {start_s} and {end_s} s "
                         f"(the video's frames span {t[0]:.2f}-{t[-1]:.2f} s)")
    return observations.subset_frames(keep)


def rotation_hint(video) -> Optional[str]:
    """The readout a rotated (portrait) phone video implies, from its rotation metadata: sensor rows
    become image columns when the player turns the picture by 90 or 270 degrees. None if unknown/0."""
    try:
        import cv2

        capture = cv2.VideoCapture(str(video))
        if not capture.isOpened():
            return None
        angle = int(round(capture.get(cv2.CAP_PROP_ORIENTATION_META))) % 360
        capture.release()
    except Exception:  # noqa: BLE001 - no metadata is no hint
        return None
    return {90: RIGHT_TO_LEFT, 180: BOTTOM_TO_TOP, 270: LEFT_TO_RIGHT}.get(angle)
