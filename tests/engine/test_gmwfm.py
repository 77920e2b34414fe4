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
    assert est.estimator == "ARMAV" and "f = log10" in est.notes[0]
    r = np.log10(wv.variance) - np.log10(est.implied)
    assert est.objective == pytest.approx(float(np.sum(w * r * r)), rel=1e-12)


def test_gmwfm_identity_is_the_gmwm(accel_like):
    truth, wv = accel_like
    g = eg.fit_gmwm(wv, truth.cleared())
    exact = fit_gmwfm(wv, truth.cleared(), f="identity")
    assert exact.params == pytest.approx(g.params, rel=1e-12)
    generic = fit_gmwfm(wv, truth.cleared(), f=lambda v: v)  # the generic optimiser
    assert generic.objective <= g.objective * (1 + 1e-6)
    assert generic.estimator == "GMWFM(<lambda>)"


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


def test_terms_at_zero_are_named_by_their_label_in_the_ordered_fitted_model():
    """The old ARMAV named a zero-variance GM by its position before the most-persistent-first
    ordering, so ``at_bound`` could point at a GM with a positive variance."""
    truth = eg.parse_model(
        "GM(beta=5.0, sigma2_gm=1.0)+GM(beta=0.05, sigma2_gm=0.5)+WN(sigma2=1.0)+RW(gamma2=1e-6)"
    )
    n_zero = 0
    for seed, f in ((3, "log10"), (4, "sqrt"), (5, "sqrt")):
        wv = eg.wavelet_variance(truth.simulate(2**14, fs=100.0, rng=seed), fs=100.0)
        est = fit_gmwfm(wv, "3*GM+WN+RW", f=f)
        zero = {
            f"{lab}.{p.param_names[-1] if p.nonlinear else p.param_names[0]}"
            for lab, p in zip(est.model.labels, est.model.processes, strict=True)
            if p.linear_coef() == 0.0
        }
        n_zero += len(zero)
        assert zero == {b for b in est.at_bound if not b.endswith((".beta", ".phi"))}
        betas = [est.params[f"GM_{i}.beta"] for i in (1, 2, 3)]
        assert betas == sorted(betas)  # most persistent first
    assert n_zero >= 1  # the third GM is not needed: some variance is 0


def test_the_gmwfm_result_shares_the_fit_result_base(accel_like):
    from engine.fit import FitResult

    truth, wv = accel_like
    est = fit_armav(wv, truth.cleared())
    assert isinstance(est, FitResult) and est.weights == "ci" and est.estimator == "ARMAV"
    w = 1 / (np.log10(wv.ci_high) - np.log10(wv.ci_low)) ** 2
    np.testing.assert_allclose(np.diagonal(est.omega), w, rtol=1e-12)
    r = np.log10(wv.variance) - np.log10(est.implied)
    assert est.objective == pytest.approx(float(r @ est.omega @ r), rel=1e-12)
    assert est.summary().startswith("ARMAV fit of") and est.n_evaluations > 0
    d = est.to_dict()
    assert d["f"] == "log10" and d["weights"] == "ci" and d["params"][0]["label"] == "QN"
    common = est.as_estimate()
    assert common.method == "ARMAV" and common.params == est.params
    assert common.objective == est.objective
