"""The first-order moving average MA(1): its WV, simulator, fit, model string and units.

MA1 is the process added as one class (``engine/models/ma1.py``): every fact these tests read
(transform, unit, slider scale, search coordinate, identifiability) comes from that class.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.fit._varpro import NNLSProblem, sqrt_weight
from engine.models import MA1
from engine.units import process_from_values, process_values

TAU = 2.0 ** np.arange(1, 10)  # 2 .. 512 samples


def _haar_wv_of_autocovariance(process: eg.Process, tau: int) -> float:
    """``nu2 = h' Sigma h`` over one window of ``tau`` samples, ``Sigma`` from the
    autocovariance (the general identity of docs/conventions.md)."""
    m = tau // 2
    h = np.concatenate([np.full(m, -1.0), np.full(m, 1.0)]) / tau
    lags = np.subtract.outer(np.arange(tau), np.arange(tau))
    return float(h @ process.autocovariance(lags) @ h)


@pytest.mark.parametrize("theta", [-0.95, -0.6, 0.0, 0.3, 0.9])
def test_wv_closed_form_equals_the_autocovariance_quadratic_form(theta: float) -> None:
    ma = MA1(theta=theta, sigma2=1.7)
    expected = [_haar_wv_of_autocovariance(ma, int(t)) for t in TAU]
    np.testing.assert_allclose(ma.wv(TAU), expected, rtol=1e-12)
    # written out: sigma2 [(1 + theta)^2 / tau - 6 theta / tau^2]
    np.testing.assert_allclose(ma.wv(TAU), 1.7 * ((1 + theta) ** 2 / TAU - 6 * theta / TAU**2))


def test_wv_of_simulated_logs_agrees_with_the_closed_form() -> None:
    """200 simulated logs of 2^12 samples: at every level the mean empirical WV is within
    4 standard errors (replicate SD / sqrt(200)) of the closed form; 11 levels at 4 SE leave
    a false alarm probability below 1e-3."""
    theta, s2, reps, n = -0.6, 2.0, 200, 2**12
    ma = MA1(theta=theta, sigma2=s2)
    rng = np.random.default_rng(7)
    wvs = [eg.wavelet_variance(ma.simulate(n, rng), fs=1.0) for _ in range(reps)]
    w = np.array([v.variance for v in wvs])
    mean, se = w.mean(axis=0), w.std(axis=0, ddof=1) / math.sqrt(reps)
    z = (mean - ma.wv(wvs[0].tau_samples)) / se
    assert np.all(np.abs(z) < 4.0), z


def test_simulator_is_stationary_with_the_declared_autocovariance() -> None:
    """One log of 2^18 samples: the lag-0, 1 and 2 sample autocovariances within 5 standard
    errors of ``sigma2 (1 + theta^2)``, ``sigma2 theta`` and 0. Bartlett's variances for an
    MA(1): ``2 (g0^2 + 2 g1^2) / n``, ``(g0^2 + 3 g1^2) / n``, ``(g0^2 + 2 g1^2) / n``."""
    ma = MA1(theta=0.5, sigma2=3.0)
    n = 2**18
    x = ma.simulate(n, rng=11)
    acov = [float(np.mean(x[: n - h] * x[h:])) for h in range(3)]
    g0, g1, g2 = ma.autocovariance(np.arange(3))
    assert (g0, g1, g2) == (3.0 * 1.25, 1.5, 0.0)
    var = [2 * (g0**2 + 2 * g1**2), g0**2 + 3 * g1**2, g0**2 + 2 * g1**2]
    for a, t, v in zip(acov, (g0, g1, g2), var, strict=True):
        assert abs(a - t) < 5 * math.sqrt(v / n), (a, t)
    # the first and the second half have the same variance (no start-up transient)
    assert np.var(x[: n // 2]) == pytest.approx(np.var(x[n // 2 :]), rel=0.03)


def test_spectrum_integrates_to_the_variance_and_is_white_at_long_scales() -> None:
    ma = MA1(theta=0.4, sigma2=2.0)
    f = (np.arange(4096) + 0.5) / 8192  # midpoints of (0, 1/2)
    var = 2 * float(np.mean(ma.psd(f, fs=1.0))) * 0.5  # two-sided S over (-1/2, 1/2)
    assert var == pytest.approx(2.0 * (1 + 0.16), rel=1e-9)
    assert ma.white_equivalent(1.0) == pytest.approx(2.0 * 1.4**2, rel=1e-12)


def test_fit_recovers_theta_and_sigma2_with_calibrated_intervals() -> None:
    """100 simulated MA1(theta = 0.4, sigma2 = 1e-2) logs of 2^13 samples at 100 Hz, each
    fitted as "MA1": the mean estimates are within 4 Monte Carlo SEs of the truth, and each
    parameter's 95 % interval covers the truth in at least 88 of 100 logs (the binomial
    99.9 % lower limit of 95 % coverage over 100 logs is 0.95 - 3.3 x 0.0218 = 0.878).
    Measured: 96 and 93 of 100."""
    truth = {"MA1.theta": 0.4, "MA1.sigma2": 1e-2}
    reps = 100
    est = np.zeros((reps, 2))
    covered = np.zeros(2, dtype=int)
    for i in range(reps):
        x = MA1(theta=0.4, sigma2=1e-2).simulate(2**13, rng=100 + i)
        res = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0), "MA1")
        ci = res.conf_int()
        for j, name in enumerate(truth):
            est[i, j] = res.params[name]
            k = ci.names.index(name)
            covered[j] += int(ci.lower[k] <= truth[name] <= ci.upper[k])
    mc_se = est.std(axis=0, ddof=1) / math.sqrt(reps)
    assert np.all(np.abs(est.mean(axis=0) - list(truth.values())) < 4 * mc_se)
    assert np.all(covered >= 88), covered


@pytest.mark.parametrize("theta", [-0.7, 0.25])
def test_fit_of_ma1_plus_random_walk_recovers_both(theta: float) -> None:
    """30 logs of MA1(theta, 4e-3) + RW(1e-9), 2^15 samples: theta's estimates within 4
    Monte Carlo SEs of the truth, sigma2 and gamma2 within 4 SEs too (both kinds of sign of
    theta: a QN-like and a filtered-white-noise-like MA1)."""
    model = eg.parse_model(f"MA1(theta={theta}, sigma2=4e-3) + RW(gamma2=1e-9)")
    truth = model.values()
    reps = 30
    fits = [
        eg.fit_gmwm(
            eg.wavelet_variance(model.simulate(2**15, fs=100.0, rng=500 + i), fs=100.0), "MA1+RW"
        ).params
        for i in range(reps)
    ]
    names = list(fits[0])
    e = np.array([[f[n] for n in names] for f in fits])
    se = e.std(axis=0, ddof=1) / math.sqrt(reps)
    for j, name in enumerate(names):
        assert abs(e[:, j].mean() - truth[name]) < 4 * se[j], (name, e[:, j].mean(), truth[name])


def test_model_string_round_trip_and_identifiability() -> None:
    m = eg.parse_model("RW(gamma2=1e-9) + MA1(theta=-0.25, sigma2=0.5)")
    assert m.spec() == "RW+MA1" and m.labels == ["RW", "MA1"]
    assert eg.parse_model(m.spec(values=True)) == m
    assert eval(repr(m), {"RW": eg.RW, "MA1": MA1}) == m  # repr evaluates back
    assert eg.parse_model("ma1(0.3, 2)").processes[0] == MA1(theta=0.3, sigma2=2.0)
    for spec, words in [
        ("MA1+WN", "mixes MA1 and WN"),
        ("MA1+QN", "mixes MA1 and QN"),
        ("2*MA1", "2 MA1 terms"),
    ]:
        with pytest.raises(eg.ModelError, match=words):
            eg.parse_model(spec).validate()
    with pytest.raises(ValueError, match=r"MA1.theta must be in \(-1, 1\)"):
        MA1(theta=1.0, sigma2=1.0)


def test_units_transform_and_slider_come_from_its_declaration() -> None:
    assert eg.units.param_unit("MA1", "theta", "deg/s") == "1 (per sample)"
    assert eg.units.param_unit("MA1", "sigma2", "deg/s") == "(deg/s)^2"
    ma = MA1(theta=-0.3, sigma2=2e-3)
    u = ma.to_unconstrained()
    np.testing.assert_allclose(u, [math.atanh(-0.3), math.log(2e-3)])
    np.testing.assert_allclose(ma.from_unconstrained(u).values, ma.values, rtol=1e-12)
    for z in (-40.0, 0.0, 40.0):  # any real maps inside the bounds
        q = ma.from_unconstrained(np.array([z, z]))
        assert -1 < q.theta < 1 and q.sigma2 > 0
    assert MA1.params()["theta"].slider == "linear"
    assert ma.bounds() == {"theta": (-1.0, 1.0), "sigma2": (0.0, math.inf)}


def test_datasheet_rows_and_back() -> None:
    ma = MA1(theta=0.2, sigma2=1e-2)
    fs = 100.0
    vals = process_values(ma, fs)
    assert vals["theta"] == 0.2
    assert vals["N"] == pytest.approx(math.sqrt(1e-2 * 1.2**2 / fs), rel=1e-12)
    back = process_from_values("MA1", vals, fs)
    assert back.theta == pytest.approx(0.2) and back.sigma2 == pytest.approx(1e-2, rel=1e-12)
    rows = eg.units.datasheet(ma + eg.RW(1e-9), fs, "deg/s")
    by_symbol = {(r["label"], r["symbol"], r["unit"]): r["value"] for r in rows}
    # the white noise it adds at long scales reads as an angle random walk: 60 N deg/sqrt(h)
    assert by_symbol[("MA1", "ARW", "deg/sqrt(h)")] == pytest.approx(60 * vals["N"], rel=1e-12)
    assert by_symbol[("MA1", "theta", "1 (per sample)")] == 0.2


def test_mixed_search_reaches_the_minimum_of_a_dense_grid() -> None:
    """GM + MA1 + RW mixes two search coordinates (log correlation time, atanh theta): the fit
    is at or below the best of 120 x 120 profiled points of the two coordinates."""
    model = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-4) + MA1(theta=0.3, sigma2=1e-3) + RW(1e-9)")
    x = model.simulate(2**16, fs=100.0, rng=3)
    wv = eg.wavelet_variance(x, fs=100.0)
    res = eg.fit_gmwm(wv, "GM+MA1+RW")
    prob = NNLSProblem.from_wv(eg.parse_model("GM+MA1+RW"), wv, sqrt_weight(res.omega))
    assert prob.k == 2 and len(prob.groups) == 2
    ug, um = np.meshgrid(
        np.linspace(prob.lo[0], prob.hi[0], 120), np.linspace(-6.0, 6.0, 120), indexing="ij"
    )
    grid = prob.profile_many(np.column_stack([ug.ravel(), um.ravel()]))
    assert res.objective <= grid.min() * (1 + 1e-9)
    assert res.params["MA1.theta"] == pytest.approx(0.3, abs=0.1)
    assert res.params["GM.beta"] == pytest.approx(0.5, rel=0.5)


def test_on_real_logs_ma1_reaches_at_most_the_qn_plus_wn_objective(real_data: Path) -> None:
    """MA1's WV spans every non-negative mix of the WN and QN shapes (theta in (-1, 0]) and
    more (theta > 0): on every channel of the ADIS imu1 log and the MTi-G log the MA1 models'
    objectives are at most those with QN+WN in its place, with and without a GM.

    Measured (objective, ci weights; MA1+RW vs QN+WN+RW): imu1 gyro_x 1.84 vs 938, accel_x
    198 vs 1534, MTi-G gyro_x 7.54 vs 8.09; GM+MA1+RW vs GM+QN+WN+RW on imu1 gyro_x 0.49 vs
    10.7: the ADIS samples are positively correlated with their neighbours (theta 0.17 to
    0.22), which the QN+WN pair cannot express."""
    for name in ("adis16405_imu1.h5", "mtig_cont_imu1.h5"):
        log = eg.load_log(real_data / name)
        for ch in log.channels:
            wv = log.wavelet_variance(ch)
            for ma, qw in (("MA1+RW", "QN+WN+RW"), ("GM+MA1+RW", "GM+QN+WN+RW")):
                a, b = eg.fit_gmwm(wv, ma), eg.fit_gmwm(wv, qw)
                assert a.objective <= b.objective * (1 + 1e-9), (name, ch, ma)
            theta = eg.fit_gmwm(wv, "MA1+RW").params["MA1.theta"]
            if name.startswith("adis") and ch != "gyro_z":
                assert 0.1 < theta < 0.3, (ch, theta)


@pytest.mark.parametrize("theta", [-0.6, 0.4])
def test_armav_recovers_theta_and_sigma2(theta: float) -> None:
    """The GMWFM moves each non-linear term in its class's coordinate (MA1: atanh theta), so
    it fits an MA1 (the old code refused it: it moved log correlation times only). 40 logs
    of MA1(theta, 1e-2) + RW(1e-8), 2^14 samples at 100 Hz, fitted by the ARMAV (f = log10):
    the mean theta and sigma2 within 4 Monte Carlo SEs (replicate SD / sqrt(40)) of the
    truth. Measured: theta -0.6014 (SE 0.0010) and 0.3977 (SE 0.0016), sigma2 9.979e-3 and
    9.982e-3 (SE 2e-5); about 0.1 s of CPU per fit."""
    model = eg.parse_model(f"MA1(theta={theta}, sigma2=1e-2) + RW(gamma2=1e-8)")
    reps = 40
    est = np.zeros((reps, 2))
    for i in range(reps):
        wv = eg.wavelet_variance(model.simulate(2**14, fs=100.0, rng=700 + i), fs=100.0)
        res = eg.fit.fit_armav(wv, "MA1+RW")
        assert res.converged and "MA1.theta" not in res.at_bound
        est[i] = res.params["MA1.theta"], res.params["MA1.sigma2"]
    se = est.std(axis=0, ddof=1) / math.sqrt(reps)
    np.testing.assert_array_less(np.abs(est.mean(axis=0) - [theta, 1e-2]), 4 * se)


def test_armav_of_gm_plus_ma1_is_at_or_below_the_truth_and_the_gmwm_estimate() -> None:
    """GM + MA1 + RW by the ARMAV mixes two search coordinates (log correlation time, atanh
    theta). Its objective is ``sum_j w_j (log10 nu_hat_j - log10 nu_j)^2`` with ``w_j = 1 /
    (log10 ci_high_j - log10 ci_low_j)^2`` at its estimate, and at most that sum at the true
    values and at the GMWM estimate."""
    truth = eg.parse_model(
        "GM(beta=0.5, sigma2_gm=1e-4) + MA1(theta=0.3, sigma2=1e-3) + RW(gamma2=1e-9)"
    )
    wv = eg.wavelet_variance(truth.simulate(2**15, fs=100.0, rng=5), fs=100.0)
    tau = wv.tau_samples.astype(float)
    w = 1.0 / (np.log10(wv.ci_high) - np.log10(wv.ci_low)) ** 2

    def objective(m: eg.Model) -> float:
        return float(np.sum(w * (np.log10(wv.variance) - np.log10(m.wv(tau, wv.fs))) ** 2))

    res = eg.fit.fit_armav(wv, "GM+MA1+RW")
    assert res.objective == pytest.approx(objective(res.model), rel=1e-12)
    assert res.objective <= objective(truth)
    assert res.objective <= objective(eg.fit_gmwm(wv, "GM+MA1+RW").model)
    assert res.params["MA1.theta"] == pytest.approx(0.3, abs=0.1)


def test_multivariate_fit_recovers_each_channels_ma1_beside_a_shared_random_walk() -> None:
    """The multivariate fit moves each non-linear term in its class's coordinate, so a channel
    may hold an MA1 (the old code refused it). 20 two-channel logs of 2^14 samples: channel a
    MA1(-0.5, 1e-2), channel b MA1(0.4, 2e-2), a random walk shared with correlation 0.6;
    fitted as "MA1+RW" with RW shared: each channel's mean theta and sigma2 within 4 Monte
    Carlo SEs (replicate SD / sqrt(20)) of the truth. Measured: theta -0.5012 (SE 0.0014) and
    0.4006 (SE 0.0021); about 0.7 s of CPU per fit."""
    truth = eg.MultiModel(
        ["a", "b"],
        {
            "a": "MA1(theta=-0.5, sigma2=1e-2)+RW(gamma2=1e-8)",
            "b": "MA1(theta=0.4, sigma2=2e-2)+RW(gamma2=1e-8)",
        },
        shared=["RW"],
        cov={"RW": [[1e-8, 6e-9], [6e-9, 1e-8]]},
    )
    want = {"a.MA1.theta": -0.5, "a.MA1.sigma2": 1e-2, "b.MA1.theta": 0.4, "b.MA1.sigma2": 2e-2}
    reps = 20
    est = np.zeros((reps, len(want)))
    for i in range(reps):
        x = truth.simulate(2**14, rng=900 + i)
        res = eg.fit_mgmwm(x, eg.MultiModel(["a", "b"], "MA1+RW", shared=["RW"]))
        assert not any(".theta" in b for b in res.at_bound)
        est[i] = [res.params[k] for k in want]
    se = est.std(axis=0, ddof=1) / math.sqrt(reps)
    np.testing.assert_array_less(np.abs(est.mean(axis=0) - list(want.values())), 4 * se)


def test_multivariate_fit_without_shared_terms_is_the_univariate_fits() -> None:
    """Nothing shared: the multivariate objective is the sum of the channels' own, so each
    channel's MA1 + RW estimate is its univariate GMWM fit's (theta to 1e-5)."""
    model = eg.parse_model("MA1(theta=0.3, sigma2=1e-2) + RW(gamma2=1e-8)")
    x = {c: model.simulate(2**14, rng=seed) for c, seed in (("a", 11), ("b", 12))}
    res = eg.fit_mgmwm(x, eg.MultiModel(["a", "b"], "MA1+RW"))
    for c in ("a", "b"):
        uni = eg.fit_gmwm(eg.wavelet_variance(x[c]), "MA1+RW").params
        assert res.params[f"{c}.MA1.theta"] == pytest.approx(uni["MA1.theta"], abs=1e-5)
        assert res.params[f"{c}.MA1.sigma2"] == pytest.approx(uni["MA1.sigma2"], rel=1e-5)


def _shared_ma1() -> eg.MultiModel:
    """Two channels sharing an MA1 (theta 0.4, innovation covariance with correlation 0.42),
    each with its own random walk."""
    return eg.MultiModel(
        ["a", "b"],
        "MA1+RW(gamma2=1e-8)",
        shared=["MA1"],
        cov={"MA1": [[1e-2, 6e-3], [6e-3, 2e-2]]},
        nl={"MA1": 0.4},
    )


def test_shared_ma1_implied_wccv_against_monte_carlo() -> None:
    """A shared MA1 (``simulate_shared``: one theta, correlated innovations, stationary from
    the first sample): over 100 simulated logs of 2^12 samples the mean WV and WCCV at 8
    levels are within 4 standard errors of the implied ``b_j(theta) C`` (24 moments at 4 SE:
    a false alarm below 2e-3). Measured: largest |z| 2.06."""
    mm = _shared_ma1()
    reps, levels = 100, 8
    sims = np.array(
        [
            eg.wv.wv_matrix(
                mm.simulate(2**12, rng=r), channels=["a", "b"], levels=levels, ci=False
            ).values
            for r in range(reps)
        ]
    )
    implied = mm.implied(2.0 ** np.arange(1, levels + 1), 1.0)
    z = (sims.mean(axis=0) - implied) / (sims.std(axis=0, ddof=1) / math.sqrt(reps))
    assert np.all(np.abs(z) < 4.0), z


def test_shared_ma1_is_recovered_and_its_interval_uses_its_own_transform() -> None:
    """20 logs of 2^14 samples of the shared MA1 above, fitted as "MA1+RW" with MA1 shared:
    theta and the innovation covariance within 4 Monte Carlo SEs (replicate SD / sqrt(20)) of
    the truth. The Wald interval of the shared theta is symmetric in atanh(theta), the
    transform MA1 declares. Measured: theta 0.3990 (SE 0.0027), cov 9.967e-3, 5.971e-3,
    1.998e-2; about 0.13 s of CPU per fit."""
    truth = _shared_ma1()
    want = {
        "MA1.theta": 0.4,
        "MA1.cov[a,a]": 1e-2,
        "MA1.cov[a,b]": 6e-3,
        "MA1.cov[b,b]": 2e-2,
    }
    reps = 20
    est = np.zeros((reps, len(want)))
    for i in range(reps):
        x = truth.simulate(2**14, rng=1000 + i)
        res = eg.fit_mgmwm(x, eg.MultiModel(["a", "b"], "MA1+RW", shared=["MA1"]))
        est[i] = [res.params[k] for k in want]
    se = est.std(axis=0, ddof=1) / math.sqrt(reps)
    np.testing.assert_array_less(np.abs(est.mean(axis=0) - list(want.values())), 4 * se)
    ci = res.conf_int()
    k = ci.names.index("MA1.theta")
    lo, est_k, hi = ci.lower[k], ci.estimate[k], ci.upper[k]
    assert lo < est_k < hi
    assert math.atanh(lo) + math.atanh(hi) == pytest.approx(2 * math.atanh(est_k), abs=1e-9)


def test_the_ranking_keeps_it() -> None:
    """The ranking neither folds an MA1 into WN (it has no correlation time, whatever its
    theta) nor takes it for a random walk."""
    model = eg.parse_model("MA1(theta=-0.3, sigma2=1e-2) + RW(gamma2=1e-8)")
    wv = eg.wavelet_variance(model.simulate(2**14, fs=100.0, rng=4), fs=100.0)
    ranked = {c.model: c for c in eg.rank_models(wv, ["MA1+RW", "QN+WN+RW"]).candidates}
    ma = ranked["RW+MA1"]
    assert ma.sub_sample == () and ma.changes == () and not ma.error
    # theta < 0 with RW: the same WV family as QN+WN+RW, the same minimum
    assert ma.objective == pytest.approx(ranked["QN+WN+RW"].objective, rel=1e-6)


def test_replicate_fit_starts_from_given_values_of_either_sign() -> None:
    """Three recordings of MA1(theta = -0.3) + RW fitted together from the true values as a
    start: the start is the process's own coordinate (atanh theta; a log correlation time of a
    negative theta was a math domain error), and theta is recovered within 0.05."""
    model = eg.parse_model("MA1(theta=-0.3, sigma2=1e-2) + RW(gamma2=1e-8)")
    wvs = [
        eg.wavelet_variance(model.simulate(2**14, fs=100.0, rng=40 + i), fs=100.0) for i in range(3)
    ]
    res = eg.fit.fit_replicates(wvs, model)
    assert res.params["MA1.theta"] == pytest.approx(-0.3, abs=0.05)
    assert res.objective <= eg.fit.fit_replicates(wvs, "MA1+RW").objective * (1 + 1e-9)


def test_on_the_adis_gyros_the_armav_and_the_multivariate_fit_take_an_ma1(real_data: Path) -> None:
    """ADIS16405 imu1 gyro_x/y/z (10^6 samples at 100 Hz): the ARMAV's MA1 + RW reaches at most
    its QN + WN + RW objective on each axis (MA1 spans every mix of those two shapes and more);
    the multivariate fit with nothing shared gives each axis its univariate GMWM theta; with
    the MA1 shared the common theta lies between the axes' own and its interval is finite.

    Measured: ARMAV objectives 2.21 / 2.75 / 2524 against 1033 / 1010 / 2859; theta per axis
    0.1745 / 0.1724 / 0.0453 (GMWM, and the multivariate fit); shared theta 0.1247 (95 %
    0.1234-0.1260)."""
    log = eg.load_log(real_data / "adis16405_imu1.h5")
    axes = ["gyro_x", "gyro_y", "gyro_z"]
    own = {}
    for c in axes:
        wv = log.wavelet_variance(c)
        ma, qw = eg.fit.fit_armav(wv, "MA1+RW"), eg.fit.fit_armav(wv, "QN+WN+RW")
        assert ma.objective <= qw.objective * (1 + 1e-9), c
        own[c] = eg.fit_gmwm(wv, "MA1+RW").params["MA1.theta"]
    wvm = eg.wv.wv_matrix({c: np.asarray(log[c]) for c in axes}, channels=axes, fs=log.fs)
    indep = eg.fit_mgmwm(wvm, eg.MultiModel(axes, "MA1+RW"))
    for c in axes:
        assert indep.params[f"{c}.MA1.theta"] == pytest.approx(own[c], abs=1e-4)
    shared = eg.fit_mgmwm(wvm, eg.MultiModel(axes, "MA1+RW", shared=["MA1"]))
    theta = shared.params["MA1.theta"]
    assert min(own.values()) < theta < max(own.values())
    ci = shared.conf_int()
    k = ci.names.index("MA1.theta")
    assert ci.lower[k] < theta < ci.upper[k] and ci.upper[k] - ci.lower[k] < 0.01
