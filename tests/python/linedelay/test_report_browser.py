"""report.html in a real browser (issue 31): headless Chromium (Debian's `chromium`, installed by
scripts/install-system-deps.sh) opens the line-delay and the flicker reports; every <img> must decode
(complete, with a width) and the page must log no console error. The check itself is tested on a page
with a broken image and a script error. Skips, saying why, only when chromium is not installed.

Also what a newcomer reads: no raw result.json keys, a sentence under every plot, the expert's plots
in the appendix.
"""
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from rscalib.cli import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (scripts/install-system-deps.sh "
                                                             "installs it): the browser test cannot run")

# After the page has loaded: which images did not decode, and how many there are.
_PROBE = """<script>window.addEventListener("load", function () {
  var bad = [], images = document.images;
  for (var i = 0; i < images.length; i++) {
    if (!(images[i].complete && images[i].naturalWidth > 0)) bad.push(images[i].alt || images[i].src.slice(0, 40));
  }
  document.body.setAttribute("data-images", String(images.length));
  document.body.setAttribute("data-broken", JSON.stringify(bad));
});</script>"""


def open_in_chromium(page: Path, tmp_path: Path) -> dict:
    """Open a copy of `page` (with the probe script appended) in headless Chromium: the number of
    images, the ones that did not decode, and the console errors."""
    probed = tmp_path / f"probed_{page.parent.name}_{page.name}"
    probed.write_text(page.read_text().replace("</body>", _PROBE + "</body>"))
    done = subprocess.run([CHROMIUM, "--headless", "--disable-gpu", "--no-sandbox", "--enable-logging=stderr",
                           "--v=0", "--virtual-time-budget=5000", f"--user-data-dir={tmp_path / 'profile'}",
                           "--dump-dom", probed.as_uri()], capture_output=True, text=True, timeout=180)
    dom = done.stdout
    images = re.search(r'data-images="(\d+)"', dom)
    broken = re.search(r'data-broken="([^"]*)"', dom)
    console = [line for line in done.stderr.splitlines() if "CONSOLE" in line and
               ("ERROR" in line or "Uncaught" in line or "Failed" in line)]
    return {"loaded": images is not None, "images": int(images.group(1)) if images else 0,
            "broken": json.loads(broken.group(1).replace("&quot;", '"')) if broken else None,
            "console_errors": console, "stderr": done.stderr[-2000:]}


@needs_chromium
def test_the_browser_check_catches_a_broken_image_and_a_script_error(tmp_path):
    page = tmp_path / "bad.html"
    page.write_text('<!doctype html><html><body><img src="data:image/png;base64,AAAA" alt="broken">'
                    '<script>no_such_function();</script></body></html>')
    seen = open_in_chromium(page, tmp_path)
    assert seen["loaded"], seen["stderr"]
    assert seen["images"] == 1 and seen["broken"] == ["broken"]
    assert seen["console_errors"], seen["stderr"]


@pytest.fixture(scope="module")
def linedelay_report(tmp_path_factory):
    """`rscalib linedelay` on a 1.5 s render: its output folder."""
    root = tmp_path_factory.mktemp("browser_linedelay")
    assert main(["simulate", "--out", str(root / "video"), "--duration", "1.5", "--seed", "3", "--supersample", "1",
                 "--quiet"]) == 0
    main(["linedelay", str(root / "video" / "video.avi"), "--target", str(root / "video" / "target.yaml"),
          "--camera", str(root / "video" / "camera.yaml"), "--out", str(root / "out"), "--quiet"])
    return root / "out"


@pytest.fixture(scope="module")
def flicker_report(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser_flicker")
    assert main(["simulate", "--out", str(root / "led"), "--size", "320x240", "--duration", "0.4", "--motion", "0",
                 "--supersample", "1", "--quiet", "--flicker-hz", "1000", "--flicker-depth", "0.3",
                 "--line-delay", "30us"]) == 0
    main(["flicker", str(root / "led" / "video.avi"), "--out", str(root / "out"), "--quiet", "--frequency", "1000"])
    return root / "out"


@needs_chromium
@pytest.mark.parametrize("which", ["linedelay_report", "flicker_report"])
def test_report_opens_in_chromium_with_every_image_and_no_console_error(which, request, tmp_path):
    out = request.getfixturevalue(which)
    written = json.loads((out / "result.json").read_text())
    seen = open_in_chromium(out / "report.html", tmp_path)
    assert seen["loaded"], seen["stderr"]
    assert seen["images"] == len(written["files"]["plots"]) > 0
    assert seen["broken"] == []
    assert seen["console_errors"] == []


def test_linedelay_report_speaks_to_a_newcomer(linedelay_report):
    page = (linedelay_report / "report.html").read_text()
    written = json.loads((linedelay_report / "result.json").read_text())
    main_part, appendix = page.split("Appendix: for the expert")
    # no raw result.json keys in what a newcomer reads
    for key in list(written.get("guidance", {})) + ["normalised_cost", "row_coverage_deciles", "J/2N"]:
        assert key not in main_part, key
    # a sentence under every plot saying what to look for
    captions = re.findall(r"<figcaption>(.*?)</figcaption>", page, flags=re.S)
    assert len(captions) == len(written["files"]["plots"])
    assert all('class="look"' in c and "Look for" in c for c in captions)
    # the expert's plots and numbers are in the appendix, the trajectory is not
    for title in ("How image motion stretches the detection noise", "Knot density and image motion",
                  "Line delay per knot-adaptation round", "knot segments"):
        assert title not in main_part and title in appendix, title
    assert appendix.count("<img") == 3 and main_part.count("<img") == 3
