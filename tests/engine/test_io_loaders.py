"""Tests of engine.io: loaders for text/NPY/NPZ/HDF5 logs and WV summaries, and save_log."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from engine.io import ImuLog, LoadError, load_log, save_log
from engine.wv import WaveletVariance

ADIS = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]


@pytest.fixture(scope="module")
def data(real_data: Path) -> Path:
    """The real-data folder (conftest: skipped without it, a failure when CI requires it)."""
    return real_data


def raises(path: Path | str, *fragments: str, **kw: object) -> str:
    """load_log(path, **kw) must raise LoadError naming the file and every fragment."""
    with pytest.raises(LoadError) as exc:
        load_log(path, **kw)
    msg = str(exc.value)
    for frag in (Path(path).name, *fragments):
        assert frag in msg, f"{frag!r} not in {msg!r}"
    return msg


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def rng_channels(n: int = 1000, seed: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"gyro_x": rng.normal(0.3, 0.05, n), "accel_z": rng.normal(-1.0, 1e-3, n)}


# ----------------------------------------------------------------------------- real data
def test_adis_raw_log(data: Path) -> None:
    log = load_log(data / "adis16405_imu1.h5")
    assert isinstance(log, ImuLog) and not log.is_summary
    assert log.names == ADIS
    assert log.n == 1_000_000 and log.fs == 100.0 and log.fs_source == "file"
    assert log.duration_s == pytest.approx(10_000.0)
    assert log.units == {**dict.fromkeys(ADIS[:3], "deg/s"), **dict.fromkeys(ADIS[3:], "g")}
    for name in ADIS:
        assert log[name].dtype == np.float64 and log[name].shape == (1_000_000,)
    with h5py.File(data / "adis16405_imu1.h5", "r") as f:
        np.testing.assert_array_equal(log["accel_z"], f["accel_z"][...])
    assert log["accel_z"].mean() == pytest.approx(-1.016, abs=0.005)
    assert "ADIS16405" in log.meta["sensor"] and log.meta["format"] == "hdf5"
    assert log.source == str(data / "adis16405_imu1.h5") and log.wv == {}


def test_mtig_single_channel(data: Path) -> None:
    log = load_log(data / "mtig_cont_imu1.h5")
    assert log.names == ["gyro_x"] and log.n == 500_000 and log.fs == 100.0
    assert log.units == {"gyro_x": "rad/s"}


def test_real_channel_selection_and_fs_override(data: Path) -> None:
    log = load_log(data / "adis16405_imu2.h5", channel="accel_z", fs=50)
    assert log.names == ["accel_z"] and log.units == {"accel_z": "g"}
    assert log.fs == 50.0 and log.fs_source == "user" and log.duration_s == 20_000.0
    assert load_log(data / "adis16405_imu2.h5", channel=1).names == ["gyro_y"]
    assert load_log(data / "adis16405_imu2.h5", channel=-1).names == ["accel_z"]
    msg = raises(
        data / "adis16405_imu2.h5", "no channel 'mag_x'", "gyro_x", "accel_z", channel="mag_x"
    )
    assert "index" in msg
    raises(data / "adis16405_imu2.h5", "out of range", "0..5", channel=6)


def test_navchip_summary(data: Path) -> None:
    path = data / "derived" / "navchip_wv_av.h5"
    log = load_log(path)
    assert log.is_summary and log.channels == {}
    assert log.names == ADIS and len(log.wv) == 6
    assert log.fs == 250.0 and log.n == 3_105_250 and log.fs_source == "file"
    assert log.duration_s == pytest.approx(12_421.0)
    assert log.units["gyro_x"] == "rad/s" and log.units["accel_y"] == "m/s^2"
    with h5py.File(path, "r") as f:
        for ch in ADIS:
            wv = log.wv[ch]
            assert isinstance(wv, WaveletVariance) and wv.n_levels == 20
            assert wv.n == 3_105_250 and wv.fs == 250.0 and not wv.robust
            np.testing.assert_array_equal(wv.variance, f[f"wv/{ch}/variance"][...])
            np.testing.assert_array_equal(wv.ci_low, f[f"wv/{ch}/ci_low"][...])
            np.testing.assert_array_equal(wv.ci_high, f[f"wv/{ch}/ci_high"][...])
            np.testing.assert_allclose(wv.tau_s, f[f"wv/{ch}/tau_s"][...], rtol=1e-15)
        assert log.wv["gyro_x"].unit == "rad/s" and log.wv["accel_x"].unit == "m/s^2"
    one = load_log(path, channel="gyro_z")
    assert one.names == ["gyro_z"] and list(one.wv) == ["gyro_z"]
    assert load_log(path, channel=3).names == ["accel_x"]
    assert load_log(path, fs=125).wv["gyro_x"].tau_s[0] == 2 / 125
    raises(path, "no channel 'mag_x'", "gyro_x", channel="mag_x")
    with pytest.raises(LoadError, match="summary"):
        log["gyro_x"]


@pytest.mark.parametrize(
    ("name", "levels", "fs", "n", "unit"),
    [
        ("navchip_wv_av.h5", 20, 250, 3_105_250, "rad/s"),
        ("ln200_wv_av.h5", 22, 400, 8_640_000, "rad/s"),
        ("imar_wv_av.h5", 21, 400, 5_760_000, "rad/s"),
        ("kvh1750_wv_av.h5", 18, 1000, 1_000_000, ""),
        ("mtig_imu6_wv.h5", 18, 100, 873_684, "rad/s"),
    ],
)
def test_all_summaries(data: Path, name: str, levels: int, fs: float, n: int, unit: str) -> None:
    log = load_log(data / "derived" / name)
    assert log.is_summary and log.fs == fs and log.n == n
    assert all(wv.n_levels == levels for wv in log.wv.values())
    assert log.wv["gyro_x"].unit == unit and log.units["gyro_x"] == unit


# ----------------------------------------------------------------------------- round trips
def test_roundtrip_h5(tmp_path: Path) -> None:
    ch = rng_channels(5000)
    ch["f32"] = ch["gyro_x"].astype(np.float32)
    ch["counts"] = np.arange(5000, dtype=np.int16) % 7
    units = {"gyro_x": "deg/s", "accel_z": "g"}
    out = save_log(
        tmp_path / "sim.h5", ch, 200.0, units, attrs={"sensor": "simulated", "model": {"WN": 1e-4}}
    )
    log = load_log(out)
    assert log.names == list(ch) and log.fs == 200.0 and log.fs_source == "file"
    assert log.units == {"gyro_x": "deg/s", "accel_z": "g", "f32": "", "counts": ""}
    np.testing.assert_array_equal(log["gyro_x"], ch["gyro_x"])
    np.testing.assert_array_equal(log["accel_z"], ch["accel_z"])
    assert log["f32"].dtype == np.float32 and np.array_equal(log["f32"], ch["f32"])
    assert log["counts"].dtype == np.float64 and np.array_equal(log["counts"], ch["counts"])
    assert log.meta["sensor"] == "simulated" and json.loads(log.meta["model"]) == {"WN": 1e-4}
    with h5py.File(out, "r") as f:
        assert f.attrs["kind"] == "raw" and f.attrs["schema_version"] == "1"
        assert f.attrs["n_samples"] == 5000 and f.attrs["duration_s"] == 25.0
        assert json.loads(f.attrs["units"])["gyro_x"] == "deg/s"
        assert f["gyro_x"].compression == "gzip" and f["gyro_x"].attrs["units"] == "deg/s"


def test_roundtrip_npy(tmp_path: Path) -> None:
    ch = rng_channels(3000)
    log = load_log(save_log(tmp_path / "two.npy", ch, 100.0), fs=100.0)
    assert np.load(tmp_path / "two.npy").shape == (3000, 2)
    assert log.names == ["col0", "col1"] and log.fs == 100.0 and log.fs_source == "user"
    np.testing.assert_array_equal(log["col0"], ch["gyro_x"])
    np.testing.assert_array_equal(log[1], ch["accel_z"])
    one = load_log(save_log(tmp_path / "one.npy", {"g": ch["gyro_x"]}, 100.0))
    assert one.names == ["x"] and one.fs == 1.0 and one.fs_source == "default"
    assert np.array_equal(one["x"], ch["gyro_x"]) and one.meta["notes"]


@pytest.mark.parametrize("fs", [200.0, 100.0, 333.3, 0.5])
def test_roundtrip_csv(tmp_path: Path, fs: float) -> None:
    ch = rng_channels(2000)
    ch["gyro_x"][5] = 1e-300  # extreme magnitudes survive the text format
    out = save_log(tmp_path / "sim.csv", ch, fs, {"gyro_x": "rad/s", "accel_z": "m/s^2"})
    assert out.read_text().splitlines()[0] == "time,gyro_x [rad/s],accel_z [m/s^2]"
    log = load_log(out)
    assert log.names == ["gyro_x", "accel_z"] and log.meta["time_column"] == "time"
    assert log.fs == fs and log.fs_source == "time column"
    assert log.units == {"gyro_x": "rad/s", "accel_z": "m/s^2"}
    for k, v in ch.items():
        np.testing.assert_allclose(log[k], v, rtol=1e-15, atol=0)


def test_save_log_errors(tmp_path: Path) -> None:
    ch = rng_channels(100)
    with pytest.raises(ValueError, match="extension"):
        save_log(tmp_path / "x.parquet", ch, 100.0)
    with pytest.raises(ValueError, match="200 samples|100 samples"):
        save_log(tmp_path / "x.h5", {"a": np.zeros(100), "b": np.zeros(200)}, 100.0)
    with pytest.raises(ValueError, match="fs_hz"):
        save_log(tmp_path / "x.h5", ch, 100.0, attrs={"fs_hz": 3})
    with pytest.raises(LoadError, match="sampling frequency"):
        save_log(tmp_path / "x.h5", ch, 0.0)
    with pytest.raises(ValueError, match="CSV"):
        save_log(tmp_path / "x.csv", {"a,b": np.zeros(10)}, 1.0)
    with pytest.raises(ValueError, match="no channels"):
        save_log(tmp_path / "x.npy", {}, 1.0)
    with pytest.raises(ValueError, match="time column"):
        save_log(tmp_path / "x.h5", {"time": np.zeros(10)}, 1.0)
    assert not list(tmp_path.iterdir())


# ----------------------------------------------------------------------------- text formats
def test_csv_header_time_column_infers_fs(tmp_path: Path) -> None:
    t = np.arange(400) / 200.0
    lines = ["# logged by test", "Time,gyro_x,gyro_y"]
    lines += [f"{ti:.3f},{np.sin(i):.6f},{i % 5}" for i, ti in enumerate(t)]
    log = load_log(write(tmp_path / "log.csv", "\n".join(lines) + "\n"))
    assert log.names == ["gyro_x", "gyro_y"] and log.n == 400
    assert log.fs == 200.0 and log.fs_source == "time column"
    assert log["gyro_x"][3] == pytest.approx(np.sin(3), abs=1e-6)
    assert log.meta["header"] is True and log.meta["delimiter"] == ","
    assert load_log(tmp_path / "log.csv", fs=10).fs == 10.0


@pytest.mark.parametrize(
    ("col", "step", "fs"),
    [
        ("time_ms", 10, 100.0),
        ("time [ms]", 5, 200.0),
        ("time_ns", 2_500_000, 400.0),
        ("t (us)", 1000, 1000.0),
        ("timestamp", 10_000_000, 100.0),
        ("seconds", 0.25, 4.0),
    ],
)
def test_time_units(tmp_path: Path, col: str, step: float, fs: float) -> None:
    rows = [f"{1e3 + i * step!r},{(-1) ** i * 0.1}" for i in range(50)]
    log = load_log(write(tmp_path / "t.csv", f"{col},x\n" + "\n".join(rows)))
    assert log.names == ["x"] and log.fs == pytest.approx(fs, rel=1e-12)
    if col == "timestamp":  # no unit given, huge steps: nanoseconds, and the user is told
        assert any("nanoseconds" in note for note in log.meta["notes"])


def test_headerless_with_and_without_time(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=(64, 2))
    rows = [f"{i * 0.01:.2f} {a!r} {b!r}" for i, (a, b) in enumerate(x.tolist())]
    log = load_log(write(tmp_path / "a.txt", "\n".join(rows)))
    assert log.names == ["col1", "col2"] and log.fs == 100.0 and log.fs_source == "time column"
    assert np.array_equal(log["col2"], x[:, 1]) and log.meta["header"] is False
    log = load_log(write(tmp_path / "b.txt", "\n".join(f"{a!r}\t{b!r}" for a, b in x.tolist())))
    assert log.names == ["col0", "col1"] and log.fs == 1.0 and log.fs_source == "default"
    assert log.meta["delimiter"] == "tab" and np.array_equal(log["col0"], x[:, 0])
    ramp = "\n".join(f"{i} {i}" for i in range(10))  # both increasing: no time column guess
    assert load_log(write(tmp_path / "c.txt", ramp)).names == ["col0", "col1"]


def test_tsv_whitespace_units_and_comments(tmp_path: Path) -> None:
    body = "\n".join(f"{i / 50}\t{0.1 * i}\t{-1 + 0.001 * i}" for i in range(20))
    tsv = load_log(write(tmp_path / "x.tsv", "t\tgyro_z [deg/s]\taccel_x (g)\n" + body))
    assert tsv.names == ["gyro_z", "accel_x"] and tsv.fs == 50.0
    assert tsv.units == {"gyro_z": "deg/s", "accel_x": "g"}
    text = (
        "# comment line\n  time   gyro_x [rad / s]   accel_y (m/s^2)  # inline comment\n\n"
        + "\n".join(f"  {i / 10}   {0.5 * i:e}    {i}  " for i in range(8))
        + "\n# end\n"
    )
    ws = load_log(write(tmp_path / "x.dat", text))
    assert ws.names == ["gyro_x", "accel_y"] and ws.fs == 10.0
    assert ws.units == {"gyro_x": "rad / s", "accel_y": "m/s^2"} and ws["gyro_x"][2] == 1.0
    assert ws.meta["delimiter"] == "whitespace"


def test_text_dialects(tmp_path: Path) -> None:
    semi = "time;x\n" + "\n".join(f"{i},0;{i},5" for i in range(6))  # decimal commas
    log = load_log(write(tmp_path / "eu.csv", semi))
    assert log.fs == 1.0 and log.fs_source == "time column" and log["x"][2] == 2.5
    quoted = '"time","gyro_x [deg/s]",\r\n' + "".join(f"{i / 4},{i},\r\n" for i in range(6))
    (tmp_path / "q.csv").write_bytes(b"\xef\xbb\xbf" + quoted.encode())  # BOM, CRLF, trailing ,
    log = load_log(tmp_path / "q.csv")
    assert log.names == ["gyro_x"] and log.units == {"gyro_x": "deg/s"} and log.fs == 4.0
    log = load_log(write(tmp_path / "noext", "a,a\n1,2\n3,4\n5,6\n7,8\n"))  # unknown extension
    assert log.names == ["a", "a_1"] and log["a_1"][0] == 2.0
    (tmp_path / "lat.csv").write_bytes("temp [\xb0C];x\n1;2\n2;3\n3;4\n4;5\n".encode("latin-1"))
    assert load_log(tmp_path / "lat.csv").units == {"temp": "\xb0C", "x": ""}
    save_log(tmp_path / "h5.h5", rng_channels(10), 5.0)
    (tmp_path / "h5.h5").rename(tmp_path / "renamed.bin")  # content beats extension
    assert load_log(tmp_path / "renamed.bin").fs == 5.0


def test_channel_selection_and_constant_signal(tmp_path: Path) -> None:
    path = write(
        tmp_path / "c.csv", "t,a,b,c\n" + "\n".join(f"{i},1.5,{i % 2},{i}" for i in range(10))
    )
    log = load_log(path, channel="b")
    assert log.names == ["b"] and log.units == {"b": ""} and log.n == 10
    assert load_log(path, channel=0).names == ["a"]
    assert load_log(path, channel="2").names == ["c"]  # digit string from a CLI
    assert np.all(load_log(path)["a"] == 1.5)  # constant: not a load error
    with pytest.raises(LoadError, match="no channel 'z'.*a, b, c"):
        load_log(path)["z"]


# ----------------------------------------------------------------------------- npy / npz / h5
def test_npz_and_structured_npy(tmp_path: Path) -> None:
    x = np.random.default_rng(5).normal(size=(100, 3))
    np.savez(
        tmp_path / "a.npz",
        gyro_x=x[:, 0],
        acc=x,
        fs=np.float64(400.0),
        units=json.dumps({"gyro_x": "rad/s"}),
        sensor="sim",
    )
    log = load_log(tmp_path / "a.npz")
    assert log.names == ["gyro_x", "acc[0]", "acc[1]", "acc[2]"] and log.fs == 400.0
    assert log.fs_source == "file" and log.units["gyro_x"] == "rad/s"
    assert log.meta["sensor"] == "sim"
    np.testing.assert_array_equal(log["acc[2]"], x[:, 2])
    np.savez(tmp_path / "b.npz", t=np.arange(100) * 0.004, gyro=x[:, 0].astype(np.float32))
    log = load_log(tmp_path / "b.npz")
    assert log.names == ["gyro"] and log.fs == 250.0 and log["gyro"].dtype == np.float32
    rec = np.zeros(50, dtype=[("time", "f8"), ("gx", "f4"), ("n", "i4")])
    rec["time"], rec["gx"], rec["n"] = np.arange(50) / 20, np.arange(50), np.arange(50) % 3
    np.save(tmp_path / "rec.npy", rec)
    log = load_log(tmp_path / "rec.npy")
    assert log.names == ["gx", "n"] and log.fs == 20.0 and log["n"].dtype == np.float64
    rec = np.zeros(20, dtype=[("acc", "f8", (2,)), ("g", "f8")])
    rec["acc"][:, 1] = np.arange(20)
    np.save(tmp_path / "sub.npy", rec)
    log = load_log(tmp_path / "sub.npy")
    assert log.names == ["acc[0]", "acc[1]", "g"] and log["acc[1]"][-1] == 19.0
    np.save(tmp_path / "rows.npy", x.T)  # (3, N): channels in rows
    assert np.array_equal(load_log(tmp_path / "rows.npy")["col1"], x[:, 1])


def test_generic_hdf5(tmp_path: Path) -> None:
    x = np.random.default_rng(6).normal(size=(300, 3))
    path = tmp_path / "generic.hdf5"
    with h5py.File(path, "w") as f:
        f["imu/acc"] = x
        f["imu/acc"].attrs["units"] = "m/s^2"
        f["imu/gyro_x"] = x[:, 0].astype(np.float32)
        f["imu/gyro_x"].attrs["sample_rate"] = 125.0
        f["imu/time"] = np.arange(300) / 100.0
        f["calib/bias"] = np.array([1.0, 2.0, 3.0])
        f["mag"] = x.T[:2]  # (2, N): channels in rows
        f["label"] = np.array([b"a", b"b"])
    log = load_log(path)
    assert log.names == ["imu/acc[0]", "imu/acc[1]", "imu/acc[2]", "imu/gyro_x", "mag[0]", "mag[1]"]
    assert np.array_equal(log["mag[1]"], x[:, 1])
    assert log.fs == 125.0 and log.fs_source == "file" and log.units["imu/acc[1]"] == "m/s^2"
    assert log["imu/gyro_x"].dtype == np.float32 and np.array_equal(log["imu/acc[2]"], x[:, 2])
    assert any("calib/bias" in note for note in log.meta["notes"])
    raises(path, "only 3 sample", channel="calib/bias")  # other lengths stay selectable
    with h5py.File(path, "a") as f:
        del f["imu/gyro_x"]
    log = load_log(path)
    assert log.fs == 100.0 and log.fs_source == "time column" and "imu/time" not in log.names


def test_summary_schema_errors(tmp_path: Path) -> None:
    def make(name: str, variance: np.ndarray, **attrs: object) -> Path:
        path = tmp_path / name
        with h5py.File(path, "w") as f:
            f.attrs.update({"kind": "wavelet_variance", "fs_hz": 10.0, **attrs})
            f["wv/gyro_x/variance"] = variance
            f["wv/gyro_x/tau_samples"] = 2 ** np.arange(1, variance.size + 1)
            f["wv/gyro_x"].attrs["robust"] = True
        return path

    good = load_log(make("ok.h5", np.array([4.0, 2.0, 1.0]), n_samples=100))
    wv = good.wv["gyro_x"]
    assert wv.robust and wv.ci_low[0] < 4.0 < wv.ci_high[0] and wv.n_levels == 3
    assert good.fs == 10.0 and good.n == 100 and good.units == {"gyro_x": ""}
    raises(make("non.h5", np.array([1.0, 2.0])), "n_samples")
    raises(make("neg.h5", np.array([1.0, -2.0]), n_samples=50), "wv/gyro_x/variance")
    with h5py.File(tmp_path / "tau.h5", "w") as f:
        f.attrs["n_samples"] = 50
        f["wv/accel_x/variance"] = np.ones(3)
        f["wv/accel_x/tau_samples"] = np.array([4, 8, 16])
    raises(tmp_path / "tau.h5", "wv/accel_x/tau_samples")


# ----------------------------------------------------------------------------- bad inputs
def test_missing_empty_and_binary(tmp_path: Path) -> None:
    raises(tmp_path / "nope.csv", "no such file")
    raises(write(tmp_path / "empty.csv", ""), "empty")
    raises(write(tmp_path / "comments.csv", "# only\n\n# comments\n"), "empty")
    msg = raises(write(tmp_path / "head.csv", "time,gyro_x\n"), "no data rows", "2 column(s)")
    assert "gyro_x" not in msg  # a lone first line may not be a header: never quoted
    (tmp_path / "rand.csv").write_bytes(np.random.default_rng(0).bytes(4096))
    raises(tmp_path / "rand.csv", "not a text file")
    raises(write(tmp_path / "fake.h5", "1,2,3\n"), "not a readable HDF5")
    raises(write(tmp_path / "fake.npy", "1,2,3\n"), ".npy")
    raises(tmp_path, "directory")


_ROWS = [f"{i / 100},{i * 0.1},{i}" for i in range(30)]


@pytest.mark.parametrize(
    ("name", "edits", "fragments"),
    [
        # header at line 1: row 15 is line 17
        ("abc", {15: "0.15,abc,15"}, ("column 2 of 3 ('gyro_x')", "line 17", "not a number")),
        ("gap", {3: "0.03,,3"}, ("column 2 of 3 ('gyro_x')", "line 5", "empty field")),
        ("ragged", {7: "0.07,0.7"}, ("line 9", "2 value(s) where 3")),
        (
            "nan",
            {i: f"{i / 100},{'nan' if i < 20 else 'inf'},{i}" for i in (10, 12, 20)},
            ("column 'gyro_x' has 3 NaN/Inf", "first at line 12 (sample 10)", "interpolate"),
        ),
        ("order", {4: _ROWS[5], 5: _ROWS[4]}, ("time column 'time'", "line 7", "fs=")),
    ],
)
def test_bad_csv_rows(
    tmp_path: Path, name: str, edits: dict[int, str], fragments: tuple[str, ...]
) -> None:
    bad = [edits.get(i, row) for i, row in enumerate(_ROWS)]
    path = write(tmp_path / f"{name}.csv", "time,gyro_x,n\n" + "\n".join(bad))
    raises(path, *fragments)
    if name == "order":
        assert load_log(path, fs=100).fs == 100.0  # user fs ignores the time


def test_bad_values(tmp_path: Path) -> None:
    raises(write(tmp_path / "short.csv", "t,x\n0,1\n1,2\n2,3\n"), "only 3 sample", "at least 4")
    x = np.ones(20)
    x[5] = np.inf
    np.save(tmp_path / "inf.npy", x)
    raises(tmp_path / "inf.npy", "column 'x'", "first at sample 5")
    np.save(tmp_path / "cplx.npy", np.ones(10, complex))
    raises(tmp_path / "cplx.npy", "complex128")
    np.save(tmp_path / "cube.npy", np.ones((4, 4, 4)))
    raises(tmp_path / "cube.npy", "(4, 4, 4)")
    np.save(tmp_path / "obj.npy", np.array([{}, 1], dtype=object))
    raises(tmp_path / "obj.npy", ".npy")
    np.savez(tmp_path / "nochan.npz", fs=100.0)
    raises(tmp_path / "nochan.npz", "no numeric channel")


def test_bad_fs_and_channel(tmp_path: Path) -> None:
    path = save_log(tmp_path / "ok.h5", rng_channels(64), 100.0)
    for bad in (0, -5.0, float("nan"), float("inf"), True, "fast"):
        raises(path, "fs =", "Hz", fs=bad)
    raises(path, "no channel 'gyro_y'", "gyro_x, accel_z", channel="gyro_y")
    raises(path, "index 2 is out of range", channel=2)
    raises(path, "no channel", channel=1.5)
    with h5py.File(path, "a") as f:
        f.attrs["fs_hz"] = 0.0
    raises(path, "attribute 'fs_hz'", "fs=")
    assert load_log(path, fs=25).fs == 25.0


def test_the_wv_of_a_channel_is_the_log_s_one_operation(tmp_path: Path) -> None:
    """``ImuLog.wavelet_variance``: the WV of the samples (unit and fs of the log), or a summary
    file's WV (truncated, relabelled, robust or classical as asked), with one rule set."""
    from engine.wv import wavelet_variance

    rng = np.random.default_rng(7)
    x = np.cumsum(rng.normal(size=4096)) * 1e-3 + rng.normal(size=4096)
    log = ImuLog({"gyro_x": x, "flat": np.full(64, 2.5)}, fs=50.0, units={"gyro_x": "deg/s"})
    wv = log.wavelet_variance("gyro_x", levels=8)
    ref = wavelet_variance(x, fs=50.0, levels=8, unit="deg/s")
    np.testing.assert_array_equal(wv.variance, ref.variance)
    np.testing.assert_array_equal(wv.ci_low, ref.ci_low)
    assert (wv.fs, wv.unit, wv.n_levels) == (50.0, "deg/s", 8)
    assert log.wavelet_variance(0, levels=8).variance.tolist() == wv.variance.tolist()
    rob = log.wavelet_variance("gyro_x", robust=True, eff=0.8, levels=6)
    np.testing.assert_array_equal(
        rob.variance, wavelet_variance(x, fs=50.0, levels=6, robust=True, eff=0.8).variance
    )
    other = log.wavelet_variance("gyro_x", levels=8, fs=100.0)  # fs overrides the log's
    assert other.fs == 100.0 and np.array_equal(other.tau_s, wv.tau_s / 2)
    np.testing.assert_array_equal(other.variance, wv.variance)
    with pytest.raises(LoadError, match=r"channel 'flat' is constant \(all 64 samples equal 2.5\)"):
        log.wavelet_variance("flat")
    with pytest.raises(LoadError, match="has no channel 'nope'"):
        log.wavelet_variance("nope")

    # a summary file: its WV, never recomputed
    summary = ImuLog({}, fs=50.0, wv={"gyro_x": ref})
    assert summary.wavelet_variance("gyro_x") is ref
    assert summary.wavelet_variance("gyro_x", levels=5).n_levels == 5
    assert summary.wavelet_variance("gyro_x", fs=25.0).fs == 25.0
    assert summary.unit_of("gyro_x") == "deg/s"
    with pytest.raises(LoadError, match="levels=9 is too many: .* has 8 levels for gyro_x"):
        summary.wavelet_variance("gyro_x", levels=9)
    with pytest.raises(LoadError, match="classical WV of gyro_x only: robust=True needs the raw"):
        summary.wavelet_variance("gyro_x", robust=True)
    both = ImuLog({}, fs=50.0, wv={"gyro_x": rob})  # a robust WV carries its classical one
    assert both.wavelet_variance("gyro_x", robust=True) is rob
    assert both.wavelet_variance("gyro_x") is rob.classical is not None
    robust_only = ImuLog({}, fs=50.0, wv={"gyro_x": dataclasses.replace(rob, classical=None)})
    with pytest.raises(LoadError, match="robust WV of gyro_x only: pass robust=True"):
        robust_only.wavelet_variance("gyro_x")
