"""The export bound covers the data, not only the fit.

A WN+RW fit of an ADIS16405 channel misfits the log (its WV is below the empirical 95 %
interval at 12-14 of 19 scales); the exported file must still have a WV at least the lower
end of the empirical interval at every dyadic scale from two filter steps to the horizon, and
the CLI must say, next to the file, that model and data disagree.

The file's WV is computed here from the numbers read back from the file with the formulas of
docs/conventions.md (WN ``sigma2 / tau``, RW ``gamma2 (tau^2 + 2) / (12 tau)``), and the
empirical interval from the log by ``ImuLog.wavelet_variance`` (the eta3 interval), not by the
code under test.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

import engine as eg
from engine.cli import main
from engine.formats import export
from engine.formats.projection import MISFIT_SHARE, misfit

DEG = math.pi / 180
G = 9.80665
ADIS = [f"adis16405_imu{i}.h5" for i in range(1, 7)]


def kalibr_wv(path, ch: str, tau: np.ndarray, fs: float) -> np.ndarray:
    """The WV (native unit^2, tau in samples) of the Kalibr file's WN+RW for channel ``ch``."""
    d = yaml.safe_load(path.read_text())
    kind = "gyroscope" if ch.startswith("gyro") else "accelerometer"
    ax = ch[-1]
    n = d[f"{kind}_noise_density_per_axis"][ax]
    k = d[f"{kind}_random_walk_per_axis"][ax]
    f_si = DEG if kind == "gyroscope" else G  # the logs are in deg/s and g
    s2 = (n / f_si) ** 2 * fs  # per-sample WN variance
    g2 = (k / f_si) ** 2 / fs  # per-sample RW variance
    return s2 / tau + g2 * (tau**2 + 2) / (12 * tau)


@pytest.mark.real_data
@pytest.mark.parametrize("name", ADIS)
def test_wn_rw_export_bounds_the_data_lower_limit_on_every_adis_channel(
    real_data, name, tmp_path, capsys
) -> None:
    """The acceptance criterion: `gmwm export --model WN+RW` of every ADIS16405 channel
    writes a file whose WV is >= the lower end of the empirical 95 % interval at every scale
    from 2 filter steps (0.02 s at 100 Hz) to the horizon (default: the log, 10^4 s; the
    longest dyadic scale is 5243 s). Before: below at 12-14 of 19 scales on imu1's gyros."""
    out = tmp_path / "imu.yaml"
    argv = ["export", str(real_data / name), "--model", "WN+RW", "--format", "kalibr"]
    assert main([*argv, "-o", str(out), "--no-intervals"]) == 0
    printed = capsys.readouterr().out
    log = eg.load_log(real_data / name)
    for ch in log.names:
        wv = log.wavelet_variance(ch)
        tau = np.asarray(wv.tau_samples, float)
        band = tau >= 2.0  # two filter steps at the log's rate
        fw = kalibr_wv(out, ch, tau[band], log.fs)
        lo = np.asarray(wv.ci_low)[band]
        assert np.all(fw >= lo * (1 - 1e-9)), (ch, tau[band][fw < lo], (fw / lo).min())
        # the fitted WN+RW alone is below the data: the CLI says so next to the file
        fit = eg.fit_gmwm(wv, "WN+RW")
        mw = fit.model.wv(tau, log.fs)
        outside = int(np.sum((mw < np.asarray(wv.ci_low)) | (mw > np.asarray(wv.ci_high))))
        if outside > MISFIT_SHARE * tau.size:
            assert f"warning: {ch} (WN+RW): model and data disagree" in printed
            assert f"at {outside} of {tau.size} scales" in printed


@pytest.mark.real_data
def test_defect_1_imu1_gyro_x_was_below_the_data(real_data) -> None:
    """The fitted model alone (``data="none"``, the old default) is below the empirical lower
    limit on imu1 gyro_x at many scales, so the test above can fail; the default export is
    not, and the options ``estimate`` and ``high`` bound the estimate and the upper limit."""
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    wv = log.wavelet_variance("gyro_x")
    fit = eg.fit_gmwm(wv, "WN+RW")
    tau = np.asarray(wv.tau_samples, float)
    for data, limit, must in (
        ("none", wv.ci_low, False),
        ("low", wv.ci_low, True),
        ("estimate", wv.variance, True),
        ("high", wv.ci_high, True),
    ):
        p = eg.formats.project(fit, "kalibr", channel="gyro_x", ci=None, data=data)
        s2 = (p.value("N") / DEG) ** 2 * log.fs
        g2 = (p.value("K") / DEG) ** 2 / log.fs
        fw = s2 / tau + g2 * (tau**2 + 2) / (12 * tau)
        below = int(np.sum(fw < np.asarray(limit) * (1 - 1e-9)))
        if must:
            assert below == 0, (data, below)
            assert p.data == data and "empirical WV" in p.header_lines()[0]
        else:
            assert below >= 10, below  # defect 1: 12-14 of 19 scales below
    # the misfit line: 14 of 19 scales outside (13 below), its smallest ratio at 81.92 s
    line = misfit(fit, "gyro_x")
    mw = fit.model.wv(tau, log.fs)
    n_out = int(np.sum((mw < wv.ci_low) | (mw > wv.ci_high)))
    assert n_out >= 12 and f"at {n_out} of 19 scales" in line


@pytest.mark.real_data
def test_misfit_in_file_report_and_json(real_data, capsys) -> None:
    """The misfit line is in the file (a ``# warning:`` line), in the JSON report per channel
    and in ``gmwm export --json``; a well-fitting model gets none."""
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    wv = log.wavelet_variance("gyro_x")
    fits = {"gyro_x": eg.fit_gmwm(wv, "WN+RW")}
    text = export(None, fits, "kalibr", allow_partial=True, ci=None)
    assert "# warning: gyro_x (WN+RW): model and data disagree" in text
    rep = json.loads(export(None, fits, "json", ci=None))
    assert rep["channels"]["gyro_x"]["misfit"].startswith("gyro_x (WN+RW): model and data")
    good = eg.fit_gmwm(wv, "2*GM+WN+RW")
    assert misfit(good, "gyro_x") == ""
    argv = ["export", str(real_data / "adis16405_imu1.h5"), "--model", "WN+RW"]
    assert main([*argv, "--channels", "gyro_x", "--partial", "-o", "/dev/null", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["misfit"][0].startswith("gyro_x (WN+RW): model and data disagree")


def test_misfit_threshold_is_a_binomial_tail() -> None:
    """MISFIT_SHARE: with J = 19 scales, each outside with probability 0.05 under a true
    model, 7 or more outside (the flag) has probability about 2e-5 (binomial tail, computed
    here)."""
    j, p = 19, 0.05
    k0 = math.floor(MISFIT_SHARE * j) + 1
    tail = sum(math.comb(j, k) * p**k * (1 - p) ** (j - k) for k in range(k0, j + 1))
    assert k0 == 7 and 1e-5 < tail < 3e-5
