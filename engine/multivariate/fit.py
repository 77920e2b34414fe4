"""Fitting a multivariate latent model: :func:`fit_mgmwm` and :func:`moment_covariance`.

MGMWM (the multivariate paper, eq. 8). All WV and WCCV moments, the upper triangle of the
(J, k, k) array including the diagonal, are stacked and matched:
``theta_hat = argmin sum_{p <= q, j} w_pqj (nu_hat_pqj - nu_pqj(theta))^2``, with by default
``w = 1 / (ci_high - ci_low)^2`` (the univariate ``"ci"`` weights; the diagonal uses the same
eta3 intervals, so a model without shared processes reproduces the univariate fits), or the
two-step efficient ``Omega = V^-1`` of :func:`moment_covariance`.

The minimum is reached by variable projection: the inner problem (variances and covariance
matrices, a convex least squares over non-negative orthants and PSD cones) is solved exactly
(:mod:`engine.multivariate._cone`), the non-linear parameters (AR1, GM, MA1) by
:func:`.problem.search`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..fit import FitError
from ..fit._varpro import sub_sample_warnings
from ..models import ModelError
from ..wv import WVMatrix, wv_matrix
from .moments import moment_covariance
from .problem import MProblem, boundary_estimates, fitted_model, search
from .result import MGMWMResult
from .spec import MultiModel

__all__ = ["fit_mgmwm", "as_wvm"]


def _weights(wvm: WVMatrix, weights: str | np.ndarray) -> tuple[np.ndarray, str]:
    j, k = wvm.n_levels, wvm.k
    for p, c in enumerate(wvm.channels):
        if not np.any(wvm.values[:, p, p] > 0):
            raise FitError(
                f"channel {c} is constant (its WV is 0 at every level): there is "
                "no noise to model; drop it from the channels"
            )
    if isinstance(weights, str):
        if weights == "identity":
            return np.ones((j, k, k)), "identity"
        if weights != "ci":
            raise FitError(
                f"unknown weights {weights!r}: use 'ci', 'identity', 'efficient' or a "
                f"({j}, {k}, {k}) array"
            )
        width = wvm.ci_high - wvm.ci_low
        ok = np.isfinite(width) & (width > 0)
        if not np.all(ok):
            lv, p, q = (int(v) for v in np.argwhere(~ok)[0])
            what = (
                f"the WV of {wvm.channels[p]}"
                if p == q
                else f"the WCCV of {wvm.channels[p]} and {wvm.channels[q]}"
            )
            raise FitError(
                f"the interval of {what} at level {lv + 1} is empty or not finite, "
                "so weights='ci' is undefined; use weights='identity'"
            )
        return 1.0 / width**2, "ci"
    w = np.asarray(weights, dtype=float)
    if w.shape != (j, k, k):
        raise FitError(
            f"the weights have shape {w.shape}; give a ({j}, {k}, {k}) array, one "
            "non-negative weight per moment"
        )
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise FitError("the weights must be finite and non-negative")
    if not np.allclose(w, np.transpose(w, (0, 2, 1))):
        raise FitError("the weights must be symmetric in the two channel indices")
    return w, "user"


def as_wvm(data: Any, channels: Sequence[str], fs: float | None, levels: int | None) -> WVMatrix:
    if isinstance(data, WVMatrix):
        missing = [c for c in channels if c not in data.channels]
        if missing:
            raise FitError(
                f"the model's channel(s) {', '.join(missing)} are not in the WV "
                f"matrix (channels: {', '.join(data.channels)})"
            )
        if fs is not None and not math.isclose(fs, data.fs, rel_tol=1e-9):
            raise FitError(f"fs={fs} Hz disagrees with the WV matrix's fs={data.fs} Hz")
        wvm = data.select(channels) if tuple(channels) != data.channels else data
    else:
        if isinstance(data, np.ndarray) and data.ndim == 2:
            if data.shape[1] != len(channels):
                raise FitError(
                    f"the data has {data.shape[1]} columns but the model has "
                    f"{len(channels)} channels ({', '.join(channels)})"
                )
            data = dict(zip(channels, data.T, strict=True))
        try:
            wvm = wv_matrix(data, channels=list(channels), fs=fs)
        except KeyError as e:
            raise FitError(str(e.args[0]) if e.args else str(e)) from None
    if levels is not None:
        if not 1 <= levels <= wvm.n_levels:
            raise FitError(
                f"levels={levels} is out of range: the WV matrix has {wvm.n_levels} levels"
            )
        wvm = wvm.truncate(levels)
    return wvm


def _fitted_fields(
    fitted: MultiModel, wvm: WVMatrix, prob: MProblem, u: np.ndarray
) -> dict[str, Any]:
    """The fields of the result that follow from the fitted model: ``model``, ``wvm``,
    ``components`` (implied WV matrices per process), ``implied`` (their sum), ``at_bound``
    and ``warnings`` (AR1/GM terms faster than one sample, labelled by channel)."""
    comps = fitted.components(wvm.tau_samples, wvm.fs)
    warnings = [
        w
        for p, c in enumerate(fitted.channels)
        for w in sub_sample_warnings(
            fitted.models[c], wvm.fs, wvm.units[p] if p < len(wvm.units) else "", f"{c}."
        )
    ]
    return {
        "model": fitted,
        "wvm": wvm,
        "components": comps,
        "implied": np.sum(np.array(list(comps.values())), axis=0),
        "at_bound": boundary_estimates(fitted, prob, u),
        "warnings": warnings,
    }


def fit_mgmwm(
    data: WVMatrix | Any,
    model: MultiModel,
    *,
    weights: str | np.ndarray = "ci",
    levels: int | None = None,
    fs: float | None = None,
) -> MGMWMResult:
    """Fit a multivariate latent model by the multivariate GMWM.

    Parameters
    ----------
    data : WVMatrix, ndarray (N, k), mapping of name to series, or ImuLog
        The empirical WV/WCCV matrix (from :func:`engine.wv.wv_matrix`), or the raw channels
        (the matrix is computed for the model's channels, in the model's order).
    model : MultiModel
        Structure (values, if any, are extra starting points).
    weights : {"ci", "identity", "efficient"} or ndarray (J, k, k)
        Moment weights: ``1 / (ci_high - ci_low)^2`` (default), ones, given diagonal weights,
        or ``"efficient"``: two-step, ``Omega = V^-1`` with V the model-implied Gaussian
        covariance of all stacked moments (:func:`moment_covariance`) at the ``"ci"`` fit
        (the GMWM paper, Corollary 1; it lets the WCCV inform the WV parameters).
    levels : int, optional
        Use only the first ``levels`` levels.
    fs : float, optional
        Sampling frequency of raw data (Hz).

    Returns
    -------
    MGMWMResult

    Raises
    ------
    ModelError
        Bad model structure (see :class:`MultiModel`) or more parameters than moments.
    FitError
        Missing or constant channels, empty intervals, bad weights.

    Examples
    --------
    Two channels with their own white noise and a random walk they share (correlation 0.8):

    >>> import numpy as np
    >>> import engine as eg
    >>> truth = eg.MultiModel(
    ...     ["a", "b"], "WN(1.0)+RW(1e-3)", shared=["RW"],
    ...     cov={"RW": [[1e-3, 8e-4], [8e-4, 1e-3]]},
    ... )
    >>> x = truth.simulate(2**14, rng=np.random.default_rng(2))
    >>> res = eg.fit_mgmwm(x, eg.MultiModel(["a", "b"], "WN+RW", shared=["RW"]))
    >>> {k: f"{v:.3g}" for k, v in res.params.items()}  # doctest: +NORMALIZE_WHITESPACE
    {'RW.cov[a,a]': '0.000987', 'RW.cov[a,b]': '0.000813', 'RW.cov[b,b]': '0.00105',
     'a.WN.sigma2': '0.992', 'b.WN.sigma2': '0.99'}
    >>> f"{res.correlation('RW')[0, 1]:.2f}"
    '0.80'
    """
    t0 = time.perf_counter()
    if not isinstance(model, MultiModel):
        raise ModelError(
            f"model must be a MultiModel, got {type(model).__name__}; build one "
            "with MultiModel(channels, 'WN+RW', shared=['RW'])"
        )
    wvm = as_wvm(data, model.channels, fs, levels)
    efficient = isinstance(weights, str) and weights == "efficient"
    w, wname = _weights(wvm, "ci" if efficient else weights)
    n_par = sum(
        len(t.proto.param_names)
        if not t.shared
        else (len(t.chans) if t.diagonal else len(t.chans) * (len(t.chans) + 1) // 2)
        + (1 if t.nonlinear else 0)
        for t in model.terms()
    )
    n_mom = wvm.n_levels * wvm.k * (wvm.k + 1) // 2
    if n_par > n_mom:
        raise ModelError(
            f"the model has {n_par} parameters but there are only {n_mom} "
            "moments: use more levels or a smaller model"
        )
    for c in model.channels:
        try:
            model.models[c].validate(wvm.n_levels)
        except ModelError as e:
            raise ModelError(f"channel {c}: {e}") from None
    if not efficient:
        return _fit(wvm, model, w, None, wname, t0)
    first = _fit(wvm, model, w, None, "ci", t0)
    from ..fit.asymptotic import inverse_cov

    omega = inverse_cov(moment_covariance(first.model, wvm))
    return _fit(wvm, first.model, w, omega, "efficient", t0)


def _fit(
    wvm: WVMatrix, model: MultiModel, w: np.ndarray, omega: np.ndarray | None, wname: str, t0: float
) -> MGMWMResult:
    prob = MProblem(model, wvm, w, omega)
    if not prob.slots:
        u = np.zeros(0)
        converged, method, msg = True, "closed-form", "exact (convex inner problem)"
    else:
        u, converged = search(prob, model, wvm, w)
        method = "profiled nelder-mead"
        msg = (
            "converged"
            if converged
            else "the local search stopped before meeting its "
            "tolerance; the estimate may be slightly above the minimum"
        )
    f, h, s, coupled = prob.solve(u)
    fields = _fitted_fields(fitted_model(model, prob, u, h, s), wvm, prob, u)
    implied = fields["implied"]
    iu = np.triu_indices(wvm.k)
    if omega is None:
        resid = (wvm.values - implied)[:, iu[0], iu[1]]
        objective = float(np.sum(w[:, iu[0], iu[1]] * resid**2))
        omega = np.diag(np.concatenate([w[:, p, q] for p, q in prob.pairs]))
    else:
        r = prob.y - np.concatenate([implied[:, p, q] for p, q in prob.pairs])
        objective = float(r @ omega @ r)
    return MGMWMResult(
        **fields,
        weights=wname,
        objective=objective,
        converged=converged,
        psd_active=coupled,
        n_evaluations=prob.n_eval,
        method=method,
        message=msg,
        elapsed_s=time.perf_counter() - t0,
        omega=omega,
        n_inner=prob.n_inner,
    )
