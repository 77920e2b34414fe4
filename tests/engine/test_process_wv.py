"""Implied Haar WV of every latent process against its autocovariance; simulators (Monte Carlo)."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest

import engine as eg

TAU = 2.0 ** np.arange(1, 9)  # 2 .. 256 samples


def haar_filter(tau: int) -> np.ndarray:
    m = tau // 2
    return np.concatenate([np.full(m, -1.0), np.full(m, 1.0)]) / tau


def wv_from_covariance(cov: np.ndarray, tau: int) -> float:
    """nu2 = h' Sigma h over one window of tau samples (Sigma: tau x tau covariance)."""
    h = haar_filter(tau)
    return float(h @ cov @ h)


def stationary_cov(process, tau: int, fs: float) -> np.ndarray:
    lags = np.subtract.outer(np.arange(tau), np.arange(tau))
    return process.autocovariance(lags, fs)


@pytest.mark.parametrize(
    "process",
    [
        eg.WN(sigma2=2.5),
        eg.QN(q2=0.7),
        eg.AR1(phi=0.8, sigma2=1.3),
        eg.AR1(phi=-0.6, sigma2=0.4),
        eg.AR1(phi=0.999, sigma2=1e-3),
        eg.GM(beta=2.0, sigma2_gm=4.0),
    ],
    ids=repr,
)
def test_implied_wv_equals_quadratic_form_of_autocovariance(process):
    fs = 50.0
    expected = [wv_from_covariance(stationary_cov(process, int(t), fs), int(t)) for t in TAU]
    np.testing.assert_allclose(process.wv(TAU, fs), expected, rtol=1e-9)


def test_random_walk_wv_equals_quadratic_form_of_its_covariance():
    g2 = 0.3
    for t in TAU.astype(int):
        idx = np.arange(1, t + 1) + 17  # any start: increments are stationary
        cov = g2 * np.minimum.outer(idx, idx)
        assert eg.RW(gamma2=g2).wv(np.array([t]))[0] == pytest.approx(
            wv_from_covariance(cov, t), rel=1e-9
        )


def test_drift_wv_is_its_squared_haar_coefficient():
    om = 0.02
    for t in TAU.astype(int):
        x = om * np.arange(1, t + 1)
        w = haar_filter(t) @ x
        assert eg.DR(omega=om).wv(np.array([t]))[0] == pytest.approx(w**2, rel=1e-12)


def test_gm_is_ar1_with_converted_parameters():
    fs, beta, s2 = 100.0, 0.5, 3e-4
    gm = eg.GM(beta=beta, sigma2_gm=s2)
    phi = math.exp(-beta / fs)
    ar = eg.AR1(phi=phi, sigma2=s2 * (1 - phi**2))
    assert gm.as_ar1(fs) == ar
    np.testing.assert_allclose(gm.wv(TAU, fs), ar.wv(TAU, fs), rtol=1e-12)


def test_ar1_wv_is_stable_near_unit_root():
    """phi -> 1: the closed form cancels; the series branch must agree with the limit."""
    tau = 2.0 ** np.arange(1, 15)
    x = 1e-10  # phi = exp(-x); the AR1 departs from the RW limit by about 0.4 x tau
    v = eg.models.ar1_wv(tau, math.exp(-x), 1.0)
    limit_rw = (tau**2 + 2) / (12 * tau)  # AR1 -> RW with gamma2 = sigma2
    np.testing.assert_allclose(v, limit_rw, rtol=1e-5)
    # continuity across the switch between the series and the closed form (x tau = 2e-3)
    for t in (2.0**10, 2.0**16):
        xs = 2e-3 / t
        lo = eg.models.ar1_wv(np.array([t]), math.exp(-xs * (1 - 1e-9)))[0]
        hi = eg.models.ar1_wv(np.array([t]), math.exp(-xs * (1 + 1e-9)))[0]
        assert lo == pytest.approx(hi, rel=1e-8)


def test_ar1_wv_against_high_precision():
    mp = pytest.importorskip("mpmath")  # shipped with the test extra
    mp.mp.dps = 50

    def ref(t, phi):
        phi, t = mp.mpf(phi), mp.mpf(t)
        return ((phi**2 - 1) * t + 2 * phi * (phi**t - 4 * phi ** (t / 2) + 3)) / (
            (phi - 1) ** 3 * (phi + 1) * t**2
        )

    tau = 2.0 ** np.arange(1, 24)
    for phi in (-0.9, 0.3, 0.9, 0.99, 0.9999, 1 - 1e-6, 1 - 1e-9):
        expected = np.array([float(ref(t, phi)) for t in tau])
        np.testing.assert_allclose(eg.models.ar1_wv(tau, phi), expected, rtol=1e-9)


def test_ar1_wv_vectorised_over_phi():
    phis = np.array([0.1, 0.5, 0.99, 0.999999])
    out = eg.models.ar1_wv(TAU, phis, 2.0)
    assert out.shape == (4, TAU.size)
    for i, p in enumerate(phis):
        np.testing.assert_allclose(out[i], eg.models.ar1_wv(TAU, float(p), 2.0), rtol=1e-12)


@pytest.mark.parametrize(
    ("spec", "fs"),
    [
        ("WN(sigma2=2.0)", 1.0),
        ("QN(q2=0.5)", 1.0),
        ("RW(gamma2=1e-3)", 1.0),
        ("DR(omega=1e-3)", 1.0),
        ("AR1(phi=0.95, sigma2=1.0)", 1.0),
        ("GM(beta=2.0, sigma2_gm=1.0)", 100.0),
        ("GM(beta=5, sigma2_gm=1e-2)+QN(q2=1e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-7)", 100.0),
    ],
)
def test_simulation_agrees_with_implied_wv(spec, fs):
    """Monte Carlo: the mean empirical WV of 60 simulated series matches the implied WV."""
    model = eg.parse_model(spec)
    rng = np.random.default_rng(zlib.crc32(spec.encode()))  # str hash() differs per process
    n, reps, levels = 2**13, 60, 8
    est = np.array(
        [
            eg.wavelet_variance(model.simulate(n, fs=fs, rng=rng), levels=levels, fs=fs).variance
            for _ in range(reps)
        ]
    )
    truth = model.wv(2.0 ** np.arange(1, levels + 1), fs)
    if spec.startswith("DR"):
        # deterministic: every replicate equals the truth, up to the de-meaning
        np.testing.assert_allclose(est.mean(0), truth, rtol=1e-9)
        return
    se = est.std(0, ddof=1) / math.sqrt(reps)
    z = (est.mean(0) - truth) / se
    # MODWT WV is unbiased (the mean is removed; its effect is O(1/N), far below the SE)
    assert np.all(np.abs(z) < 4.0), z


def test_ar1_simulation_starts_stationary():
    rng = np.random.default_rng(5)
    ar = eg.AR1(phi=0.99, sigma2=1.0)
    first = np.array([ar.simulate(3, rng)[0] for _ in range(4000)])
    assert np.var(first) == pytest.approx(1 / (1 - 0.99**2), rel=0.08)


def test_qn_simulation_has_process_variance_2q2():
    x = eg.QN(q2=0.25).simulate(200_000, 1)
    assert np.var(x) == pytest.approx(0.5, rel=0.02)
    assert np.corrcoef(x[1:], x[:-1])[0, 1] == pytest.approx(-0.5, abs=0.01)


def test_drift_is_per_sample_whatever_fs():
    x = eg.DR(omega=0.1).simulate(5, fs=100.0)
    np.testing.assert_allclose(x, 0.1 * np.arange(1, 6))


@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: eg.WN(sigma2=-1.0), "WN.sigma2 must be >= 0"),
        (lambda: eg.AR1(phi=1.0, sigma2=1.0), r"AR1.phi must be in \(-1, 1\)"),
        (lambda: eg.GM(beta=0.0, sigma2_gm=1.0), "GM.beta must be > 0"),
        (lambda: eg.RW(gamma2=float("nan")), "finite number"),
        (lambda: eg.WN().with_values(sigma3=1.0), "no parameter 'sigma3'"),
    ],
)
def test_invalid_values_are_rejected(factory, match):
    with pytest.raises(ValueError, match=match):
        factory()


def test_missing_values_are_reported():
    with pytest.raises(ValueError, match="GM has no value for sigma2_gm"):
        eg.GM(beta=1.0).wv(TAU)


def test_processes_are_frozen_and_hashable():
    a, b = eg.GM(beta=1.0, sigma2_gm=2.0), eg.GM(beta=1.0, sigma2_gm=2.0)
    assert a == b and hash(a) == hash(b)
    with pytest.raises(AttributeError):
        a.beta = 3.0  # type: ignore[misc]
