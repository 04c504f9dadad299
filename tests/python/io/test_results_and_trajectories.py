"""result.json provenance (rscalib.io.results), trajectory files (rscalib.io.trajectory_files) and the
warning for unknown keys in a target file (rscalib.io.targets)."""
import hashlib
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rscalib.io import results
from rscalib.io.targets import TargetFileWarning, load_target
from rscalib.io.trajectory_files import CSV_COLUMNS, write_trajectory_csv, write_tum_trajectory


def read_tum(path):
    """The TUM RGB-D format as documented: `timestamp tx ty tz qx qy qz qw`, `#` comments; the pose
    of the camera in the world (camera-to-world)."""
    rows = [line.split() for line in open(path) if line.strip() and not line.startswith("#")]
    return np.array(rows, dtype=float)


def test_tum_holds_the_camera_to_world_pose_of_the_world_to_camera_states(tmp_path):
    rng = np.random.default_rng(1)
    states = np.c_[rng.normal(size=(20, 3)), rng.normal(size=(20, 3)) * 1.5]
    states[4] = np.nan                      # no pose at that time: left out
    states[5, 3:], states[6, 3:] = 0.0, 1e-9  # no rotation, and the small-angle branch
    assert np.nanmax(np.linalg.norm(states[:, 3:], axis=1)) > np.pi  # and rotation vectors past pi
    times = np.linspace(0, 1, 20)
    write_tum_trajectory(tmp_path / "t.txt", times, states)
    tum = read_tum(tmp_path / "t.txt")
    ok = np.all(np.isfinite(states), axis=1)
    assert tum.shape == (19, 8)
    np.testing.assert_allclose(tum[:, 0], times[ok])
    for row, state in zip(tum, states[ok]):
        rotation_cw = Rotation.from_rotvec(state[3:]).as_matrix()
        rotation_wc = Rotation.from_quat(row[4:8]).as_matrix()   # scalar last, as TUM
        np.testing.assert_allclose(rotation_wc, rotation_cw.T, atol=1e-8)
        world_point = np.array([0.3, -0.2, 1.0])
        camera_point = rotation_cw @ world_point + state[:3]
        np.testing.assert_allclose(rotation_wc @ camera_point + row[1:4], world_point, atol=1e-8)


def test_trajectory_csv_says_it_holds_world_to_camera(tmp_path):
    write_trajectory_csv(tmp_path / "t.csv", [0.0, 0.1], np.zeros((2, 6)))
    header = (tmp_path / "t.csv").read_text().splitlines()[0].split(",")
    assert header == list(CSV_COLUMNS) and all("world_to_camera" in c for c in header[1:])


def test_provenance_records_the_command_line_and_each_input_file(tmp_path):
    target = tmp_path / "target.yaml"
    target.write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.04\n"
                      "colSpacingMeters: 0.04\n")
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        (folder / f"{i}.png").write_bytes(bytes([i]) * 10)
    results.set_command_line(["rscalib", "flicker", str(folder)])
    try:
        path = results.write_result_json(tmp_path / "out", {"rows": 480}, "flicker",
                                         {"source": str(folder), "target": str(target), "frequency_hz": 100.0})
    finally:
        results.set_command_line(None)
    provenance = json.loads(path.read_text())["provenance"]
    assert provenance["command_line"] == f"rscalib flicker {folder}"
    assert provenance["inputs"]["frequency_hz"] == 100.0
    assert provenance["input_files"]["target"]["sha256"] == hashlib.sha256(target.read_bytes()).hexdigest()
    assert provenance["input_files"]["source"]["files"] == 3
    assert provenance["target_as_read"]["targetCols"] == 9 and provenance["rows"] == 480


def test_unknown_keys_in_a_target_file_warn(tmp_path):
    path = tmp_path / "target.yaml"
    path.write_text("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.04\n"
                    "colSpacingMeters: 0.04\nsquareSize: 0.04\n")
    with pytest.warns(TargetFileWarning, match="squareSize not used"):
        load_target(path)
    path.write_text("target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\ncodeOffset: 0\n")
    load_target(path)   # Kalibr's default codeOffset: no warning (pytest turns rscalib warnings into errors)
