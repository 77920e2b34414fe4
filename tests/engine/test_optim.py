"""The fit path's own kernels (engine._optim) against SciPy and analytic values; its NNLS (SciPy's)
by the KKT conditions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize, special

from engine._optim import chi2_isf, gamma_p, least_squares, nnls

DFS = [
    0.3,
    1.0,
    1.3,
    2.0,
    3.7,
    10.0,
    19.9,
    20.1,
    55.5,
    150.0,
    199.0,
    201.0,
    1e3,
    3.2e4,
    1e5,
    3.15e6,
]


@pytest.mark.parametrize("p", [0.025, 0.975, 0.005, 0.995, 0.5, 0.3, 1e-6, 1e-12])
def test_chi2_isf_equals_scipy(p: float) -> None:
    ours = chi2_isf(np.array(DFS), p)
    ref = special.chdtri(np.array(DFS), p)
    np.testing.assert_allclose(ours, ref, rtol=1e-12)


def test_chi2_isf_far_lower_tail_of_huge_df_matches_cornish_fisher() -> None:
    # scipy's chdtri loses ~1e-5 here; the Cornish-Fisher expansion is exact to O(1/sqrt(df))
    for df in (1e8, 1e10):
        for p_low in (1e-6, 1e-12):
            z = -float(special.ndtri(1 - p_low))  # the lower p_low quantile of N(0, 1)
            cf = (
                df
                + z * math.sqrt(2 * df)
                + 2 / 3 * (z * z - 1)
                + (z**3 - 7 * z) / (9 * math.sqrt(2 * df))
            )
            assert chi2_isf(df, 1 - p_low) == pytest.approx(cf, rel=0, abs=1e-2)


def test_chi2_isf_analytic_cases() -> None:
    # df = 2: exponential with mean 2, isf = -2 log p
    for p in (0.9, 0.5, 0.025, 1e-9):
        assert chi2_isf(2.0, p) == pytest.approx(-2 * math.log(p), rel=1e-14)
    # df = 1: (Phi^-1(1 - p/2))^2
    assert chi2_isf(1.0, 0.05) == pytest.approx(1.959963984540054**2, rel=1e-13)
    assert chi2_isf(3.0, 0.0) == math.inf and chi2_isf(3.0, 1.0) == 0.0
    with pytest.raises(ValueError):
        chi2_isf(0.0, 0.5)


@pytest.mark.parametrize(
    "a,x",
    [
        (0.5, 0.01),
        (1.0, 3.0),
        (100.0, 90.0),
        (1e6, 1.003e6),
        (5.0, 40.0),
        (150.0, 300.0),
        (50.0, 80.0),
        (20.0, 21.5),
        (3.0, 0.5),
        (99.0, 150.0),
    ],
)
def test_gamma_p_equals_scipy(a: float, x: float) -> None:
    assert gamma_p(a, x) == pytest.approx(special.gammainc(a, x), rel=1e-13, abs=1e-300)
    # a = 1: P = 1 - exp(-x)
    assert gamma_p(1.0, x) == pytest.approx(-math.expm1(-x), rel=1e-14)


def test_nnls_reaches_scipy_residual() -> None:
    rng = np.random.default_rng(0)
    for _ in range(300):
        m, n = int(rng.integers(3, 25)), int(rng.integers(1, 8))
        a = rng.normal(size=(m, n)) * np.exp(rng.uniform(-6, 6, n))  # badly scaled columns
        b = rng.normal(size=m)
        x1, r1 = nnls(a, b)
        x2, r2 = optimize.nnls(a, b)
        assert np.all(x1 >= 0)
        assert r1 <= r2 * (1 + 1e-9) + 1e-12
        if m >= n:  # unique solution
            np.testing.assert_allclose(a @ x1, a @ x2, rtol=1e-7, atol=1e-9 * np.abs(b).max())


def test_nnls_kkt_conditions() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(20, 6))
    b = rng.normal(size=20)
    x, _ = nnls(a, b)
    grad = a.T @ (a @ x - b)
    free = x > 0
    np.testing.assert_allclose(grad[free], 0.0, atol=1e-10)
    assert np.all(grad[~free] >= -1e-10)


def test_least_squares_reaches_scipy_cost_with_and_without_active_bounds() -> None:
    """Exponential-decay fits (a classic non-linear least squares) against SciPy's TRF."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 4.0, 30)
    for _ in range(20):
        truth = np.array([rng.uniform(0.5, 3), rng.uniform(0.2, 2), rng.uniform(-1, 1)])
        y = truth[0] * np.exp(-truth[1] * t) + truth[2] + 0.02 * rng.normal(size=t.size)

        def res(p: np.ndarray, y: np.ndarray = y) -> np.ndarray:
            return p[0] * np.exp(-p[1] * t) + p[2] - y

        for lb, ub in (
            (np.full(3, -10.0), np.full(3, 10.0)),  # inactive
            (np.array([0.0, 0.0, 0.0]), np.array([10.0, 10.0, 10.0])),  # offset >= 0
        ):
            x0 = np.clip(np.array([1.0, 1.0, 0.5]), lb, ub)
            ours = least_squares(res, x0, lb, ub)
            ref = optimize.least_squares(res, x0, bounds=(lb, ub), ftol=1e-12, xtol=1e-10)
            assert ours.success
            assert np.all(ours.x >= lb) and np.all(ours.x <= ub)
            assert ours.cost <= ref.cost * (1 + 1e-9) + 1e-15
            assert ours.cost == pytest.approx(0.5 * float(res(ours.x) @ res(ours.x)), rel=1e-14)


def test_second_difference_sums_same_with_any_blas_pool(monkeypatch: pytest.MonkeyPatch) -> None:
    """Whole BLAS dot (one-thread pool) and chunked dot (threaded pool) give the same sums,
    equal to the direct definition."""
    import engine.wv._kernel as W

    rng = np.random.default_rng(5)
    x = rng.normal(size=100_003).cumsum() * 1e-3 + rng.normal(size=100_003)
    s = W.cumsum_demeaned(x)
    ms = np.array([1, 2, 3, 8, 100, 4096, 30_000])
    direct = np.array([np.sum((s[2 * m :] - 2 * s[m:-m] + s[: s.size - 2 * m]) ** 2) for m in ms])
    for threads in (1, 4, None):
        monkeypatch.setattr(W, "blas_threads", lambda t=threads: t)
        np.testing.assert_allclose(W.second_difference_sums(s, x.size, ms), direct, rtol=1e-11)


def test_blas_pool_can_be_read_and_limited() -> None:
    from engine._blas import blas_threads, set_blas_threads

    before = blas_threads()
    if before is None:
        pytest.skip("no OpenBLAS found in this process")
    try:
        assert set_blas_threads(1) and blas_threads() == 1
    finally:
        set_blas_threads(before)
    assert blas_threads() == before


# property-based: any small problem, the KKT conditions; any df and p, the quantile's defining
# equation and monotonicity
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=150, deadline=None)
@given(
    m=st.integers(1, 30),
    n=st.integers(1, 8),
    seed=st.integers(0, 2**32 - 1),
    scale=st.floats(-8, 8),
)
def test_nnls_kkt_on_random_problems(m: int, n: int, seed: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(m, n)) * 10.0**scale
    b = rng.normal(size=m)
    x, r = nnls(a, b)
    assert np.all(x >= 0) and np.isfinite(r)
    grad = a.T @ (a @ x - b)
    tol = 1e-8 * max(1.0, float(np.abs(a).max()) ** 2 * max(1.0, float(np.abs(x).max())))
    assert np.all(grad >= -tol)  # no descent direction into the feasible set
    assert np.all(np.abs(grad[x > 0]) <= tol)
    assert r <= np.linalg.norm(b) * (1 + 1e-12)  # never worse than x = 0


@settings(max_examples=150, deadline=None)
@given(df=st.floats(0.5, 1e7), p=st.floats(1e-9, 1 - 1e-9))
def test_chi2_isf_inverts_the_survival_function(df: float, p: float) -> None:
    x = float(chi2_isf(df, p))
    assert x > 0 and math.isfinite(x)
    q = float(special.chdtrc(df, x))  # survival function at our quantile
    assert q == pytest.approx(p, rel=1e-7, abs=1e-13)
    assert float(chi2_isf(df, min(p * 1.01, 1 - 1e-12))) <= x  # decreasing in p
