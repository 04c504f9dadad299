"""Tests of the per-frame loop of self-calibration (rscalib.selfcalib.driver.run_bank) with a scripted
measurement source that finds nothing: the order of the calls, how many new features are asked for,
skipped and limited frames, deleted features passed on, and input errors. Oracle: the loop's
contract (docs/sog.md §1), counted call by call."""
import numpy as np
import pytest

from rscalib import InputError
from rscalib.selfcalib.driver import SelfCalibHistory, run_bank
from rscalib.selfcalib.prior import initial_bank, make_bank


class Scripted:
    """A source that never finds a feature and offers new ones on a grid inside the image."""

    def __init__(self):
        self.calls = []

    def measure(self, frame, ids, uv_pred, cov):
        self.calls.append(("measure", frame, len(ids)))
        return np.full((len(ids), 2), np.nan), np.zeros(len(ids), dtype=bool)

    def forget(self, feature_ids):
        if len(feature_ids):
            self.calls.append(("forget", frame_of(self), sorted(int(i) for i in feature_ids)))

    def new_features(self, frame, count, search):
        assert len(search.ids) == len(search.uv_pred) == len(search.found)
        self.calls.append(("new", frame, count))
        u, v = np.meshgrid(np.linspace(60, 260, 5), np.linspace(50, 190, 4))
        return np.c_[u.ravel(), v.ravel()][:count]

    def track(self, frame, feature_ids, uv):
        self.calls.append(("track", frame, len(feature_ids)))


def frame_of(source):
    return next(c[1] for c in reversed(source.calls) if c[0] == "measure")


def one_gaussian_bank():
    grid = dict(f_range=(180.0, 210.0), f_count=1, k1_count=1, k2_count=1)
    return make_bank(320, 240, bank=initial_bank(320, 240, **grid))


def test_first_frame_starts_the_map_later_frames_add_at_most_max_new():
    source = Scripted()
    frames = [(0.0, "a"), (0.1, None), (0.2, "b"), (0.3, "c"), (0.4, "d")]
    seen = []
    history = run_bank(one_gaussian_bank(), frames, source, min_visible=6, max_new_per_frame=2, max_frames=4,
                       on_frame=lambda k, bank, report: seen.append((k, report.num_used)))
    assert isinstance(history, SelfCalibHistory)
    np.testing.assert_array_equal(history.frame, [0, 2, 3])          # None skipped, "d" beyond max_frames
    assert seen == [(0, 0), (2, 0), (3, 0)]
    news = [c for c in source.calls if c[0] == "new"]
    assert news == [("new", "a", 6), ("new", "b", 2), ("new", "c", 2)]
    assert [c for c in source.calls if c[0] == "track"] == [("track", "a", 6), ("track", "b", 2), ("track", "c", 2)]
    # every feature the bank predicted was searched (the frames' first calls)
    assert source.calls[0] == ("measure", "a", 0)
    np.testing.assert_array_equal(history.map_size, [6, 8, 10])
    np.testing.assert_array_equal(history.features_used, [0, 0, 0])
    assert history.mean.shape == (3, 5) and history.bounds_99.shape == (3, 5, 2)
    assert history.collapse_frame == 0                                 # one Gaussian from the start
    assert len(history.summary_dict()["gaussians"]) == 3


def test_deleted_features_are_forgotten_by_the_source():
    source = Scripted()
    reports = []
    run_bank(one_gaussian_bank(), [(0.1 * k, k) for k in range(12)], source, min_visible=4, max_new_per_frame=1,
             on_frame=lambda k, bank, report: reports.append((k, sorted(int(i) for i in report.deleted_feature_ids))))
    deleted = [(k, ids) for k, ids in reports if ids]
    assert deleted, "features never found are deleted after a few searches"
    assert [c for c in source.calls if c[0] == "forget"] == [("forget", k, ids) for k, ids in deleted]


@pytest.mark.parametrize("frames, message", [
    ([(0.0, "a"), (0.0, "b")], "frame times must increase"),
    ([(0.0, None)], "no frames to process"),
    ([], "no frames to process"),
])
def test_input_errors(frames, message):
    with pytest.raises(InputError, match=message):
        run_bank(one_gaussian_bank(), frames, Scripted())
