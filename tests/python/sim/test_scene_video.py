"""Synthetic scene renderer for the SOG self-calibration engine (rscalib.sim.scene_video)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

import rscalib
from rscalib.sim import scene_video as sr
from rscalib.sim.trajectories import RoomWalkTrajectory

FPS = 30.0


@pytest.fixture(scope="module")
def room_frames() -> sr.RenderedFrames:
    return sr.render_scene_frames(num_frames=4, seed=0)


def small_pose(angle_deg=(3.0, -4.0, 2.0), t_m=(0.05, -0.03, 0.1)):
    R, _ = cv2.Rodrigues(np.deg2rad(np.asarray(angle_deg, dtype=np.float64)))
    return R, np.asarray(t_m, dtype=np.float64)


def front_plane(texture: np.ndarray, texels_per_m: float, depth_m: float) -> sr.TexturedPlane:
    """A plane z = depth_m facing a camera at the origin, u along world x, v along world y."""
    h, w = texture.shape
    size = (w / texels_per_m, h / texels_per_m)
    return sr.TexturedPlane("front", (-0.5 * size[0], -0.5 * size[1], depth_m), (1, 0, 0), (0, 1, 0), size,
                            texture, texels_per_m)


def project(camera, R, p, points_w):
    return np.asarray(camera.project(points_w @ np.asarray(R).T + p))


# ---------------------------------------------------------------------------------------------------
# Geometry


def test_surface_points_project_back_to_their_pixels(room_frames):
    cam = room_frames.camera
    for frame in (0, 3):
        hits = room_frames.surface(frame)
        assert hits.points_w.shape == (cam.height, cam.width, 3)
        assert np.all(hits.plane_index >= 0)  # closed room: every ray hits a wall
        R, p = room_frames.R_cw[frame], room_frames.p_cw[frame]
        pts = hits.points_w.reshape(-1, 3)
        uu, vv = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
        uv = project(cam, R, p, pts)
        np.testing.assert_allclose(uv, np.column_stack([uu.ravel(), vv.ravel()]), atol=1e-6)
        np.testing.assert_allclose((pts @ R.T + p)[:, 2], hits.depth_m.ravel(), rtol=1e-9)
        # Points lie inside the 4 x 3 x 2.5 m room, on its boundary.
        lim = np.array([2.0, 1.5])
        on_wall = np.isclose(np.abs(pts[:, :2]), lim, atol=1e-6).any(axis=1)
        on_floor_or_ceiling = np.isclose(pts[:, 2], 0.0, atol=1e-6) | np.isclose(pts[:, 2], 2.5, atol=1e-6)
        assert np.all(on_wall | on_floor_or_ceiling)


def test_markers_appear_where_the_camera_model_projects_them():
    cam = sr.default_camera()
    tpm, depth_m = 400.0, 2.0
    texture = np.full((int(3.0 * tpm), int(4.0 * tpm)), 0.1, dtype=np.float32)
    plane = front_plane(texture, tpm, depth_m)
    # 6 x 4 bright discs (1.5 cm radius, ~1.5 px in the image) spread to the image borders.
    xs, ys = np.meshgrid(np.linspace(-1.6, 1.6, 6), np.linspace(-1.2, 1.2, 4))
    markers_w = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, depth_m)])
    for x, y, _ in markers_w:
        centre_tx = ((np.array([x, y]) - plane.origin_m[:2]) * tpm - 0.5) * 16
        cv2.circle(texture, tuple(np.round(centre_tx).astype(int)), int(0.015 * tpm * 16), 0.9, -1, cv2.LINE_AA, 4)
    plane.texture = texture
    R, p = small_pose()
    renderer = sr.SceneRenderer(cam, sr.Scene([plane]), supersampling=3)
    img = renderer.render(R, p) - 0.1
    uv_pred = project(cam, R, p, markers_w)
    inside = np.all((uv_pred > 6) & (uv_pred < [cam.width - 7, cam.height - 7]), axis=1)
    assert inside.sum() >= 12
    errors = []
    for u, v in uv_pred[inside]:
        u0, v0 = int(round(u)), int(round(v))
        win = img[v0 - 5:v0 + 6, u0 - 5:u0 + 6].astype(np.float64)
        vv, uu = np.mgrid[v0 - 5:v0 + 6, u0 - 5:u0 + 6]
        centroid = np.array([(win * uu).sum(), (win * vv).sum()]) / win.sum()
        errors.append(np.linalg.norm(centroid - [u, v]))
    assert max(errors) < 0.3, errors


def edge_columns(img: np.ndarray, level: float) -> np.ndarray:
    """Per row, the sub-pixel column where a dark-to-bright step crosses `level` (NaN if none)."""
    out = np.full(img.shape[0], np.nan)
    for row in range(img.shape[0]):
        above = np.flatnonzero((img[row, :-1] < level) & (img[row, 1:] >= level))
        if len(above) == 1:
            i = above[0]
            out[row] = i + (level - img[row, i]) / (img[row, i + 1] - img[row, i])
    return out


@pytest.mark.parametrize("distorted", [True, False])
def test_straight_edges_are_curved_by_the_distortion(distorted):
    params = list(sr.PAPER_CAMERA_PARAMS) if distorted else [*sr.PAPER_CAMERA_PARAMS[:3], 0.0, 0.0]
    cam = rscalib.CameraModel("civera-radial", params, 320, 240, pixel_size_mm=(sr.PAPER_PIXEL_SIZE_MM,) * 2)
    tpm, depth_m, edge_x_m = 200.0, 1.5, 0.9
    texture = np.full((int(6.0 * tpm), int(8.0 * tpm)), 0.15, dtype=np.float32)
    plane = front_plane(texture, tpm, depth_m)
    texture[:, int(round((edge_x_m - plane.origin_m[0]) * tpm)):] = 0.85  # step at world x = edge_x_m
    plane.texture = texture
    renderer = sr.SceneRenderer(cam, sr.Scene([plane]), supersampling=3)
    img = renderer.render(np.eye(3), np.zeros(3))
    cols = edge_columns(img, 0.5)
    rows = np.flatnonzero(np.isfinite(cols))
    assert len(rows) == cam.height

    # Where the model puts the 3-D edge in each row: project a dense line and interpolate.
    line = np.column_stack([np.full(4001, edge_x_m), np.linspace(-2.5, 2.5, 4001), np.full(4001, depth_m)])
    uv_line = np.asarray(cam.project(line))
    ok = np.isfinite(uv_line).all(axis=1)
    model_cols = np.interp(rows, uv_line[ok, 1], uv_line[ok, 0])
    assert np.max(np.abs(cols[rows] - model_cols)) < 0.3

    fit = np.polyfit(rows, cols[rows], 1)
    deviation_px = np.max(np.abs(np.polyval(fit, rows) - cols[rows]))
    if distorted:
        assert deviation_px > 3.0, deviation_px
    else:
        assert deviation_px < 0.2, deviation_px


# ---------------------------------------------------------------------------------------------------
# Determinism, files, trajectory


def test_render_is_deterministic_from_the_seed(room_frames):
    again = sr.render_scene_frames(num_frames=2, seed=0)
    np.testing.assert_array_equal(again.images, room_frames.images[:2])
    other = sr.render_scene_frames(num_frames=1, seed=1)
    assert np.mean(np.abs(other.images[0].astype(int) - room_frames.images[0])) > 10
    noisy_a = sr.render_scene_frames(num_frames=2, seed=0, noise_sigma=2.0)
    noisy_b = sr.render_scene_frames(num_frames=2, seed=0, noise_sigma=2.0)
    np.testing.assert_array_equal(noisy_a.images, noisy_b.images)
    diff = noisy_a.images.astype(float) - room_frames.images[:2]
    assert 1.5 < diff.std() < 2.5


def test_sequence_files(tmp_path, room_frames):
    seq = sr.render_scene_sequence(tmp_path / "seq", num_frames=4, seed=0, fps=FPS)
    names = sorted(p.name for p in (tmp_path / "seq").glob("*.png"))
    assert names == [f"frame_{i:06d}.png" for i in range(4)]
    times = np.loadtxt(tmp_path / "seq" / "timestamps.txt")
    np.testing.assert_allclose(times, np.arange(4) / FPS, atol=1e-9)
    for i, path in enumerate(seq.frame_paths):
        np.testing.assert_array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), room_frames.images[i])

    truth = sr.load_scene_truth(tmp_path / "seq")
    assert truth["camera"]["model"] == "civera-radial"
    np.testing.assert_allclose(truth["camera"]["params"], sr.PAPER_CAMERA_PARAMS)
    np.testing.assert_allclose(truth["camera"]["pixel_size_mm"], sr.PAPER_PIXEL_SIZE_MM)
    assert truth["fps"] == FPS and truth["seed"] == 0 and truth["num_frames"] == 4
    np.testing.assert_allclose(truth["t_s"], times, atol=1e-9)
    np.testing.assert_allclose(truth["R_cw"], room_frames.R_cw, atol=1e-12)
    np.testing.assert_allclose(truth["p_cw"], room_frames.p_cw, atol=1e-12)
    np.testing.assert_allclose(truth["center_w"], -np.einsum("nji,nj->ni", truth["R_cw"], truth["p_cw"]),
                               atol=1e-12)
    assert len(truth["scene"]["planes"]) == 6
    json.dumps(truth["scene"])  # plain data


def test_planes_scene_has_background_and_hits():
    frames = sr.render_scene_frames(num_frames=1, seed=0, scene=sr.planes_scene(0),
                                    trajectory=RoomWalkTrajectory(seed=0, yaw0_deg=0.0, yaw_amplitude_deg=15,
                                                                  center_m=(0.0, 0.0, 1.4)))
    hits = frames.surface(0)
    assert np.mean(hits.plane_index >= 0) > 0.9
    assert np.all(np.isnan(hits.depth_m[hits.plane_index < 0]))


# ---------------------------------------------------------------------------------------------------
# Features: what the SOG front end needs


def test_corners_and_ncc_matches_follow_the_truth(room_frames):
    cam = room_frames.camera
    half, search = 5, 8  # 11x11 patches, ±8 px search window
    good, total = 0, 0
    for i in range(len(room_frames.images) - 1):
        img0, img1 = room_frames.images[i], room_frames.images[i + 1]
        corners = cv2.goodFeaturesToTrack(img0, maxCorners=400, qualityLevel=0.01, minDistance=5)
        assert corners is not None and len(corners) >= 100
        corners = corners.reshape(-1, 2)
        border = half + search + 2
        keep = np.all((corners >= border) & (corners < [cam.width - border, cam.height - border]), axis=1)
        corners = np.round(corners[keep])
        X = room_frames.surface(i, corners).points_w
        uv_true = project(cam, room_frames.R_cw[i + 1], room_frames.p_cw[i + 1], X)
        for (u, v), (ut, vt) in zip(corners.astype(int), uv_true):
            if not (np.isfinite(ut) and border <= ut < cam.width - border and border <= vt < cam.height - border):
                continue
            patch = img0[v - half:v + half + 1, u - half:u + half + 1]
            cu, cv_ = int(round(ut)), int(round(vt))
            window = img1[cv_ - half - search:cv_ + half + search + 1, cu - half - search:cu + half + search + 1]
            score = cv2.matchTemplate(window, patch, cv2.TM_CCOEFF_NORMED)
            py, px = np.unravel_index(np.argmax(score), score.shape)
            offset = np.zeros(2)
            for axis, (a, b, c) in enumerate(
                    [(score[py, px - 1], score[py, px], score[py, px + 1]) if 0 < px < score.shape[1] - 1 else (0, 1, 0),
                     (score[py - 1, px], score[py, px], score[py + 1, px]) if 0 < py < score.shape[0] - 1 else (0, 1, 0)]):
                denom = a - 2 * b + c
                offset[axis] = 0.5 * (a - c) / denom if denom < 0 else 0.0  # parabola through the peak
            match = np.array([cu - search + px, cv_ - search + py]) + offset
            total += 1
            good += np.linalg.norm(match - [ut, vt]) < 1.0
    assert total >= 200
    assert good / total > 0.9, (good, total)
