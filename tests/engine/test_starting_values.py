"""engine.fit.start (rough starting values read off a WV) and engine.fit.gmwm_objective."""

from __future__ import annotations

import math

import numpy as np
import pytest

import engine as eg


@pytest.fixture(scope="module")
def wv() -> eg.WaveletVariance:
    rng = np.random.default_rng(7)
    n = 2**14
    x = 0.1 * rng.normal(size=n) + 0.001 * np.cumsum(rng.normal(size=n))
    return eg.wavelet_variance(x, fs=200.0)


def test_linear_values_are_half_the_tightest_ratio(wv: eg.WaveletVariance) -> None:
    """WN: WV = sigma2 / tau; RW: gamma2 (tau^2 + 2) / (12 tau); DR: omega^2 tau^2 / 16 (tau in
    samples). Each guess is half the largest value whose curve stays below the empirical WV."""
    tau = wv.tau_samples.astype(float)
    nu = wv.variance
    got = eg.fit.starting_values(eg.parse_model("WN+RW+DR"), wv)
    assert set(got) == {"WN.sigma2", "RW.gamma2", "DR.omega"}
    assert got["WN.sigma2"] == pytest.approx(0.5 * np.min(nu * tau), rel=1e-12)
    assert got["RW.gamma2"] == pytest.approx(0.5 * np.min(nu * 12 * tau / (tau**2 + 2)), rel=1e-12)
    assert got["DR.omega"] == pytest.approx(math.sqrt(0.5 * np.min(nu * 16 / tau**2)), rel=1e-12)


def test_correlation_times_spread_geometrically(wv: eg.WaveletVariance) -> None:
    """Two nonlinear processes: correlation times tau_J / 4 (the slowest, first) and 2 samples;
    a GM's beta is fs / T, an AR1's phi is exp(-1 / T)."""
    t_slow, t_fast = wv.tau_samples[-1] / 4.0, 2.0
    got = eg.fit.starting_values(eg.parse_model("GM+AR1"), wv)
    assert got["GM.beta"] == pytest.approx(wv.fs / t_slow, rel=1e-12)
    assert got["AR1.phi"] == pytest.approx(math.exp(-1.0 / t_fast), rel=1e-12)
    two = eg.fit.starting_values(eg.parse_model("2*GM"), wv)
    assert two["GM_1.beta"] == pytest.approx(wv.fs / t_slow, rel=1e-12)
    assert two["GM_2.beta"] == pytest.approx(wv.fs / t_fast, rel=1e-12)
    one = eg.fit.starting_values(eg.parse_model("AR1"), wv)  # one: the slowest only
    assert one["AR1.phi"] == pytest.approx(math.exp(-1.0 / t_slow), rel=1e-12)


@pytest.mark.parametrize("spec", ["WN+RW", "QN+WN+AR1+GM+DR", "2*GM+WN", "MA1+RW", "GM+MA1+DR"])
def test_each_guessed_curve_touches_half_the_empirical_wv(
    wv: eg.WaveletVariance, spec: str
) -> None:
    """The intent: each process's WV curve at its guessed values is at most half the empirical
    WV at every scale and exactly half at its binding scale; the guessed model's WV stays
    below (number of processes) / 2 times the empirical WV and reaches half of it somewhere."""
    model = eg.parse_model(spec)
    vals = eg.fit.starting_values(model, wv)
    assert set(vals) == {
        f"{lab}.{n}"
        for lab, p in zip(model.labels, model.processes, strict=True)
        for n in p.param_names
    }
    total = np.zeros(wv.n_levels)
    for lab, p in zip(model.labels, model.processes, strict=True):
        q = p.with_values(**{n: vals[f"{lab}.{n}"] for n in p.param_names})
        curve = np.asarray(eg.Model((q,)).wv(wv.tau_samples.astype(float), wv.fs), float)
        ratio = curve / wv.variance
        assert ratio.max() == pytest.approx(0.5, rel=1e-9)
        total += curve
    r = total / wv.variance
    assert r.max() >= 0.5 - 1e-9 and r.max() <= 0.5 * len(model) + 1e-9


@pytest.mark.parametrize("theta", [-0.6, 0.5])
def test_ma1_theta_is_read_off_the_two_smallest_scales(theta: float) -> None:
    """An MA1's start is its own (``MA1.start_nl``): the theta whose WV ratio
    ``nu(4) / nu(2) = (2 + theta + 2 theta^2) / (4 (1 - theta + theta^2))`` is the data's,
    within 0.05 of the truth on a 2^14-sample MA1 + RW log (the ratio's sampling error moves it
    by about 0.01 here); the old start, a correlation time of a quarter of the largest scale,
    gave theta = 0.9998 whatever the data. A fit from the started model reaches the plain
    fit's objective (GMWM and ARMAV), and a GM beside it keeps the correlation-time start."""
    truth = eg.parse_model(f"MA1(theta={theta}, sigma2=1e-2) + RW(gamma2=1e-9)")
    wv = eg.wavelet_variance(truth.simulate(2**14, fs=100.0, rng=21), fs=100.0)
    got = eg.fit.starting_values(eg.parse_model("MA1+RW"), wv)
    assert got["MA1.theta"] == pytest.approx(theta, abs=0.05)
    r = wv.variance[1] / wv.variance[0]
    t = got["MA1.theta"]  # on a grid of step 0.01: the ratio within a step's change of it
    assert (2 + t + 2 * t * t) / (4 * (1 - t + t * t)) == pytest.approx(r, rel=0.02)
    started = eg.parse_model("MA1+RW").processes
    model = eg.Model(
        tuple(
            p.with_values(**{n: got[f"{lab}.{n}"] for n in p.param_names})
            for lab, p in zip(eg.parse_model("MA1+RW").labels, started, strict=True)
        )
    )
    for fit in (eg.fit_gmwm, eg.fit.fit_armav):
        plain, from_start = fit(wv, "MA1+RW"), fit(wv, model)
        assert from_start.objective <= plain.objective * (1 + 1e-9)
        assert from_start.params["MA1.theta"] == pytest.approx(theta, abs=0.05)
    both = eg.fit.starting_values(eg.parse_model("GM+MA1+RW"), wv)
    assert both["MA1.theta"] == got["MA1.theta"]
    assert both["GM.beta"] == pytest.approx(wv.fs / (wv.tau_samples[-1] / 4.0), rel=1e-12)


def test_gmwm_objective_is_the_fits_objective_and_a_weighted_sum(wv: eg.WaveletVariance) -> None:
    """``gmwm_objective`` at a fit's estimate is the fit's objective; at other values it is
    sum_j w_j (nu_hat_j - nu_j)^2 with the diagonal weights 1 / (ci_high - ci_low)^2."""
    for spec in ("WN+RW", "GM+WN"):
        for weights in ("ci", "identity"):
            fit = eg.fit_gmwm(wv, spec, weights=weights)
            got = eg.fit.gmwm_objective(wv, fit.model, weights)
            assert got == pytest.approx(fit.objective, rel=1e-12, abs=0)
    model = eg.parse_model("WN(sigma2=0.01)+RW(gamma2=1e-6)")
    tau = wv.tau_samples.astype(float)
    nu = 0.01 / tau + 1e-6 * (tau**2 + 2) / (12 * tau)
    w = 1.0 / (wv.ci_high - wv.ci_low) ** 2
    want = float(np.sum(w * (wv.variance - nu) ** 2))
    assert eg.fit.gmwm_objective(wv, model) == pytest.approx(want, rel=1e-12)
    assert eg.fit.gmwm_objective(wv, "WN(sigma2=0.01)+RW(gamma2=1e-6)") == pytest.approx(
        want, rel=1e-12
    )
    ident = float(np.sum((wv.variance - nu) ** 2))
    assert eg.fit.gmwm_objective(wv, model, "identity") == pytest.approx(ident, rel=1e-12)
