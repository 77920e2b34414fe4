"""The closed-form model covariance of the WV (engine.fit._closed_form) against the
frequency-domain quadrature it replaced (kept here as the slow reference) and against direct
lag-domain sums."""

from __future__ import annotations

import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

import engine as eg
import engine.fit._closed_form as cf
from engine.fit import fit_efficient
from engine.fit.asymptotic import inverse_cov, spectral_density, wv_cov_model
from engine.models import RW, Model


def fake_wv(n: int, fs: float = 1.0, levels: int | None = None) -> SimpleNamespace:
    """What wv_cov_model reads from a WV: levels, M_j and fs (no series needed)."""
    levels = int(math.floor(math.log2(n - 1))) if levels is None else levels
    tau = 2 ** np.arange(1, levels + 1)
    return SimpleNamespace(n_levels=levels, n_coef=n - tau + 1, fs=fs, n=n)


def quadrature(model: Model, wv, nodes: int, zero_node: bool = True) -> np.ndarray:
    """The previous wv_cov_model: periodic trapezoid rule with ``nodes`` intervals on [0, 1/2]
    of ``|H_j|^2 |H_k|^2 S^2``. It is exact for QN/WN/RW when ``nodes >= 2^(J+1)`` and has a
    wrap-around error of about ``phi^(2 nodes)`` for an AR1; ``zero_node=False`` leaves out
    the f = 0 node as the previous code did (wrong when the model has a random walk)."""
    model = Model(tuple(p for p in model.processes if p.linear_coef() != 0))
    levels = wv.n_levels
    f = np.arange(0, nodes + 1) / (2.0 * nodes)
    w = np.full(f.size, 1.0 / nodes)
    w[0] = w[-1] = 0.5 / nodes
    s = np.zeros(f.size)
    g = np.empty((levels, f.size))
    with np.errstate(divide="ignore", invalid="ignore"):
        for p in model.processes:
            s += spectral_density(p, f, wv.fs)
        for j in range(levels):
            m = 2**j
            g[j] = np.sin(np.pi * f * m) ** 4 / (m * m * np.sin(np.pi * f) ** 2) * s
    # the limit at f = 0: gamma2 m^2 / 4 for a random walk, 0 for the other processes
    g[:, 0] = (
        sum(float(p.gamma2) for p in model.processes if isinstance(p, RW))
        * 4.0 ** (np.arange(levels))
        / 4.0
    )
    if not zero_node:
        w[0] = 0.0
    m_j = np.asarray(wv.n_coef, float)
    # the second-order part; a drift's first-order share is exact in wv_cov_model (the mean of
    # the coefficients over the log) and checked against brute force in test_jtest_calibration
    return 2.0 * ((g * w) @ g.T) / np.maximum.outer(m_j, m_j)


def reference_nodes(model: Model, levels: int, fs: float) -> int:
    """Enough trapezoid intervals that the AR1 wrap-around is below 1e-15 relative."""
    need = 2 ** (levels + 1)
    for p in model.processes:
        if p.code in ("AR1", "GM"):
            ar = p if p.code == "AR1" else p.as_ar1(fs)
            need = max(need, int(40.0 / -math.log(abs(float(ar.phi)))))
    return 1 << math.ceil(math.log2(need))


MODELS = [
    ("WN(sigma2=1)", 1.0),
    ("QN(q2=2)", 1.0),
    ("RW(gamma2=1)", 1.0),
    ("QN(q2=0.3)+WN(sigma2=1)+RW(gamma2=1e-4)+DR(omega=1e-3)", 1.0),
    ("AR1(phi=0.5, sigma2=1)", 1.0),
    ("AR1(phi=-0.6, sigma2=1)+WN(sigma2=0.1)", 1.0),
    ("AR1(phi=0.999, sigma2=1)+WN(sigma2=1)+RW(gamma2=1e-6)+QN(q2=0.1)", 1.0),
    ("GM(beta=2, sigma2_gm=1)+WN(sigma2=0.5)", 100.0),
    ("GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.01, sigma2_gm=1e-4)+WN(sigma2=1e-2)", 100.0),
    ("GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.5, sigma2_gm=1e-4)+RW(gamma2=1e-10)", 100.0),
    ("AR1(phi=0.9, sigma2=1)+AR1(phi=0.9000001, sigma2=2)+QN(q2=1)", 1.0),
]


@pytest.mark.parametrize(("spec", "fs"), MODELS)
@pytest.mark.parametrize("n", [300, 2**10, 5000])
def test_closed_form_matches_the_quadrature(spec, fs, n):
    model = eg.parse_model(spec)
    wv = fake_wv(n, fs)
    ref = quadrature(model, wv, reference_nodes(model, wv.n_levels, fs))
    # a drift adds no second-order term: its first-order share (exact in wv_cov_model) is
    # checked against brute force in test_jtest_calibration
    new = wv_cov_model(eg.Model(tuple(p for p in model.processes if p.code != eg.DR.code)), wv)
    assert np.all(ref > 0)
    np.testing.assert_allclose(new, ref, rtol=1e-10, atol=0)


def test_closed_form_matches_the_quadrature_at_13_levels():
    model = eg.parse_model(MODELS[8][0])
    wv = fake_wv(2**13 + 5, 100.0)
    ref = quadrature(model, wv, reference_nodes(model, wv.n_levels, 100.0))
    np.testing.assert_allclose(wv_cov_model(model, wv), ref, rtol=1e-10, atol=0)


def lag_sum(filters_by_source: list[list[np.ndarray]]) -> np.ndarray:
    """``C_jk = sum_h s_j(h) s_k(h)``, ``s_j`` the autocovariance of the level-j coefficients
    written as independent unit white noises through finite filters (one list per source)."""
    levels = len(filters_by_source[0])
    out = np.zeros((levels, levels))
    acfs = [[np.correlate(h, h, "full") for h in src] for src in filters_by_source]

    def total(j: int, lag_max: int) -> np.ndarray:
        s = np.zeros(2 * lag_max + 1)
        for src in acfs:
            a = src[j]
            c = (a.size - 1) // 2
            lo = max(0, c - lag_max)
            s[lag_max - (c - lo) : lag_max + (c - lo) + 1] += a[lo : 2 * c - lo + 1]
        return s

    lag_max = max(a.size for src in acfs for a in src)
    s = [total(j, lag_max) for j in range(levels)]
    for j in range(levels):
        for k in range(levels):
            out[j, k] = s[j] @ s[k]
    return out


def test_random_walk_white_and_quantization_noise_equal_the_direct_lag_sum():
    """A derivation-free check: the Haar coefficients of QN + WN + RW are finite filters of
    three independent white noises, and ``C_jk = sum_h s_j(h) s_k(h)`` summed directly. The
    previous quadrature (without its f = 0 node) fails this by up to 26 % at the last level."""
    q2, sigma2, gamma2, levels = 0.3, 1.0, 0.05, 9
    haar = []
    for j in range(1, levels + 1):
        m = 2 ** (j - 1)
        haar.append(np.r_[np.ones(m), -np.ones(m)] / (2 * m))
    wn = [math.sqrt(sigma2) * h for h in haar]
    qn = [math.sqrt(q2) * np.convolve(h, [1.0, -1.0]) for h in haar]
    rw = [math.sqrt(gamma2) * np.cumsum(h)[:-1] for h in haar]
    direct = lag_sum([wn, qn, rw])
    wv = fake_wv(2**levels + 1)
    m_j = wv.n_coef.astype(float)
    model = eg.parse_model(f"QN(q2={q2})+WN(sigma2={sigma2})+RW(gamma2={gamma2})")
    np.testing.assert_allclose(
        wv_cov_model(model, wv), 2 * direct / np.maximum.outer(m_j, m_j), rtol=1e-12
    )
    old = quadrature(model, wv, 2 ** (levels + 1), zero_node=False)
    assert abs(old[-1, -1] / wv_cov_model(model, wv)[-1, -1] - 1) > 0.1


def test_an_ar1_equals_its_truncated_lag_sum():
    """AR1 with phi = 0.8 through a truncated MA(inf) filter (truncation error 0.8^400)."""
    phi, levels = 0.8, 6
    psi = phi ** np.arange(400)
    filt = [np.convolve(np.r_[np.ones(2**j), -np.ones(2**j)] / 2 ** (j + 1), psi) for j in range(6)]
    wv = fake_wv(2**levels + 1)
    m_j = wv.n_coef.astype(float)
    expect = 2 * lag_sum([filt]) / np.maximum.outer(m_j, m_j)
    np.testing.assert_allclose(
        wv_cov_model(eg.parse_model(f"AR1(phi={phi}, sigma2=1)"), wv), expect, rtol=1e-11
    )


@pytest.mark.parametrize("gap", [2.0, 6.0, 9.0])
def test_decimal_digits_suffice(monkeypatch, gap):
    """48 more digits change nothing: the cancellation near phi = 1 is covered (1 - phi down
    to 1e-9, two AR1s 1e-7 apart)."""
    phi = 1.0 - 10.0**-gap
    ar = [(phi, 1e-3), (phi - 1e-7, 2e-3), (0.5, 1.0)]
    base = cf.closed_form_c(18, 0.1, 1.0, 1e-6, ar)
    digits = cf._digits
    monkeypatch.setattr(cf, "_digits", lambda phis: digits(phis) + 48)
    more = cf.closed_form_c(18, 0.1, 1.0, 1e-6, ar)
    np.testing.assert_allclose(base, more, rtol=1e-14, atol=0)


def test_22_levels_in_milliseconds():
    """T = 6.3e6 at 100 Hz (22 levels), a slow GM: was 13 s with the 2^23-node
    quadrature; the bound is loose for a loaded machine."""
    model = eg.parse_model(
        "GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.01, sigma2_gm=1e-4)+WN(sigma2=1e-2)"
        "+RW(gamma2=1e-10)"
    )
    wv = fake_wv(6_300_000, 100.0)
    wv_cov_model(model, wv)  # the integer kernels of 22 levels, cached per process
    t = time.perf_counter()
    v = wv_cov_model(model, wv)
    assert time.perf_counter() - t < 1.0
    assert v.shape == (22, 22) and np.all(np.linalg.eigvalsh(v) > 0)


def test_fit_efficient_uses_the_closed_form():
    model = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)")
    x = model.simulate(5000, rng=4)
    wv = eg.wavelet_variance(x)
    res = fit_efficient(wv, "WN+RW")
    first = eg.fit_gmwm(wv, "WN+RW")
    vmat = quadrature(first.model, wv, 2 ** (wv.n_levels + 1))
    again = eg.fit_gmwm(wv, first.model, weights=inverse_cov(vmat))
    np.testing.assert_allclose(res.implied, again.implied, rtol=1e-6)
