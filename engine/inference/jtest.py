"""Goodness of fit: Hansen's J-test of over-identifying restrictions for the GMWM.

The test is a test of the *model*, whatever the weights of the fit it is asked about: the model
is refitted with efficient weights ``Omega = V^-1`` (V the model-implied covariance of the WV
at the fit's estimate) on the levels whose WV is nearly Gaussian, and the minimised objective

    T = min_theta (nu_hat - nu(theta))_K' (V_KK)^-1 (nu_hat - nu(theta))_K

is compared with a chi-square with ``|K| - p`` degrees of freedom (``p`` the free parameters of
that refit: a parameter on its boundary does not count).

Why not the fit's own weights and every level (what the J-test did before)?

* The chi-square holds only for the efficient weights: with the ci weights (the default of
  :func:`engine.fit.fit_gmwm` and of model selection) the same quadratic form of the residuals
  rejected the true QN+WN+RW+DR model in 46.5 % of logs at the 5 % level.
* The coarsest levels have few equivalent degrees of freedom ``eta_j = M_j / 2^j`` (Percival
  and Walden's eta3: 1 at the last level, 3 at the one before): their WV is far from Gaussian
  (a chi-square with 1-3 degrees of freedom is skewed 1.6-2.8) and the asymptotic V there is
  far off, so a quadratic form that weights them with ``V^-1`` has a chi-square reference only
  in name. Measured (400 logs each, efficient weights, every level): 8.5 % rejections at 5 %
  on QN+WN+RW+DR (N = 2^15) and 2.8 % on 2*GM+WN+RW (N = 2^15); without the levels with
  ``eta_j < 4``: 5.0 % and 5.5 % (``tests/benchmarks/bench_jtest.py``).
* The rule counts the degrees of freedom of the *estimator*: a robust WV of Gaussian
  efficiency ``eff`` has the variance of a classical one from ``eff`` times as many
  coefficients, so a level enters when ``eff * M_j / 2^j >= ETA_MIN`` (``eff = 1`` for the
  classical WV; :func:`jtest_levels`). With ``ETA_MIN = 10`` a classical WV of ``2^n`` samples
  loses its last three levels (``eta_j`` = 1, 3, 7) and a robust one (eff 0.6) its last four
  (also 15, i.e. 9 robust degrees of freedom). The robust WV's coarse levels are biased
  upwards (+2.8 % at ``eta_j = 15``, +5.5 % at 7; 2000 logs of GM+WN at 2^13) and skewed, and
  with them the test rejected the true robust GM+WN at 5 % in 9.0 % (2^13, 300 logs) and
  8.5-10 % (2^16, 200 logs) of logs; without them 5.0 % and 5.6 % (``docs/jtest.md``). The
  price is power against what shows only at the levels left out: WN tested on WN+RW with the
  RW's WV crossing the white noise's at 1100 samples (2^14) is rejected in 76 % of logs instead
  of 98 % (classical) and 12 % instead of 96 % (robust); ``docs/jtest.md`` says what is left.
* V at the first-step estimate or at the truth made no difference once those levels are out
  (within Monte Carlo error), so V is evaluated once, at the fit's estimate.

V is :func:`engine.fit.wv_cov_model` at the fit's estimate: the covariance of the WV's own
estimator (a robust WV's variance is 1.3-1.5 times the classical one's) with a drift's
first-order share (up to 10^4 times the rest at the coarse levels of a log with a strong
drift). Without them the test rejected the true model in 36-39 % of robust GM+WN logs and
18 % of WN+RW+DR logs with a strong drift; ``docs/jtest.md`` has the Monte Carlo with them
(``tests/benchmarks/jtest_mc.py``). A V without a chi-square reference (``v="data"``: the
diagonal of the classical WV's variance, no covariance between levels) gives no p-value: the
result says ``calibrated=False`` and why (``note``), and ``p_value`` is NaN (null in JSON).

``method="bootstrap"`` compares the same statistic with its distribution over parametric-
bootstrap replicates of the fitted model, each fitted with the fit's own weights and then
tested the same way (no chi-square assumption; the same V for every replicate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._jsonutil import FieldsDict
from .._parallel import parallel_map
from ..fit import FitError, GMWMResult, fit_gmwm
from ..fit.asymptotic import drift_share, free_params, wv_cov_model
from ..fit.covariance import inverse_cov, v_options, wv_cov
from ..models import Model
from ..wv import WaveletVariance, wavelet_variance

if TYPE_CHECKING:  # pragma: no cover
    from typing_extensions import Unpack

    from ..fit.covariance import VOptions

__all__ = [
    "j_test",
    "JTest",
    "ETA_MIN",
    "jtest_levels",
    "efficient_j",
    "calibration_note",
    "NOT_CALIBRATED_DATA",
    "DRIFT_SHARE_MAX",
]

#: Levels whose estimator has fewer equivalent degrees of freedom than this,
#: ``eff * M_j / 2^j`` (``eff`` the robust WV's Gaussian efficiency, 1 for the classical WV),
#: are left out of the J statistic (:func:`jtest_levels`; see the module docstring).
ETA_MIN = 10.0


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
        :data:`ETA_MIN` equivalent degrees of freedom, are left out); 0 when not recorded.
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
#: the statistic, the J-test has no calibrated chi-square reference: the share is proportional
#: to the random walk's variance, which so strong a drift leaves poorly determined (WN+RW+DR
#: at 2^14 with the share 4000 times the rest: 24-37 % rejections of the true model at 5 %,
#: and 10 % even with V at the truth; at 40-140 times: 3-7.5 %; ``docs/jtest.md``).
DRIFT_SHARE_MAX = 1000.0

#: Why a J-test with V from the data (``v="data"``) has no p-value.
NOT_CALIBRATED_DATA = (
    "V from the data (v='data') is the diagonal of the classical WV's variance: without the "
    "covariance between levels T has no chi-square reference; use v='model' (default) or "
    "method='bootstrap'"
)


def jtest_levels(wv: WaveletVariance) -> int:
    """How many levels (1..K) enter the J statistic: those whose estimator has at least
    :data:`ETA_MIN` equivalent degrees of freedom, ``eff * M_j / 2^j >= ETA_MIN``.

    ``M_j / 2^j`` is Percival and Walden's eta3 of the classical WV; a robust WV of Gaussian
    efficiency ``eff`` (``wv.eff``) has the variance of a classical one from ``eff`` times as
    many coefficients, so its degrees of freedom are ``eff`` times fewer (``eff = 1`` for the
    classical WV).

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
    >>> jtest_levels(eg.wavelet_variance(x))  # eta3 = 7, 3, 1 at the last three levels
    9
    >>> jtest_levels(eg.wavelet_variance(x, robust=True))  # and 0.6 * 15 = 9 < 10
    8
    """
    eff = float(wv.eff) if wv.robust else 1.0
    edof = eff * wv.n_coef / wv.tau_samples
    return int(np.count_nonzero(edof >= ETA_MIN))


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
        :func:`engine.fit.fit_gmwm`.

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
            f"have at least {ETA_MIN:g} equivalent degrees of freedom (eff M_j / 2^j), the model "
            f"has {p} parameters; use a longer log or a smaller model"
        )
    fit = fit_gmwm(wv, start, weights=inverse_cov(vmat[:k, :k]), levels=k, optima=optima)
    df = k - len(free_params(fit))
    return float(fit.objective), df, k, fit


def calibration_note(model: Model, wv: WaveletVariance, vmat: np.ndarray, levels: int) -> str:
    """Why the asymptotic J-test of a model with V = ``vmat`` is not calibrated, or ``""``.

    Not calibrated when a drift's first-order share of ``Var(nu_j)``
    (:func:`engine.fit.asymptotic.drift_share`) exceeds :data:`DRIFT_SHARE_MAX` times the rest
    at one of the statistic's ``levels``.
    """
    share = np.diagonal(drift_share(model, wv))[:levels]
    if not np.any(share > 0):
        return ""
    noise = Model(tuple(p for p in model.processes if not p.deterministic))
    rest = np.diagonal(wv_cov_model(noise, wv))[:levels] if noise.processes else share * 0
    ratio = share / np.maximum(rest, np.finfo(float).tiny)
    j = int(np.argmax(ratio))
    if ratio[j] <= DRIFT_SHARE_MAX:
        return ""
    return (
        f"not calibrated: the drift's share of the WV's variance is {ratio[j]:.3g} times the "
        f"rest at level {j + 1} (above {DRIFT_SHARE_MAX:g}); it scales with the random walk's "
        "variance, which so strong a drift leaves too poorly determined for a chi-square "
        "reference"
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
    on the levels whose estimator has at least :data:`ETA_MIN` equivalent degrees of freedom
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
    (8, 6.99, 0.54)
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
