"""Covariance of the WV, efficient weights, intervals, J-test (Monte Carlo against known truth)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.fit import fit_efficient
from engine.fit.asymptotic import free_params, jacobian, wv_cov_model
from engine.fit.covariance import wv_cov_bootstrap, wv_cov_data
from engine.inference import j_test, param_intervals


def corr(a: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.diagonal(a))
    return a / np.outer(d, d)


@pytest.mark.parametrize(
    ("spec", "fs"),
    [
        ("WN(sigma2=1)+RW(gamma2=1e-4)", 1.0),
        # 7 s of CPU each: the slow tier (the WN+RW case above keeps the claim in the default)
        pytest.param("GM(beta=2, sigma2_gm=1)+WN(sigma2=0.5)", 100.0, marks=pytest.mark.slow),
        pytest.param("AR1(phi=0.999, sigma2=1)+WN(sigma2=1)", 1.0, marks=pytest.mark.slow),
    ],
)
def test_model_covariance_matches_monte_carlo(spec, fs):
    model = eg.parse_model(spec)
    wv = eg.wavelet_variance(model.simulate(2**12, fs=fs, rng=0), fs=fs)
    v = wv_cov_model(model, wv)
    mc = wv_cov_bootstrap(model, wv, B=1500, seed=1)
    ratio = np.diagonal(v)[:-2] / np.diagonal(mc)[:-2]
    # the MC variance of a variance estimate over 1500 draws has a relative SE of about 4-8 %
    assert np.all(np.abs(ratio - 1) < 0.2), ratio
    assert np.all(np.abs(corr(v)[:7, :7] - corr(mc)[:7, :7]) < 0.12)
    assert np.all(np.linalg.eigvalsh(v) > 0)


def test_model_covariance_of_white_noise_level_one_is_exact():
    """Level 1 of WN: W_t = (x_t - x_{t-1})/2, MA(1); Var(mean W^2) = 2/M sum_d C(d)^2."""
    wv = eg.wavelet_variance(np.random.default_rng(0).standard_normal(1000))
    v = wv_cov_model(eg.parse_model("WN(sigma2=1)"), wv)
    c0, c1 = 0.5, -0.25
    assert v[0, 0] == pytest.approx(2 * (c0**2 + 2 * c1**2) / 999, rel=1e-10)


def test_data_covariance_diagonal_matches_monte_carlo():
    model = eg.parse_model("GM(beta=2, sigma2_gm=1)+WN(sigma2=0.5)")
    rng = np.random.default_rng(2)
    xs = [model.simulate(2**13, fs=100.0, rng=rng) for _ in range(200)]
    wvs = [eg.wavelet_variance(x, fs=100.0) for x in xs]
    mc = np.var([w.variance for w in wvs], axis=0, ddof=1)
    est = np.mean(
        [np.diagonal(wv_cov_data(x, w)) for x, w in zip(xs[:20], wvs, strict=False)], axis=0
    )
    ratio = est[:7] / mc[:7]
    assert np.all(np.abs(ratio - 1) < 0.3), ratio


def test_data_covariance_needs_matching_series():
    x = np.random.default_rng(0).standard_normal(100)
    with pytest.raises(ValueError, match="100 samples but the WV was computed from 50"):
        wv_cov_data(x, eg.wavelet_variance(x[:50]))


def coverage(spec: str, n: int, reps: int, fs: float, seed: int) -> dict[str, float]:
    model = eg.parse_model(spec)
    truth = model.values()
    rng = np.random.default_rng(seed)
    hits = dict.fromkeys(truth, 0)
    for _ in range(reps):
        res = eg.fit_gmwm(
            eg.wavelet_variance(model.simulate(n, fs=fs, rng=rng), fs=fs), model.cleared()
        )
        for iv in param_intervals(res, level=0.95):
            hits[iv.name] += iv.low <= truth[iv.name] <= iv.high
    return {k: v / reps for k, v in hits.items()}


@pytest.mark.slow
@pytest.mark.parametrize(
    ("spec", "n", "fs"),
    [
        ("WN(sigma2=1)+RW(gamma2=1e-4)", 2**14, 1.0),
        ("GM(beta=1, sigma2_gm=1)+WN(sigma2=1)", 2**15, 100.0),
    ],
)
def test_asymptotic_interval_coverage_near_nominal(spec, n, fs):
    """Two-sided 95 % intervals: coverage within 2 points of nominal, plus the binomial
    noise of 300 replicates (SE 1.3 points)."""
    cov = coverage(spec, n, 300, fs, seed=7)
    for c in cov.values():
        assert abs(c - 0.95) < 0.045, cov


def test_intervals_contain_estimate_and_respect_parameter_space():
    model = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-9)")
    wv = eg.wavelet_variance(model.simulate(2**16, fs=100.0, rng=3), fs=100.0, unit="deg/s")
    res = eg.fit_gmwm(wv, model.cleared())
    ivs = param_intervals(res)
    assert [iv.name for iv in ivs] == list(res.params)
    for iv in ivs:
        if math.isnan(iv.low):
            assert iv.name in res.at_bound or res.params[iv.name] == 0
            continue
        assert 0 < iv.low <= iv.value <= iv.high
    assert ivs[0].unit == "1/s" and ivs[1].unit == "(deg/s)^2"
    narrow = param_intervals(res, level=0.5)
    assert narrow[2].high - narrow[2].low < ivs[2].high - ivs[2].low


@pytest.mark.slow  # 120 bootstrap refits: 6 s of CPU
def test_bootstrap_intervals_agree_with_asymptotic():
    model = eg.parse_model("GM(beta=2, sigma2_gm=1)+WN(sigma2=1)")
    wv = eg.wavelet_variance(model.simulate(2**14, fs=100.0, rng=4), fs=100.0)
    res = eg.fit_gmwm(wv, model.cleared())
    a = {iv.name: iv for iv in param_intervals(res)}
    b = {iv.name: iv for iv in param_intervals(res, method="bootstrap", B=120, seed=1)}
    for name in a:
        wa, wb = a[name].high - a[name].low, b[name].high - b[name].low
        assert wb == pytest.approx(wa, rel=0.35), (name, wa, wb)


@pytest.mark.slow
def test_efficient_weights_lower_rmse_than_ci_weights():
    """Corollary 1 of the GMWM paper, Monte Carlo: V^-1 weights beat diag(1/ci width^2)."""
    model = eg.parse_model("GM(beta=2, sigma2_gm=1)+WN(sigma2=1)")
    truth = np.array(list(model.values().values()))
    rng = np.random.default_rng(11)
    err_ci, err_eff = [], []
    for _ in range(150):
        wv = eg.wavelet_variance(model.simulate(2**13, fs=100.0, rng=rng), fs=100.0)
        err_ci.append(np.array(list(eg.fit_gmwm(wv, model.cleared()).params.values())) / truth)
        err_eff.append(np.array(list(fit_efficient(wv, model.cleared()).params.values())) / truth)
    rmse_ci = np.sqrt(np.mean((np.array(err_ci) - 1) ** 2, axis=0))
    rmse_eff = np.sqrt(np.mean((np.array(err_eff) - 1) ** 2, axis=0))
    assert rmse_eff[0] < 0.95 * rmse_ci[0], (rmse_ci, rmse_eff)  # beta: clearly better
    assert np.all(rmse_eff < 1.03 * rmse_ci), (rmse_ci, rmse_eff)  # never clearly worse


@pytest.mark.slow
def test_j_test_size_under_a_correct_model():
    model = eg.parse_model("GM(beta=2, sigma2_gm=1)+WN(sigma2=1)")
    rng = np.random.default_rng(12)
    p = []
    for _ in range(200):
        wv = eg.wavelet_variance(model.simulate(2**13, fs=100.0, rng=rng), fs=100.0)
        p.append(j_test(fit_efficient(wv, model.cleared())).p_value)
    p = np.array(p)
    # size at the 5 % level near nominal (binomial SE 1.5 points at 200 replicates); the
    # statistic is slightly conservative in the bulk (V is estimated from the same fit)
    assert np.mean(p < 0.05) == pytest.approx(0.05, abs=0.035)
    assert 0.25 < np.mean(p < 0.5) <= 0.6


@pytest.mark.slow
def test_j_test_of_a_ci_fit_is_calibrated_400_replicates():
    """The J-test the app's Fit badge and the report show (j_test of the
    default ci fit) rejects the true QN+WN+RW+DR (with drift) at 5 % in 5 % of logs. 400
    replicates: binomial 95 % band 5 % +- 2.2 %. The old statistic (the ci fit's residuals in
    V^-1 on every level against chi2(J - p)) rejects far more often in the same logs.
    tests/benchmarks/bench_jtest.py runs three models, two lengths, 400 logs each."""
    from scipy import stats

    from engine.fit.asymptotic import wv_cov_model

    truth = eg.parse_model("QN(q2=2e-5)+WN(sigma2=7e-5)+RW(gamma2=1e-10)+DR(omega=5e-8)")
    rng = np.random.default_rng(22)
    reps, new, old = 400, [], []
    for _ in range(reps):
        wv = eg.wavelet_variance(truth.simulate(2**14, fs=100.0, rng=rng), fs=100.0)
        res = eg.fit_gmwm(wv, "QN+WN+RW+DR")
        new.append(j_test(res).p_value)
        r = wv.variance - res.implied
        t_old = r @ np.linalg.solve(wv_cov_model(res.model, wv), r)
        old.append(stats.chi2.sf(t_old, wv.n_levels - 4))
    band = 1.96 * np.sqrt(0.05 * 0.95 / reps)  # 0.0214
    assert abs(np.mean(np.array(new) < 0.05) - 0.05) <= band, np.mean(np.array(new) < 0.05)
    assert np.mean(np.array(old) < 0.05) > 0.2


def test_j_test_rejects_a_wrong_model():
    x = eg.parse_model("GM(beta=2, sigma2_gm=1)+WN(sigma2=0.2)").simulate(2**15, fs=100.0, rng=5)
    wv = eg.wavelet_variance(x, fs=100.0)
    assert j_test(fit_efficient(wv, "WN+RW")).p_value < 1e-6
    jt = j_test(fit_efficient(wv, "GM+WN"))
    # the statistic leaves out the last two levels (M_j / 2^j = 1 and 3 < ETA_MIN = 4)
    assert jt.p_value > 1e-3 and jt.df == jt.levels - 3 and jt.levels == wv.n_levels - 2


def test_the_v_options_are_one_keyword_list_with_one_set_of_defaults():
    """wv_cov, fit_efficient, param_intervals and j_test take the same VOptions keywords; a
    misspelt one is an error that lists them (not silently ignored)."""
    from engine.fit.covariance import V_DEFAULTS, v_options, wv_cov

    x = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)").simulate(2**12, fs=10.0, rng=1)
    res = eg.fit_gmwm(eg.wavelet_variance(x, fs=10.0), "WN+RW")
    known = "the V options are v, x, B, seed, workers, executor"
    for call in (
        lambda: wv_cov(res, "model", bootstraps=5),
        lambda: fit_efficient(res.wv, "WN+RW", bootstraps=5),
        lambda: param_intervals(res, bootstraps=5),
        lambda: j_test(res, bootstraps=5),
    ):
        with pytest.raises(TypeError, match=f"unknown keyword.*bootstraps: {known}"):
            call()
    assert list(V_DEFAULTS) == "v x B seed workers executor".split()
    assert v_options({})["B"] == 100 and v_options({}, B=200)["B"] == 200
    assert v_options({"B": 7}, B=200)["B"] == 7
    # the keywords reach their use: V from the data equals wv_cov_data; B and seed pick the
    # bootstrap replicates (the J-test's default B is 200: p is a multiple of 1/201)
    np.testing.assert_allclose(  # V from the data is diagonal: Omega = diag(1 / V_jj)
        fit_efficient(res.wv, "WN+RW", v="data", x=x).omega,
        np.diag(1.0 / np.diag(wv_cov_data(x, res.wv))),
        rtol=1e-12,
    )
    p = j_test(res, method="bootstrap", seed=4).p_value
    assert abs(p * 201 - round(p * 201)) < 1e-9
    p19 = j_test(res, method="bootstrap", B=19, seed=4).p_value
    assert abs(p19 * 20 - round(p19 * 20)) < 1e-9


def test_cli_fit_with_intervals(capsys, tmp_path):
    path = tmp_path / "s.h5"
    assert (
        main(
            [
                "simulate",
                "--model",
                "WN(sigma2=4)+RW(gamma2=1e-4)",
                "-n",
                "30000",
                "--seed",
                "2",
                "-o",
                str(path),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["fit", str(path), "--model", "WN+RW", "--ci", "asymptotic", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    names = [iv["name"] for iv in d["intervals"]]
    assert names == ["WN.sigma2", "RW.gamma2"]
    wn = d["intervals"][0]
    assert wn["low"] < 4.0 < wn["high"] and wn["level"] == 0.95
    assert main(["fit", str(path), "--model", "WN+RW", "--weights", "efficient"]) == 0
    assert "efficient" in capsys.readouterr().out


def test_jacobian_of_a_term_far_below_the_others() -> None:
    # d nu / d log(theta) of a variance is the process's own WV (nu is linear in it), even for a
    # random walk 1e-14 of the white noise at the finest scales: the difference is taken of the
    # moved process's term, not of the whole model's WV, where that term was below rounding
    # (a central difference of the sum put it 20 % off there, measured); the bound is the
    # central difference's own error in log(gamma2) = -27.6, step h = 1e-5 * 27.6: h^2 / 6 =
    # 1.3e-8
    tau = 2.0 ** np.arange(1, 20)
    wv = eg.wavelet_variance(np.random.default_rng(0).standard_normal(2**20), fs=100.0)
    model = eg.parse_model("WN(sigma2=1.0) + RW(gamma2=1e-12)")
    res = eg.fit_gmwm(wv, model, fixed=True)
    jac = jacobian(res)
    assert free_params(res) == [(0, "sigma2"), (1, "gamma2")]
    np.testing.assert_allclose(jac[:, 0], 1.0 / tau, rtol=1e-7)
    np.testing.assert_allclose(jac[:, 1], 1e-12 * (tau**2 + 2.0) / (12.0 * tau), rtol=1e-7)
