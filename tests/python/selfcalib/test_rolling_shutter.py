"""selfcalib/rolling_shutter.py against exact rolling-shutter pixels of features moving at known
image velocities: a row-v pixel is where the feature was at t + v d (solved exactly below), and the
corrected pixel must be where it was at the reference row's time."""
import numpy as np
import pytest

from rscalib.errors import InputError
from rscalib.selfcalib.rolling_shutter import RollingShutterCorrection, TimedFrame, timed_frames

HEIGHT = 240
D_S = 60e-6            # s/row: 14.4 ms readout over 240 rows, the renders' rolling shutter
FPS = 30.0


class MovingFeatures:
    """Feature i at u0_i + w_i t (px, px/s): the rolling-shutter pixel at frame time t solves
    p = u0 + w (t + p_v d) exactly (p_v = (u0_v + w_v t) / (1 - w_v d))."""

    def __init__(self, u0: np.ndarray, w: np.ndarray):
        self.u0, self.w = u0, w
        self.options = None
        self.tracked: list = []

    def at(self, t_s: float, ids=None) -> np.ndarray:
        ids = np.arange(len(self.u0)) if ids is None else np.asarray(ids)
        u0, w = self.u0[ids], self.w[ids]
        row = (u0[:, 1] + w[:, 1] * t_s) / (1.0 - w[:, 1] * D_S)
        return u0 + w * (t_s + row * D_S)[:, None]

    def measure(self, image, ids, uv_pred, cov):
        return self.at(image, ids), np.ones(len(ids), bool)

    def forget(self, ids):
        pass

    def new_features(self, image, count, search):
        return self.at(image)[:count]

    def track(self, image, ids, uv):
        self.tracked.append(np.asarray(uv).copy())


def _scene(seed=3, n=40):
    rng = np.random.default_rng(seed)
    u0 = np.c_[rng.uniform(20, 300, n), rng.uniform(20, 220, n)]
    # velocities of a rotating camera: an affine field of the start positions, plus a little parallax
    w = (u0 - [160, 120]) @ np.array([[0.3, -0.8], [0.8, 0.3]]) + [250.0, -120.0] + rng.normal(0, 5, (n, 2))
    return MovingFeatures(u0, w)


def test_corrected_pixels_are_where_the_features_were_at_the_reference_row_time():
    scene = _scene()
    source = RollingShutterCorrection(scene, D_S, HEIGHT)
    ids = np.arange(len(scene.u0))
    t_ref_offset = source.reference_row * D_S
    started = source.new_features(TimedFrame(0.0, 0.0), len(ids), None)
    source.track(TimedFrame(0.0, 0.0), ids, started)
    np.testing.assert_allclose(scene.tracked[0], scene.at(0.0))     # patches cut at the raw pixels
    errors_before, errors_after = [], []
    for k in range(1, 6):
        t = k / FPS
        uv, found = source.measure(TimedFrame(t, t), ids, scene.at(t), np.tile(np.eye(2), (len(ids), 1, 1)))
        assert found.all()
        truth = scene.u0 + scene.w * (t + t_ref_offset)
        errors_after.append(np.abs(uv - truth).max())
        errors_before.append(np.abs(scene.at(t) - truth).max())
    # the shift is up to |w| * 120 rows * 60 us (~2 px here); what remains is second order in w_v d
    assert min(errors_before) > 1.0
    assert max(errors_after) < 0.02 * max(errors_before)


def test_features_without_two_measurements_use_the_frame_velocity_field():
    scene = _scene(seed=4)
    source = RollingShutterCorrection(scene, D_S, HEIGHT)
    ids = np.arange(len(scene.u0))
    source.track(TimedFrame(0.0, 0.0), ids, scene.at(0.0))
    t = 1 / FPS
    source.measure(TimedFrame(t, t), ids, scene.at(t), np.tile(np.eye(2), (len(ids), 1, 1)))
    # a new corner this frame has no history: corrected by the affine field of the others
    new = MovingFeatures(scene.u0[:1] + [5.0, 7.0], scene.w[:1])
    raw = new.at(t)
    corrected = raw - source._shift(raw, source._field_velocity(raw))
    truth = new.u0 + new.w * (t + source.reference_row * D_S)
    assert np.abs(corrected - truth).max() < 0.15 * np.abs(raw - truth).max()


def test_timed_frames_and_bad_line_delays():
    frames = list(timed_frames([(0.0, "a"), (0.1, None), (0.2, "c")]))
    assert frames[1] == (0.1, None) and frames[2][1].t_s == 0.2 and frames[2][1].image == "c"
    for bad in (0.0, -1e-5, float("nan")):
        with pytest.raises(InputError):
            RollingShutterCorrection(_scene(), bad, HEIGHT)
