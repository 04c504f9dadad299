"""The early board probe (detection.probe.early_board) with the declared size: a match seen at half
resolution and confirmed once at full resolution settles it; anything else is decided at full
resolution, as without a declared size."""
import pytest

from rscalib.detection import probe


@pytest.fixture(scope="module")
def video_640(tmp_path_factory):
    from rscalib.sim.target_video import render_video

    folder = tmp_path_factory.mktemp("early_640")
    render_video(folder, duration_s=2.0, size=(640, 480), seed=3, progress=False, workers=1)
    return folder / "video.avi"


@pytest.fixture(scope="module")
def video_320(tmp_path_factory):
    from rscalib.sim.target_video import render_video

    folder = tmp_path_factory.mktemp("early_320")
    render_video(folder, duration_s=2.0, size=(320, 240), seed=3, progress=False, workers=1)
    return folder / "video.avi"


def sizes_searched(monkeypatch) -> list:
    """The image sizes whole_board_size is called on, from now on."""
    searched = []
    original = probe.whole_board_size

    def recording(gray):
        searched.append(gray.shape[::-1])
        return original(gray)

    monkeypatch.setattr(probe, "whole_board_size", recording)
    return searched


def test_a_match_is_settled_at_half_resolution(video_640, monkeypatch):
    assert probe.early_board(video_640) == (9, 6)
    searched = sizes_searched(monkeypatch)
    assert probe.early_board(video_640, expected=(6, 9)) == (9, 6)
    # the frames at half resolution, and one full-resolution confirmation (no larger board hidden)
    assert searched.count((640, 480)) == 1 and searched[-1] == (640, 480)
    assert set(searched[:-1]) == {(320, 240)} and len(searched) >= 3


@pytest.mark.parametrize("declared", [(10, 7), (4, 3)])
def test_a_mismatch_is_decided_at_full_resolution(video_640, monkeypatch, declared):
    searched = sizes_searched(monkeypatch)
    assert probe.early_board(video_640, expected=declared) == (9, 6)   # what the frames show
    assert (640, 480) in searched


def test_a_small_video_gives_the_same_answer(video_320):
    """320x240: the board is still seen whole at 160x120, and the answer is the full-resolution one."""
    assert probe.early_board(video_320, expected=(9, 6)) == probe.early_board(video_320) == (9, 6)
