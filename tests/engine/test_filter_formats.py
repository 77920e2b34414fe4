"""Filter export formats (engine.formats.vio/autopilot/sim/ins): every key read back from the
file and checked against the fit's datasheet table (engine.units.datasheet_rows), --inflate,
the autopilot range warnings, and a fit -> OpenVINS -> simulate -> refit round trip."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
import yaml

import engine as eg
from engine.demo import demo_path
from engine.formats import FORMATS, ExportError, export
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
    text = export(None, fits, "openvins", projection="fit", inflate=inflate, rostopic="/mybag/imu")
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
    d = json.loads(export(None, fits, "basalt", projection="fit"))
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
    o = _cv_yaml(export(None, fits, "orbslam3", projection="fit"))
    assert close(o["IMU.NoiseGyro"], worst(fits, GYROS, n_si))
    assert close(o["IMU.NoiseAcc"], worst(fits, ACCELS, n_si))
    assert close(o["IMU.GyroWalk"], worst(fits, GYROS, k_si))
    assert close(o["IMU.AccWalk"], worst(fits, ACCELS, k_si))
    assert o["IMU.Frequency"] == 100.0
    text = export(None, fits, "vins", projection="fit")
    v = _cv_yaml(text)
    # VINS: per-sample (discrete) standard deviations at the IMU rate, density x sqrt(fs)
    r = math.sqrt(100.0)
    assert close(v["gyr_n"], worst(fits, GYROS, n_si) * r)
    assert close(v["acc_n"], worst(fits, ACCELS, n_si) * r)
    assert close(v["gyr_w"], worst(fits, GYROS, k_si) * r)
    assert close(v["acc_w"], worst(fits, ACCELS, k_si) * r)
    assert "per-sample (discrete) standard deviations" in text


def test_inflate_is_explicit(fits) -> None:
    with pytest.raises(ExportError, match="inflate must be a positive"):
        export(None, fits, "openvins", projection="fit", inflate=0)
    with pytest.raises(ExportError, match="reports the fit itself"):
        export(None, fits, "datasheet", projection="fit", inflate=2)
    k1 = yaml.safe_load(export(None, fits, "kalibr", projection="fit"))
    k2 = yaml.safe_load(export(None, fits, "kalibr", projection="fit", inflate=2.5))
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
    # data="none": the fitted WN+RW itself (the default also bounds the data's
    # lower 95 % limit and raises N where the fit is below it)
    d = _cv_yaml(export(tmp_path / "imu.yaml", wfits, "openvins", data="none"))["imu0"]
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


# ----------------------------------------------------------------------------- autopilots
def _px4(text: str) -> dict[str, float]:
    out = {}
    for ln in text.splitlines():
        if ln and not ln.startswith("#"):
            vid, cid, name, value, typ = ln.split("\t")
            assert (vid, cid, typ) == ("1", "1", "9")
            out[name] = float(value)
    return out


def _ardupilot(text: str) -> dict[str, float]:
    return {
        m.group(1): float(m.group(2))
        for m in re.finditer(r"^([A-Z0-9_]+),(\S+)$", text, flags=re.MULTILINE)
    }


@pytest.mark.parametrize(("fmt", "rate"), [("px4", 100.0), ("ardupilot", 400.0)])
def test_autopilot_params(fits, fmt: str, rate: float) -> None:
    text = export(None, fits, fmt, projection="fit", filter_rate=rate)
    d = (_px4 if fmt == "px4" else _ardupilot)(text)
    names = (
        ("EKF2_GYR_NOISE", "EKF2_ACC_NOISE", "EKF2_GYR_B_NOISE", "EKF2_ACC_B_NOISE")
        if fmt == "px4"
        else ("EK3_GYRO_P_NSE", "EK3_ACC_P_NSE", "EK3_GBIAS_P_NSE", "EK3_ABIAS_P_NSE")
    )
    want = (
        worst(fits, GYROS, n_si),
        worst(fits, ACCELS, n_si),
        worst(fits, GYROS, k_si),
        worst(fits, ACCELS, k_si),
    )
    assert list(d) == list(names)
    for name, w in zip(names, want, strict=True):
        assert close(d[name], w * math.sqrt(rate)), name
        assert f"# {name} [" in text
    assert "warning" not in text  # the demo's values are inside the documented ranges


def test_autopilot_needs_rate_and_warns_out_of_range(fits) -> None:
    with pytest.raises(ExportError, match="filter rate"):
        export(None, fits, "px4", projection="fit")
    # inflate 200: EKF2_GYR_NOISE = 200 x 9.6e-4 rad/s > 0.1, its documented maximum
    with pytest.warns(UserWarning, match=r"EKF2_GYR_NOISE = .* outside .*\[0.0001, 0.1\]"):
        text = export(None, fits, "px4", projection="fit", filter_rate=100.0, inflate=200.0)
    assert "# warning: EKF2_GYR_NOISE" in text
    # a tiny value goes below EK3_GBIAS_P_NSE's documented minimum 1e-5
    with pytest.warns(UserWarning, match="EK3_GBIAS_P_NSE"):
        export(None, fits, "ardupilot", projection="fit", filter_rate=100.0, inflate=0.01)
    d1 = _px4(export(None, fits, "px4", projection="fit", filter_rate=100.0))
    d3 = _px4(export(None, fits, "px4", projection="fit", filter_rate=100.0, inflate=3.0))
    assert all(close(d3[k], 3.0 * d1[k]) for k in d1)


def test_cli_export_inflate_and_filter_rate(fits, tmp_path, capsys) -> None:
    from engine.cli import main

    out = tmp_path / "ekf.params"
    argv = ["export", str(demo_path()), "--model", "GM+WN+RW", "--projection", "fit"]
    argv += ["--format", "px4"]
    assert main([*argv, "-o", str(out), "--filter-rate", "250", "--inflate", "2"]) == 0
    text = out.read_text()
    assert "inflate = 2.0" in text and "filter rate 250.0 Hz" in text
    d = _px4(text)
    assert close(d["EKF2_GYR_NOISE"], 2.0 * worst(fits, GYROS, n_si) * math.sqrt(250.0))
    assert main([*argv, "-o", str(out)]) == 2  # no --filter-rate: a one-line error
    assert "filter rate" in capsys.readouterr().err
    assert main([*argv[:-1], "openvins", "-o", "-"]) == 0
    assert "rostopic: /imu0" in capsys.readouterr().out  # not a bag: the default topic


def test_cli_openvins_rostopic_is_the_bags_topic(tmp_path, capsys) -> None:
    from engine.cli import main
    from engine.io import write_imu_bag

    rng = np.random.default_rng(5)
    n = 4000
    bag = write_imu_bag(
        tmp_path / "imu.bag",
        1e-3 * rng.standard_normal((n, 3)),
        1e-2 * rng.standard_normal((n, 3)),
        np.arange(n, dtype=np.int64) * 10_000_000,
        topic="/drone/imu/data",
    )
    argv = ["export", str(bag), "--model", "WN+RW", "--format", "openvins", "-o", "-"]
    assert main(argv) == 0
    d = _cv_yaml(capsys.readouterr().out + "\n")["imu0"]
    assert d["rostopic"] == "/drone/imu/data" and d["update_rate"] == 100.0
    assert main([*argv, "--rostopic", "/other"]) == 0
    assert "rostopic: /other" in capsys.readouterr().out
    # the Python API: the log's topic when the log came from a bag
    blog = eg.load_log(bag)
    bfits = {c: eg.fit_gmwm(eg.wavelet_variance(blog[c], fs=blog.fs), "WN+RW") for c in blog.names}
    units = {c: blog.units.get(c) or ("rad/s" if "gyro" in c else "m/s^2") for c in blog.names}
    text = export(None, bfits, "kalibr", projection="fit", log=blog, units=units)
    assert yaml.safe_load(text)["rostopic"] == "/drone/imu/data"
    assert "rostopic: /imu0" in export(None, bfits, "openvins", projection="fit", units=units)


# ----------------------------------------------------------------------------- simulators, INS
def b_si(r: eg.GMWMResult) -> float:
    return ds(r, "bias instability (Allan floor, SI)", "B")


def tc(r: eg.GMWMResult) -> float:
    return ds(r, "correlation time", "T_c", "GM")


def sgm_si(r: eg.GMWMResult) -> float:
    return ds(r, "stationary std", "sigma_gm", "GM") * si_factor(r.wv.unit)[1]


def sq_si(r: eg.GMWMResult) -> float:
    return ds(r, "driving-noise density (SI)", "sqrt(q)", "GM")


def test_matlab(fits) -> None:
    text = export(None, fits, "matlab", projection="fit", inflate=1.5)
    assert re.search(r"^fs = 100\.0;", text, flags=re.MULTILINE)
    assert (
        "imuSensor('accel-gyro', 'SampleRate', fs, 'Gyroscope', gyro, 'Accelerometer', accel)"
        in text
    )
    for var, fn, chans in (("gyro", "gyroparams", GYROS), ("accel", "accelparams", ACCELS)):
        block = re.search(rf"{var} = {fn}\( \.\.\.\n(.*?\);)", text, flags=re.DOTALL).group(1)
        for key, f in (("NoiseDensity", n_si), ("RandomWalk", k_si), ("BiasInstability", b_si)):
            m = re.search(rf"'{key}', \[([^\]]+)\]", block)
            got = [float(v) for v in m.group(1).split()]
            assert all(close(g, 1.5 * f(fits[c])) for g, c in zip(got, chans, strict=True)), key
    assert "(rad/s)/sqrt(Hz)" in text and "(m/s^2)*sqrt(Hz)" in text


def test_gazebo_rotors(fits) -> None:
    import xml.etree.ElementTree as ET

    text = export(None, fits, "gazebo", projection="fit", inflate=2.0)
    root = ET.fromstring(text[text.index("<plugin") :])
    v = {e.tag: float(e.text) for e in root}
    for s, chans in (("gyroscope", GYROS), ("accelerometer", ACCELS)):
        assert close(v[f"{s}NoiseDensity"], 2.0 * worst(fits, chans, n_si))
        assert close(v[f"{s}RandomWalk"], 2.0 * worst(fits, chans, sq_si))  # GM, not RW
        assert v[f"{s}BiasRandomWalk"] == v[f"{s}RandomWalk"]  # RotorS's spelling too
        assert close(v[f"{s}BiasCorrelationTime"], worst(fits, chans, tc))  # not inflated
        assert v[f"{s}TurnOnBiasSigma"] == 0.0
    assert len(v) == 10
    assert 'filename="libgazebo_imu_plugin.so"' in text  # the file PX4-classic loads
    wn_rw = {c: eg.fit_gmwm(fits[c].wv, "WN+RW") for c in ("gyro_x", "accel_x")}
    with pytest.raises(ExportError, match="GM term"):
        export(None, wn_rw, "gazebo", projection="fit")


def test_kfgins(fits) -> None:
    d = yaml.safe_load(export(None, fits, "kf-gins", projection="fit"))["imunoise"]
    deg = math.pi / 180
    t_max = max(tc(r) for r in fits.values())

    def sgm_kept_q(r: eg.GMWMResult) -> float:
        # one corrtime (the largest) with each channel's driving noise 2 sigma^2 / T_c kept
        # (its own sigma_gm with the largest T_c under-bounded it)
        return sgm_si(r) * math.sqrt(t_max / tc(r))

    for key, chans, f, factor in (
        ("arw", GYROS, n_si, 60 / deg),  # rad/s/sqrt(Hz) -> deg/sqrt(h)
        ("vrw", ACCELS, n_si, 60.0),  # m/s^2/sqrt(Hz) -> m/s/sqrt(h)
        ("gbstd", GYROS, sgm_kept_q, 3600 / deg),  # rad/s -> deg/h
        ("abstd", ACCELS, sgm_kept_q, 1e5),  # m/s^2 -> mGal
    ):
        assert len(d[key]) == 3
        assert all(close(g, f(fits[c]) * factor) for g, c in zip(d[key], chans, strict=True)), key
    assert close(d["corrtime"], max(tc(r) for r in fits.values()) / 3600)


def test_ros_imu_covariance(fits) -> None:
    d = yaml.safe_load(export(None, fits, "ros-imu", projection="fit", inflate=3.0))
    assert d["orientation_covariance"][0] == -1.0
    for key, chans in (
        ("angular_velocity_covariance", GYROS),
        ("linear_acceleration_covariance", ACCELS),
    ):
        m = np.reshape(d[key], (3, 3))
        assert np.all(m[~np.eye(3, dtype=bool)] == 0)
        for i, c in enumerate(chans):  # per-sample variance = N^2 fs, x inflate^2
            assert close(m[i, i], 9.0 * n_si(fits[c]) ** 2 * fits[c].fs)


@pytest.mark.slow  # 12 filter exports: 37 s of CPU today
def test_every_registered_filter_format_records_inflate(fits) -> None:
    filt = ["kalibr", "openvins", "basalt", "orbslam3", "vins", "px4", "ardupilot", "matlab"]
    filt += ["gazebo", "gz-sim", "kf-gins", "ros-imu"]
    assert set(filt) | {"json", "csv", "datasheet", "datasheet-csv"} == set(FORMATS)
    for f in filt:
        assert "inflate = 1.25" in export(None, fits, f, inflate=1.25, filter_rate=100.0), f
