"""Parameter intervals of a GMWM fit: asymptotic sandwich or parametric bootstrap.

``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2) in the
unconstrained space of each parameter (log variances, log beta, atanh phi) mapped back, so the
intervals stay inside the parameter space; or the parametric bootstrap (percentile).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..fit import FitError, GMWMResult, fit_gmwm
from ..model import Model
from ..processes import _BACKWARD, _FORWARD
from ..wavelet import wavelet_variance
from .covariance import parallel_map, wv_cov

__all__ = ["param_intervals", "ParamInterval", "jacobian", "free_params"]


# ------------------------------------------------------------------------------------------
# intervals and goodness of fit
# ------------------------------------------------------------------------------------------
def free_params(res: GMWMResult) -> list[tuple[int, str]]:
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
        procs[i] = procs[i].with_values(**{name: _BACKWARD[name](float(ui))})
    return Model(tuple(procs))


def _u0(model: Model, free: list[tuple[int, str]]) -> np.ndarray:
    """Unconstrained coordinates of the free parameters."""
    return np.array([_FORWARD[n](float(getattr(model.processes[i], n))) for i, n in free])


def jacobian(res: GMWMResult, free: list[tuple[int, str]] | None = None) -> np.ndarray:
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


@dataclass(frozen=True)
class ParamInterval:
    """A parameter estimate with its two-sided interval."""

    name: str
    value: float
    low: float
    high: float
    unit: str
    method: str
    level: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "low": self.low,
            "high": self.high,
            "unit": self.unit,
            "method": self.method,
            "level": self.level,
        }


def _boot_fit(args: tuple) -> dict[str, float] | None:
    model, spec, n, fs, levels, omega, seed = args
    x = model.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    try:
        wv = wavelet_variance(x, fs=fs, levels=levels)
        w = "ci" if omega is None else omega
        return fit_gmwm(wv, spec, weights=w).params
    except (FitError, ValueError):  # pragma: no cover - degenerate replicate
        return None


def param_intervals(
    res: GMWMResult,
    *,
    method: str = "asymptotic",
    level: float = 0.95,
    v: str | np.ndarray = "model",
    x: Any = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
) -> list[ParamInterval]:
    """Two-sided intervals for every parameter of a fit.

    Parameters
    ----------
    method : {"asymptotic", "bootstrap"}
        ``asymptotic``: the sandwich covariance in the unconstrained space (log of variances
        and beta, atanh of phi, omega as is) and Wald intervals mapped back, so they respect
        the parameter space; parameters estimated on a boundary get ``nan`` bounds.
        ``bootstrap``: parametric bootstrap percentile intervals (B refits).
    level : float
        Two-sided coverage (0.95 gives the 2.5 % and 97.5 % quantiles, unlike the R packages'
        normal quantile at 1 - alpha).
    v : {"model", "bootstrap", "data"} or array
        Covariance of the WV for the asymptotic method.
    """
    from scipy import stats

    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    recs = res.param_records
    if method == "asymptotic":
        free = free_params(res)
        vmat = wv_cov(res, v, x=x, B=B, seed=seed, workers=workers)
        a = jacobian(res, free)
        w = res.omega
        bread = np.linalg.pinv(a.T @ w @ a)
        cov = bread @ a.T @ w @ vmat @ w @ a @ bread
        se = np.sqrt(np.maximum(np.diagonal(cov), 0.0))
        z = stats.norm.ppf(0.5 + level / 2)
        u0 = _u0(res.model, free)
        bounds = {}
        for k, (i, name) in enumerate(free):
            lo = _BACKWARD[name](u0[k] - z * se[k])
            hi = _BACKWARD[name](u0[k] + z * se[k])
            bounds[(res.model.labels[i], name)] = (min(lo, hi), max(lo, hi))
        out = []
        for r in recs:
            lo, hi = bounds.get((r.label, r.name), (math.nan, math.nan))
            if r.name == "omega":  # the sign of a drift is not identified: report |omega|
                lo, hi = (max(lo, 0.0), hi) if r.value >= 0 else (lo, hi)
            out.append(
                ParamInterval(
                    r.full_name, r.value, float(lo), float(hi), r.unit, "asymptotic", level
                )
            )
        return out
    if method == "bootstrap":
        seeds = np.random.SeedSequence(seed).spawn(B)
        omega = None if res.weights == "ci" else res.omega
        items = [
            (res.model, res.model.cleared(), res.wv.n, res.fs, res.wv.n_levels, omega, s)
            for s in seeds
        ]
        fits = [f for f in parallel_map(_boot_fit, items, workers) if f is not None]
        if len(fits) < max(10, B // 2):
            raise FitError("too many bootstrap refits failed; the model may be unidentifiable")
        out = []
        for r in recs:
            vals = np.array([f[r.full_name] for f in fits])
            lo, hi = np.quantile(vals, [0.5 - level / 2, 0.5 + level / 2])
            out.append(
                ParamInterval(
                    r.full_name, r.value, float(lo), float(hi), r.unit, "bootstrap", level
                )
            )
        return out
    raise ValueError(f"unknown interval method {method!r}: use 'asymptotic' or 'bootstrap'")
