"""PX4 ULog and ArduPilot DataFlash logs read natively (pyulog, pymavlink), on files written
by tests/fixtures/make_flight_logs.py from its binary-format writers, and on a real log."""

from __future__ import annotations

import builtins
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from flightlogs import make

import engine as eg
from engine.cli import main

pytest.importorskip("pyulog", reason="pip install 'gmwm-app[px4]'")
pytest.importorskip("pymavlink", reason="pip install 'gmwm-app[ardupilot]'")

FS = 250.0


@pytest.fixture(scope="module")
def flight() -> make.Flight:
    return make.simulate_flight(FS, still_s=(8.0, 8.0), move_s=4.0, seed=5)


@pytest.fixture(scope="module")
def logs(flight: make.Flight, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("flight")
    return {
        "ulg": make.write_ulog(d / "flight.ulg", flight, make.PX4_PARAMS),
        "bin": make.write_dataflash(d / "00000001.BIN", flight, make.ARDUPILOT_PARAMS),
    }


def test_ulog_sensor_combined(logs, flight) -> None:
    log = eg.load_log(logs["ulg"])
    assert log.meta["format"] == "ulog" and log.meta["topic"] == "sensor_combined"
    assert log.names == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    assert log.fs == pytest.approx(FS, rel=1e-9) and log.fs_source == "time column"
    assert log.units["gyro_x"] == "rad/s" and log.units["accel_z"] == "m/s^2"
    np.testing.assert_array_equal(log["gyro_x"], flight.gyro[:, 0].astype(np.float32))
    assert log.meta["params"]["EKF2_GYR_NOISE"] == 0.015


def test_ulog_instances_and_temperature(logs, flight) -> None:
    log = eg.load_log(logs["ulg"], topic="sensor_gyro")
    assert log.names == [f"imu{k}_gyro_{a}" for k in (0, 1) for a in "xyz"]
    assert sorted(log.aux) == ["imu0_temperature", "imu1_temperature"]
    np.testing.assert_allclose(log.aux["imu1_temperature"], flight.temp, atol=1e-5)
    # the second instance has 1.5x the noise std: WV ratio 2.25 at level 1 (n=5000: +-6 %)
    still = ~flight.moving[: log.n]
    a, b = log["imu0_gyro_x"][still], log["imu1_gyro_x"][still]
    assert np.var(np.diff(b)) / np.var(np.diff(a)) == pytest.approx(2.25, rel=0.1)
    acc = eg.load_log(logs["ulg"], topic="sensor_accel")
    assert acc.units["imu0_accel_z"] == "m/s^2"
    with pytest.raises(eg.LoadError, match="no topic 'vehicle_gps_position'.*sensor_combined"):
        eg.load_log(logs["ulg"], topic="vehicle_gps_position")


def test_dataflash_imu_instances(logs, flight) -> None:
    log = eg.load_log(logs["bin"])
    assert log.meta["format"] == "dataflash" and log.meta["instances"] == 2
    assert log.names[:6] == [f"imu0_{s}_{a}" for s in ("gyro", "accel") for a in "xyz"]
    assert log.fs == pytest.approx(FS, rel=1e-9)
    np.testing.assert_array_equal(log["imu0_accel_z"], flight.accel[:, 2].astype(np.float32))
    assert log.units["imu0_temperature"] == "degC" and "imu0_temperature" in log.aux
    assert log.meta["params"]["EK3_GYRO_P_NSE"] == 0.015


def test_uploads_as_bytes(logs) -> None:
    """The app's upload gives the content: both formats are read from bytes too."""
    for key in ("ulg", "bin"):
        a = eg.load_log(logs[key].read_bytes(), name=logs[key].name)
        b = eg.load_log(logs[key])
        assert a.names == b.names and np.array_equal(a[0], b[0]) and a.fs == b.fs


def test_missing_extra_is_named(logs, monkeypatch) -> None:
    real = builtins.__import__

    def no_flight_libs(name, *args, **kwargs):
        if name.split(".")[0] in ("pyulog", "pymavlink"):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_flight_libs)
    with pytest.raises(eg.LoadError, match=r"PX4 ULog.*pyulog.*gmwm-app\[px4\]"):
        eg.load_log(logs["ulg"])
    with pytest.raises(eg.LoadError, match=r"DataFlash.*pymavlink.*gmwm-app\[ardupilot\]"):
        eg.load_log(logs["bin"])


def test_not_a_text_file_names_the_formats(tmp_path: Path) -> None:
    """Defect 2's message: it names the binary formats read (ROS bags, ULog, DataFlash) and
    the converters."""
    p = tmp_path / "unknown.dat"
    p.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(eg.LoadError) as err:
        eg.load_log(p)
    msg = str(err.value)
    for word in ("ROS bags", "ULog (.ulg)", "DataFlash (.bin)", "ulog2csv", "mavlogdump"):
        assert word in msg


def test_cli_wv_of_a_ulog(logs, capsys) -> None:
    """Defect 2: `gmwm wv flight.ulg` exited 2; now the WV of gyro_x at 250 Hz."""
    assert main(["wv", str(logs["ulg"]), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fs"] == FS and out["tau_s"][0] == pytest.approx(2 / FS)


@pytest.mark.real_data
def test_real_log_through_a_ulog(real_data: Path, tmp_path: Path) -> None:
    """A real static log (ADIS16405 replicate 1, first 200 000 samples, deg/s -> rad/s and
    g -> m/s^2) written as a ULog at 100 Hz and read back: the WV of gyro_x equals the HDF5
    log's within float32 rounding (1e-6 relative on every level)."""
    n = 200_000
    with h5py.File(real_data / "adis16405_imu1.h5", "r") as f:
        gyro = np.stack([f[f"gyro_{a}"][:n] for a in "xyz"], axis=1) * np.pi / 180
        accel = np.stack([f[f"accel_{a}"][:n] for a in "xyz"], axis=1) * 9.80665
    t_us = 1_000_000 + np.arange(n, dtype=np.int64) * 10_000
    fl = make.Flight(t_us, gyro, accel, np.full(n, 25.0), np.zeros(n, bool), 100.0, 0.0, 0.0)
    log = eg.load_log(make.write_ulog(tmp_path / "adis.ulg", fl))
    assert log.fs == 100.0 and log.n == n
    ref = eg.wavelet_variance(gyro[:, 0].astype(np.float32).astype(np.float64), fs=100.0)
    got = log.wavelet_variance("gyro_x")
    np.testing.assert_allclose(got.variance, ref.variance, rtol=1e-6)
    # and the native deg/s WV scaled by (pi/180)^2: level 1 of replicate 1 is 1.05e-3 deg^2/s^2
    deg = eg.load_log(real_data / "adis16405_imu1.h5", channel="gyro_x", segment=(0, n))
    wdeg = deg.wavelet_variance("gyro_x")
    np.testing.assert_allclose(got.variance, wdeg.variance * (np.pi / 180) ** 2, rtol=1e-5)


def test_app_upload_of_flight_logs(logs, flight) -> None:
    """The app's upload (AppState.load_upload: the content and its name) reads both formats,
    selects gyro_x (not a time or instance column) and computes its WV at 250 Hz."""
    from gmwm_app.state import AppState

    for key, first in (("ulg", "gyro_x"), ("bin", "imu0_gyro_x")):
        s = AppState()
        assert s.load_upload(logs[key].read_bytes(), logs[key].name), s.error
        assert s.channel == first and s.wv is not None and s.wv.fs == FS
        assert s.wv.n == flight.t_us.size
    # a flight's still segments: the WV pools them (8 + 8 s still, edges trimmed)
    s = AppState()
    assert s.load_upload(logs["ulg"].read_bytes(), "flight.ulg", segments="auto"), s.error
    segs = eg.load_log(logs["ulg"], segments="auto").segments
    assert s.wv is not None and s.wv.n == sum(b - a for a, b in segs) < (~flight.moving).sum()


def test_dataflash_text_log(flight, tmp_path: Path) -> None:
    """The text form of a DataFlash log (.log, first line FMT) is read by DFReader_text."""
    p = make.write_dataflash_text(tmp_path / "flight.log", flight, make.ARDUPILOT_PARAMS)
    log = eg.load_log(p)
    assert log.meta["format"] == "dataflash" and log.fs == pytest.approx(FS, rel=1e-9)
    np.testing.assert_array_equal(log["gyro_x"], flight.gyro[:, 0])
    assert list(log.aux) == ["temperature"] and log.meta["params"]["EK3_GYRO_P_NSE"] == 0.015


def test_app_still_segments_checkbox(logs, flight, app) -> None:
    """The Data panel's 'still segments only' box: an uploaded flight's WV pools its still
    segments; unticked, the whole flight."""
    segs = eg.load_log(logs["ulg"], segments="auto").segments
    app.still_only.value = True
    app.upload.value = {"flight.ulg": logs["ulg"].read_bytes()}
    assert app.state.error == "" and app.state.channel == "gyro_x"
    assert app.state.wv.n == sum(b - a for a, b in segs)
    app.still_only.value = False
    app.upload.value = {"flight2.ulg": logs["ulg"].read_bytes()}
    assert app.state.wv.n == flight.t_us.size
