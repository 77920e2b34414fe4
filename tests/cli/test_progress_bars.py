"""Progress bars of the ``gmwm`` command: tqdm bars on a terminal, nothing elsewhere.

Each long command (``report``, ``batch``, ``select``, ``fit`` of several files) runs twice in
this process: with stderr on a pseudo-terminal, where the bar of each stage is drawn (its
name, ``100%|`` and the final count), and with stderr captured (not a terminal, as a pipe or
a file), where no bar and no progress line is printed (only what the command says anyway).
"""

from __future__ import annotations

import fcntl
import os
import pty
import shutil
import struct
import sys
import termios
import threading
from pathlib import Path

import pytest

import engine as eg
from engine.cli import main


def on_terminal(argv: list[str]) -> tuple[int, str]:
    """Run ``gmwm ARGV`` in this process with stderr on a pseudo-terminal (120 columns);
    (exit status, what the terminal showed)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    chunks: list[bytes] = []

    def drain() -> None:  # the terminal's buffer is small: read while the command writes
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the writing side is closed
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    term = os.fdopen(slave, "w", encoding="utf-8", buffering=1)
    saved = sys.stderr
    sys.stderr = term
    try:
        code = main(argv)
    finally:
        sys.stderr = saved
        term.close()
    reader.join(timeout=30)
    os.close(master)
    return code, b"".join(chunks).decode("utf-8", "replace")


def on_pipe(argv: list[str], capsys) -> tuple[int, str]:
    """The same with stderr not a terminal (captured): (exit status, stderr)."""
    capsys.readouterr()
    code = main(argv)
    return code, capsys.readouterr().err


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


def test_report_draws_a_bar_per_stage_on_a_terminal_and_nothing_on_a_pipe(tmp_path, capsys):
    argv = [str(eg.demo_path()), "--model", "WN+RW", "--channels", "gyro_x"]
    code, shown = on_terminal(["report", *argv, "-o", str(tmp_path / "t.html")])
    assert code == 0, shown
    # each stage's bar, complete: 1 channel fitted, its numbers and the export, 4 figures
    # and their serialisation, the page
    for stage, count in [("fits", "1/1"), ("intervals", "2/2"), ("figures", "5/5")]:
        line = next(ln for ln in shown.split("\r") if f"gmwm report: {stage}" in ln and count in ln)
        assert "100%|" in line
    assert "gmwm report: writing" in shown
    code, err = on_pipe(["report", *argv, "-o", str(tmp_path / "p.html")], capsys)
    assert code == 0 and (tmp_path / "p.html").stat().st_size > 100_000
    _no_bar(err)
    assert "gmwm report:" not in err


def test_batch_counts_logs_then_the_fleet_page_on_a_terminal_only(two_logs, tmp_path, capsys):
    argv = [
        "batch",
        *map(str, two_logs),
        "--model",
        "WN+RW",
        "--channels",
        "gyro_x",
        "--workers",
        "1",
    ]
    code, shown = on_terminal([*argv, "--report", str(tmp_path / "t.html")])
    assert code == 0, shown
    assert any(
        "gmwm batch: logs" in ln and "2/2" in ln and "100%|" in ln for ln in shown.split("\r")
    )
    assert "gmwm batch: report: figures" in shown
    code, err = on_pipe([*argv, "-o", str(tmp_path / "p")], capsys)
    assert code == 0 and (tmp_path / "p" / "summary.csv").exists()
    _no_bar(err)
    assert "/2 logs" not in err and "gmwm batch: logs" not in err
    code, quiet = on_terminal([*argv, "-o", str(tmp_path / "q"), "--quiet"])
    assert code == 0 and "%|" not in quiet


def test_select_counts_its_candidates_on_a_terminal_only(tmp_path, capsys):
    argv = ["select", str(eg.demo_path()), "--channel", "gyro_x", "--max-model", "WN+RW+DR"]
    code, shown = on_terminal(argv)
    assert code == 0, shown
    # the 7 sub-models of WN+RW+DR, each fitted once
    assert any("gmwm select: candidates" in ln and "100%|" in ln for ln in shown.split("\r"))
    code, err = on_pipe(argv, capsys)
    assert code == 0
    _no_bar(err)


def test_fit_of_several_files_counts_the_files_on_a_terminal_only(two_logs, tmp_path, capsys):
    argv = ["fit", *map(str, two_logs), "--model", "WN+RW", "--channel", "gyro_x"]
    code, shown = on_terminal(argv)
    assert code == 0, shown
    assert any(
        "gmwm fit: files" in ln and "2/2" in ln and "100%|" in ln for ln in shown.split("\r")
    )
    code, err = on_pipe(argv, capsys)
    assert code == 0
    _no_bar(err)
