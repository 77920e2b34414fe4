"""Progress bars of the ``gmwm`` command: tqdm bars on a terminal, nothing on a pipe.

Each long command (``report``, ``batch``, ``select``, ``fit`` of several files) runs in a
child process twice: with stderr on a pseudo-terminal, where the bar of each stage is drawn
(its name, ``100%|`` and the final count), and with stderr on a pipe, where no bar and no
progress line is printed (only what the command says anyway).
"""

from __future__ import annotations

import fcntl
import os
import pty
import select
import shutil
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

import engine as eg

ROOT = Path(__file__).resolve().parents[2]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "120"}


def on_terminal(argv: list[str], cwd: Path) -> tuple[int, str]:
    """Run ``python -m engine.cli ARGV`` with stderr on a pseudo-terminal (120 columns);
    (exit status, what the terminal showed)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    proc = subprocess.Popen(
        [sys.executable, "-m", "engine.cli", *argv],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=slave,
        cwd=cwd,
        env=_env(),
    )
    os.close(slave)
    chunks = []
    while True:
        ready, _, _ = select.select([master], [], [], 120)
        if not ready:
            proc.kill()
            break
        try:
            data = os.read(master, 65536)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    return proc.wait(timeout=120), b"".join(chunks).decode("utf-8", "replace")


def on_pipe(argv: list[str], cwd: Path) -> tuple[int, str]:
    """The same with stderr on a pipe: (exit status, stderr)."""
    p = subprocess.run(
        [sys.executable, "-m", "engine.cli", *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=_env(),
        timeout=300,
    )
    return p.returncode, p.stderr


def _no_bar(err: str) -> None:
    assert "%|" not in err and "\r" not in err and " ETA " not in err, err


@pytest.fixture(scope="module")
def two_logs(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("bars")
    out = []
    for k in (1, 2):
        p = d / f"unit{k}.h5"
        shutil.copy(eg.demo_path(), p)
        out.append(p)
    return out


def test_report_draws_a_bar_per_stage_on_a_terminal_and_nothing_on_a_pipe(tmp_path):
    argv = [str(eg.demo_path()), "--model", "WN+RW", "--channels", "gyro_x,gyro_y"]
    code, shown = on_terminal(["report", *argv, "-o", str(tmp_path / "t.html")], tmp_path)
    assert code == 0, shown
    # each stage's bar, complete: 2 channels fitted, 2 channels' numbers and the export,
    # 8 figures and their serialisation, the page
    for stage, count in [("fits", "2/2"), ("intervals", "3/3"), ("figures", "9/9")]:
        line = next(ln for ln in shown.split("\r") if f"gmwm report: {stage}" in ln and count in ln)
        assert "100%|" in line
    assert "gmwm report: writing" in shown
    code, err = on_pipe(["report", *argv, "-o", str(tmp_path / "p.html")], tmp_path)
    assert code == 0 and (tmp_path / "p.html").stat().st_size > 100_000
    _no_bar(err)
    assert "gmwm report:" not in err


def test_batch_counts_logs_then_the_fleet_page_on_a_terminal_only(two_logs, tmp_path):
    argv = ["batch", *map(str, two_logs), "--model", "WN+RW", "--channels", "gyro_x"]
    code, shown = on_terminal([*argv, "--report", str(tmp_path / "t.html")], tmp_path)
    assert code == 0, shown
    assert any(
        "gmwm batch: logs" in ln and "2/2" in ln and "100%|" in ln for ln in shown.split("\r")
    )
    assert "gmwm batch: report: figures" in shown
    code, err = on_pipe([*argv, "--report", str(tmp_path / "p.html")], tmp_path)
    assert code == 0 and (tmp_path / "p.html").exists()
    _no_bar(err)
    assert "/2 logs" not in err and "gmwm batch: logs" not in err
    code, quiet = on_terminal([*argv, "-o", str(tmp_path / "q"), "--quiet"], tmp_path)
    assert code == 0 and "%|" not in quiet


def test_select_counts_its_candidates_on_a_terminal_only(tmp_path):
    argv = ["select", str(eg.demo_path()), "--channel", "gyro_x", "--max-model", "WN+RW+DR"]
    code, shown = on_terminal(argv, tmp_path)
    assert code == 0, shown
    # the 7 sub-models of WN+RW+DR, each fitted once
    assert any("gmwm select: candidates" in ln and "100%|" in ln for ln in shown.split("\r"))
    code, err = on_pipe(argv, tmp_path)
    assert code == 0
    _no_bar(err)


def test_fit_of_several_files_counts_the_files_on_a_terminal_only(two_logs, tmp_path):
    argv = ["fit", *map(str, two_logs), "--model", "WN+RW", "--channel", "gyro_x"]
    code, shown = on_terminal(argv, tmp_path)
    assert code == 0, shown
    assert any(
        "gmwm fit: files" in ln and "2/2" in ln and "100%|" in ln for ln in shown.split("\r")
    )
    code, err = on_pipe(argv, tmp_path)
    assert code == 0
    _no_bar(err)
