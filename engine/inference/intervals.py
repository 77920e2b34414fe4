"""Parameter intervals of a GMWM fit: asymptotic sandwich or parametric bootstrap.

``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2) in the
unconstrained space of each parameter (log variances, log beta, atanh phi) mapped back, so the
intervals stay inside the parameter space; or the parametric bootstrap (percentile).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..fit import FitError, GMWMResult, fit_gmwm
from ..wv import wavelet_variance
from .asymptotic import asymptotic_bounds
from .covariance import parallel_map, wv_cov

__all__ = ["param_intervals", "ParamInterval"]


# ------------------------------------------------------------------------------------------
# intervals and goodness of fit
# ------------------------------------------------------------------------------------------
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
        """JSON-ready dictionary: every field by name."""
        return asdict(self)


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
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
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
    B, seed : int
        Bootstrap replicates (the bootstrap method, or ``v="bootstrap"``) and base seed:
        replicate b draws from the b-th child of ``SeedSequence(seed)``.
    workers : int
        Local worker processes (1: in process).
    executor : concurrent.futures.Executor, optional
        Runs the replicates instead of the local pool, e.g. a Dask ``Client.get_executor()``.
        The intervals do not depend on ``workers`` or ``executor``.
    progress : callable (done, total), optional
        Called after every bootstrap refit (the bootstrap method).
    """
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    recs = res.param_records
    if method == "asymptotic":
        vmat = wv_cov(res, v, x=x, B=B, seed=seed, workers=workers, executor=executor)
        return [
            ParamInterval(r.full_name, r.value, lo, hi, r.unit, "asymptotic", level)
            for r, (lo, hi) in zip(recs, asymptotic_bounds(res, vmat, level), strict=True)
        ]
    if method == "bootstrap":
        seeds = np.random.SeedSequence(seed).spawn(B)
        omega = None if res.weights == "ci" else res.omega
        items = [
            (res.model, res.model.cleared(), res.wv.n, res.fs, res.wv.n_levels, omega, s)
            for s in seeds
        ]
        boot = parallel_map(_boot_fit, items, workers, executor=executor, progress=progress)
        fits = [f for f in boot if f is not None]
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
