"""rscalib.sim.scene_truth: the true pixels of image tracks in a realistic render, checked against the
rendered images themselves (an independent oracle: pyramidal KLT on the frames) and for
self-consistency (a pixel's point projects back to that pixel)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from rscalib.sim.scene_realism import SceneRealism, render_realistic_scene
from rscalib.sim.scene_truth import RenderTruth


@pytest.fixture(scope="module")
def render(tmp_path_factory):
    out = tmp_path_factory.mktemp("truth")
    scene = render_realistic_scene(out, "look-around", (320, 240), 8, 3, realism=SceneRealism(textures="procedural"))
    frames = [cv2.imread(str(out / f["file"]), cv2.IMREAD_GRAYSCALE) for f in scene.truth["frames"]]
    return json.loads((out / "truth.json").read_text()), frames


def test_a_pixels_point_projects_back_to_it(render):
    truth, _ = render
    rt = RenderTruth(truth)
    rng = np.random.default_rng(0)
    uv = rng.uniform([10, 10], [310, 230], (50, 2))
    frame = rng.integers(0, len(truth["frames"]), 50)
    X = rt.points_under(frame, uv)
    assert np.all(np.abs(X[:, :2]) <= np.array(truth["realism"]["room_size_m"][:2]) / 2 + 1e-9)
    np.testing.assert_allclose(rt.project(frame, X, v_guess_px=uv[:, 1] + 3.0, iterations=6), uv, atol=1e-4)


def test_track_pixels_agree_with_klt_on_the_rendered_frames(render):
    truth, frames = render
    rt = RenderTruth(truth)
    corners = cv2.goodFeaturesToTrack(frames[0], 80, 0.02, 10).reshape(-1, 2).astype(np.float64)
    last = len(frames) - 1
    klt, status, _ = cv2.calcOpticalFlowPyrLK(frames[0], frames[last], corners.astype(np.float32).reshape(-1, 1, 2),
                                              None, winSize=(21, 21), maxLevel=3)
    klt = klt.reshape(-1, 2).astype(np.float64)
    ok = status.ravel() == 1
    frame = np.r_[np.zeros(len(corners), int), np.full(len(corners), last)]
    track = np.r_[np.arange(len(corners)), np.arange(len(corners))]
    true = rt.track_pixels(frame, track, np.r_[corners, klt])
    np.testing.assert_allclose(true[: len(corners)], corners, atol=1e-4)       # the first view is its own truth
    err = np.linalg.norm(true[len(corners):] - klt, axis=1)[ok]
    moved = np.linalg.norm(klt - corners, axis=1)[ok]
    assert np.median(moved) > 3.0                   # the view did move ...
    assert np.median(err) < 0.3                     # ... and the truth follows the images
