"""A ``gmwm`` command never destroys data.

Before: ``gmwm export LOG -o LOG`` (or through a symlink) overwrote the IMU log; on a full
disk ``report``, ``export -o`` and ``simulate`` exited with "No space left on device" (no file
named) and left truncated files that looked complete. Now an output that is an input is
refused before any work, and every output is written to a temporary file in its folder and
renamed over the target only when complete (engine._files.atomic_output).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import engine._files as files
from engine._parallel import PARENT_POLL_S
from engine.cli import main
from engine.io import save_log

MODEL = "WN+RW"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.fixture
def log(tmp_path: Path) -> Path:
    rng = np.random.default_rng(7)
    x = rng.normal(size=20_000) + np.cumsum(rng.normal(scale=1e-3, size=20_000))
    return save_log(tmp_path / "imu.h5", {"gyro_x": x}, 100.0, units={"gyro_x": "rad/s"})


def leftovers(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if ".tmp" in p.name]


# ------------------------------------------------------------------ output is an input
@pytest.mark.parametrize("how", ["same", "symlink", "hardlink", "relative"])
def test_export_refuses_to_overwrite_its_input(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, log: Path, how: str
) -> None:
    before = digest(log)
    out = {
        "same": log,
        "symlink": tmp_path / "out.yaml",
        "hardlink": tmp_path / "hard.h5",
        "relative": tmp_path / "sub" / ".." / "imu.h5",
    }[how]
    if how == "symlink":
        out.symlink_to(log)
    elif how == "hardlink":
        os.link(log, out)
    elif how == "relative":
        (tmp_path / "sub").mkdir()
    code, _, err = run(
        capsys, "export", str(log), "--model", MODEL, "--format", "json", "-o", str(out)
    )
    assert code == 2 and digest(log) == before
    assert f"-o {out} is the input file '{log}'" in err
    assert "would destroy the input" in err and len(err.strip().splitlines()) == 1


def test_report_and_batch_report_refuse_their_inputs(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, log: Path
) -> None:
    page = tmp_path / "imu.html"
    shutil.copy(log, page)  # a log named like the page
    before = digest(page)
    code, _, err = run(capsys, "report", str(page), "--model", MODEL, "-o", str(page))
    assert code == 2 and "is the input file" in err and digest(page) == before
    code, _, err = run(
        capsys, "batch", str(tmp_path / "*.html"), "--model", MODEL, "--report", str(page)
    )
    assert code == 2 and "is the input file" in err and digest(page) == before


# ------------------------------------------------------------------ full disk
def test_a_failed_write_names_the_file_and_keeps_the_old_one(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    log: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """ENOSPC when the data are flushed (monkeypatched): exit 2, one line naming the file,
    the previous content intact and no temporary file left."""
    out = tmp_path / "imu.yaml"
    out.write_text("previous\n")

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", full)
    code, _, err = run(
        capsys, "export", str(log), "--model", MODEL, "--format", "json", "-o", str(out)
    )
    assert code == 2
    assert err.strip() == (
        f"gmwm: error: cannot write '{out}' (No space left on device): nothing was written "
        "and any previous file of that name is unchanged; free space or choose another folder"
    )
    assert out.read_text() == "previous\n" and leftovers(tmp_path) == []


def test_atomic_output_replaces_the_target_of_a_symlink(tmp_path: Path) -> None:
    target = tmp_path / "real.txt"
    target.write_text("old")
    target.chmod(0o640)
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    files.write_atomic(link, "new")
    assert link.is_symlink() and target.read_text() == "new"
    assert (target.stat().st_mode & 0o777) == 0o640 and leftovers(tmp_path) == []
    with pytest.raises(RuntimeError):  # an error inside the block: nothing replaced
        with files.atomic_output(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("writer failed")
    assert target.read_text() == "new" and leftovers(tmp_path) == []


@pytest.fixture
def full_disk(tmp_path: Path):  # type: ignore[no-untyped-def]
    """A 64 KiB tmpfs (root only; skipped elsewhere)."""
    mnt = tmp_path / "full"
    mnt.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root")
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True
    )
    if r.returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


def test_a_real_full_disk(capsys: pytest.CaptureFixture[str], log: Path, full_disk: Path) -> None:
    """report, export, simulate (HDF5 and CSV) onto a 64 KiB tmpfs: each exits 2 naming its
    file, an older file of that name is intact, nothing else is left (before: a truncated
    64 KiB report.html that looked complete, and "No space left on device" naming nothing)."""
    old = full_disk / "report.html"
    old.write_text("<p>previous report</p>")
    code, _, err = run(capsys, "report", str(log), "--model", MODEL, "-o", str(old))
    assert code == 2 and f"cannot write '{old}' (No space left on device)" in err
    assert old.read_text() == "<p>previous report</p>"
    for out, argv in [
        ("sim.h5", ["simulate", "--model", "WN(1)", "-n", "200000", "-o"]),
        ("sim.csv", ["simulate", "--model", "WN(1)", "-n", "200000", "-o"]),
        ("fit.json", ["export", str(log), "--model", MODEL, "--format", "json", "-o"]),
    ]:
        if out == "fit.json":  # fill the disk so that even a small JSON cannot fit
            (full_disk / "filler").write_bytes(b"\0" * (60 * 1024 - old.stat().st_size))
        code, _, err = run(capsys, *argv, str(full_disk / out))
        assert code == 2, (out, err)
        assert f"cannot write '{full_disk / out}' (No space left on device)" in err, err
        assert len(err.strip().splitlines()) == 1
        assert not (full_disk / out).exists() and leftovers(full_disk) == []


# ------------------------------------------------------------------ batch workers
def _children(pid: int) -> set[int]:
    out: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            out |= {int(c) for c in (task / "children").read_text().split()}
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc (Linux)")
def test_batch_workers_end_with_their_parent(tmp_path: Path) -> None:
    """SIGKILL of ``gmwm batch`` while its two workers fit: every child (workers and the
    resource tracker) is gone within 5 s (before: alive 14 min later, 120 MB each)."""
    rng = np.random.default_rng(3)
    logs = []
    for k in range(6):
        x = rng.normal(size=200_000) + np.cumsum(rng.normal(scale=1e-3, size=200_000))
        logs.append(str(save_log(tmp_path / f"u{k}.h5", {"gyro_x": x}, 100.0)))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    argv = ["-m", "engine.cli", "batch", *logs, "--model", "3*GM+WN+RW", "--workers", "2"]
    proc = subprocess.Popen(
        [sys.executable, *argv, "--quiet", "-o", str(tmp_path / "out")],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        kids: set[int] = set()
        while time.monotonic() < deadline and len(kids) < 3 and proc.poll() is None:
            kids |= _children(proc.pid)
            time.sleep(0.2)
        assert len(kids) >= 2, "the batch never started its workers"
        time.sleep(1.0)  # the workers are fitting
        kids |= _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        end = time.monotonic() + 5 + PARENT_POLL_S
        while time.monotonic() < end and any(_alive(k) for k in kids):
            time.sleep(0.1)
        left = [k for k in kids if _alive(k)]
        assert not left, f"{len(left)} of {len(kids)} children still alive 5 s after SIGKILL"
    finally:
        for k in _children(proc.pid) | kids:
            with contextlib.suppress(OSError):
                if _alive(k):
                    os.kill(k, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()


def test_writing_to_a_device_writes_in_place_and_keeps_the_device(
    capsys: pytest.CaptureFixture[str], log: Path
) -> None:
    """`gmwm export LOG -o /dev/null`: the atomic writer renamed its temporary file over the
    output, so as root it replaced /dev/null (a character device) with a regular file for every
    process of the machine. A path that is not a regular file is written in place."""
    import stat

    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    try:
        code, _, err = run(
            capsys, "export", str(log), "--model", MODEL, "--format", "json", "-o", "/dev/null"
        )
        assert code == 0, err
        assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    finally:  # never leave the machine without /dev/null, whatever the code under test did
        if not stat.S_ISCHR(os.stat("/dev/null").st_mode) and os.geteuid() == 0:
            os.remove("/dev/null")
            os.mknod("/dev/null", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
            os.chmod("/dev/null", 0o666)
