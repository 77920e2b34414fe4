"""Empirical Haar WV: direct convolution, Allan identity, intervals, robust version, errors."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import WV_KEYS

import engine as eg
from engine.wv import eta3_interval


def direct_wv(x: np.ndarray, levels: int) -> np.ndarray:
    """Brute-force Haar MODWT WV: convolve with the level-j filter, keep full windows."""
    x = np.asarray(x, float) - np.mean(x)
    out = []
    for j in range(1, levels + 1):
        m = 2 ** (j - 1)
        h = np.concatenate([np.full(m, 1.0), np.full(m, -1.0)]) / 2**j  # latest first
        w = np.convolve(x, h, mode="valid")
        out.append(np.mean(w**2))
    return np.array(out)


def overlapping_avar(x: np.ndarray, m: int) -> float:
    """Textbook overlapping Allan variance at averaging time m samples (divisor N - 2m + 1)."""
    x = np.asarray(x, float)
    c = np.concatenate([[0.0], np.cumsum(x)])
    avg = (c[m:] - c[:-m]) / m  # running means, length N - m + 1
    d = avg[m:] - avg[:-m]  # N - 2m + 1 differences
    return 0.5 * np.mean(d**2)


@pytest.mark.parametrize("n", [4, 5, 7, 64, 1000, 1024, 1025, 4099])
def test_equals_direct_convolution(n):
    x = np.random.default_rng(n).standard_normal(n).cumsum() * 0.1 + np.random.default_rng(
        n + 1
    ).standard_normal(n)
    wv = eg.wavelet_variance(x)
    assert wv.n_levels == int(np.floor(np.log2(n - 1)))
    np.testing.assert_allclose(wv.variance, direct_wv(x, wv.n_levels), rtol=1e-10)
    assert np.all(wv.n_coef == n - 2**wv.levels + 1)
    assert np.all(wv.n_coef >= 2)


def test_power_of_two_length_has_last_level_with_two_coefficients():
    wv = eg.wavelet_variance(np.random.default_rng(0).standard_normal(2**12))
    assert wv.n_levels == 11
    assert wv.n_coef[-1] == 2**12 - 2**11 + 1
    assert np.all(np.isfinite(wv.variance)) and np.all(wv.variance > 0)


def test_equals_half_overlapping_allan_variance():
    x = np.random.default_rng(3).standard_normal(5000) + 0.01 * np.arange(5000) ** 0.5
    wv = eg.wavelet_variance(x, fs=10.0)
    av = np.array([overlapping_avar(x, 2 ** (j - 1)) for j in wv.levels])
    np.testing.assert_allclose(wv.variance, av / 2, rtol=1e-10)


def test_equals_half_allantools_oadev_squared():
    allantools = pytest.importorskip("allantools", reason="allantools comes with the bench extra")
    x = np.random.default_rng(4).standard_normal(20000)
    wv = eg.wavelet_variance(x, fs=50.0)
    taus = wv.tau_s / 2  # Allan averaging time of level j is 2^(j-1) samples
    t, adev, _, _ = allantools.oadev(x, rate=50.0, data_type="freq", taus=taus)[:4]
    np.testing.assert_allclose(t, taus)
    np.testing.assert_allclose(wv.variance, adev**2 / 2, rtol=1e-9)


def test_scales_in_samples_and_seconds():
    wv = eg.wavelet_variance(np.random.default_rng(0).standard_normal(300), fs=200.0)
    np.testing.assert_array_equal(wv.tau_samples, 2 ** np.arange(1, 9))
    np.testing.assert_allclose(wv.tau_s, 2 ** np.arange(1, 9) / 200.0)


def test_mean_removed_before_summing_keeps_digits_with_large_offset():
    x = np.random.default_rng(5).standard_normal(200_000)
    a = eg.wavelet_variance(x).variance
    b = eg.wavelet_variance(x + 1e7).variance
    np.testing.assert_allclose(b, a, rtol=1e-6)


def test_float32_input_matches_float64():
    x = np.random.default_rng(6).standard_normal(10000)
    x32 = x.astype(np.float32)
    np.testing.assert_allclose(
        eg.wavelet_variance(x32).variance,
        eg.wavelet_variance(x32.astype(np.float64)).variance,
        rtol=1e-12,
    )


def test_explicit_levels_and_truncate():
    x = np.random.default_rng(7).standard_normal(4000)
    full = eg.wavelet_variance(x)
    five = eg.wavelet_variance(x, levels=5)
    np.testing.assert_allclose(five.variance, full.variance[:5])
    np.testing.assert_allclose(full.truncate(5).ci_high, five.ci_high)


def test_eta3_interval_formula():
    wv = eg.wavelet_variance(np.random.default_rng(8).standard_normal(1000), alpha=0.1)
    from scipy import stats

    eta = np.maximum(wv.n_coef / wv.tau_samples, 1)
    np.testing.assert_allclose(wv.ci_low, eta * wv.variance / stats.chi2.ppf(0.95, eta))
    np.testing.assert_allclose(wv.ci_high, eta * wv.variance / stats.chi2.ppf(0.05, eta))
    lo, hi = eta3_interval(wv.variance, wv.n_coef, wv.tau_samples, 0.1)
    np.testing.assert_allclose(lo, wv.ci_low)


@pytest.mark.parametrize("spec", ["WN(sigma2=1)", "RW(gamma2=1)", "AR1(phi=0.9, sigma2=1)"])
def test_interval_coverage_is_at_least_nominal(spec):
    """eta3 (docs/conventions.md) is a conservative equivalent-degrees-of-freedom choice.

    Monte Carlo, 300 series of 4096 samples: coverage at every level at least nominal, less
    the binomial noise (SE about 1.3 points).
    """
    rng = np.random.default_rng(9)
    model = eg.parse_model(spec)
    reps, n, levels = 300, 4096, 6
    tau = 2.0 ** np.arange(1, levels + 1)
    truth = model.wv(tau)
    hits = np.zeros(levels)
    for _ in range(reps):
        wv = eg.wavelet_variance(model.simulate(n, rng=rng), levels=levels)
        hits += (wv.ci_low <= truth) & (truth <= wv.ci_high)
    coverage = hits / reps
    assert np.all(coverage >= 0.92), coverage


def test_biweight_constants_match_conventions():
    assert eg.wv.biweight_constant(0.6) == pytest.approx(4.40, abs=0.01)
    assert eg.wv.biweight_constant(0.8) == pytest.approx(5.45, abs=0.01)
    assert eg.wv.biweight_constant(0.9) == pytest.approx(6.58, abs=0.01)


def test_robust_wv_is_consistent_and_has_its_efficiency():
    rng = np.random.default_rng(10)
    reps, n = 300, 3000
    cl, rb = [], []
    for _ in range(reps):
        wv = eg.wavelet_variance(rng.standard_normal(n), levels=1, robust=True, eff=0.6)
        rb.append(wv.variance[0])
        cl.append(wv.classical.variance[0])
    rb, cl = np.array(rb), np.array(cl)
    assert np.mean(rb) == pytest.approx(0.5, rel=0.02)  # unbiased at the Gaussian
    # efficiency = var(classical) / var(robust): 0.6 by construction (MC, about +-0.1)
    assert np.var(cl) / np.var(rb) == pytest.approx(0.6, abs=0.1)


def test_robust_wv_resists_outliers():
    rng = np.random.default_rng(11)
    x = rng.standard_normal(20000)
    idx = rng.choice(x.size, 20, replace=False)
    x[idx] += 50.0  # 0.1 % of samples, up to 6 % of the level-6 coefficients
    wv = eg.wavelet_variance(x, robust=True, levels=6)
    truth = 1.0 / wv.tau_samples
    assert np.all(np.abs(wv.variance / truth - 1) < 0.15), wv.variance / truth
    assert np.all(wv.classical.variance / truth > 2.0)  # the classical WV is ruined
    assert np.all(wv.ci_low < wv.variance) and np.all(wv.variance < wv.ci_high)
    # the robust interval is the classical relative width scaled by sqrt(1/eff)
    rel_c = (wv.classical.ci_high - wv.classical.variance) / wv.classical.variance
    rel_r = (wv.ci_high - wv.variance) / wv.variance
    np.testing.assert_allclose(rel_r, rel_c * np.sqrt(1 / 0.6))


def test_haar_coefficients_level_one():
    x = np.array([1.0, 3.0, 2.0, 7.0, 4.0])
    w = eg.wv.haar_coefficients(x, 1)
    np.testing.assert_allclose(w, np.diff(x) / 2)


@pytest.mark.parametrize("n", [5, 64, 1000, 70_001])
def test_sampled_coefficients_are_every_step_th_of_the_direct_convolution(n):
    """Every ``max(1, 2^j // 8)``-th coefficient of level j (the tail factors' sample), from the
    level-j filter convolved with the series; the one-level-at-a-time form with a reused
    buffer gives the same arrays to the last bit."""
    x = np.random.default_rng(n).standard_normal(n) + 50.0
    levels = int(np.floor(np.log2(n - 1)))
    listed = eg.wv.sampled_haar_coefficients(x, levels)
    d = x - x.mean()
    for j, (w, w_it) in enumerate(
        zip(listed, eg.wv.iter_sampled_haar_coefficients(x, levels, reuse=True), strict=True), 1
    ):
        m, step = 2 ** (j - 1), max(1, 2**j // 8)
        h = np.concatenate([np.full(m, 1.0), np.full(m, -1.0)]) / 2**j
        full = np.convolve(d, h, mode="valid")
        assert w.size == (n - 2 * m) // step + 1
        np.testing.assert_allclose(w, full[::step], rtol=1e-9, atol=1e-12)
        assert np.array_equal(w, w_it)


@pytest.mark.parametrize(
    ("x", "kwargs", "match"),
    [
        (np.ones(3), {}, "at least 4"),
        (np.array([1.0, np.nan, 2, 3, 4]), {}, "NaN/Inf.*sample 1"),
        (np.array([1.0, 2, np.inf, 3, 4]), {}, "NaN/Inf"),
        (np.arange(100.0), {"levels": 7}, "supports 1 to 6"),
        (np.arange(100.0), {"levels": 0}, "out of range"),
        (np.arange(100.0), {"fs": 0.0}, "fs must be"),
        (np.arange(100.0), {"fs": -5.0}, "fs must be"),
        (np.arange(100.0), {"robust": True, "eff": 1.0}, "eff"),
        (np.arange(100.0), {"alpha": 1.5}, "alpha"),
        (np.zeros((10, 3, 2)), {}, "one-dimensional"),  # (N, 3): one WV per axis now
    ],
)
def test_bad_input_messages(x, kwargs, match):
    with pytest.raises(ValueError, match=match):
        eg.wavelet_variance(x, **kwargs)


def test_text_input_rejected():
    with pytest.raises(TypeError, match="numeric"):
        eg.wavelet_variance(np.array(["a", "b", "c", "d"]))


def test_to_dict_is_json_ready():
    import json

    wv = eg.wavelet_variance(np.random.default_rng(1).standard_normal(100), fs=2.0)
    d = json.loads(json.dumps(wv.to_dict()))
    assert set(d) >= WV_KEYS
    assert d["n"] == 100 and d["fs"] == 2.0 and len(d["variance"]) == 6


def test_wv_matrix_reads_an_imulog_or_any_log_like_object_by_duck_typing():
    """engine.wv.wccv does not import engine.io: an ImuLog, or any object with a ``channels``
    mapping and ``fs``, gives the same matrix as the plain mapping with that fs."""
    from types import SimpleNamespace

    from engine.io import ImuLog
    from engine.wv import wv_matrix

    rng = np.random.default_rng(3)
    ch = {"a": rng.normal(size=4096), "b": rng.normal(size=4096).cumsum() * 0.01}
    ref = wv_matrix(ch, fs=50.0, units={"a": "deg/s", "b": "g"})
    log = ImuLog(channels=ch, fs=50.0, units={"a": "deg/s", "b": "g"})
    alike = SimpleNamespace(channels=ch, fs=50.0, units={"a": "deg/s", "b": "g"})
    for got in (wv_matrix(log), wv_matrix(alike)):
        assert got.fs == 50.0 and got.units == ("deg/s", "g") and got.channels == ("a", "b")
        np.testing.assert_array_equal(got.values, ref.values)
    # the diagonal is the WV of each channel
    np.testing.assert_allclose(
        ref.values[:, 1, 1], eg.wavelet_variance(ch["b"]).variance, rtol=1e-13
    )
    with pytest.raises(ValueError, match="no raw samples"):
        wv_matrix(SimpleNamespace(channels={}, fs=1.0, source="summary.h5"))


def test_import_engine_leaves_the_wccv_and_stream_modules_to_first_use():
    """``engine.wv`` exports the WCCV and the streamed WV lazily (they need SciPy's special
    functions); first use imports them and caches the attribute."""
    import subprocess
    import sys

    code = (
        "import sys, engine, engine.wv as w\n"
        "assert 'engine.wv.wccv' not in sys.modules and 'engine.wv.stream' not in sys.modules\n"
        "f = w.wv_matrix\n"
        "assert 'engine.wv.wccv' in sys.modules and w.__dict__['wv_matrix'] is f\n"
        "assert engine.wv_matrix is f and 'wavelet_variance_stream' in dir(w)\n"
        "try:\n    w.nope\nexcept AttributeError as e:\n    assert 'nope' in str(e)\n"
        "else:\n    raise SystemExit('no AttributeError')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_with_fs_retags_scales_and_robust_companion() -> None:
    """``with_fs``: same variances and intervals, scales in seconds follow the new fs; a
    robust WV's classical companion is re-tagged too; the original is unchanged."""
    x = np.random.default_rng(3).normal(size=4096)
    wv = eg.wavelet_variance(x, fs=100.0, robust=True)
    re = wv.with_fs(400.0)
    assert re.fs == 400.0 and wv.fs == 100.0
    np.testing.assert_array_equal(re.variance, wv.variance)
    np.testing.assert_array_equal(re.ci_low, wv.ci_low)
    np.testing.assert_array_equal(re.ci_high, wv.ci_high)
    np.testing.assert_array_equal(re.tau_samples, wv.tau_samples)
    np.testing.assert_allclose(re.tau_s, 2.0 ** np.arange(1, wv.n_levels + 1) / 400.0, rtol=0)
    assert re.robust and re.classical is not None and re.classical.fs == 400.0
    np.testing.assert_array_equal(re.classical.variance, wv.classical.variance)
    np.testing.assert_allclose(re.classical.tau_s, wv.classical.tau_s / 4.0, rtol=1e-15)
    assert wv.with_fs(400.0).to_dict() == eg.wavelet_variance(x, fs=400.0, robust=True).to_dict()
    with pytest.raises(ValueError, match="fs"):
        wv.with_fs(0.0)
