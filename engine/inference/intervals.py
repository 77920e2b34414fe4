"""Parameter intervals of a GMWM fit: asymptotic sandwich or parametric bootstrap.

``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2) in the
unconstrained space of each parameter (log variances, log beta, atanh phi) mapped back, so the
intervals stay inside the parameter space; or the parametric bootstrap (percentile).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._parallel import parallel_map
from ..fit import FitError, GMWMResult, fit_gmwm
from ..fit.asymptotic import asymptotic_bounds
from ..fit.covariance import v_options, wv_cov
from ..wv import wavelet_variance

if TYPE_CHECKING:  # pragma: no cover
    from typing_extensions import Unpack

    from ..fit.covariance import VOptions

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
    progress: Callable[[int, int], None] | None = None,
    **options: Unpack[VOptions],
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
    progress : callable (done, total), optional
        Called after every bootstrap refit (the bootstrap method).
    **options
        :class:`VOptions`: ``v`` and ``x``, the covariance of the WV for the asymptotic
        method; ``B`` and ``seed``, the bootstrap's replicates (the bootstrap method, or
        ``v="bootstrap"``) and base seed; ``workers`` or ``executor``, where the replicates
        run (the intervals do not depend on them).

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = eg.parse_model("WN(1e-2) + RW(1e-6)").simulate(2**12, rng=np.random.default_rng(1))
    >>> res = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0), "WN + RW")
    >>> for p in eg.param_intervals(res):
    ...     print(f"{p.name}: {p.low:.2e} <= {p.value:.2e} <= {p.high:.2e} {p.unit}")
    WN.sigma2: 9.62e-03 <= 1.00e-02 <= 1.05e-02 u^2
    RW.gamma2: 4.56e-07 <= 1.27e-06 <= 3.53e-06 u^2
    """
    o = v_options(options)
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    recs = res.param_records
    if method == "asymptotic":
        vmat = wv_cov(res, **o)
        return [
            ParamInterval(r.full_name, r.value, lo, hi, r.unit, "asymptotic", level)
            for r, (lo, hi) in zip(recs, asymptotic_bounds(res, vmat, level), strict=True)
        ]
    if method == "bootstrap":
        seeds = np.random.SeedSequence(o["seed"]).spawn(o["B"])
        omega = None if res.weights == "ci" else res.omega
        items = [
            (res.model, res.model.cleared(), res.wv.n, res.fs, res.wv.n_levels, omega, s)
            for s in seeds
        ]
        boot = parallel_map(
            _boot_fit, items, o["workers"], executor=o["executor"], progress=progress
        )
        fits = [f for f in boot if f is not None]
        if len(fits) < max(10, o["B"] // 2):
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
