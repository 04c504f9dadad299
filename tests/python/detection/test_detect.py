"""Target detection (rscalib.detection): real fixtures (../shared/data), synthetic views with known
pixel truth for every target type, the quality checks and their drop reasons, and detect_video
(parallel workers, cache, counts)."""
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from rscalib.detection.detectors import Detector, _outer_ring_alternates, detect_image
from rscalib.detection.options import DetectOptions
from rscalib.detection.pipeline import detect_video, segment_plan
from rscalib.detection.quality import local_homography_residual
from rscalib.io.targets import target_from_dict

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="shared fixtures ../shared/data not present")

K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
CHECKERBOARD = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                                 "rowSpacingMeters": 0.03, "colSpacingMeters": 0.03})
TARGETS = {
    "checkerboard": CHECKERBOARD,
    "circlegrid": target_from_dict({"target_type": "circlegrid", "targetCols": 7, "targetRows": 5,
                                    "spacingMeters": 0.035, "asymmetricGrid": False}),
    "acircles": target_from_dict({"target_type": "circlegrid", "targetCols": 4, "targetRows": 11,
                                  "spacingMeters": 0.02, "asymmetricGrid": True}),
    "aprilgrid": target_from_dict({"target_type": "aprilgrid", "tagCols": 6, "tagRows": 4, "tagSize": 0.035,
                                   "tagSpacing": 0.3}),
    "charuco": target_from_dict({"target_type": "charuco", "squaresX": 8, "squaresY": 6, "squareLength": 0.035,
                                 "markerLength": 0.026, "dictionary": "DICT_5X5_100"}),
}


def pose(target, roll_deg=0.0, tilt=(0.25, -0.2), distance_m=0.55):
    """A camera pose facing the printed side, the target centre on the optical axis."""
    centre = 0.5 * (target.points_m.min(0) + target.points_m.max(0))
    flip = np.diag([1.0, -1.0, -1.0]) if target.target_type == "aprilgrid" else np.eye(3)  # Kalibr: y up
    r = cv2.Rodrigues(np.array([tilt[0], tilt[1], np.deg2rad(roll_deg)]))[0] @ flip
    t = np.array([0, 0, distance_m]) - r @ centre
    return r, t


def render(target, r, t, size=(640, 480), blur_px=0, noise=2.0, seed=0):
    """Pinhole view of the printed target (homography warp of target.draw) and the target->image
    homography; motion blur along u by a box of blur_px; Gaussian noise on the grey levels."""
    h_img = K @ np.column_stack([r[:, 0], r[:, 1], t])
    board, h_board = target.draw(pixels_per_metre=1.5 * K[0, 0] / t[2], margin_m=0.01)
    image = cv2.warpPerspective(board, h_img @ np.linalg.inv(h_board), size, flags=cv2.INTER_LINEAR,
                                borderValue=110)
    if blur_px:
        kernel = np.zeros((blur_px, blur_px), np.float32)
        kernel[blur_px // 2, :] = 1.0 / blur_px
        image = cv2.filter2D(image, -1, kernel)
    if noise:
        rng = np.random.default_rng(seed)
        image = np.clip(image + rng.normal(0, noise, image.shape), 0, 255).astype(np.uint8)
    return image, h_img


def project(h, points):
    return cv2.perspectiveTransform(points[:, :2].reshape(-1, 1, 2).astype(np.float64), h).reshape(-1, 2)


# -- real images --------------------------------------------------------------------------------


@needs_data
def test_opencv_chessboard_stills():
    detector = Detector(CHECKERBOARD)
    for path in sorted((DATA / "opencv_stereo_chessboard").glob("left*.jpg")):
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found = detector.detect(image)
        assert found.accepted, (path.name, found.reason)
        np.testing.assert_array_equal(found.point_id, np.arange(54))
        assert 0.5 < found.blur_px < 4.0
        # canonical ids: the cell inside corners 0, 1, 9, 10 is a black square
        cell = found.uv[[0, 1, 10, 9]].mean(0)
        neighbour = found.uv[[1, 2, 11, 10]].mean(0)
        assert image[int(cell[1]), int(cell[0])] + 60 < image[int(neighbour[1]), int(neighbour[0])]


@needs_data
def test_kalibr_checkerboard_and_circle_grid_photos():
    board = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 8,
                              "rowSpacingMeters": 0.05, "colSpacingMeters": 0.05})
    image = cv2.imread(str(DATA / "kalibr_test_targets" / "checkerboard_9x8_inner_1280x960.jpg"))
    found = detect_image(image, board)
    assert found.accepted and len(found.point_id) == 72
    circles = target_from_dict({"target_type": "circlegrid", "targetCols": 7, "targetRows": 5,
                                "spacingMeters": 0.01, "asymmetricGrid": False})
    image = cv2.imread(str(DATA / "kalibr_test_targets" / "circlegrid_7x5_symmetric_1280x720.jpg"))
    found = detect_image(image, circles)
    assert found.accepted and len(found.point_id) == 35
    # symmetric grid: ids fixed by the image, x axis to the right
    assert found.uv[6, 0] > found.uv[0, 0]


@needs_data
def test_euroc_aprilgrid_matches_kalibr_geometry():
    """35 of 36 tags (README); with the published EuRoC intrinsics a PnP through Kalibr's point
    layout fits to a fraction of a pixel — corner order, ids and geometry are all right."""
    grid = target_from_dict({"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": 0.088,
                             "tagSpacing": 0.3})
    image = cv2.imread(str(DATA / "aprilgrid_real_frames" / "euroc_aprilgrid_752x480.png"), cv2.IMREAD_GRAYSCALE)
    found = detect_image(image, grid)
    assert found.accepted and len(found.point_id) == 35 * 4
    assert len(np.unique(found.point_id)) == 140
    cameras = {  # EuRoC cam0 and cam1 (which camera took the frame is not recorded)
        "cam0": ([458.654, 457.296, 367.215, 248.375], [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]),
        "cam1": ([457.587, 456.134, 379.999, 255.238], [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]),
    }
    rms = {}
    for name, (f, dist) in cameras.items():
        k = np.array([[f[0], 0, f[2]], [0, f[1], f[3]], [0, 0, 1]])
        points = grid.points_m[found.point_id]
        ok, rvec, tvec = cv2.solvePnP(points, found.uv, k, np.array(dist))
        projected, _ = cv2.projectPoints(points, rvec, tvec, k, np.array(dist))
        rms[name] = np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - found.uv) ** 2, axis=1)))
    assert min(rms.values()) < 0.4, rms


# -- synthetic views ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(TARGETS))
@pytest.mark.parametrize("roll_deg", [0.0, 75.0, 180.0, 290.0])
def test_synthetic_views_have_the_right_ids(name, roll_deg):
    target = TARGETS[name]
    r, t = pose(target, roll_deg)
    image, h = render(target, r, t)
    found = detect_image(image, target)
    assert found.accepted, found.reason
    truth = project(h, target.points_m)
    if name == "circlegrid":
        # a symmetric grid turned by 180 degrees looks the same: ids follow the image (x axis to
        # the right); compare with the truth as turned
        turned = truth[::-1]
        if np.linalg.norm(found.uv - turned[found.point_id], axis=1).max() < 1.0:
            truth = turned
        x_axis = found.uv[6] - found.uv[0]
        assert x_axis[0] > -0.2 * np.linalg.norm(x_axis)
    error = np.linalg.norm(found.uv - truth[found.point_id], axis=1)
    assert error.max() < 0.35, (name, error.max())
    # printed side towards the camera: x, y turn clockwise in the image (u right, v down), except
    # for Kalibr's aprilgrid frame (y up the printed page)
    xy = target.points_m[found.point_id, :2]
    linear = np.linalg.lstsq(np.c_[xy - xy.mean(0), np.ones(len(xy))], found.uv - found.uv.mean(0), rcond=None)[0]
    assert np.sign(np.linalg.det(linear[:2])) == (-1 if name == "aprilgrid" else 1)
    expected = {"checkerboard": 54, "circlegrid": 35, "acircles": 44, "aprilgrid": 96, "charuco": 35}[name]
    assert len(found.point_id) == expected


def test_partial_views_keep_their_ids():
    for name in ("aprilgrid", "charuco"):
        target = TARGETS[name]
        r, t = pose(target, 20.0)
        image, h = render(target, r, t)
        truth = project(h, target.points_m)
        image[:, : int(np.median(truth[:, 0]))] = 110  # hide the left half
        found = detect_image(image, target)
        assert found.accepted, (name, found.reason)
        assert 8 <= len(found.point_id) < target.num_points * 0.75
        assert np.linalg.norm(found.uv - truth[found.point_id], axis=1).max() < 0.35


def test_outer_ring_check_rejects_a_grid_shifted_onto_the_squares_outer_edge():
    # OpenCV can return such a grid when the board's edge row leaves the image (seen on rendered
    # 752x480 videos); its ids are off by a row, which wrecks a line-delay estimate.
    r, t = pose(CHECKERBOARD, roll_deg=8.0)
    image, h = render(CHECKERBOARD, r, t)
    rows, cols = CHECKERBOARD.grid_shape
    step = CHECKERBOARD.points_m[cols, :2] - CHECKERBOARD.points_m[0, :2]   # one row along the target
    true_uv = project(h, CHECKERBOARD.points_m)
    assert _outer_ring_alternates(image, true_uv, rows, cols)
    for sign in (1.0, -1.0):
        shifted = CHECKERBOARD.points_m.copy()
        shifted[:, :2] += sign * step
        assert not _outer_ring_alternates(image, project(h, shifted), rows, cols), sign


def test_circle_centres_are_grey_centroids_robust_to_a_threshold_at_the_dark_level():
    # Circles at grey level 20 = the blob detector's lowest threshold: with noise the binarised
    # circles fall apart there and the blob centres were biased (0.36 px in v on rendered 1080p).
    target = TARGETS["circlegrid"]
    rng = np.random.default_rng(3)
    errors = {False: [], True: []}
    for _k in range(6):
        r, t = pose(target, roll_deg=rng.uniform(-20, 20), tilt=tuple(rng.uniform(-0.3, 0.3, 2)))
        image, h = render(target, r, t, noise=0.0)
        image = np.clip(np.rint(20.0 + (229.0 - 20.0) * image / 255.0 + rng.normal(0, 2.0, image.shape)), 0, 255)
        image = image.astype(np.uint8)
        truth = project(h, target.points_m)
        for refine in errors:
            found = Detector(target, DetectOptions(refine_circles=refine)).detect(image)
            assert found.accepted, refine
            errors[refine].append(found.uv - truth[found.point_id])
    rms = {refine: float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for refine, e in errors.items()}
    assert rms[True] < 0.1, rms
    assert rms[True] < 0.7 * rms[False], rms


def test_drop_reasons():
    target = TARGETS["aprilgrid"]
    r, t = pose(target, 10.0)
    image, h = render(target, r, t)
    truth = project(h, target.points_m)
    # one tag visible: too few points
    corners = truth[target.tag_corner_ids()[9]]
    lo, hi = corners.min(0) - 6, corners.max(0) + 6
    single = np.full_like(image, 110)
    single[int(lo[1]):int(hi[1]), int(lo[0]):int(hi[0])] = image[int(lo[1]):int(hi[1]), int(lo[0]):int(hi[0])]
    assert detect_image(single, target).reason == "wrong_count"
    # nothing there
    assert detect_image(np.full((480, 640), 128, np.uint8), CHECKERBOARD).reason == "no_target"
    # motion blur
    r, t = pose(CHECKERBOARD, 5.0)
    sharp = detect_image(render(CHECKERBOARD, r, t)[0], CHECKERBOARD)
    blurred = detect_image(render(CHECKERBOARD, r, t, blur_px=13)[0], CHECKERBOARD)
    assert sharp.accepted and sharp.blur_px < 2.5
    assert blurred.reason == "blur" and 9 < blurred.blur_px < 16
    assert detect_image(render(CHECKERBOARD, r, t, blur_px=13)[0], CHECKERBOARD,
                        DetectOptions(max_blur_px=20)).accepted


def test_local_homography_residual_tolerates_distortion_not_wrong_points():
    target = CHECKERBOARD
    rvec, tvec = np.array([0.3, -0.2, 0.1]), np.array([-0.12, -0.07, 0.35])
    dist = np.array([-0.35, 0.15, 0, 0, 0])  # strong barrel distortion
    uv = cv2.projectPoints(target.points_m, rvec, tvec, K, dist)[0].reshape(-1, 2)
    ids = np.arange(target.num_points)
    clean = local_homography_residual(target, ids, uv)
    assert np.nanmax(clean) < 0.05
    swapped = uv.copy()
    swapped[[20, 21]] = swapped[[21, 20]]
    assert np.nanmax(local_homography_residual(target, ids, swapped)) > 0.5
    shifted = uv.copy()
    shifted[30] += 0.5 * np.linalg.norm(uv[31] - uv[30])
    assert np.nanmax(local_homography_residual(target, ids, shifted)) > DetectOptions().max_residual



def test_local_homography_residual_is_the_direct_linear_transform_of_each_neighbourhood():
    """Against the textbook algorithm written out here: for each point, the normalised DLT
    homography of its 8 nearest target neighbours (the last right singular vector of the design,
    Hartley & Zisserman alg. 4.2) predicts the point; the residual is that distance over the pixel
    step to the nearest neighbour. Same values to 1e-6 on noisy full and subset detections."""
    target = CHECKERBOARD
    rng = np.random.default_rng(5)
    rvec, tvec = np.array([0.4, -0.3, 0.2]), np.array([-0.1, -0.05, 0.4])
    uv_all = cv2.projectPoints(target.points_m, rvec, tvec, K, np.array([-0.2, 0.05, 0, 0, 0]))[0].reshape(-1, 2)

    def normalised(points):
        centre = points.mean(0)
        scale = np.sqrt(((points - centre) ** 2).sum(1).mean())
        return (points - centre) / scale, np.array([[1 / scale, 0, -centre[0] / scale],
                                                    [0, 1 / scale, -centre[1] / scale], [0, 0, 1]])

    for ids in (np.arange(target.num_points), np.sort(rng.choice(target.num_points, 30, replace=False))):
        uv = uv_all[ids] + rng.normal(0, 0.3, (len(ids), 2))
        ours = local_homography_residual(target, ids, uv)
        xy = target.points_m[ids, :2]
        dist = np.linalg.norm(xy[:, None] - xy[None], axis=2)
        np.fill_diagonal(dist, np.inf)
        checked = 0
        for i, near in enumerate(np.argsort(dist, axis=1)[:, :8]):
            if not np.isfinite(ours[i]):
                continue
            x, tx = normalised(xy[near])
            u, tu = normalised(uv[near])
            rows = [r for (a, b), (c, d) in zip(x, u)
                    for r in ([a, b, 1, 0, 0, 0, -c * a, -c * b, -c], [0, 0, 0, a, b, 1, -d * a, -d * b, -d])]
            h = np.linalg.inv(tu) @ np.linalg.svd(np.array(rows))[2][-1].reshape(3, 3) @ tx
            q = h @ np.r_[xy[i], 1.0]
            step = np.linalg.norm(uv[near[0]] - uv[i])
            assert ours[i] == pytest.approx(np.linalg.norm(q[:2] / q[2] - uv[i]) / step, rel=1e-6, abs=1e-9)
            checked += 1
        assert checked >= len(ids) // 2


# -- videos -------------------------------------------------------------------------------------


def write_test_video(path, fps=30.0):
    """24 views of the checkerboard, 4 empty frames and 4 blurred ones, interleaved."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (640, 480), False)
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 100)
    kinds = []
    rng = np.random.default_rng(1)
    for i in range(32):
        kind = "empty" if i % 8 == 3 else "blurred" if i % 8 == 6 else "board"
        r, t = pose(CHECKERBOARD, roll_deg=rng.uniform(-30, 30), tilt=rng.uniform(-0.35, 0.35, 2),
                    distance_m=rng.uniform(0.5, 0.7))
        image = np.full((480, 640), 110, np.uint8) if kind == "empty" else \
            render(CHECKERBOARD, r, t, blur_px=15 if kind == "blurred" else 0, seed=i)[0]
        writer.write(image)
        kinds.append(kind)
    writer.release()
    return path, kinds


@pytest.fixture(scope="module")
def test_video(tmp_path_factory):
    return write_test_video(tmp_path_factory.mktemp("video") / "board.avi")


def test_alongside_runs_once_while_the_workers_start_and_its_error_stops_the_detection(test_video, tmp_path):
    """`alongside` (the line-delay job's early check of the target file) runs once, in this process,
    with workers (frames decoded here, or segments the workers decode themselves: runs of 2 frames),
    in one process and on a cached result; an exception it raises stops the detection: nothing is
    returned or cached."""
    path, kinds = test_video
    cache = tmp_path / "cache"
    segments = DetectOptions(workers=2, cache=False, full_detection_every=2)
    assert segment_plan(len(kinds), 2, 2) is not None
    for options in (DetectOptions(workers=2, cache_dir=cache), DetectOptions(workers=1, cache=False), segments,
                    DetectOptions(workers=2, cache_dir=cache)):   # the last: from the cache
        calls: list = []
        result = detect_video(path, CHECKERBOARD, options, progress=False, alongside=lambda calls=calls: calls.append(1))
        assert calls == [1] and result.frames_detected == kinds.count("board")
    assert result.from_cache

    class Stop(Exception):
        pass

    def stop():
        raise Stop("the target file does not match")

    other = tmp_path / "other_cache"
    for options in (DetectOptions(workers=2, cache_dir=other), replace(segments, cache=True, cache_dir=other)):
        with pytest.raises(Stop):
            detect_video(path, CHECKERBOARD, options, progress=False, alongside=stop)
    assert not list(other.glob("*.npz"))


def test_detect_video_counts_and_caches(test_video, tmp_path, capsys):
    path, kinds = test_video
    cache = tmp_path / "cache"
    started = time.perf_counter()
    first = detect_video(path, CHECKERBOARD, DetectOptions(workers=2, cache_dir=cache), progress=True)
    first_s = time.perf_counter() - started
    assert not first.from_cache
    assert first.frames_total == 32 and first.image_size == (640, 480)
    assert first.frames_detected == kinds.count("board") == 24
    assert first.dropped == {"no_target": 4, "blur": 4}
    assert first.frames_total == first.frames_detected + sum(first.dropped.values())
    boards = [i for i, k in enumerate(kinds) if k == "board"]
    np.testing.assert_array_equal(first.frame_numbers, boards)
    obs = first.observations
    np.testing.assert_allclose(obs.frame_times_s, np.array(boards) / 30.0, atol=1e-9)
    assert obs.num_observations == 24 * 54
    for rows in obs.frame_slices():
        np.testing.assert_array_equal(obs.point_id[rows], np.arange(54))
    assert first.timestamps == "container"
    assert np.all(first.blur_px < 4)
    assert "detecting checkerboard" in capsys.readouterr().err  # the progress bar (stderr)

    started = time.perf_counter()
    again = detect_video(path, CHECKERBOARD, DetectOptions(workers=2, cache_dir=cache), progress=False)
    again_s = time.perf_counter() - started
    assert again.from_cache and again_s < 0.25 * first_s, (again_s, first_s)
    np.testing.assert_array_equal(again.observations.uv, obs.uv)
    np.testing.assert_array_equal(again.frame_numbers, first.frame_numbers)
    assert again.dropped == first.dropped and again.frames_total == 32 and again.frame_labels == first.frame_labels

    # the key covers the target and the options, not only the video
    other = target_from_dict({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                              "rowSpacingMeters": 0.031, "colSpacingMeters": 0.031})
    assert not detect_video(path, other, DetectOptions(workers=1, cache_dir=cache), progress=False).from_cache
    strict = detect_video(path, CHECKERBOARD, replace(DetectOptions(max_blur_px=20.0), workers=1, cache_dir=cache), progress=False)
    assert not strict.from_cache and strict.frames_detected == 28


def test_one_worker_gives_the_same_detections(test_video, tmp_path):
    path, _ = test_video
    parallel = detect_video(path, CHECKERBOARD, DetectOptions(workers=2, cache=False), progress=False)
    serial = detect_video(path, CHECKERBOARD, DetectOptions(workers=1, cache=False), progress=False)
    np.testing.assert_array_equal(parallel.observations.uv, serial.observations.uv)
    assert parallel.dropped == serial.dropped


def test_corrupt_cache_is_ignored(test_video, tmp_path):
    path, _ = test_video
    cache = tmp_path / "cache"
    detect_video(path, CHECKERBOARD, DetectOptions(workers=1, cache_dir=cache), progress=False)
    (entry,) = cache.glob("*.npz")
    entry.write_bytes(b"garbage")
    result = detect_video(path, CHECKERBOARD, DetectOptions(workers=1, cache_dir=cache), progress=False)
    assert not result.from_cache and result.frames_detected == 24
    assert detect_video(path, CHECKERBOARD, DetectOptions(workers=1, cache_dir=cache), progress=False).from_cache


def test_detect_video_memory_does_not_grow_with_length(tmp_path):
    """120 frames of 640x480 (37 MB of grey pixels) pass through with a few MB at most."""
    import tracemalloc
    path = tmp_path / "long.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480), False)
    views = [render(CHECKERBOARD, *pose(CHECKERBOARD, roll), seed=k)[0] for k, roll in enumerate((0, 10, 20))]
    for i in range(120):
        writer.write(views[i % 3])
    writer.release()
    tracemalloc.start()
    result = detect_video(path, CHECKERBOARD, DetectOptions(workers=1, cache=False), progress=False)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert result.frames_detected == 120
    assert peak < 8 * 640 * 480, f"peak {peak / 1e6:.1f} MB"


@pytest.mark.parametrize("name", ["checkerboard", "circlegrid", "acircles"])
def test_layout_symmetries_skip_refits_without_changing_the_ids(name):
    """_canonical fits one homography for the re-indexings that are symmetries of the layout (all of a
    regular grid's, not all of an asymmetric circle grid's); forcing every fit gives the same detection."""
    target = TARGETS[name]
    fast = Detector(target)
    assert fast._layout_symmetry[0] and all(fast._layout_symmetry) == (name != "acircles")
    slow = Detector(target)
    slow._layout_symmetry = [False] * len(slow._layout_symmetry)
    for roll_deg in (0.0, 75.0, 180.0, 290.0):
        image, _ = render(target, *pose(target, roll_deg))
        a, b = fast.detect(image), slow.detect(image)
        assert a.accepted and b.accepted
        assert np.array_equal(a.point_id, b.point_id) and np.array_equal(a.uv, b.uv)


def test_local_homography_residual_refuses_neighbours_that_are_not_points():
    """The core's fit is given each point's neighbours as row indices: one outside the points is
    refused with the reason, not read out of bounds."""
    from rscalib import _core
    from rscalib.errors import InputError

    cols = CHECKERBOARD.grid_shape[1]
    xy = CHECKERBOARD.points_m[[r * cols + c for r in range(3) for c in range(3)], :2]   # a 3x3 patch
    nearest = np.array([[j for j in range(9) if j != i] for i in range(9)], dtype=np.int32)
    uv = xy * 1000.0 + 50.0
    assert np.nanmax(_core.local_homography_residual(xy, uv, nearest)) < 1e-9   # an exact homography
    nearest[4, 3] = 9
    with pytest.raises(InputError, match="nearest"):
        _core.local_homography_residual(xy, uv, nearest)
