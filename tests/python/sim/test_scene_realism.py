"""The realistic room renderer (rscalib.sim.scene_realism): rolling shutter, frame timing, photographic
textures, and one `rscalib selfcalib` run on a realistic sequence. Fixed seeds; small and fast."""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rscalib._core import CameraModel
from rscalib.sim import scene_realism as sr
from rscalib.sim.scene_video import Scene, SceneRenderer, TexturedPlane
from rscalib.sim.trajectories import CameraMotion

CLI = [sys.executable, "-m", "rscalib.cli"]
F, Z = 200.0, 2.0


class Translation(CameraMotion):
    """Camera looking along world +z (R = I), centre moving at a constant velocity from the origin."""

    def __init__(self, velocity_m_s):
        self.velocity = np.asarray(velocity_m_s, dtype=np.float64)

    def _pose(self, t_s):
        return np.tile(np.eye(3), (len(t_s), 1, 1)), t_s[:, None] * self.velocity


def edge_scene(vertical_edge: bool) -> tuple[CameraModel, SceneRenderer]:
    """A 4 × 4 m plane at z = 2 m, dark (0.2) on one side of x = 0 (vertical edge) or y = 0 (horizontal)."""
    texture = np.full((800, 800), 0.8, dtype=np.float32)
    if vertical_edge:
        texture[:, :400] = 0.2
    else:
        texture[:400, :] = 0.2
    camera = CameraModel("civera-radial", [F, 159.5, 119.5, 0.0, 0.0], 320, 240, pixel_size_mm=(0.0112, 0.0112))
    plane = TexturedPlane("front", (-2.0, -2.0, Z), (1, 0, 0), (0, 1, 0), (4.0, 4.0), texture, 200.0)
    return camera, SceneRenderer(camera, Scene([plane]), supersampling=2)


def crossing(profile: np.ndarray) -> float:
    """Sub-pixel position where a dark-to-bright profile crosses 0.5."""
    i = int(np.argmax(profile >= 0.5))
    return i - 1 + (0.5 - profile[i - 1]) / (profile[i] - profile[i - 1])


def rows_render(renderer, motion, line_delay_s):
    R, p = motion.pose_cw(np.arange(renderer.height) * line_delay_s)
    return renderer.render_rows(R, p)


def test_render_rows_with_one_pose_is_the_global_shutter_image():
    camera, renderer = edge_scene(True)
    R, p = Translation((0.3, 0.1, 0.0)).pose_cw(np.array([0.05]))
    rows = renderer.render_rows(np.repeat(R, 240, axis=0), np.repeat(p, 240, axis=0))
    np.testing.assert_allclose(rows, renderer.render(R[0], p[0]), atol=1e-6)


def test_rolling_shutter_shears_a_vertical_edge_under_sideways_motion():
    _, renderer = edge_scene(True)
    speed_m_s, d = 2.0, 100e-6  # image speed -F v / Z = -200 px/s: 0.02 px per row
    image = rows_render(renderer, Translation((speed_m_s, 0.0, 0.0)), d)
    rows = np.arange(20, 220, 20)
    u = np.array([crossing(image[v]) for v in rows])
    predicted = 159.5 - F * speed_m_s * rows * d / Z
    np.testing.assert_allclose(u, predicted, atol=0.1)
    assert u[0] - u[-1] > 3.0  # a visible shear: the edge leans by 3.6 px over 180 rows


def test_rolling_shutter_moves_a_horizontal_edge_under_vertical_motion_as_predicted():
    _, renderer = edge_scene(False)
    speed_m_s, d = 4.0, 100e-6
    gs = renderer.render(np.eye(3), np.zeros(3))
    rs = rows_render(renderer, Translation((0.0, speed_m_s, 0.0)), d)
    v_gs = crossing(gs[:, 100:220].mean(axis=1))
    v_rs = crossing(rs[:, 100:220].mean(axis=1))
    # Row v is seen at t = v d: v = cy - F speed v d / Z  =>  v = cy / (1 + F speed d / Z).
    assert v_gs == pytest.approx(119.5, abs=0.1)
    assert v_rs == pytest.approx(119.5 / (1 + F * speed_m_s * d / Z), abs=0.1)
    assert v_gs - v_rs > 4.0


def small_realism(**phone) -> sr.SceneRealism:
    realism = sr.SceneRealism(textures="procedural", texels_per_m=100.0)
    return replace(realism, phone=replace(realism.phone, exposure_samples=2, **phone))


def test_timestamps_jitter_and_drop(tmp_path):
    realism = small_realism(jitter_s=3e-3, drop_probability=0.2)
    seq = sr.render_realistic_scene(tmp_path, "look-around", (320, 240), 15, seed=3, realism=realism)
    stamps = np.loadtxt(tmp_path / "timestamps.txt")
    frames = sorted(tmp_path.glob("frame_*.png"))
    assert len(stamps) == len(frames) == seq.truth["num_frames_rendered"] < 15  # some frames dropped
    steps = np.diff(stamps)
    assert np.all(steps > 0)
    assert np.any(steps > 1.5 / 30)  # a gap where a frame was dropped
    regular = steps[steps < 1.5 / 30]
    assert regular.std() > 1e-3  # jitter of a few ms
    assert seq.truth["shutter"] == "rolling" and seq.truth["line_delay_s"] == pytest.approx(60e-6)
    assert seq.truth["textures"] == "procedural"
    assert seq.truth["codec_used"].startswith(("h264", "mpeg4"))
    assert len(seq.truth["auto_exposure"]["steps"]) == 2


# ../shared/data beside the checkout (the installed package cannot know where the checkout is)
SHARED_DATA = Path(__file__).resolve().parents[4] / "shared" / "data"


def test_photographic_textures_come_from_the_shared_data():
    tiles = sr.photo_tiles(SHARED_DATA) if SHARED_DATA.is_dir() else None
    if tiles is None:
        pytest.skip("../shared/data not present")
    names = [name for name, _ in tiles.photographs]
    assert any(n.startswith("real_selfcalib_s3phone/") for n in names)
    assert any(n.startswith("opencv_stereo_chessboard/") for n in names)
    texture = tiles(1.0, 0.5, seed=7, texels_per_m=200.0)
    assert texture.shape == (100, 200) and texture.dtype == np.float32
    assert texture.std() > 0.05
    np.testing.assert_array_equal(texture, tiles(1.0, 0.5, seed=7, texels_per_m=200.0))  # seeded


def test_missing_photographs_fall_back_to_procedural_and_say_so(tmp_path):
    realism = replace(small_realism(), textures="photo", data_dir=str(tmp_path / "absent"))
    seq = sr.render_realistic_scene(tmp_path / "seq", "sideways-dolly", (320, 240), 3, seed=1, realism=realism)
    assert seq.truth["textures"].startswith("procedural (no photographs")


def test_motion_styles_differ_as_documented():
    t = np.linspace(0.0, 6.0, 181)
    for style, (min_path_m, max_turn_deg) in {"walk-forward": (2.0, 60.0), "look-around": (0.0, 360.0),
                                              "sideways-dolly": (2.4, 20.0)}.items():
        motion = sr.StyledRoomMotion(style, seed=5, duration_s=6.0)
        R, centre = motion.pose_wc(t)
        path = np.linalg.norm(centre[-1] - centre[0])
        forward = R[:, :, 2]
        turn = np.degrees(np.arccos(np.clip(forward @ forward[0], -1, 1))).max()
        assert path >= min_path_m and turn <= max_turn_deg, style
        assert np.all(np.abs(centre[:, :2]) < np.array(sr.ROOM_SIZE_M[:2]) / 2 - 0.3), style  # inside the room
    assert np.linalg.norm(np.ptp(sr.StyledRoomMotion("look-around", 5, 6.0).pose_wc(t)[1], axis=0)) < 0.3


def test_selfcalib_on_a_realistic_sequence_is_inside_its_bounds_or_exit_3(tmp_path):
    seq = sr.render_realistic_scene(tmp_path / "seq", "walk-forward", (320, 240), 70, seed=2,
                                    realism=replace(small_realism(), textures="photo"))
    proc = subprocess.run([*CLI, "selfcalib", str(tmp_path / "seq"), "--pixel-size-mm", "0.0112",
                           "--out", str(tmp_path / "out"), "--quiet"], capture_output=True, text=True)
    assert proc.returncode in (0, 3), proc.stderr
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    if proc.returncode == 0:
        for name, truth in zip(("f", "cx", "cy", "k1", "k2"), seq.truth["camera"]["params"]):
            lo, hi = result[f"{name}_bounds_99"]
            assert lo <= truth <= hi, name
    else:
        assert result["determined"] is False and result["reason"]
