"""The asymptotic theory of a GMWM fit: the model-implied covariance of the WV, the Jacobian of
the implied WV in the unconstrained coordinates, and the sandwich intervals.

It needs no fitting, and the fit needs it (:meth:`engine.fit.GMWMResult.conf_int`, the
efficient weights of :mod:`engine.fit.covariance`), so it sits in the fitting layer;
:mod:`engine.inference` (intervals, J-test, selection) and :mod:`engine.formats` (the
projection's intervals) build on it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..fit.result import FitError
from ..models import FROM_UNCONSTRAINED, TO_UNCONSTRAINED, Model, Process
from ..wv import WaveletVariance
from ._closed_form import closed_form_c

__all__ = [
    "spectral_density",
    "frequency_grid",
    "wv_cov_model",
    "free_params",
    "jacobian",
    "param_cov",
    "asymptotic_bounds",
    "delta_bounds",
]


def spectral_density(p: Process, f: np.ndarray, fs: float) -> np.ndarray:
    """Two-sided spectral density on f in cycles/sample (0 < f <= 1/2); RW generalised.

    The process's own :meth:`engine.models.Process.psd`.
    """
    return p.psd(f, fs)


def frequency_grid(levels: int, model: Model, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on (0, 1/2] and weights of the periodic trapezoid rule for an even integrand (the
    node f = 0, weight ``1 / (2F)``, is left out: add it where the integrand is not 0 there).

    With ``2F`` equispaced nodes on a period, the rule is exact for trigonometric polynomials
    of degree below ``2F``: the Haar gains of levels j, k have degree ``2^j + 2^k``, so
    ``F = 2^(J+1)`` integrates white-noise-like terms exactly; AR1/GM terms need ``F`` above a
    few correlation times (the rule then equals the lag-domain sum up to a negligible wrap).
    """
    need = 2 ** (levels + 1)
    for p in model.processes:
        ar = p.psd_terms(fs).ar
        if ar is not None and 0 < ar[0] < 1:
            # a few correlation times, but no more than 8x the longest scale: beyond the
            # series' span a near-unit-root AR1 acts as a random walk
            need = max(need, int(min(-16.0 / math.log(ar[0]), 2.0 ** (levels + 4))))
    f_nodes = 1 << int(math.ceil(math.log2(need)))
    f = np.arange(1, f_nodes + 1) / (2.0 * f_nodes)
    w = np.full(f_nodes, 1.0 / f_nodes)  # 2 / (2F): the mirrored node counts twice
    w[-1] = 0.5 / f_nodes  # f = 1/2 is its own mirror image
    return f, w


def wv_cov_model(model: Model, wv: WaveletVariance) -> np.ndarray:
    """Asymptotic Gaussian covariance of the WV implied by a model (full J x J matrix).

    ``Cov(nu_j, nu_k) = (2 / max(M_j, M_k)) int_{-1/2}^{1/2} |H_j|^2 |H_k|^2 S^2 df``, in closed
    form (:mod:`engine.fit._closed_form`: 25 lags of one generalised autocovariance per
    pair of levels, exact integer sums for QN/WN/RW, decimal arithmetic for AR1/GM), so the
    cost does not grow with the series: about 1 ms for 22 levels without AR1/GM terms, 10-20 ms
    per AR1/GM term.

    Parameters
    ----------
    model : Model
        Every parameter set (e.g. ``result.model``).
    wv : WaveletVariance
        Gives the levels, ``M_j`` and fs.
    """
    if not model.is_set:
        raise FitError("wv_cov_model needs a model with every value set (a fitted model)")
    # S = q2 x + sigma2 + gamma2 / x + sum s / y(phi): the processes' spectral pieces
    poly = {1: 0.0, 0: 0.0, -1: 0.0}
    ar: list[tuple[float, float]] = []
    for p in model.processes:
        if p.linear_coef() == 0:
            continue  # fitted at zero: contributes nothing (its phi/beta is arbitrary)
        terms = p.psd_terms(wv.fs)  # a drift has none: no first-order contribution
        for power, coef in terms.poly.items():
            if power not in poly:  # pragma: no cover - no process has such a spectrum yet
                raise TypeError(
                    f"wv_cov_model has no closed form for {p.code}'s spectral term x^{power}"
                )
            poly[power] += coef
        if terms.ar is not None:
            ar.append(terms.ar)
    c = closed_form_c(wv.n_levels, poly[1], poly[0], poly[-1], ar)
    m_j = wv.n_coef.astype(float)
    return 2.0 * c / np.maximum.outer(m_j, m_j)


def free_params(res: Any) -> list[tuple[int, str]]:
    """(process index, parameter name) of the free parameters: not on a boundary, and not
    belonging to an AR1/GM whose variance is 0 (its phi/beta is then not identified)."""
    out = []
    for i, (lab, p) in enumerate(zip(res.model.labels, res.model.processes, strict=True)):
        if p.linear_coef() <= 0:
            continue
        for name in p.param_names:
            if f"{lab}.{name}" not in res.at_bound:
                out.append((i, name))
    return out


def _set(model: Model, free: list[tuple[int, str]], u: np.ndarray) -> Model:
    """The model with the free parameters set from unconstrained coordinates ``u``."""
    procs = list(model.processes)
    for (i, name), ui in zip(free, u, strict=True):
        procs[i] = procs[i].with_values(**{name: FROM_UNCONSTRAINED[name](float(ui))})
    return Model(tuple(procs))


def _u0(model: Model, free: list[tuple[int, str]]) -> np.ndarray:
    """Unconstrained coordinates of the free parameters."""
    return np.array([TO_UNCONSTRAINED[n](float(getattr(model.processes[i], n))) for i, n in free])


def jacobian(res: Any, free: list[tuple[int, str]] | None = None) -> np.ndarray:
    """d nu / d u (J x p) at the estimate, u the unconstrained coordinates of free parameters."""
    free = free_params(res) if free is None else free
    u0 = _u0(res.model, free)
    tau = res.wv.tau_samples
    jac = np.empty((tau.size, len(free)))
    for k in range(len(free)):
        h = 1e-5 * max(1.0, abs(u0[k]))
        up, dn = u0.copy(), u0.copy()
        up[k] += h
        dn[k] -= h
        jac[:, k] = (
            _set(res.model, free, up).wv(tau, res.fs) - _set(res.model, free, dn).wv(tau, res.fs)
        ) / (2 * h)
    return jac


def param_cov(res: Any, vmat: np.ndarray, free: list[tuple[int, str]] | None = None) -> np.ndarray:
    """The sandwich covariance ``(A' W A)^-1 A' W V W A (A' W A)^-1`` of the free parameters
    (:func:`free_params`, in that order) in their unconstrained coordinates (log of variances
    and beta, atanh of phi, omega as is).

    Parameters
    ----------
    res : GMWMResult
        The fit (model, WV, Omega, at_bound).
    vmat : ndarray (J, J)
        Covariance of the WV.
    free : list of (process index, parameter name), optional
        Default :func:`free_params` of ``res``.

    Returns
    -------
    ndarray (p, p)
    """
    free = free_params(res) if free is None else free
    a = jacobian(res, free)
    w = res.omega
    bread = _equilibrated_pinv(a.T @ w @ a)
    return bread @ a.T @ w @ vmat @ w @ a @ bread


def _equilibrated_pinv(m: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a symmetric information matrix after scaling it to a unit diagonal.

    A parameter that the data barely inform (a random walk in a short log: its information is
    1e-20 of the white noise's) is a badly *scaled* direction, not a missing one: a plain
    ``pinv`` drops it below its relative cutoff and reports a variance of 0. Scaled, its
    variance comes out as large as it is. Parameters with no information at all (a zero
    diagonal) keep ``pinv``'s 0.
    """
    d = np.diagonal(m).copy()
    s = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 1.0)
    return s[:, None] * np.linalg.pinv(s[:, None] * m * s[None, :]) * s[None, :]


def asymptotic_bounds(res: Any, vmat: np.ndarray, level: float) -> list[tuple[float, float]]:
    """Wald bounds of every parameter (in ``res.param_records`` order) at two-sided ``level``.

    The sandwich ``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2)
    in the unconstrained coordinates (log of variances and beta, atanh of phi, omega as is),
    mapped back, so the bounds respect the parameter space. A parameter on a boundary (or of
    an AR1/GM with zero variance) gets ``nan`` bounds; a drift's bounds are of ``|omega|``.

    Parameters
    ----------
    res : GMWMResult
        The fit (model, WV, Omega, at_bound).
    vmat : ndarray (J, J)
        Covariance of the WV.
    level : float
        Two-sided coverage in (0, 1).
    """
    from scipy import stats

    free = free_params(res)
    cov = param_cov(res, vmat, free)
    se = np.sqrt(np.maximum(np.diagonal(cov), 0.0))
    z = stats.norm.ppf(0.5 + level / 2)
    u0 = _u0(res.model, free)
    bounds = {}
    for k, (i, name) in enumerate(free):
        lo = FROM_UNCONSTRAINED[name](u0[k] - z * se[k])
        hi = FROM_UNCONSTRAINED[name](u0[k] + z * se[k])
        bounds[(res.model.labels[i], name)] = (min(lo, hi), max(lo, hi))
    out = []
    for r in res.param_records:
        lo, hi = bounds.get((r.label, r.name), (math.nan, math.nan))
        if r.name == "omega":  # the sign of a drift is not identified: report |omega|
            lo, hi = (max(lo, 0.0), hi) if r.value >= 0 else (lo, hi)
        out.append((float(lo), float(hi)))
    return out


def delta_bounds(
    res: Any,
    fns: Sequence[Callable[[Model, float], float]],
    level: float,
    *,
    vmat: np.ndarray | None = None,
) -> list[tuple[float, float]]:
    """Delta-method bounds of positive functions of a fitted model, on the log scale.

    For each ``g = fn(model, fs)``: ``se = sqrt(d' C d)`` with ``d`` the central-difference
    gradient of ``g`` in the unconstrained coordinates of the free parameters
    (:func:`free_params`) and ``C`` their sandwich covariance (:func:`param_cov`); the bounds
    are ``g exp(-/+ z se / g)`` (positive, like the parameters' own).

    Parameters
    ----------
    res : GMWMResult
        The fit (model, WV, Omega, at_bound).
    fns : sequence of callables ``(model, fs) -> float``
        The quantities.
    level : float
        Two-sided coverage in (0, 1).
    vmat : ndarray (J, J), optional
        Covariance of the WV (default :func:`wv_cov_model` of the fit).

    Returns
    -------
    list of (low, high)
        NaN bounds for a quantity that is not positive or that depends on no free parameter
        (all its terms on a bound).
    """
    from scipy import stats

    free = free_params(res)
    if not free:
        return [(math.nan, math.nan)] * len(fns)
    try:
        cov = param_cov(res, wv_cov_model(res.model, res.wv) if vmat is None else vmat, free)
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - degenerate V
        return [(math.nan, math.nan)] * len(fns)
    z = float(stats.norm.ppf(0.5 + level / 2))
    u0 = _u0(res.model, free)
    steps = [1e-5 * max(1.0, abs(u)) for u in u0]
    shifted = []
    for k, h in enumerate(steps):
        up, dn = u0.copy(), u0.copy()
        up[k] += h
        dn[k] -= h
        shifted.append((_set(res.model, free, up), _set(res.model, free, dn)))
    out = []
    for fn in fns:
        g0 = fn(res.model, res.fs)
        if not (math.isfinite(g0) and g0 > 0):
            out.append((math.nan, math.nan))
            continue
        d = np.array(
            [
                (fn(a, res.fs) - fn(b, res.fs)) / (2 * h)
                for (a, b), h in zip(shifted, steps, strict=True)
            ]
        )
        var = float(d @ cov @ d)
        if not (math.isfinite(var) and var > 0):
            out.append((math.nan, math.nan))
            continue
        s = min(math.sqrt(var) / g0, 700.0 / z)  # beyond: an interval of no information
        out.append((g0 * math.exp(-z * s), g0 * math.exp(z * s)))
    return out
