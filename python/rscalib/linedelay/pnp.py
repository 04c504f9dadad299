"""Per-frame global-shutter pose (PnP): the initial guess of the line-delay engine and the
baseline it is compared against (paper §4.1 and Fig. 5)."""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Optional

import cv2
import numpy as np

from .._core import CameraModel, poses_at, rotation_vector_to_matrix, unwrap_rotation_vectors
from ..errors import InputError
from ..observations import Observations


@dataclass
class FramePoses:
    """T_cw of every frame from its own points, global-shutter model.

    ok: (F,) bool, a pose was found; rotation_vector, translation: (F, 3), x_c = R x_w + p
    (NaN where not ok); rms_px: (F,) reprojection RMS of that frame's points.
    """

    ok: np.ndarray
    rotation_vector: np.ndarray
    translation: np.ndarray
    rms_px: np.ndarray

    def of_frames(self, frame_times_s: np.ndarray, subset_times_s: np.ndarray) -> FramePoses:
        """The poses of the frames at subset_times_s, these poses being of the frames at
        frame_times_s (e.g. a half of the video: the same per-frame PnP, not computed again)."""
        index = np.searchsorted(frame_times_s, subset_times_s)
        if np.any(index >= len(frame_times_s)) or not np.array_equal(frame_times_s[index], subset_times_s):
            raise ValueError("the subset's frames are not among these poses' frames")
        return FramePoses(self.ok[index], self.rotation_vector[index], self.translation[index], self.rms_px[index])


def per_frame_pnp(observations: Observations, camera: CameraModel, min_points: int = 6,
                  threads: int = 2) -> FramePoses:
    """Planar PnP (OpenCV IPPE, then Levenberg-Marquardt) on undistorted, normalised points.

    Normalising through the camera's own unprojection makes this work for every model. Frames are
    independent: `threads` share them (OpenCV releases the GIL); the result does not depend on it.
    """
    count = observations.num_frames
    ok = np.zeros(count, dtype=bool)
    rvecs = np.full((count, 3), np.nan)
    tvecs = np.full((count, 3), np.nan)
    rms = np.full(count, np.nan)
    rays = camera.unproject(observations.uv)
    points_w = observations.points_w()
    identity = np.eye(3)
    planar = np.allclose(observations.target_points[:, 2], 0.0)
    flag = cv2.SOLVEPNP_IPPE if planar else cv2.SOLVEPNP_ITERATIVE
    slices = [rows[np.isfinite(rays[rows, 0])] for rows in observations.frame_slices()]

    def solve(frames) -> None:
        for frame in frames:
            rows = slices[frame]
            if len(rows) < min_points:
                continue
            obj = points_w[rows].reshape(-1, 1, 3)
            img = rays[rows, :2].reshape(-1, 1, 2)
            found, rvec, tvec = cv2.solvePnP(obj, img, identity, None, flags=flag)
            if not found:
                continue
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, identity, None, rvec, tvec)
            rotation = cv2.Rodrigues(rvec)[0]
            if np.any(points_w[rows] @ rotation[2] + tvec[2, 0] <= 0):  # a point behind the camera
                continue
            ok[frame] = True
            rvecs[frame] = rvec.ravel()
            tvecs[frame] = tvec.ravel()

    chunks = np.array_split(np.arange(count), max(1, min(int(threads), count)))
    if len(chunks) > 1:
        with ThreadPoolExecutor(max_workers=len(chunks), thread_name_prefix="rscalib-pnp") as pool:
            list(pool.map(solve, chunks))
    else:
        solve(chunks[0] if chunks else [])
    # reprojection RMS of every posed frame, in one projection call
    posed = np.flatnonzero(ok)
    if len(posed):
        rows = np.concatenate([slices[f] for f in posed])
        owner = np.repeat(posed, [len(slices[f]) for f in posed])
        rotations = np.array([cv2.Rodrigues(rvecs[f])[0] for f in posed])
        at = np.searchsorted(posed, owner)
        points_c = np.einsum("nij,nj->ni", rotations[at], points_w[rows]) + tvecs[owner]
        squared = (camera.project(points_c) - observations.uv[rows]) ** 2
        finite = np.isfinite(squared)
        sums = np.bincount(owner, weights=np.where(finite, squared, 0.0).sum(axis=1), minlength=count)
        counts = np.bincount(owner, weights=finite.sum(axis=1), minlength=count)
        with np.errstate(invalid="ignore", divide="ignore"):  # a frame with no finite projection: NaN
            rms[posed] = np.sqrt(sums[posed] / counts[posed])
    return FramePoses(ok, rvecs, tvecs, rms)


_POSE_FIELDS = ("ok", "rotation_vector", "translation", "rms_px")


class PosesAlongside:
    """per_frame_pnp of the frames detection hands on while it detects the next ones (detect_video's
    on_frames): the poses are ready when detection ends (0.6 s after it for a minute of video
    otherwise). Each frame's pose is its own, so they are those of one per_frame_pnp to the bit."""

    def __init__(self, camera: CameraModel):
        self.camera = camera
        self.target_points = np.zeros((0, 3))
        self.times: list = []
        self.parts: list[FramePoses] = []   # one per batch, with its frame count in counts
        self.counts: list[int] = []

    def of_target(self, target_points: np.ndarray) -> PosesAlongside:
        """These, for frames of a target with these points (metres, the target's frame)."""
        self.target_points = np.asarray(target_points, dtype=np.float64)
        return self

    def __call__(self, start: int, times_s: list, point_ids: list, uvs: list) -> None:
        if not 0 <= start <= len(self.times):
            raise ValueError(f"frames from {start} handed on after only {len(self.times)}")
        while sum(self.counts) > start:   # detection began again from `start`: those after it go
            keep = start - (sum(self.counts) - self.counts[-1])
            if keep > 0:
                self.parts[-1] = FramePoses(*(getattr(self.parts[-1], name)[:keep] for name in _POSE_FIELDS))
                self.counts[-1] = keep
            else:
                self.counts.pop(), self.parts.pop()
        del self.times[start:]
        counts = [len(ids) for ids in point_ids]
        batch = Observations(frame_times_s=np.asarray(times_s, dtype=np.float64),
                             frame_index=np.repeat(np.arange(len(counts)), counts),
                             point_id=np.concatenate(point_ids), uv=np.concatenate(uvs),
                             target_points=self.target_points,
                             image_size=(self.camera.width, self.camera.height))
        self.parts.append(per_frame_pnp(batch, self.camera, threads=1))   # the workers have the cores
        self.counts.append(len(counts))
        self.times.extend(times_s)

    def poses_of(self, observations: Observations) -> Optional[FramePoses]:
        """The poses of observations' frames (all handed on, or a time window of them), None when they
        are not among those handed on."""
        if not self.parts:
            return None
        joined = FramePoses(*(np.concatenate([getattr(p, name) for p in self.parts]) for name in _POSE_FIELDS))
        try:
            return joined.of_frames(np.asarray(self.times, dtype=np.float64), observations.frame_times_s)
        except ValueError:
            return None


@dataclass
class PnpTrajectory:
    """Per-frame GS PnP poses as a trajectory (`rscalib localize --model gs-pnp`): each pose is stamped
    at the middle of its frame's image readout, t_i + d x image height / 2 (the time a global-shutter fit
    of a rolling-shutter frame best represents; trajectory.csv's mid-readout rows use the same time), or
    at t_i when no line delay is known.

    times_s: (F,) of the frames with a pose; states: (F, 6) T_cw [p; phi], rotation vectors unwrapped
    (paper eq. 22) as the spline's state."""

    times_s: np.ndarray
    states: np.ndarray
    frames_total: int
    frames_used: int
    observations: int                 # target points in the frames with a pose
    rms_px: float
    line_delay_s: Optional[float]
    readout_time_s: float             # rows d (0 without a line delay)
    warnings: list[str] = field(default_factory=list)
    trajectory_model: str = "gs-pnp"

    def summary_dict(self) -> dict:
        """JSON-ready fields, the keys of the other line-delay results where they apply."""
        known = self.line_delay_s is not None and self.line_delay_s != 0
        return {"trajectory_model": self.trajectory_model, "frames_total": self.frames_total,
                "frames_used": self.frames_used, "observations": self.observations, "rms_px": self.rms_px,
                "line_delay_s": self.line_delay_s, "readout_time_s": self.readout_time_s if known else None,
                "time_reference": "mid-readout" if known else "row 0 (no line delay given)",
                "warnings": list(self.warnings)}


def pnp_trajectory(observations: Observations, camera: CameraModel, rows: Optional[int] = None,
                   line_delay_s: Optional[float] = None) -> PnpTrajectory:
    """The per-frame GS PnP baseline as a trajectory (see PnpTrajectory); rows: read out
    (default: image height). InputError when no frame has a pose."""
    rows = rows if rows is not None else observations.image_size[1]
    poses = per_frame_pnp(observations, camera)
    if np.count_nonzero(poses.ok) == 0:
        raise InputError("no frame has enough target points for a PnP pose")
    readout_s = (line_delay_s or 0.0) * rows
    # the middle of the image's readout (its rows, not the --rows read out): as trajectory.csv
    times = observations.frame_times_s[poses.ok] + 0.5 * (line_delay_s or 0.0) * observations.image_size[1]
    states = np.c_[poses.translation[poses.ok], unwrap_rotation_vectors(poses.rotation_vector[poses.ok])]
    points = np.bincount(observations.frame_index, minlength=observations.num_frames)[poses.ok]
    return PnpTrajectory(times_s=times, states=states, frames_total=observations.num_frames,
                         frames_used=int(np.count_nonzero(poses.ok)), observations=int(np.sum(points)),
                         rms_px=float(np.sqrt(np.nanmean(poses.rms_px[poses.ok] ** 2))),
                         line_delay_s=line_delay_s, readout_time_s=readout_s)


def compare_with_pnp(result, camera: CameraModel) -> dict:
    """How a continuous-time result (rscalib.localize / calibrate_line_delay) compares with the
    per-frame GS PnP poses it started from (paper Fig. 5): the reprojection RMS of both, and how
    far their camera centres differ at the frames' mid-readout times."""
    poses = result.frame_poses
    obs = result.used_observations
    t_mid = np.clip(obs.frame_times_s + 0.5 * result.line_delay_s * obs.image_size[1], result.trajectory.t_begin,
                    result.trajectory.t_end)
    rotations, translations = poses_at(result.trajectory, t_mid)
    centre_rs = -np.einsum("nji,nj->ni", rotations, translations)
    r_gs = np.stack([rotation_vector_to_matrix(v) for v in poses.rotation_vector])
    centre_gs = -np.einsum("nji,nj->ni", r_gs, poses.translation)
    diff = np.linalg.norm(centre_rs - centre_gs, axis=1)
    return {"gs_pnp_rms_px": float(np.sqrt(np.nanmean(poses.rms_px ** 2))), "rs_rms_px": result.rms_px,
            "mean_centre_difference_m": float(np.mean(diff)), "max_centre_difference_m": float(np.max(diff))}
