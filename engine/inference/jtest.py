"""Goodness of fit: Hansen's J-test of over-identifying restrictions for the GMWM.

The test is a test of the *model*, whatever the weights of the fit it is asked about: the model
is refitted with efficient weights ``Omega = V^-1`` (V the model-implied covariance of the WV
of the WV's own estimator at the fit's estimate, with a drift's share) on the levels whose WV
is nearly Gaussian (:func:`jtest_levels`), and the minimised objective is compared with a
chi-square with ``|K| - p`` degrees of freedom. A V without a chi-square reference gives no
p-value (``calibrated=False`` and the reason in ``note``); ``method="bootstrap"`` compares the
same statistic with parametric-bootstrap replicates. Why efficient weights and these levels,
with the measured rejection rates: docs/methods.md, "The J-test"; the calibration Monte Carlo:
docs/jtest.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._jsonutil import FieldsDict
from .._parallel import parallel_map
from ..fit import FitError, GMWMResult, fit_gmwm
from ..fit.asymptotic import drift_share, free_params, inverse_cov, wv_cov_model
from ..fit.covariance import v_options, wv_cov
from ..models import Model
from ..wv import WaveletVariance, wavelet_variance

if TYPE_CHECKING:  # pragma: no cover
    from typing_extensions import Unpack

    from ..fit.covariance import VOptions

__all__ = [
    "j_test",
    "JTest",
    "ETA_MIN",
    "ETA_MIN_ROBUST",
    "LEVELS_RULE",
    "jtest_levels",
    "efficient_j",
    "calibration_note",
    "NOT_CALIBRATED_DATA",
    "DRIFT_SHARE_MAX",
    "drift_share_ratio",
]

#: Levels of a classical WV with fewer equivalent degrees of freedom ``M_j / 2^j`` than this
#: are left out of the J statistic (the last two levels at the default number of levels;
#: :func:`jtest_levels`).
ETA_MIN = 4.0
#: Levels of a robust WV whose estimator has fewer equivalent degrees of freedom
#: ``eff * M_j / 2^j`` than this (``eff`` its Gaussian efficiency) are left out: its coarse
#: levels carry a small-sample bias (+2.35 %, +4.3 %, +8.3 % at ``M_j / 2^j`` = 15, 7, 3,
#: measured) that the classical WV's do not (:func:`jtest_levels`, docs/jtest.md).
ETA_MIN_ROBUST = 10.0
#: The levels rule in words (messages, the app's help).
LEVELS_RULE = f"M_j / 2^j >= {ETA_MIN:g}, robust WV: eff M_j / 2^j >= {ETA_MIN_ROBUST:g}"


@dataclass(frozen=True)
class JTest(FieldsDict):
    """Hansen's J-test of over-identifying restrictions for a GMWM fit (``to_dict()``: every
    field).

    Attributes
    ----------
    statistic : float
        T, the efficient objective on the levels used.
    df : int
        Degrees of freedom: levels used less free parameters.
    p_value : float
        Upper tail of T (chi-square, or the bootstrap distribution).
    method : str
        ``"asymptotic"`` (chi-square) or ``"bootstrap"``.
    levels : int
        Number of levels in the statistic (levels 1..``levels``: the coarsest, with fewer than
        :func:`jtest_levels`'s rule, are left out); 0 when not recorded.
    calibrated : bool
        Whether ``p_value`` has a calibrated reference; when False, ``p_value`` is NaN.
    note : str
        Why the test is not calibrated (empty when it is).
    """

    statistic: float
    df: int
    p_value: float
    method: str
    levels: int = 0
    calibrated: bool = True
    note: str = ""

    def p_text(self, spec: str = ".3g") -> str:
        """The p-value as shown in tables: formatted, or ``"not calibrated"``."""
        return format(self.p_value, spec) if self.calibrated else "not calibrated"


#: Above this ratio of a drift's first-order share of ``Var(nu_j)`` to the rest, at any level of
#: the statistic and judged at the estimate (:func:`drift_share_ratio`), the J-test has no
#: calibrated chi-square reference. With V at the truth the test holds its size at every
#: share measured (3.0-4.0 % at 40-36,000 times); with V at the estimate it does not once the
#: share is large, because the share scales with the random walk's variance, which so strong a
#: drift leaves poorly determined. WN+RW+DR at 2^14, 1800 logs binned by this ratio: 2.9-6.4 %
#: rejected at 5 % up to 1000 (3.7 % pooled), 8.6 % at 1000-2000, 22-25 % above 4000
#: (``tests/benchmarks/jtest_drift_scan.py``, ``docs/jtest.md``).
DRIFT_SHARE_MAX = 1000.0

#: Why a J-test with V from the data (``v="data"``) has no p-value.
NOT_CALIBRATED_DATA = (
    "V from the data (v='data') is the diagonal of the classical WV's variance: without the "
    "covariance between levels T has no chi-square reference; use v='model' (default) or "
    "method='bootstrap'"
)


def jtest_levels(wv: WaveletVariance) -> int:
    """How many levels (1..K) enter the J statistic: those whose estimator has enough
    equivalent degrees of freedom for a chi-square reference.

    A classical WV: ``M_j / 2^j >= ETA_MIN`` (4; ``M_j / 2^j`` is Percival and Walden's eta3).
    A robust WV of Gaussian efficiency ``eff`` (``wv.eff``) has the variance of a classical one
    from ``eff`` times as many coefficients, and its coarse levels are biased upwards at small
    eta3, so it needs ``eff * M_j / 2^j >= ETA_MIN_ROBUST`` (10): with the classical rule the
    robust J-test rejected the true GM+WN in 8.3-9.6 % of logs at 5 % (docs/jtest.md).

    Parameters
    ----------
    wv : WaveletVariance
        Gives ``M_j``, ``2^j`` and the estimator (``robust``, ``eff``).

    Returns
    -------
    int
        K: the statistic uses levels 1..K (the coarsest levels are the ones left out).

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = np.random.default_rng(0).standard_normal(2**13)
    >>> jtest_levels(eg.wavelet_variance(x))  # eta3 = 3, 1 at the last two levels
    10
    >>> jtest_levels(eg.wavelet_variance(x, robust=True))  # and 0.6 * 15 = 9 < 10
    8
    """
    eta = wv.n_coef / wv.tau_samples
    if wv.robust:
        return int(np.count_nonzero(float(wv.eff) * eta >= ETA_MIN_ROBUST))
    return int(np.count_nonzero(eta >= ETA_MIN))


def efficient_j(
    wv: WaveletVariance, start: Model, vmat: np.ndarray, optima: dict[Any, Any] | None = None
) -> tuple[float, int, int, GMWMResult]:
    """The J statistic of a model: its efficient refit on the levels of :func:`jtest_levels`.

    Parameters
    ----------
    wv : WaveletVariance
        The empirical WV.
    start : Model
        The model (its values, if set, start the refit).
    vmat : ndarray (J, J)
        Covariance of the WV; only its block on the levels used matters.
    optima : dict, optional
        Shared by the refits of several models (a ranking's candidates), as in
        :func:`engine.fit.fit_gmwm`; each refit is then a polish from the values of ``start``
        (``fit_gmwm(polish=True)``: its optimum moves little from the fitted candidate's).

    Returns
    -------
    statistic, df, levels, refit
        T (the refit's objective), ``levels - p`` with ``p`` the refit's free parameters, the
        number of levels used, and the refit itself (to the first ``levels`` levels).

    Raises
    ------
    FitError
        Fewer levels in the statistic than free parameters plus one.
    """
    k = jtest_levels(wv)
    p = start.n_params
    if k <= p:
        raise FitError(
            f"the J-test needs more levels than parameters: {k} of the {wv.n_levels} levels "
            f"have enough equivalent degrees of freedom ({LEVELS_RULE}), the model "
            f"has {p} parameters; use a longer log or a smaller model"
        )
    fit = fit_gmwm(
        wv,
        start,
        weights=inverse_cov(vmat[:k, :k]),
        levels=k,
        optima=optima,
        polish=optima is not None,
    )
    df = k - len(free_params(fit))
    return float(fit.objective), df, k, fit


def drift_share_ratio(model: Model, wv: WaveletVariance, levels: int) -> tuple[float, int]:
    """The largest ratio, over the statistic's levels, of a drift's first-order share of
    ``Var(nu_j)`` (:func:`engine.fit.asymptotic.drift_share`) to the rest of ``Var(nu_j)``
    (the noise's :func:`engine.fit.wv_cov_model`), and the level (1-based) where it is.

    The number :func:`calibration_note` compares with :data:`DRIFT_SHARE_MAX`.

    Parameters
    ----------
    model : Model
        Every parameter set (a fitted model, or the truth in a Monte Carlo).
    wv : WaveletVariance
        Gives the levels, ``M_j``, ``n`` and fs.
    levels : int
        The statistic uses levels 1..``levels`` (:func:`jtest_levels`).

    Returns
    -------
    ratio, level
        ``(0.0, 0)`` without a drift.
    """
    share = np.diagonal(drift_share(model, wv))[:levels]
    if not np.any(share > 0):
        return 0.0, 0
    noise = Model(tuple(p for p in model.processes if not p.deterministic))
    rest = np.diagonal(wv_cov_model(noise, wv))[:levels] if noise.processes else share * 0
    ratio = share / np.maximum(rest, np.finfo(float).tiny)
    j = int(np.argmax(ratio))
    return float(ratio[j]), j + 1


def calibration_note(model: Model, wv: WaveletVariance, vmat: np.ndarray, levels: int) -> str:
    """Why the asymptotic J-test of a model with V = ``vmat`` is not calibrated, or ``""``.

    Not calibrated when a drift's first-order share of ``Var(nu_j)`` exceeds
    :data:`DRIFT_SHARE_MAX` times the rest at one of the statistic's ``levels``, judged at the
    estimate (:func:`drift_share_ratio`).
    """
    ratio, level = drift_share_ratio(model, wv, levels)
    if ratio <= DRIFT_SHARE_MAX:
        return ""
    return (
        f"not calibrated: the drift's share of the WV's variance is {ratio:.3g} times the "
        f"rest at level {level} (above {DRIFT_SHARE_MAX:g}); V at the estimate is then too "
        "uncertain for a chi-square reference (the share scales with the random walk's "
        "variance, which so strong a drift leaves poorly determined)"
    )


def _boot_statistic(args: tuple) -> float:
    """J statistic of one parametric-bootstrap replicate (a task of :func:`parallel_map`): the
    replicate's WV is computed like the fit's (classical or robust, same efficiency)."""
    res, vmat, seed = args
    xb = res.model.simulate(res.wv.n, fs=res.fs, rng=np.random.default_rng(seed))
    wvb = wavelet_variance(
        xb, fs=res.fs, levels=res.wv.n_levels, robust=res.wv.robust, eff=res.wv.eff
    )
    fb = fit_gmwm(wvb, res.model.cleared(), weights=res.omega)
    return efficient_j(wvb, fb.model, vmat)[0]


def j_test(res: GMWMResult, *, method: str = "asymptotic", **options: Unpack[VOptions]) -> JTest:
    """Goodness of fit of a fitted model (calibrated whatever the fit's weights, for a
    classical or robust WV, with or without a drift).

    The model is refitted with ``Omega = V^-1`` (V at the fit's estimate, :class:`VOptions`;
    by default :func:`engine.fit.wv_cov_model`, the covariance of the WV's own estimator)
    on the levels whose estimator has enough equivalent degrees of freedom
    (:func:`jtest_levels`), and
    ``T = (nu_hat - nu(theta))' V^-1 (nu_hat - nu(theta))`` at that refit is compared with
    ``chi2(levels - p)`` (``method="asymptotic"``) or with its distribution over parametric-
    bootstrap replicates (``method="bootstrap"``). See the module docstring for why, with the
    measured rejection rates of the true model.

    Parameters
    ----------
    res : GMWMResult
        The fit (any weights).
    method : {"asymptotic", "bootstrap"}
        The reference distribution of T.
    **options
        :class:`VOptions`: how V is estimated (``v``, ``x``), the bootstrap's replicates
        (``B``, default 200 here) and base seed, and where they run (``workers``,
        ``executor``; the result does not depend on them).

    Returns
    -------
    JTest
        With ``calibrated=False``, a NaN ``p_value`` and the reason in ``note`` when V has no
        chi-square reference (``v="data"`` with ``method="asymptotic"``).

    Raises
    ------
    FitError
        Too few levels for the model's parameters.
    ValueError
        An unknown ``method``.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = eg.parse_model("WN(1e-2) + RW(1e-6)").simulate(2**14, rng=np.random.default_rng(1))
    >>> res = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0), "WN + RW")
    >>> jt = eg.j_test(res)
    >>> jt.df, round(jt.statistic, 2), round(jt.p_value, 2)  # the right model: no rejection
    (9, 9.89, 0.36)
    """
    o = v_options(options, B=200)
    if method not in ("asymptotic", "bootstrap"):
        raise ValueError(f"unknown J-test method {method!r}: use 'asymptotic' or 'bootstrap'")
    from scipy import stats

    vmat = wv_cov(res, **o)
    t, df, k, refit = efficient_j(res.wv, res.model, vmat)
    model_v = isinstance(o["v"], str) and o["v"] == "model"
    if model_v and np.any(np.diagonal(drift_share(res.model, res.wv)) > 0):
        # a drift's share of V scales with the random walk's variance, which the fit's own
        # weights estimate less well than the efficient refit: V once more, at the refit
        # (WN+RW+DR, 2^16, 40 logs: mean T/df 1.11 -> 1.03)
        vmat = wv_cov_model(refit.model, res.wv)
        t, df, k, refit = efficient_j(res.wv, refit.model, vmat)
    if df < 1:
        raise FitError(f"the J-test needs more levels than free parameters (J - p = {df})")
    if method == "asymptotic":
        if isinstance(o["v"], str) and o["v"] == "data":
            return JTest(t, df, math.nan, "asymptotic", k, False, NOT_CALIBRATED_DATA)
        note = calibration_note(refit.model, res.wv, vmat, k)
        if note:
            return JTest(t, df, math.nan, "asymptotic", k, False, note)
        return JTest(t, df, float(stats.chi2.sf(t, df)), "asymptotic", k)
    items = [(res, vmat, s) for s in np.random.SeedSequence(o["seed"]).spawn(o["B"])]
    stats_b = parallel_map(_boot_statistic, items, o["workers"], executor=o["executor"])
    p = (1 + np.sum(np.array(stats_b) >= t)) / (1 + len(stats_b))
    return JTest(t, df, float(p), "bootstrap", k)
