"""Issue 12: the noise model of real detections, the halves' self-check, readout directions and
time windows (independent oracles: the simulated noise, a hand-computed z, the camera's own
projection of the reflected geometry)."""
import math

import numpy as np
import pytest

from rscalib import CameraModel
from rscalib.errors import InputError
from rscalib.linedelay import noise, selfcheck
from rscalib.linedelay.readout import time_window, to_top_to_bottom
from rscalib.observations import Observations
from rscalib.sim.target_observations import simulate_default


def _grid_observations(frames=60, sigma_per_frame=None, fixed_px=0.0, white_px=0.1, seed=0):
    """A 9x6 grid seen fronto-parallel, drifting slowly; noise per frame plus a fixed pattern."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.arange(9) * 0.04, np.arange(6) * 0.04)
    pts = np.c_[xs.ravel(), ys.ravel(), np.zeros(54)]
    pattern = rng.normal(0.0, fixed_px, (54, 2)) if fixed_px else np.zeros((54, 2))
    uv, fi, pid = [], [], []
    for f in range(frames):
        s = white_px if sigma_per_frame is None else sigma_per_frame[f]
        base = 100 + pts[:, :2] * 1000 + np.array([f * 0.5, 0.2 * f])
        uv.append(base + pattern + rng.normal(0.0, s, (54, 2)))
        fi.append(np.full(54, f))
        pid.append(np.arange(54))
    obs = Observations(frame_times_s=np.arange(frames) / 30.0, frame_index=np.concatenate(fi),
                       point_id=np.concatenate(pid), uv=np.concatenate(uv), target_points=pts, image_size=(640, 480))
    truth = np.concatenate([np.tile(100 + pts[:, :2] * 1000, (1, 1)) + np.array([f * 0.5, 0.2 * f])
                            for f in range(frames)])
    return obs, truth


def test_frame_sigma_follows_the_noise_of_each_frame():
    sigma = np.where(np.arange(60) < 30, 0.1, 0.5)
    obs, _ = _grid_observations(sigma_per_frame=sigma)
    est = noise.frame_pixel_sigma(obs, noise.estimate_pixel_sigma(obs))
    assert np.median(est[:30]) == pytest.approx(0.1, rel=0.35)
    assert np.median(est[30:]) == pytest.approx(0.5, rel=0.25)


@pytest.mark.parametrize("fixed", [0.0, 0.3])
def test_residual_structure_finds_a_repeating_error(fixed):
    obs, truth = _grid_observations(fixed_px=fixed, white_px=0.1, seed=3)
    residual = obs.uv - truth
    s = noise.residual_structure(obs, residual, np.full(obs.num_observations, 0.1))
    if fixed:
        assert s.fixed_pattern_px == pytest.approx(fixed, rel=0.3)
        assert s.correlation > 0.8 and s.inflation > 3
    else:
        assert s.fixed_pattern_px < 0.03
        assert abs(s.correlation) < 0.1 and s.inflation < 1.15


def test_a_pose_error_per_frame_is_not_a_fixed_pattern():
    """A smooth misfit over the board (what a missing knot leaves) is removed by the per-frame detrend."""
    obs, truth = _grid_observations(white_px=0.1, seed=4)
    drift = np.repeat(np.c_[np.sin(np.arange(60) / 5.0), np.cos(np.arange(60) / 7.0)], 54, axis=0) * 2.0
    s = noise.residual_structure(obs, obs.uv - truth + drift, np.full(obs.num_observations, 0.1))
    assert s.fixed_pattern_px < 0.03 and s.inflation < 1.2


def test_detrend_per_frame_matches_a_least_squares_fit_per_frame():
    """The vectorised detrend against numpy's lstsq of [1, u - mean u, v - mean v] frame by frame, with an
    empty frame, a 5-point frame (too few: NaN), collinear points, one repeated point and NaN residuals."""
    rng = np.random.default_rng(3)
    frames, points = 40, 54
    fi, pid = np.repeat(np.arange(frames), points), np.tile(np.arange(points), frames)
    keep = (rng.uniform(size=len(fi)) > 0.2) & (fi != 5) & ~((fi == 6) & (pid >= 5))
    uv = rng.uniform(0, 640, (len(fi), 2))
    uv[fi == 7, 1] = 100.0
    uv[fi == 8] = uv[fi == 8][0]
    res = rng.normal(size=(len(fi), 2))
    res[rng.uniform(size=len(fi)) < 0.02] = np.nan
    obs = Observations(np.arange(frames) / 30.0, fi[keep], pid[keep], uv[keep], np.zeros((points, 3)), (640, 480))
    got = noise.detrend_per_frame(obs, res[keep])
    expected = np.full_like(got, np.nan)
    for rows in obs.frame_slices():
        rows = rows[np.all(np.isfinite(res[keep][rows]), axis=1)]
        if len(rows) >= 8:
            design = np.c_[np.ones(len(rows)), obs.uv[rows] - obs.uv[rows].mean(axis=0)]
            beta = np.linalg.lstsq(design, res[keep][rows], rcond=None)[0]
            expected[rows] = (res[keep][rows] - design @ beta) * math.sqrt(len(rows) / (len(rows) - 3))
    assert np.array_equal(np.isnan(got), np.isnan(expected)) and np.isnan(got[obs.frame_index == 6]).all()
    np.testing.assert_allclose(got[~np.isnan(got)], expected[~np.isnan(expected)], atol=1e-12)


class _R:
    def __init__(self, d, s, determined=True):
        self.line_delay_s, self.line_delay_std_s, self.determined, self.normalised_cost = d, s, determined, 1.0


def _by_half(obs, first, second):
    """A fake solve answering by which half it was given (the halves run in two threads)."""
    return lambda half: first if half.frame_times_s[0] == obs.frame_times_s[0] else second


def test_halves_agree_and_widen_by_the_birge_ratio():
    obs, _ = _grid_observations()
    check = selfcheck.halves(obs, _by_half(obs, _R(30e-6, 0.1e-6), _R(30.5e-6, 0.1e-6)))
    z = 0.5 / math.hypot(0.1, 0.1)
    assert check["z"] == pytest.approx(z) and check["agree"] is False and check["widen"] == pytest.approx(z)
    assert selfcheck.widened_std(0.07e-6, check) == pytest.approx(0.07e-6 * z)
    check = selfcheck.halves(obs, _by_half(obs, _R(30e-6, 0.1e-6), _R(30.1e-6, 0.1e-6)))
    assert check["agree"] is True and check["widen"] == 1.0


def test_halves_are_inconclusive_when_a_half_is_undetermined():
    obs, _ = _grid_observations()
    check = selfcheck.halves(obs, _by_half(obs, _R(30e-6, 0.1e-6), _R(-3e-3, float("inf"), determined=False)))
    assert check["agree"] is None and check["widen"] == 1.0 and "reason" in check


def test_halves_split_the_frames_in_time():
    obs, _ = _grid_observations(frames=40)
    seen = []
    selfcheck.halves(obs, lambda half: seen.append(half.frame_times_s.copy()) or _R(1e-5, 1e-7))
    seen.sort(key=lambda t: t[0])
    assert seen[0][-1] < seen[1][0] and len(seen[0]) + len(seen[1]) == 40


def test_halves_are_solved_at_once_with_the_same_answer():
    """parallel=True runs both solves concurrently (each waits at a barrier the other must reach)
    and reports exactly what the sequential check reports."""
    import threading

    obs, _ = _grid_observations(frames=40)
    barrier = threading.Barrier(2, timeout=30)

    def solve(half):
        barrier.wait()
        return _R(30e-6 + 1e-9 * len(half.frame_times_s), 0.1e-6)

    parallel = selfcheck.halves(obs, solve, parallel=True)
    barrier = threading.Barrier(2, timeout=0.5)
    sequential = selfcheck.halves(obs, lambda half: _R(30e-6 + 1e-9 * len(half.frame_times_s), 0.1e-6),
                                  parallel=False)
    assert parallel == sequential and parallel["z"] is not None
    with pytest.raises(threading.BrokenBarrierError):
        selfcheck.halves(obs, solve, parallel=False)   # one solve alone never passes the barrier


@pytest.mark.parametrize("readout", ["bottom-up", "left-right", "right-left"])
def test_readout_transform_is_the_same_geometry(readout):
    """The transformed camera projects the transformed board, posed by F R F', F p, exactly where
    the transformed pixels are (F: the reflection of the image axes)."""
    cam = CameraModel("pinhole-radtan", [500, 510, 330, 235, -0.1, 0.05, 0.002, -0.001, 0.0], 640, 480)
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-0.1, 0.1, (20, 2)), np.zeros(20)]
    from scipy.spatial.transform import Rotation
    R = Rotation.from_rotvec([0.1, -0.2, 0.05]).as_matrix()
    p = np.array([0.01, -0.02, 0.5])
    uv = np.asarray(cam.project((pts @ R.T) + p))
    obs = Observations(frame_times_s=np.zeros(1), frame_index=np.zeros(20, int), point_id=np.arange(20), uv=uv,
                       target_points=pts, image_size=(640, 480))
    obs2, cam2 = to_top_to_bottom(obs, cam, readout)
    F = {"bottom-up": np.diag([1.0, -1, 1]), "left-right": np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, 1]]),
         "right-left": np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])}[readout]
    Fw = F if readout != "right-left" else np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])
    R2, p2 = F @ R @ Fw.T, F @ p
    assert np.linalg.det(R2) == pytest.approx(1.0)
    uv2 = np.asarray(cam2.project(obs2.target_points @ R2.T + p2))
    np.testing.assert_allclose(uv2, obs2.uv, atol=1e-6)
    assert (cam2.width, cam2.height) == tuple(obs2.image_size)


def test_time_window_keeps_the_frames_in_it():
    obs, _ = _grid_observations(frames=60)
    part = time_window(obs, 0.5, 1.0)
    assert part.frame_times_s[0] >= 0.5 and part.frame_times_s[-1] <= 1.0 and part.num_frames == 16
    with pytest.raises(InputError):
        time_window(obs, 5.0, 6.0)
    with pytest.raises(InputError):
        time_window(obs, 1.0, 0.5)


def test_frame_noise_model_keeps_the_line_delay_on_simulated_observations():
    """The default noise model on exact RS observations with white noise: the same answer, within 3 sigma,
    and nothing learnt that is not there."""
    from rscalib.linedelay.spline import calibrate_line_delay
    sim = simulate_default(line_delay_s=30e-6, duration_s=4.0, seed=11)
    c = sim.camera
    cam = CameraModel(c.model, c.params, c.width, c.height)
    r = calibrate_line_delay(sim.observations, cam)
    assert abs(r.line_delay_s - 30e-6) <= 3 * r.line_delay_std_s
    assert r.noise["sigma_d_inflation"] < 1.3 and r.noise["fixed_pattern_px"] < 0.1
    assert 0.7 < r.normalised_cost < 1.3


def test_halves_take_their_poses_from_the_whole_videos_pnp():
    """The self-check's halves reuse the whole video's per-frame PnP: the same poses as PnP run on
    the half itself, whatever the number of threads."""
    from rscalib.linedelay.pnp import per_frame_pnp
    sim = simulate_default(line_delay_s=30e-6, duration_s=2.0, seed=4)
    c = sim.camera
    cam = CameraModel(c.model, c.params, c.width, c.height)
    obs = sim.observations
    whole = per_frame_pnp(obs, cam, threads=2)
    single = per_frame_pnp(obs, cam, threads=1)
    assert np.array_equal(whole.rotation_vector, single.rotation_vector, equal_nan=True)
    times = obs.frame_times_s
    half = obs.subset_frames(times >= 0.5 * (times[0] + times[-1]))
    direct = per_frame_pnp(half, cam)
    shared = whole.of_frames(times, half.frame_times_s)
    assert np.array_equal(shared.ok, direct.ok) and shared.ok.sum() == half.num_frames
    assert np.array_equal(shared.translation, direct.translation)
    np.testing.assert_allclose(shared.rms_px, direct.rms_px, rtol=1e-12)
    with pytest.raises(ValueError):
        whole.of_frames(times, half.frame_times_s + 1e-3)
