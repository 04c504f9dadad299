"""Targets (rscalib.io.targets): Kalibr-style YAML, built-in targets, point layouts and ids, one-line errors,
drawing."""
import cv2
import numpy as np
import pytest
import yaml

from rscalib import InputError
from rscalib.io.targets import PRESET_TARGETS, Target, aprilgrid_tag_cells, as_target, load_target, target_from_dict

CHECKERBOARD = {"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
                "rowSpacingMeters": 0.03, "colSpacingMeters": 0.025}
CIRCLES = {"target_type": "circlegrid", "targetCols": 7, "targetRows": 5, "spacingMeters": 0.02,
           "asymmetricGrid": False}
ACIRCLES = {"target_type": "circlegrid", "targetCols": 4, "targetRows": 11, "spacingMeters": 0.02,
            "asymmetricGrid": True}
APRILGRID = {"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": 0.088, "tagSpacing": 0.3}
CHARUCO = {"target_type": "charuco", "squaresX": 7, "squaresY": 5, "squareLength": 0.04, "markerLength": 0.03,
           "dictionary": "DICT_5X5_100"}


def write(tmp_path, text, name="target.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_checkerboard_layout_follows_conventions(tmp_path):
    path = write(tmp_path, "target_type: 'checkerboard'  # Kalibr template\ntargetCols: 9\ntargetRows: 6\n"
                           "rowSpacingMeters: 0.03\ncolSpacingMeters: 0.025\n")
    t = load_target(path)
    assert t.target_type == "checkerboard" and t.num_points == 54 and t.grid_shape == (6, 9)
    # id r * cols + c at (c * colSpacing, r * rowSpacing, 0): x along the columns
    np.testing.assert_allclose(t.points_m[0], [0, 0, 0])
    np.testing.assert_allclose(t.points_m[1], [0.025, 0, 0])
    np.testing.assert_allclose(t.points_m[9], [0, 0.03, 0])
    np.testing.assert_allclose(t.points_m[53], [8 * 0.025, 5 * 0.03, 0])
    assert np.all(t.points_m[:, 2] == 0)
    # edges: 8 per row x 6 rows + 9 per column x 5
    assert len(t.edge_pairs) == 8 * 6 + 9 * 5


def test_circle_grids():
    t = target_from_dict(CIRCLES)
    assert t.num_points == 35
    np.testing.assert_allclose(t.points_m[8], [0.02, 0.02, 0])
    a = target_from_dict(ACIRCLES)
    assert a.num_points == 44
    # Kalibr / OpenCV asymmetric layout: ((2c + r % 2) s, r s)
    np.testing.assert_allclose(a.points_m[1], [0.04, 0, 0])
    np.testing.assert_allclose(a.points_m[4], [0.02, 0.02, 0])
    np.testing.assert_allclose(a.points_m[5], [0.06, 0.02, 0])
    # neighbours for the blur measure are the nearest circles (diagonal at s * sqrt 2)
    d = np.linalg.norm(a.points_m[a.edge_pairs[:, 0]] - a.points_m[a.edge_pairs[:, 1]], axis=1)
    np.testing.assert_allclose(d, 0.02 * np.sqrt(2))


def test_aprilgrid_is_kalibrs_geometry():
    t = target_from_dict(APRILGRID)
    assert t.num_points == 144 and t.grid_shape == (12, 12)
    size, pitch = 0.088, 0.088 * 1.3
    # width 6 tags + 5 gaps = 0.66 m (README of the EuRoC fixture)
    assert t.points_m[:, 0].max() == pytest.approx(0.66)
    corners = t.tag_corner_ids()
    assert corners.shape == (36, 4)
    # tag 0: bottom-left, bottom-right, top-right, top-left (Kalibr's order, y up)
    np.testing.assert_array_equal(corners[0], [0, 1, 13, 12])
    np.testing.assert_allclose(t.points_m[corners[0]][:, :2], [[0, 0], [size, 0], [size, size], [0, size]])
    # tag 7 = row 1, column 1
    np.testing.assert_allclose(t.points_m[corners[7][0]][:2], [pitch, pitch])
    np.testing.assert_allclose(t.points_m[corners[7][2]][:2], [pitch + size, pitch + size])
    assert sorted(corners.ravel()) == list(range(144))
    assert len(t.edge_pairs) == 4 * 36


def test_charuco_points():
    t = target_from_dict(CHARUCO)
    assert t.num_points == 6 * 4
    np.testing.assert_allclose(t.points_m[0], [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(t.points_m[1], [0.04, 0, 0], atol=1e-12)
    np.testing.assert_allclose(t.points_m[6], [0, 0.04, 0], atol=1e-12)
    assert t.charuco_board().getChessboardSize() == (7, 5)


def test_fingerprint_tracks_the_definition():
    a, b = target_from_dict(CHECKERBOARD), target_from_dict(dict(CHECKERBOARD))
    c = target_from_dict({**CHECKERBOARD, "rowSpacingMeters": 0.031})
    assert a.fingerprint() == b.fingerprint() != c.fingerprint()
    assert "9x6" in a.describe()


@pytest.mark.parametrize("text, words", [
    ("target_type: checkerboard\ntargetCols: [9\n", ["not valid YAML"]),
    ("just a string\n", ["mapping"]),
    ("targetCols: 9\n", ["target_type"]),
    ("target_type: hexagons\n", ["unknown target_type", "hexagons"]),
    ("target_type: checkerboard\ntargetCols: 9\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n", ["targetRows"]),
    ("target_type: checkerboard\ntargetCols: nine\ntargetRows: 6\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n",
     ["targetCols", "whole number"]),
    ("target_type: checkerboard\ntargetCols: 9.5\ntargetRows: 6\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n",
     ["targetCols"]),
    ("target_type: checkerboard\ntargetCols: 1\ntargetRows: 6\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n",
     ["targetCols", "at least 2"]),
    ("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: -0.03\ncolSpacingMeters: 0.03\n",
     ["rowSpacingMeters", "positive"]),
    ("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: abc\ncolSpacingMeters: 0.03\n",
     ["rowSpacingMeters", "number"]),
    ("target_type: circlegrid\ntargetCols: 7\ntargetRows: 5\nspacingMeters: 0.02\nasymmetricGrid: maybe\n",
     ["asymmetricGrid"]),
    ("target_type: circlegrid\ntargetCols: 4\ntargetRows: 10\nspacingMeters: 0.02\nasymmetricGrid: true\n",
     ["odd targetRows"]),
    ("target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\n", ["tagSpacing"]),
    ("target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 26.4\n", ["tagSpacing", "ratio"]),
    ("target_type: aprilgrid\ntagCols: 30\ntagRows: 30\ntagSize: 0.01\ntagSpacing: 0.3\n", ["587"]),
    ("target_type: charuco\nsquaresX: 7\nsquaresY: 5\nsquareLength: 0.04\nmarkerLength: 0.05\n", ["markerLength"]),
    ("target_type: charuco\nsquaresX: 7\nsquaresY: 5\nsquareLength: 0.04\nmarkerLength: 0.03\n"
     "dictionary: DICT_NOPE\n", ["DICT_NOPE"]),
    ("target_type: charuco\nsquaresX: 30\nsquaresY: 30\nsquareLength: 0.04\nmarkerLength: 0.03\n"
     "dictionary: DICT_4X4_50\n", ["DICT_4X4_50", "markers"]),
])
def test_bad_target_files_give_one_line_reasons(tmp_path, text, words):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as error:
        load_target(path)
    message = str(error.value)
    assert "\n" not in message
    assert str(path) in message
    for word in words:
        assert word in message, message


def test_missing_target_file(tmp_path):
    with pytest.raises(InputError, match="target file not found"):
        load_target(tmp_path / "nope.yaml")


def _pixel(image, h, xy):
    u, v = np.asarray(xy, float) @ h[:2, :2].T + h[:2, 2]
    return int(image[int(round(v)), int(round(u))])


@pytest.mark.parametrize("spec", [CHECKERBOARD, CIRCLES, ACIRCLES, APRILGRID, CHARUCO])
def test_draw_maps_points_to_pixels(spec):
    """draw() returns the board image and the target -> pixel homography: the pattern sits where
    the points say (circle centres black; around a corner, the documented colours)."""
    t = target_from_dict(spec)
    image, h = t.draw(pixels_per_metre=2000, margin_m=0.01)
    assert image.dtype == np.uint8 and image.ndim == 2
    uv = t.points_m[:, :2] @ h[:2, :2].T + h[:2, 2]
    assert uv.min() > 0 and (uv.max(0) < [image.shape[1] - 1, image.shape[0] - 1]).all()
    if t.target_type == "circlegrid":
        assert max(_pixel(image, h, p) for p in t.points_m[:, :2]) < 30
    elif t.target_type == "checkerboard":
        d = 0.005
        p0 = t.points_m[0, :2]
        assert _pixel(image, h, p0 + [d, d]) == 0        # the first cell is black
        assert _pixel(image, h, p0 + [-d, d]) == 255
        assert _pixel(image, h, p0 + [-d, -d]) == 0
        last = t.points_m[-1, :2]                         # 9 + 6 odd: the opposite corner is white
        assert _pixel(image, h, last + [d, d]) == 255
    elif t.target_type == "aprilgrid":
        d = 0.01
        for tag in (0, 35):
            c0, c1, c2, c3 = t.points_m[t.tag_corner_ids()[tag], :2]
            assert _pixel(image, h, c0 + [d, d]) == 0     # black tag border inside
            assert _pixel(image, h, c0 - [d, d]) == 0     # Kalibr's corner square
            assert _pixel(image, h, c0 + [-d, d]) == 255  # white gap
            assert _pixel(image, h, c2 - [d, d]) == 0
            assert _pixel(image, h, c2 + [d, d]) == 0
            assert _pixel(image, h, c2 + [d, -d]) == 255


# ---------------------------------------------------------------------------------------------------
# Built-in targets, one value per definition, AprilGrid tags as printed


@pytest.mark.parametrize("name", sorted(PRESET_TARGETS))
def test_named_targets_are_their_kalibr_fields(name, tmp_path):
    t = Target.named(name)
    assert t == target_from_dict(PRESET_TARGETS[name]) and t.kalibr_dict() == PRESET_TARGETS[name]
    assert hash(t) == hash(Target.named(name)) and len({t, Target.named(name)}) == 1
    path = write(tmp_path, yaml.safe_dump(t.kalibr_dict(), sort_keys=False))
    assert load_target(path) == t and as_target(path) == t and as_target(str(path)) == t
    assert as_target(name) == t and as_target(t) is t
    np.testing.assert_allclose(t.center_m(), 0.5 * (t.points_m.min(0) + t.points_m.max(0)))


def test_named_target_errors_and_values():
    with pytest.raises(InputError, match="unknown target 'hexagons'"):
        as_target("hexagons")
    board = Target.named("checkerboard")
    assert (board.grid_shape, board.spec["colSpacingMeters"]) == ((6, 9), 0.04)
    assert Target.named("acircles").spec["asymmetricGrid"] and Target.named("acircles").grid_shape == (11, 4)
    assert Target.named("aprilgrid").num_points == 4 * 36
    assert board != target_from_dict({**PRESET_TARGETS["checkerboard"], "rowSpacingMeters": 0.03})


def test_aprilgrid_drawing_decodes_with_the_aruco_corner_ids():
    """The printed tags (aprilgrid_tag_cells, used by draw() and the renderer's texture) decode with
    cv2.aruco to their own ids, each marker corner on the point aruco_corner_ids() names."""
    t = target_from_dict({**APRILGRID, "tagCols": 3, "tagRows": 2})
    np.testing.assert_array_equal(t.aruco_corner_ids(), t.tag_corner_ids()[:, [1, 0, 3, 2]])
    cells = aprilgrid_tag_cells(6)
    assert cells.shape == (6, 10, 10) and not cells[:, [0, 1, -2, -1]].any() and not cells[:, :, [0, 1, -2, -1]].any()
    image, h = t.draw(pixels_per_metre=1500, margin_m=0.02)
    params = cv2.aruco.DetectorParameters()
    params.markerBorderBits = 2
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)
    corners, ids, _ = detector.detectMarkers(image)
    assert ids is not None and sorted(ids.ravel()) == list(range(6))
    uv = t.points_m[:, :2] @ h[:2, :2].T + h[:2, 2]
    for quad, tag in zip(corners, ids.ravel()):
        nearest = np.linalg.norm(quad.reshape(4, 2)[:, None] - uv[None], axis=2).argmin(axis=1)
        np.testing.assert_array_equal(nearest, t.aruco_corner_ids()[tag])
