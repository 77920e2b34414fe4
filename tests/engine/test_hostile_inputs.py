"""Hostile files: each bound of the loaders proved on a small generated file.

Before: a 1.5 KB HDF5 of one-sample chunks took 3.85 GB; a 1.5 KB HDF5 declaring 16 GB and a
1.24 MB ``.npz`` inflating to 1.26 GB passed the memory check; a CSV of 1e5 columns took 63 s
(quadratic name handling) and a (1e6, 1e6) HDF5 dataset gave no answer in 60 s; a 2 GB sparse
``.csv`` was read whole (37 s, 4.1 GB) before "not a text file"; every load could count on all
of ``MemAvailable``. The scales here prove each bound without gigabytes; measured figures are
in docs/cli-safety.md.
"""

from __future__ import annotations

import csv
import os
import resource
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import h5py
import numpy as np
import pytest

import engine._limits as _limits
from engine._text import spreadsheet_safe
from engine.cli import main
from engine.io import LoadError, load_log
from engine.io._assemble import MAX_CHANNELS, ordered_names
from engine.io.hdf5 import H5_MAX_CHUNKS

ROOT = Path(__file__).resolve().parents[2]


def _unwritten_h5(path: Path, n: int, chunks: tuple[int, ...] | None = (65536,), **kw) -> Path:
    """An HDF5 file with one dataset of ``n`` float64 samples, none written (fill values)."""
    with h5py.File(path, "w") as f:
        f.attrs["fs_hz"] = 100.0
        f.create_dataset("gyro_x", shape=(n, *kw.get("extra", ())), dtype="f8", chunks=chunks)
    return path


def _timed(fn):  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    try:
        out = fn()
    except LoadError as exc:
        out = exc
    return out, time.perf_counter() - t0


# ------------------------------------------------------------------- declared-size bombs
def test_hdf5_declaring_gigabytes_of_fill_values_is_refused(tmp_path: Path) -> None:
    """32e6 unwritten samples (256 MB declared) in a file of a few KB: over 256 times its
    stored size, refused from the declaration (before: read, 256 MB of zeros)."""
    p = _unwritten_h5(tmp_path / "bomb.h5", 32_000_000)
    assert p.stat().st_size < 10_000
    err, dt = _timed(lambda: load_log(p))
    assert isinstance(err, LoadError), "the declared 256 MB were read"
    msg = str(err)
    assert "bomb.h5" in msg and "declares far more data than it holds" in msg
    assert "(1 dataset column(s) of 32000000 samples) from 0 bytes on disk" in msg and dt < 2.0
    # 16 GB declared (a reported file): the same refusal, as fast
    p16 = _unwritten_h5(tmp_path / "bomb16.h5", 2_000_000_000)
    err, dt = _timed(lambda: load_log(p16))
    assert isinstance(err, LoadError) and "16 GB" in str(err) and dt < 2.0


def _npz_bomb(path: Path, n: int) -> Path:
    """A ``.npz`` whose one array holds ``n`` float64 zeros, written in 1 MB pieces (the test
    never holds the array)."""
    header = {"descr": "<f8", "fortran_order": False, "shape": (n,)}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        with z.open("gyro_x.npy", "w", force_zip64=True) as m:
            np.lib.format.write_array_header_1_0(m, header)
            block = bytes(1 << 20)
            left = 8 * n
            while left:
                m.write(block[: min(left, len(block))])
                left -= min(left, len(block))
    return path


def test_npz_that_inflates_a_thousand_times_is_refused(tmp_path: Path) -> None:
    """256 MB of zeros deflate to about 250 KB: refused by the estimate, nothing inflated
    (before: loaded, 256 MB; a reported 1.24 MB file inflated to 1.26 GB)."""
    p = _npz_bomb(tmp_path / "bomb.npz", 32_000_000)
    assert p.stat().st_size < 1_000_000
    err, dt = _timed(lambda: load_log(p, fs=100))
    assert isinstance(err, LoadError), "the archive was inflated"
    assert "declares far more data than it holds" in str(err) and dt < 2.0


def test_small_constant_files_are_not_bombs(tmp_path: Path) -> None:
    """Below the 64 MB floor a well-compressed file loads (4e6 zeros: 32 MB from 32 KB)."""
    p = _npz_bomb(tmp_path / "zeros.npz", 4_000_000)
    assert p.stat().st_size * _limits.MAX_EXPANSION < 32_000_000
    assert load_log(p, fs=100).n == 4_000_000


@pytest.mark.real_data
def test_real_logs_are_far_from_the_expansion_bound(real_data: Path) -> None:
    """The shared logs (gzip, 65536-sample chunks) expand about 10 times: they load."""
    p = real_data / "adis16405_imu1.h5"
    log = load_log(p)
    ratio = 8 * log.n * len(log.names) / p.stat().st_size
    assert 5 < ratio < 20 and log.n == 1_000_000 and len(log.names) == 6


# ------------------------------------------------------------------- HDF5 chunks
_RSS = """
import resource, sys, time
import engine as eg
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
log = eg.load_log(sys.argv[1])
dt = time.perf_counter() - t0
print(log.n, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) * 1024, dt)
"""


def test_one_sample_chunks_are_read_in_bounded_memory(tmp_path: Path) -> None:
    """1e5 unwritten one-sample chunks: the library's chunk map is built 1024 chunks at a
    time. Peak resident growth of the load, measured in a fresh process: before 380 MB (3.8 KB
    a chunk, all at once); now under 60 MB (the samples: 0.8 MB)."""
    p = _unwritten_h5(tmp_path / "c1.h5", 100_000, chunks=(1,))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", _RSS, str(p)], capture_output=True, text=True, env=env, timeout=120
    )
    assert out.returncode == 0, out.stderr
    n, grown, _ = out.stdout.split()
    assert int(n) == 100_000
    assert int(grown) < 60e6, f"load grew the process by {int(grown) / 1e6:.0f} MB"


def test_a_million_one_sample_chunks_are_refused(tmp_path: Path) -> None:
    p = _unwritten_h5(tmp_path / "c1.h5", 1_000_000, chunks=(1,))
    err, dt = _timed(lambda: load_log(p))
    assert isinstance(err, LoadError) and dt < 2.0
    assert f"1000000 chunks of 1 sample(s), more than {H5_MAX_CHUNKS} chunks" in str(err)
    assert "h5repack" in str(err)


# ------------------------------------------------------------------- names in linear time
def test_a_huge_2d_dataset_is_refused_at_once(tmp_path: Path) -> None:
    """(1e6, 1e6) float64 declared in a 2 KB file (before: no answer in 60 s)."""
    p = tmp_path / "square.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("imu", shape=(1_000_000, 1_000_000), dtype="f8", chunks=(1000, 1000))
    err, dt = _timed(lambda: load_log(p, fs=100))
    assert isinstance(err, LoadError) and dt < 2.0
    assert f"more than the {MAX_CHANNELS} channels a log may have" in str(err)


def _wide_csv(path: Path, k: int, rows: int = 5) -> Path:
    head = ",".join(f"c{j}" for j in range(k))
    row = ",".join(["0.5"] * k)
    path.write_text(head + "\n" + "\n".join([row] * rows) + "\n")
    return path


def test_a_csv_of_1e5_columns_is_refused_at_its_header(tmp_path: Path) -> None:
    """1.1 MB of header and 5 rows (before: 63 s of quadratic name checks)."""
    p = _wide_csv(tmp_path / "wide.csv", 100_000)
    err, dt = _timed(lambda: load_log(p, fs=100))
    assert isinstance(err, LoadError) and dt < 3.0, dt
    assert "has 100000 columns, more than the 10000 channels" in str(err)


def test_one_channel_of_a_csv_of_1e5_columns_in_seconds(tmp_path: Path) -> None:
    """With channel= the file is parsed (5 rows x 1e5 values) and one channel kept; the
    header's duplicate check is a set look-up (before: 5e9 string comparisons)."""
    p = _wide_csv(tmp_path / "wide.csv", 100_000)
    (log, dt) = _timed(lambda: load_log(p, fs=100, channel="c99999"))
    assert not isinstance(log, Exception), log
    assert log.names == ["c99999"] and log.n == 5 and dt < 10.0, dt


def test_ordered_names_is_linear() -> None:
    """3e4 names and a units map of 3e4: a few ms (before: 9e8 list comparisons, ~10 s)."""
    names = [f"n{j}" for j in range(30_000)]
    units = {f"n{j}": "" for j in range(29_999, -1, -1)}
    t0 = time.perf_counter()
    out = ordered_names(names, units)
    assert time.perf_counter() - t0 < 0.5
    assert out == list(units) and len(out) == 30_000
    assert ordered_names(["b", "a", "c"], {"c": "", "x": "", "a": ""}) == ["c", "a", "b"]


# ------------------------------------------------------------------- sparse text
def test_a_sparse_csv_is_refused_from_its_first_block(tmp_path: Path) -> None:
    """2 GB of holes named .csv: refused from its first 64 KiB in well under a second, in
    bounded memory (before: 37 s and 4.1 GB); a header followed by holes is refused at the
    first 16 MB block with a NUL byte."""
    p = tmp_path / "sparse.csv"
    with open(p, "wb") as f:
        f.truncate(2 * 10**9)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    err, dt = _timed(lambda: load_log(p, fs=100))
    assert isinstance(err, LoadError) and "is not a text file" in str(err)
    assert dt < 1.0 and resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 100_000
    q = tmp_path / "late.csv"
    with open(q, "wb") as f:
        f.write(b"gyro_x\n" + b"0.5\n" * 20_000)
        f.truncate(200 * 10**6)
    err, dt = _timed(lambda: load_log(q, fs=100))
    assert isinstance(err, LoadError) and "is not a text file" in str(err) and dt < 2.0


# ------------------------------------------------------------------- one shared budget
def test_loads_share_one_budget(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A load reserves its estimate until it ends: a second load that would fit alone is
    refused while the first holds its share, and accepted once it has ended."""
    p = tmp_path / "x.npy"
    np.save(p, np.random.default_rng(0).normal(size=100_000))  # needs 800 kB
    monkeypatch.setattr(_limits, "available_memory", lambda: 10**9)
    _limits.set_load_budget(1_200_000)
    try:
        assert load_log(p, fs=100).n == 100_000  # alone: fits
        held, release = threading.Event(), threading.Event()

        def other_load() -> None:  # another session's load, in progress
            with _limits.load_scope():
                _limits.check_memory(800_000, "other.h5")
                held.set()
                release.wait(10)

        th = threading.Thread(target=other_load)
        th.start()
        assert held.wait(10) and _limits.reserved_memory() == 800_000
        with pytest.raises(
            LoadError, match=r"the 1.2 MB load budget of this process has 0.4 MB free \(0.8 MB held"
        ):
            load_log(p, fs=100)
        release.set()
        th.join(10)
        assert _limits.reserved_memory() == 0
        assert load_log(p, fs=100).n == 100_000
    finally:
        _limits.set_load_budget(None)
    assert _limits.load_budget() is None


def test_reservations_subtract_from_the_available_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_limits, "available_memory", lambda: 1_000_000)
    with _limits.load_scope():
        _limits.check_memory(700_000, "a.csv")
        with pytest.raises(
            ValueError, match=r"0.3 MB are available besides the 0.7 MB held by loads in progress"
        ):
            _limits.check_memory(400_000, "b.csv")  # alone it would fit
    _limits.check_memory(400_000, "b.csv")
    assert _limits.reserved_memory() == 0


def test_budget_is_checked() -> None:
    for bad in (0, -5, True):
        with pytest.raises(ValueError, match="positive number of bytes"):
            _limits.set_load_budget(bad)  # type: ignore[arg-type]


# ------------------------------------------------------------------- names and options
HOSTILE_NAMES = ("=cmd|' /C calc'!A0", "\x1b]0;pwned\x07gx")


def _hostile_csv(path: Path) -> Path:
    t = np.arange(3000) / 100
    rng = np.random.default_rng(5)
    lines = [f"time,{HOSTILE_NAMES[0]},{HOSTILE_NAMES[1]}"]
    lines += [
        f"{a},{b},{c}"
        for a, b, c in zip(t, rng.normal(size=3000), rng.normal(size=3000), strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_formula_names_are_text_in_every_csv_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A channel named ``=cmd|...`` becomes ``'=cmd|...`` in the export CSVs, the fleet
    summary and a simulated CSV's header (before: written raw, a formula to a spreadsheet)."""
    src = _hostile_csv(tmp_path / "inj.csv")
    for fmt in ("datasheet-csv", "csv"):
        out = tmp_path / f"{fmt}.csv"
        assert main(["export", str(src), "--model", "WN", "--format", fmt, "-o", str(out)]) == 0
        cells = [row[0] for row in csv.reader(out.read_text().splitlines()[1:])]
        assert any(c.startswith("'=cmd|") for c in cells), fmt
        assert not any(c.startswith(("=", "+", "@")) for c in cells), fmt
    assert main(["batch", str(src), "--model", "WN", "-o", str(tmp_path / "b")]) == 0
    cells = [r[0] for r in csv.reader((tmp_path / "b" / "summary.csv").read_text().splitlines())]
    assert "'=cmd|' /C calc'!A0" in cells and not any(c.startswith("=") for c in cells)
    sim = tmp_path / "sim.csv"
    argv = ["simulate", "--model", "WN(1)", "-n", "100", "--channel", "=1+1", "-o", str(sim)]
    assert main(argv) == 0
    assert sim.read_text().splitlines()[0] == "time,'=1+1"
    capsys.readouterr()


def test_spreadsheet_safe_keeps_numbers() -> None:
    assert spreadsheet_safe("-1.5e-3") == "-1.5e-3" and spreadsheet_safe("+7") == "+7"
    assert spreadsheet_safe("@SUM(A1)") == "'@SUM(A1)" and spreadsheet_safe("-x") == "'-x"
    assert spreadsheet_safe("\uff1dcmd") == "'\uff1dcmd" and spreadsheet_safe("") == ""


def test_terminal_escapes_in_names_are_never_printed_raw(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Errors, tables and batch lines show ``\\x1b`` as text (before: the ESC byte itself)."""
    src = _hostile_csv(tmp_path / "inj.csv")
    assert main(["fit", str(src), "--model", "WN", "--channel", "nope"]) == 2
    assert main(["wv", str(src), "--channel", "1"]) == 0
    assert main(["batch", str(src), "--model", "WN", "-o", str(tmp_path / "b")]) == 0
    out, err = capsys.readouterr()
    assert "\x1b" not in out + err and "\x07" not in out + err
    assert "\\x1b]0;pwned\\x07gx" in err  # named, escaped, in the error


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["wv", "LOG", "--fs", "1e308"],
            "outside the range of a sampling frequency (1e-09 to 1e+09 Hz)",
        ),
        (["wv", "LOG", "--fs", "1e-300"], "outside the range of a sampling frequency"),
        (
            [
                "export",
                "LOG",
                "--model",
                "WN",
                "--ci",
                "bootstrap",
                "-B",
                "1e11",
                "--format",
                "json",
                "-o",
                "OUT",
            ],
            "-B 1e11: must be from 2 to 100000 bootstrap replicates",
        ),
        (
            [
                "export",
                "LOG",
                "--model",
                "WN",
                "--ci",
                "bootstrap",
                "-B",
                "100000000000",
                "--format",
                "json",
                "-o",
                "OUT",
            ],
            "must be from 2 to 100000 bootstrap replicates",
        ),
    ],
)
def test_absurd_fs_and_replicates_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    """``--fs 1e308`` and ``-B 1e11`` (before: accepted) are one-line usage errors, in under
    a second, before anything is read."""
    src = _hostile_csv(tmp_path / "x.csv")
    argv = [str(src) if a == "LOG" else str(tmp_path / "o.json") if a == "OUT" else a for a in argv]
    t0 = time.perf_counter()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert time.perf_counter() - t0 < 1.0 and not (tmp_path / "o.json").exists()


def test_engine_owns_the_bounds() -> None:
    import engine as eg
    from engine._limits import MAX_REPLICATES, check_replicates

    with pytest.raises(ValueError, match="outside the range of a sampling frequency"):
        eg.wavelet_variance(np.ones(64), fs=1e308)
    assert check_replicates(MAX_REPLICATES) == MAX_REPLICATES
    with pytest.raises(ValueError, match="B must be from 2 to 100000"):
        check_replicates(10**11)
