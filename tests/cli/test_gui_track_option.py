"""``workbench gui --track FILE [--frame N]``: the Animate tool's timeline from the command line."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from workbench.core.errors import InputError

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "hello_world_track.json"


def _parse(*argv: str):
    from workbench.cli import gui_cmd

    parser = argparse.ArgumentParser()
    gui_cmd.register(parser.add_subparsers())
    return gui_cmd.options_from(parser.parse_args(["gui", *argv]))


def test_a_track_opens_the_animate_tool_at_a_frame() -> None:
    opts = _parse("--track", str(EXAMPLE), "--frame", "12")
    assert opts.tool == "animate" and opts.track == EXAMPLE and opts.track_frame == 12


@pytest.mark.parametrize(
    "argv,needle",
    [(("--track", "no_such_track.json"), "does not exist"), (("--frame", "-3"), "0 or more")],
)
def test_bad_track_options_are_refused(argv, needle) -> None:
    full = argv if argv[0] == "--track" else ("--track", str(EXAMPLE), *argv)
    with pytest.raises(InputError, match=needle):
        _parse(*full)
