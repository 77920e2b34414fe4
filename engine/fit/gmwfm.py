"""GMWFM: the generalized method of wavelet functional moments, and the ARMAV.

``theta_hat = argmin ||f(nu_hat) - f(nu(theta))||^2_Omega`` with ``f`` applied level by level
(the GMWM paper, eq. 1). ``f = identity`` is the GMWM; ``f = log10`` is the ARMAV (the
autonomous regression method for the Allan variance, Jurado, Schubert Kabban & Raquet 2019).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._optim import least_squares
from ..models import Model, Process, parse_model
from ..wv import WaveletVariance
from ._varpro import (
    NNLSProblem,
    fitted_fields,
    persistent_first,
    sqrt_weight,
)
from .estimate import MethodEstimate
from .gmwm import fit_gmwm, weight_matrix
from .result import FitError, OneWVFit, UnivariateFit

__all__ = ["fit_gmwfm", "fit_armav", "GMWFMResult"]


# -------------------------------------------------------------------------------------------
_F: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "identity": lambda v: v,
    "log10": np.log10,
    "log": np.log,
    "sqrt": np.sqrt,
}
_U_LO, _U_HI = -70.0, 8.0  # bounds of the log linear coefficients (relative to their scale)
_EDGE = math.log(1.01)  # how far inside its range a start's non-linear coordinate is put


@dataclass(frozen=True, eq=False, kw_only=True)
class GMWFMResult(OneWVFit, UnivariateFit):
    """Result of :func:`fit_gmwfm` / :func:`fit_armav` (the fields of
    :class:`engine.fit.result.FitResult`, the objective in f-space, plus:).

    Attributes
    ----------
    wv : WaveletVariance
        The empirical WV.
    f : str
        Name of the function matched (``"log10"``, ``"sqrt"`` ...).
    estimator : str
        ``"ARMAV"`` or ``"GMWFM(<f>)"``: the name in comparison tables.
    implied : ndarray (J,)
        Implied WV at the empirical scales.
    components : dict[str, ndarray]
        Implied WV of each process, summing to ``implied``.
    notes : tuple of str
        How the estimate was made (f, weights, starts, evaluations, terms at 0).
    """

    wv: WaveletVariance
    f: str
    estimator: str
    implied: np.ndarray
    components: dict[str, np.ndarray]
    notes: tuple[str, ...] = ()

    def _summary_head(self) -> list[str]:
        w = self.wv
        return [
            f"{self.estimator} fit of {self.model.spec()}",
            f"  data: N = {w.n} samples, fs = {w.fs:g} Hz, {w.n_levels} WV levels",
            f"  f = {self.f}; weights: {self.weights}; objective = {self.objective:.6g}; "
            f"{self.method}, {self.n_evaluations} evaluations, {1e3 * self.elapsed_s:.1f} ms",
        ]

    def _summary_tail(self) -> list[str]:
        return [""] + [f"  note: {s}" for s in self.notes] if self.notes else []

    def _dict_extra(self) -> dict[str, Any]:
        return {
            "f": self.f,
            "estimator": self.estimator,
            "n": int(self.wv.n),
            "implied": [float(v) for v in self.implied],
            "components": {k: [float(x) for x in v] for k, v in self.components.items()},
            "notes": list(self.notes),
        }

    def as_estimate(self) -> MethodEstimate:
        """The estimate in the common form of the comparison tables (:mod:`engine.fit.estimate`)."""
        return MethodEstimate(
            method=self.estimator,
            model=self.model,
            params={k: v for k, v in self.model.values().items() if v is not None},  # all set
            tau_samples=np.asarray(self.wv.tau_samples),
            implied=self.implied,
            components=self.components,
            fs=float(self.wv.fs),
            unit=self.wv.unit,
            objective=float(self.objective),
            notes=self.notes,
            details={
                "f": self.f,
                "weights": self.weights,
                "at_bound": list(self.at_bound),
                "converged": bool(self.converged),
            },
        )


def _resolve_f(f: str | Callable[[np.ndarray], np.ndarray]) -> tuple[str, Callable]:
    if isinstance(f, str):
        if f not in _F:
            raise FitError(f"unknown f={f!r}: use one of {', '.join(_F)} or a callable")
        return f, _F[f]
    if callable(f):
        return getattr(f, "__name__", "f"), f
    raise FitError(f"f must be a name or a callable, got {type(f).__name__}")


def _f_weights(
    wv: WaveletVariance, fun: Callable, weights: str | np.ndarray, fname: str
) -> tuple[np.ndarray, str]:
    """Omega in f-space: ``"ci"`` is ``diag(1 / (f(ci_high) - f(ci_low))^2)``."""
    if isinstance(weights, str) and weights == "ci":
        with np.errstate(all="ignore"):
            width = np.asarray(fun(wv.ci_high), float) - np.asarray(fun(wv.ci_low), float)
        if np.any(~np.isfinite(width)) or np.any(width <= 0):
            raise FitError(
                f"the interval of {fname}(WV) is empty or not finite at some level, "
                "so weights='ci' is undefined; use another weighting"
            )
        return np.diag(1.0 / width**2), "ci"
    return weight_matrix(wv, weights)


def _grid_starts(
    prob: NNLSProblem,
    m: Model,
    wv: WaveletVariance,
    a: np.ndarray,
    fy: np.ndarray,
    fun: Callable,
    start: Callable[[np.ndarray, np.ndarray], np.ndarray],
    keep: int = 8,
) -> list[np.ndarray]:
    """Starts from the core's grid of search coordinates: for each candidate the variances of
    the linearised problem (NNLS with the weights ``A diag(f'(nu_hat))``, the first-order
    expansion of ``f`` at the data), scored by the exact f-space objective."""
    nu = wv.variance
    with np.errstate(all="ignore"):
        fp = (np.asarray(fun(nu * (1 + 1e-6)), float) - np.asarray(fun(nu * (1 - 1e-6)), float)) / (
            2e-6 * nu
        )
    if not np.all(np.isfinite(fp)):
        return []
    lin = NNLSProblem.from_wv(m, wv, a * fp[None, :])
    scored = []
    for u in prob.candidates():
        _, h, x = lin.solve(lin.phis_of(u))
        with np.errstate(all="ignore"):
            r = a @ (fy - np.asarray(fun(np.maximum(x @ h, 1e-300)), float))
        cost = float(r @ r)
        if np.isfinite(cost):
            scored.append((cost, u, h))
    scored.sort(key=lambda t: t[0])
    return [start(h, np.asarray(u, float)) for _, u, h in scored[:keep]]


def fit_gmwfm(
    wv: WaveletVariance,
    model: Model | Process | str,
    *,
    f: str | Callable[[np.ndarray], np.ndarray] = "log10",
    weights: str | np.ndarray = "ci",
    levels: int | None = None,
    method: str | None = None,
) -> GMWFMResult:
    """Generalized method of wavelet functional moments (the GMWM paper, eq. 1).

    ``theta_hat = argmin ||f(nu_hat) - f(nu(theta))||^2_Omega`` with ``f`` applied level by
    level. ``f = identity`` is the GMWM (delegated to :func:`engine.fit_gmwm`, exact);
    ``f = log10`` is the ARMAV (see :func:`fit_armav`).

    Parameters
    ----------
    wv : WaveletVariance
        The empirical WV (classical: the identity ``AVAR = 2 nu2`` makes a fit on the octave
        AVAR the same fit, ``log10`` only adding the constant ``log10 2`` to both sides).
    model : Model, Process or str
        Any engine model (QN, WN, RW, DR, AR1, GM, MA1).
    f : {"log10", "log", "sqrt", "identity"} or callable
        The function of the WV to match; a callable must be vectorised, continuous and
        strictly increasing on the positive reals.
    weights : {"ci", "identity"} or array
        ``"ci"``: ``diag(1 / (f(ci_high) - f(ci_low))^2)``, the inverse squared width of the
        WV's eta3 interval carried through ``f`` (for ``f = identity`` the GMWM's default
        weights; for ``log10`` a width that depends only on the level's degrees of freedom,
        so each level weighs in proportion to its number of independent Haar coefficients).
        ``"identity"``: unweighted; or a (J,) vector / (J, J) matrix.
    levels : int, optional
        Use only the first ``levels`` levels.
    method : str, optional
        Name given to the result (default ``"GMWFM(<f>)"``).

    Returns
    -------
    GMWFMResult

    Raises
    ------
    FitError
        The WV is zero at some level (``f`` undefined), bad weights, or the model has more
        parameters than levels.

    Notes
    -----
    Each process contributes a non-negative coefficient ``h`` times its WV shape (and AR1, GM
    and MA1 a non-linear parameter). The search space is ``log h`` (scaled per process; a
    coefficient whose curve stays below 1e-9 of the fitted WV at every level is reported as
    exactly 0, the objective being flat there) and each non-linear term's search coordinate as
    its class declares it (:meth:`engine.models.Process.search_nl`: AR1, GM the log
    correlation time in samples, so an AR1 coefficient is searched in (0, 1); MA1 atanh theta),
    within its declared range; the fit runs bounded least squares
    (:func:`engine._optim.least_squares`, a projected Levenberg-Marquardt) from the GMWM
    estimate and from an equal-share start (and, with non-linear terms, from coordinates
    shifted by ``log 4``: correlation times 4x shorter and longer, and from the best points of
    the fit's grid) and keeps the lowest objective.
    """
    t0 = time.perf_counter()
    fname, fun = _resolve_f(f)
    name = method or f"GMWFM({fname})"
    m = parse_model(model)
    if levels is not None:
        if not 1 <= levels <= wv.n_levels:
            raise FitError(f"levels={levels} is out of range: the WV has {wv.n_levels} levels")
        wv = wv.truncate(levels)
    m.validate(wv.n_levels)
    if fname == "identity" and f == "identity":
        res = fit_gmwm(wv, m, weights=weights)
        notes = [f"GMWM, weights {res.weights}, {res.method}"]
        if res.at_bound:
            notes.append(f"at a bound: {', '.join(res.at_bound)}")
        return GMWFMResult(
            model=res.model,
            weights=res.weights,
            omega=res.omega,
            objective=res.objective,
            converged=res.converged,
            at_bound=list(res.at_bound),
            warnings=list(res.warnings),
            n_evaluations=res.n_evaluations,
            method=res.method,
            message=res.message,
            elapsed_s=time.perf_counter() - t0,
            wv=wv,
            f=fname,
            estimator=name,
            implied=res.implied,
            components=res.components,
            notes=tuple(notes),
        )
    if np.any(~(wv.variance > 0)):
        bad = int(np.flatnonzero(~(wv.variance > 0))[0]) + 1
        raise FitError(f"the WV is zero at level {bad}, so {fname}(WV) is undefined")
    with np.errstate(all="ignore"):
        fy = np.asarray(fun(wv.variance), dtype=float)
    if fy.shape != wv.variance.shape or not np.all(np.isfinite(fy)):
        raise FitError(f"{fname}(WV) is not finite at every level")
    omega, wname = _f_weights(wv, fun, weights, fname)
    a = sqrt_weight(omega)
    # the non-linear terms move in the coordinates their classes declare (AR1, GM: log
    # correlation time in samples; MA1: atanh theta), within their declared ranges
    prob = NNLSProblem.from_wv(m, wv, np.eye(wv.n_levels))
    p, k = prob.p, prob.k
    lo_u = np.broadcast_to(np.asarray(prob.lo, float), (k,))
    hi_u = np.broadcast_to(np.asarray(prob.hi, float), (k,))

    # starting point: the GMWM estimate (weights "ci") in the problem's process order
    try:
        g = fit_gmwm(wv, m, weights="ci")
        gm_model = g.model
    except FitError:
        gm_model = None

    def coord_of(pr: Process) -> float:
        """A fitted term's search coordinate (0 when its value is out of the search's reach)."""
        v = pr.nl_value(wv.fs)
        u = None if v is None else pr.search_of_nl(v)
        return u if u is not None and math.isfinite(u) else 0.0

    h0 = np.zeros(p)
    u0 = np.zeros(k)
    if gm_model is not None:
        # match processes by kind (AR1/GM most persistent first in both)
        pool = {
            c: [q for q in gm_model.processes if q.code == c]
            for c in {q.code for q in gm_model.processes}
        }
        taken: dict[str, int] = {}
        for i in range(p):
            c = m.processes[i].code
            j = taken.get(c, 0)
            q = pool[c][j]
            taken[c] = j + 1
            h0[i] = q.linear_coef()
            if q.nonlinear is not None:
                u0[prob.nl_idx.index(i)] = coord_of(q)
    if k:  # a hundredth of a log correlation time inside its range (log 1.01)
        u0 = np.clip(u0, lo_u + _EDGE, hi_u - _EDGE)
    x0 = prob.design(prob.phis_of(u0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(x0 > 0, wv.variance[:, None] / np.where(x0 > 0, x0, 1.0), np.inf)
    scale = np.min(ratio, axis=0)  # the largest coefficient whose curve stays below the data
    scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)

    def unpack(z: np.ndarray) -> tuple[np.ndarray, tuple[float, ...]]:
        return scale * np.exp(z[:p]), prob.phis_of(z[p:])

    def resid(z: np.ndarray) -> np.ndarray:
        h, phis = unpack(z)
        nu = prob.design(phis) @ h
        with np.errstate(all="ignore"):
            r = fy - np.asarray(fun(np.maximum(nu, 1e-300)), float)
        return a @ np.where(np.isfinite(r), r, 1e3)

    def start(h: np.ndarray, u: np.ndarray) -> np.ndarray:
        v = np.log(np.maximum(h, 1e-30 * scale) / scale)
        return np.concatenate(
            [np.clip(v, _U_LO + 1, _U_HI - 1), np.clip(u, lo_u + 1e-6, hi_u - 1e-6)]
        )

    starts = [start(np.full(p, 1.0 / p) * scale, u0)]
    if gm_model is not None:
        starts.insert(0, start(h0, u0))
        if k:  # correlation times 4x longer and shorter (a shift of log 4 in any coordinate)
            starts += [start(h0, u0 + math.log(4.0)), start(h0, u0 - math.log(4.0))]
    if k:
        starts += _grid_starts(prob, m, wv, a, fy, fun, start)
    lb = np.concatenate([np.full(p, _U_LO), lo_u])
    ub = np.concatenate([np.full(p, _U_HI), hi_u])
    best = None
    n_eval = 0
    for z0 in starts:
        z0 = np.clip(z0, lb + 1e-9, ub - 1e-9)
        r = least_squares(resid, z0, lb, ub, ftol=1e-12, xtol=1e-10, max_nfev=2000)
        n_eval += r.nfev
        if best is None or r.cost < best.cost:
            best = r
    assert best is not None
    z = best.x.copy()
    h, phis = unpack(z)
    # a coefficient whose curve is below 1e-9 of the fitted WV at every level (or at its lower
    # bound) is estimated as exactly 0: the objective is flat there
    x_fit = prob.design(phis)
    nu_fit = x_fit @ h
    share = np.max(x_fit * h[None, :] / np.maximum(nu_fit, 1e-300)[:, None], axis=0)
    zero = (z[:p] <= _U_LO + 1.0) | (share < 1e-9)
    h = np.where(zero, 0.0, h)
    nl_vals = dict(zip(prob.nl_idx, phis, strict=True))
    fitted = persistent_first(
        [pr.from_fit(float(h[i]), nl_vals.get(i), wv.fs) for i, pr in enumerate(m.processes)],
        wv.fs,
    )
    # at_bound: labels of the fitted (ordered) model with a variance at 0 or a correlation time
    # at an edge
    fields = fitted_fields(fitted, wv, prob.tc_min, prob.tc_max)
    bound = fields["at_bound"]
    with np.errstate(all="ignore"):
        rr = a @ (fy - np.asarray(fun(np.maximum(fields["implied"], 1e-300)), float))
    objective = float(rr @ rr)
    notes = [
        f"f = {fname}, weights {wname}"
        + (" (1/(f(ci_high) - f(ci_low))^2)" if wname == "ci" else ""),
        f"bounded least squares, {len(starts)} starts, {int(best.nfev)} evaluations in the "
        "best run",
    ]
    if bound:
        notes.append(f"at a bound: {', '.join(bound)}")
    return GMWFMResult(
        **fields,
        weights=wname,
        omega=omega,
        objective=objective,
        converged=bool(best.success),
        n_evaluations=n_eval,
        method="bounded least squares",
        message="converged" if best.success else "the least-squares search hit its budget",
        elapsed_s=time.perf_counter() - t0,
        f=fname,
        estimator=name,
        notes=tuple(notes),
    )


def fit_armav(
    wv: WaveletVariance,
    model: Model | Process | str,
    *,
    weights: str | np.ndarray = "ci",
    levels: int | None = None,
) -> GMWFMResult:
    """ARMAV: the wavelet functional moments estimator with ``f = log10``.

    The autonomous regression method for the Allan variance (Jurado, Schubert Kabban & Raquet,
    2019) regresses ``log10`` of the octave Allan variance on the log10 of the model-implied
    one; as the GMWM paper (section III) does, it is computed here as :func:`fit_gmwfm` with
    ``f = log10`` on the Haar WV (``AVAR = 2 nu2``, so the two are the same estimator).

    Weights (our reading, documented choice): ``"ci"`` (default) weighs each octave by the
    inverse squared width of the log10 of its chi-square interval, i.e. in proportion to the
    reliability of that octave's estimate (its equivalent degrees of freedom); this is the
    log-space counterpart of the GMWM's default ``Omega``, matching the paper's remark that
    "the GMWM and the ARMAV are based on different but relatively similar choices of Omega".
    ``weights="identity"`` gives the unweighted log regression of some public ARMAV
    implementations. Either way ``log10`` of a chi-square-like estimate is biased low
    (Jensen's inequality: ``E log nu_hat < log E nu_hat``), most at the long scales where few
    coefficients are averaged, which is the bias the GMWM paper shows.

    Parameters
    ----------
    wv : WaveletVariance
        Classical empirical WV.
    model : Model, Process or str
        E.g. ``"QN+WN+RW+DR"`` (Jurado's linear model without bias instability) or with GM.
    weights, levels
        See :func:`fit_gmwfm`.

    Returns
    -------
    GMWFMResult
        ``estimator="ARMAV"`` (``.as_estimate()`` gives the comparison form).
    """
    return fit_gmwfm(wv, model, f="log10", weights=weights, levels=levels, method="ARMAV")
