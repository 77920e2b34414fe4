"""The selected model is one a user can act on: no AR1/GM faster than one sample, no parameter
at a bound, on the real ADIS16405 log where the ranking's first row has both.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.inference.selection import actionable, rank_models

MAX_MODEL = "2*GM+WN+QN+RW+DR"


@pytest.fixture(scope="module")
def gyro_x_wv(real_data: Path):
    log = eg.load_log(real_data / "adis16405_imu1.h5", channel="gyro_x")
    return eg.wavelet_variance(log["gyro_x"], fs=log.fs)


@pytest.fixture(scope="module")
def ranking(gyro_x_wv):
    return rank_models(gyro_x_wv, max_model=MAX_MODEL)


def _tc_samples(res):
    return [
        -1.0 / np.log(q.nl_value(res.wv.fs)) for q in res.model.processes if q.nonlinear is not None
    ]


@pytest.mark.real_data
def test_the_selection_has_no_sub_sample_term_and_nothing_at_a_bound(ranking):
    # before: the selection was 2*GM+QN with GM_2 at 0.55 samples and QN.q2 at 0
    top = ranking.candidates[0]
    assert not top.is_actionable and top.result.warnings  # the first row is the disguised one
    best = ranking.best
    assert best.is_actionable and best.result is not None
    assert best.result.at_bound == [] and best.result.warnings == []
    assert min(_tc_samples(best.result), default=np.inf) >= 1.0
    assert best.model == "GM+WN"
    # the slow GM of the first row is kept (its correlation time, about 118 s), the disguised
    # one is now white noise: N of the selection carries it
    assert 50 < 1.0 / best.result.params["GM.beta"] < 300
    assert best.derived_from == top.model and "folded into WN" in best.derivation[0]
    # the table and the JSON say so
    assert ranking.table().splitlines()[1].startswith("selected: GM+WN (the rank-1")
    assert ranking.to_dict()["selected"]["model"] == "GM+WN"
    assert ranking.to_dict()["selected"]["derived_from"] == top.model
    assert "not selectable" in top.note


@pytest.mark.real_data
def test_a_selected_models_noise_density_matches_the_allan_deviation_at_one_second(
    ranking, gyro_x_wv
):
    # the selection's WN is the white noise an IMU user reads off the Allan deviation: at
    # tau = 1 s (2^7 samples at 100 Hz) the ADEV is mostly white noise, and the selection's
    # implied ADEV (the square root of the WV) is within 5 % of the empirical one, at every
    # scale from 8 samples to 2^12 samples (41 s) within 10 % (a refit of the variances at the
    # kept correlation times put it 17 % below at 1 s: WN pulled down by the finest scale)
    ratio = np.sqrt(ranking.best.result.implied / gyro_x_wv.variance)
    j = int(np.flatnonzero(gyro_x_wv.tau_samples == 128)[0])
    assert abs(ratio[j] - 1) < 0.05, ratio[j]
    assert np.all(np.abs(ratio[2:12] - 1) < 0.1), ratio


@pytest.mark.real_data
def test_report_and_fleet_fit_the_selection(real_data: Path):
    # gmwm report / the fleet fit each channel with batch.fit_log(select=...): the selected
    # model, not the first row (a small maximal model keeps this quick)
    lf = eg.fit_log(real_data / "adis16405_imu1.h5", select="2*GM+QN", channels=["gyro_x"])
    res = lf.fits["gyro_x"]
    assert res.at_bound == [] and res.warnings == []
    assert res.model.spec() == "GM+WN"


@pytest.mark.real_data
def test_cli_select_json_names_the_selection(capsys, real_data: Path):
    path = str(real_data / "adis16405_imu1.h5")
    code = main(["select", path, "--channel", "gyro_x", "--models", "2*GM+QN,GM+WN", "--json"])
    assert code == 0
    d = json.loads(capsys.readouterr().out)
    assert d["candidates"][0]["actionable"] is False
    assert d["selected"]["model"] == "GM+WN" and d["selected"]["actionable"] is True


def test_actionable_folds_a_sub_sample_term_and_drops_a_term_at_its_bound():
    truth = eg.parse_model("GM(beta=0.2, sigma2_gm=1e-3)+WN(sigma2=1e-2)")
    x = truth.simulate(2**15, fs=100.0, rng=np.random.default_rng(4))
    wv = eg.wavelet_variance(x, fs=100.0)
    res = eg.fit_gmwm(wv, truth + eg.QN(q2=0.0), fixed=True)
    model, changes = actionable(res)
    assert res.at_bound == ["QN.q2"]
    assert model == truth and changes == ["QN dropped (QN.q2 at its bound)"]
    # a GM at 0.3 samples with WN: folded into WN
    fake = eg.parse_model(
        f"GM(beta={100 / 0.3}, sigma2_gm=1e-3)+GM(beta=0.2, sigma2_gm=1e-3)+WN(sigma2=1e-2)"
    )
    res2 = eg.fit_gmwm(wv, fake, fixed=True)
    m2, ch2 = actionable(res2)
    assert m2.spec() == "GM+WN" and ch2 == ["GM_2 (0.3 samples) folded into WN"]
    fast = fake.processes[0]
    assert m2.values()["WN.sigma2"] == pytest.approx(1e-2 + fast.white_equivalent(100.0))
    # the implied WV is kept at the scales much longer than 0.3 samples
    tau = wv.tau_samples[3:]
    np.testing.assert_allclose(m2.wv(tau, 100.0), fake.wv(tau, 100.0), rtol=0.02)
    # an actionable fit is its own model
    ok = eg.fit_gmwm(wv, "GM+WN")
    assert actionable(ok) == (ok.model, [])


def test_fixed_gives_the_result_of_the_given_values():
    truth = eg.parse_model("GM(beta=0.2, sigma2_gm=1e-3)+WN(sigma2=1e-2)")
    x = truth.simulate(2**15, fs=100.0, rng=np.random.default_rng(4))
    wv = eg.wavelet_variance(x, fs=100.0)
    res = eg.fit_gmwm(wv, truth, fixed=True)
    assert res.model == truth and res.method == "fixed"
    assert res.objective == pytest.approx(eg.fit.gmwm_objective(wv, truth), rel=1e-12)
    assert res.objective >= eg.fit_gmwm(wv, "GM+WN").objective
    with pytest.raises(eg.FitError, match="fixed=True"):
        eg.fit_gmwm(wv, "GM+WN", fixed=True)
