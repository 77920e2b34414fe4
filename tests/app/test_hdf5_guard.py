"""The app's HDF5 watchdog (gmwm_app/hdf5_guard.py): a file that hangs the HDF5 C library is
refused within the time limit, in a helper process, and the server process stays free."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import h5py
import pytest

from engine.demo import demo_path
from gmwm_app import hdf5_guard as guard
from gmwm_app.data import read_source

DAMAGED = Path(__file__).resolve().parents[1] / "fixtures" / "damaged_heap.h5"


@pytest.fixture(autouse=True)
def fresh_helper():
    yield
    guard.stop_helper()


def test_is_hdf5_by_signature_or_name() -> None:
    head = demo_path().read_bytes()[:2056]
    assert guard.is_hdf5(head) and guard.is_hdf5(b"x" * 512 + guard.HDF5_MAGIC)
    assert guard.is_hdf5(b"time,gyro_x\n", "log.H5")
    assert not guard.is_hdf5(b"time,gyro_x\n1,2\n", "log.csv")


def test_a_valid_file_passes_and_the_helper_is_kept() -> None:
    guard.check_hdf5(str(demo_path()), "demo_imu.h5")  # starts the helper
    proc = guard._HELPER["proc"]
    t0 = time.perf_counter()
    guard.check_hdf5(demo_path().read_bytes(), "upload.h5")  # content, same helper
    assert time.perf_counter() - t0 < 2.0 and guard._HELPER["proc"] is proc
    # 200000 x 6 samples in the demo, its datasets and attributes: the walk counts them
    assert guard.walk_hdf5(str(demo_path())) >= 7


def test_other_read_errors_are_left_to_the_loader() -> None:
    guard.check_hdf5(b"not hdf5 at all", "fake.h5")  # no exception: the loader explains
    with pytest.raises(ValueError, match="fake.h5"):
        read_source("upload", data=b"time,gyro_x\nnot hdf5\n", filename="fake.h5")


def test_a_read_that_never_returns_is_refused_and_the_helper_replaced(tmp_path) -> None:
    """A FIFO named like an HDF5 file: opening it blocks in C (no writer), whatever the HDF5
    version, so the time limit is what ends the check."""
    fifo = tmp_path / "stuck.h5"
    os.mkfifo(fifo)
    guard.start_helper()
    stuck = guard._HELPER["proc"]
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"file 'stuck.h5' could not be read: .* in 2 s"):
        guard.check_hdf5(str(fifo), "stuck.h5", timeout=2.0)
    assert 2.0 <= time.perf_counter() - t0 < 6.0
    assert not stuck.is_alive() and "proc" not in guard._HELPER
    guard.check_hdf5(str(demo_path()), "demo_imu.h5")  # a new helper serves the next file
    assert guard._HELPER["proc"] is not stuck


def test_a_file_that_hangs_the_hdf5_library_is_refused_in_time(monkeypatch) -> None:
    """The damaged file hangs HDF5 2.0 (tests/fixtures/README.md): there the watchdog must be
    what refuses it; with another HDF5 the load must still end promptly with a clear
    message."""
    monkeypatch.setattr(guard, "TIMEOUT_S", 3.0)
    beats: list[float] = []
    stop = threading.Event()

    def heartbeat() -> None:  # this process keeps running Python while the helper hangs
        while not stop.is_set():
            beats.append(time.perf_counter())
            time.sleep(0.05)

    hb = threading.Thread(target=heartbeat, daemon=True)
    hb.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(ValueError) as err:
            read_source("upload", data=DAMAGED.read_bytes(), filename="damaged_heap.h5")
    finally:
        stop.set()
        hb.join()
    elapsed = time.perf_counter() - t0
    msg = str(err.value)
    assert "damaged_heap.h5" in msg
    assert elapsed < 3.0 + 5.0
    if h5py.version.hdf5_version.startswith("2.0."):  # the version known to hang on it
        assert "did not finish" in msg
    if "did not finish" in msg:  # the helper hung and was replaced
        assert "in 3 s" in msg and "probably damaged" in msg
        assert "proc" not in guard._HELPER
        gaps = [b - a for a, b in zip(beats, beats[1:], strict=False)]
        assert max(gaps) < 1.0, "this process was held while the helper hung"
    # the next file loads (a new helper), under the default limit: the 3 s above is for the
    # damaged file; a freshly spawned helper (an interpreter importing h5py) took longer than
    # that to read the demo at load 20 (two test workers on the shared machine)
    monkeypatch.undo()
    out = read_source("path", path=str(demo_path()))
    assert out.log.n == 200000
