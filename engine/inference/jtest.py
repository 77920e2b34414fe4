"""Goodness of fit: ``T = (nu_hat - nu)' V^-1 (nu_hat - nu)`` against a chi-square with
``J - p`` degrees of freedom (Hansen's J test for the GMWM)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._jsonutil import FieldsDict
from .._parallel import parallel_map
from ..fit import FitError, GMWMResult, fit_gmwm
from ..wv import wavelet_variance
from .asymptotic import free_params
from .covariance import inverse_cov, v_options, wv_cov

if TYPE_CHECKING:  # pragma: no cover
    from typing_extensions import Unpack

    from .covariance import VOptions

__all__ = ["j_test", "JTest"]


@dataclass(frozen=True)
class JTest(FieldsDict):
    """Hansen's J-test of over-identifying restrictions for a GMWM fit (``to_dict()``: the
    four fields)."""

    statistic: float
    df: int
    p_value: float
    method: str


def _boot_statistic(args: tuple) -> float:
    """J statistic of one parametric-bootstrap replicate (a task of :func:`parallel_map`)."""
    res, vinv, seed = args
    xb = res.model.simulate(res.wv.n, fs=res.fs, rng=np.random.default_rng(seed))
    wvb = wavelet_variance(xb, fs=res.fs, levels=res.wv.n_levels)
    fb = fit_gmwm(wvb, res.model.cleared(), weights=res.omega)
    rb = wvb.variance - fb.implied
    return float(rb @ vinv @ rb)


def j_test(res: GMWMResult, *, method: str = "asymptotic", **options: Unpack[VOptions]) -> JTest:
    """Goodness of fit: ``T = (nu_hat - nu(theta_hat))' V^-1 (nu_hat - nu(theta_hat))``.

    Under a correct model and efficient weights, ``T ~ chi2(J - p)`` asymptotically
    (``method="asymptotic"``). ``method="bootstrap"`` compares T with its distribution over
    parametric-bootstrap replicates refitted the same way (no chi-square assumption).

    Parameters
    ----------
    res : GMWMResult
        The fit.
    method : {"asymptotic", "bootstrap"}
        The reference distribution of T.
    **options
        :class:`VOptions`: how V is estimated (``v``, ``x``), the bootstrap's replicates
        (``B``, default 200 here) and base seed, and where they run (``workers``,
        ``executor``; the result does not depend on them).
    """
    o = v_options(options, B=200)
    from scipy import stats

    vmat = wv_cov(res, **o)
    vinv = inverse_cov(vmat)
    r = res.wv.variance - res.implied
    t = float(r @ vinv @ r)
    df = res.wv.n_levels - len(free_params(res))
    if df < 1:
        raise FitError(f"the J-test needs more levels than free parameters (J - p = {df})")
    if method == "asymptotic":
        return JTest(t, df, float(stats.chi2.sf(t, df)), "asymptotic")
    if method == "bootstrap":
        items = [(res, vinv, s) for s in np.random.SeedSequence(o["seed"]).spawn(o["B"])]
        stats_b = parallel_map(_boot_statistic, items, o["workers"], executor=o["executor"])
        p = (1 + np.sum(np.array(stats_b) >= t)) / (1 + len(stats_b))
        return JTest(t, df, float(p), "bootstrap")
    raise ValueError(f"unknown J-test method {method!r}")
