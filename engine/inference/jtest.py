"""Goodness of fit: ``T = (nu_hat - nu)' V^-1 (nu_hat - nu)`` against a chi-square with
``J - p`` degrees of freedom (Hansen's J test for the GMWM)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._jsonutil import FieldsDict
from ..fit import FitError, GMWMResult, fit_gmwm
from ..wv import wavelet_variance
from .asymptotic import free_params
from .covariance import inverse_cov, wv_cov

__all__ = ["j_test", "JTest"]


@dataclass(frozen=True)
class JTest(FieldsDict):
    """Hansen's J-test of over-identifying restrictions for a GMWM fit (``to_dict()``: the
    four fields)."""

    statistic: float
    df: int
    p_value: float
    method: str


def j_test(
    res: GMWMResult,
    *,
    v: str | np.ndarray = "model",
    x: Any = None,
    B: int = 200,
    seed: int | None = 0,
    workers: int = 1,
    method: str = "asymptotic",
) -> JTest:
    """Goodness of fit: ``T = (nu_hat - nu(theta_hat))' V^-1 (nu_hat - nu(theta_hat))``.

    Under a correct model and efficient weights, ``T ~ chi2(J - p)`` asymptotically
    (``method="asymptotic"``). ``method="bootstrap"`` compares T with its distribution over
    parametric-bootstrap replicates refitted the same way (no chi-square assumption).
    """
    from scipy import stats

    vmat = wv_cov(res, v, x=x, B=B, seed=seed, workers=workers)
    vinv = inverse_cov(vmat)
    r = res.wv.variance - res.implied
    t = float(r @ vinv @ r)
    df = res.wv.n_levels - len(free_params(res))
    if df < 1:
        raise FitError(f"the J-test needs more levels than free parameters (J - p = {df})")
    if method == "asymptotic":
        return JTest(t, df, float(stats.chi2.sf(t, df)), "asymptotic")
    if method == "bootstrap":
        seeds = np.random.SeedSequence(seed).spawn(B)
        stats_b = []
        for s in seeds:
            xb = res.model.simulate(res.wv.n, fs=res.fs, rng=np.random.default_rng(s))
            wvb = wavelet_variance(xb, fs=res.fs, levels=res.wv.n_levels)
            fb = fit_gmwm(wvb, res.model.cleared(), weights=res.omega)
            rb = wvb.variance - fb.implied
            stats_b.append(float(rb @ vinv @ rb))
        p = (1 + np.sum(np.array(stats_b) >= t)) / (1 + len(stats_b))
        return JTest(t, df, float(p), "bootstrap")
    raise ValueError(f"unknown J-test method {method!r}")
