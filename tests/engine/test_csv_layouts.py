"""CSV files that know time: time columns with their unit, instance and counter columns,
``name[0]`` headers, temperatures kept aside, and the layouts of ulog2csv, mavlogdump,
Sensor Logger and phyphox (each on a small file in that layout, made by
tests/fixtures/make_flight_logs.py; the converters themselves run where installed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from flightlogs import make

import engine as eg
from engine.cli import main

FS = 250.0


@pytest.fixture(scope="module")
def still() -> make.Flight:
    """A still 'flight' (no motion): 24 s at 250 Hz, gyro white noise std 0.004 rad/s."""
    return make.simulate_flight(FS, still_s=(24.0,), seed=3)


@pytest.fixture(scope="module")
def files(still: make.Flight, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("layouts")
    out = {
        "sensor_logger": make.write_sensor_logger(still, d),
        "phyphox": make.write_phyphox(still, d),
        "ulg": make.write_ulog(d / "px4.ulg", still),
        "bin": make.write_dataflash(d / "ardupilot.bin", still),
    }
    if _has("pyulog"):
        out["ulog2csv"] = make.write_ulog2csv(out["ulg"], d)
    if _has("pymavlink"):
        out["mavlogdump"] = make.write_mavlogdump_csv(out["bin"], d / "ardupilot_IMU.csv")
    return out


def _has(mod: str) -> bool:
    try:
        __import__(mod)
    except ImportError:
        return False
    return True


def test_ulog2csv_microsecond_timestamps_and_array_headers(files, still) -> None:
    """Defect 1: ``timestamp`` in us read as seconds (fs 0.00025) and ``gyro_rad[0]`` parsed
    as unit ``0``. Now fs = 250 Hz from the stamps, gyro_x in rad/s, counters dropped."""
    if "ulog2csv" not in files:
        pytest.skip("pyulog not installed (pip install 'gmwm-app[px4]')")
    log = eg.load_log(files["ulog2csv"])
    assert log.fs == pytest.approx(FS, rel=1e-9) and log.fs_source == "time column"
    assert log.names == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    assert log.units["gyro_x"] == "rad/s" and log.units["accel_z"] == "m/s^2"
    assert log.meta["profile"] == "ulog2csv (PX4 sensor_combined)"
    # the samples are the simulated ones (ulog2csv writes float32 with 10 digits)
    np.testing.assert_allclose(log["gyro_x"], still.gyro[:, 0], rtol=0, atol=1e-9)
    wv = log.wavelet_variance("gyro_x")
    assert wv.fs == FS and wv.tau_s[0] == pytest.approx(2 / FS)


def test_ulog2csv_kalibr_rate_and_density(files, still, tmp_path: Path) -> None:
    """The Kalibr file of a ulog2csv CSV: update_rate 250 (was 0.00025) and the white-noise
    density N = sigma / sqrt(fs) of the simulation within its sampling error."""
    if "ulog2csv" not in files:
        pytest.skip("pyulog not installed")
    log = eg.load_log(files["ulog2csv"], channel="gyro_x")
    res = eg.fit_gmwm(log.wavelet_variance("gyro_x"), eg.parse_model("WN"))
    n = still.t_us.size
    # sigma2 from ~n samples: relative std sqrt(2/n) = 0.0058; 5 sigma band
    assert res.params["WN.sigma2"] == pytest.approx(still.gyro_sigma**2, rel=5 * np.sqrt(2 / n))


def test_mavlogdump_time_instance_and_temperature(files, still) -> None:
    """Defect 3: TimeUS and the instance column I became channels (TimeUS the default one) and
    T was dropped. Now TimeUS gives fs, each IMU instance has its channels, T is auxiliary."""
    if "mavlogdump" not in files:
        pytest.skip("pymavlink not installed (pip install 'gmwm-app[ardupilot]')")
    log = eg.load_log(files["mavlogdump"])
    assert log.fs == pytest.approx(FS, rel=1e-9)
    assert log.names[0] == "imu0_gyro_x" and "TimeUS" not in log.names and "I" not in log.names
    assert {"imu1_gyro_x", "imu1_accel_z"} <= set(log.names)
    assert sorted(log.aux) == ["imu0_temperature", "imu1_temperature"]
    assert log.units["imu0_temperature"] == "degC" and log.units["imu0_gyro_x"] == "rad/s"
    np.testing.assert_allclose(log.aux["imu0_temperature"], still.temp, atol=1e-5)
    np.testing.assert_allclose(log["imu0_gyro_x"], still.gyro[:, 0], atol=1e-7)


def test_mavlogdump_fit_is_the_noise_not_a_ramp(files, still, tmp_path: Path, capsys) -> None:
    """`gmwm fit ardupilot_IMU.csv --model WN+RW` fitted the TimeUS ramp (RW.gamma2 7.2e6);
    now the default channel is the gyro and WN.sigma2 is the simulated 1.6e-5 (rad/s)^2."""
    if "mavlogdump" not in files:
        pytest.skip("pymavlink not installed")
    import json

    assert main(["fit", str(files["mavlogdump"]), "--model", "WN+RW", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fs"] == FS
    params = {f"{p['label']}.{p['name']}": p["value"] for p in out["params"]}
    assert out["params"][0]["unit"] == "(rad/s)^2"
    n = still.t_us.size
    assert params["WN.sigma2"] == pytest.approx(still.gyro_sigma**2, rel=5 * np.sqrt(2 / n))
    assert params["RW.gamma2"] < 1e-6  # the ramp gave 7.2e6


def test_sensor_logger_seconds_elapsed_is_time(files, still) -> None:
    """Defect 3: Sensor Logger's seconds_elapsed became a channel. Now ``time`` (ns since the
    epoch) gives fs and both time columns stay out of the channels; units from the file name."""
    log = eg.load_log(files["sensor_logger"])
    assert log.names == ["z", "y", "x"]
    assert log.fs == pytest.approx(FS, rel=1e-6) and log.units["x"] == "rad/s"
    np.testing.assert_array_equal(log["x"], still.gyro[:, 0])


def test_phyphox_layout(files, still) -> None:
    """phyphox's export: ``Time (s)`` is the time, units from the header ``(rad/s)``."""
    log = eg.load_log(files["phyphox"])
    assert log.names == ["Gyroscope x", "Gyroscope y", "Gyroscope z"]
    assert log.fs == pytest.approx(FS, rel=1e-6) and log.units["Gyroscope x"] == "rad/s"
    np.testing.assert_allclose(log["Gyroscope x"], still.gyro[:, 0], rtol=1e-9)


@pytest.mark.parametrize(
    ("name", "step", "fs"),
    [
        ("timestamp", 4000, 250.0),  # microseconds (PX4)
        ("time", 10, 100.0),  # milliseconds
        ("t", 2_500_000, 400.0),  # nanoseconds
        ("time", 0.01, 100.0),  # seconds
        ("TimeUS", 2500, 400.0),  # named unit
        ("time_boot_ms", 5, 200.0),  # named unit
    ],
)
def test_time_unit_from_name_and_spacing(tmp_path: Path, name: str, step: float, fs: float):
    """A time column's unit from its name, else from its spacing; never a channel."""
    rng = np.random.default_rng(0)
    rows = "\n".join(f"{1000 * step + i * step!r},{float(rng.normal())!r}" for i in range(400))
    p = tmp_path / "t.csv"
    p.write_text(f"{name},gyro_x\n{rows}\n")
    log = eg.load_log(p)
    assert log.names == ["gyro_x"] and log.fs == pytest.approx(fs, rel=1e-9)


def test_index_header_beyond_three(tmp_path: Path) -> None:
    """``q[0..3]`` (four elements) become q_x, q_y, q_z and q_3; a counter column is dropped."""
    rng = np.random.default_rng(1)
    head = "q[0],q[1],q[2],q[3],error_count"
    rows = "\n".join(",".join(repr(float(v)) for v in rng.normal(size=4)) + ",0" for _ in range(50))
    p = tmp_path / "q.csv"
    p.write_text(head + "\n" + rows + "\n")
    log = eg.load_log(p, fs=100.0)
    assert log.names == ["q_x", "q_y", "q_z", "q_3"] and log.units["q_x"] == ""


def test_temperature_only_file_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "temp.csv"
    p.write_text("time,temperature\n" + "\n".join(f"{i / 100},{20 + i / 1e3}" for i in range(50)))
    with pytest.raises(eg.LoadError, match="only time and temperature"):
        eg.load_log(p)
