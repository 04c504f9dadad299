"""The one progress bar (rscalib._progress): silent, a caller's callback, or a bar on stderr only."""
from rscalib._progress import Progress


def test_a_callback_gets_done_and_total():
    seen = []
    with Progress(lambda done, total: seen.append((done, total)), 4, "work") as bar:
        bar.update(1)
        bar.advance(2)
        bar.update(4, "status text")
    assert seen == [(1, 4), (3, 4), (4, 4)]


def test_silent_and_bar_modes_keep_stdout_clean(capsys):
    with Progress(False, 3, "quiet") as bar:
        bar.update(3)
    assert capsys.readouterr() == ("", "")
    with Progress(True, 3, "shown") as bar:
        bar.update(3, "f 194.1 px")
    out, err = capsys.readouterr()
    assert out == ""
    assert "shown" in err and "3/3" in err and "f 194.1 px" in err


def test_nothing_is_shown_before_the_first_update(capsys):
    """An input error found before any work must stay the only line on stderr."""
    with Progress(True, 10, "never started"):
        pass
    assert capsys.readouterr() == ("", "")
