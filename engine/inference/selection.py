"""Model selection by the Wavelet Variance Information Criterion (WVIC).

For a candidate model fitted by GMWM with weights Omega, the criterion estimates the expected
distance between the model-implied WV and an independent new empirical WV:

    WVIC = objective + optimism,   optimism = 2 tr(Omega Cov(nu_hat, nu(theta_hat))).

* asymptotic optimism: with ``A = d nu / d theta`` and ``V = Cov(nu_hat)``,
  ``Cov(nu_hat, nu(theta_hat)) = V Omega A (A' Omega A)^-1 A'`` (delta method), so
  ``optimism = 2 tr(Omega A (A' Omega A)^-1 A' Omega V)``; parameters on a boundary do not
  count (they are not free);
* bootstrap optimism: ``2 tr(Omega C)`` with ``C`` the covariance of (nu_hat*, nu(theta_hat*))
  over parametric-bootstrap replicates from the largest candidate.

One V (from the largest candidate's fit, by default the analytic Gaussian one) serves all
candidates, so every criterion is on the same scale. Reference: Guerrier & Molinari, "Wavelet
variance based model selection" (WVIC), and the GMWM model-selection work of the SMAC group.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from collections.abc import Callable, Iterable
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..fit import FitError, GMWMResult, fit_gmwm
from ..models import Model, ModelError, parse_model
from ..wv import WaveletVariance, wavelet_variance
from .asymptotic import free_params, jacobian
from .covariance import inverse_cov, parallel_map, wv_cov

__all__ = ["submodels", "rank_models", "SelectionResult", "Candidate"]


def submodels(max_model: Model | str) -> list[Model]:
    """Every distinct non-empty sub-model of a maximal model.

    AR1/GM terms are exchangeable, so ``3*GM+WN+QN+RW+DR`` has ``4 * 2^4 - 1 = 63`` distinct
    sub-models (the 127 subsets of its seven terms, less the duplicates).
    """
    m = parse_model(max_model).cleared()
    counts: dict[str, int] = {}
    protos: dict[str, Any] = {}
    for p in m.processes:
        counts[p.code] = counts.get(p.code, 0) + 1
        protos[p.code] = p
    codes = list(counts)
    out = []
    for ks in itertools.product(*(range(counts[c] + 1) for c in codes)):
        procs = tuple(p for c, k in zip(codes, ks, strict=True) for p in [protos[c]] * k)
        if procs:
            out.append(Model(procs))
    return out


@dataclass(frozen=True)
class Candidate:
    """One ranked candidate."""

    model: str
    n_params: int
    objective: float
    optimism: float
    criterion: float
    j_stat: float
    j_df: int
    j_p_value: float
    result: GMWMResult | None = field(default=None, repr=False, compare=False)
    error: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = {
            k: getattr(self, k)
            for k in (
                "model",
                "n_params",
                "objective",
                "optimism",
                "criterion",
                "j_stat",
                "j_df",
                "j_p_value",
                "error",
            )
        }
        if self.result is not None:
            d["params"] = [r.to_dict() for r in self.result.param_records]
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()
        }


@dataclass(frozen=True, eq=False)
class SelectionResult:
    """Candidates ranked by WVIC (smallest first), with the settings used."""

    candidates: list[Candidate]
    optimism: str
    weights: str
    elapsed_s: float

    @property
    def best(self) -> Candidate:
        return self.candidates[0]

    def table(self) -> str:
        """Readable ranked table."""
        lines = [
            f"WVIC ranking ({len(self.candidates)} candidates, {self.optimism} optimism, "
            f"weights {self.weights}, {self.elapsed_s:.2f} s)",
            f"{'rank':>4} {'model':<22} {'p':>3} {'objective':>12} {'optimism':>10} "
            f"{'WVIC':>12} {'J-test p':>9}",
        ]
        for i, c in enumerate(self.candidates, 1):
            if c.error:
                lines.append(f"{i:>4} {c.model:<22} {c.n_params:>3}  not fitted: {c.error}")
                continue
            jp = f"{c.j_p_value:9.3g}" if math.isfinite(c.j_p_value) else f"{'n/a':>9}"
            lines.append(
                f"{i:>4} {c.model:<22} {c.n_params:>3} {c.objective:>12.5g} "
                f"{c.optimism:>10.4g} {c.criterion:>12.5g} {jp}"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "optimism": self.optimism,
            "weights": self.weights,
            "elapsed_s": self.elapsed_s,
            "candidates": [c.to_dict() for c in self.candidates],
        }


def _asymptotic_optimism(res: GMWMResult, v: np.ndarray) -> float:
    free = free_params(res)
    if not free:
        return 0.0
    a = jacobian(res, free)
    w = res.omega
    proj = a @ np.linalg.pinv(a.T @ w @ a) @ a.T
    return float(2.0 * np.trace(w @ proj @ w @ v))


def _boot_pair(args: tuple) -> tuple[np.ndarray, list[np.ndarray | None]]:
    model, specs, n, fs, levels, weights, seed = args
    x = model.simulate(n, fs=fs, rng=np.random.default_rng(seed))
    wv = wavelet_variance(x, fs=fs, levels=levels)
    fits = []
    for spec in specs:
        try:
            fits.append(fit_gmwm(wv, spec, weights=weights).implied)
        except (FitError, ModelError):  # pragma: no cover
            fits.append(None)
    return wv.variance, fits


def rank_models(
    wv: WaveletVariance,
    candidates: Iterable[Model | str] | None = None,
    *,
    max_model: Model | str | None = None,
    weights: str | np.ndarray = "ci",
    optimism: str = "asymptotic",
    v: str | np.ndarray = "model",
    B: int = 100,
    seed: int | None = 0,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    executor: Executor | None = None,
) -> SelectionResult:
    """Fit and rank candidate models by WVIC = objective + optimism.

    Parameters
    ----------
    wv : WaveletVariance
        The empirical WV.
    candidates : iterable of Model or str, optional
        The candidates; or ``max_model`` to rank every sub-model (:func:`submodels`).
    weights : {"ci", "identity", "efficient"} or array
        Omega, the same for every candidate. ``"efficient"``: two-step, every candidate is
        first fitted with ``"ci"`` weights, V is estimated (``v``) from the largest candidate
        that fits, and every candidate is refitted with ``Omega = V^-1`` (the GMWM paper,
        Corollary 1), so that the J-test's chi-square applies and the objectives compare.
    optimism : {"asymptotic", "bootstrap"}
        How the optimism is estimated (see the module docstring).
    v : {"model", "bootstrap"} or array
        Covariance of the WV for the asymptotic optimism and the J-test, estimated once from
        the largest candidate that fits.
    B, seed, workers, executor
        Bootstrap replicates (``optimism="bootstrap"`` or ``v="bootstrap"``), base seed
        (replicate b draws from the b-th child of ``SeedSequence(seed)``), and where they run:
        ``workers`` local processes, or ``executor`` (any ``concurrent.futures.Executor``,
        e.g. a Dask ``Client.get_executor()``). The ranking does not depend on either. The
        candidate fits themselves run in process (milliseconds each: shipping them would
        cost more than it saves).
    progress : callable, optional
        Called as ``progress(done, total)`` after each candidate.
    """
    from scipy import stats

    t0 = time.perf_counter()
    if candidates is None:
        if max_model is None:
            raise ModelError("give candidate models or a max_model")
        models = submodels(max_model)
    else:
        models = [parse_model(c).cleared() for c in candidates]
        if max_model is not None:
            models += submodels(max_model)
    seen, uniq = set(), []
    for m in models:
        if m.spec() not in seen:
            seen.add(m.spec())
            uniq.append(m)
    if not uniq:
        raise ModelError("no candidate models to rank")
    efficient = isinstance(weights, str) and weights == "efficient"
    total = 2 * len(uniq) if efficient else len(uniq)

    def fit_all(w: str | np.ndarray, done: int) -> list[tuple[Model, GMWMResult | None, str]]:
        out: list[tuple[Model, GMWMResult | None, str]] = []
        for i, m in enumerate(uniq):
            try:
                m.validate(wv.n_levels)
                out.append((m, fit_gmwm(wv, m, weights=w), ""))
            except (FitError, ModelError) as e:
                out.append((m, None, str(e)))
            if progress is not None:
                progress(done + i + 1, total)
        return out

    def largest_fit(
        fits: list[tuple[Model, GMWMResult | None, str]],
    ) -> tuple[list[GMWMResult], GMWMResult]:
        ok = [r for _, r, _ in fits if r is not None]
        if not ok:
            raise FitError("no candidate could be fitted: " + "; ".join(e for *_, e in fits))
        return ok, max(ok, key=lambda r: (r.model.n_params, -r.objective))

    fitted = fit_all("ci" if efficient else weights, 0)
    ok, largest = largest_fit(fitted)
    vmat = wv_cov(largest, v, B=B, seed=seed, workers=workers, executor=executor)
    vinv = inverse_cov(vmat)
    if efficient:  # second step: one Omega = V^-1 for every candidate
        weights = vinv
        fitted = fit_all(vinv, len(uniq))
        ok, largest = largest_fit(fitted)

    boot_opt: dict[str, float] = {}
    if optimism == "bootstrap":
        specs = [r.model.cleared() for r in ok]
        seeds = np.random.SeedSequence(seed).spawn(B)
        omega = None if isinstance(weights, str) else weights
        items = [
            (largest.model, specs, wv.n, wv.fs, wv.n_levels, weights if omega is None else omega, s)
            for s in seeds
        ]
        pairs = parallel_map(_boot_pair, items, workers, executor=executor)
        nus = np.array([p[0] for p in pairs])
        for k, r in enumerate(ok):
            rows = [
                (nu, f[k])
                for nu, f in zip(nus, (p[1] for p in pairs), strict=True)
                if f[k] is not None
            ]
            a = np.array([x for x, _ in rows])
            b = np.array([y for _, y in rows])
            c = (a - a.mean(0)).T @ (b - b.mean(0)) / (len(rows) - 1)
            boot_opt[r.model.spec()] = float(2.0 * np.trace(r.omega @ c))
    elif optimism != "asymptotic":
        raise ValueError(f"unknown optimism {optimism!r}: use 'asymptotic' or 'bootstrap'")

    cands = []
    for m, r, err in fitted:
        if r is None:
            cands.append(
                Candidate(
                    m.spec(),
                    m.n_params,
                    math.nan,
                    math.nan,
                    math.inf,
                    math.nan,
                    0,
                    math.nan,
                    None,
                    err,
                )
            )
            continue
        opt = boot_opt[m.spec()] if optimism == "bootstrap" else _asymptotic_optimism(r, vmat)
        resid = wv.variance - r.implied
        jstat = float(resid @ vinv @ resid)
        df = wv.n_levels - len(free_params(r))
        jp = float(stats.chi2.sf(jstat, df)) if df > 0 else math.nan
        cands.append(
            Candidate(m.spec(), m.n_params, r.objective, opt, r.objective + opt, jstat, df, jp, r)
        )

    # candidates whose extra terms are fitted at zero tie with the smaller model: within a
    # relative 1e-6 of each other, the one with fewer parameters ranks first
    def order(a: Candidate, b: Candidate) -> int:
        if abs(a.criterion - b.criterion) > 1e-6 * max(abs(a.criterion), abs(b.criterion)):
            return -1 if a.criterion < b.criterion else 1
        return (a.n_params > b.n_params) - (a.n_params < b.n_params) or (
            (a.model > b.model) - (a.model < b.model)
        )

    cands.sort(key=functools.cmp_to_key(order))
    wname = "efficient" if efficient else (weights if isinstance(weights, str) else "user")
    return SelectionResult(cands, optimism, wname, time.perf_counter() - t0)
