"""linedelay/pipeline.py (video -> result, the path of the CLI and the experiments) and the writers
of linedelay/report.py for every model."""
import json

import numpy as np
import pytest

from rscalib.detection.options import DetectOptions
from rscalib.errors import InputError
from rscalib.io.cameras import load_camera, write_opencv_yaml
from rscalib.linedelay import pipeline
from rscalib.linedelay.options import LineDelayOptions, LocalizeOptions
from rscalib.linedelay.pnp import PnpTrajectory, PosesAlongside, per_frame_pnp
from rscalib.linedelay.spline import calibrate_line_delay

D_S = 40e-6


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    from rscalib.sim.target_video import render_video

    out = tmp_path_factory.mktemp("pipeline_video")
    render_video(out, line_delay_s=D_S, fps=30, size=(640, 480), target="checkerboard", duration_s=1.5,
                 seed=3, supersample=1, progress=False)
    return out


def files(video):
    return video / "video.avi", video / "target.yaml", video / "camera.yaml"


def cached(tmp_path, **options):
    """The line-delay options with the detection cache in tmp_path."""
    return LineDelayOptions(detection=DetectOptions(cache_dir=tmp_path / "cache"), **options)


def _halves_then_whole(observations, camera):
    """What calibrate_video documents: the halves from their own PnP starts, then the whole video from
    their joined trajectory and mean d (pipeline._start_from_halves)."""
    from rscalib.linedelay import selfcheck

    solved = []

    def solve(half):
        solved.append(calibrate_line_delay(half, camera))
        return solved[-1]

    check = selfcheck.halves(observations, solve, parallel=False)
    start = pipeline._start_from_halves(solved, LineDelayOptions())
    return calibrate_line_delay(observations, camera, **start), check, start


def test_calibrate_video_is_detect_then_the_engine(video, tmp_path):
    detected, rounds = [], []
    run = pipeline.calibrate_video(*files(video), cached(tmp_path), on_detection=detected.append,
                                   on_round=rounds.append)
    camera = load_camera(video / "camera.yaml").camera
    detection = pipeline.detect(*files(video)[:2], camera, cached(tmp_path))
    direct, check, start = _halves_then_whole(detection.observations, camera)
    assert start, "both halves solved: the whole video starts from them"
    assert run.result.self_check == check
    assert run.model == "spline" and run.command == "linedelay"
    assert run.result.line_delay_s == direct.line_delay_s
    assert run.result.line_delay_std_s == direct.line_delay_std_s
    assert len(detected) == 1 and detected[0].frames_total == detection.frames_total
    assert [r.round for r in rounds] == [h.round for h in run.result.history]
    assert abs(run.result.line_delay_s - D_S) < 0.03 * D_S
    assert run.fps == pytest.approx(30.0)
    assert run.settings == {"trajectory_model": "spline", "standardise_errors": True, "motion_prior": True,
                            "adaptive_knots": True, "readout": "top-to-bottom", "start_s": None, "end_s": None}
    assert run.verdict.trusted and run.line_delay_s == run.result.line_delay_s
    # the lossless render is far above a phone's bitrate; a re-encoded video would be named
    assert run.guidance["video_bits_per_pixel"] > 1.0
    assert not any("bit/pixel" in line for line in run.guidance["advice"])
    from rscalib.linedelay.guidance import capture_guidance
    low = capture_guidance(run.result, run.detection, bits_per_pixel=0.1)
    assert any("compressed to 0.10 bit/pixel" in line for line in low["advice"])


def test_the_whole_video_starting_from_its_halves_agrees_with_the_pnp_start(video, tmp_path):
    """The halves' joined trajectory is only a start (issue 17): the whole video's d is the one the PnP
    start gives, to a small fraction of sigma_d, and without the self-check the PnP start is used."""
    plain = pipeline.calibrate_video(*files(video), cached(tmp_path, self_check=False))
    camera = load_camera(video / "camera.yaml").camera
    observations = pipeline.detect(*files(video)[:2], camera, cached(tmp_path)).observations
    from_pnp = calibrate_line_delay(observations, camera)
    assert plain.result.line_delay_s == from_pnp.line_delay_s and plain.result.self_check is None
    seeded = pipeline.calibrate_video(*files(video), cached(tmp_path))
    assert abs(seeded.result.line_delay_s - from_pnp.line_delay_s) < 0.3 * from_pnp.line_delay_std_s
    assert seeded.result.solver_line_delay_std_s == pytest.approx(from_pnp.solver_line_delay_std_s, rel=0.1)


def test_the_poses_computed_while_detecting_are_one_pnp_pass_to_the_bit(video, tmp_path):
    """PosesAlongside (the per-frame PnP computed as detection hands frames on) gives per_frame_pnp's
    poses to the bit, in batches, after detection starts again from an earlier frame, and for a time
    window; frames it was not given: None. calibrate_video uses it (its d is the direct solve's:
    test_calibrate_video_is_detect_then_the_engine)."""
    camera = load_camera(video / "camera.yaml").camera
    observations = pipeline.detect(*files(video)[:2], camera, cached(tmp_path)).observations
    rows = observations.frame_slices()
    times = list(observations.frame_times_s)
    alongside = PosesAlongside(camera).of_target(observations.target_points)

    def hand_on(start, stop):
        alongside(start, times[start:stop], [observations.point_id[r] for r in rows[start:stop]],
                  [observations.uv[r] for r in rows[start:stop]])

    count = observations.num_frames
    for start, stop in ((0, 10), (10, 25), (5, 30), (30, count)):   # (5, 30): detection began again at 5
        hand_on(start, stop)
    direct = per_frame_pnp(observations, camera)
    got = alongside.poses_of(observations)
    for name in ("ok", "rotation_vector", "translation", "rms_px"):
        np.testing.assert_array_equal(getattr(got, name), getattr(direct, name))
    assert got.ok.sum() > 0.9 * count
    window = observations.subset_frames(np.arange(count) >= 20)
    np.testing.assert_array_equal(alongside.poses_of(window).translation, direct.translation[20:])
    partial = PosesAlongside(camera).of_target(observations.target_points)
    partial(0, times[:10], [observations.point_id[r] for r in rows[:10]], [observations.uv[r] for r in rows[:10]])
    assert partial.poses_of(observations) is None and PosesAlongside(camera).poses_of(observations) is None


def test_linear_writes_a_report_through_the_same_writers(video, tmp_path):
    run = pipeline.calibrate_video(*files(video), cached(tmp_path, baseline="linear"))
    summary = run.write(tmp_path / "lin")
    written = json.loads((tmp_path / "lin" / "result.json").read_text())
    assert written["trajectory_model"] == "linear" and written["provenance"]["command"] == "linedelay"
    assert written["baseline"] == "linear"
    assert written["provenance"]["inputs"]["video"] == str(video / "video.avi")
    assert written["line_delay_s"] == summary["line_delay_s"] == run.result.line_delay_s
    assert "verdict" in written and written["frames_total"] == run.detection.frames_total
    assert written["files"]["plots"] == ["residuals_time.png", "residuals_image.png", "trajectory.png"]
    html = (tmp_path / "lin" / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3
    for name in ("trajectory.csv", "camera_with_line_delay.yaml", "camchain.yaml", "gyroflow_lens_profile.json"):
        assert (tmp_path / "lin" / name).stat().st_size > 0


def test_localize_rs_spline_and_gs_pnp(video, tmp_path):
    localize = LocalizeOptions(detection=DetectOptions(cache_dir=tmp_path / "cache"))
    rs = pipeline.localize_video(*files(video), D_S, localize)
    assert rs.command == "localize" and rs.comparison["rs_rms_px"] == rs.result.rms_px
    summary = rs.write(tmp_path / "rs")
    assert summary["trajectory_model"] == "rs-spline" and "line_delay_std_s" not in summary
    assert json.loads((tmp_path / "rs" / "result.json").read_text())["gs_pnp_comparison"] == rs.comparison
    assert (tmp_path / "rs" / "trajectory.png").stat().st_size > 0

    gs = pipeline.localize_video(*files(video), D_S, LocalizeOptions(model="gs-pnp", detection=localize.detection))
    assert isinstance(gs.result, PnpTrajectory)
    gs.write(tmp_path / "gs")
    table = np.loadtxt(tmp_path / "gs" / "trajectory.csv", delimiter=",", skiprows=1)
    assert table.shape == (gs.result.frames_used, 7)
    # mid-readout time stamps: row-0 times + rows d / 2
    frame_times = gs.detection.observations.frame_times_s
    assert table[0, 0] == pytest.approx(frame_times[0] + 0.5 * 480 * D_S)


@pytest.mark.parametrize("kwargs, message", [
    ({"baseline": "bezier"}, "unknown baseline"),
    ({"baseline": "linear", "uniform_knots": 5}, "only for the spline"),
    ({"baseline": "linear", "motion_prior": False}, "only for the spline"),
    ({"readout": "sideways"}, "unknown readout direction"),
    ({"robust_loss": "tukey"}, "unknown robust loss"),
])
def test_line_delay_options_refuse_what_means_nothing(kwargs, message):
    """Bad options are refused where they are made, before any detection."""
    with pytest.raises(InputError, match=message):
        LineDelayOptions(**kwargs)


def test_missing_files_and_missing_line_delay(video, tmp_path):
    with pytest.raises(InputError, match="video not found"):
        pipeline.calibrate_video(tmp_path / "nope.avi", *files(video)[1:])
    with pytest.raises(InputError, match="target file not found"):
        pipeline.calibrate_video(files(video)[0], tmp_path / "nope.yaml", files(video)[2])
    with pytest.raises(InputError, match="camera file not found"):
        pipeline.calibrate_video(*files(video)[:2], tmp_path / "nope.yaml")
    no_delay = tmp_path / "camera.yaml"  # the rendered camera file carries the true line delay
    write_opencv_yaml(load_camera(video / "camera.yaml").camera, no_delay)
    uncached = LocalizeOptions(detection=DetectOptions(cache=False))
    with pytest.raises(InputError, match="no line delay"):
        pipeline.localize_video(*files(video)[:2], no_delay, options=uncached)
    assert pipeline.localize_video(*files(video), options=uncached).result.line_delay_s == \
        load_camera(video / "camera.yaml").line_delay_s  # the camera file's line delay by default
    with pytest.raises(InputError, match="finite"):
        pipeline.localize_video(*files(video), line_delay_s=float("nan"), options=uncached)
