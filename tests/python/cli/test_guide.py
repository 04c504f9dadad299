"""`rscalib guide`: the guides travel with the installed package, and the verdicts point at them."""
import subprocess
import sys
from pathlib import Path

CLI = [sys.executable, "-m", "rscalib.cli"]
DOCS = Path(__file__).resolve().parents[3] / "docs"


def test_the_capture_guide_is_installed_and_printed():
    shown = subprocess.run([*CLI, "guide", "capture"], capture_output=True, text=True, timeout=60)
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout == (DOCS / "capture.md").read_text()     # the same text as the repository's
    where = Path(subprocess.run([*CLI, "guide", "capture", "--path"], capture_output=True, text=True,
                                timeout=60).stdout.strip())
    assert where.name == "capture.md" and "site-packages" in str(where)   # from the package, not the checkout
    assert (where.parent / "capture" / "framing.png").stat().st_size > 0  # with its figures


def test_the_formats_guide_and_a_bad_name():
    assert "docs/formats.md" not in subprocess.run([*CLI, "guide", "formats"], capture_output=True, text=True,
                                                   timeout=60).stderr
    bad = subprocess.run([*CLI, "guide", "nonsense"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_verdicts_point_at_the_installed_guide():
    from rscalib.cli.common import CAPTURE_GUIDE

    assert "rscalib guide capture" in CAPTURE_GUIDE and "repository" not in CAPTURE_GUIDE


def test_a_reader_that_goes_away_is_no_error():
    """`rscalib guide capture | head -1`: the reader closes the pipe before the text is written. That
    is not bad input (exit 2) but the shell's broken pipe, 128 + SIGPIPE, and nothing is said."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)   # the reader is gone before the first write
    try:
        done = subprocess.run([*CLI, "guide", "capture"], stdout=write_end, stderr=subprocess.PIPE, text=True,
                              timeout=60)
    finally:
        os.close(write_end)
    assert done.returncode == 141, done.stderr
    assert done.stderr == ""
