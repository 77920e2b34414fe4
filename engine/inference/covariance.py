"""Covariance of the wavelet variance, and the efficient (two-step) GMWM.

``V = Cov(nu_hat)`` across levels, three ways: :func:`wv_cov_data` (from the data, diagonal,
Percival & Walden), :func:`wv_cov_model` (from a fitted model, Gaussian and asymptotic, full),
:func:`wv_cov_bootstrap` (parametric bootstrap); :func:`wv_cov` picks one by name for a fit.
:func:`fit_efficient` refits with ``Omega = V^-1`` (the GMWM paper, Corollary 1).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from ..fit import FitError, GMWMResult, fit_gmwm
from ..model import Model
from ..processes import AR1, DR, GM, QN, RW, WN, Process
from ..wavelet import WaveletVariance, _as_series, _cumsum_demeaned, wavelet_variance

__all__ = [
    "wv_cov_data",
    "wv_cov_model",
    "wv_cov_bootstrap",
    "wv_cov",
    "fit_efficient",
    "inverse_cov",
    "parallel_map",
    "frequency_grid",
    "spectral_density",
]


def wv_cov_data(x: Any, wv: WaveletVariance) -> np.ndarray:
    """Diagonal asymptotic covariance of the classical WV from the data (Percival & Walden).

    ``Var(nu_j) = 2 A_j / M_j``, ``A_j = s_0^2/2 + sum_{tau >= 1} s_tau^2`` with ``s_tau`` the
    (biased) autocovariances of the boundary-free level-j coefficients, computed by FFT.

    Parameters
    ----------
    x : array_like, shape (N,)
        The series the WV was computed from.
    wv : WaveletVariance
        Its WV (gives the levels).
    """
    a = _as_series(x)
    if a.size != wv.n:
        raise ValueError(f"the series has {a.size} samples but the WV was computed from {wv.n}")
    s = _cumsum_demeaned(a)
    out = np.empty(wv.n_levels)
    for i, j in enumerate(wv.levels):
        m = 1 << (int(j) - 1)
        w = (s[2 * m :] - 2.0 * s[m:-m] + s[: s.size - 2 * m]) / (2.0 * m)
        nfft = 1 << int(math.ceil(math.log2(2 * w.size)))
        spec = np.fft.rfft(w, nfft)
        acf = np.fft.irfft(spec.real**2 + spec.imag**2, nfft)[: w.size] / w.size
        a_j = float(acf @ acf) - 0.5 * acf[0] ** 2
        out[i] = 2.0 * a_j / w.size
    return np.diag(out)


def spectral_density(p: Process, f: np.ndarray, fs: float) -> np.ndarray:
    """Two-sided spectral density on f in cycles/sample (0 < f <= 1/2); RW generalised."""
    sin2 = np.sin(np.pi * f) ** 2
    if isinstance(p, WN):
        return np.full_like(f, float(p.sigma2))
    if isinstance(p, QN):
        return 4.0 * float(p.q2) * sin2
    if isinstance(p, RW):
        return float(p.gamma2) / (4.0 * sin2)
    if isinstance(p, DR):
        return np.zeros_like(f)  # deterministic: no first-order contribution to Cov(nu_hat)
    if isinstance(p, (AR1, GM)):
        ar = p if isinstance(p, AR1) else p.as_ar1(fs)
        phi, s2 = float(ar.phi), float(ar.sigma2)
        # 1 - 2 phi cos w + phi^2 = (1 - phi)^2 + 4 phi sin^2(w/2), stable near phi = 1
        return s2 / ((1.0 - phi) ** 2 + 4.0 * phi * sin2)
    raise TypeError(f"no spectral density for {p.code}")  # pragma: no cover


def frequency_grid(levels: int, model: Model, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on (0, 1/2] and weights of the periodic trapezoid rule for an even integrand.

    With ``2F`` equispaced nodes on a period, the rule is exact for trigonometric polynomials
    of degree below ``2F``: the Haar gains of levels j, k have degree ``2^j + 2^k``, so
    ``F = 2^(J+1)`` integrates white-noise-like terms exactly; AR1/GM terms need ``F`` above a
    few correlation times (the rule then equals the lag-domain sum up to a negligible wrap).
    """
    need = 2 ** (levels + 1)
    for p in model.processes:
        if isinstance(p, (AR1, GM)):
            ar = p if isinstance(p, AR1) else p.as_ar1(fs)
            if 0 < float(ar.phi) < 1:
                # a few correlation times, but no more than 8x the longest scale: beyond the
                # series' span a near-unit-root AR1 acts as a random walk
                need = max(need, int(min(-16.0 / math.log(float(ar.phi)), 2.0 ** (levels + 4))))
    f_nodes = 1 << int(math.ceil(math.log2(need)))
    f = np.arange(1, f_nodes + 1) / (2.0 * f_nodes)
    w = np.full(f_nodes, 1.0 / f_nodes)  # 2 / (2F): the mirrored node counts twice
    w[-1] = 0.5 / f_nodes  # f = 1/2 is its own mirror image
    return f, w


def wv_cov_model(model: Model, wv: WaveletVariance) -> np.ndarray:
    """Asymptotic Gaussian covariance of the WV implied by a model (full J x J matrix).

    ``Cov(nu_j, nu_k) = (2 / max(M_j, M_k)) int_{-1/2}^{1/2} |H_j|^2 |H_k|^2 S^2 df``.

    Parameters
    ----------
    model : Model
        Every parameter set (e.g. ``result.model``).
    wv : WaveletVariance
        Gives the levels, ``M_j`` and fs.
    """
    if not model.is_set:
        raise FitError("wv_cov_model needs a model with every value set (a fitted model)")
    levels = wv.n_levels
    # processes fitted at zero contribute nothing (and their phi/beta is arbitrary)
    model = Model(tuple(p for p in model.processes if p.linear_coef() != 0))
    f, wts = frequency_grid(levels, model, wv.fs)
    m_j = wv.n_coef.astype(float)
    out = np.zeros((levels, levels))
    inv_m2 = 1.0 / 4.0 ** np.arange(levels)  # 1 / m^2, m = 2^(j-1)
    chunk = 1 << 14
    g = np.empty((levels, chunk))
    for a in range(0, f.size, chunk):
        fc, wc = f[a : a + chunk], wts[a : a + chunk]
        k = fc.size
        s = np.zeros_like(fc)
        for p in model.processes:
            s += spectral_density(p, fc, wv.fs)
        # |H_j|^2 S = sin^4(pi f m) / (m^2 sin^2(pi f)) S, by sin(2x) = 2 sin x cos x
        x = np.pi * fc
        sin_m, cos_m = np.sin(x), np.cos(x)
        base = s / (sin_m * sin_m)
        for j in range(levels):
            sin2 = sin_m * sin_m
            np.multiply(sin2 * sin2, base * inv_m2[j], out=g[j, :k])
            sin_m, cos_m = 2.0 * sin_m * cos_m, 1.0 - 2.0 * sin2
        gk = g[:, :k]
        out += (gk * wc) @ gk.T
    v = 2.0 * out / np.maximum.outer(m_j, m_j)
    return v


_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _boot_wv(args: tuple) -> np.ndarray:
    model, n, fs, levels, robust, eff, seed = args
    x = model.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    return wavelet_variance(x, fs=fs, levels=levels, robust=robust, eff=eff).variance


def parallel_map(fn, items: list, workers: int) -> list:
    """``map`` over processes. Workers are spawned with one BLAS thread each: forked workers
    that inherit a multithreaded BLAS spin on each other's small matrix products (10x slower)."""
    main_file = getattr(sys.modules.get("__main__"), "__file__", None)
    if workers <= 1 or len(items) < 4 or not main_file or not os.path.exists(main_file):
        return [fn(it) for it in items]  # spawned workers cannot re-import an interactive main
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
            return list(ex.map(fn, items, chunksize=max(1, len(items) // (4 * workers))))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def wv_cov_bootstrap(
    model: Model, wv: WaveletVariance, *, B: int = 100, seed: int | None = 0, workers: int = 1
) -> np.ndarray:
    """Parametric-bootstrap covariance of the WV: simulate ``B`` series of the model's length.

    Parameters
    ----------
    model : Model
        Every value set. B, seed, workers: replicates, base seed (replicate b uses
        ``[seed, b]``), processes (results do not depend on it).
    """
    if B < 2:
        raise ValueError(f"B must be at least 2, got {B}")
    seeds = np.random.SeedSequence(seed).spawn(B)
    items = [(model, wv.n, wv.fs, wv.n_levels, wv.robust, wv.eff, s) for s in seeds]
    sims = np.array(parallel_map(_boot_wv, items, workers))
    return np.cov(sims, rowvar=False)


# ------------------------------------------------------------------------------------------
# efficient GMWM
# ------------------------------------------------------------------------------------------
def inverse_cov(v: np.ndarray) -> np.ndarray:
    """Symmetric inverse of a covariance, with eigenvalues floored for stability."""
    vals, vecs = np.linalg.eigh((v + v.T) / 2)
    vals = np.maximum(vals, vals.max() * 1e-12)
    inv = (vecs / vals) @ vecs.T
    return (inv + inv.T) / 2


def fit_efficient(
    wv: WaveletVariance,
    model: Model | str,
    *,
    v: str | np.ndarray = "model",
    x: Any = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
) -> GMWMResult:
    """Two-step efficient GMWM: ``weights="ci"``, then ``Omega = V^-1`` with V estimated.

    Parameters
    ----------
    v : {"model", "bootstrap", "data"} or array
        How V is estimated: from the first-step fit (analytic Gaussian or parametric
        bootstrap), from the data (needs ``x``; diagonal), or given.
    """
    first = fit_gmwm(wv, model)
    vmat = wv_cov(first, v, x=x, B=B, seed=seed, workers=workers)
    res = fit_gmwm(wv, first.model, weights=inverse_cov(vmat))
    object.__setattr__(res, "weights", "efficient")
    return res


def wv_cov(
    res: GMWMResult,
    v: str | np.ndarray,
    *,
    x: Any = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
) -> np.ndarray:
    """The covariance V of a fit's WV, by name.

    Parameters
    ----------
    res : GMWMResult
        The fit (its model and WV).
    v : {"model", "bootstrap", "data"} or ndarray (J, J)
        :func:`wv_cov_model`, :func:`wv_cov_bootstrap` (``B``, ``seed``, ``workers``),
        :func:`wv_cov_data` (needs the raw series ``x``) or a given matrix (checked).
    """
    if isinstance(v, np.ndarray):
        if v.shape != (res.wv.n_levels,) * 2:
            raise FitError(f"V has shape {v.shape}, expected {(res.wv.n_levels,) * 2}")
        return v
    if v == "model":
        return wv_cov_model(res.model, res.wv)
    if v == "bootstrap":
        return wv_cov_bootstrap(res.model, res.wv, B=B, seed=seed, workers=workers)
    if v == "data":
        if x is None:
            raise FitError("v='data' needs the raw series x")
        return wv_cov_data(x, res.wv)
    raise FitError(f"unknown V estimator {v!r}: use 'model', 'bootstrap', 'data' or a matrix")
