"""AR1/GM correlation times shorter than one sample: every fit flags them.

The search is not bounded at one sample (see engine/fit/_varpro.py and README, "Correlation
times shorter than one sample"): a sub-sample AR1/GM is white noise in disguise, but with
neighbouring samples correlated it fits real sensors (the ADIS16405's filtered outputs) far
better than WN. Every fit keeps the minimum and says so: ``FitResult.warnings``, the summary, the
JSON, the CLI and the app.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.multivariate import MultiModel

FS = 100.0


def wn_equivalent(q: eg.Process, fs: float) -> float:
    """Long-scale WN level of an AR1/GM (docs/conventions.md: the AR1 WV tends to
    sigma2/(1-phi)^2/tau)."""
    if isinstance(q, eg.GM):
        phi = math.exp(-q.beta / fs)
        return q.sigma2_gm * (1 + phi) / (1 - phi)
    return q.sigma2 / (1 - q.phi) ** 2


def sub_sample_terms(res: eg.fit.FitResult, fs: float) -> dict[str, eg.Process]:
    """The fitted AR1/GM terms with a positive variance and a correlation time < 1 sample."""
    out = {}
    for lab, q in zip(res.model.labels, res.model.processes, strict=True):
        if q.code == "GM" and q.sigma2_gm > 0 and q.beta / fs > 1:
            out[lab] = q
        if q.code == "AR1" and q.sigma2 > 0 and q.phi < math.exp(-1):
            out[lab] = q
    return out


def ma1(n: int, b: float, rng: int) -> np.ndarray:
    """White noise through a 2-tap filter: lag-1 autocorrelation b / (1 + b^2), none beyond."""
    e = np.random.default_rng(rng).standard_normal(n + 1)
    return e[1:] + b * e[:-1]


# ------------------------------------------------------------------------------------------
# simulations
# ------------------------------------------------------------------------------------------
def test_exact_wv_of_a_fast_gm_is_flagged_and_wn_absorbs_it():
    """WN(1) + GM with a correlation time of 0.2 samples, fitted on its exact WV: the GM is
    found at 0.2 samples, flagged with its WN-equivalent, and WN alone takes it."""
    tau = 2.0 ** np.arange(1, 19)
    truth = eg.WN(1.0) + eg.GM(FS / 0.2, 1.0)
    wv = eg.WaveletVariance.from_arrays(truth.wv(tau, FS), n=2**20, fs=FS, unit="deg/s")
    res = eg.fit_gmwm(wv, "GM+WN")
    assert res.params["GM.beta"] == pytest.approx(500.0, rel=1e-6)
    assert len(res.warnings) == 1 and res.warnings[0].startswith("GM: correlation time 0.002 s")
    equiv = (1 + math.exp(-5)) / (1 - math.exp(-5))  # 1.01357
    assert f"WN-equivalent sigma2 = {equiv:.4g} (deg/s)^2" in res.warnings[0]
    assert f"N = {math.sqrt(equiv / FS):.4g} deg/s/sqrt(Hz)" in res.warnings[0]
    # the same WN the flagged term hides: WN alone takes WN + the GM's equivalent (1 + 1.0136)
    # to 1 % (the rest is the small 1/tau^2 part a GM adds at the shortest scales)
    wn = eg.fit_gmwm(wv, "WN")
    assert wn.params["WN.sigma2"] == pytest.approx(1.0 + equiv, rel=0.01)
    assert not wn.warnings
    # the summary and the JSON carry the warning; the GMWFM (identity and log10) too
    assert res.warnings[0] in res.summary() and res.to_dict()["warnings"] == res.warnings
    assert eg.fit.fit_gmwfm(wv, "GM+WN", f="identity").warnings == res.warnings
    armav = eg.fit.fit_armav(wv, "GM+WN")
    assert armav.params["GM.beta"] == pytest.approx(500.0, rel=1e-3)
    assert len(armav.warnings) == 1 and "shorter than one sample" in armav.warnings[0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_simulated_fast_gm_plus_wn_flags_every_sub_sample_term(seed):
    """Simulated WN(1) + GM(0.2 samples, 1): whatever the fit does with the unidentifiable fast
    GM, every term faster than one sample is flagged, no other is, and WN alone takes the total
    white level 2.0136."""
    rng = np.random.default_rng(seed)
    n = 2**18
    x = eg.WN(1.0).simulate(n, rng) + eg.GM(FS / 0.2, 1.0).simulate(n, rng, fs=FS)
    wv = eg.wavelet_variance(x, fs=FS)
    res = eg.fit_gmwm(wv, "GM+WN")
    fast = sub_sample_terms(res, FS)
    assert [w.split(":")[0] for w in res.warnings] == list(fast)
    total = res.params["WN.sigma2"] + sum(wn_equivalent(q, FS) for q in fast.values())
    wn = eg.fit_gmwm(wv, "WN").params["WN.sigma2"]
    assert wn == pytest.approx(total, rel=0.02)
    assert wn == pytest.approx(2.0136, rel=0.02)


def test_filtered_white_noise_is_fitted_by_a_flagged_sub_sample_gm():
    """The sensor-filter case (ADIS-like lag-1 correlation 0.17, none at lag 2): the fit uses a
    GM faster than one sample, flags it, and its WN-equivalent is the noise's long-run variance
    (1 + b)^2 within 5 %; the term is real: WN alone fits several times worse."""
    b = 0.178
    wv = eg.wavelet_variance(ma1(2**18, b, rng=5), fs=FS)
    res = eg.fit_gmwm(wv, "GM+WN")
    fast = sub_sample_terms(res, FS)
    assert list(fast) == ["GM"] and res.warnings[0].startswith("GM: correlation time")
    equiv = res.params["WN.sigma2"] + wn_equivalent(fast["GM"], FS)
    assert equiv == pytest.approx((1 + b) ** 2, rel=0.05)
    assert eg.fit_gmwm(wv, "WN").objective > 3 * res.objective


def test_multivariate_fit_flags_per_channel():
    x = np.column_stack([ma1(2**17, 0.4, rng=1), 2 * ma1(2**17, 0.4, rng=2)])
    mm = MultiModel(["a", "b"], {"a": "GM+WN", "b": "GM+WN"})
    res = eg.fit_mgmwm(x, mm, fs=FS)
    assert res.params["a.GM.beta"] > FS and res.params["b.GM.beta"] > FS
    assert [w.split(":")[0] for w in res.warnings] == ["a.GM", "b.GM"]
    assert all(w in res.summary() for w in res.warnings)
    assert res.to_dict()["warnings"] == res.warnings


def test_slow_terms_are_not_flagged():
    tau = 2.0 ** np.arange(1, 16)
    truth = eg.GM(0.5, 1e-3) + eg.WN(1e-2)
    wv = eg.WaveletVariance.from_arrays(truth.wv(tau, FS), n=2**17, fs=FS)
    res = eg.fit_gmwm(wv, "GM+WN")
    assert res.params["GM.beta"] == pytest.approx(0.5, rel=1e-6) and res.warnings == []


# ------------------------------------------------------------------------------------------
# the shared real logs
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def adis_gyro_x(real_data: Path) -> eg.WaveletVariance:
    log = eg.load_log(real_data / "adis16405_imu1.h5", channel="gyro_x")
    return eg.wavelet_variance(log["gyro_x"], fs=log.fs, unit="deg/s")


def test_adis_sub_sample_gm_is_flagged_with_the_data_white_level(adis_gyro_x):
    """ADIS16405 gyro_x, 2*GM+WN+RW: GM_2 at beta = 182 1/s (0.55 samples at 100 Hz) with WN at
    0. It is flagged, and its WN-equivalent is the data's white level: nu * tau at level 6,
    where the slow terms are below 1e-4 of the WV, within 6 %."""
    res = eg.fit_gmwm(adis_gyro_x, "2*GM+WN+RW")
    assert res.params["GM_2.beta"] > adis_gyro_x.fs and res.params["WN.sigma2"] == 0.0
    fast = sub_sample_terms(res, adis_gyro_x.fs)
    assert list(fast) == ["GM_2"] and len(res.warnings) == 1
    assert res.warnings[0].startswith("GM_2: correlation time 0.0055 s = 0.55 samples")
    equiv = wn_equivalent(fast["GM_2"], adis_gyro_x.fs)
    assert f"WN-equivalent sigma2 = {equiv:.4g} (deg/s)^2" in res.warnings[0]
    plateau = adis_gyro_x.variance[5] * adis_gyro_x.tau_samples[5]
    assert equiv == pytest.approx(plateau, rel=0.06)
    # GMWFM (log10, the ARMAV) reaches the same sub-sample term and flags it too
    armav = eg.fit.fit_armav(adis_gyro_x, "2*GM+WN+RW")
    assert armav.params["GM_2.beta"] > adis_gyro_x.fs
    assert [w.split(":")[0] for w in armav.warnings] == ["GM_2"]


def test_adis_replicates_beta_177_is_flagged(real_data: Path):
    """The replicate fit of ADIS gyro_x (recordings 1 to 3): GM_2 at beta = 177 1/s."""
    wvs = [
        eg.wavelet_variance(
            eg.load_log(real_data / f"adis16405_imu{k}.h5", channel="gyro_x")["gyro_x"], fs=FS
        )
        for k in (1, 2, 3)
    ]
    res = eg.fit.fit_replicates(wvs, "2*GM+WN+RW")
    assert res.params["GM_2.beta"] == pytest.approx(177, abs=2)
    assert res.params["WN.sigma2"] == 0.0
    assert [w.split(":")[0] for w in res.warnings] == ["GM_2"]


def test_navchip_zero_variance_gm_beta_429_is_flagged(real_data: Path):
    """NavChip gyro_x WV, GM+WN+RW: the GM has variance 0 and beta = 429 1/s (0.58 samples at
    250 Hz): the warning says the beta means nothing."""
    wv = eg.load_log(real_data / "derived" / "navchip_wv_av.h5").wv["gyro_x"]
    res = eg.fit_gmwm(wv, "GM+WN+RW")
    assert res.params["GM.sigma2_gm"] == 0.0 and res.params["GM.beta"] > wv.fs
    assert res.params["GM.beta"] == pytest.approx(429.2, abs=1)
    assert len(res.warnings) == 1
    assert res.warnings[0].startswith("GM: correlation time 0.00233 s = 0.58 samples")
    assert "variance is 0" in res.warnings[0] and "means nothing" in res.warnings[0]


# ------------------------------------------------------------------------------------------
# CLI and app
# ------------------------------------------------------------------------------------------
def test_cli_prints_the_warning_and_puts_it_in_the_json(capsys, tmp_path):
    path = tmp_path / "fast.h5"
    model = "GM(beta=200, sigma2_gm=1)+WN(sigma2=0.2)"  # a GM of 0.5 samples at 100 Hz
    argv = ["simulate", "--model", model, "-n", "131072", "--fs", "100", "--seed", "0"]
    assert main([*argv, "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["fit", str(path), "--model", "GM+WN"]) == 0
    out = capsys.readouterr().out
    assert "warning: GM: correlation time" in out and "shorter than one sample" in out
    assert main(["fit", str(path), "--model", "GM+WN", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    beta = next(p["value"] for p in d["params"] if p["name"] == "beta")
    assert beta == pytest.approx(200, rel=0.15)
    assert len(d["warnings"]) == 1 and d["warnings"][0].startswith("GM: correlation time")


def test_cli_navchip_warning(capsys, real_data):
    path = real_data / "derived" / "navchip_wv_av.h5"
    assert main(["fit", str(path), "--channel", "gyro_x", "--model", "GM+WN+RW"]) == 0
    out = capsys.readouterr().out
    assert "warning: GM: correlation time 0.00233 s = 0.58 samples" in out


def test_app_state_shows_the_warning(tmp_path):
    from gmwm_app.state import AppState

    rng = np.random.default_rng(4)
    n = 2**16
    x = eg.GM(200.0, 1.0).simulate(n, rng, fs=FS) + eg.WN(0.2).simulate(n, rng)
    path = eg.io.save_log(tmp_path / "fast.h5", {"gyro_x": x}, fs=FS)
    s = AppState()
    assert s.load_path(path), s.error
    assert s.set_model("GM+WN")
    assert s.result.params["GM.beta"] > FS
    assert any(w.startswith("GM: correlation time") for w in s.warnings())
