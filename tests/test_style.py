"""One formatter and one linter for the whole tree: ``ruff format`` and ``ruff check``.

Skipped (with the reason) only when ruff is not installed; the test extra installs it.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _ruff() -> list[str]:
    try:
        from ruff.__main__ import find_ruff_bin  # the pip package ships the binary

        return [str(find_ruff_bin())]
    except ImportError:
        exe = shutil.which("ruff")
        if exe is None:
            pytest.skip("ruff is not installed (pip install ruff, or the [test] extra)")
        return [exe]


@pytest.mark.parametrize("args", [["format", "--check", "."], ["check", "."]])
def test_tree_is_ruff_clean(args: list[str]) -> None:
    p = subprocess.run(
        [*_ruff(), *args], cwd=REPO, capture_output=True, text=True, timeout=300, check=False
    )
    assert p.returncode == 0, f"ruff {' '.join(args)} in {REPO}:\n{p.stdout}\n{p.stderr}"
