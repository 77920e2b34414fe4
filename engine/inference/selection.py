"""Model selection by the Wavelet Variance Information Criterion (WVIC).

For a candidate model fitted by GMWM with weights Omega, the criterion estimates the expected
distance between the model-implied WV and an independent new empirical WV:
``WVIC = objective + optimism``, ``optimism = 2 tr(Omega Cov(nu_hat, nu(theta_hat)))``,
asymptotic (delta method) or by parametric bootstrap, with one V for all candidates so that
every criterion is on the same scale. Each candidate's J-test is the calibrated one of
:func:`engine.inference.j_test`. A candidate whose AR1/GM is white noise in disguise (faster
than one sample) is ranked as its *WN twin* unless the distance test of the fold rejects the
twin at :data:`DISGUISE_LEVEL`. The formulas and the twin rule: docs/methods.md, "Model
selection by the WVIC"; the user's view and the Monte Carlo: docs/selection.md,
docs/inference.md.

Reference: Guerrier & Molinari, "Wavelet variance based model selection" (WVIC), and the GMWM
model-selection work of the SMAC group.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import textwrap
import time
from collections import Counter
from collections.abc import Callable, Iterable
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._parallel import parallel_map
from ..fit import FitError, GMWMResult, fit_gmwm
from ..fit._varpro import TC_FLAG
from ..fit.asymptotic import free_params, inverse_cov, jacobian
from ..fit.covariance import wv_cov
from ..models import WN, Model, ModelError, Process, parse_model
from ..wv import WaveletVariance, wavelet_variance
from .jtest import LEVELS_RULE, calibration_note, efficient_j, jtest_levels

__all__ = [
    "submodels",
    "rank_models",
    "SelectionResult",
    "Candidate",
    "wn_twin",
    "actionable",
    "tie_choice",
    "wvic_se",
    "JTEST_NOTE",
    "DISGUISE_LEVEL",
    "DEFAULT_SELECT",
    "TIE_Z",
    "SLOW_GM",
    "GM_RW",
]

#: The maximal model whose WVIC-best sub-model is fitted when no model is given (``gmwm
#: report``, ``gmwm batch``, :func:`engine.reporting.gather_report`).
DEFAULT_SELECT = "2*GM+WN+QN+RW+DR"

#: A candidate with an AR1/GM faster than one sample keeps its own rank only when the distance
#: test of folding that term into WN rejects the fold at this level (a small level: under a
#: model without such a term the top-ranked structure must not carry one).
DISGUISE_LEVEL = 1e-3

#: The WVIC's tie band, in standard errors of the difference from the first row
#: (:func:`tie_choice`): a candidate within it is not told apart from the first row by the data.
TIE_Z = 1.0

#: A GM/AR1 whose correlation time exceeds this fraction of the log's length mimics a random
#: walk at the scales of the log (:func:`tie_choice`): 1, a correlation time beyond the log
#: (docs/selection.md: a smaller fraction swaps real GMs for random walks on simulated logs).
SLOW_GM = 1.0

#: A tie that adds a RW beside the selection's slowest AR1/GM is chosen when that term's
#: correlation time exceeds this fraction of the log (:func:`tie_choice`): inf, never
#: (docs/selection.md: on simulated logs a finite fraction finds more hidden random walks but
#: takes the selection's WV out of the true band where the random walk is too small to see).
GM_RW = math.inf

#: What the J column of a ranking is (the table's last line; the app and docs/inference.md agree).
JTEST_NOTE = (
    "J-test p: efficient J-test of each candidate (refitted with Omega = V^-1, V of the WV's "
    "own estimator with a drift's share, from the largest candidate, on the levels with "
    f"{LEVELS_RULE}) against chi2(levels - p), whatever the ranking's weights"
)


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


def _correlation_time(p: Process, fs: float) -> float:
    """Correlation time in samples of a fitted process with a non-linear parameter
    (:meth:`~engine.models.Process.correlation_time`: AR1, GM ``-1 / log(phi)``); NaN for one
    without a correlation time (an MA1), which is then neither folded into WN nor taken for
    a random walk."""
    if p.nl_value(fs) is None:
        raise ValueError(f"{p.code} has no correlation time")
    tc = p.correlation_time(fs)
    return math.nan if tc is None else tc


def wn_twin(fitted: Model, fs: float) -> tuple[Model, list[str]]:
    """The model in effect of a fit whose AR1/GM terms may be white noise in disguise.

    Every AR1/GM whose correlation time is below one sample (``TC_FLAG``) is folded into WN
    (one WN term, added if the model has none); one fitted at zero variance is dropped.

    Parameters
    ----------
    fitted : Model
        A fitted model (every value set).
    fs : float
        Sampling frequency (Hz): a GM's beta is in 1/s.

    Returns
    -------
    twin, labels
        The twin's structure (values cleared) and the labels of the folded terms with their
        correlation times (e.g. ``["GM_3 (0.17 samples)"]``); ``(fitted structure, [])`` when
        there is none.
    """
    keep, labels, to_wn = [], [], False
    for lab, q in zip(fitted.labels, fitted.processes, strict=True):
        if q.nonlinear is not None and q.is_set:  # an AR1/GM: it has a correlation time
            tc = _correlation_time(q, fs)
            if tc < TC_FLAG:
                labels.append(f"{lab} ({tc:.2g} samples)")
                to_wn = to_wn or q.linear_coef() > 0
                continue
        keep.append(q.cleared())
    if not labels:
        return fitted.cleared(), []
    if to_wn and not any(q.code == WN.code for q in keep):
        keep.append(WN())
    return Model(tuple(keep)), labels


def actionable(res: GMWMResult) -> tuple[Model, list[str]]:
    """The model a user can act on that a fit stands for, and what was changed to get it.

    A fitted model is *actionable* when no AR1/GM term is faster than one sample (``TC_FLAG``)
    and no parameter is at a bound (``res.at_bound``: a variance at 0, a correlation time at
    the edge of the explored range). Otherwise every such AR1/GM with a positive variance is
    folded into WN (its white-noise twin, :func:`wn_twin`: WN's variance grows by the term's
    white-noise equivalent, :meth:`~engine.models.Process.white_equivalent`, so the implied
    WV is unchanged at the scales much longer than its correlation time) and every other term
    with a parameter at a bound is dropped; every other value is kept.

    Parameters
    ----------
    res : GMWMResult
        The fit.

    Returns
    -------
    model, changes
        The actionable model (every value set) and one line per change (e.g.
        ``"GM_2 (0.55 samples) folded into WN"``, ``"QN dropped (QN.q2 at its bound)"``);
        ``(res.model, [])`` when the fit is actionable.
    """
    fs = res.wv.fs
    keep, changes, white = [], [], 0.0
    for lab, q in zip(res.model.labels, res.model.processes, strict=True):
        bound = [b for b in res.at_bound if b.startswith(lab + ".")]
        if q.nonlinear is not None and q.linear_coef() > 0:
            tc = _correlation_time(q, fs)
            if tc < TC_FLAG:
                changes.append(f"{lab} ({tc:.2g} samples) folded into WN")
                white += q.white_equivalent(fs)
                continue
        if bound:
            changes.append(f"{lab} dropped ({', '.join(bound)} at its bound)")
            continue
        if q.code != WN.code:
            keep.append(q)
        else:
            white += q.linear_coef()
    if not changes:
        return res.model, []
    if white > 0:
        keep.append(WN(sigma2=white))
    return Model(tuple(keep)), changes


@dataclass(frozen=True)
class Candidate:
    """One ranked candidate.

    ``sub_sample`` lists its AR1/GM terms faster than one sample and ``twin`` the model with
    those terms folded into WN (:func:`wn_twin`); both are empty for an ordinary candidate.
    ``twin_p`` is the p-value of the distance test of the fold and ``as_twin`` whether the
    candidate is ranked as its twin (white noise in effect: ``twin_p >= DISGUISE_LEVEL``).
    ``added`` is True for a WN twin that was not among the candidates and was fitted to rank
    one that is. ``changes`` lists what makes the candidate not actionable
    (:func:`actionable`): such a candidate is never the selection. ``derived_from`` names the
    top-ranked candidate the selection was derived from (empty for a ranked candidate) and
    ``derivation`` the changes made to it.
    """

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
    sub_sample: tuple[str, ...] = ()
    twin: str = ""
    added: bool = False
    twin_p: float = math.nan
    as_twin: bool = False
    changes: tuple[str, ...] = ()
    derived_from: str = ""
    derivation: tuple[str, ...] = ()

    @property
    def is_actionable(self) -> bool:
        """Fitted, with no AR1/GM faster than one sample and no parameter at a bound."""
        return self.result is not None and not self.changes

    @property
    def note(self) -> str:
        """One line for the table: not fitted, white noise in disguise, an added twin, or why
        the candidate cannot be selected and what it stands for."""
        if self.error:
            return f"not fitted: {self.error}"
        parts = []
        if self.twin:
            head = f"{', '.join(self.sub_sample)} < 1 sample"
            tp = f"{self.twin_p:.2g}" if math.isfinite(self.twin_p) else "n/c"
            if self.as_twin:
                parts.append(f"{head}: WN in effect (p = {tp}), ranked as {self.twin}")
            else:
                parts.append(f"{head}: not WN in effect (vs {self.twin}: p = {tp})")
        elif self.added:
            parts.append("WN twin (added)")
        if self.changes:
            parts.append(f"not selectable: {'; '.join(self.changes)}")
        if self.derived_from:
            parts.append(f"selected: {self.derived_from} with {'; '.join(self.derivation)}")
        return "; ".join(parts)

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
                "twin",
                "twin_p",
                "as_twin",
                "added",
                "derived_from",
            )
        }
        d["sub_sample"] = list(self.sub_sample)
        d["changes"] = list(self.changes)
        d["derivation"] = list(self.derivation)
        d["actionable"] = self.is_actionable
        if self.result is not None:
            d["params"] = [r.to_dict() for r in self.result.param_records]
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()
        }


@dataclass(frozen=True, eq=False)
class SelectionResult:
    """Candidates ranked by WVIC (smallest first), with the settings used.

    ``best`` is the selection, a model a user can act on (:attr:`Candidate.is_actionable`):
    the first row when it is actionable, else the model derived from the first row by
    :func:`actionable` (each AR1/GM faster than one sample folded into WN, each term at a bound
    dropped; the other values kept: the implied WV is the first row's at every scale longer
    than a few samples: ``first_actionable``); then, among the candidates the WVIC does not
    tell apart from the first row, a RW for a drift or for a GM slower than the log, and the
    fewer parameters among over-fitted ties (:func:`tie_choice`). ``selected`` is the
    selection when it is not the first row.
    """

    candidates: list[Candidate]
    optimism: str
    weights: str
    elapsed_s: float
    selected: Candidate | None = None
    #: why the J column has no p-values (``"not calibrated: ..."``), or ``""``
    j_note: str = ""
    #: the model a user can act on derived from the first row, before the tie rules of
    #: :func:`tie_choice` (None when the first row is actionable)
    first_actionable: Candidate | None = None
    #: the covariance of the WV (J, J) of the optimism, the J column and the tie band
    v: np.ndarray | None = field(default=None, repr=False)

    @property
    def best(self) -> Candidate:
        """The selected candidate (see the class notes)."""
        return self.selected if self.selected is not None else self.candidates[0]

    def table(self) -> str:
        """Readable ranked table, with a last line saying which test the J column is."""
        best = self.best
        how = (
            f"the rank-1 {best.derived_from} with {'; '.join(best.derivation)}"
            if best.derived_from
            else "rank 1"
        )
        lines = [
            f"WVIC ranking ({len(self.candidates)} candidates, {self.optimism} optimism, "
            f"weights {self.weights}, {self.elapsed_s:.2f} s)",
            f"selected: {best.model} ({how}; objective {best.objective:.5g})",
            f"{'rank':>4} {'model':<22} {'p':>3} {'objective':>12} {'optimism':>10} "
            f"{'WVIC':>12} {'J-test p':>9}  note",
        ]
        for i, c in enumerate(self.candidates, 1):
            if c.error:
                lines.append(f"{i:>4} {c.model:<22} {c.n_params:>3}  {c.note}")
                continue
            jp = f"{c.j_p_value:9.3g}" if math.isfinite(c.j_p_value) else f"{'n/a':>9}"
            jp = f"{'n/c':>9}" if self.j_note and math.isfinite(c.j_stat) else jp
            lines.append(
                f"{i:>4} {c.model:<22} {c.n_params:>3} {c.objective:>12.5g} "
                f"{c.optimism:>10.4g} {c.criterion:>12.5g} {jp}  {c.note}".rstrip()
            )
        lines += textwrap.wrap(JTEST_NOTE, 100)
        if self.j_note:
            lines += textwrap.wrap(f"J-test p n/c: {self.j_note}", 100)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "optimism": self.optimism,
            "weights": self.weights,
            "elapsed_s": self.elapsed_s,
            "selected": self.best.to_dict(),
            "j_note": self.j_note,
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
    fits: list[np.ndarray | None] = []
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

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = eg.parse_model("WN(1e-2) + RW(1e-6)").simulate(2**14, rng=np.random.default_rng(1))
    >>> ranking = eg.rank_models(eg.wavelet_variance(x, fs=100.0), ["WN", "WN + RW"])
    >>> ranking.best.model
    'WN+RW'
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
    n_uniq = len(uniq)
    rounds = 2 if efficient else 1
    total = (rounds + 1) * n_uniq  # the fits, then one J-test refit per candidate
    Fits = list[tuple[Model, GMWMResult | None, str]]

    # the sub-models' optima, shared by every fit: the candidates are fitted smallest first,
    # so each one's search is anchored at the optima of all its candidate sub-models and no
    # candidate's fit is above a smaller candidate's (engine.fit._varpro.nested_search)
    optima: dict[Any, Any] = {}
    by_size = sorted(range(len(uniq)), key=lambda i: len(uniq[i].processes))

    def fit_all(models: list[Model], w: str | np.ndarray, done: int | None) -> Fits:
        out: dict[int, tuple[Model, GMWMResult | None, str]] = {}
        order = by_size if models is uniq else range(len(models))
        for n, i in enumerate(order):
            m = models[i]
            try:
                m.validate(wv.n_levels)
                out[i] = (m, fit_gmwm(wv, m, weights=w, optima=optima), "")
            except (FitError, ModelError) as e:
                out[i] = (m, None, str(e))
            if progress is not None and done is not None:
                progress(done + n + 1, total)
        return [out[i] for i in range(len(models))]

    def largest_fit(fits: Fits) -> tuple[list[GMWMResult], GMWMResult]:
        ok = [r for _, r, _ in fits if r is not None]
        if not ok:
            raise FitError("no candidate could be fitted: " + "; ".join(e for *_, e in fits))
        return ok, max(ok, key=lambda r: (r.model.n_params, -r.objective))

    fitted = fit_all(uniq, "ci" if efficient else weights, 0)
    ok, largest = largest_fit(fitted)
    vmat = wv_cov(largest, v, B=B, seed=seed, workers=workers, executor=executor)
    if efficient:  # second step: one Omega = V^-1 for every candidate
        weights = inverse_cov(vmat)
        fitted = fit_all(uniq, weights, n_uniq)
        ok, largest = largest_fit(fitted)
    # the J column's p-values, unless V has no chi-square reference (a drift far too strong)
    j_note = calibration_note(largest.model, wv, vmat, jtest_levels(wv))

    # white noise in disguise: a candidate with an AR1/GM faster than one sample is ranked as
    # its WN twin, which is fitted (with the same weights) when it is not a candidate; a
    # twin's own fit may fold a term in turn (each twin has fewer AR1/GM terms: this ends)
    twins: dict[str, tuple[str, tuple[str, ...]]] = {}
    known = {m.spec() for m in uniq}

    def flag(entries: Fits) -> list[Model]:
        new: list[Model] = []
        for m, r, _ in entries:
            if r is None:
                continue
            tw, labels = wn_twin(r.model, wv.fs)
            if labels and tw.processes:
                twins[m.spec()] = (tw.spec(), tuple(labels))
                if tw.spec() not in known:
                    known.add(tw.spec())
                    new.append(tw)
        return new

    added: set[str] = set()
    new_twins = flag(fitted)
    while new_twins:
        extra = fit_all(new_twins, weights, None)
        fitted += extra
        added |= {m.spec() for m in new_twins}
        new_twins = flag(extra)
    ok = [r for _, r, _ in fitted if r is not None]

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
        for k, fit_k in enumerate(ok):
            rows = [
                (nu, f[k])
                for nu, f in zip(nus, (p[1] for p in pairs), strict=True)
                if f[k] is not None
            ]
            a = np.array([x for x, _ in rows])
            b = np.array([y for _, y in rows])
            c = (a - a.mean(0)).T @ (b - b.mean(0)) / (len(rows) - 1)
            boot_opt[fit_k.model.spec()] = float(2.0 * np.trace(fit_k.omega @ c))
    elif optimism != "asymptotic":
        raise ValueError(f"unknown optimism {optimism!r}: use 'asymptotic' or 'bootstrap'")

    cands: list[Candidate] = []
    j_optima: dict[Any, Any] = {}  # the J-test refits share theirs too (one Omega = V^-1)
    for i, (m, r, err) in enumerate(fitted):
        tw, labels = twins.get(m.spec(), ("", ()))
        extra_fields: dict[str, Any] = {
            "sub_sample": labels,
            "twin": tw,
            "added": m.spec() in added,
            "changes": tuple(actionable(r)[1]) if r is not None else (),
        }
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
                    **extra_fields,
                )
            )
            continue
        opt = boot_opt[m.spec()] if optimism == "bootstrap" else _asymptotic_optimism(r, vmat)
        try:  # the calibrated J-test: efficient refit on the levels with enough coefficients
            jstat, df, _, _ = efficient_j(wv, r.model, vmat, j_optima)
            jp = float(stats.chi2.sf(jstat, df)) if df > 0 and not j_note else math.nan
        except (FitError, ModelError, np.linalg.LinAlgError):
            jstat, df, jp = math.nan, 0, math.nan
        if progress is not None and i < n_uniq:
            progress(rounds * n_uniq + i + 1, total)
        cands.append(
            Candidate(
                m.spec(),
                m.n_params,
                r.objective,
                opt,
                r.objective + opt,
                jstat,
                df,
                jp,
                r,
                **extra_fields,
            )
        )

    # a candidate with a term in disguise ranks as its twin, immediately after it, unless the
    # distance test rejects the fold (resolved through twins of twins)
    by_spec = {c.model: c for c in cands}
    for k, c in enumerate(cands):
        t = by_spec.get(c.twin) if c.twin else None
        if t is None or t.result is None:
            continue
        tp = math.nan  # no calibrated test (j_note): folded, as a disguised term is by default
        if math.isfinite(c.j_stat) and math.isfinite(t.j_stat) and not j_note:
            tp = float(stats.chi2.sf(t.j_stat - c.j_stat, max(t.j_df - c.j_df, 1)))
        cands[k] = dataclasses.replace(c, twin_p=tp, as_twin=not tp < DISGUISE_LEVEL)
    eff = _rank_criteria(cands)

    # candidates whose extra terms are fitted at zero tie with the smaller model: within a
    # relative 1e-6 of each other, the one with fewer parameters ranks first
    def order(a: Candidate, b: Candidate) -> int:
        ca, cb = eff[a.model], eff[b.model]
        if abs(ca - cb) > 1e-6 * max(abs(ca), abs(cb)):
            return -1 if ca < cb else 1
        return (
            (a.as_twin > b.as_twin) - (a.as_twin < b.as_twin)
            or (a.n_params > b.n_params) - (a.n_params < b.n_params)
            or ((a.model > b.model) - (a.model < b.model))
        )

    cands.sort(key=functools.cmp_to_key(order))
    wname = "efficient" if efficient else (weights if isinstance(weights, str) else "user")
    derived = _selection(wv, cands[0], weights, vmat, j_note)
    chosen = tie_choice(cands, derived if derived is not None else cands[0], vmat)
    return SelectionResult(
        cands,
        optimism,
        wname,
        time.perf_counter() - t0,
        selected=None if chosen is cands[0] else chosen,
        j_note=j_note,
        first_actionable=derived,
        v=vmat,
    )


def _rank_criteria(cands: list[Candidate]) -> dict[str, float]:
    """The criterion each candidate ranks by: its WVIC, or its WN twin's when it is ranked as
    its twin (resolved through twins of twins)."""
    by_spec = {c.model: c for c in cands}

    def rank_criterion(c: Candidate) -> float:
        seen = set()
        while c.as_twin and c.model not in seen:
            seen.add(c.model)
            c = by_spec[c.twin]
        return c.criterion

    return {c.model: rank_criterion(c) for c in cands}


def _structure(model: Model) -> Counter[str]:
    """The terms of a fitted model with a positive variance, counted by code."""
    return Counter(q.code for q in model.processes if q.linear_coef() > 0)


def wvic_se(c: GMWMResult, top: GMWMResult, opt_c: float, opt_top: float, v: np.ndarray) -> float:
    """Standard error of the WVIC difference of two fits with the same weights Omega
    (``c.objective + opt_c - top.objective - opt_top``; V the covariance of the WV).

    First order (delta method): the gradient of a fit's objective in the empirical WV is
    ``2 Omega (nu_hat - nu(theta_hat))``, so the difference's is ``2 Omega (nu_top - nu_c)``
    and its variance ``4 d' Omega V Omega d`` with ``d = nu_c - nu_top``. Second order, which
    dominates when the two implied WVs nearly coincide (nested models): the extra fit of
    ``k = |p_c - p_top|`` parameters lowers the objective by a sum of ``k`` chi-square(1)-like
    terms whose mean is half the optimisms' difference; with ``Omega = V^-1`` it is
    ``chi2(k)``, of standard deviation ``sqrt(2 k) = |optimism_c - optimism_top| / sqrt(2 k)``.
    """
    d = c.implied - top.implied
    w = top.omega
    first = 2.0 * math.sqrt(max(float(d @ w @ v @ w @ d), 0.0))
    k = max(abs(c.model.n_params - top.model.n_params), 1)
    return math.hypot(first, abs(opt_c - opt_top) / math.sqrt(2.0 * k))


def tie_choice(
    ranked: list[Candidate],
    selected: Candidate,
    v: np.ndarray,
    *,
    z: float = TIE_Z,
    slow_gm: float = SLOW_GM,
    gm_rw: float = GM_RW,
) -> Candidate:
    """The selection among the candidates that the WVIC does not tell apart from the first row.

    The WVIC has a sampling distribution: a candidate whose WVIC exceeds the first row's by at
    most ``z`` standard errors of the difference (delta method plus the second-order term of
    nested fits: docs/selection.md) is *tied* with it. Among
    the actionable ranked candidates tied with the first row (never one ranked as its WN
    twin), starting from ``selected`` (the first row, or the model a user can act on derived
    from it):

    1. **a random walk bounds the long scales** (the filter's horizon): when ``selected`` has
       no RW and a tie is ``selected`` with its drift DR, or its slowest AR1/GM if that one's
       correlation time exceeds ``slow_gm`` times the log's length, replaced by a RW, or
       ``selected`` with a RW added beside that AR1/GM if its correlation time exceeds
       ``gm_rw`` times the log's length, that tie is chosen (fewest parameters, then
       smallest WVIC);
    2. **the fewer parameters among over-fitted ties**: a tie whose terms are a strict part
       of the choice's (keeping its RW) replaces it (fewest parameters, then smallest WVIC).

    Parameters
    ----------
    ranked : list of Candidate
        The ranked candidates, first row first (:attr:`SelectionResult.candidates`).
    selected : Candidate
        The selection before the tie rules (the first row when it is actionable).
    v : ndarray (J, J)
        Covariance of the WV, the ranking's V.
    z : float
        The tie band in standard errors (:data:`TIE_Z`).
    slow_gm : float
        Fraction of the log's length beyond which a correlation time mimics a random walk
        (:data:`SLOW_GM`).
    gm_rw : float
        Fraction of the log's length beyond which a correlation time may hide a random walk
        beside it (:data:`GM_RW`: inf, off by default).

    Returns
    -------
    Candidate
        ``selected`` when no rule applies; else the tie chosen, with ``derived_from`` (the
        first row) and ``derivation`` (``selected``'s derivation, then what the rules did,
        with the WVIC difference and the band).
    """
    top, res = ranked[0], selected.result
    if top.result is None or res is None:
        return selected
    eff = _rank_criteria(ranked)
    ties: list[tuple[Candidate, Counter[str], str]] = []
    for c in ranked:
        if c.as_twin or not c.is_actionable or c.result is None:
            continue
        diff = eff[c.model] - eff[top.model]
        se = wvic_se(c.result, top.result, c.optimism, top.optimism, v)
        if diff <= z * se:
            ties.append(
                (c, _structure(c.result.model), f"WVIC {diff:+.3g} within {z:g} SE = {z * se:.3g}")
            )

    def pick(options: list[tuple[Candidate, Counter[str], str]]) -> tuple[Candidate, str]:
        c, _, how = min(options, key=lambda t: (t[0].n_params, eff[t[0].model]))
        return c, how

    cur, why = selected, list(selected.derivation)
    have = _structure(res.model)
    if not have["RW"]:
        swaps: list[tuple[Counter[str], str]] = []
        if have["DR"]:
            swaps.append((have - Counter(["DR"]) + Counter(["RW"]), "a RW for its drift DR"))
        slow = [
            (_correlation_time(q, res.wv.fs), q.code)
            for q in res.model.processes
            if q.nonlinear is not None and q.linear_coef() > 0
        ]
        slow = [t for t in slow if not math.isnan(t[0])]
        tc, code = max(slow) if slow else (0.0, "")
        if slow and tc > slow_gm * res.wv.n:
            what = f"a RW for its {code} of {tc:.3g} samples"
            swaps.append((have - Counter([code]) + Counter(["RW"]), what))
        if slow and tc > gm_rw * res.wv.n:
            what = f"a RW beside its {code} of {tc:.3g} samples ({tc / res.wv.n:.2g} of the log)"
            swaps.append((have + Counter(["RW"]), what))
        for target, what in swaps:
            options = [t for t in ties if t[1] == target]
            if options:
                c, how = pick(options)
                why.append(f"{c.model} for {cur.model}: {what}, tied ({how})")
                cur, have = c, target
                break
    parts = [
        t
        for t in ties
        if t[1] != have and all(t[1][k] <= have[k] for k in t[1]) and (t[1]["RW"] or not have["RW"])
    ]
    if parts:
        c, how = pick(parts)
        why.append(f"{c.model} for {cur.model}: fewer parameters, tied ({how})")
        cur = c
    if cur is selected:
        return selected
    return dataclasses.replace(cur, derived_from=top.model, derivation=tuple(why))


def _selection(
    wv: WaveletVariance,
    top: Candidate,
    weights: str | np.ndarray,
    vmat: np.ndarray,
    j_note: str = "",
) -> Candidate | None:
    """The model a user can act on derived from the top-ranked candidate (None when it is
    one): :func:`actionable` applied until nothing changes. Not refitted: a refit of the
    structure puts a term back below one sample where the data favour it (on the ADIS16405
    gyros, whose filter correlates neighbouring samples, every GM slides there), and a refit
    of the variances alone at the kept correlation times lets the finest scale (the
    largest weight, where the filter shows) pull WN 30 % below the WV at 1 s."""
    from scipy import stats

    if top.result is None or top.is_actionable:
        return None
    res, derivation = top.result, []
    while True:
        model, changes = actionable(res)
        if not changes or not model.processes:
            break
        derivation += changes
        res = fit_gmwm(wv, model, weights=weights, fixed=True)
    opt = _asymptotic_optimism(res, vmat)
    try:
        jstat, df, _, _ = efficient_j(wv, res.model.cleared(), vmat)
        jp = float(stats.chi2.sf(jstat, df)) if df > 0 and not j_note else math.nan
    except (FitError, ModelError, np.linalg.LinAlgError):
        jstat, df, jp = math.nan, 0, math.nan
    return Candidate(
        res.model.spec(),
        res.model.n_params,
        res.objective,
        opt,
        res.objective + opt,
        jstat,
        df,
        jp,
        res,
        changes=tuple(actionable(res)[1]),
        derived_from=top.model,
        derivation=tuple(derivation),
    )
