"""The type checker on ``engine``: mypy with the project's ``[tool.mypy]`` (pyproject.toml) must
report no error, so that the annotations stay true as the code changes.

mypy is in the ``test`` extra: a missing mypy fails this test rather than skipping it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_mypy_engine_clean() -> None:
    try:
        import mypy  # noqa: F401
    except ImportError:  # pragma: no cover - the test extra installs it
        pytest.fail("mypy is not installed: pip install -e '.[test]' (the test extra has it)")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"mypy found errors in engine:\n{out}"
    assert "Success: no issues found" in out, out
