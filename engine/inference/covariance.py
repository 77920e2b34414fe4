"""Covariance of the wavelet variance, and the efficient (two-step) GMWM.

``V = Cov(nu_hat)`` across levels, three ways: :func:`wv_cov_data` (from the data, diagonal,
Percival & Walden), :func:`wv_cov_model` (from a fitted model, Gaussian and asymptotic, full),
:func:`wv_cov_bootstrap` (parametric bootstrap); :func:`wv_cov` picks one by name for a fit.
:func:`fit_efficient` refits with ``Omega = V^-1`` (the GMWM paper, Corollary 1).
"""

from __future__ import annotations

import math
from concurrent.futures import Executor
from typing import Any

import numpy as np

from .._parallel import parallel_map
from ..fit import FitError, GMWMResult, fit_gmwm
from ..models import Model
from ..wv import WaveletVariance, as_series, cumsum_demeaned, wavelet_variance
from .asymptotic import wv_cov_model

__all__ = [
    "wv_cov_data",
    "wv_cov_bootstrap",
    "wv_cov",
    "fit_efficient",
    "inverse_cov",
    "parallel_map",
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
    a = as_series(x)
    if a.size != wv.n:
        raise ValueError(f"the series has {a.size} samples but the WV was computed from {wv.n}")
    s = cumsum_demeaned(a)
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


def _boot_wv(args: tuple) -> np.ndarray:
    model, n, fs, levels, robust, eff, seed = args
    x = model.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    return wavelet_variance(x, fs=fs, levels=levels, robust=robust, eff=eff).variance


def wv_cov_bootstrap(
    model: Model,
    wv: WaveletVariance,
    *,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
    executor: Executor | None = None,
) -> np.ndarray:
    """Parametric-bootstrap covariance of the WV: simulate ``B`` series of the model's length.

    Parameters
    ----------
    model : Model
        Every value set. B, seed, workers: replicates, base seed (replicate b uses the b-th
        child of ``SeedSequence(seed)``), local processes (results do not depend on it).
    executor : concurrent.futures.Executor, optional
        Runs the replicates instead of the local pool (e.g. a Dask ``Client.get_executor()``);
        the results do not depend on it (:func:`engine.inference.parallel_map`).
    """
    if B < 2:
        raise ValueError(f"B must be at least 2, got {B}")
    seeds = np.random.SeedSequence(seed).spawn(B)
    items = [(model, wv.n, wv.fs, wv.n_levels, wv.robust, wv.eff, s) for s in seeds]
    sims = np.array(parallel_map(_boot_wv, items, workers, executor=executor))
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
    executor: Executor | None = None,
) -> GMWMResult:
    """Two-step efficient GMWM: ``weights="ci"``, then ``Omega = V^-1`` with V estimated.

    Parameters
    ----------
    v : {"model", "bootstrap", "data"} or array
        How V is estimated: from the first-step fit (analytic Gaussian or parametric
        bootstrap), from the data (needs ``x``; diagonal), or given.
    B, seed, workers, executor
        The bootstrap's replicates, seed, local processes or executor (:func:`wv_cov`).
    """
    first = fit_gmwm(wv, model)
    vmat = wv_cov(first, v, x=x, B=B, seed=seed, workers=workers, executor=executor)
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
    executor: Executor | None = None,
) -> np.ndarray:
    """The covariance V of a fit's WV, by name.

    Parameters
    ----------
    res : GMWMResult
        The fit (its model and WV).
    v : {"model", "bootstrap", "data"} or ndarray (J, J)
        :func:`wv_cov_model`, :func:`wv_cov_bootstrap` (``B``, ``seed``, ``workers``,
        ``executor``),
        :func:`wv_cov_data` (needs the raw series ``x``) or a given matrix (checked).
    """
    if isinstance(v, np.ndarray):
        if v.shape != (res.wv.n_levels,) * 2:
            raise FitError(f"V has shape {v.shape}, expected {(res.wv.n_levels,) * 2}")
        return v
    if v == "model":
        return wv_cov_model(res.model, res.wv)
    if v == "bootstrap":
        return wv_cov_bootstrap(
            res.model, res.wv, B=B, seed=seed, workers=workers, executor=executor
        )
    if v == "data":
        if x is None:
            raise FitError("v='data' needs the raw series x")
        return wv_cov_data(x, res.wv)
    raise FitError(f"unknown V estimator {v!r}: use 'model', 'bootstrap', 'data' or a matrix")
