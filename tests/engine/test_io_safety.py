"""What the readers refuse: anything but a regular file, content in messages, files too large.

A FIFO once made ``gmwm wv x.h5`` (and the app's ``?source=path``) wait forever,
``/dev/zero`` grew memory until a MemoryError, messages quoted ``/etc/passwd`` and listed the
server's folders, and nothing compared a file's needs with the available memory. Every reader
now opens files through :mod:`engine._files`; these tests give each of them the hostile input.
A reader that blocks fails its test after a time limit instead of hanging it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import threading
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from conftest import run_capped

import engine._files as files
import engine._limits as _limits
from engine.cli import main as gmwm
from engine.inference.datasheet_check import read_datasheet
from engine.io import LoadError, load_log
from engine.io.text import text_memory_need
from engine.session import load_session
from engine.wv import open_series, wavelet_variance_stream
from gmwm_app import limits
from gmwm_app.state import AppState

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs (POSIX)")

LIMIT_S = 10.0  # a refusal takes milliseconds; a reader blocked on a FIFO never returns


def within(fn: Callable[[], Any], fifo: Path | None = None, limit: float = LIMIT_S) -> Any:
    """``fn()`` (its result, or the exception it raised), failing the test when it is still
    running after ``limit`` seconds (a writer then opens ``fifo`` so the blocked thread ends)."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["out"] = fn()
        except BaseException as exc:  # noqa: BLE001 - returned to the test
            box["out"] = exc

    t0 = time.perf_counter()
    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(limit)
    if th.is_alive():
        if fifo is not None:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))  # EOF for the blocked reader
        th.join(5)
        pytest.fail(f"still blocked after {limit:g} s (a FIFO or device was opened)")
    box["elapsed"] = time.perf_counter() - t0
    return box["out"]


@pytest.fixture
def fifo_dir(tmp_path: Path) -> Path:
    for name in ("x.h5", "x.csv", "x.npy", "x.npz", "x.bag", "x.mcap", "x.yaml", "x.json"):
        os.mkfifo(tmp_path / name)
    return tmp_path


@pytest.fixture
def no_limits() -> Any:
    yield
    limits.configure()


# ------------------------------------------------------------------ only regular files
@pytest.mark.parametrize("name", ["x.h5", "x.csv", "x.npy", "x.npz", "x.bag", "x.mcap"])
def test_every_loader_refuses_a_fifo_at_once(fifo_dir: Path, name: str) -> None:
    out = within(lambda: load_log(fifo_dir / name), fifo_dir / name)
    assert isinstance(out, LoadError), out
    msg = str(out)
    assert msg == f"'{fifo_dir / name}' is not a regular file (it is a FIFO (named pipe)): " + (
        "give the path of a file"
    )
    # the file as the user named it (a server passes what its user typed)
    assert "'~/x.h5' is not a regular file" in str(
        within(lambda: load_log(fifo_dir / name, name="~/x.h5"), fifo_dir / name)
    )


def test_streamed_datasheet_and_session_readers_refuse_a_fifo(fifo_dir: Path) -> None:
    for name in ("x.h5", "x.npy"):
        out = within(lambda n=name: open_series(fifo_dir / n), fifo_dir / name)
        assert isinstance(out, ValueError) and "not a regular file (it is a FIFO" in str(out)
        out = within(lambda n=name: wavelet_variance_stream(fifo_dir / n, fs=1.0))
        assert isinstance(out, ValueError) and "FIFO" in str(out)
    for name in ("x.yaml", "x.json"):
        out = within(lambda n=name: read_datasheet(fifo_dir / n), fifo_dir / name)
        assert isinstance(out, ValueError) and "not a regular file" in str(out), out
    out = within(lambda: load_session(fifo_dir / "x.json"), fifo_dir / "x.json")
    assert isinstance(out, ValueError) and "not a regular file" in str(out), out


def test_a_bag_folder_holds_regular_files_only(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    os.mkfifo(bag / "bag_0.db3")
    out = within(lambda: load_log(bag), bag / "bag_0.db3")
    assert isinstance(out, LoadError) and f"'{bag}/bag_0.db3' is not a regular file" in str(out)
    (bag / "bag_0.db3").unlink()
    (bag / "metadata.yaml").unlink()
    os.mkfifo(bag / "metadata.yaml")
    out = within(lambda: load_log(bag), bag / "metadata.yaml")
    assert isinstance(out, LoadError) and "metadata.yaml' is not a regular file" in str(out)


def test_other_kinds_are_named() -> None:
    out = within(lambda: load_log("/dev/null"))
    assert isinstance(out, LoadError) and "(it is a character device)" in str(out)
    assert files.file_kind(os.stat("/").st_mode) == "a directory"
    assert files.file_kind(os.stat(__file__).st_mode) == "a regular file"


@pytest.mark.parametrize("stream", [False, True])
def test_gmwm_wv_refuses_a_fifo_in_one_line(fifo_dir: Path, stream: bool) -> None:
    """The command as a user runs it (a process: a regression is killed by the timeout)."""
    for name in ("x.h5", "x.npy") if stream else ("x.h5", "x.csv", "x.npy"):
        cmd = [sys.executable, "-m", "engine.cli", "wv", str(fifo_dir / name)]
        r = subprocess.run(cmd + ["--stream"] * stream, capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stdout == "", r.stderr
        assert r.stderr == (
            f"gmwm: error: '{fifo_dir / name}' is not a regular file (it is a FIFO (named "
            "pipe)): give the path of a file\n"
        )


_DEV_ZERO = textwrap.dedent(
    """
    import json, sys
    from engine.io import load_log
    from engine.wv import open_series
    from engine.cli import main
    out = {}
    for name, fn in (("load_log", load_log), ("open_series", open_series)):
        try:
            fn("/dev/zero")
        except ValueError as exc:
            out[name] = str(exc)
    out["rc"] = main(["wv", "/dev/zero"])
    # the peak resident memory of this program (VmHWM starts anew at exec; ru_maxrss keeps the
    # forking parent's, a test runner of several hundred MB late in a run)
    hwm = next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
    out["maxrss_mb"] = int(hwm.split()[1]) / 1024
    print(json.dumps(out))
    """
)


def test_dev_zero_is_refused_without_reading_it() -> None:
    """Was: 450 MB/s of zeros read until a MemoryError. The child has a 4 GB address space, so
    a regression ends in a MemoryError there (and a failed test) instead of filling this
    machine."""

    r = run_capped(_DEV_ZERO, 4 << 30, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    refusal = (
        "'/dev/zero' is not a regular file (it is a character device): give the path of a file"
    )
    assert out["load_log"] == refusal and out["open_series"] == refusal
    assert out["rc"] == 2 and r.stderr == f"gmwm: error: {refusal}\n"
    # the imports (numpy, scipy, h5py) take about 100 MB; one read of /dev/zero's would be GBs
    assert out["maxrss_mb"] < 400, out


def test_app_path_source_refuses_a_fifo_and_keeps_working(
    app_state: AppState, fifo_dir: Path
) -> None:
    s = app_state
    for name in ("x.h5", "x.csv", "x.npy"):
        fifo = fifo_dir / name
        ok = within(lambda f=fifo: s.from_query({"source": "path", "path": str(f)}), fifo)
        assert ok is False
        assert f"'{fifo}' is not a regular file (it is a FIFO (named pipe))" in s.error
        assert "showing the demo instead" in s.error and s.log is not None
        assert within(lambda f=fifo: s.load_path(f), fifo) is False
        assert "not a regular file" in s.error and "\n" not in s.error
    assert s.add_process("WN"), s.error  # the session goes on


# ------------------------------------------------------------------ no content, no folders
_SECRETS = ("s3cr3t-hunter2", "root:x:0:0", "/root", "/bin/bash", "api_key", "AKIA0123")


def _passwd_like(tmp_path: Path) -> list[Path]:
    """Files that are not logs, whose every line is something a message must not show."""
    out = []
    for name, text in {
        "passwd": "root:x:0:0:root:/root:/bin/bash\nsvc:x:1:1:s3cr3t-hunter2:/srv:/bin/bash\n",
        "config.txt": "api_key = AKIA0123\npassword = s3cr3t-hunter2\n",
        "keys.csv": "api_key,password\nAKIA0123,s3cr3t-hunter2\n",
        "header.csv": "api_key;s3cr3t-hunter2\n",
        # a log whose bad cell is secret: the column name is shown, the cell is not
        "log.csv": "time,gyro_x\n0,0.1\n0.01,s3cr3t-hunter2\n0.02,0.3\n",
        "ragged.csv": "api_key,password,AKIA0123\n1,2\n",
    }.items():
        p = tmp_path / name
        p.write_text(text)
        out.append(p)
    return out


def test_loader_messages_quote_no_content(tmp_path: Path) -> None:
    for p in _passwd_like(tmp_path):
        with pytest.raises(LoadError) as exc:
            load_log(p)
        msg = str(exc.value)
        assert str(p) in msg and "line " in msg, msg
        assert not [s for s in _SECRETS if s in msg], msg
        if p.name == "log.csv":
            assert "line 3, column 2 of 2 ('gyro_x'): a value that is not a number" in msg
        if p.name == "passwd":
            assert "line 2, column 1 of 1: a value that is not a number" in msg


def test_app_path_source_quotes_no_content(
    app_state: AppState, tmp_path: Path, no_limits: None
) -> None:
    """The reported case: a server started in / lets ?source=path name any file under it."""
    limits.configure(data_dirs=[tmp_path])
    s = app_state
    for p in _passwd_like(tmp_path):
        assert not s.from_query({"source": "path", "path": str(p)})
        assert str(p) in s.error and not [x for x in _SECRETS if x in s.error], s.error


def test_refused_paths_list_no_folder(app_state: AppState, tmp_path: Path, no_limits: None) -> None:
    inside = tmp_path / "data"
    inside.mkdir()
    limits.configure(data_dirs=[inside, Path.home(), Path(np.__file__).parent])
    s = app_state
    for asked in ("/etc/passwd", "../../etc/shadow", str(tmp_path / "other.csv")):
        assert not s.from_query({"source": "path", "path": asked})
        assert f"'{asked}' is outside the folders this server may read" in s.error
        assert "upload the file instead" in s.error
        for folder in (str(inside), str(Path.home()), "site-packages", "numpy"):
            assert folder not in s.error, (folder, s.error)
    limits.configure()  # any path: a missing one is named as typed, ~ not expanded
    assert not s.from_query({"source": "path", "path": "~/no_such_log_1234.csv"})
    assert "no such file on the server: '~/no_such_log_1234.csv'" in s.error
    assert str(Path.home()) not in s.error


# ------------------------------------------------------------------ memory-aware refusal
def _peak(fn: Callable[[], Any]) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _refused_at(monkeypatch: pytest.MonkeyPatch, path: Path, need: int, **kw: Any) -> None:
    """The load is refused with ``need - 1`` bytes available and goes on with ``need``."""
    monkeypatch.setattr(_limits, "available_memory", lambda: need - 1)
    with pytest.raises(LoadError, match="is too large to load: it needs about") as exc:
        load_log(path, **kw)
    assert str(path) in str(exc.value) and "available: free memory" in str(exc.value)
    monkeypatch.setattr(_limits, "available_memory", lambda: need)
    assert load_log(path, **kw).n > 0


def test_npy_npz_hdf5_refused_from_shape_times_itemsize(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    n = 50_000
    rng = np.random.default_rng(1)
    a = rng.normal(size=(n, 3))
    np.save(tmp_path / "f8.npy", a)  # the array + contiguous copies of its 3 columns
    _refused_at(monkeypatch, tmp_path / "f8.npy", 2 * 24 * n, fs=100)
    counts = rng.integers(-500, 500, size=n).astype(np.int16)
    np.save(tmp_path / "i2.npy", counts)  # int16 + its float64 copy
    _refused_at(monkeypatch, tmp_path / "i2.npy", 2 * n + 8 * n, fs=100)
    np.savez(tmp_path / "z.npz", gyro_x=a[:, 0], gyro_y=counts, fs=np.float64(100))
    _refused_at(monkeypatch, tmp_path / "z.npz", 8 * n + (2 + 8) * n + 8)
    with h5py.File(tmp_path / "log.h5", "w") as f:
        f.attrs["fs_hz"] = 100.0
        f["time"] = np.arange(n) / 100.0
        for j, ch in enumerate(("gyro_x", "gyro_y", "gyro_z")):
            f[ch] = a[:, j]
    _refused_at(monkeypatch, tmp_path / "log.h5", 3 * 8 * n + 8 * n)
    _refused_at(monkeypatch, tmp_path / "log.h5", 8 * n + 8 * n, channel="gyro_y")


def test_array_estimates_bound_the_measured_peak(tmp_path: Path) -> None:
    """The estimate is the peak tracemalloc measures, within 10 %."""
    n = 200_000
    a = np.random.default_rng(2).normal(size=(n, 3)) * 100
    for dt in ("f8", "f4", "i2"):
        np.save(tmp_path / f"{dt}.npy", a.astype(dt))
        need = {"f8": 48, "f4": 24, "i2": 6 + 24}[dt] * n
        peak = _peak(lambda d=dt: load_log(tmp_path / f"{d}.npy", fs=100))
        assert 0.9 * peak <= need <= 1.1 * peak, (dt, peak, need)


@pytest.mark.parametrize(
    ("fmt", "delim", "k"),
    [("%.6f", ",", 7), ("%.4f", ",", 1), ("%d", ",", 12), ("%.6f", " ", 6), ("%.17g", "\t", 2)],
)
def test_text_estimate_bounds_the_measured_peak(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fmt: str, delim: str, k: int
) -> None:
    """Bytes, lines and values extrapolated from the first 64 KiB: the measured peak of
    reading 50 000 rows lies between 60 % and 100 % of the estimate."""
    rng = np.random.default_rng(3)
    x = rng.integers(0, 10, size=(50_000, k)) if fmt == "%d" else rng.normal(size=(50_000, k))
    p = tmp_path / "log.txt"
    np.savetxt(p, x, fmt=fmt, delimiter=delim)
    raw = p.read_bytes()
    need = text_memory_need(len(raw), raw[: 1 << 16])
    peak = _peak(lambda: load_log(p, fs=100))
    assert 0.6 * need <= peak <= need, (peak, need)
    _refused_at(monkeypatch, p, need, fs=100)


def test_too_large_in_the_cli_and_the_stream_still_works(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    x = np.random.default_rng(4).normal(size=20_000)
    np.save(tmp_path / "x.npy", x)
    monkeypatch.setattr(_limits, "available_memory", lambda: 100_000)  # 0.1 MB
    assert gmwm(["wv", str(tmp_path / "x.npy"), "--fs", "100"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs about 0.16 MB of memory" in err, err
    assert "0.1 MB are available" in err
    # streaming reads blocks: the same file in bounded memory, no refusal
    assert gmwm(["wv", str(tmp_path / "x.npy"), "--fs", "100", "--stream"]) == 0
    assert "Haar wavelet variance" in capsys.readouterr().out
