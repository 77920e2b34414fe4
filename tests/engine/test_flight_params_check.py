"""`gmwm check flight.ulg --params ...`: the EKF noise parameters flown against the log's
still segments (engine.formats.flight_check), on flights of tests/fixtures/make_flight_logs.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from flightlogs import make

from engine.cli import main
from engine.formats.flight_check import read_params_file

pytest.importorskip("pyulog")
pytest.importorskip("pymavlink")

FS = 250.0


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> tuple[make.Flight, Path, Path]:
    d = tmp_path_factory.mktemp("params")
    fl = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=11)
    return (
        fl,
        make.write_ulog(d / "flight.ulg", fl, make.PX4_PARAMS),
        make.write_dataflash(d / "flight.bin", fl, make.ARDUPILOT_PARAMS),
    )


def _check(capsys, *argv: str) -> dict:
    assert main(["check", *argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    return {r["name"]: r for r in out["params"]} | {"_": out}


def test_the_measured_noise_is_the_simulated_one(flight, capsys) -> None:
    """EKF2_GYR_NOISE measured = sigma / sqrt(fs) x sqrt(100 Hz) = 0.004 / sqrt(250) x 10 =
    2.530e-3 rad/s (max over 3 axes of ~9750 still samples: within 3 %); the flown 0.015
    is 5.9x that: consistent."""
    fl, ulg, _ = flight
    rows = _check(capsys, str(ulg), "--params", "log")
    want = fl.gyro_sigma / np.sqrt(FS) * np.sqrt(100.0)
    assert rows["EKF2_GYR_NOISE"]["measured"] == pytest.approx(want, rel=0.03)
    assert rows["EKF2_GYR_NOISE"]["flown"] == 0.015
    assert rows["EKF2_GYR_NOISE"]["verdict"].startswith("consistent")
    want_acc = fl.accel_sigma / np.sqrt(FS) * 10.0
    assert rows["EKF2_ACC_NOISE"]["measured"] == pytest.approx(want_acc, rel=0.03)
    assert rows["EKF2_ACC_NOISE"]["verdict"].startswith("too large")  # 0.35 is 18x
    assert rows["_"]["still_s"] == pytest.approx(39.0)


def test_exported_parameters_check_as_ratio_one(flight, capsys, tmp_path: Path) -> None:
    """Round trip: the file `gmwm export --format px4` writes from the same segments has
    ratio 1 for every parameter; halving one makes it 'too small' at ratio 0.5."""
    _, ulg, _ = flight
    out = tmp_path / "vehicle.params"
    argv = ["export", str(ulg), "--segments", "auto", "--model", "WN+RW", "--format", "px4"]
    assert main([*argv, "--filter-rate", "100", "-o", str(out)]) == 0
    capsys.readouterr()
    rows = _check(capsys, str(ulg), "--params", str(out))
    for name in ("EKF2_GYR_NOISE", "EKF2_ACC_NOISE", "EKF2_GYR_B_NOISE", "EKF2_ACC_B_NOISE"):
        assert rows[name]["ratio"] == pytest.approx(1.0, rel=1e-12)
    params = read_params_file(out)
    half = tmp_path / "half.params"
    half.write_text(
        "\n".join(
            f"1\t1\t{k}\t{v / (2 if k == 'EKF2_GYR_NOISE' else 1)!r}\t9" for k, v in params.items()
        )
    )
    rows = _check(capsys, str(ulg), "--params", str(half))
    assert rows["EKF2_GYR_NOISE"]["ratio"] == pytest.approx(0.5, rel=1e-12)
    assert rows["EKF2_GYR_NOISE"]["verdict"].startswith("too small")


def test_ardupilot_log_parameters(flight, capsys, tmp_path: Path) -> None:
    """The .bin's PARM values at EKF3's 83 Hz: EK3_GYRO_P_NSE measured = 0.004 / sqrt(250) x
    sqrt(83) = 2.305e-3 rad/s; a Mission Planner .param file gives the same verdicts."""
    fl, _, binf = flight
    rows = _check(capsys, str(binf), "--params", "log")
    want = fl.gyro_sigma / np.sqrt(FS) * np.sqrt(83.0)
    assert rows["EK3_GYRO_P_NSE"]["measured"] == pytest.approx(want, rel=0.03)
    assert rows["_"]["filter_rate"] == 83.0
    p = tmp_path / "vehicle.param"
    p.write_text("".join(f"{k},{v}\n" for k, v in make.ARDUPILOT_PARAMS.items()))
    again = _check(capsys, str(binf), "--params", str(p))
    assert again["EK3_GYRO_P_NSE"]["ratio"] == pytest.approx(
        rows["EK3_GYRO_P_NSE"]["ratio"], rel=1e-6
    )


def test_bad_parameter_files(flight, capsys, tmp_path: Path) -> None:
    _, ulg, _ = flight
    empty = tmp_path / "empty.params"
    empty.write_text("# nothing\n")
    assert main(["check", str(ulg), "--params", str(empty)]) == 2
    assert "no NAME VALUE line" in capsys.readouterr().err
    other = tmp_path / "other.params"
    other.write_text("1\t1\tMC_ROLL_P\t6.5\t9\n")
    assert main(["check", str(ulg), "--params", str(other)]) == 2
    assert "no EKF noise parameter" in capsys.readouterr().err
