"""The calibration report of a log with a temperature channel: per channel the bias-temperature
sensitivity with its interval in datasheet units (deg/h per degC, mg per degC), the fit of the
compensated signal, and both wavelet variances (raw and compensated) on the channel's WV
figure; the report's JSON carries the temperature fit. A log without a temperature channel
shows nothing new."""

from __future__ import annotations

import html
import re

import numpy as np
import pytest

import engine as eg
from engine.inference.temperature import temperature_sensitivity
from engine.reporting import gather_report, render_html
from engine.reporting.render import figure_specs

FS = 100.0
N = 200_000  # 33 min at 100 Hz
GYRO_C = 2e-3  # deg/s per degC = 7.2 deg/h per degC
ACCEL_C = 1e-4  # g per degC = 0.1 mg per degC
GYRO = "WN(sigma2=1e-4)+RW(gamma2=1e-10)"  # (deg/s)^2
ACCEL = "WN(sigma2=1e-6)+RW(gamma2=1e-13)"  # g^2

SENS_RE = re.compile(
    r'<p class="temperature" data-channel="([^"]+)">Temperature sensitivity\s*'
    r'<span class="sensitivity" data-value="([^"]+)">[^<]*</span>\s*'
    r'\[<span class="low" data-value="([^"]+)">[^<]*</span>,\s*'
    r'<span class="high" data-value="([^"]+)">[^<]*</span>\]\s*'
    r'<span class="unit">([^<]*)</span>'
)


def thermal_profile(n: int = N) -> np.ndarray:
    """Warm-up from 25 to 35 degC (time constant 300 s) with a 2 degC cycle of 600 s (the
    profile of tests/engine/test_temperature_compensation.py and temperature_mc.py)."""
    t = np.arange(n) / FS
    return 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sin(2 * np.pi * t / 600)


@pytest.fixture(scope="module")
def thermal():
    """A gyro (deg/s) and an accelerometer (g) with planted sensitivities, the temperature as
    an auxiliary channel; the report with the temperature channel found (``auto``)."""
    temp = thermal_profile()
    gx = eg.parse_model(GYRO).simulate(N, fs=FS, rng=11) + GYRO_C * temp
    ax = eg.parse_model(ACCEL).simulate(N, fs=FS, rng=12) + ACCEL_C * temp
    log = eg.ImuLog(
        {"gyro_x": gx, "accel_x": ax},
        FS,
        units={"gyro_x": "deg/s", "accel_x": "g"},
        aux={"imu_temp": temp},
        source="thermal.h5",
    )
    rep = gather_report(log, model="WN+RW", export_format=None, temperature="auto")
    return log, rep, render_html(rep), rep.to_dict()


def test_page_and_json_give_the_planted_sensitivity_in_datasheet_units(thermal):
    """The sensitivity on the page (value and 95 % interval, full precision in data-value) is
    the JSON's, in deg/h/degC for the gyro and mg/degC for the accelerometer, and its interval
    covers the planted 7.2 deg/h/degC and 0.1 mg/degC (one seed; the interval's coverage is
    98 % over 200 logs, docs/qualify.md)."""
    _, _, page, data = thermal
    found = {m[0]: m[1:] for m in SENS_RE.findall(page)}
    truth = {"gyro_x": (7.2, "deg/h/degC"), "accel_x": (0.1, "mg/degC")}
    assert set(found) == set(truth)
    assert temperature_sensitivity(GYRO_C, "deg/s")[0] == pytest.approx(7.2)  # the premise
    assert temperature_sensitivity(ACCEL_C, "g")[0] == pytest.approx(0.1)
    for ch, (value, unit) in truth.items():
        v, lo, hi, u = found[ch]
        t = data["channels"][ch]["temperature"]
        assert html.unescape(u) == unit == t["sensitivity_unit"]
        assert float(v) == t["sensitivity"] and [float(lo), float(hi)] == t["sensitivity_interval"]
        assert float(lo) < value < float(hi), (ch, lo, hi)
        assert t["temperature"] == "imu_temp" and t["level"] == 0.95
        assert 0 < float(hi) - float(lo) < value  # informative: narrower than the effect


def test_the_fit_is_of_the_compensated_signal_and_the_raw_one_inflates_the_rw(thermal):
    """The channel's fit (its parameter table and JSON) is that of the compensated signal: its
    RW interval covers the planted gamma2, the same model on the raw signal gives a RW
    several times larger (the thermal ramp read as a random walk)."""
    _, rep, _, data = thermal
    for ch, gamma2 in (("gyro_x", 1e-10), ("accel_x", 1e-13)):
        c = rep.channels[ch]
        assert c.fit is c.temperature.fit
        (rw,) = [iv for iv in c.intervals if iv.name == "RW.gamma2"]
        assert rw.low <= gamma2 <= rw.high, (ch, rw)
        raw = c.temperature.fit_raw.params["RW.gamma2"]
        assert raw > 2 * rw.value, (ch, raw, rw.value)
        t = data["channels"][ch]["temperature"]
        assert t["fit_raw"]["model"] == "WN+RW"
        assert data["channels"][ch]["fit"]["params"] == t["fit"]["params"]


def test_the_wv_figure_draws_both_wvs(thermal):
    """The channel's WV figure has the compensated WV (the fit's) and the raw WV, each equal to
    the Haar WV computed here from the signal with and without the planted relation."""
    log, rep, page, _ = thermal
    specs = figure_specs(rep)
    temp = log.aux["imu_temp"]
    for ch in ("gyro_x", "accel_x"):
        layers = {lay.label: lay for lay in specs[f"{ch}-wv"].layers if lay.kind == "points"}
        raw = eg.wavelet_variance(log[ch], fs=FS)
        np.testing.assert_allclose(
            layers["WV before temperature compensation"].y, raw.variance, rtol=1e-12
        )
        coef = rep.channels[ch].temperature.coef[0]
        comp = eg.wavelet_variance(log[ch] - coef * (temp - temp.mean()), fs=FS)
        np.testing.assert_allclose(layers["empirical WV"].y, comp.variance, rtol=1e-9)
        # the thermal ramp lifts the raw WV at the long scales, not at the short ones
        assert raw.variance[-1] > 2 * comp.variance[-1]
        assert raw.variance[0] == pytest.approx(comp.variance[0], rel=1e-3)
    assert page.count("WV before temperature compensation") >= 2


def test_a_log_without_temperature_shows_nothing_new():
    """The same kind of gyro log without a temperature channel: no temperature paragraph, no
    raw WV on the figure, ``temperature`` None in the JSON, the fit of the raw signal."""
    n = 2**15
    x = eg.parse_model(GYRO).simulate(n, fs=FS, rng=3)
    log = eg.ImuLog({"gyro_x": x}, FS, units={"gyro_x": "deg/s"}, source="plain.h5")
    rep = gather_report(log, model="WN+RW", export_format=None, temperature="auto")
    page, data = render_html(rep), rep.to_dict()
    assert 'class="temperature"' not in page and "temperature compensation" not in page
    assert data["channels"]["gyro_x"]["temperature"] is None
    labels = [lay.label for lay in figure_specs(rep)["gyro_x-wv"].layers]
    assert "WV before temperature compensation" not in labels
    np.testing.assert_allclose(
        rep.channels["gyro_x"].fit.wv.variance, eg.wavelet_variance(x, fs=FS).variance
    )


@pytest.mark.real_data
def test_a_real_log_without_temperature_is_reported_as_before(real_data):
    """ADIS16405 unit 1 (no temperature channel), gyro_x: the report with the temperature
    channel looked for (the default) fits the raw signal's WV and its page and JSON hold no
    temperature figure."""
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    assert not any("temp" in n for n in [*log.names, *log.aux])  # the premise
    rep = gather_report(log, model="WN+QN+RW", channels=["gyro_x"], export_format=None)
    c = rep.channels["gyro_x"]
    assert c.temperature is None and rep.to_dict()["channels"]["gyro_x"]["temperature"] is None
    np.testing.assert_array_equal(c.fit.wv.variance, log.wavelet_variance("gyro_x").variance)
    page = render_html(rep)
    assert 'class="temperature"' not in page and "temperature compensation" not in page


def test_a_sensitivity_not_distinguishable_from_0_is_reported_not_applied():
    """A gyro with no true sensitivity and a temperature that barely moves (30.1 to 30.6
    degC): the report (through the batch's fit_log) shows the sensitivity as information
    only: the paragraph says "not compensated", the fit and the WV figure are the raw
    signal's, with no grey WV beside them, the JSON says ``compensated`` false; the batch's
    status says so too."""
    from engine.batch import fit_log

    t = np.arange(N) / FS
    temp = 30.1 + 0.5 * (1 - np.exp(-t / 900)) + np.random.default_rng(9).normal(0, 0.01, N)
    x = eg.parse_model(GYRO).simulate(N, fs=FS, rng=13)
    log = eg.ImuLog(
        {"gyro_x": x}, FS, units={"gyro_x": "deg/s"}, aux={"imu_temp": temp}, source="r.h5"
    )
    rep = gather_report(log, model="WN+RW", export_format=None, temperature="auto")
    c = rep.channels["gyro_x"]
    lo, hi = c.temperature.sensitivity_interval
    assert lo < 0 < hi and not c.temperature.applied  # the premise, and the decision
    raw = eg.wavelet_variance(x, fs=FS)
    np.testing.assert_array_equal(c.fit.wv.variance, raw.variance)
    labels = [lay.label for lay in figure_specs(rep)["gyro_x-wv"].layers]
    assert "WV before temperature compensation" not in labels
    page = html.unescape(render_html(rep))
    assert "not compensated" in page and "--temperature imu_temp" in page
    assert "WV before temperature compensation" not in page
    d = rep.to_dict()["channels"]["gyro_x"]["temperature"]
    assert d["compensated"] is False and d["fit_raw"] is None and d["wv_raw"] is None
    status = fit_log(log, model="WN+RW").status()["temperature"]["gyro_x"]
    assert status["compensated"] is False and status["fit_raw_model"] is None


def test_the_reports_filter_file_reads_the_compensated_signal():
    """A gyro_x of white noise N = 1e-4 rad/s/sqrt(Hz) (and a random walk) whose bias steps
    with a heater (2e-4 rad/s per degC, 4 degC steps every 5 min after a 10 degC warm-up): the
    report fits the compensated signal, and the Kalibr file it carries must take its tail
    factors from that signal too (``engine.inference.temperature.compensate_channels``): the
    planted density within 3 %; the raw signal's steps (tail factors 1.8-3.0 at 5-20 s) made
    it 1.65e-4."""
    import yaml

    n = 2**17
    t = np.arange(n) / FS
    temp = 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sign(np.sin(2 * np.pi * t / 600))
    x = eg.parse_model("WN(1e-6)+RW(1e-12)").simulate(n, rng=np.random.default_rng(1))
    log = eg.ImuLog(
        {"gyro_x": x + 2e-4 * (temp - 25)}, FS, units={"gyro_x": "rad/s"},
        aux={"imu_temp": temp}, source="heater.h5",
    )  # fmt: skip
    rep = gather_report(log, model="WN+RW", export_format="kalibr", temperature="auto")
    assert rep.channels["gyro_x"].temperature.applied
    text = rep.export["text"]
    assert float(yaml.safe_load(text)["gyroscope_noise_density"]) == pytest.approx(1e-4, rel=0.03)
