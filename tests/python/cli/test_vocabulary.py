"""One vocabulary in every command's help (issue 32): the readout directions are today's words
(rscalib.readout), never the earlier ones; every option that takes a line delay says it takes a unit."""
from __future__ import annotations

import argparse
import re

import pytest

from rscalib.cli import build_parser
from rscalib.readout import READOUT_DIRECTIONS

EARLIER = ("top-down", "bottom-up", "left-right", "right-left")


def _subcommands() -> dict:
    parser = build_parser()
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices)


@pytest.mark.parametrize("name", sorted(_subcommands()))
def test_help_uses_todays_readout_words(name):
    text = " ".join(_subcommands()[name].format_help().split())    # argparse wraps lines
    for word in EARLIER:
        assert not re.search(rf"(?<![\w-]){word}(?![\w-])", text), (name, word)
    for word in re.findall(r"\b(?:top|bottom|left|right)-to-(?:top|bottom|left|right)\b", text):
        assert word in READOUT_DIRECTIONS, (name, word)


@pytest.mark.parametrize("name", sorted(_subcommands()))
def test_line_delay_options_take_a_unit(name):
    sub = _subcommands()[name]
    for action in sub._actions:
        if any(flag.startswith("--line-delay") for flag in action.option_strings) and action.help != argparse.SUPPRESS \
                and "from" not in action.option_strings[0]:
            assert "us" in action.help or "unit" in action.help, (name, action.option_strings, action.help)
            assert action.type("30us") == pytest.approx(30e-6) and action.type("3e-5") == pytest.approx(3e-5)
