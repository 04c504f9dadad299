"""The renderer's truth for image tracks of a realistic room sequence (issue 30; docs/sog.md §23).

A track of a front end starts at a pixel of its first frame; the 3-D point it follows is where the
true ray of that pixel (at that row's exposure time) meets the room's box (the realistic scenes of
:mod:`rscalib.sim.scene_realism` are a closed box). Every later observation of the track is then
compared with that point projected at the observation's own row time (rolling shutter: row v of
frame i at ``t_i + v d``, plus half the exposure: the blur's centre).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from .._core import CameraModel
from .scene_realism import StyledRoomMotion

__all__ = ["RenderTruth"]


class RenderTruth:
    """The camera, motion, frame times and room of a sequence's ``truth.json`` (as a dict)."""

    def __init__(self, truth: dict) -> None:
        cam = truth["camera"]
        self.camera = CameraModel(cam["model"], list(cam["params"]), int(cam["width"]), int(cam["height"]),
                                  pixel_size_mm=list(cam["pixel_size_mm"]))
        self.motion = StyledRoomMotion(truth["style"], truth["seed"], truth["num_frames_requested"] / truth["fps"])
        self.frame_t_s = np.array([f["t_s"] for f in truth["frames"]])
        self.line_delay_s = float(truth["line_delay_s"])
        self.exposure_s = float(truth["exposure_s"])
        lx, ly, lz = truth["realism"]["room_size_m"]
        self.room_lo = np.array([-lx / 2, -ly / 2, 0.0])
        self.room_hi = np.array([lx / 2, ly / 2, lz])

    def row_time(self, frame: np.ndarray, v_px: np.ndarray) -> np.ndarray:
        """Mid-exposure time (s) of row ``v_px`` of frames ``frame``."""
        return self.frame_t_s[np.asarray(frame, np.int64)] + np.asarray(v_px) * self.line_delay_s + 0.5 * self.exposure_s

    def points_under(self, frame: np.ndarray, uv_px: np.ndarray) -> np.ndarray:
        """(N, 3) world points seen at distorted pixels ``uv_px`` of frames ``frame``: the rays at
        their rows' times cut with the room's box."""
        uv = np.asarray(uv_px, np.float64).reshape(-1, 2)
        R, p = self.motion.pose_cw(self.row_time(frame, uv[:, 1]))
        ray_c = np.asarray(self.camera.unproject(uv), np.float64)
        ray_w = np.einsum("nji,nj->ni", R, ray_c)                     # R_cwᵀ ray
        centre = -np.einsum("nji,nj->ni", R, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            exit_t = np.where(ray_w > 0, (self.room_hi - centre) / ray_w, (self.room_lo - centre) / ray_w)
        exit_t = np.where(np.isfinite(exit_t) & (exit_t > 0), exit_t, np.inf)
        return centre + np.min(exit_t, axis=1)[:, None] * ray_w

    def project(self, frame: np.ndarray, X_w: np.ndarray, v_guess_px: Optional[np.ndarray] = None,
                iterations: int = 3) -> np.ndarray:
        """(N, 2) distorted pixels of world points ``X_w`` in frames ``frame`` under the rolling
        shutter: the row time from the projected row itself (fixed-point iterations from
        ``v_guess_px``, default the middle row). NaN behind the camera."""
        frame = np.asarray(frame, np.int64)
        X_w = np.asarray(X_w, np.float64).reshape(-1, 3)
        v = np.full(len(frame), (self.camera.height - 1) / 2.0) if v_guess_px is None else np.asarray(v_guess_px, float)
        uv = np.full((len(frame), 2), np.nan)
        for _ in range(max(1, iterations)):
            R, p = self.motion.pose_cw(self.row_time(frame, np.nan_to_num(v, nan=(self.camera.height - 1) / 2.0)))
            X_c = np.einsum("nij,nj->ni", R, X_w) + p
            uv = np.asarray(self.camera.project(X_c), np.float64)
            v = uv[:, 1]
        return uv

    def track_pixels(self, frame: np.ndarray, track_id: np.ndarray, uv_px: np.ndarray) -> np.ndarray:
        """The true pixel (N, 2) of every observation of image tracks: the point under each track's
        first observation, projected in the observation's frame (the measured row as the start)."""
        frame = np.asarray(frame, np.int64)
        track_id = np.asarray(track_id, np.int64)
        uv = np.asarray(uv_px, np.float64).reshape(-1, 2)
        order = np.lexsort((frame, track_id))
        first = order[np.r_[True, np.diff(track_id[order]) != 0]] if len(order) else order
        X_first = self.points_under(frame[first], uv[first])
        _, which = np.unique(track_id, return_inverse=True)    # track ids sorted like first's
        return self.project(frame, X_first[which], v_guess_px=uv[:, 1])
