"""Uploads bounded while they arrive, and parsed without copies beyond about twice their size.

The chunks of an upload are fed to :class:`gmwm_app.upload.BoundedFileDropper` as the browser
sends them (Panel's ``upload_event``, ``chunk_size`` bytes each). A file announced larger than
the limit is refused at its first chunk, a client that lies about its size at the chunk that
crosses the limit; the page shows the message and the session keeps its data. The memory
test follows an upload from its first chunk to the parsed log with tracemalloc (Python's
allocations, numpy's included): before, a CSV peaked at 6.4x its size (chunks, their join,
a str decode, an encode back, the whole text and a list of its lines) and an HDF5 file at 3x.
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import h5py
import numpy as np
import pytest

from gmwm_app import limits
from gmwm_app.data import read_source
from gmwm_app.upload import BoundedFileDropper, browser_size_limit

#: Peak memory of an upload, from its first chunk to the parsed log, per byte of the file.
MAX_PEAK_RATIO = 2.5


@pytest.fixture
def limit_mb() -> Iterator[Any]:
    """Configure an upload limit (MB) for the test; restores the default after."""
    old = limits.current()

    def set_limit(mb: float) -> None:
        limits.configure(max_upload_mb=mb)

    yield set_limit
    limits.configure(
        max_upload_mb=old.max_upload_mb,
        data_dirs=old.data_dirs,
        allowed_files=old.allowed_files,
    )


def _event(name: str, chunk: int, total: int, data: bytes, kind: str = "text/csv") -> Any:
    return SimpleNamespace(
        event_name="upload_event",
        data={"name": name, "chunk": chunk, "total_chunks": total, "type": kind, "data": data},
    )


def _send(w: BoundedFileDropper, name: str, content: bytes, total: int | None = None) -> None:
    """Send ``content`` as the browser does (``total`` overrides the announced chunk count)."""
    cs = w.chunk_size
    n_chunks = -(-(len(content) + 1) // cs)  # the browser's count (+1: empty files)
    total = n_chunks if total is None else total
    for i in range(n_chunks):
        w._process_event(_event(name, i + 1, total, content[i * cs : (i + 1) * cs]))


def test_upload_round_trip_bytes_not_str(limit_mb: Any) -> None:
    limit_mb(1.0)
    w = BoundedFileDropper(chunk_size=1000)
    assert w.max_file_size == browser_size_limit(1_000_000) == "1000KB"  # the browser's check
    content = ("time,gyro_x\n" + "".join(f"{i / 100},{i % 7}\n" for i in range(5000))).encode()
    assert 30_000 < len(content) < 1_000_000  # 39 chunks
    _send(w, "log.csv", content)
    assert w.value == {"log.csv": content} and type(w.value["log.csv"]) is bytes
    assert w.mime_type == {"log.csv": "text/csv"} and w.refused == "" and w.held_bytes() == 0


def test_upload_refused_at_first_chunk_when_announced_too_large(limit_mb: Any) -> None:
    limit_mb(0.01)  # 10 kB
    w = BoundedFileDropper(chunk_size=1000)
    w._process_event(_event("big.csv", 1, 12, b"x" * 1000))  # 11 full chunks announced: > 10 kB
    assert "big.csv is over 0.011 MB" in w.refused and "(0.01 MB)" in w.refused
    assert "--max-upload-mb" in w.refused and w.held_bytes() == 0
    for k in range(2, 13):  # the rest of the refused upload is dropped as it arrives
        w._process_event(_event("big.csv", k, 12, b"x" * 1000))
        assert w.held_bytes() == 0
    assert w.value == {}


def test_upload_refused_when_a_client_lies_about_its_size(limit_mb: Any) -> None:
    limit_mb(0.01)
    # a client announcing 2 chunks, then sending chunk numbers below the total forever
    w2 = BoundedFileDropper(chunk_size=1000)
    for k in range(1, 40):
        w2._process_event(_event("slow.csv", k, k + 1, b"2" * 1000))  # never the last
        assert w2.held_bytes() <= 10_000
    assert "slow.csv is over" in w2.refused
    # two names at once share the limit
    w3 = BoundedFileDropper(chunk_size=1000)
    for k in range(1, 8):
        w3._process_event(_event("a.csv", k, 100, b"a" * 1000))
        w3._process_event(_event("b.csv", k, 100, b"b" * 1000))
        assert w3.held_bytes() <= 10_000
    assert w3.refused


def test_page_shows_the_refusal_and_keeps_its_data(app: Any, limit_mb: Any) -> None:
    s = app.state
    before = (s.filename, s.n, s.channel)
    limit_mb(0.01)
    app.upload._process_event(_event("huge.csv", 1, 10**4, b"0" * app.upload.chunk_size))
    assert "huge.csv is over" in s.error and "more than this server accepts" in s.error
    assert (s.filename, s.n, s.channel) == before and app.upload.refused == ""
    # the same refusal again is shown again; then a good upload still works
    s.error = ""
    app.upload._process_event(_event("huge.csv", 1, 10**4, b"0" * app.upload.chunk_size))
    assert "huge.csv is over" in s.error


def _csv(path: Path, n: int) -> Path:
    """A CSV as the project's own writer makes it (engine.io.save: %.17g, a time column)."""
    rng = np.random.default_rng(7)
    t = np.arange(n) / 100.0
    with open(path, "w") as f:
        f.write("time [s],gyro_x [deg/s],gyro_y [deg/s],gyro_z [deg/s]\n")
        np.savetxt(f, np.column_stack([t, rng.normal(0, 0.01, (n, 3))]), fmt="%.17g", delimiter=",")
    return path


def _h5(path: Path, n: int) -> Path:
    rng = np.random.default_rng(8)
    with h5py.File(path, "w") as f:
        for c in ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"):
            f.create_dataset(c, data=rng.normal(0, 0.01, n)).attrs["units"] = "deg/s"
        f.attrs["fs_hz"] = 100.0
    return path


@pytest.mark.parametrize(("kind", "n"), [("csv", 260_000), ("h5", 450_000)])
def test_upload_peak_memory_about_twice_the_file(
    tmp_path: Path, kind: str, n: int, limit_mb: Any
) -> None:
    f = _csv(tmp_path / "log.csv", n) if kind == "csv" else _h5(tmp_path / "log.h5", n)
    size = f.stat().st_size
    assert 20e6 < size < 40e6, size
    limit_mb(100.0)
    w = BoundedFileDropper()  # 8 MB chunks, as served
    got: dict[str, Any] = {}
    w.param.watch(lambda e: got.update(e.new), "value")
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        with open(f, "rb") as fh:  # the chunks as they arrive (one in memory at a time)
            cs, total = w.chunk_size, -(-(size + 1) // w.chunk_size)
            for i in range(total):
                w._process_event(_event(f.name, i + 1, total, fh.read(cs), "text/csv"))
        data = got.pop(f.name)
        w.value = {}
        loaded = read_source("upload", data=data, filename=f.name)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert loaded.log.n == n and loaded.log.fs == pytest.approx(100.0)
    ratio = peak / size
    print(f"{kind}: {size / 1e6:.1f} MB, peak {peak / 1e6:.1f} MB = {ratio:.2f}x")
    assert ratio < MAX_PEAK_RATIO, f"{kind}: peak {ratio:.2f}x the file size"
    # the values are the file's (the round trip through chunks and parsing)
    ref = np.loadtxt(f, delimiter=",", skiprows=1) if kind == "csv" else None
    if ref is not None:
        np.testing.assert_array_equal(loaded.log.channels["gyro_y"], ref[:, 2])
    else:
        with h5py.File(f) as h:
            np.testing.assert_array_equal(loaded.log.channels["accel_z"], h["accel_z"][:])
