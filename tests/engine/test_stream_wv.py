"""Streaming WV of long logs: same numbers as in memory, bounded memory, NPY/HDF5/arrays."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import h5py
import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.wv import open_series, wavelet_variance_stream

TRUTH = "GM(beta=0.2, sigma2_gm=1e-4)+WN(sigma2=1e-2)+RW(gamma2=1e-9)"


@pytest.fixture(scope="module")
def signal() -> np.ndarray:
    """A long-ish log with a large offset (gravity-like) to stress the numerics."""
    return 9.81 + eg.parse_model(TRUTH).simulate(300_007, fs=100.0, rng=4)


@pytest.mark.parametrize("block", [1024, 4096, 1 << 15, 1 << 19])
def test_npy_matches_in_memory(tmp_path: Path, signal: np.ndarray, block: int) -> None:
    np.save(tmp_path / "x.npy", signal)
    ref = eg.wavelet_variance(signal, fs=100.0)
    got = wavelet_variance_stream(tmp_path / "x.npy", fs=100.0, block=block)
    assert got.n == ref.n and got.fs == 100.0 and got.n_levels == ref.n_levels == 18
    np.testing.assert_allclose(got.variance, ref.variance, rtol=1e-12)
    np.testing.assert_allclose(got.ci_low, ref.ci_low, rtol=1e-12)
    np.testing.assert_array_equal(got.n_coef, ref.n_coef)


@pytest.mark.parametrize("n", [4, 5, 1023, 1024, 1025, 2048, 2049, 3 * 1024, 8193])
def test_lengths_around_block_boundaries(n: int) -> None:
    x = np.random.default_rng(n).normal(size=n).cumsum()
    ref = eg.wavelet_variance(x)
    for levels in (None, 1):
        got = wavelet_variance_stream(x, block=1024, levels=levels)
        np.testing.assert_allclose(got.variance, ref.variance[: got.n_levels], rtol=1e-12)


def test_float32_int_counts_and_scale(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    counts = rng.integers(-3000, 3000, 50_000).astype(np.int16)
    np.save(tmp_path / "c.npy", counts)
    got = wavelet_variance_stream(tmp_path / "c.npy", scale=0.05, block=2048, fs=200.0)
    log = eg.load_log(tmp_path / "c.npy", scale=0.05, fs=200.0)
    ref = eg.wavelet_variance(log["x"], fs=200.0)
    np.testing.assert_allclose(got.variance, ref.variance, rtol=1e-12)
    x32 = rng.normal(size=40_000).astype(np.float32)
    np.save(tmp_path / "f.npy", x32)
    np.testing.assert_allclose(
        wavelet_variance_stream(tmp_path / "f.npy", block=1024).variance,
        eg.wavelet_variance(x32).variance,
        rtol=1e-12,
    )


@pytest.mark.parametrize("order", ["C", "F"])
def test_two_dimensional_npy_columns(tmp_path: Path, order: str, monkeypatch) -> None:
    from engine.wv.stream import _NpySource

    monkeypatch.setattr(_NpySource, "piece", 1000)  # rows read in many small pieces
    a = np.asarray(np.random.default_rng(1).normal(size=(20_000, 3)), order=order)
    np.save(tmp_path / "a.npy", a)
    for j in range(3):
        got = wavelet_variance_stream(tmp_path / "a.npy", column=j, block=1024)
        np.testing.assert_allclose(got.variance, eg.wavelet_variance(a[:, j]).variance, rtol=1e-12)
    with pytest.raises(ValueError, match="choose a column"):
        wavelet_variance_stream(tmp_path / "a.npy")
    with pytest.raises(ValueError, match="out of range"):
        wavelet_variance_stream(tmp_path / "a.npy", column=3)


def test_hdf5_dataset_attributes_and_objects(tmp_path: Path, signal: np.ndarray) -> None:
    p = eg.io.save_log(
        tmp_path / "s.h5", {"gyro_x": signal, "gyro_y": -signal}, 100.0, units={"gyro_x": "deg/s"}
    )
    got = wavelet_variance_stream(p, dataset="gyro_x", block=1 << 14)
    ref = eg.wavelet_variance(signal, fs=100.0)
    assert got.fs == 100.0 and got.unit == "deg/s"  # fs_hz and units from the file
    np.testing.assert_allclose(got.variance, ref.variance, rtol=1e-12)
    with h5py.File(p, "r") as f:  # an open h5py.Dataset works too
        got2 = wavelet_variance_stream(f["gyro_y"], fs=100.0, block=1 << 14)
    np.testing.assert_allclose(got2.variance, ref.variance, rtol=1e-12)
    with pytest.raises(ValueError, match="several datasets"):
        wavelet_variance_stream(p)
    with pytest.raises(ValueError, match="no dataset 'gyro_z'.*gyro_x"):
        wavelet_variance_stream(p, dataset="gyro_z")


def test_memmap_and_fit_on_streamed_wv(tmp_path: Path, signal: np.ndarray) -> None:
    np.save(tmp_path / "x.npy", signal)
    mm = np.load(tmp_path / "x.npy", mmap_mode="r")
    wv = wavelet_variance_stream(mm, fs=100.0, block=1 << 16)
    res = eg.fit_gmwm(wv, "GM+WN+RW")
    ref = eg.fit_gmwm(eg.wavelet_variance(signal, fs=100.0), "GM+WN+RW")
    for k, v in ref.params.items():
        assert res.params[k] == pytest.approx(v, rel=1e-6)


def test_errors(tmp_path: Path) -> None:
    x = np.ones(5000)
    x[3210] = np.nan
    with pytest.raises(ValueError, match="first at sample 3210"):
        wavelet_variance_stream(x, block=1024)
    with pytest.raises(ValueError, match="at least 4"):
        wavelet_variance_stream(np.ones(3))
    with pytest.raises(ValueError, match="power of two"):
        wavelet_variance_stream(np.ones(100), block=1000)
    with pytest.raises(ValueError, match="levels=9 is out of range"):
        wavelet_variance_stream(np.arange(300.0), levels=9)
    with pytest.raises(ValueError, match="overflow"):
        wavelet_variance_stream(np.full(3000, 1e308), block=1024)
    (tmp_path / "t.csv").write_text("1,2\n")
    with pytest.raises(ValueError, match="npy and HDF5"):
        wavelet_variance_stream(tmp_path / "t.csv")
    with pytest.raises(ValueError, match="no such file"):
        wavelet_variance_stream(tmp_path / "missing.npy")
    np.save(tmp_path / "c.npy", np.ones(10, complex))
    with pytest.raises(ValueError, match="complex"):
        wavelet_variance_stream(tmp_path / "c.npy")


def test_memory_is_bounded_by_the_block(tmp_path: Path) -> None:
    """Allocations stay O(block x streams) (6 streams of 0.25 MB here), far below the 8 MB of
    data; the 1e8-sample resident-memory figure is in tests/benchmarks/bench_stream.py."""
    n = 1 << 20
    np.save(tmp_path / "big.npy", np.random.default_rng(0).normal(size=n))
    tracemalloc.start()
    wv = wavelet_variance_stream(tmp_path / "big.npy", block=1 << 14)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert wv.n_levels == 19
    assert peak < 3e6, f"peak traced allocation {peak / 1e6:.1f} MB"
    src = open_series(tmp_path / "big.npy")
    assert src.n == n
    src.close()


def test_progress_callback(tmp_path: Path) -> None:
    calls: list[tuple[int, int]] = []
    wavelet_variance_stream(
        np.random.default_rng(0).normal(size=10_000),
        block=1024,
        progress=lambda d, t: calls.append((d, t)),
    )
    assert calls and all(d <= t for d, t in calls) and calls[-1][0] == calls[-1][1]
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_cli_stream(tmp_path: Path, signal: np.ndarray, capsys) -> None:
    p = eg.io.save_log(tmp_path / "s.h5", {"gyro_x": signal}, 100.0, units={"gyro_x": "deg/s"})
    assert main(["wv", str(p), "--json"]) == 0
    ref = json.loads(capsys.readouterr().out)
    assert main(["wv", str(p), "--stream", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["channel"] == "gyro_x" and got["fs"] == 100.0
    np.testing.assert_allclose(got["variance"], ref["variance"], rtol=1e-12)
    assert main(["fit", str(p), "--stream", "--model", "WN+RW", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["n"] == signal.size
    assert main(["wv", str(p), "--stream", "--robust"]) == 2
    assert "classical" in capsys.readouterr().err
    np.save(tmp_path / "a.npy", np.column_stack([signal, signal]))
    assert (
        main(["wv", str(tmp_path / "a.npy"), "--stream", "--channel", "1", "--fs", "100", "--json"])
        == 0
    )
    got = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(got["variance"], ref["variance"], rtol=1e-12)


# ----------------------------------------------------------------------------- loader: dtypes
def test_float32_logs_stay_float32(tmp_path: Path) -> None:
    x = np.random.default_rng(2).normal(size=5000).astype(np.float32)
    np.save(tmp_path / "f.npy", x)
    log = eg.load_log(tmp_path / "f.npy", fs=100.0)
    assert log["x"].dtype == np.float32
    np.testing.assert_array_equal(log["x"], x)
    # the WV is computed in float64 from the float32 samples: the same as from a float64 copy
    np.testing.assert_array_equal(
        eg.wavelet_variance(log["x"]).variance, eg.wavelet_variance(x.astype(np.float64)).variance
    )


def test_integer_counts_with_scale_are_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    counts = {
        "gyro_x": rng.integers(-32768, 32767, 4000).astype(np.int16),
        "accel_z": rng.integers(-(2**31), 2**31 - 1, 4000).astype(np.int32),
    }
    p = eg.io.save_log(tmp_path / "c.h5", counts, 200.0)
    log = eg.load_log(p, scale=0.05)
    for k, c in counts.items():
        assert log[k].dtype == np.float64
        np.testing.assert_array_equal(log[k], c.astype(np.float64) * 0.05)  # one rounding
    assert log.meta["scale"] == {"gyro_x": 0.05, "accel_z": 0.05}
    log = eg.load_log(p, scale={"gyro_x": 0.05}, units={"gyro_x": "deg/s"})
    np.testing.assert_array_equal(log["accel_z"], counts["accel_z"].astype(np.float64))
    assert log.units == {"gyro_x": "deg/s", "accel_z": ""}
    assert eg.load_log(p, units="g").units == {"gyro_x": "g", "accel_z": "g"}
    csvp = tmp_path / "c.csv"
    csvp.write_text("gyro_x\n" + "\n".join(str(int(v)) for v in counts["gyro_x"]))
    np.testing.assert_array_equal(
        eg.load_log(csvp, scale=0.05)["gyro_x"], counts["gyro_x"].astype(np.float64) * 0.05
    )
    for bad, frag in (
        (0, "not a valid scale"),
        (float("nan"), "not a valid scale"),
        ("x", "not a valid scale"),
        ({"mag": 1.0}, "unknown channel"),
    ):
        with pytest.raises(eg.LoadError, match=frag):
            eg.load_log(p, scale=bad)
    with pytest.raises(eg.LoadError, match="unknown channel"):
        eg.load_log(p, units={"mag": "g"})
    with pytest.raises(eg.LoadError, match="overflow"):
        eg.load_log(p, scale=1e308)
    np.save(tmp_path / "huge.npy", np.full(100, 1e200))
    with pytest.raises(eg.LoadError, match="too large for a variance"):
        eg.load_log(tmp_path / "huge.npy")
