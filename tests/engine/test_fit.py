"""GMWM fitting: closed form, global minimum, recovery of known parameters, results, errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import optimize

import engine as eg
from engine.fit._varpro import NNLSProblem, sqrt_weight


def objective(wv, omega, model) -> float:
    r = wv.variance - model.wv(wv.tau_samples, wv.fs)
    return float(r @ omega @ r)


@pytest.fixture(scope="module")
def linear_wv():
    m = eg.parse_model("QN(q2=4e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-8)+DR(omega=1e-6)")
    return eg.wavelet_variance(m.simulate(2**17 + 123, fs=100.0, rng=11), fs=100.0)


def test_closed_form_equals_unconstrained_wls_when_interior(linear_wv):
    """GMWM paper eq. 7: h = (X' W X)^-1 X' W nu when every coefficient is positive."""
    res = eg.fit_gmwm(linear_wv, "QN+WN+RW+DR")
    assert res.method == "closed-form" and not res.at_bound
    tau = linear_wv.tau_samples.astype(float)
    x = np.column_stack([6 / tau**2, 1 / tau, (tau**2 + 2) / (12 * tau), tau**2 / 16])
    w = res.omega
    h = np.linalg.solve(x.T @ w @ x, x.T @ w @ linear_wv.variance)
    got = res.params
    np.testing.assert_allclose(
        [got["QN.q2"], got["WN.sigma2"], got["RW.gamma2"], got["DR.omega"] ** 2], h, rtol=1e-6
    )


def test_closed_form_equals_numerical_minimum(linear_wv):
    res = eg.fit_gmwm(linear_wv, "QN+WN+RW+DR")
    omega = res.omega

    def f(logp):
        m = eg.parse_model("QN+WN+RW+DR").processes
        vals = np.exp(logp)
        model = eg.Model(
            (
                m[0].with_values(vals[0]),
                m[1].with_values(vals[1]),
                m[2].with_values(vals[2]),
                m[3].with_values(math.sqrt(vals[3])),
            )
        )
        return objective(linear_wv, omega, model)

    best = math.inf
    for start in ([-5, -4, -18, -30], [-8, -2, -22, -33], [-3, -6, -15, -28]):
        r = optimize.minimize(
            f,
            start,
            method="Nelder-Mead",
            options={"xatol": 1e-10, "fatol": 1e-14, "maxfev": 40000},
        )
        best = min(best, r.fun)
    assert res.objective <= best * (1 + 1e-9)
    assert res.objective == pytest.approx(best, rel=1e-4)


def test_closed_form_respects_non_negativity():
    """A WN-only signal fitted with WN+RW: RW must be exactly 0 (not negative), flagged."""
    x = np.random.default_rng(1).standard_normal(50000)
    res = eg.fit_gmwm(x, "WN+RW+QN")
    assert all(v >= 0 for v in res.params.values())
    assert res.params["WN.sigma2"] == pytest.approx(1.0, rel=0.03)
    assert res.at_bound  # at least one of RW/QN is zero


def profile_min_brute(wv, spec, axes) -> float:
    """Brute-force minimum of the profiled objective over a grid of correlation times."""
    model = eg.parse_model(spec)
    omega = np.diag(1 / (wv.ci_high - wv.ci_low) ** 2)
    prob = NNLSProblem.from_wv(model, wv, sqrt_weight(omega))
    best = math.inf
    for u in axes:
        best = min(best, prob.profile(np.asarray(u, float)))
    return best


def test_ar1_wn_reaches_global_minimum_near_unit_root():
    """The R packages can stop at phi = 0.10 when the minimum is near 0.99 (docs/conventions.md)."""
    m = eg.parse_model("AR1(phi=0.99, sigma2=1e-2)+WN(sigma2=1.0)")
    wv = eg.wavelet_variance(m.simulate(2**16, rng=3))
    res = eg.fit_gmwm(wv, "AR1+WN")
    assert res.params["AR1.phi"] == pytest.approx(0.99, abs=0.006)
    grid = [(u,) for u in np.linspace(math.log(0.2), math.log(4 * 2**15), 4000)]
    assert res.objective <= profile_min_brute(wv, "AR1+WN", grid) * (1 + 1e-9)
    # objective at the R-like local answer phi = 0.1 is far worse
    prob = NNLSProblem.from_wv(eg.parse_model("AR1+WN"), wv, sqrt_weight(res.omega))
    assert prob.solve((0.1,))[0] > 10 * res.objective


def test_two_gm_fit_reaches_global_minimum_and_recovers_truth():
    truth = eg.parse_model(
        "GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.01, sigma2_gm=1e-4)"
        "+WN(sigma2=1e-2)+RW(gamma2=1e-10)"
    )
    fs = 100.0
    wv = eg.wavelet_variance(truth.simulate(10**6, fs=fs, rng=1), fs=fs)
    res = eg.fit_gmwm(wv, "2*GM+WN+RW")
    assert res.converged
    g = np.linspace(math.log(0.25), math.log(4 * 2**19), 160)
    grid = [(a, b) for a in g for b in g if a > b]
    assert res.objective <= profile_min_brute(wv, "2*GM+WN+RW", grid) * (1 + 1e-9)
    p = res.params
    # most persistent first
    assert p["GM_1.beta"] < p["GM_2.beta"]
    assert p["GM_2.beta"] == pytest.approx(0.5, rel=0.15)
    assert p["GM_2.sigma2_gm"] == pytest.approx(4e-4, rel=0.15)
    assert p["GM_1.beta"] == pytest.approx(0.01, rel=0.5)
    assert p["WN.sigma2"] == pytest.approx(1e-2, rel=0.01)


def test_monte_carlo_recovery_of_wn_rw():
    """Mean relative error over 30 replicates (known truth), with MC tolerances."""
    truth = {"WN.sigma2": 2.0, "RW.gamma2": 1e-5}
    m = eg.parse_model("WN(sigma2=2)+RW(gamma2=1e-5)")
    rng = np.random.default_rng(21)
    est = np.array(
        [
            [eg.fit_gmwm(m.simulate(2**15, rng=rng), "WN+RW").params[k] for k in truth]
            for _ in range(30)
        ]
    )
    rel = est / np.array(list(truth.values())) - 1
    assert abs(rel[:, 0].mean()) < 0.01 and rel[:, 0].std() < 0.03
    assert abs(rel[:, 1].mean()) < 0.15 and rel[:, 1].std() < 0.5


def test_gm_wn_recovery_in_continuous_time_units():
    fs = 200.0
    m = eg.parse_model("GM(beta=2.0, sigma2_gm=1e-3)+WN(sigma2=1e-3)")
    rng = np.random.default_rng(5)
    betas = [
        eg.fit_gmwm(m.simulate(2**16, fs=fs, rng=rng), "GM+WN", fs=fs).params["GM.beta"]
        for _ in range(12)
    ]
    assert np.median(betas) == pytest.approx(2.0, rel=0.15)


def test_raw_signal_and_its_wv_give_the_same_fit():
    x = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)").simulate(5000, rng=2)
    a = eg.fit_gmwm(x, "WN+RW", fs=10.0)
    b = eg.fit_gmwm(eg.wavelet_variance(x, fs=10.0), "WN+RW")
    assert a.params == b.params and a.fs == 10.0


@pytest.mark.parametrize("n", [2**10, 2**14, 2**14 + 1])
def test_power_of_two_lengths_fit(n):
    x = eg.parse_model("GM(beta=0.2, sigma2_gm=1)+WN(sigma2=1)").simulate(n, rng=n)
    res = eg.fit_gmwm(x, "GM+WN")
    assert res.wv.n_levels == int(np.floor(np.log2(n - 1)))
    assert np.isfinite(res.objective)


def test_levels_option_and_weights():
    x = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)").simulate(20000, rng=4)
    wv = eg.wavelet_variance(x)
    res8 = eg.fit_gmwm(wv, "WN+RW", levels=8)
    assert res8.wv.n_levels == 8 and res8.implied.size == 8
    ci = eg.fit_gmwm(wv, "WN+RW")
    same = eg.fit_gmwm(wv, "WN+RW", weights=1 / (wv.ci_high - wv.ci_low) ** 2)
    assert same.weights == "user"
    np.testing.assert_allclose(list(same.params.values()), list(ci.params.values()), rtol=1e-10)
    ident = eg.fit_gmwm(wv, "WN+RW", weights="identity")
    assert ident.weights == "identity"
    full = eg.fit_gmwm(wv, "WN+RW", weights=np.diag(1 / (wv.ci_high - wv.ci_low) ** 2) + 0.0)
    assert full.objective == pytest.approx(ci.objective, rel=1e-10)


def test_user_starting_values_are_used_and_never_hurt():
    truth = eg.parse_model("GM(beta=0.05, sigma2_gm=1)+WN(sigma2=1)")
    wv = eg.wavelet_variance(truth.simulate(2**15, rng=9))
    plain = eg.fit_gmwm(wv, "GM+WN")
    started = eg.fit_gmwm(wv, truth)
    assert started.objective <= plain.objective * (1 + 1e-8)


def test_result_object():
    truth = eg.parse_model("GM(beta=1, sigma2_gm=1e-2)+WN(sigma2=1e-2)+RW(gamma2=1e-8)")
    wv = eg.wavelet_variance(truth.simulate(2**16, fs=50.0, rng=3), fs=50.0, unit="deg/s")
    res = eg.fit_gmwm(wv, "GM+WN+RW")
    np.testing.assert_allclose(sum(res.components.values()), res.implied, rtol=1e-12)
    assert res.objective == pytest.approx(objective(wv, res.omega, res.model), rel=1e-12)
    np.testing.assert_allclose(res.implied_at(wv.tau_samples), res.implied, rtol=1e-12)
    d = json.loads(json.dumps(res.to_dict()))
    assert d["model"] == "GM+WN+RW" and d["weights"] == "ci" and d["n"] == 2**16
    names = [(p["process"], p["index"], p["name"]) for p in d["params"]]
    assert names == [
        ("GM", 1, "beta"),
        ("GM", 1, "sigma2_gm"),
        ("WN", 1, "sigma2"),
        ("RW", 1, "gamma2"),
    ]
    units = {p["name"]: p["unit"] for p in d["params"]}
    assert units == {
        "beta": "1/s",
        "sigma2_gm": "(deg/s)^2",
        "sigma2": "(deg/s)^2",
        "gamma2": "(deg/s)^2",
    }
    assert set(d["components"]) == {"GM", "WN", "RW"}
    text = res.summary()
    assert "GM.beta" in text and "1/s" in text and "angle random walk" in text
    assert "deg/sqrt(h)" in text and "deg/h/sqrt(h)" in text


@pytest.mark.parametrize(
    ("signal", "spec", "exc", "match"),
    [
        (np.ones(1000), "WN", eg.FitError, "constant signal"),
        (
            np.random.default_rng(0).standard_normal(40),
            "3*GM+WN+RW",
            eg.ModelError,
            "8 parameters but the WV has only 5 levels",
        ),
        (np.random.default_rng(0).standard_normal(400), "WN+WN", eg.ModelError, "2 WN terms"),
        (np.random.default_rng(0).standard_normal(400), "AR1+GM", eg.ModelError, "mixes"),
        (np.random.default_rng(0).standard_normal(400), "FOO", eg.ModelError, "unknown process"),
    ],
)
def test_fit_errors(signal, spec, exc, match):
    with pytest.raises(exc, match=match):
        eg.fit_gmwm(signal, spec)


def test_bad_weights_rejected():
    wv = eg.wavelet_variance(np.random.default_rng(0).standard_normal(400))
    with pytest.raises(eg.FitError, match="shape"):
        eg.fit_gmwm(wv, "WN", weights=np.eye(3))
    with pytest.raises(eg.FitError, match="unknown weights"):
        eg.fit_gmwm(wv, "WN", weights="efficient-ish")
    with pytest.raises(eg.FitError, match="levels=40"):
        eg.fit_gmwm(wv, "WN", levels=40)


def test_every_fit_result_shares_one_base_with_the_same_fields() -> None:
    from engine.fit import FitResult
    from engine.inference import param_intervals

    truth = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-4)+WN(sigma2=1e-3)")
    x = truth.simulate(2**15, fs=100.0, rng=3)
    wv = eg.wavelet_variance(x, fs=100.0)
    g = eg.fit_gmwm(wv, "GM+WN")
    r = eg.fit.fit_replicates([wv, eg.wavelet_variance(x[:10_000], fs=100.0)], "GM+WN")
    for res in (g, r):
        assert isinstance(res, FitResult) and res.weights == "ci"
        assert isinstance(res.omega, np.ndarray) and res.omega.ndim == 2
        text = res.summary()
        assert isinstance(text, str) and text.startswith("GMWM") and str(res) == text
        assert res._repr_html_().startswith("<pre>GMWM")
        d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
        assert {"model", "fs", "weights", "objective", "params", "converged", "at_bound"} <= set(d)
        assert [f"{p['label']}.{p['name']}" for p in d["params"]] == list(res.params)
    # the objective is the quadratic form in omega (block diagonal for the replicates)
    e = wv.variance - g.implied
    assert g.objective == pytest.approx(float(e @ g.omega @ e), rel=1e-12)
    e = np.concatenate([w.variance - im for w, im in zip(r.wvs, r.implied, strict=True)])
    assert r.objective == pytest.approx(float(e @ r.omega @ e), rel=1e-12)
    # conf_int: the asymptotic intervals, labelled; a 90 % interval inside the 95 % one
    ci90, ci95 = g.conf_int(0.10), g.conf_int()
    assert ci90.names == tuple(g.params) and ci90.level == pytest.approx(0.9)
    for iv in param_intervals(g, level=0.9):
        assert ci90.row(iv.name) == (iv.value, iv.low, iv.high)
        _, lo95, hi95 = ci95.row(iv.name)
        assert lo95 < iv.low < iv.value < iv.high < hi95
    assert "<table>" in ci90._repr_html_() and "GM.beta" in str(ci90)
    with pytest.raises(eg.FitError, match="not available"):
        r.conf_int()


def test_efficient_weights_are_a_choice_of_fit_gmwm():
    """``fit_gmwm(weights="efficient")``: the ci fit, V implied by it, the refit with V^-1 (the
    GMWM paper, Corollary 1), step by step; ``fit_efficient`` is the same call."""
    from engine.fit import fit_efficient
    from engine.fit.asymptotic import inverse_cov, wv_cov_model
    from engine.fit.covariance import wv_cov_data

    rng = np.random.default_rng(3)
    x = rng.normal(scale=0.05, size=2**14) + np.cumsum(rng.normal(scale=1e-3, size=2**14))
    wv = eg.wavelet_variance(x, fs=100.0)
    eff = eg.fit_gmwm(wv, "WN+RW", weights="efficient")
    first = eg.fit_gmwm(wv, "WN+RW")
    by_hand = eg.fit_gmwm(wv, first.model, weights=inverse_cov(wv_cov_model(first.model, wv)))
    assert eff.weights == "efficient"
    np.testing.assert_array_equal(eff.omega, by_hand.omega)
    assert eff.params == by_hand.params
    assert fit_efficient(wv, "WN+RW").params == eff.params
    # a raw signal and levels go through the same path
    raw = eg.fit_gmwm(x, "WN+RW", fs=100.0, weights="efficient", levels=8)
    assert raw.wv.n_levels == 8 and raw.weights == "efficient"
    # the V options reach the estimate of V
    data = eg.fit_gmwm(wv, "WN+RW", weights="efficient", v="data", x=x)
    np.testing.assert_allclose(data.omega, inverse_cov(wv_cov_data(x, wv)), rtol=1e-12)
    with pytest.raises(TypeError, match="v, x set how V is estimated.*weights='efficient'"):
        eg.fit_gmwm(wv, "WN+RW", v="data", x=x)
