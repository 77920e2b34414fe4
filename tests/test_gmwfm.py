"""GMWFM and ARMAV: the objective's minimum, the GMWM as the identity case, GM terms, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

import engine as eg
from engine.fit.gmwfm import fit_armav, fit_gmwfm


@pytest.fixture(scope="module")
def accel_like() -> tuple[eg.Model, eg.WaveletVariance]:
    truth = eg.parse_model("QN(q2=0.05)+WN(sigma2=1.0)+RW(gamma2=1e-6)+DR(omega=1e-5)")
    return truth, eg.wavelet_variance(truth.simulate(2**17, rng=4))


def brute_log10_min(wv: eg.WaveletVariance, model: eg.Model, w: np.ndarray) -> float:
    from scipy import optimize

    x = np.column_stack([p.basis(wv.tau_samples.astype(float), wv.fs) for p in model])
    fy = np.log10(wv.variance)

    def obj(u):
        with np.errstate(all="ignore"):
            r = fy - np.log10(x @ np.exp(np.minimum(u, 700.0)))
        return float(np.sum(w * r * r)) if np.all(np.isfinite(r)) else 1e300

    rng = np.random.default_rng(0)
    best = math.inf
    scale = np.log(np.min(wv.variance[:, None] / x, axis=0))
    for _ in range(12):
        r = optimize.minimize(
            obj,
            scale + rng.uniform(-20, 0, x.shape[1]),
            method="Nelder-Mead",
            options={"xatol": 1e-10, "fatol": 1e-15, "maxfev": 20000},
        )
        r = optimize.minimize(obj, r.x, method="BFGS")
        best = min(best, r.fun)
    return best


def test_armav_reaches_the_minimum_of_its_objective(accel_like):
    truth, wv = accel_like
    est = fit_armav(wv, truth.cleared())
    w = 1 / (np.log10(wv.ci_high) - np.log10(wv.ci_low)) ** 2
    assert est.objective <= brute_log10_min(wv, truth.cleared(), w) * (1 + 1e-7)
    unw = fit_armav(wv, truth.cleared(), weights="identity")
    assert unw.objective <= brute_log10_min(wv, truth.cleared(), np.ones(wv.n_levels)) * (1 + 1e-7)
    assert est.method == "ARMAV" and "f = log10" in est.notes[0]
    r = np.log10(wv.variance) - np.log10(est.implied)
    assert est.objective == pytest.approx(float(np.sum(w * r * r)), rel=1e-12)


def test_gmwfm_identity_is_the_gmwm(accel_like):
    truth, wv = accel_like
    g = eg.fit_gmwm(wv, truth.cleared())
    exact = fit_gmwfm(wv, truth.cleared(), f="identity")
    assert exact.params == pytest.approx(g.params, rel=1e-12)
    generic = fit_gmwfm(wv, truth.cleared(), f=lambda v: v)  # the generic optimiser
    assert generic.objective <= g.objective * (1 + 1e-6)
    assert generic.method == "GMWFM(<lambda>)"


def test_gmwfm_with_gauss_markov():
    truth = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-4)+WN(sigma2=1e-3)")
    wv = eg.wavelet_variance(truth.simulate(2**17, fs=100.0, rng=2), fs=100.0)
    est = fit_armav(wv, truth.cleared())
    assert est.params["GM.beta"] == pytest.approx(0.5, rel=0.15)
    assert est.params["GM.sigma2_gm"] == pytest.approx(1e-4, rel=0.15)
    assert est.params["WN.sigma2"] == pytest.approx(1e-3, rel=0.02)
    sq = fit_gmwfm(wv, truth.cleared(), f="sqrt")
    assert sq.params["WN.sigma2"] == pytest.approx(1e-3, rel=0.02)


def test_gmwfm_errors(accel_like):
    truth, wv = accel_like
    zero = eg.WaveletVariance.from_arrays(np.r_[wv.variance[:-1], 0.0], n=wv.n)
    with pytest.raises(eg.FitError, match="zero at level"):
        fit_armav(zero, "WN")
    with pytest.raises(eg.FitError, match="unknown f"):
        fit_gmwfm(wv, "WN", f="cube")
    with pytest.raises(eg.ModelError):
        fit_armav(wv.truncate(2), truth.cleared())
