"""The app and a log with a temperature channel: the Fit view says the bias-temperature
sensitivity in one line (AppState.temperature) and fits the compensated signal, as ``gmwm fit
--temperature auto`` does; nothing changes for a log without one."""

from __future__ import annotations

import re

import numpy as np
import pytest

import engine as eg
from gmwm_app.report_download import session_report
from gmwm_app.state import AppState

FS = 100.0
N = 200_000
C = 2e-3  # deg/s per degC = 7.2 deg/h per degC
SPEC = "WN(sigma2=1e-4)+RW(gamma2=1e-10)"
LINE = re.compile(r"temperature sensitivity (\S+) \[(\S+), (\S+)\] deg/h/degC")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("app_temperature")
    t = np.arange(N) / FS
    temp = 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sin(2 * np.pi * t / 600)
    x = eg.parse_model(SPEC).simulate(N, fs=FS, rng=21)
    units = {"gyro_x": "deg/s", "temperature": "degC"}
    eg.save_log(d / "thermal.csv", {"gyro_x": x + C * temp, "temperature": temp}, FS, units=units)
    eg.save_log(d / "plain.csv", {"gyro_x": x + C * temp}, FS, units={"gyro_x": "deg/s"})
    return d, x, temp


def _rw(s: AppState) -> float:
    return float(s.result.params["RW.gamma2"])


def test_fit_view_says_the_sensitivity_and_fits_the_compensated_signal(logs):
    """The line holds the sensitivity and a 95 % interval covering the planted 7.2
    deg/h/degC; the session's WV is that of the compensated signal: at the short scales it is
    the raw one's, at the long scales where the raw signal's is 2 to 18 times that of the noise
    alone (computed here without the temperature term), it is the noise's within 30 %; the WN+RW
    fit's RW is then the planted 1e-10 within 30 %, and the fit of the log without its
    temperature column inflates it. The downloaded report has the temperature paragraph."""
    d, x, temp = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv"), s.error
    m = LINE.search(s.temperature)
    assert m is not None, s.temperature
    lo, hi = float(m[2]), float(m[3])
    assert lo < 7.2 < hi and "compensated" in s.temperature
    noise = eg.wavelet_variance(x, fs=FS).variance
    raw = eg.wavelet_variance(x + C * temp, fs=FS).variance
    wv = s.wv.variance
    assert wv[0] == pytest.approx(raw[0], rel=1e-3)
    ramp = raw > 2 * noise  # the premise: the ramp dominates the long scales (up to 18x)
    assert ramp.sum() >= 4 and np.max(raw / noise) > 10
    np.testing.assert_allclose(wv[ramp], noise[ramp], rtol=0.3)
    assert s.set_model("WN+RW"), s.error
    assert _rw(s) == pytest.approx(1e-10, rel=0.3)
    page = session_report(s)
    assert '<p class="temperature" data-channel="gyro_x">' in page

    plain = AppState()
    assert plain.load_path(d / "plain.csv"), plain.error
    assert plain.temperature == ""
    np.testing.assert_allclose(plain.wv.variance, raw)
    assert plain.set_model("WN+RW"), plain.error
    assert _rw(plain) > 2 * _rw(s)
    assert 'class="temperature"' not in session_report(plain)
