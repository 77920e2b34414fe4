"""The pieces of the profiled objective that make model selection cheaper, checked against
independent computations. What selection costs is a benchmark, not a test:
tests/benchmarks/bench_ranking.py prints it (a ratio to a bare NumPy Haar WV timed in the same
run) and docs/performance.md has the before/after table.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize

import engine as eg
from engine.fit._varpro import NNLSProblem, sqrt_weight
from engine.fit.gmwm import weight_matrix
from engine.models.processes import ar1_wv, ar1_wv_pos


def test_ar1_series_branch_equals_the_vectorised_formula() -> None:
    # correlation times from 0.01 samples to 1e9: the series (x tau < 2e-3) covers none, some
    # and all of the scales; ar1_wv's array branch evaluates it term by term, independently
    tau = 2.0 ** np.arange(1, 21)
    for tc in (0.01, 0.7, 30.0, 600.0, 3e3, 1e5, 1e7, 1e9):
        phi = math.exp(-1.0 / tc)
        fast = ar1_wv_pos(tau, phi)
        ref = ar1_wv(tau, np.array([phi]))[0]
        np.testing.assert_allclose(fast, ref, rtol=1e-13, atol=0)
    # and the defining limit: a random walk's WV per unit innovation as phi = exp(-x) -> 1
    # (the first correction is -3 x tau / 8 relative: 4e-10 at x = 1e-15, tau = 2^20)
    rw = (tau**2 + 2.0) / (12.0 * tau)
    np.testing.assert_allclose(ar1_wv_pos(tau, math.exp(-1e-15)), rw, rtol=1e-9)


def _problem(model: str, weights: str = "ci") -> NNLSProblem:
    x = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-8)").simulate(
        2**16, fs=100.0, rng=np.random.default_rng(4)
    )
    wv = eg.wavelet_variance(x, fs=100.0)
    omega = (
        weight_matrix(wv, weights)[0]
        if weights == "ci"
        else np.linalg.inv(np.diag(wv.variance) ** 2 + 1e-3 * np.outer(wv.variance, wv.variance))
    )
    return NNLSProblem.from_wv(eg.parse_model(model), wv, sqrt_weight(omega))


@pytest.mark.parametrize("weights", ["ci", "full"])
def test_profile_is_the_nnls_of_the_weighted_design(weights: str) -> None:
    # the profile (constant columns weighted once, a diagonal A as a vector) against the NNLS of
    # A X formed here from the processes' own basis, for a diagonal and a full weight matrix
    prob = _problem("2*GM+WN+QN+RW+DR", weights)
    u = np.log([400.0, 3.0])
    phis = np.exp(-1.0 / np.exp(u))
    cols = [
        p.basis(prob.tau, prob.fs, phis[list(prob.nl_idx).index(i)] if p.nonlinear else None)
        for i, p in enumerate(prob.model.processes)
    ]
    c = prob.a @ np.column_stack(cols)
    norms = np.linalg.norm(c, axis=0)
    g, rnorm = scipy.optimize.nnls(c / norms, prob.b)
    assert prob.profile(u) == pytest.approx(rnorm**2, rel=1e-10)
    assert prob.solve(tuple(phis))[0] == pytest.approx(rnorm**2, rel=1e-10)


def test_each_point_of_the_profile_is_solved_once() -> None:
    prob = _problem("2*GM+WN")
    u = np.log([400.0, 3.0])
    first = prob.profile(u)
    n = prob.n_eval
    assert prob.profile(u.copy()) == first and prob.n_eval == n
    prob.profile(u + [1e-9, 0.0])
    assert prob.n_eval == n + 1
