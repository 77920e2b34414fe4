"""engine.formats.projection: the rule, the over-bound and its least inflation, the intervals,
on simulated fits and on the real ADIS16405 log, and the filter formats that use it (every
file parses and has the consumer's keys; each consumer-convention fix).

The expected numbers are computed here from the fit's parameters with the docs/conventions.md
formulas (WN ``sigma2 / tau``, RW ``gamma2 (tau^2 + 2) / (12 tau)``, the AR1 formula through
the autocovariance identity), not with the code under test."""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

import engine as eg
from engine.demo import demo_path
from engine.formats import ExportError, export, project
from engine.formats.autopilot import RANGES

ADIS = Path("/work/shared/data/adis16405_imu1.h5")
DEG = math.pi / 180


def wn_wv(s2: float, tau: np.ndarray) -> np.ndarray:
    return s2 / tau


def rw_wv(g2: float, tau: np.ndarray) -> np.ndarray:
    return g2 * (tau**2 + 2) / (12 * tau)


def acov_wv(acov, tau: int) -> float:
    """Haar WV from an autocovariance: nu2 = sum_{l,m} h_l h_m gamma(l - m)."""
    h = np.r_[np.full(tau // 2, 1.0 / tau), np.full(tau // 2, -1.0 / tau)]
    lags = np.subtract.outer(np.arange(tau), np.arange(tau))
    return float(h @ acov(np.abs(lags)) @ h)


@pytest.fixture(scope="module")
def fast_gm_fit() -> eg.GMWMResult:
    """WN + a GM faster than one sample (T_c = 0.4 samples at 100 Hz), in rad/s."""
    m = eg.parse_model("GM(250, 4e-4)+WN(1e-4)")
    x = m.simulate(200_000, fs=100.0, rng=np.random.default_rng(3))
    return eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0, unit="rad/s"), "GM+WN")


def test_fast_gm_is_white_noise(fast_gm_fit) -> None:
    r = fast_gm_fit
    v = r.model.values()
    phi = math.exp(-v["GM.beta"] / 100.0)
    want = math.sqrt((v["WN.sigma2"] + v["GM.sigma2_gm"] * (1 + phi) / (1 - phi)) / 100.0)
    p = project(r, "WN+RW", bound=False, ci=None)
    assert math.isclose(p.value("N"), want, rel_tol=1e-12)
    assert p.assignment["GM"].startswith("WN")
    # bounded: the WN level whose WV bounds the GM's up to the horizon is its DC equivalent
    pb = project(r, "WN+RW", ci=None)
    assert math.isclose(pb.value("N"), want, rel_tol=2e-3)
    # the fit has no bias term: K is set (never 0) with a warning that says so
    assert pb.value("K") > 0 and "no bias term" in pb.warnings[0]


def test_ar1_wv_formula_in_test_matches_autocovariance() -> None:
    """The test's own cross-check of the GM WV (used below) against the acov identity."""
    phi, s2 = 0.9, 2.0
    acov = lambda k: s2 * phi**k  # noqa: E731 - stationary variance s2
    for tau in (2, 8, 32):
        got = eg.parse_model(f"GM({-math.log(phi)}, {s2})").wv(np.array([tau]), 1.0)[0]
        assert math.isclose(got, acov_wv(acov, tau), rel_tol=1e-10)


@pytest.fixture(scope="module")
def adis() -> dict[str, eg.GMWMResult]:
    if not ADIS.exists():
        pytest.skip("real ADIS16405 log not available")
    log = eg.load_log(ADIS)
    wv = eg.wavelet_variance(log["gyro_x"], fs=log.fs, unit=log.units["gyro_x"])
    return {s: eg.fit_gmwm(wv, s) for s in ("2*GM+WN+RW", "WN+RW", "GM+WN")}


def consumer_wv(p, tau: np.ndarray, fs: float) -> np.ndarray:
    """The exported WN+RW model's WV (rad/s)^2 from N and K alone."""
    return wn_wv(p.value("N") ** 2 * fs, tau) + rw_wv(p.value("K") ** 2 / fs, tau)


def test_adis_bound_holds_binds_and_does_not_blow_up(adis) -> None:
    r, ref = adis["2*GM+WN+RW"], adis["WN+RW"]
    fs = r.fs
    p = project(r, "WN+RW", channel="gyro_x")
    pr = project(ref, "WN+RW", bound=False, ci=None)
    assert r.model.values()["WN.sigma2"] == 0.0  # the defect: WN fitted at 0
    # N > 0 and close to the WN+RW fit's; K finite, no 8000x blow-up
    assert 1.0 < p.value("N") / pr.value("N") < 1.5
    assert 0.5 < p.value("K") / pr.value("K") < 3.0
    # the bound: consumer WV >= fitted WV (deg/s -> rad/s) at every even scale of the band
    lo, hi = p.band
    tau = np.unique(2 * np.round(np.geomspace(lo * fs, hi * fs, 4000) / 2))
    ratio = consumer_wv(p, tau, fs) / (r.model.wv(tau, fs) * DEG**2)
    assert ratio.min() >= 1 - 1e-4
    # tight (binding) at the reported scales
    for name in ("N", "K"):
        t = p.params[name].binding_tau_s * fs
        k = np.array([t])
        assert math.isclose(
            consumer_wv(p, k, fs)[0], r.model.wv(k, fs)[0] * DEG**2, rel_tol=2e-3
        ), name
    # every value carries its interval
    for q in p.params.values():
        assert q.low < q.value < q.high, q
    # GM+WN: no 8000x random walk any more (the sub-sample GM is white noise)
    g = project(adis["GM+WN"], "WN+RW", ci=None)
    assert g.value("K") < pr.value("K") and g.value("N") > 0


@pytest.fixture(scope="module")
def adis_accel() -> eg.GMWMResult:
    if not ADIS.exists():
        pytest.skip("real ADIS16405 log not available")
    log = eg.load_log(ADIS)
    return eg.fit_gmwm(eg.wavelet_variance(log["accel_x"], fs=log.fs), "2*GM+WN+RW")


@pytest.mark.parametrize("data", ["none", "low"])
@pytest.mark.parametrize("channel", ["gyro_x", "accel_x"])
def test_least_inflation_against_a_brute_force_grid(adis, adis_accel, channel, data) -> None:
    """The least inflation is the least geometric-mean ratio consumer WV / fitted WV over the
    band's scales (6 per octave, even samples) among the WN + RW whose WV bounds the fitted
    WV: the engine's optimum equals a grid search (for each N on a fine grid the least K is
    the max over scales of the shortfall / RW's WV). Values in the log's unit (``unit=""``).

    The first objective (the sum of squared factors over the plain conversion) fails here: on
    accel_x its K was x9 the WN+RW fit's and its geometric-mean ratio 12.2 against the
    optimum's 1.25 (gyro_x: 1.447 against 1.437).

    ``data="none"`` bounds the fitted WV alone (the former default); ``"low"`` (the
    default since) also the lower limit of the empirical 95 % interval at the WV's dyadic
    scales in the band, which then join the objective's scales with the larger target."""
    r = adis["2*GM+WN+RW"] if channel == "gyro_x" else adis_accel
    fs = r.fs
    p = project(r, "WN+RW", ci=None, horizon_s=2000.0, unit="", data=data)
    lo, hi = p.band[0] * fs, p.band[1] * fs
    td = np.asarray(r.wv.tau_samples, float)
    td = td[(td >= lo) & (td <= hi)] if data == "low" else td[:0]
    floor = dict(zip(td, np.asarray(r.wv.ci_low)[np.isin(r.wv.tau_samples, td)], strict=True))

    def tgt(t: np.ndarray) -> np.ndarray:
        return np.maximum(r.model.wv(t, fs), [floor.get(float(v), 0.0) for v in t])

    tau = np.unique(np.r_[2 * np.round(np.geomspace(lo, hi, 3000) / 2), td])
    target = tgt(tau)
    k = int(math.ceil(6 * math.log2(hi / lo))) + 1
    t_obj = np.unique(np.r_[2 * np.round(np.geomspace(lo, hi, k) / 2), td])
    w_obj = tgt(t_obj)

    def geo(s2: float, g2: float) -> float:
        return math.exp(np.mean(np.log((wn_wv(s2, t_obj) + rw_wv(g2, t_obj)) / w_obj)))

    best, arg = math.inf, (0.0, 0.0)
    n0 = p.params["N"].plain
    for n in np.linspace(0.5, 3.0, 5001) * n0:
        short = target - wn_wv(n * n * fs, tau)
        g2 = max(float(np.max(short / rw_wv(1.0, tau))), 0.0)
        g = geo(n * n * fs, g2)
        if g < best:
            best, arg = g, (n, math.sqrt(g2 * fs))
    got = geo(p.value("N") ** 2 * fs, p.value("K") ** 2 / fs)
    # the guarantee: the exported WV is at least the fitted WV at every scale of the band
    cw = wn_wv(p.value("N") ** 2 * fs, tau) + rw_wv(p.value("K") ** 2 / fs, tau)
    assert np.min(cw / target) >= 1 - 1e-4
    assert got <= best * (1 + 1e-3) and got >= best * (1 - 1e-3), (got, best)
    assert math.isclose(p.value("N"), arg[0], rel_tol=2e-3)
    assert math.isclose(p.value("K"), arg[1], rel_tol=2e-2)


def test_gm_consumer_bound_and_confidence(adis) -> None:
    r = adis["2*GM+WN+RW"]
    fs = r.fs
    p = project(r, "kf-gins", ci=None)
    assert p.consumer == "WN+GM"
    tau = np.unique(2 * np.round(np.geomspace(p.band[0] * fs, p.band[1] * fs, 2000) / 2))
    tc, sb = p.value("T_c"), p.value("sigma_b")
    gm = eg.parse_model(f"GM({1 / tc}, {sb**2})").wv(tau, fs)
    cw = wn_wv(p.value("N") ** 2 * fs, tau) + gm
    assert np.min(cw / (r.model.wv(tau, fs) * DEG**2)) >= 1 - 1e-4
    # confidence 0.95: the bound covers the upper limit of the eta3 interval (scipy's chi2)
    from scipy.stats import chi2

    p95 = project(r, "WN+RW", ci=None, confidence=0.95, horizon_s=1000.0)
    tau = np.unique(2 * np.round(np.geomspace(p95.band[0] * fs, p95.band[1] * fs, 2000) / 2))
    eta = np.maximum((r.wv.n - tau + 1) / tau, 1.0)
    upper = r.model.wv(tau, fs) * DEG**2 * eta / chi2.ppf(0.025, eta)
    assert np.min(consumer_wv(p95, tau, fs) / upper) >= 1 - 1e-4
    assert p95.value("K") > project(r, "WN+RW", ci=None, horizon_s=1000.0).value("K")
    with pytest.raises(ExportError, match="unknown consumer"):
        project(r, "nonsense")


# ----------------------------------------------------------------------------- the formats
@pytest.fixture(scope="module")
def demo_fits() -> dict[str, eg.GMWMResult]:
    log = eg.load_log(demo_path())
    return {
        c: eg.fit_gmwm(eg.wavelet_variance(log[c], fs=log.fs, unit=log.units[c]), "GM+WN+RW")
        for c in log.names
    }


def _cv(text: str) -> dict:
    assert text.startswith("%YAML:1.0\n")
    return yaml.safe_load(text.split("\n", 1)[1])


def test_every_filter_format_parses_with_positive_keys(demo_fits) -> None:
    kw = {"ci": None, "filter_rate": 100.0}
    k = yaml.safe_load(export(None, demo_fits, "kalibr", **kw))
    for key in ("gyroscope", "accelerometer"):
        assert k[f"{key}_noise_density"] > 0 and k[f"{key}_random_walk"] > 0
    o = _cv(export(None, demo_fits, "openvins", **kw))["imu0"]
    assert o["gyroscope_noise_density"] > 0 and o["accelerometer_random_walk"] > 0
    b = json.loads(export(None, demo_fits, "basalt", **kw))["value0"]
    assert all(v > 0 for v in b["gyro_noise_std"] + b["accel_bias_std"])
    orb = _cv(export(None, demo_fits, "orbslam3", **kw))
    assert type(orb["IMU.Frequency"]) is int and orb["IMU.Frequency"] == 100
    vins = _cv(export(None, demo_fits, "vins", **kw))
    assert math.isclose(vins["gyr_n"], k["gyroscope_noise_density"] * 10.0, rel_tol=1e-12)
    kf = yaml.safe_load(export(None, demo_fits, "kf-gins", **kw))["imunoise"]
    for key in ("arw", "vrw", "gbstd", "abstd", "gsstd", "asstd"):
        assert len(kf[key]) == 3 and min(kf[key]) > 0, key
    assert kf["corrtime"] > 0
    gz = export(None, demo_fits, "gazebo", **kw)
    root = ET.fromstring(gz[gz.index("<plugin") :])
    tags = {e.tag for e in root}
    assert {"gyroscopeBiasRandomWalk", "gyroscopeRandomWalk", "accelerometerRandomWalk"} <= tags
    assert root.get("filename") == "libgazebo_imu_plugin.so"
    sdf = export(None, demo_fits, "gz-sim", **kw)
    imu = ET.fromstring(sdf)  # the whole file: a comment, then the <imu> element
    sdf_names = {"mean", "stddev", "bias_mean", "bias_stddev", "dynamic_bias_stddev"}
    sdf_names.add("dynamic_bias_correlation_time")
    for tag in ("angular_velocity", "linear_acceleration"):
        for ax in "xyz":
            noise = imu.find(f"{tag}/{ax}/noise")
            assert noise.get("type") == "gaussian"
            assert {e.tag for e in noise} == sdf_names  # sdformat's element names
            assert float(noise.find("stddev").text) > 0
            assert float(noise.find("dynamic_bias_correlation_time").text) > 0
    ros = yaml.safe_load(export(None, demo_fits, "ros-imu", **kw))
    assert min(np.diag(np.reshape(ros["angular_velocity_covariance"], (3, 3)))) > 0
    # every header says what was projected and bounded, with intervals unless skipped
    text = export(None, demo_fits, "kalibr")
    assert "projected onto WN+RW" in text and "binding at tau" in text and "(95 %)" in text


def test_px4_vehicle_id_and_ardupilot_range(demo_fits) -> None:
    text = export(None, demo_fits, "px4", filter_rate=100.0, vehicle_id=7, ci=None)
    rows = [ln.split("\t") for ln in text.splitlines() if ln and not ln.startswith("#")]
    assert rows and all(r[0] == "7" and r[1] == "1" for r in rows)
    with pytest.raises(ExportError, match="vehicle_id"):
        export(None, demo_fits, "px4", filter_rate=100.0, vehicle_id=0, ci=None)
    assert RANGES["EK3_ABIAS_P_NSE"][4] == 0.02  # current ArduPilot documentation
    ap = export(None, demo_fits, "ardupilot", filter_rate=83.0, ci=None, projection="fit")
    assert "80-83 Hz" in ap and "clips or refuses" not in ap


def test_check_reads_nested_kalibr_and_openvins(demo_fits, tmp_path, capsys) -> None:
    from engine.cli import main

    ov = tmp_path / "kalibr_imu_chain.yaml"
    ov.write_text(export(None, demo_fits, "openvins", ci=None))
    nested = tmp_path / "imu-camchain.yaml"
    nested.write_text(
        "imu0:\n  accelerometer_noise_density: 0.0012\n  accelerometer_random_walk: 1.0e-4\n"
        "  gyroscope_noise_density: 9.6e-5\n  gyroscope_random_walk: 7.7e-6\n"
        "  rostopic: /imu0\n  update_rate: 100.0\n"
    )
    for f in (ov, nested):
        argv = ["check", str(demo_path()), "--channel", "gyro_x", "--datasheet-file", str(f)]
        assert main([*argv, "--json"]) == 0, capsys.readouterr().err
        d = json.loads(capsys.readouterr().out)
        assert d["datasheet"]["values"]["N"][0] > 0


def test_cli_export_projection_options(tmp_path, capsys) -> None:
    from engine.cli import main

    argv = ["export", str(demo_path()), "--model", "GM+WN+RW", "--format", "kalibr", "-o", "-"]
    assert main([*argv, "--no-intervals", "--horizon", "100", "--bound-confidence", "0.95"]) == 0
    out = capsys.readouterr().out
    assert "upper 95 % limit" in out and re.search(r"tau = 0\.02 \.\. 100 s", out)
    assert main([*argv, "--bound-band", "5:1"]) == 2
    assert "--bound-band" in capsys.readouterr().err


# ------------------------------------------------------------------------------ JSON report
def test_json_report_carries_the_projections_with_intervals_and_factors(demo_fits) -> None:
    """The JSON report holds, per channel and requested consumer, every
    exported value with its plain conversion, factor, binding scale and 95 % interval; the
    values are ``project``'s and their WV bounds the fitted WV (checked with this file's
    formulas, not the engine's)."""
    fits = {c: demo_fits[c] for c in ("gyro_x", "accel_x")}
    # data="none": the bound of the fitted WV alone, whose values all depend on the fit (the
    # default also bounds the data's lower limit; a value set by it has no
    # interval from the fit's covariance: checked at the end)
    rep = json.loads(export(None, fits, "json", data="none"))  # default: WN+RW
    assert rep["projection"]["mode"] == "bound" and rep["projection"]["consumers"] == ["WN+RW"]
    for ch, r in fits.items():
        d = rep["channels"][ch]["projections"]["WN+RW"]
        p = project(r, "WN+RW", channel=ch, data="none")
        assert d["consumer"] == "WN+RW" and d["bounded"] is True
        assert d["unit"] == ("rad/s" if ch.startswith("gyro") else "m/s^2")
        for name in ("N", "K"):
            q = d["params"][name]
            assert q["value"] == p.value(name)  # the engine's projection, to the bit
            assert q["low"] < q["value"] < q["high"] and q["level"] == 0.95
            # delta method on the log: the interval is symmetric in log
            assert math.isclose(q["high"] / q["value"], q["value"] / q["low"], rel_tol=1e-9)
            assert math.isclose(q["factor"], q["value"] / q["plain"], rel_tol=1e-12)
            assert q["binding_tau_s"] is not None and q["binds"]
        # the bound in the report's own numbers (SI -> the log's unit)
        f = 1.0 if r.wv.unit in ("rad/s", "m/s^2") else (DEG if ch.startswith("gyro") else 9.80665)
        fs = r.fs
        lo, hi = d["band_s"]
        tau = np.unique(2 * np.round(np.geomspace(lo * fs, hi * fs, 2000) / 2))
        n_, k_ = d["params"]["N"]["value"] / f, d["params"]["K"]["value"] / f
        cw = wn_wv(n_**2 * fs, tau) + rw_wv(k_**2 / fs, tau)
        assert np.min(cw / r.model.wv(tau, fs)) >= 1 - 1e-4
        assert d["inflation"]["geometric_mean"] >= 1.0
    # several consumers, by model or format name; plain; none with projection="fit"
    rep = json.loads(export(None, fits, "json", consumers=["kf-gins", "ros-imu"], ci=None))
    g = rep["channels"]["gyro_x"]["projections"]
    assert set(g) == {"kf-gins", "ros-imu"}
    assert (
        set(g["kf-gins"]["params"]) == {"N", "sigma_b", "T_c"} and g["ros-imu"]["consumer"] == "WN"
    )
    assert g["kf-gins"]["params"]["T_c"]["value"] > 0 and g["kf-gins"]["params"]["N"]["low"] is None
    plain = json.loads(export(None, fits, "json", projection="plain", ci=None))
    q = plain["channels"]["gyro_x"]["projections"]["WN+RW"]["params"]["K"]
    assert q["value"] == q["plain"] and q["factor"] == 1.0
    none = json.loads(export(None, fits, "json", projection="fit"))
    assert none["channels"]["gyro_x"]["projections"] == {}
    with pytest.raises(ExportError, match="unknown consumer"):
        export(None, fits, "json", consumers=["nonsense"])
    # the default (data="low"): a value bound by the empirical WV has no fit interval
    d = json.loads(export(None, fits, "json"))["channels"]["gyro_x"]["projections"]["WN+RW"]
    for q in d["params"].values():
        if "empirical WV" in q["binds"]:
            assert q["low"] is None and q["high"] is None
        else:
            assert q["low"] < q["value"] < q["high"]


def test_cli_json_report_consumers(capsys) -> None:
    from engine.cli import main

    argv = ["export", str(demo_path()), "--model", "GM+WN+RW", "--channels", "gyro_x"]
    argv += ["--format", "json", "-o", "-", "--no-intervals", "--partial"]
    assert main([*argv, "--consumer", "kalibr", "--consumer", "WN+GM"]) == 0
    d = json.loads(capsys.readouterr().out)["channels"]["gyro_x"]["projections"]
    assert set(d) == {"kalibr", "WN+GM"} and d["kalibr"]["params"]["K"]["value"] > 0
    assert main([*argv, "--consumer", "nonsense"]) == 2
    assert "unknown consumer 'nonsense'" in capsys.readouterr().err
