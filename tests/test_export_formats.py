"""Filter export formats (engine.export.vio/autopilot/sim/ins): every key read back from the
file and checked against the fit's datasheet table (engine.units.datasheet_rows), --inflate,
the autopilot range warnings, and a fit -> OpenVINS -> simulate -> refit round trip."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

import engine as eg
from engine.demo import demo_path
from engine.export import ExportError, export
from engine.units import datasheet_rows, si_factor

REL = 1e-12
GYROS = ("gyro_x", "gyro_y", "gyro_z")
ACCELS = ("accel_x", "accel_y", "accel_z")


@pytest.fixture(scope="module")
def log() -> eg.ImuLog:
    return eg.load_log(demo_path())


@pytest.fixture(scope="module")
def fits(log: eg.ImuLog) -> dict[str, eg.GMWMResult]:
    """The demo's six channels, GM+WN+RW (a GM term for the Gauss-Markov formats)."""
    return {
        c: eg.fit_gmwm(eg.wavelet_variance(log[c], fs=log.fs, unit=log.units[c]), "GM+WN+RW")
        for c in log.names
    }


def ds(res: eg.GMWMResult, quantity: str, symbol: str, proc: str | None = None) -> float:
    """One value of the fit's datasheet table (with the Allan floor)."""
    rows = datasheet_rows(res.model, res.fs, res.wv.unit, n_levels=res.wv.n_levels)
    got = [
        r.value
        for r in rows
        if r.quantity == quantity and r.symbol == symbol and (proc is None or r.process == proc)
    ]
    assert len(got) == 1, (quantity, symbol, got)
    return float(got[0])


def n_si(r: eg.GMWMResult) -> float:
    return ds(r, "white noise density (SI)", "N")


def k_si(r: eg.GMWMResult) -> float:
    gyro = si_factor(r.wv.unit)[0] == "gyroscope"
    name = "rate random walk (SI)" if gyro else "acceleration random walk (SI)"
    return ds(r, name, "K")


def worst(fits, chans, fn) -> float:
    return max(fn(fits[c]) for c in chans)


def _cv_yaml(text: str) -> dict:
    """An OpenCV ``%YAML:1.0`` file as PyYAML reads it (the directive line dropped)."""
    assert text.startswith("%YAML:1.0\n")
    return yaml.safe_load(text.split("\n", 1)[1])


def close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL, abs_tol=0.0)


# ----------------------------------------------------------------------------- VIO
@pytest.mark.parametrize("inflate", [1.0, 3.5])
def test_openvins(fits, inflate: float) -> None:
    text = export(None, fits, "openvins", inflate=inflate, rostopic="/mybag/imu")
    d = _cv_yaml(text)["imu0"]
    assert close(d["gyroscope_noise_density"], inflate * worst(fits, GYROS, n_si))
    assert close(d["gyroscope_random_walk"], inflate * worst(fits, GYROS, k_si))
    assert close(d["accelerometer_noise_density"], inflate * worst(fits, ACCELS, n_si))
    assert close(d["accelerometer_random_walk"], inflate * worst(fits, ACCELS, k_si))
    assert d["rostopic"] == "/mybag/imu" and d["update_rate"] == 100.0
    assert d["time_offset"] == 0.0 and d["model"] == "kalibr"
    assert np.array_equal(d["T_i_b"], np.eye(4))
    for k in ("Tw", "R_IMUtoGYRO", "Ta", "R_IMUtoACC"):
        assert np.array_equal(d[k], np.eye(3))
    assert np.array_equal(d["Tg"], np.zeros((3, 3)))
    assert f"inflate = {inflate!r}" in text
    # every number has its unit on its line
    for key in ("noise_density", "random_walk"):
        assert all("/sqrt(Hz)]" in ln for ln in text.splitlines() if f"_{key}:" in ln)


def test_basalt(fits) -> None:
    d = json.loads(export(None, fits, "basalt"))
    v = d["value0"]
    assert v["imu_update_rate"] == 100.0
    for key, chans, fn in (
        ("gyro_noise_std", GYROS, n_si),
        ("gyro_bias_std", GYROS, k_si),
        ("accel_noise_std", ACCELS, n_si),
        ("accel_bias_std", ACCELS, k_si),
    ):
        assert len(v[key]) == 3
        assert all(close(a, fn(fits[c])) for a, c in zip(v[key], chans, strict=True)), key
        assert "sqrt(Hz)" in d["gmwm_export"]["units"][key]


def test_orbslam3_and_vins(fits) -> None:
    o = _cv_yaml(export(None, fits, "orbslam3"))
    assert close(o["IMU.NoiseGyro"], worst(fits, GYROS, n_si))
    assert close(o["IMU.NoiseAcc"], worst(fits, ACCELS, n_si))
    assert close(o["IMU.GyroWalk"], worst(fits, GYROS, k_si))
    assert close(o["IMU.AccWalk"], worst(fits, ACCELS, k_si))
    assert o["IMU.Frequency"] == 100.0
    text = export(None, fits, "vins")
    v = _cv_yaml(text)
    assert close(v["gyr_n"], worst(fits, GYROS, n_si))
    assert close(v["acc_n"], worst(fits, ACCELS, n_si))
    assert close(v["gyr_w"], worst(fits, GYROS, k_si))
    assert close(v["acc_w"], worst(fits, ACCELS, k_si))
    assert "convention: continuous-time densities as in Kalibr" in text


def test_inflate_is_explicit(fits) -> None:
    with pytest.raises(ExportError, match="inflate must be a positive"):
        export(None, fits, "openvins", inflate=0)
    with pytest.raises(ExportError, match="reports the fit itself"):
        export(None, fits, "datasheet", inflate=2)
    k1 = yaml.safe_load(export(None, fits, "kalibr"))
    k2 = yaml.safe_load(export(None, fits, "kalibr", inflate=2.5))
    assert k2["gyroscope_noise_density"] == 2.5 * k1["gyroscope_noise_density"]
    assert k2["accelerometer_random_walk"] == 2.5 * k1["accelerometer_random_walk"]
    assert k2["update_rate"] == k1["update_rate"]


def test_openvins_round_trip_simulate_refit(log, tmp_path) -> None:
    """Fit WN+RW on the demo -> OpenVINS file -> WN+RW from its densities -> simulate ->
    refit: the refits' mean is the file's value within 4 Monte Carlo standard errors."""
    wfits = {
        c: eg.fit_gmwm(eg.wavelet_variance(log[c], fs=log.fs, unit=log.units[c]), "WN+RW")
        for c in ("gyro_x", "accel_x")
    }
    d = _cv_yaml(export(tmp_path / "imu.yaml", wfits, "openvins"))["imu0"]
    assert close(d["gyroscope_noise_density"], n_si(wfits["gyro_x"]))
    fs = d["update_rate"]
    reps = 8
    for sensor in ("gyroscope", "accelerometer"):
        n, k = d[f"{sensor}_noise_density"], d[f"{sensor}_random_walk"]
        model = eg.WN(n * n * fs) + eg.RW(k * k / fs)  # N = sqrt(sigma2/fs), K = sqrt(gamma2 fs)
        su = "rad/s" if sensor == "gyroscope" else "m/s^2"
        got = []
        for i in range(reps):
            x = model.simulate(len(log["gyro_x"]), fs=fs, rng=900 + i)
            r = eg.fit_gmwm(eg.wavelet_variance(x, fs=fs, unit=su), "WN+RW")
            got.append([n_si(r), k_si(r)])
        g = np.array(got)
        se = g.std(axis=0, ddof=1) / math.sqrt(reps)
        assert np.all(np.abs(g.mean(axis=0) - [n, k]) < 4 * se), (sensor, g.mean(0), [n, k], se)
        assert np.all(se / [n, k] < 0.1)  # the check has power: errors of a few percent
