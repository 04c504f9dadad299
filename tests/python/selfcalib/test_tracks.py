"""The bundle adjustment's front end (rscalib.selfcalib.tracks, docs/sog.md §22) against oracles it
does not use: a textured plane seen through known homographies (each track's true pixel in frame k
is H_k H_0⁻¹ applied to its first pixel), correspondences with known outliers, exact velocities.
Fixed seeds; 320x240 so that each test runs in about a second."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from rscalib.errors import InputError
from rscalib.selfcalib.tracks import FeatureTracker, TrackOptions, geometric_inliers, image_velocities, track_features

WIDTH, HEIGHT = 320, 240
K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])


def texture(width: int, height: int, seed: int) -> np.ndarray:
    """Blobs at two scales: corners everywhere, smooth enough to interpolate (float32, 20-235)."""
    rng = np.random.default_rng(seed)
    fine = cv2.GaussianBlur(rng.uniform(0, 1, (height, width)).astype(np.float32), (0, 0), 1.5)
    coarse = cv2.GaussianBlur(rng.uniform(0, 1, (height, width)).astype(np.float32), (0, 0), 5.0)
    image = fine / fine.std() + 0.7 * coarse / coarse.std()
    return cv2.normalize(image, None, 20, 235, cv2.NORM_MINMAX)


def rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    Rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return Rz @ Rx @ Ry


def plane_homography(R: np.ndarray, centre: np.ndarray, texel_m: float, origin_texel: tuple[float, float],
                     depth_m: float = 2.0) -> np.ndarray:
    """Texture pixel (s, t) -> image pixel for a plane z = depth_m whose texel (s, t) lies at world
    ((s - s0) texel_m, (t - t0) texel_m, depth_m), seen by a camera x_c = R (X - centre)."""
    s0, t0 = origin_texel
    A = np.array([[texel_m, 0.0, -texel_m * s0], [0.0, texel_m, -texel_m * t0], [0.0, 0.0, depth_m]])
    A[:, 2] -= centre
    return K @ R @ A


class PlaneVideo:
    """Frames of a textured plane (``texture`` float32) under homographies ``H[k]`` (texture -> image),
    with sensor noise; optionally a square patch of another texture moving on its own."""

    def __init__(self, tex: np.ndarray, H: list, times: np.ndarray, noise: float = 1.0, seed: int = 3,
                 moving_patch: bool = False) -> None:
        self.tex, self.H, self.times, self.noise, self.seed = tex, H, times, noise, seed
        self.moving_patch = moving_patch
        self.patch = texture(48, 48, seed + 100)

    def patch_corner(self, k: int) -> np.ndarray:
        return np.array([60.0 + 2.5 * k, 150.0 - 1.5 * k])   # moves ~3 px/frame against the scene

    def frames(self):
        rng = np.random.default_rng(self.seed)
        for k, (t, H) in enumerate(zip(self.times, self.H)):
            image = cv2.warpPerspective(self.tex, H, (WIDTH, HEIGHT), flags=cv2.INTER_CUBIC,
                                        borderMode=cv2.BORDER_REFLECT)
            if self.moving_patch:
                x, y = self.patch_corner(k)
                shift = np.array([[1.0, 0.0, x], [0.0, 1.0, y]])
                warped = cv2.warpAffine(self.patch, shift, (WIDTH, HEIGHT), flags=cv2.INTER_CUBIC)
                inside = cv2.warpAffine(np.ones_like(self.patch), shift, (WIDTH, HEIGHT)) > 0.5
                image = np.where(inside, warped, image)
            image = image + rng.normal(0, self.noise, image.shape)
            yield float(t), np.clip(np.round(image), 0, 255).astype(np.uint8)

    def truth(self, frame: np.ndarray, track_id: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Each observation's true pixel: its track's first pixel carried by H_k H_first⁻¹."""
        order = np.lexsort((frame, track_id))
        first = {}
        for i in order.tolist():
            first.setdefault(int(track_id[i]), i)
        out = np.empty_like(uv)
        for i in range(len(frame)):
            j = first[int(track_id[i])]
            M = self.H[int(frame[i])] @ np.linalg.inv(self.H[int(frame[j])])
            x = M @ np.array([uv[j, 0], uv[j, 1], 1.0])
            out[i] = x[:2] / x[2]
        return out


def wandering_video(frames: int = 120, seed: int = 5, **kwargs) -> PlaneVideo:
    """A camera drifting over a plane 2 m away: ±0.25 m sideways, ±12 % in distance, ±8° roll,
    ±4° yaw/pitch (so each track's appearance changes: scale, rotation, perspective)."""
    tex = texture(900, 700, seed)
    times = np.arange(frames) / 30.0
    H = []
    for t in times:
        a = 2 * np.pi * t / (frames / 30.0)
        R = rotation(np.deg2rad(4) * np.sin(a), np.deg2rad(4) * np.sin(2 * a), np.deg2rad(8) * np.sin(a + 1))
        centre = np.array([0.25 * np.sin(a), 0.15 * np.sin(2 * a + 0.5), 0.24 * np.sin(1.5 * a)])
        H.append(plane_homography(R, centre, 0.005, (450, 350)))
    return PlaneVideo(tex, H, times, **kwargs)


def errors(video: PlaneVideo, tracks) -> tuple[np.ndarray, np.ndarray]:
    truth = video.truth(tracks.frame, tracks.track_id, tracks.uv_px)
    err = np.linalg.norm(tracks.uv_px - truth, axis=1)
    order = np.lexsort((tracks.frame, tracks.track_id))
    first = {}
    for i in order.tolist():
        first.setdefault(int(tracks.track_id[i]), int(tracks.frame[i]))
    age = tracks.frame - np.array([first[int(i)] for i in tracks.track_id])
    return err, age


@pytest.fixture(scope="module")
def wandering():
    video = wandering_video()
    return video, track_features(video.frames())


def test_tracks_follow_the_plane_without_drift(wandering):
    video, tracks = wandering
    err, age = errors(video, tracks)
    lengths = tracks.track_lengths()
    assert tracks.stats["live_tracks_median"] > 150        # 250 wanted at 320x240
    assert np.sum(lengths["span_frames"] >= 100) > 50         # long tracks
    assert np.mean(err > 1.0) < 0.002
    good = err <= 1.0
    young = np.sqrt(np.mean(err[good & (age >= 1) & (age < 10)] ** 2))
    old = np.sqrt(np.mean(err[good & (age >= 60)] ** 2))
    assert old < 0.1 and young < 0.1
    assert old < 1.5 * young + 0.02                           # no growth with age
    anchored = tracks.anchored & good & (age >= 60)
    assert np.sqrt(np.mean(err[anchored] ** 2)) < 0.08


def test_without_anchoring_the_same_tracks_drift(wandering):
    """The oracle can see drift: frame-to-frame KLT alone accumulates it."""
    video, anchored_tracks = wandering
    tracks = track_features(video.frames(), TrackOptions(anchor=False))
    err, age = errors(video, tracks)
    err_a, age_a = errors(video, anchored_tracks)
    old = (age >= 60) & (err < 2)
    old_a = (age_a >= 60) & (err_a < 2)
    assert np.sqrt(np.mean(err[old] ** 2)) > 1.5 * np.sqrt(np.mean(err_a[old_a] ** 2))


def test_keyframes_and_their_observations(wandering):
    _, tracks = wandering
    gaps = np.diff(tracks.keyframes)
    assert tracks.keyframes[0] == 0 and gaps.max() <= TrackOptions().keyframe_max_gap_frames
    obs = tracks.keyframe_observations(min_keyframes=3)
    assert set(np.unique(obs.frame)) <= set(tracks.keyframes.tolist())
    _, counts = np.unique(obs.track_id, return_counts=True)
    assert counts.min() >= 3
    np.testing.assert_array_equal(obs.t_s, tracks.t_s[obs.frame])
    assert len(obs.position_sigma) == len(obs) and np.all(np.isfinite(obs.position_sigma))
    thin = tracks.keyframe_observations(min_keyframes=2, max_keyframes=5)
    assert len(np.unique(thin.frame)) <= 5 and len(thin.keyframes) == 5
    # every keyframe observation was aligned with its track's first view (or is that first view)
    rows = np.isin(tracks.frame, tracks.keyframes)
    assert np.mean(tracks.anchored[rows]) > 0.97


def test_image_velocities_against_the_known_motion():
    """The plane slides at a constant image velocity; frames come at jittered times."""
    rng = np.random.default_rng(8)
    times = np.cumsum(rng.uniform(0.027, 0.040, 60))
    velocity = np.array([75.0, -40.0])                         # px/s in the image
    tex = texture(900, 700, 9)
    H = [np.array([[1.0, 0.0, -300 + velocity[0] * t], [0.0, 1.0, -200 + velocity[1] * t], [0.0, 0.0, 1.0]])
         for t in times]
    done = []
    tracks = track_features(PlaneVideo(tex, H, times).frames(), frame_count=60,
                            progress=lambda n, total: done.append((n, total)))
    assert done[-1] == (60, 60)                                # the progress callback saw every frame
    v = tracks.velocity_px_s
    ok = np.all(np.isfinite(v), axis=1)
    assert ok.mean() > 0.95
    assert np.median(np.linalg.norm(v[ok] - velocity, axis=1)) < 0.02 * np.linalg.norm(velocity)


def test_image_velocities_use_the_frames_own_times():
    t = np.array([0.0, 0.03, 0.07, 0.10, 0.14, 0.18, 0.21, 0.50])
    frame = np.array([0, 1, 2, 3, 7, 1, 2])
    track = np.array([1, 1, 1, 1, 1, 2, 2])
    uv = np.c_[10 * t[frame], np.zeros(7)]
    v = image_velocities(frame, track, uv, t)
    np.testing.assert_allclose(v[:4, 0], 10.0)               # central or one-sided, exact for linear motion
    np.testing.assert_allclose(v[:4, 1], 0.0)
    assert np.all(np.isnan(v[4]))                              # its neighbour is 4 frames away
    np.testing.assert_allclose(v[5:, 0], 10.0)
    v_gap = image_velocities(frame, track, uv, t, max_gap_frames=0)
    assert np.all(np.isnan(v_gap))


def general_scene(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of n random 3-D points (depths 2-8 m) in two views 0.3 m apart, rotated 3°."""
    rng = np.random.default_rng(seed)
    X = np.c_[rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(2, 8, n)]
    def view(R, c):
        x = (R @ (X - c).T).T @ K.T
        return x[:, :2] / x[:, 2:]
    return view(np.eye(3), np.zeros(3)), view(rotation(0.05, 0.01, 0.02), np.array([0.3, 0.05, 0.1]))


@pytest.mark.parametrize("scene", ["general", "plane"])
def test_geometric_check_removes_injected_wrong_matches(scene):
    rng = np.random.default_rng(21)
    if scene == "general":
        uv0, uv1 = general_scene(4, 300)
    else:   # a homography: the fundamental matrix is not determined, the check must use H
        uv0 = rng.uniform([0, 0], [WIDTH, HEIGHT], (300, 2))
        H = plane_homography(rotation(0.02, 0.01, 0.03), np.array([0.1, 0.0, 0.05]), 0.005, (160, 120))
        H = H @ np.linalg.inv(plane_homography(np.eye(3), np.zeros(3), 0.005, (160, 120)))
        x = np.c_[uv0, np.ones(300)] @ H.T
        uv1 = x[:, :2] / x[:, 2:]
    uv1 = uv1 + rng.normal(0, 0.2, uv1.shape)
    wrong = rng.choice(300, 30, replace=False)
    # a moving patch: its matches move together, 4-8 px off the scene's motion
    uv1[wrong] += rng.uniform(4, 8) * np.array([np.cos(1.0), np.sin(1.0)]) + rng.normal(0, 0.2, (30, 2))
    inliers = geometric_inliers(uv0, uv1, 1.0, TrackOptions().homography_share, TrackOptions().homography_px_factor)
    right = np.setdiff1d(np.arange(300), wrong)
    assert inliers[right].mean() > 0.97
    assert inliers[wrong].sum() <= 1


def test_moving_patch_is_not_tracked_as_scene():
    video = wandering_video(frames=60, seed=6, moving_patch=True)
    tracks = track_features(video.frames())
    err, age = errors(video, tracks)
    # observations of the patch (tracked with it) would be wrong by 3 px more each frame; the few
    # 1-1.5 px errors are scene points next to the patch's edge (their first view holds some of it)
    assert np.sum(err > 2.0) == 0
    assert np.mean(err > 1.0) < 0.01
    assert tracks.stats["rejected_frame_ransac"] > 20


def test_forward_backward_check_drops_points_under_a_sudden_occluder():
    """A square of another texture appears in frame 20 for 3 frames: KLT's forward-backward check
    (or the RANSAC) drops the points under it instead of following the occluder."""
    video = wandering_video(frames=40, seed=7)
    frames = list(video.frames())
    block = texture(90, 90, 77).astype(np.uint8)
    for k in (20, 21, 22):
        frames[k][1][60:150, 100:190] = block
    tracks = track_features(frames)
    err, _ = errors(video, tracks)
    visible = ~((tracks.frame >= 20) & (tracks.frame <= 22) & (tracks.uv_px[:, 0] > 95) & (tracks.uv_px[:, 0] < 195)
                & (tracks.uv_px[:, 1] > 55) & (tracks.uv_px[:, 1] < 155))
    assert np.mean(err[visible] > 1.0) < 0.003
    assert tracks.stats["lost_klt"] + tracks.stats["rejected_frame_ransac"] > 20


def pan_video(tex: np.ndarray, frames: int = 140, seed: int = 2, pan_px: float = 420.0) -> PlaneVideo:
    """The view (320 px wide) slides ``pan_px`` to the right over the texture and back: the first
    view leaves entirely and comes back (each lost point was seen in a keyframe together with
    points that are still tracked when it returns: the geometric check's support)."""
    times = np.arange(frames) / 30.0
    half = frames // 2
    x = np.where(np.arange(frames) < half, np.arange(frames), frames - np.arange(frames)) * (pan_px / half)
    H = [np.array([[1.0, 0.0, -20 - xi], [0.0, 1.0, -20.0 + 5 * np.sin(i / 9)], [0.0, 0.0, 1.0]])
         for i, xi in enumerate(x)]
    return PlaneVideo(tex, H, times, seed=seed)


def revived_errors(video: PlaneVideo, tracks) -> np.ndarray:
    """Error of each re-identified observation (the frame it came back in) against its old id's truth."""
    err, _ = errors(video, tracks)
    out = []
    for frame, track_id, _ in tracks.reid_events.tolist():
        out.append(err[(tracks.frame == frame) & (tracks.track_id == track_id)][0])
    return np.array(out)


def test_points_that_come_back_get_their_old_ids():
    video = pan_video(texture(900, 400, 12))
    tracks = track_features(video.frames())
    revived = revived_errors(video, tracks)
    gaps = tracks.reid_events[:, 0] - tracks.reid_events[:, 2]
    assert np.sum(gaps > 30) > 30                  # after leaving the view, many come back ...
    assert np.all(revived < 1.0)                   # ... as the same points
    lengths = tracks.track_lengths()
    assert np.sum(lengths["span_frames"] >= 120) > 30


def test_no_wrong_merge_on_a_repeated_texture():
    """A 60x60 px tile repeated: every lost descriptor has copies in the next view; the geometric
    check (and the ratio test) must keep them apart."""
    tile = texture(60, 60, 13)
    video = pan_video(np.tile(tile, (7, 15)))
    tracks = track_features(video.frames())
    revived = revived_errors(video, tracks)
    assert len(revived) == 0 or np.all(revived < 1.0)
    assert tracks.stats["reid_rejected_geometry"] + tracks.stats["reid_candidates"] > 0


def some_frames(n: int = 3, size=(WIDTH, HEIGHT)):
    rng = np.random.default_rng(0)
    return [(0.033 * k, rng.integers(0, 255, (size[1], size[0]), dtype=np.uint8)) for k in range(n)]


def test_bad_input_is_refused_with_a_clear_message():
    frames = some_frames(3)
    with pytest.raises(InputError, match="expected 320x240"):
        track_features(frames[:2] + some_frames(1, (160, 120)))
    with pytest.raises(InputError, match="at least 2 frames"):
        track_features(frames[:1])
    with pytest.raises(InputError, match="at least 2 frames"):
        track_features([])
    with pytest.raises(InputError, match="does not increase"):
        track_features([frames[1], frames[0]])
    with pytest.raises(InputError, match="uint8"):
        track_features([(0.0, frames[0][1].astype(np.float32)), frames[1]])
    with pytest.raises(InputError, match="time_s, image"):
        track_features([frames[0][1], frames[1][1]])
    with pytest.raises(InputError, match="not finite"):
        track_features([frames[0], (float("nan"), frames[1][1])])
    with pytest.raises(InputError, match="too small"):
        FeatureTracker((16, 16))
    with pytest.raises(InputError, match="RANSAC method"):
        geometric_inliers(np.zeros((20, 2)), np.zeros((20, 2)), 1.0, 0.9, 2.0, method="lmeds")


def test_no_track_starts_on_an_edge_and_position_sigma_ranks_first_views(wandering):
    """Stripes (intensity varying along x only) fix no position along y: no track is born there;
    on the blob texture every track has a finite position_sigma under the threshold."""
    rng = np.random.default_rng(4)
    x = np.arange(WIDTH)
    stripes = 128 + 60 * np.sin(2 * np.pi * x / 23.0) + 30 * np.sin(2 * np.pi * x / 7.0)
    frames = [(0.033 * k, np.clip(np.tile(stripes + 2.0 * k, (HEIGHT, 1)) + rng.normal(0, 1.0, (HEIGHT, WIDTH)),
                                  0, 255).astype(np.uint8)) for k in range(4)]
    assert len(track_features(frames)) == 0
    _, tracks = wandering
    limit = TrackOptions().scaled((WIDTH, HEIGHT)).max_position_sigma
    assert np.all(np.isfinite(tracks.position_sigma)) and np.all(tracks.position_sigma <= limit)
    assert len(tracks.position_sigma) == len(tracks)
