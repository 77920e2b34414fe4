"""Covariance of the wavelet variance, the weights of the efficient (two-step) GMWM.

``V = Cov(nu_hat)`` across levels, three ways: :func:`wv_cov_data` (from the data, diagonal,
Percival & Walden), :func:`wv_cov_model` (from a fitted model, Gaussian and asymptotic, full),
:func:`wv_cov_bootstrap` (parametric bootstrap); :func:`wv_cov` picks one by name for a fit.
``fit_gmwm(..., weights="efficient")`` refits with ``Omega = V^-1`` (the GMWM paper,
Corollary 1); this module sits below :mod:`engine.fit.gmwm` so that the fit can do it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from concurrent.futures import Executor
from typing import TYPE_CHECKING, Any, Protocol, TypedDict

import numpy as np

from .._limits import check_replicates
from .._parallel import parallel_map
from ..models import Model
from ..wv import WaveletVariance, as_series, haar_coefficients, wavelet_variance
from .asymptotic import wv_cov_model
from .result import FitError

if TYPE_CHECKING:  # pragma: no cover
    from typing_extensions import Unpack

__all__ = [
    "wv_cov_data",
    "wv_cov_bootstrap",
    "wv_cov",
    "VOptions",
    "V_DEFAULTS",
    "v_options",
]


class _ReplicateOptions(TypedDict, total=False):
    """The :class:`VOptions` other than ``v`` (what :func:`wv_cov` takes besides ``v``)."""

    x: Any
    B: int
    seed: int | None
    workers: int
    executor: Executor | None


class VOptions(_ReplicateOptions, total=False):
    """How V, the covariance of the WV, and the parametric-bootstrap replicates are computed:
    the keywords that :func:`wv_cov`, :func:`fit_efficient`, :func:`param_intervals` and
    :func:`j_test` share (one list, one set of defaults: :data:`V_DEFAULTS`).

    Attributes
    ----------
    v : {"model", "bootstrap", "data"} or ndarray (J, J)
        :func:`wv_cov_model` (default), :func:`wv_cov_bootstrap`, :func:`wv_cov_data` (needs
        ``x``) or a given matrix (its shape is checked).
    x : array_like
        The raw series (``v="data"``).
    B : int
        Bootstrap replicates (default 100; the J-test's 200).
    seed : int or None
        Base seed: replicate b draws from the b-th child of ``SeedSequence(seed)`` (default 0).
    workers : int
        Local worker processes (default 1: in process).
    executor : concurrent.futures.Executor
        Runs the replicates instead of the local pool (e.g. a Dask ``Client.get_executor()``).
        No result depends on ``workers`` or ``executor``.
    """

    v: str | np.ndarray


#: The defaults of :class:`VOptions`.
V_DEFAULTS: dict[str, Any] = {
    "v": "model",
    "x": None,
    "B": 100,
    "seed": 0,
    "workers": 1,
    "executor": None,
}


def v_options(options: Mapping[str, Any], **defaults: Any) -> dict[str, Any]:
    """Every :class:`VOptions` keyword with its value: ``options`` over ``defaults`` (e.g.
    ``B=200``) over :data:`V_DEFAULTS`.

    Raises
    ------
    TypeError
        An unknown keyword; the message lists the known ones.
    """
    unknown = sorted(set(options) - set(V_DEFAULTS))
    if unknown:
        raise TypeError(
            f"unknown keyword(s) {', '.join(unknown)}: the V options are {', '.join(V_DEFAULTS)}"
        )
    out = {**V_DEFAULTS, **defaults, **options}
    out["B"] = check_replicates(out["B"])
    return out


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
    out = np.empty(wv.n_levels)
    for i, j in enumerate(wv.levels):
        w = haar_coefficients(a, int(j))
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
        the results do not depend on it (:func:`engine._parallel.parallel_map`).
    """
    B = check_replicates(B)
    seeds = np.random.SeedSequence(seed).spawn(B)
    items = [(model, wv.n, wv.fs, wv.n_levels, wv.robust, wv.eff, s) for s in seeds]
    sims = np.array(parallel_map(_boot_wv, items, workers, executor=executor))
    return np.cov(sims, rowvar=False)


class _FittedWV(Protocol):
    """What :func:`wv_cov` reads of a fit: its model and its empirical WV."""

    @property
    def model(self) -> Model: ...

    @property
    def wv(self) -> WaveletVariance: ...


def wv_cov(
    res: _FittedWV, v: str | np.ndarray = "model", **options: Unpack[_ReplicateOptions]
) -> np.ndarray:
    """The covariance V of a fit's WV, by name.

    Parameters
    ----------
    res : GMWMResult
        The fit (its model and WV).
    v : {"model", "bootstrap", "data"} or ndarray (J, J)
        :func:`wv_cov_model`, :func:`wv_cov_bootstrap`, :func:`wv_cov_data` (needs the raw
        series ``x``) or a given matrix (checked).
    **options
        The other :class:`VOptions` (``x``, ``B``, ``seed``, ``workers``, ``executor``).
    """
    o = v_options(options)
    if isinstance(v, np.ndarray):
        if v.shape != (res.wv.n_levels,) * 2:
            raise FitError(f"V has shape {v.shape}, expected {(res.wv.n_levels,) * 2}")
        return v
    if v == "model":
        return wv_cov_model(res.model, res.wv)
    if v == "bootstrap":
        return wv_cov_bootstrap(
            res.model,
            res.wv,
            B=o["B"],
            seed=o["seed"],
            workers=o["workers"],
            executor=o["executor"],
        )
    if v == "data":
        if o["x"] is None:
            raise FitError("v='data' needs the raw series x")
        return wv_cov_data(o["x"], res.wv)
    raise FitError(f"unknown V estimator {v!r}: use 'model', 'bootstrap', 'data' or a matrix")
