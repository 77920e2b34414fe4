"""Filter files against their own claims, on the real ADIS16405 log.

Every filter format is written, read back by the reader ``gmwm check`` uses
(:func:`engine.formats.readers.read_check_file`), and the noise model the file states is
compared with what its header claims: for a bounded file, its WV (computed here from the
values read back, with the docs/conventions.md formulas through ``Model.wv``) is at least the
fitted model's WV and the lower end of the empirical 95 % interval at every dyadic scale of the
band (two filter steps to the horizon); for ``sensor_msgs/Imu``, the white part only. Then
``gmwm check`` reads the same file against the log (exit 0).
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
import yaml

import engine as eg
from engine.cli import main
from engine.formats import FORMATS, export
from engine.formats.readers import read_check_file, read_filter_noise
from engine.units import si_factor

MODELS = ("WN+RW", "2*GM+WN+RW")
FILTERS = [k for k, f in FORMATS.items() if f.is_filter]


@pytest.fixture(scope="module")
def adis(real_data):
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    fits = {
        m: {c: eg.fit_gmwm(log.wavelet_variance(c), m) for c in ("gyro_x", "accel_x")}
        for m in MODELS
    }
    return log, fits


def _write(tmp_path, fits, fmt, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # range warnings of PX4/ArduPilot: tested elsewhere
        text = export(None, fits, fmt, ci=None, filter_rate=kw.pop("filter_rate", 100.0), **kw)
    path = tmp_path / f"{fmt}{FORMATS[fmt].suffix}"
    path.write_text(text)
    return path, text


@pytest.mark.real_data
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("fmt", [*FILTERS, "json", "datasheet-csv"])
def test_every_format_round_trips_through_check_and_keeps_its_claim(
    adis, fmt, model, tmp_path, capsys
) -> None:
    log, all_fits = adis
    fits = all_fits[model]
    path, text = _write(tmp_path, fits, fmt)
    for ch, r in fits.items():
        kind = "gyroscope" if ch.startswith("gyro") else "accelerometer"
        spec = read_check_file(path, channel=ch, kind=kind, fs=log.fs)
        assert spec.kind == kind
        m = spec.model(log.fs, log.units[ch])
        tau = np.asarray(r.wv.tau_samples, float)
        band = (tau >= 2.0) & (tau / log.fs <= log.n / log.fs)
        fw = m.wv(tau[band], log.fs)
        if fmt == "datasheet-csv":  # the fit itself, GM terms included (defect 5: read as N 0)
            assert np.allclose(fw, r.model.wv(tau[band], log.fs), rtol=1e-6, atol=0)
            continue
        if fmt == "ros-imu":  # claims the white part only: WV >= that of the white terms
            assert "NOT the bias terms" in text
            p = eg.formats.project(r, "WN", ci=None, channel=ch)
            f_si = math.pi / 180 if kind == "gyroscope" else 9.80665
            n_file = spec.values["N"]
            assert math.isclose(n_file, p.value("N"), rel_tol=1e-9)
            ts = p.tau_s * log.fs
            assert np.all((n_file / f_si) ** 2 * log.fs / ts >= p.target_wv / f_si**2 * (1 - 1e-9))
            continue
        # the header's claim: >= the fitted WV and the data's lower limit over the band
        assert "empirical WV's lower 95 % limit" in text or fmt == "json"
        target = np.maximum(r.model.wv(tau[band], log.fs), np.asarray(r.wv.ci_low)[band])
        assert np.all(fw >= target * (1 - 1e-6)), (ch, (fw / target).min())
    argv = ["check", str(log.source), "--channel", "gyro_x", "--datasheet-file", str(path)]
    assert main([*argv, "--json"]) == 0, capsys.readouterr().err
    d = json.loads(capsys.readouterr().out)
    assert d["summary"]["n_scales"] == 19


def test_hand_written_consumer_files_are_read() -> None:
    """Files as the consumers' users write them: OpenCV ``%YAML:1.0`` with an
    ``!!opencv-matrix`` (VINS, ORB-SLAM3) and a QGroundControl ``.params`` dump with
    EKF2_PREDICT_US; values converted back with the consumer's own convention."""
    vins = (
        "%YAML:1.0\nimu: 1\nextrinsicRotation: !!opencv-matrix\n   rows: 3\n   cols: 3\n"
        "   dt: d\n   data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
        "acc_n: 0.1          # accelerometer measurement noise standard deviation.\n"
        "gyr_n: 0.01\nacc_w: 0.001\ngyr_w: 0.0001\ng_norm: 9.81007\n"
    )
    fn = read_filter_noise(vins, fs=200.0)
    assert fn.fmt == "vins" and fn.rate == 200.0
    assert math.isclose(fn.values["accelerometer"]["*"]["N"], 0.1 / math.sqrt(200.0))
    assert math.isclose(fn.values["gyroscope"]["*"]["K"], 0.0001 / math.sqrt(200.0))
    orb = (
        '%YAML:1.0\nCamera.type: "PinHole"\nIMU.T_b_c1: !!opencv-matrix\n   rows: 4\n'
        "   cols: 4\n   dt: f\n   data: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n"
        "IMU.NoiseGyro: 1.7e-4 # 1.6968e-04\nIMU.NoiseAcc: 2.0000e-3\n"
        "IMU.GyroWalk: 1.9393e-05\nIMU.AccWalk: 3.0000e-03\nIMU.Frequency: 200.0\n"
    )
    fn = read_filter_noise(orb)
    assert fn.fmt == "orbslam3" and fn.values["gyroscope"]["*"] == {"N": 1.7e-4, "K": 1.9393e-5}
    px4 = (
        "# Onboard parameters for Vehicle 1\n#\n# Vehicle-Id Component-Id Name Value Type\n"
        "1\t1\tEKF2_ACC_B_NOISE\t0.003000000026077032\t9\n1\t1\tEKF2_ACC_NOISE\t0.34999999\t9\n"
        "1\t1\tEKF2_GYR_B_NOISE\t0.0010000000474974513\t9\n1\t1\tEKF2_GYR_NOISE\t0.015\t9\n"
        "1\t1\tEKF2_PREDICT_US\t5000\t6\n"
    )
    fn = read_filter_noise(px4)
    assert fn.fmt == "px4" and fn.rate == 200.0
    assert math.isclose(fn.values["gyroscope"]["*"]["N"], 0.015 / math.sqrt(200.0))
    fn = read_filter_noise(px4.replace("1\t1\tEKF2_PREDICT_US\t5000\t6\n", ""))
    assert fn.rate == 100.0 and "assumed" in fn.notes[0]


@pytest.mark.real_data
def test_filter_rate_is_honoured_by_every_writer(adis, tmp_path) -> None:
    """Defect 4: per-sample values scale with sqrt(rate), densities do not, the rate is
    written; a rate above the log's and a term that changes role are warned about; PX4 states
    EKF2_PREDICT_US."""
    log, all_fits = adis
    fits = all_fits["WN+RW"]
    got = {}
    for rate in (100.0, 200.0, 400.0):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            vins = export(None, fits, "vins", ci=None, filter_rate=rate)
            kal = export(None, fits, "kalibr", ci=None, filter_rate=rate, allow_partial=True)
            ros = export(None, fits, "ros-imu", ci=None, filter_rate=rate)
            gz = export(None, fits, "gz-sim", ci=None, filter_rate=rate)
            px4 = export(None, fits, "px4", ci=None, filter_rate=rate)
        msgs = [str(w.message) for w in caught]
        assert any("exceeds the log's 100 Hz" in m for m in msgs) == (rate > 100.0)
        v = yaml.safe_load(vins.split("\n", 1)[1])
        k = yaml.safe_load(kal)
        r = yaml.safe_load(ros)
        sd = read_filter_noise(gz)
        assert k["update_rate"] == rate and sd.rate == rate
        assert f"EKF2_PREDICT_US = {1e6 / rate:g} us" in px4
        got[rate] = (v["gyr_n"], k["gyroscope_noise_density"], r["angular_velocity_covariance"][0])
    for rate, (gyr_n, n, _) in got.items():
        # per sample at the consumer's rate: VINS N sqrt(rate), ROS N^2 rate (the white part)
        assert math.isclose(gyr_n, n * math.sqrt(rate), rel_tol=1e-9)
    # the white part (the WN term) is rate-free as a density: ROS covariance / rate constant
    assert math.isclose(got[100.0][2] / 100.0, got[400.0][2] / 400.0, rel_tol=1e-9)
    # the density is the same at every rate here (the band starts at 2 log samples), so VINS
    # gyr_n doubles from 100 to 400 Hz (it was identical at every --filter-rate before)
    assert math.isclose(got[400.0][0] / got[100.0][0], 2.0, rel_tol=1e-9)
    # at 200 Hz (step 5 ms) the 5.5 ms GM of gyro_x is bias, not white noise: said
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        export(None, all_fits["2*GM+WN+RW"], "kalibr", ci=None, filter_rate=200.0)
    assert any("GM_2 changes role" in str(w.message) for w in caught)


@pytest.mark.real_data
def test_kf_gins_one_bias_model_bounds_every_channel(real_data, tmp_path) -> None:
    """Defect 3: KF-GINS takes one corrtime; the file's Gauss-Markov bias (that corrtime with
    each axis's gbstd/abstd) and N bound every channel's fitted WV and the data's lower limit
    over the band. Before: the largest T_c (1e5 s) with per-channel sigma_b for their own T_c,
    file WV 0.065-0.15 of the fitted gyro WV at 160-5000 s."""
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    fits = {c: eg.fit_gmwm(log.wavelet_variance(c), "2*GM+WN+RW") for c in log.names}
    path, text = _write(tmp_path, fits, "kf-gins")
    d = yaml.safe_load(text)["imunoise"]
    assert "one T_c" in text and isinstance(d["corrtime"], float)
    for ch, r in fits.items():
        kind = "gyroscope" if ch.startswith("gyro") else "accelerometer"
        spec = read_check_file(path, channel=ch, kind=kind, fs=log.fs)
        assert spec.gm[0][0] == pytest.approx(d["corrtime"] * 3600.0)
        tau = np.asarray(r.wv.tau_samples, float)
        band = tau >= 2.0
        fw = spec.model(log.fs, log.units[ch]).wv(tau[band], log.fs)
        target = np.maximum(r.model.wv(tau[band], log.fs), np.asarray(r.wv.ci_low)[band])
        assert np.all(fw >= target * (1 - 1e-6)), (ch, (fw / target).min())


@pytest.mark.real_data
def test_kf_gins_unbounded_projections_are_what_the_file_writes(adis, tmp_path) -> None:
    """Without the bound KF-GINS's file takes the largest T_c and keeps each channel's driving
    noise; the projections (what the app's preview shows, ``engine.formats.projections``)
    carry the same T_c, sigma_b and consumer WV as the file read back. Before: each channel's
    own T_c and sigma_b (gyro_x's and accel_x's T_c differ on ADIS imu1)."""
    log, all_fits = adis
    fits = all_fits["2*GM+WN+RW"]
    projs = eg.formats.projections(fits, "kf-gins", projection="plain", ci=None, log=log)
    path, text = _write(tmp_path, fits, "kf-gins", projection="plain", log=log)
    tc = yaml.safe_load(text)["imunoise"]["corrtime"] * 3600.0
    own = []
    for ch, p in projs.items():
        kind = "gyroscope" if ch.startswith("gyro") else "accelerometer"
        spec = read_check_file(path, channel=ch, kind=kind, fs=log.fs)
        ((tc_file, _sigma_b),) = spec.gm
        assert p.value("T_c") == pytest.approx(tc, rel=1e-9) == tc_file
        own.append(p.params["T_c"].plain)
        # the file's WV (its N and its Gauss-Markov bias, read back) is the preview's
        fw = spec.model(log.fs, log.units[ch]).wv(p.tau_s * log.fs, log.fs)
        si = si_factor(log.units[ch])[1]
        np.testing.assert_allclose(p.consumer_wv, fw * si**2, rtol=1e-6)
    assert tc == pytest.approx(max(own), rel=1e-9) and min(own) < 0.9 * max(own)
