"""GMWM: fit a composite latent model by matching the empirical and the implied wavelet variance.

``theta_hat = argmin (nu_hat - nu(theta))' Omega (nu_hat - nu(theta))``.

Every process has one non-negative linear coefficient ``h`` (variance-like) and AR1/GM also one
non-linear parameter (phi). The implied WV is ``X(phi) h``, so for fixed phi the minimum over
``h >= 0`` is a non-negative least-squares problem solved exactly (variable projection):

* models made only of QN, WN, RW and DR: closed form (the GMWM paper, eq. 6-7, with h >= 0);
* models with AR1/GM: a deterministic grid over the correlation times of the AR1/GM terms
  (all candidates at once, bounded by the unconstrained least-squares lower bound), then a
  local Nelder-Mead search on the profiled objective from the best candidates, repeated until
  the objective stops improving. The search space is the log correlation time.

Reference: Guerrier, Skaloud, Stebler & Victoria-Feser (2013), JASA 108(502);
Guerrier, Jurado, Khaghani et al. (2020), IEEE TIM (the GMWM paper).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from ..models import Model, Process, parse_model
from ..wv import WaveletVariance, wavelet_variance
from ..wv.classical import axis_columns
from ._varpro import (
    NNLSProblem,
    fitted_fields,
    fitted_model,
    nested_search,
    persistent_first,
    search_message,
    sqrt_weight,
    start_coordinates,
)
from .asymptotic import asymptotic_bounds, inverse_cov, wv_cov_model
from .covariance import VOptions, v_options, wv_cov
from .ieee import IeeeTable, ieee_table
from .result import FitError, OneWVFit, ParamTable, UnivariateFit

if TYPE_CHECKING:  # pragma: no cover
    from typing_extensions import Unpack

__all__ = ["fit_gmwm", "GMWMResult", "weight_matrix", "gmwm_objective"]


@dataclass(frozen=True, eq=False, kw_only=True)
class GMWMResult(OneWVFit, UnivariateFit):
    """Result of :func:`fit_gmwm` (the fields of :class:`engine.fit.result.FitResult`, plus:).

    Attributes
    ----------
    wv : WaveletVariance
        The empirical WV the model was fitted to.
    implied : ndarray, shape (J,)
        Model-implied WV at the empirical scales.
    components : dict[str, ndarray]
        Implied WV of each process by label (``WN``, ``GM_1`` ...), summing to ``implied``.

    ``weights`` is ``"ci"``, ``"identity"`` or ``"user"``; ``omega`` the (J, J) matrix;
    ``at_bound`` lists a variance at 0 or a correlation time at the edge of the explored
    range (a sign that the model may be too large); ``warnings`` flags an AR1/GM whose
    correlation time is shorter than one sample (white noise in disguise); ``method`` is
    ``"closed-form"`` or ``"grid+nelder-mead"``.
    """

    wv: WaveletVariance
    implied: np.ndarray
    components: dict[str, np.ndarray]

    def implied_at(self, tau_samples: np.ndarray) -> np.ndarray:
        """Implied WV at other scales (samples), e.g. for a smooth curve."""
        return self.model.wv(tau_samples, self.fs)

    def conf_int(self, alpha: float = 0.05) -> ParamTable:
        """Two-sided ``1 - alpha`` asymptotic intervals (the sandwich covariance with the
        model-implied WV covariance, :func:`engine.inference.param_intervals`); a parameter on
        a boundary gets ``nan`` bounds."""
        bounds = asymptotic_bounds(self, wv_cov_model(self.model, self.wv), 1.0 - alpha)
        recs = self.param_records
        return ParamTable(
            names=tuple(r.full_name for r in recs),
            estimate=np.array([r.value for r in recs]),
            lower=np.array([b[0] for b in bounds]),
            upper=np.array([b[1] for b in bounds]),
            units=tuple(r.unit for r in recs),
            level=1.0 - alpha,
        )

    @cached_property
    def ieee(self) -> IeeeTable:
        """The IEEE quantities of the fit with 95 % intervals (:func:`engine.fit.ieee.ieee_table`):
        N (white noise, its disguised share included), B (Allan floor / 0.664), the Allan
        deviation minimum with its averaging time (model and data), and K, Q, R where the model
        has them, in SI and datasheet units."""
        return ieee_table(self)

    def _summary_head(self) -> list[str]:
        w = self.wv
        return [
            f"GMWM fit of {self.model.spec()}",
            f"  data: N = {w.n} samples, fs = {w.fs:g} Hz, {w.n_levels} WV levels"
            f"{' (robust WV)' if w.robust else ''}",
            f"  weights: {self.weights}; objective = {self.objective:.6g}; "
            f"{self.method}, {self.n_evaluations} evaluations, {1e3 * self.elapsed_s:.1f} ms",
        ]

    def _summary_tail(self) -> list[str]:
        from ..units import datasheet

        ds = datasheet(self.model, self.wv.fs, self.wv.unit, n_levels=self.wv.n_levels)
        out = ["", *self.ieee.lines()]
        if not ds:
            return out
        return (
            out
            + ["", "  datasheet view (as gmwm export --format datasheet):"]
            + [
                f"  {row['label']:<8} {row['quantity']:<40} {row['symbol']:<8} "
                f"{row['value']:>12.5g}  {row['unit']}"
                for row in ds
            ]
        )

    def _dict_extra(self) -> dict[str, Any]:
        return {
            "n": int(self.wv.n),
            "implied": [float(v) for v in self.implied],
            "components": {k: [float(x) for x in v] for k, v in self.components.items()},
            "wv": self.wv.to_dict(),
            "ieee": self.ieee.to_dict(),
        }


def weight_matrix(wv: WaveletVariance, weights: str | np.ndarray = "ci") -> tuple[np.ndarray, str]:
    """The weighting matrix Omega for a WV.

    Parameters
    ----------
    weights : {"ci", "identity"} or array
        ``"ci"``: ``diag(1 / (ci_high - ci_low)^2)`` (the R packages' default);
        ``"identity"``; a (J,) vector of diagonal weights or a (J, J) symmetric positive
        (semi-)definite matrix.
    """
    j = wv.n_levels
    if isinstance(weights, str):
        if weights == "ci":
            width = wv.ci_high - wv.ci_low
            if np.any(~np.isfinite(width)) or np.any(width <= 0):
                bad = int(np.flatnonzero(~(np.isfinite(width) & (width > 0)))[0]) + 1
                raise FitError(
                    f"the WV interval at level {bad} is empty or not finite, so "
                    "weights='ci' is undefined (constant signal?); "
                    "use another weighting"
                )
            return np.diag(1.0 / width**2), "ci"
        if weights == "identity":
            return np.eye(j), "identity"
        raise FitError(f"unknown weights {weights!r}: use 'ci', 'identity' or a matrix")
    w = np.asarray(weights, dtype=float)
    if w.ndim == 1:
        w = np.diag(w)
    if w.shape != (j, j):
        raise FitError(
            f"the weight matrix has shape {w.shape}, the WV has {j} levels: "
            f"give a ({j},) vector or a ({j}, {j}) matrix"
        )
    if not np.all(np.isfinite(w)) or not np.allclose(w, w.T, rtol=1e-10, atol=0):
        raise FitError("the weight matrix must be finite and symmetric")
    return w, "user"


def gmwm_objective(
    wv: WaveletVariance, model: Model | Process | str, weights: str | np.ndarray = "ci"
) -> float:
    """The GMWM objective of a model with every value set: ``r' Omega r``, ``r = nu_hat - nu``.

    The quantity :func:`fit_gmwm` minimises, at given values (e.g. what-if values), with the
    weights of :func:`weight_matrix`; at a fit's estimate it is the fit's ``objective``.

    Parameters
    ----------
    wv : WaveletVariance
        The empirical WV ``nu_hat``.
    model : Model, Process or str
        The model, every parameter set (``nu`` is its implied WV at ``wv``'s scales).
    weights : {"ci", "identity"} or array
        As in :func:`weight_matrix`.

    Returns
    -------
    float
        The objective (dimensionless with ``"ci"`` weights).
    """
    m = model if isinstance(model, Model) else parse_model(model)
    omega, _ = weight_matrix(wv, weights)
    r = wv.variance - m.wv(wv.tau_samples, wv.fs)
    return float(r @ omega @ r)


def fit_efficient(
    wv: WaveletVariance, model: Model | str, **options: Unpack[VOptions]
) -> GMWMResult:
    """Two-step efficient GMWM: ``fit_gmwm(wv, model, weights="efficient", **options)``.

    Kept for the callers that name it; :func:`fit_gmwm` with ``weights="efficient"`` is the
    one implementation.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = eg.parse_model("WN(1e-2) + RW(1e-6)").simulate(2**14, rng=np.random.default_rng(1))
    >>> res = eg.fit_efficient(eg.wavelet_variance(x, fs=100.0), "WN + RW")
    >>> res.weights, {k: f"{v:.2e}" for k, v in res.params.items()}
    ('efficient', {'WN.sigma2': '9.91e-03', 'RW.gamma2': '6.78e-07'})
    """
    return fit_gmwm(wv, model, weights="efficient", **options)


@overload
def fit_gmwm(
    wv_or_signal: WaveletVariance | np.ndarray[tuple[int], Any],
    model: Model | Process | str,
    *,
    fs: float | None = ...,
    weights: str | np.ndarray = ...,
    levels: int | None = ...,
    robust: bool = ...,
    eff: float = ...,
    optima: dict[Any, Any] | None = ...,
    fixed: bool = ...,
    polish: bool = ...,
    **options: Unpack[VOptions],
) -> GMWMResult: ...


@overload
def fit_gmwm(
    wv_or_signal: np.ndarray[tuple[int, int], Any],
    model: Model | Process | str,
    *,
    fs: float | None = ...,
    weights: str | np.ndarray = ...,
    levels: int | None = ...,
    robust: bool = ...,
    eff: float = ...,
    optima: dict[Any, Any] | None = ...,
    fixed: bool = ...,
    polish: bool = ...,
    **options: Unpack[VOptions],
) -> list[GMWMResult]: ...


@overload
def fit_gmwm(
    wv_or_signal: Any,
    model: Model | Process | str,
    *,
    fs: float | None = ...,
    weights: str | np.ndarray = ...,
    levels: int | None = ...,
    robust: bool = ...,
    eff: float = ...,
    optima: dict[Any, Any] | None = ...,
    fixed: bool = ...,
    polish: bool = ...,
    **options: Unpack[VOptions],
) -> GMWMResult: ...


def fit_gmwm(
    wv_or_signal: WaveletVariance | np.ndarray | Any,
    model: Model | Process | str,
    *,
    fs: float | None = None,
    weights: str | np.ndarray = "ci",
    levels: int | None = None,
    robust: bool = False,
    eff: float = 0.6,
    optima: dict[Any, Any] | None = None,
    fixed: bool = False,
    polish: bool = False,
    **options: Unpack[VOptions],
) -> GMWMResult | list[GMWMResult]:
    """Fit a latent model by GMWM.

    Parameters
    ----------
    wv_or_signal : WaveletVariance or array_like
        A WV (from :func:`wavelet_variance` or a summary file) or a raw signal, whose WV is then
        computed with ``fs``, ``robust`` and ``eff``. An ``(N, k)`` signal (``k >= 2`` axes,
        e.g. a 3-axis gyroscope) gives one fit per column, as a list (the same model each).
    model : Model, Process or str
        E.g. ``WN() + RW() + 2 * GM()`` or ``"2*GM+WN+RW"``. Values given in the model are
        used as extra starting points.
    fs : float, optional
        Sampling frequency (Hz) of a raw signal; for a WV it must agree with ``wv.fs``.
    weights : {"ci", "identity", "efficient"} or array
        Weighting matrix Omega, see :func:`weight_matrix`; ``"efficient"`` is the two-step
        efficient GMWM (the GMWM paper, Corollary 1): a fit with ``"ci"``, then a refit with
        ``Omega = V^-1``, V the covariance of the WV estimated from the first fit
        (:func:`engine.fit.covariance.wv_cov`).
    levels : int, optional
        Use only the first ``levels`` WV levels.
    robust, eff
        Robust WV settings when a raw signal is given.
    optima : dict, optional
        A dict shared by fits of several models to the same WV (e.g. every candidate of
        :func:`engine.inference.rank_models`): the optimum of each sub-model, searched once and
        reused as the anchor of the larger models (:func:`engine.fit._varpro.nested_search`,
        docs/fitting.md).
        By default each fit searches its own sub-models.
    fixed : bool
        No search: the result of ``model`` with every value given (its objective, implied WV,
        flags), e.g. a model derived from another fit, as the model a ranking selects
        (:func:`engine.inference.actionable`).
    polish : bool
        A refit near a known optimum (the J-test's efficient refit of each candidate a ranking
        has fitted): no grid of correlation times, local searches from the model's values
        and from the sub-models' optima in ``optima`` only, so the fit is at or below each of
        them (docs/fitting.md). Ignored when the model's AR1/GM values are not all given.
    **options
        With ``weights="efficient"``, how V is estimated (:class:`VOptions`: ``v``, ``x``,
        ``B``, ``seed``, ``workers``, ``executor``): by default from the first fit
        (``v="model"``, analytic Gaussian); ``"bootstrap"`` (parametric), ``"data"`` (needs
        ``x``; diagonal) or a given matrix.

    Returns
    -------
    GMWMResult, or list of GMWMResult for an ``(N, k)`` signal

    Raises
    ------
    ModelError
        Unparseable or unidentifiable model.
    FitError
        Data or weights that do not allow a fit (constant signal, too few levels ...).

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = eg.parse_model("WN(1e-2) + RW(1e-6)").simulate(2**14, rng=np.random.default_rng(1))
    >>> res = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0), "WN + RW")
    >>> {k: f"{v:.2e}" for k, v in res.params.items()}
    {'WN.sigma2': '9.90e-03', 'RW.gamma2': '5.70e-07'}
    """
    cols = None if isinstance(wv_or_signal, WaveletVariance) else axis_columns(wv_or_signal)
    if cols is not None:  # one fit per axis
        return [
            fit_gmwm(
                np.ascontiguousarray(cols[:, k]),
                model,
                fs=fs,
                weights=weights,
                levels=levels,
                robust=robust,
                eff=eff,
                **options,
            )
            for k in range(cols.shape[1])
        ]
    t0 = time.perf_counter()
    m = parse_model(model)
    if isinstance(wv_or_signal, WaveletVariance):
        wv = wv_or_signal
        if fs is not None and not math.isclose(fs, wv.fs, rel_tol=1e-9):
            raise FitError(f"fs={fs} Hz disagrees with the WV's fs={wv.fs} Hz")
    else:
        wv = wavelet_variance(wv_or_signal, fs=1.0 if fs is None else fs, robust=robust, eff=eff)
    if levels is not None:
        if not 1 <= levels <= wv.n_levels:
            raise FitError(f"levels={levels} is out of range: the WV has {wv.n_levels} levels")
        wv = wv.truncate(levels)
    efficient = isinstance(weights, str) and weights == "efficient"
    if options and not efficient:
        raise TypeError(
            f"fit_gmwm(): {', '.join(sorted(options))} set how V is estimated, which only "
            "weights='efficient' uses"
        )
    if efficient:
        kw: dict[str, Any] = {"optima": optima, "fixed": fixed, "polish": polish}
        first = fit_gmwm(wv, m, **kw)
        vmat = wv_cov(first, **v_options(options))
        res = fit_gmwm(wv, first.model, weights=inverse_cov(vmat), **kw)
        object.__setattr__(res, "weights", "efficient")
        return res
    m.validate(wv.n_levels)
    if not np.any(wv.variance > 0):
        raise FitError(
            "the wavelet variance is zero at every level (constant signal): "
            "there is no noise to model"
        )
    omega, wname = weight_matrix(wv, weights)
    a = sqrt_weight(omega)
    if fixed:
        if not m.is_set:
            raise FitError("fixed=True needs the value of every parameter of the model")
        prob = NNLSProblem.from_wv(m, wv, a)
        fitted, n_eval, converged = persistent_first(m.processes, wv.fs), 0, True
        method, msg = "fixed", "the given values (no search)"
    elif m.is_linear:
        prob = NNLSProblem.from_wv(m, wv, a)
        fitted, n_eval = fitted_model(prob, np.zeros(0), wv.fs), 1
        converged, method, msg = True, "closed-form", "closed-form non-negative least squares"
    else:
        # starting values from the user's model, if any
        start = start_coordinates(m, wv.fs)
        extra = [] if start is None else [start]
        # the search anchored at every sub-model's optimum (the degenerate corners)
        key = (wv.tau_samples.tobytes(), wv.variance.tobytes(), omega.tobytes())
        cache = optima.setdefault(key, {}) if optima is not None else {}
        _, u, converged, prob, n_eval = nested_search(
            m,
            lambda sub: NNLSProblem.from_wv(sub, wv, a),
            cache,
            extra,
            keep=3,
            polish=polish and bool(extra),
        )
        fitted = fitted_model(prob, u, wv.fs)
        method, msg = "grid+nelder-mead", search_message(converged)
    fields = fitted_fields(fitted, wv, prob.tc_min, prob.tc_max)
    resid = wv.variance - fields["implied"]
    return GMWMResult(
        **fields,
        omega=omega,
        weights=wname,
        objective=float(resid @ omega @ resid),
        converged=converged,
        n_evaluations=n_eval,
        method=method,
        message=msg,
        elapsed_s=time.perf_counter() - t0,
    )
