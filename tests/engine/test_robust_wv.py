"""Robust WV (joint biweight location and scale, nu = s^2 + mu^2): oracle, consistency with
and without drift, outliers, quantized data, fallbacks, progress, level count."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest
from scipy import integrate, optimize, stats

import engine as eg
import engine.wv.robust as rwv
from engine.wv import max_levels, robust_scale_biweight
from engine.wv._kernel import cumsum_demeaned

C = eg.wv.biweight_constant(0.6)


def _a(c: float) -> float:
    """E[psi(Z)^2] by quadrature (independent of the closed form in the engine)."""
    f = lambda z: (z * (1 - z * z / c**2) ** 2) ** 2 * stats.norm.pdf(z)  # noqa: E731
    return 2 * integrate.quad(f, 0, c, epsabs=1e-14)[0]


def oracle(w: np.ndarray, c: float = C, p: np.ndarray | None = None) -> tuple[float, float]:
    """Slow, obviously-correct joint biweight (mu, s): alternate the location equation (root by
    reweighting at fixed s) and the upper root of the scale equation (Brent at fixed mu), full
    passes, until both change by less than 1e-14 relative. ``p``: probabilities of ``w``."""
    w = np.asarray(w, float)
    p = np.full(w.size, 1.0 / w.size) if p is None else np.asarray(p, float)
    a = _a(c)

    def psi(r: np.ndarray) -> np.ndarray:
        return np.where(np.abs(r) <= c, r * (1 - r * r / c**2) ** 2, 0.0)

    def f(s: float, mu: float) -> float:
        return float(np.sum(p * psi((w - mu) / s) ** 2)) - a

    order = np.argsort(w)
    med = w[order][np.searchsorted(np.cumsum(p[order]), 0.5)]
    mu, s = float(med), 1.4826 * float(np.sqrt(np.sum(p * (w - med) ** 2)))
    for _ in range(300):
        # upper root of f(., mu): f < 0 beyond it; bracket from a large scale downwards
        hi = s * 4
        while f(hi, mu) > 0:
            hi *= 2
        lo = hi / 1.05
        while f(lo, mu) <= 0:
            lo /= 1.05
            assert lo > 1e-12 * hi, "no root of the scale equation"
        s_new = optimize.brentq(f, lo, lo * 1.05, args=(mu,), xtol=1e-16 * hi, rtol=1e-15)
        mu_new = mu
        for _ in range(1000):
            r = (w - mu_new) / s_new
            wt = p * np.where(np.abs(r) <= c, (1 - r * r / c**2) ** 2, 0.0)
            nxt = float(np.sum(wt * w) / np.sum(wt))
            if abs(nxt - mu_new) <= 1e-16 * s_new:
                break
            mu_new = nxt
        done = abs(s_new - s) <= 1e-14 * s and abs(mu_new - mu) <= 1e-14 * s
        mu, s = mu_new, s_new
        if done:
            break
    return mu, s


def coefficients(x: np.ndarray, j: int) -> np.ndarray:
    s = cumsum_demeaned(np.asarray(x, float))
    m = 1 << (j - 1)
    return (s[2 * m :] - 2.0 * s[m:-m] + s[: s.size - 2 * m]) / (2.0 * m)


def test_gaussian_psi2_mean_matches_quadrature():
    for eff in (0.6, 0.8, 0.9):
        c = eg.wv.biweight_constant(eff)
        assert rwv.gaussian_psi2_mean(c) == pytest.approx(_a(c), rel=1e-12)


def _series(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    x = rng.standard_normal(n)
    if kind == "drift":
        return x + 1e-3 * np.arange(n)
    if kind == "outliers":
        x[rng.choice(n, n // 100, replace=False)] += 20.0
        return x
    if kind == "quantized":
        return np.round(x / 1.5) * 1.5
    if kind == "rw":
        return x + 0.05 * rng.standard_normal(n).cumsum()
    return x


@pytest.mark.parametrize("kind", ["gaussian", "drift", "outliers", "quantized", "rw"])
def test_power_sum_path_equals_oracle(kind, monkeypatch):
    n = 150_000  # levels 1..14 have more than 2 x 65,536 coefficients: the power-sum path
    x = _series(kind, n, np.random.default_rng(zlib.crc32(kind.encode()) % 1000))
    direct = []
    monkeypatch.setattr(
        rwv, "biweight_location_scale", lambda w, c: direct.append(w.size) or oracle(w, c)
    )
    levels = [1, 3, 7, 11, 14]
    nu, mu, sc = rwv.robust_wv(cumsum_demeaned(x), n, 14, C)
    assert direct == []  # no level needed the direct computation
    for j in levels:
        m_ref, s_ref = oracle(coefficients(x, j))
        assert mu[j - 1] == pytest.approx(m_ref, abs=1e-10 * s_ref)
        assert sc[j - 1] == pytest.approx(s_ref, rel=1e-10)
        assert nu[j - 1] == pytest.approx(s_ref**2 + m_ref**2, rel=1e-10)


def test_consistent_with_drift_monte_carlo():
    """WN (sigma2 = 1) + DR (omega = 1e-3 per sample), N = 2e5: at every level with >= 100
    coefficients per scale the mean robust WV matches the model-implied WV
    1/tau + omega^2 tau^2 / 16 and the classical WV within Monte Carlo error."""
    rng = np.random.default_rng(2024)
    n, reps, omega, levels = 200_000, 40, 1e-3, 10
    tau = 2.0 ** np.arange(1, levels + 1)
    truth = 1 / tau + omega**2 * tau**2 / 16
    rb, cl = [], []
    for _ in range(reps):
        wv = eg.wavelet_variance(
            rng.standard_normal(n) + omega * np.arange(n), robust=True, levels=levels
        )
        rb.append(wv.variance)
        cl.append(wv.classical.variance)
    rb, cl = np.array(rb), np.array(cl)
    se = rb.std(axis=0, ddof=1) / np.sqrt(reps)
    assert np.all(np.abs(rb.mean(0) - truth) < 4 * se + 1e-4 * truth), (
        rb.mean(0) / truth - 1,
        se / truth,
    )
    assert np.all(np.abs(rb.mean(0) / cl.mean(0) - 1) < 4 * se / truth + 1e-3)
    # the older definition (scale about zero, R's) is far off where the drift dominates
    w10 = coefficients(rng.standard_normal(n) + omega * np.arange(n), 10)
    assert robust_scale_biweight(w10) / truth[-1] - 1 > 0.3


def test_gaussian_without_drift_matches_classical_and_r_definition():
    """Gaussian WN + RW: where the coefficients have mean zero, the new robust WV equals R's
    (scale about zero, robust_scale_biweight) within 1e-3 and the classical WV within 3 % at
    levels with >= 1000 coefficients per scale (one realization, N = 2e5)."""
    rng = np.random.default_rng(7)
    n = 200_000
    x = rng.standard_normal(n) + 0.01 * rng.standard_normal(n).cumsum()
    wv = eg.wavelet_variance(x, robust=True)
    well = wv.n_coef / wv.tau_samples >= 1000
    assert well.sum() == 7
    r_def = np.array([robust_scale_biweight(coefficients(x, j)) for j in wv.levels[well]])
    np.testing.assert_allclose(wv.variance[well], r_def, rtol=1e-3)
    np.testing.assert_allclose(wv.variance[well], wv.classical.variance[well], rtol=0.03)


def test_resists_one_percent_spikes_of_20_sigma():
    rng = np.random.default_rng(5)
    n = 200_000
    x = rng.standard_normal(n)
    clean = eg.wavelet_variance(x, levels=6).variance
    x[rng.choice(n, n // 100, replace=False)] += 20.0
    wv = eg.wavelet_variance(x, robust=True, levels=6)
    # a spike touches 2^j coefficients of level j: 2 % and 4 % of them at levels 1-2
    assert np.all(np.abs(wv.variance[:2] / clean[:2] - 1) < 0.10), wv.variance / clean
    assert np.all(wv.classical.variance / clean > 4.5)  # the classical WV is ruined
    # at coarser levels most coefficients carry a spike: no longer resisted (documented)
    assert wv.variance[5] / clean[5] > 2.0


def _quantized_level1_pmf(q: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact distribution of W_1 = (x_t - x_{t-1}) / 2 for x = q round(Z / q), Z ~ N(0, 1)."""
    k = np.arange(-40, 41)
    pk = stats.norm.cdf((k + 0.5) * q) - stats.norm.cdf((k - 0.5) * q)
    pw = np.convolve(pk, pk)  # difference of two iid (symmetric) values
    values = q * np.arange(-80, 81) / 2
    keep = pw > 1e-300
    return values[keep], pw[keep]


def test_quantized_data_converges_to_the_biweight_functional_of_the_discrete_law():
    """Quantized WN, step 2 sigma (52 % of the level-1 coefficients exactly 0): the robust WV
    converges to the biweight functional of the coefficients' discrete law, 0.910 of the
    classical WV at level 1 (computed here from the exact law), not to the classical WV.
    With a step of 1.5 sigma (39 % ties) the same functional is 0.998 of it: ties alone do not
    bias the estimate, the coarse discreteness does."""
    q = 1.5
    values, pw = _quantized_level1_pmf(q)
    mu_pop, s_pop = oracle(values, C, pw)
    assert (s_pop**2 + mu_pop**2) / float(np.sum(pw * values**2)) == pytest.approx(0.998, abs=0.001)
    q = 2.0
    values, pw = _quantized_level1_pmf(q)
    ew2 = float(np.sum(pw * values**2))
    mu_pop, s_pop = oracle(values, C, pw)
    ratio = (s_pop**2 + mu_pop**2) / ew2
    assert pw[values == 0][0] == pytest.approx(0.516, abs=0.001)
    assert ratio == pytest.approx(0.910, abs=0.001)
    rng = np.random.default_rng(3)
    x = np.round(rng.standard_normal(400_000) / q) * q
    wv = eg.wavelet_variance(x, robust=True, levels=2)
    assert wv.classical.variance[0] == pytest.approx(ew2, rel=0.01)
    assert wv.variance[0] == pytest.approx(ratio * ew2, rel=0.01)


def test_beyond_breakdown_the_scale_maximises_the_scale_equation():
    """70 % of the coefficients tied at 0: the scale equation has no root (its left side
    stays below E[psi(Z)^2]); the scale is then the maximiser of the left side."""
    rng = np.random.default_rng(1)
    w = np.concatenate([np.zeros(7000), rng.standard_normal(3000)])
    mu, s = rwv.biweight_location_scale(w, C)
    a = _a(C)

    def lhs(sc: float) -> float:
        r = (w - mu) / sc
        return float(np.mean(np.where(np.abs(r) <= C, r * (1 - r * r / C**2) ** 2, 0.0) ** 2))

    assert abs(mu) < 1e-3 and s > 0 and lhs(s) < a
    assert lhs(s) >= max(lhs(s * 1.001), lhs(s / 1.001))
    assert lhs(s) >= max(lhs(s * f) for f in (0.25, 0.5, 2.0, 4.0))


def test_degenerate_levels():
    assert rwv.biweight_location_scale(np.full(5, 2.0), C) == (2.0, 0.0)
    # a noiseless drift: every coefficient is omega tau / 4; robust WV = classical
    x = 0.01 * np.arange(1000.0)
    wv = eg.wavelet_variance(x, robust=True)
    # (the coefficients are equal up to the rounding of the cumulative sum)
    np.testing.assert_allclose(wv.variance, wv.classical.variance, rtol=1e-10)
    np.testing.assert_allclose(wv.variance, (0.01 * wv.tau_samples) ** 2 / 16, rtol=1e-9)


def test_progress_called_once_per_level_in_order():
    x = np.random.default_rng(0).standard_normal(5000)
    for robust in (True, False):
        calls: list[tuple[int, int]] = []

        def note(j: int, n: int, calls: list = calls) -> None:
            calls.append((j, n))

        wv = eg.wavelet_variance(x, robust=robust, progress=note)
        assert calls == [(j, wv.n_levels) for j in range(1, wv.n_levels + 1)]


def test_level_count_accepts_r_count_with_one_coefficient_at_the_last_level():
    n = 2**12
    x = np.random.default_rng(4).standard_normal(n)
    assert eg.wv.default_levels(n) == 11 and max_levels(n) == 12
    assert max_levels(n + 1) == eg.wv.default_levels(n + 1) == 12
    wv = eg.wavelet_variance(x, levels=12, robust=True)
    assert wv.n_coef[-1] == 1
    w = coefficients(x, 12)
    assert w.size == 1
    assert wv.classical.variance[-1] == pytest.approx(w[0] ** 2, rel=1e-12)
    assert wv.variance[-1] == pytest.approx(w[0] ** 2, rel=1e-12)  # one coefficient: = classical
    # eta = 1 degree of freedom: chi-square(1) interval
    lo, hi = wv.classical.ci_low[-1], wv.classical.ci_high[-1]
    assert lo == pytest.approx(w[0] ** 2 / stats.chi2.ppf(0.975, 1), rel=1e-10)
    assert hi == pytest.approx(w[0] ** 2 / stats.chi2.ppf(0.025, 1), rel=1e-10)
    assert hi / lo == pytest.approx(5116, rel=1e-3)
    with pytest.raises(ValueError, match="supports 1 to 12"):
        eg.wavelet_variance(x, levels=13)
    assert eg.wavelet_variance(x).n_levels == 11  # the default is unchanged


def test_old_definition_is_kept_as_the_scale_about_zero():
    w = np.random.default_rng(9).standard_normal(20_000) + 3.0
    # the joint estimate separates a mean of 3 sigma from the scale: nu ~ E[W^2] = 10
    mu, s = rwv.biweight_location_scale(w, C)
    assert mu == pytest.approx(3.0, abs=0.03) and s == pytest.approx(1.0, abs=0.03)
    assert s * s + mu * mu == pytest.approx(np.mean(w * w), rel=0.01)
    # the scale about zero (R's definition) is 44 % too large here
    assert robust_scale_biweight(w) / np.mean(w * w) - 1 > 0.3
    assert math.isfinite(robust_scale_biweight(w))
