"""Datasheet check (engine.inference.datasheet_check, ``gmwm check``).

Expected values are computed here from docs/conventions.md's formulas (``sigma2 = N^2 fs``,
``gamma2 = K^2 / fs``, ``q2 = (Q fs)^2``, Haar WVs ``sigma2/tau``,
``gamma2 (tau^2 + 2) / (12 tau)``, ``6 q2 / tau^2``, bias-instability floor
``(0.664 B)^2 / 2``), not by the code under test.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.cli import main

D2R = math.pi / 180.0
FS = 100.0
# the simulated sensor's datasheet: ARW 0.3 deg/sqrt(h), RRW 20 deg/h/sqrt(h), Q 5e-4 deg
ARW, RRW, QDEG = 0.3, 20.0, 5e-4
DS_TEXT = f"arw={ARW} deg/sqrt(h), rrw={RRW} deg/h/sqrt(h), q={QDEG} deg"


def _truth_wv(tau: np.ndarray, arw: float = ARW) -> np.ndarray:
    """Haar WV [(deg/s)^2] of the datasheet's WN + RW + QN, by hand."""
    n = arw / 60.0  # (deg/s)/sqrt(Hz)
    k = RRW / 216000.0  # (deg/s)/sqrt(s)
    sigma2, gamma2, q2 = n * n * FS, k * k / FS, (QDEG * FS) ** 2
    return sigma2 / tau + gamma2 * (tau**2 + 2) / (12 * tau) + 6 * q2 / tau**2


def _simulate(seed: int, n: int = 200_000) -> np.ndarray:
    n_wn = ARW / 60.0
    m = eg.WN(sigma2=n_wn * n_wn * FS) + eg.RW(gamma2=(RRW / 216000.0) ** 2 / FS)
    m = m + eg.QN(q2=(QDEG * FS) ** 2)
    return m.simulate(n, rng=seed, fs=FS)


@pytest.fixture(scope="module")
def sims():
    return [eg.wavelet_variance(_simulate(s), fs=FS, unit="deg/s") for s in range(10)]


def test_datasheet_wv_matches_closed_forms(sims):
    wv = sims[0]
    chk = eg.check_datasheet(wv, DS_TEXT)
    tau = wv.tau_samples.astype(float)
    np.testing.assert_allclose(chk.datasheet_wv, _truth_wv(tau), rtol=1e-10)
    np.testing.assert_allclose(chk.datasheet_adev, np.sqrt(2 * _truth_wv(tau)), rtol=1e-10)
    np.testing.assert_allclose(chk.allan_tau_s, tau / 2 / FS)
    assert set(chk.components) == {"QN", "WN", "RW"}


def test_true_datasheet_inside_within_binomial_tolerance(sims):
    # If the datasheet is the true model, each scale is outside its 95 % interval with
    # probability about 0.05: over 10 logs x 17 scales (170 checks) about 8.5 outside, binomial
    # sd sqrt(170 * 0.05 * 0.95) = 2.8. Percival's eta3 interval is conservative (its degrees
    # of freedom M_j / 2^j are fewer than the true ones for these noises): measured 1 of these
    # 170 (3 of 340 on 20 seeds). The test allows the mean + 3 sd.
    outside = checks = 0
    for wv in sims:
        v = eg.check_datasheet(wv, DS_TEXT).verdict
        outside += sum(x != "inside" for x in v)
        checks += len(v)
    assert checks == 170
    bound = 0.05 * checks + 3 * math.sqrt(checks * 0.05 * 0.95)
    assert outside <= bound, (outside, bound)


def test_wrong_arw_flagged_above_at_small_scales(sims):
    # ARW x 3: the white-noise WV x 9, so the datasheet is far above the data where white
    # noise dominates (tau <= 5 s here), and not at the longest scales (RW dominates).
    wrong = DS_TEXT.replace(f"arw={ARW}", f"arw={3 * ARW}")
    for wv in sims[:3]:
        chk = eg.check_datasheet(wv, wrong)
        tau = wv.tau_samples.astype(float)
        np.testing.assert_allclose(chk.datasheet_wv, _truth_wv(tau, 3 * ARW), rtol=1e-10)
        small = wv.tau_s <= 5.0
        assert all(v == "above" for v, s in zip(chk.verdict, small, strict=True) if s)
        assert chk.verdict[-1] == "inside"
        s = chk.summary()
        assert s["bands"][0]["verdict"] == "above" and s["bands"][0]["tau_s_from"] == wv.tau_s[0]
        assert s["bands"][0]["ratio_min"] > 1.5


def test_verdict_invariants(sims):
    wv = sims[1]
    ds = eg.inference.parse_datasheet("arw=0.35 deg/sqrt(h), bi=2 deg/h")
    chk = eg.check_datasheet(wv, ds, fit=eg.fit_gmwm(wv, "QN+WN+RW"))
    lo, hi, d = chk.ci_low, chk.ci_high, chk.datasheet_wv
    for j, v in enumerate(chk.verdict):
        assert v == ("below" if d[j] < lo[j] else "above" if d[j] > hi[j] else "inside")
    s = chk.summary()
    assert s["inside"] + s["above"] + s["below"] == s["n_scales"] == wv.n_levels
    assert s["outside"] == sum(b["n_scales"] for b in s["bands"])
    assert s["expected_outside"] == pytest.approx(0.05 * wv.n_levels)
    # the bias-instability floor is the constant (0.664 B)^2 / 2, B = 2 deg/h in deg/s
    floor = (math.sqrt(2 * math.log(2) / math.pi) * 2.0 / 3600.0) ** 2 / 2
    np.testing.assert_allclose(chk.components["BI floor"], floor, rtol=1e-12)
    # the GMWM fit beside it: its own verdicts against the same interval
    assert chk.fit_wv is not None and chk.fit_verdict is not None
    assert s["fit_outside"] == sum(v != "inside" for v in chk.fit_verdict)
    # a wider level: the interval contains the 95 % one, so no scale moves outside
    c99 = eg.check_datasheet(wv, ds, level=0.99)
    assert np.all(c99.ci_low <= lo) and np.all(c99.ci_high >= hi)
    assert all(
        a == "inside" for a, b in zip(c99.verdict, chk.verdict, strict=True) if b == "inside"
    )
    d = chk.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["wv_unit"] == "(deg/s)^2" and d["adev_unit"] == "deg/s"
    assert len(d["verdict"]) == len(d["tau_s"]) == len(d["fit_wv"]) == wv.n_levels
    assert "above" in chk.table() or "below" in chk.table() or "inside" in chk.table()
    assert "(deg/s)^2" in chk.table()


def test_parse_spellings_and_units():
    a = eg.inference.parse_datasheet("arw=0.3 deg/sqrt(h)")
    assert eg.inference.parse_datasheet("arw=3e-1deg/sqrt(h)").values == a.values  # no space needed
    b = eg.inference.parse_datasheet("n=0.005 (deg/s)/sqrt(Hz)")
    c = eg.inference.parse_datasheet("ARW = 0.3 °/√hr")
    want = 0.3 / 60 * D2R  # rad/s/sqrt(Hz)
    for x in (a, b, c):
        assert x.kind == "gyroscope"
        assert x.values["N"] == pytest.approx(want, rel=1e-12)
    acc = eg.inference.parse_datasheet("vrw=0.2 m/s/sqrt(h), bi=0.2 mg, accrw=0.1 m/s/h/sqrt(h)")
    assert acc.kind == "accelerometer"
    assert acc.values["N"] == pytest.approx(0.2 / 60, rel=1e-12)
    assert acc.values["B"] == pytest.approx(0.2e-3 * 9.80665, rel=1e-12)
    assert acc.values["K"] == pytest.approx(0.1 / 216000, rel=1e-12)
    rrw = eg.inference.parse_datasheet("rrw=20 deg/h/sqrt(h)")
    assert rrw.values["K"] == pytest.approx(20 / 216000 * D2R, rel=1e-12)
    # in a log in deg/s the model has sigma2 = N^2 fs (N in deg/s/sqrt(Hz))
    m = a.model(FS, "deg/s")
    assert m is not None and m[0].values[0] == pytest.approx((0.3 / 60) ** 2 * FS, rel=1e-12)


@pytest.mark.parametrize(
    "text, msg",
    [
        ("arw=0.3", "has no unit"),
        ("arw 0.3 deg/sqrt(h)", "KEY=VALUE UNIT"),
        ("foo=1 deg/h", "unknown datasheet key"),
        ("arw=0.3 m/s/sqrt(h)", "is a gyroscope value"),
        ("arw=0.3 deg/h", "not a unit of N"),
        ("arw=0.3 deg/sqrt(h), bi=5 deg/h, bi=6 deg/h", "second time"),
        ("arw=0.3 deg/sqrt(h) (adev min)", "for bi only"),
        ("arw=-1 deg/sqrt(h)", "non-negative"),
        ("arw=0.3 deg/sqrt(h), n=0.005 deg/s/sqrt(Hz)", "second time"),
        ("", "no value"),
        ("arw=1..2 deg/sqrt(h)", "KEY=VALUE UNIT"),
        ("arw=abc deg/sqrt(h)", "KEY=VALUE UNIT"),
    ],
)
def test_parse_errors(text, msg):
    with pytest.raises(eg.errors.DatasheetError, match=msg):
        eg.inference.parse_datasheet(text)


def test_unit_errors(sims):
    wv = sims[0]
    with pytest.raises(eg.errors.DatasheetError, match="accelerometer"):
        eg.check_datasheet(wv, "vrw=0.2 m/s/sqrt(h)")
    nounit = eg.wavelet_variance(_simulate(0, 5000), fs=FS)
    with pytest.raises(eg.errors.DatasheetError, match="unit"):
        eg.check_datasheet(nounit, DS_TEXT)
    with pytest.raises(eg.errors.DatasheetError, match="level"):
        eg.check_datasheet(wv, DS_TEXT, level=1.5)


@pytest.fixture(scope="module")
def gyro_fit(sims):
    return eg.fit_gmwm(sims[0], "WN+RW")


def _fit_nk(fit) -> tuple[float, float]:
    """N [rad/s/sqrt(Hz)] and K [rad/s^2/sqrt(Hz)] of a deg/s fit, by hand."""
    p = fit.params
    return math.sqrt(p["WN.sigma2"] / FS) * D2R, math.sqrt(p["RW.gamma2"] * FS) * D2R


def test_reader_round_trip_kalibr(tmp_path, gyro_fit):
    path = tmp_path / "imu.yaml"
    eg.export(path, {"gyro_x": gyro_fit}, "kalibr", allow_partial=True, projection="fit")
    ds = eg.inference.read_datasheet(path, channel="gyro_x")
    n, k = _fit_nk(gyro_fit)
    assert ds.kind == "gyroscope"
    assert ds.values["N"] == pytest.approx(n, rel=1e-9)
    assert ds.values["K"] == pytest.approx(k, rel=1e-9)
    # the file's model is the fit's: same WV at every scale
    chk = eg.check_datasheet(gyro_fit.wv, ds)
    np.testing.assert_allclose(chk.datasheet_wv, gyro_fit.implied, rtol=1e-8)


@pytest.mark.parametrize("fmt, suffix", [("json", ".json"), ("datasheet-csv", ".csv")])
def test_reader_round_trip_reports(tmp_path, gyro_fit, fmt, suffix):
    path = tmp_path / f"report{suffix}"
    eg.export(path, {"gyro_x": gyro_fit}, fmt)
    ds = eg.inference.read_datasheet(path)
    # the file's only channel is read whatever the log's channel is called
    assert eg.inference.read_datasheet(path, channel="gyro_y").values == ds.values
    n, k = _fit_nk(gyro_fit)
    assert ds.values["N"] == pytest.approx(n, rel=1e-9)
    assert ds.values["K"] == pytest.approx(k, rel=1e-9)
    assert "B" in ds.values  # the fit's bias-instability (Allan floor) row


def test_reader_round_trip_own_json(tmp_path):
    ds = eg.inference.parse_datasheet("arw=0.3 deg/sqrt(h), bi=5 deg/h, q=1e-4 deg")
    p = tmp_path / "ds.json"
    p.write_text(json.dumps(ds.to_dict()))
    back = eg.inference.read_datasheet(p)
    assert back.kind == ds.kind
    for s, v in ds.values.items():
        assert back.values[s] == pytest.approx(v, rel=1e-12)


def test_reader_errors_name_file_and_key(tmp_path):
    bad = tmp_path / "imu.yaml"
    bad.write_text("update_rate: 100.0\ngyroscope_noise_density: abc\n")
    with pytest.raises(eg.errors.DatasheetError, match=r"imu\.yaml.*gyroscope_noise_density"):
        eg.inference.read_datasheet(bad)
    both = tmp_path / "both.yaml"
    both.write_text(
        "update_rate: 100.0\ngyroscope_noise_density: 1.0e-4\naccelerometer_noise_density: 1.0e-3\n"
    )
    with pytest.raises(eg.errors.DatasheetError, match="choose one"):
        eg.inference.read_datasheet(both)
    assert eg.inference.read_datasheet(both, kind="accelerometer").values == {"N": 1e-3}
    with pytest.raises(eg.errors.DatasheetError, match="cannot read"):
        eg.inference.read_datasheet(tmp_path / "missing.yaml")
    other = tmp_path / "x.json"
    other.write_text('{"schema": "other"}')
    with pytest.raises(eg.errors.DatasheetError, match=r"x\.json.*unknown JSON"):
        eg.inference.read_datasheet(other)
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    with pytest.raises(eg.errors.DatasheetError, match="unknown datasheet file"):
        eg.inference.read_datasheet(txt)


# --------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def sim_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("check") / "sim.h5"
    eg.io.save_log(path, {"gyro_x": _simulate(7, 100_000)}, FS, units={"gyro_x": "deg/s"})
    return path


def test_cli_json(capsys, sim_log):
    code = main(["check", str(sim_log), "--datasheet", DS_TEXT, "--model", "WN+RW", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    d = json.loads(out)
    for key in (
        "datasheet",
        "tau_s",
        "empirical_wv",
        "ci_low",
        "ci_high",
        "datasheet_wv",
        "empirical_adev",
        "datasheet_adev",
        "verdict",
        "summary",
        "fit_wv",
        "fit_verdict",
        "channel",
        "wv_unit",
    ):
        assert key in d
    tau = np.asarray(d["tau_samples"], float)
    np.testing.assert_allclose(d["datasheet_wv"], _truth_wv(tau), rtol=1e-10)
    assert d["summary"]["outside"] <= 3
    assert d["datasheet"]["schema"] == "gmwm-datasheet/1"
    code = main(["check", str(sim_log), "--datasheet", DS_TEXT])
    out, _ = capsys.readouterr()
    assert code == 0 and "verdict" in out and "(deg/s)^2" in out


def test_cli_datasheet_file(capsys, sim_log, tmp_path):
    p = tmp_path / "ds.json"
    p.write_text(json.dumps(eg.inference.parse_datasheet(DS_TEXT).to_dict()))
    assert main(["check", str(sim_log), "--datasheet-file", str(p), "--json"]) == 0
    d = json.loads(capsys.readouterr()[0])
    tau = np.asarray(d["tau_samples"], float)
    np.testing.assert_allclose(d["datasheet_wv"], _truth_wv(tau), rtol=1e-10)


@pytest.mark.parametrize(
    "extra, msg",
    [
        (["--datasheet", "arw=0.3"], "no unit"),
        (["--datasheet", "vrw=0.2 m/s/sqrt(h)"], "accelerometer"),
        (["--datasheet", DS_TEXT, "--level", "2"], "--level"),
        (["--datasheet-file", "/nonexistent/imu.yaml"], "cannot read"),
        ([], "required"),
        (["--datasheet", DS_TEXT, "--model", "XX"], ""),
    ],
)
def test_cli_bad_input_exit_2(capsys, sim_log, extra, msg):
    code = main(["check", str(sim_log), *extra])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and msg in err


# --------------------------------------------------------------------------- real log
# ADIS16405 datasheet values (Analog Devices ADIS16405 data sheet, as quoted in
# https://ez.analog.com/thread/13821 "In-Run Bias Stability: 0.007 deg/sec", and as used by
# NaveGo's ADIS16405 error profile, github.com/rodralez/NaveGo examples: arw = 2
# deg/root-hour, gb_dyn = 0.007 deg/s): ARW 2 deg/sqrt(h), in-run bias stability 0.007 deg/s
# = 25.2 deg/h.
ADIS_DS = "arw=2 deg/sqrt(h), bi=25.2 deg/h"


def test_real_adis16405_gyro_departs(real_data):
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    # datasheet WV by hand: sigma2 = (2/60 deg/s/sqrt(Hz))^2 fs, floor (0.664 x 0.007)^2 / 2
    floor = (math.sqrt(2 * math.log(2) / math.pi) * 0.007) ** 2 / 2
    for ch in ("gyro_x", "gyro_z"):
        wv = eg.wavelet_variance(log[ch], fs=log.fs, unit=log.units[ch])
        chk = eg.check_datasheet(wv, ADIS_DS)
        tau = wv.tau_samples.astype(float)
        np.testing.assert_allclose(chk.datasheet_wv, (2 / 60) ** 2 * log.fs / tau + floor)
        v = chk.verdict
        assert wv.n_levels == 19
        # where it departs (measured on replicate 1): the datasheet is optimistic (below the
        # empirical interval) from 0.04 s to 655 s on both axes
        assert all(x == "below" for x in v[1:15]), v
        if ch == "gyro_x":
            # above at 0.02 s: the sensor's own filter lowers the level-1 WV below white
            # noise's; inside at the three longest scales, where the interval is wide
            assert v[0] == "above" and v[15:] == ("below", "inside", "inside", "inside")
        else:
            # gyro_z drifts: below at every scale, 20 x under the data at 5243 s
            assert set(v) == {"below"}
            assert chk.ratio[-1] < 0.06
        # the datasheet's white noise is below the data at 0.1-10 s by 0.6-0.8 in WV
        mid = (wv.tau_s > 0.1) & (wv.tau_s < 10)
        assert np.all((chk.ratio[mid] > 0.6) & (chk.ratio[mid] < 0.8)), chk.ratio[mid]


def test_real_navchip_reproduces_the_case_study(real_data):
    # README case study "NavChip gyroscope" (tests/benchmarks/case_navchip.py, which now calls
    # check_datasheet itself; these figures were first read off its own formulas): datasheet
    # ARW 0.003 (deg/s)/sqrt(Hz), BI 10 deg/h; below the interval at 17
    # of 20 scales, above at the 3 scales 0.26-1 s; GMWM (the paper's model) outside at 8.
    log = eg.load_log(real_data / "derived" / "navchip_wv_av.h5")
    wv = log.wv["gyro_x"]
    chk = eg.check_datasheet(
        wv, "n=0.003 deg/s/sqrt(Hz), bi=10 deg/h", fit=eg.fit_gmwm(wv, "QN+WN+2*GM+RW+DR")
    )
    n, b = 0.003 * D2R, 10 / 3600 * D2R  # rad/s/sqrt(Hz), rad/s
    floor = (math.sqrt(2 * math.log(2) / math.pi) * b) ** 2 / 2
    np.testing.assert_allclose(chk.datasheet_wv, n * n * wv.fs / wv.tau_samples + floor)
    s = chk.summary()
    assert (s["below"], s["above"], s["fit_outside"]) == (17, 3, 8)
    above = [band for band in s["bands"] if band["verdict"] == "above"]
    assert len(above) == 1 and above[0]["tau_s_from"] == pytest.approx(0.256)
    assert above[0]["tau_s_to"] == pytest.approx(1.024)


def test_gyroscope_and_accelerometer_items_together(tmp_path):
    """A full datasheet (this once failed with "'vrw' gives N a second time"): each
    channel is checked against its own sensor's part; bi may come once per sensor."""
    text = "arw=2 deg/sqrt(h), bi=25.2 deg/h, vrw=0.2 m/s/sqrt(h), bi=0.2 mg"
    spec = eg.inference.parse_datasheet(text)
    assert spec.kinds == ("gyroscope", "accelerometer")
    gyro, acc = spec.for_kind("gyroscope"), spec.for_kind("accelerometer")
    # 2 deg/sqrt(h) = 2/60 deg/s/sqrt(Hz) = 5.8178e-4 rad/s/sqrt(Hz); 0.2 m/s/sqrt(h) =
    # 0.2/60 m/s^2/sqrt(Hz); 0.2 mg = 0.2e-3 x 9.80665 m/s^2
    assert gyro.values["N"] == pytest.approx(2 / 60 * math.pi / 180, rel=1e-12)
    assert gyro.values["B"] == pytest.approx(25.2 / 3600 * math.pi / 180, rel=1e-12)
    assert acc.values["N"] == pytest.approx(0.2 / 60, rel=1e-12)
    assert acc.values["B"] == pytest.approx(0.2e-3 * 9.80665, rel=1e-12)
    assert spec.describe() == "ARW 2 deg/sqrt(h), B 25.2 deg/h; VRW 0.2 m/s/sqrt(h), B 0.2 mg"
    rng = np.random.default_rng(4)
    x = eg.WN(sigma2=1e-4).simulate(2**12, rng=rng, fs=100.0)
    chk_g = eg.check_datasheet(eg.wavelet_variance(x, fs=100.0, unit="deg/s"), spec)
    chk_a = eg.check_datasheet(eg.wavelet_variance(x, fs=100.0, unit="g"), spec)
    assert chk_g.datasheet.kind == "gyroscope" and chk_a.datasheet.kind == "accelerometer"
    # the check of one kind uses that kind's values: WV of WN N^2/dt / tau in the signal unit
    n_deg = 2 / 60
    assert chk_g.components["WN"][0] == pytest.approx(n_deg**2 * 100.0 / 2, rel=1e-9)
    with pytest.raises(eg.errors.DatasheetError, match="no accelerometer value"):
        eg.inference.parse_datasheet("arw=2 deg/sqrt(h)").for_kind("accelerometer")
    saved = tmp_path / "ds.json"  # the saved form keeps both parts
    saved.write_text(json.dumps(spec.to_dict()))
    assert eg.inference.read_datasheet(saved, kind="accelerometer").values == pytest.approx(
        acc.values
    )
    assert eg.inference.read_datasheet(saved, kind="gyroscope").values == pytest.approx(gyro.values)


@pytest.mark.parametrize(
    "text",
    ["bi_min=25.2 deg/h", "bis=25.2 deg/h", "bi=25.2 deg/h (ADEV min)", "adev_min=25.2 deg/h"],
)
def test_bias_instability_declared_as_the_adev_minimum(text):
    """A vendor's in-run bias stability is the ADEV minimum itself: its floor is drawn at
    25.2 deg/h, not at 0.664 x 25.2 = 16.7 deg/h as for an IEEE B."""
    spec = eg.inference.parse_datasheet(text)
    ieee = eg.inference.parse_datasheet("bi=25.2 deg/h")
    assert spec.bi_convention == "adev_min" and ieee.bi_convention == "ieee"
    floor = math.sqrt(2 * spec.floor_wv("deg/s")) * 3600  # ADEV of the floor, deg/h
    assert floor == pytest.approx(25.2, rel=1e-12)
    assert math.sqrt(2 * ieee.floor_wv("deg/s")) * 3600 == pytest.approx(
        25.2 * eg.units.BI_FACTOR, rel=1e-12
    )
    assert "ADEV minimum 25.2 deg/h" in spec.describe()
    assert eg.inference.parse_datasheet("bi=25.2 deg/h (ieee)").bi_convention == "ieee"
