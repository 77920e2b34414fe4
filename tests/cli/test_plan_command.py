"""``gmwm plan`` prints what docs/planning.md shows, to the printed digit.

Each ``$ gmwm plan ...`` block of the guide is run through the command's entry point, and every
line the guide prints must be a line of the command's output, in the same order (a block may
show only the lines it discusses). The guide's tables were written by the code before the
command was made faster (docs/performance.md, "The gmwm command's start"): a change of the
search, of the caches or of the imports that moved one printed digit fails here.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from engine.cli import main

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "planning.md"


def _examples() -> list[tuple[list[str], list[str]]]:
    """(argv after ``gmwm``, the lines printed) of each ``$ gmwm plan`` block of the guide."""
    out = []
    for block in re.findall(r"```\n(\$ gmwm plan.*?)```", GUIDE.read_text(), re.S):
        command, _, printed = block.partition("\n")
        while command.endswith("\\"):  # a command continued on the next line
            more, _, printed = printed.partition("\n")
            command = command[:-1] + " " + more.strip()
        argv = shlex.split(command)[2:]  # after "$ gmwm"
        out.append((argv, [line for line in printed.splitlines() if line.strip()]))
    return out


EXAMPLES = _examples()


def test_the_guide_has_its_examples():
    assert len(EXAMPLES) >= 5
    assert all(argv[0] == "plan" and lines for argv, lines in EXAMPLES)


@pytest.mark.parametrize(
    ("argv", "shown"), EXAMPLES, ids=[" ".join(a[1:3])[:40] for a, _ in EXAMPLES]
)
def test_each_example_prints_what_the_guide_shows(argv, shown, capsys):
    assert main(argv) == 0
    printed = capsys.readouterr().out.splitlines()
    at = 0
    for line in shown:
        assert line in printed[at:], f"{line!r} is not printed (after line {at})"
        at = printed.index(line, at) + 1
