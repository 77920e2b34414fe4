"""Test of dependence between channels (the multivariate paper, section IV, after eq. 8).

The objective difference between the model with the shared processes' covariances
restricted to be diagonal (independent channels) and the full model, compared with its
parametric-bootstrap distribution under the restricted model.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._parallel import parallel_map
from ..fit import FitError
from ..fit.result import Summary
from ..models import ModelError
from ..wv import WVMatrix, wv_matrix
from .fit import as_wvm, fit_mgmwm
from .spec import MultiModel

__all__ = ["DependenceTest", "dependence_test"]


@dataclass(frozen=True)
class DependenceTest:
    """Parametric-bootstrap test of dependence between channels.

    ``statistic = Q_independent - Q_shared`` (objective difference, >= 0 since the models
    are nested); ``p_value = (1 + #{D_b >= statistic}) / (1 + B)``. A test, not a fit: it
    has no model or estimates of its own, so it does not derive from
    :class:`engine.fit.result.FitResult`, but it has the same ``summary()`` (a
    :class:`engine.fit.result.Summary`) and ``to_dict()``.
    """

    statistic: float
    p_value: float
    objective_independent: float
    objective_shared: float
    labels: tuple[str, ...]
    B: int
    bootstrap: tuple[float, ...] = ()

    def summary(self) -> Summary:
        """One line: the statistic, its p-value and the number of replicates (a :class:`str`
        with an HTML view for notebooks, as a fit's summary)."""
        return Summary(
            f"test of dependence ({', '.join(self.labels)} shared vs independent): "
            f"D = {self.statistic:.4g}, p = {self.p_value:.3g} "
            f"(parametric bootstrap, B = {self.B})"
        )

    def __str__(self) -> str:
        return str(self.summary())

    def _repr_html_(self) -> str:
        return self.summary()._repr_html_()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: every field by name but the bootstrap values."""
        d = dataclasses.asdict(self)
        del d["bootstrap"]
        d["labels"] = list(self.labels)
        return d


def _boot_dependence(args: tuple) -> float | None:
    null_fit, h0, h1, n, fs, levels, weights, seed = args
    x = null_fit.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    try:
        wvm = wv_matrix(x, channels=list(null_fit.channels), fs=fs, levels=levels)
        q0 = fit_mgmwm(wvm, h0, weights=weights).objective
        q1 = fit_mgmwm(wvm, h1, weights=weights).objective
    except (FitError, ModelError, ValueError):  # pragma: no cover - degenerate replicate
        return None
    return q0 - q1


def dependence_test(
    data: WVMatrix | Any,
    model: MultiModel,
    *,
    labels: Sequence[str] | None = None,
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
    weights: str = "ci",
    fs: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    executor: Executor | None = None,
) -> DependenceTest:
    """Does sharing processes between channels improve the fit more than chance?

    The model with the given shared processes made independent across channels (WN/RW:
    independent per-channel processes; AR1/GM: common phi/beta, diagonal covariance) is
    fitted, and the data's objective difference ``D = Q_independent - Q_shared`` is compared
    with ``D_b`` over ``B`` series simulated from the fitted independent model, each refitted
    with both models (the multivariate paper, section IV).

    Parameters
    ----------
    data : WVMatrix, or raw channels as for :func:`fit_mgmwm`
        With a WVMatrix, simulated replicates get the same length, levels and fs.
    model : MultiModel
        The model with the shared processes.
    labels : sequence of str, optional
        Shared processes to test (default: all).
    B, seed, workers
        Bootstrap replicates, base seed (replicate b uses ``SeedSequence(seed).spawn``),
        worker processes (results do not depend on it).
    weights : {"ci", "identity"}
        Weights (recomputed for every replicate from its own intervals).
    fs : float, optional
        Sampling frequency of raw data (Hz).
    progress : callable (done, total), optional
        Called after every bootstrap replicate, in this process. An exception raised by it
        aborts the test (the replicates not yet started are cancelled) and propagates (e.g.
        a user's cancel). Results do not depend on it.
    executor : concurrent.futures.Executor, optional
        Runs the replicates instead of ``workers`` local processes, e.g. a Dask
        ``Client.get_executor()``; results do not depend on it.

    Returns
    -------
    DependenceTest
    """
    if B < 1:
        raise ValueError(f"B must be at least 1, got {B}")
    if not model.shared:
        raise ModelError("the model has no shared process: nothing to test")
    wvm = as_wvm(data, model.channels, fs, None)
    h1 = model.cleared()
    h0 = model.without_dependence(labels).cleared()
    tested = tuple(labels) if labels is not None else tuple(s.label for s in model.shared)
    fit1 = fit_mgmwm(wvm, h1, weights=weights)
    fit0 = fit_mgmwm(wvm, h0, weights=weights)
    stat = fit0.objective - fit1.objective
    seeds = np.random.SeedSequence(seed).spawn(B)
    items = [(fit0.model, h0, h1, wvm.n, wvm.fs, wvm.n_levels, weights, sd) for sd in seeds]
    out = parallel_map(_boot_dependence, items, workers, executor=executor, progress=progress)
    boot = [d for d in out if d is not None]
    if len(boot) < max(1, B // 2):
        raise FitError("too many bootstrap replicates failed; the model may be unidentifiable")
    p = (1 + sum(d >= stat for d in boot)) / (1 + len(boot))
    return DependenceTest(
        float(stat),
        float(p),
        float(fit0.objective),
        float(fit1.objective),
        tested,
        len(boot),
        tuple(float(d) for d in boot),
    )
