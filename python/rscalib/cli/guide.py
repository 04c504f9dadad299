"""`rscalib guide`: the guides that travel with the package (how to film for each command, the file
formats), printed to the terminal or opened in a browser. They are installed as package data from
the repository's docs/ (one source); a checkout that is not installed reads docs/ directly."""
from __future__ import annotations

import argparse
import sys
import webbrowser
from pathlib import Path
from typing import Optional

from ..errors import InputError

GUIDES = {"capture": ("capture.md", "how to film for each command (line delay, intrinsics, flicker, self-calibration)"),
          "formats": ("formats.md", "the camera and result files rscalib reads and writes, and for which tools")}


def guide_path(name: str) -> Optional[Path]:
    """The installed guide (rscalib/guides/NAME.md), else the checkout's docs/NAME.md; None if neither."""
    file = GUIDES[name][0]
    package = Path(__file__).resolve().parents[1]
    for candidate in (package / "guides" / file, package.parents[1] / "docs" / file):
        if candidate.is_file():
            return candidate
    return None


def pointer(name: str = "capture") -> str:
    """What a verdict says to point at a guide: the command that shows it."""
    return f"`rscalib guide {name}` ({GUIDES[name][1]})"


def add_parser(sub) -> None:
    p = sub.add_parser("guide", help="show a guide: how to film for each command, the file formats",
                       description="Print a guide that comes with rscalib (or open it in a browser with --open): "
                                   + "; ".join(f"{k}: {v[1]}" for k, v in GUIDES.items()) + ".")
    p.add_argument("name", choices=sorted(GUIDES), help="which guide")
    p.add_argument("--open", action="store_true", help="open it in a web browser instead of printing it")
    p.add_argument("--path", action="store_true", help="print only where the guide is (a Markdown file)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    path = guide_path(args.name)
    if path is None:
        raise InputError(f"the {args.name} guide is not installed with this rscalib (reinstall the package)")
    if args.path:
        print(path)
    elif args.open:
        webbrowser.open(path.as_uri())
        print(path)
    else:
        sys.stdout.write(path.read_text())
    return 0
