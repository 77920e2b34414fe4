"""The projection rule and the over-bound of :mod:`engine.formats.projection`: which fitted
terms are white at the filter step and which form the bias (:func:`split_terms`), the
consumers' WV columns (:func:`columns`), the least inflation (:func:`least_inflation`) and
one projection of a model (:func:`solve`). Quantities are per log sample, in the log's unit;
:func:`engine.formats.projection.project` converts them to the consumer's units.

**Least inflation.** Among the consumer models whose WV is at least the target (the fitted WV,
or its upper confidence limit) at every scale of a fine grid of the band (:func:`fine_scales`),
the bound takes the one with the least geometric-mean ratio consumer WV / target over the
band's scales (``POINTS_PER_OCTAVE`` per octave): it minimises the integral over log-scale of
``log(consumer WV / target)``, the log of the mean inflation factor, so a factor 2 too much at
0.1 s costs what it costs at 1000 s. The consumer's WV is linear in its variances ``x``, so the
feasible set ``A x >= t, x >= 0`` is a polyhedron, and ``sum_j log(a_j . x)`` is concave: its
minimum is at a vertex, and with one or two variances (WN; WN+RW; WN+GM at a given ``T_c``)
the vertices are the breakpoints of the feasible set's lower boundary, enumerated exactly
(:func:`lower_vertices`). A Gauss-Markov bias adds a 1-D search over ``T_c``.

Why not a linear objective: the mean *ratio* (the integrated relative excess, an LP) lets the
longest scales dominate (a random walk's excess grows with the scale), and on the ADIS16405
gyro it puts the slow GM into white noise (N x1.9): a filter with fixes every 1-10 s is then
twice too cautious (mean NEES 0.47). The sum of squared factors over the plain conversion
(the first design) depends on the plain conversion's scale: with the ADIS16405 accelerometer's
0.29 s GM the plain K is 20x the data's, so K x9 looked cheap (mean NEES 0.2 at 10 s fixes).
The geometric mean keeps both filters consistent (tests/engine/test_filter_consistency.py,
docs/fit-to-filter.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._optim import chi2_isf
from ..models import Model, ar1_wv
from ..units import ExportError

__all__ = [
    "POINTS_PER_OCTAVE",
    "Split",
    "split_terms",
    "target_ratio",
    "target_model",
    "target_wv",
    "floor_at",
    "fine_scales",
    "columns",
    "lower_vertices",
    "least_inflation",
    "solve",
    "nearby_solutions",
    "solve_at_tcs",
]

#: Scales of the objective per octave (the bound holds on an 8x finer grid, fine_scales).
POINTS_PER_OCTAVE = 6


@dataclass
class Split:
    """The fitted terms after the rule: the white part (per log sample) and the bias terms."""

    wn: float  # per log sample, native unit^2
    fast: list[tuple[str, Any]]  # processes that went to WN
    rw_k2: float  # continuous K^2 of RW + slow GMs + drift equivalent (native)
    slow: list[tuple[str, float, float]]  # (label, beta, sigma2_gm), most persistent first
    gamma2: float  # RW per sample
    omega: float  # drift per sample
    assignment: dict[str, str]


def split_terms(model: Model, fs: float, fs_f: float, tau_h: float) -> Split:
    """Apply the rule: which fitted terms are white at the filter step, which are bias."""
    sp = Split(0.0, [], 0.0, [], 0.0, 0.0, {})
    for lab, p in zip(model.labels, model.processes, strict=True):
        t = p.filter_terms(fs, fs_f, tau_h)  # each process's own rule
        sp.wn += t.white
        if t.fast:
            sp.fast.append((lab, p))
        if t.slow is not None:
            sp.slow.append((lab, *t.slow))
        sp.rw_k2 += t.rw_k2
        sp.gamma2 += t.gamma2
        if t.omega is not None:
            sp.omega = t.omega
        sp.assignment[lab] = t.assignment
    sp.slow.sort(key=lambda t: t[1])
    return sp


def target_ratio(tau: np.ndarray, n: int, confidence: float | None) -> np.ndarray:
    """Target / fitted WV: 1, or the upper limit of the eta3 interval at ``confidence``,
    ``eta / chi2_{(1-c)/2}(eta)`` with ``eta = max((n - tau + 1) / tau, 1)``
    (``docs/conventions.md``)."""
    if confidence is None:
        return np.ones_like(tau)
    eta = np.maximum((n - tau + 1.0) / tau, 1.0)
    return eta / chi2_isf(eta, 1.0 - (1.0 - float(confidence)) / 2.0)


def target_model(model: Model, sp: Split, consumer: str) -> Model | None:
    """The model whose WV the consumer bounds: the fitted model, or for the ``WN`` consumer
    its terms that are white at the filter step (None: none is)."""
    if consumer == "WN":
        return Model(tuple(p for _, p in sp.fast)) if sp.fast else None
    return model


def target_wv(
    tmodel: Model | None,
    t: np.ndarray,
    fs: float,
    n: int,
    confidence: float | None,
    floor: tuple[np.ndarray, np.ndarray] | None,
) -> np.ndarray:
    """The bound's target at scales ``t`` (log samples): the WV of ``tmodel`` (0 for None)
    times :func:`target_ratio`, and at least the empirical ``floor`` (:func:`floor_at`)."""
    base = tmodel.wv(t, fs) if tmodel is not None else np.zeros_like(t)
    base = base * target_ratio(t, n, confidence)
    if floor is None:
        return base
    return np.maximum(base, floor_at(t, *floor))


def floor_at(t: np.ndarray, tau_d: np.ndarray, wv_d: np.ndarray) -> np.ndarray:
    """The empirical floor ``wv_d`` at the scales of ``t`` that are among its dyadic scales
    ``tau_d`` (log samples), 0 elsewhere."""
    t = np.asarray(t, float)
    out = np.zeros_like(t)
    if tau_d.size == 0:
        return out
    i = np.clip(np.searchsorted(tau_d, t), 0, tau_d.size - 1)
    hit = np.isclose(tau_d[i], t, rtol=1e-9, atol=0.0)
    out[hit] = wv_d[i[hit]]
    return out


def fine_scales(tau: np.ndarray) -> np.ndarray:
    """Every even scale between the band's ends up to 8 x POINTS_PER_OCTAVE per octave."""
    k = int(math.ceil(8 * POINTS_PER_OCTAVE * math.log2(tau[-1] / tau[0]))) + 1
    return np.unique(np.concatenate([tau, 2.0 * np.round(np.geomspace(tau[0], tau[-1], k) / 2)]))


def columns(consumer: str, tau: np.ndarray, fs: float, tc: float | None) -> np.ndarray:
    """WV per unit variance of the consumer's terms (per log sample) at scales ``tau``."""
    cols = [1.0 / tau]
    if consumer == "WN+RW":
        cols.append((tau**2 + 2.0) / (12.0 * tau))
    elif consumer == "WN+GM":
        if tc is None:
            raise ValueError("columns: the WN+GM consumer needs tc, its correlation time [s]")
        phi = math.exp(-1.0 / (fs * tc))
        cols.append(ar1_wv(tau, phi, 1.0 - phi * phi))
    return np.column_stack(cols)


def lower_vertices(b: np.ndarray) -> np.ndarray:
    """The vertices of ``{y >= 0 : b y >= 1}`` for one or two columns, one per row.

    One column: the least ``y = max_j 1 / b_j``. Two columns: a constraint row ``b_j`` is
    tight somewhere on the lower boundary only if it minimises ``y . b`` over the rows for
    some direction ``y >= 0``, i.e. if it lies on the lower-left convex hull of the rows (a
    row dominated by another, or above the chord of two others, is implied by them). The
    rows are reduced to their Pareto-minimal ones (sorted by ``b_0``, ``b_1`` strictly
    decreasing), then to their lower convex hull (Andrew's monotone chain); consecutive hull
    rows meet at the vertices. From ``y0 = 0``
    (``y1 = 1 / min b_1``) to ``y1 = 0`` (``y0 = 1 / min b_0``). ``O(n log n)``, vectorised
    (the earlier walk along the envelope was ``O(n^2)``: 0.13 s for the 900 rows of a
    six-decade band). ``b`` must be positive and finite."""
    if b.shape[1] == 1:
        return np.array([[1.0 / float(np.min(b[:, 0]))]])
    p = b[np.lexsort((b[:, 1], b[:, 0]))]  # b0 ascending, ties b1 ascending
    prev = np.minimum.accumulate(np.concatenate([[np.inf], p[:-1, 1]]))
    p = p[p[:, 1] < prev]  # Pareto-minimal: b0 increasing, b1 strictly decreasing
    # lower convex hull: two vectorised passes drop the points on or above the chord of their
    # neighbours (most of them), then Andrew's monotone chain on what is left
    for _ in range(2):
        if p.shape[0] < 3:
            break
        d1, d2 = p[1:-1] - p[:-2], p[2:] - p[1:-1]
        bad = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] <= 0.0  # not a left turn
        p = np.delete(p, 1 + np.flatnonzero(bad), axis=0)
    xs, ys = p[:, 0].tolist(), p[:, 1].tolist()
    hull: list[int] = []
    for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
        while len(hull) >= 2:
            o, m = hull[-2], hull[-1]
            if (xs[m] - xs[o]) * (y - ys[m]) - (ys[m] - ys[o]) * (x - xs[m]) > 0.0:
                break
            hull.pop()
        hull.append(i)
    p = p[hull]
    a, c = p[1:][::-1], p[:-1][::-1]  # consecutive hull rows, from the y0 = 0 end
    det = a[:, 0] * c[:, 1] - a[:, 1] * c[:, 0]
    mid = np.column_stack([(c[:, 1] - a[:, 1]) / det, (a[:, 0] - c[:, 0]) / det])
    return np.vstack([[0.0, 1.0 / p[-1, 1]], mid, [1.0 / p[0, 0], 0.0]])


def least_inflation(
    a_con: np.ndarray, t_con: np.ndarray, a_obj: np.ndarray, t_obj: np.ndarray
) -> tuple[np.ndarray, float]:
    """The consumer's variances ``x >= 0`` with ``A_con x >= t_con`` and the least
    ``mean_j log((A_obj x)_j / t_obj_j)`` (module docstring).

    Parameters
    ----------
    a_con, t_con : ndarray
        Columns and target at the scales where the bound must hold (zero targets hold
        trivially).
    a_obj, t_obj : ndarray
        Columns and target at the band's scales (``POINTS_PER_OCTAVE`` per octave) of the
        objective.

    Returns
    -------
    x : ndarray
        Per-sample variances (nan when the columns are not usable, e.g. a Gauss-Markov
        column out of numerical range).
    log_excess : float
        The objective at ``x``: the log of the geometric-mean ratio consumer WV / target
        over the band (inf when not usable).
    """
    nc = a_con.shape[1]
    if nc > 2:
        raise ValueError("least_inflation handles one or two consumer variances")
    bad = (np.full(nc, np.nan), math.inf)
    # (min and max propagate a nan: one reduction each instead of elementwise tests)
    if not (a_con.min() > 0 and a_con.max() < math.inf and a_obj.min() > 0):
        return bad
    ok = t_con > 0
    if not ok.any():
        return np.zeros(nc), 0.0
    if not ok.all():
        a_con, t_con = a_con[ok], t_con[ok]
    b = a_con / t_con[:, None]
    s = b.max(axis=0)  # y = x s: the columns of b / s are at most 1
    verts = lower_vertices(b / s) / s
    keep = t_obj > 0
    if not keep.all():
        a_obj, t_obj = a_obj[keep], t_obj[keep]
    vals = np.mean(np.log((a_obj @ verts.T) / t_obj[:, None]), axis=0)
    # the consumers need white noise: a vertex without it is taken only when no other exists
    vals = np.where((verts[:, 0] > 0) | ~np.any(verts[:, 0] > 0), vals, np.inf)
    k = int(np.argmin(vals))
    x = verts[k]
    # rounding: scale up so that the bound holds at every constraint scale
    short = float(np.max(t_con / (a_con @ x)))
    return x * max(short, 1.0), float(vals[k])


#: Tolerance of the ``T_c`` search in ``log T_c``.
_XATOL = 1e-4
#: Golden-section step (the shorter part of a golden cut of 1).
_GOLD = (3.0 - math.sqrt(5.0)) / 2.0


def _bracketed_min(f: Any, a: float, b: float, c: float, fb: float, xatol: float) -> float:
    """A local minimum of ``f`` in ``[a, c]`` to ``xatol``, from a bracket ``a < b < c`` with
    ``f(b) = fb`` not above ``f(a)`` and ``f(c)``: golden-section search, which keeps the
    best point inside the bracket, so it ends at a local minimum whose value is at most
    ``fb`` (scipy's bounded search starts from its own golden points and can settle in
    another basin of the interval, above ``fb``)."""
    while c - a > xatol:
        x = b + _GOLD * (c - b) if c - b > b - a else b - _GOLD * (b - a)
        fx = float(f(x))
        if fx < fb:
            a, c = (b, c) if x > b else (a, b)
            b, fb = x, fx
        elif x > b:
            c = x
        else:
            a = x
    return b


def solve(
    model: Model,
    fs: float,
    fs_f: float,
    consumer: str,
    tau: np.ndarray,
    n: int,
    confidence: float | None,
    tau_h: float,
    bound: bool,
    floor: tuple[np.ndarray, np.ndarray] | None = None,
    tc_fix: float | None = None,
    tc_near: float | None = None,
) -> dict[str, Any]:
    """The projection of one model: plain and bounded variances (native unit, per sample).

    ``floor`` is ``(tau, wv)``: an empirical WV (a limit of its interval, or the estimate) at
    dyadic scales ``tau`` (log samples) that the consumer's WV must also reach there; the
    target is the larger of the fitted model's and this floor at those scales. ``tc_fix`` (s)
    fixes a Gauss-Markov bias's correlation time (no search): a file that takes one ``T_c``
    for several channels. ``tc_near`` (s) starts the ``T_c`` search at a known optimum of a
    nearby model (the perturbed models of the intervals' derivatives): the search runs
    within +-5 % of it instead of the whole grid (the whole grid when the optimum leaves that
    bracket).

    Returns a dictionary with ``split`` (:class:`Split`), ``plain`` (the plain conversion),
    ``target_at`` (the target WV as a function of scales), ``target`` (at ``tau``), ``x``
    (the exported variances per log sample), ``T_c`` (s; WN+GM only) and, when bounded, ``A``
    (the columns at ``tau``), ``log_excess`` (:func:`least_inflation`), ``fine`` and
    ``fine_target`` (the scales where the bound holds and the target there) and ``searched``
    (whether ``T_c`` was searched): what :func:`nearby_solutions` starts from."""
    sp = split_terms(model, fs, fs_f, tau_h)
    out: dict[str, Any] = {"split": sp}
    # plain conversion (per log sample)
    plain: dict[str, float] = {"sigma2": sp.wn}
    if consumer == "WN+RW":
        plain["gamma2"] = sp.rw_k2 / fs
    elif consumer == "WN+GM":
        tc = 1.0 / sp.slow[0][1] if sp.slow else tau_h / fs
        plain["T_c"] = tc
        plain["sb2"] = sp.rw_k2 * tc / 2.0
    out["plain"] = plain
    tmodel = target_model(model, sp, consumer)

    def target_at(t: np.ndarray) -> np.ndarray:
        return target_wv(tmodel, t, fs, n, confidence, floor)

    target = target_at(tau)
    out["target_at"] = target_at
    out["target"] = target
    if not bound:
        given = [plain["sigma2"]]
        if consumer == "WN+RW":
            given.append(plain["gamma2"])
        elif consumer == "WN+GM":
            given.append(plain["sb2"])
        out["x"], out["T_c"] = np.array(given), plain.get("T_c")
        return out
    fine = fine_scales(tau)
    ft = target_at(fine)
    at = np.searchsorted(fine, tau)  # tau is among the fine scales: their columns are shared
    out["tau"], out["fine"], out["fine_target"], out["searched"] = tau, fine, ft, False
    if consumer != "WN+GM":
        af = columns(consumer, fine, fs, None)
        a = af[at]
        x, f = least_inflation(af, ft, a, target)
        # a plain conversion that already bounds the fit at every fine scale and costs no
        # more than the optimum is kept exactly (e.g. a WN+RW fit for a WN+RW consumer)
        xp = np.array([plain["sigma2"], *([plain["gamma2"]] if consumer == "WN+RW" else [])])
        keep = target > 0
        if np.all(xp > 0) and np.all(af @ xp >= ft) and np.any(keep):
            fp = float(np.mean(np.log((a[keep] @ xp) / target[keep])))
            if fp <= f + 1e-9:
                x, f = xp, fp
        out["x"], out["T_c"], out["A"], out["log_excess"] = x, None, a, f
        return out
    if tc_fix is not None:
        af = columns(consumer, fine, fs, tc_fix)
        a = af[at]
        x, f = least_inflation(af, ft, a, target)
        if not math.isfinite(f):
            raise ExportError(
                f"no Gauss-Markov bias of T_c {tc_fix:g} s bounds the WV over the band"
            )
        out["x"], out["T_c"], out["A"], out["log_excess"] = x, float(tc_fix), a, f
        return out
    # Gauss-Markov bias: 1-D search over log T_c of the least inflation, from the band's
    # shortest scale to ten horizons
    from scipy.optimize import minimize_scalar

    lo, hi = math.log(tau[0] / fs), math.log(10.0 * max(tau[-1], tau_h) / fs)

    def obj(lt: float) -> float:
        af_ = columns(consumer, fine, fs, math.exp(lt))
        return least_inflation(af_, ft, af_[at], target)[1]

    grid = np.linspace(lo, hi, 16)
    lt = math.nan
    if tc_near is not None and lo < math.log(tc_near) < hi:
        a_, b_ = max(math.log(tc_near) - 0.05, lo), min(math.log(tc_near) + 0.05, hi)
        r = minimize_scalar(obj, bounds=(a_, b_), method="bounded", options={"xatol": _XATOL})
        x_ = float(r.x)
        inside = (a_ == lo or x_ > a_ + 1e-3) and (b_ == hi or x_ < b_ - 1e-3)
        if inside and math.isfinite(float(r.fun)):
            lt = float(r.x)
    if not math.isfinite(lt):
        vals = [obj(g) for g in grid]
        k = int(np.argmin(vals))
        if not math.isfinite(vals[k]):
            raise ExportError("no Gauss-Markov bias bounds the fitted WV over the band")
        a_, b_ = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        r = minimize_scalar(obj, bounds=(a_, b_), method="bounded", options={"xatol": _XATOL})
        if r.fun <= vals[k]:
            lt = float(r.x)
        elif 0 < k < grid.size - 1:
            # the bounded search went into another basin (two minima between the grid's
            # neighbours, e.g. ADIS16405 accel_x) and ended above the grid point, where the
            # objective may still be falling: the bracketed search keeps its best point
            lt = _bracketed_min(obj, float(a_), float(grid[k]), float(b_), float(vals[k]), _XATOL)
        else:
            lt = float(grid[k])
    tc = math.exp(lt)
    af = columns(consumer, fine, fs, tc)
    a = af[at]
    x, f = least_inflation(af, ft, a, target)
    out["x"], out["T_c"], out["A"], out["log_excess"] = x, tc, a, f
    out["searched"], out["lt_range"] = True, (lo, hi)
    return out


def solve_at_tcs(
    model: Model,
    fs: float,
    fs_f: float,
    tau: np.ndarray,
    n: int,
    confidence: float | None,
    tau_h: float,
    floor: tuple[np.ndarray, np.ndarray] | None,
    tcs: Sequence[float],
) -> list[dict[str, Any] | None]:
    """The bounded ``WN+GM`` projection at each fixed ``T_c`` of ``tcs`` (s), as
    ``solve(..., tc_fix=c)`` gives its ``x`` and ``log_excess``, with the target computed
    once (None where no bias of that ``T_c`` bounds the WV)."""
    tm = target_model(model, split_terms(model, fs, fs_f, tau_h), "WN+GM")
    target = target_wv(tm, tau, fs, n, confidence, floor)
    fine = fine_scales(tau)
    ft = target_wv(tm, fine, fs, n, confidence, floor)
    at = np.searchsorted(fine, tau)
    out: list[dict[str, Any] | None] = []
    for c in tcs:
        af = columns("WN+GM", fine, fs, float(c))
        x, f = least_inflation(af, ft, af[at], target)
        out.append({"x": x, "log_excess": f} if math.isfinite(f) else None)
    return out


#: Rows of the bound within this relative slack of the target are tight (a vertex's rows are
#: tight to rounding, about 1e-15).
_TIGHT = 1e-11
#: How far (in log T_c) the searched optimum may lie from the one the search returned: its
#: tolerance (:data:`_XATOL`) with a margin.
_NEAR_LT = 5e-3
#: Rows within this relative slack are checked at every moved model's solution (a moved
#: model's targets move by about 1e-3, its T_c by as much).
_NEAR_SLACK = 2e-2
#: A moved solution may miss such a row by this much (relative to its target): the kink's
#: row is tight at the moved T_c only to second order in the step (1e-9), and the fine
#: grid's neighbours of a tight row, nearly the same constraint, by up to 4e-6 on the
#: ADIS16405 accelerometers, where the intervals' ends then agree with every moved model
#: searched afresh to 1e-11 within 8e-4. A row missed by more (a row 1e-5 short of tight
#: that the step's 1e-3 makes binding) changes the vertex within the step.
_MISSED = 1e-5


def nearby_solutions(
    sol: dict[str, Any],
    models: Sequence[Model],
    fs: float,
    fs_f: float,
    consumer: str,
    n: int,
    confidence: float | None,
    tau_h: float,
    floor: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[dict[str, Any]] | None:
    """The bounded projections of models close to the one ``sol`` solved (the perturbed
    models of the intervals' derivatives), with the solution's tight constraints kept.

    A bounded solution is a vertex: ``x = B^-1 t_B`` with ``B`` the consumer's columns and
    ``t_B`` the target at its tight rows (two rows for two variances, one for WN). A nearby
    model moves ``t_B`` only, so its solution is one 2x2 solve, not a new least-inflation
    problem. With a searched ``T_c`` (``lt = log T_c``) the optimum either is a stationary
    point of the objective ``F(lt)`` along that vertex (``dF/dlt = 0``) or sits where a third
    row becomes tight (``a_j(lt) . x(lt) = t_j``, a kink of ``F``); the nearby model's ``lt``
    is one Newton step of that condition from the base optimum (error of second order in the
    model's change) and its ``x`` the vertex there. The base optimum is first refined from
    the search's (tolerance 1e-4 in ``lt``) to the condition's root; the exported values
    stay the search's.

    Returns
    -------
    list of dict or None
        Per model, ``x`` and ``T_c`` as :func:`solve` gives them; None when the solution is
        not such a vertex (an unbounded or plain solution, a variance at 0, more tight rows
        than variances, an optimum that the conditions do not reproduce) or when a moved
        model's solution misses a row that was near tight (the vertex changes within the
        step: on the ADIS16405 accel_z at one fixed T_c a row 1e-5 short of tight): then
        solve each model with :func:`solve`.
    """
    if "fine" not in sol or sol.get("x") is None:
        return None
    fine, ft = sol["fine"], sol["fine_target"]
    x0 = np.asarray(sol["x"], float)
    tc = sol["T_c"]
    if not (np.all(np.isfinite(x0)) and np.all(x0 > 0)):
        return None
    nc = x0.size
    ok = ft > 0
    af = columns(consumer, fine, fs, tc)
    ratio = np.full(fine.size, np.inf)
    ratio[ok] = (af[ok] @ x0) / ft[ok]
    rows = np.flatnonzero(ratio <= 1.0 + _TIGHT)
    if rows.size != nc:
        return None
    # the rows a moved model could make binding: its solution must hold there too, or the
    # vertex changes within the derivative's step (a row short of tight by less than the
    # step moves the targets), and each moved model is solved afresh, as before
    near = np.flatnonzero(ratio <= 1.0 + _NEAR_SLACK)
    tms = [target_model(m, split_terms(m, fs, fs_f, tau_h), consumer) for m in models]
    tn = np.array([target_wv(tm, fine[near], fs, n, confidence, floor) for tm in tms])
    tb = tn[:, np.searchsorted(near, rows)]
    if not sol.get("searched"):
        xs = np.linalg.solve(af[rows], tb.T).T
        out = [{"x": xi, "T_c": tc} for xi in xs] if np.all(xs > 0) else None
    else:
        out = _near_searched(sol, tms, tb, rows, fs, consumer, n, confidence, floor)
    if out is None:
        return None
    worst = 0.0
    for s, t in zip(out, tn, strict=True):
        a = columns(consumer, fine[near], fs, s["T_c"])
        worst = max(worst, float(np.max(1.0 - (a @ s["x"]) / t)))
    if worst > _MISSED:
        return None
    return out


def _near_searched(
    sol: dict[str, Any],
    tms: list[Model | None],
    tb: np.ndarray,
    rows: np.ndarray,
    fs: float,
    consumer: str,
    n: int,
    confidence: float | None,
    floor: tuple[np.ndarray, np.ndarray] | None,
) -> list[dict[str, Any]] | None:
    """:func:`nearby_solutions` with a searched ``T_c`` (its docstring)."""
    fine, ft, tau = sol["fine"], sol["fine_target"], sol["tau"]
    keep = sol["target"] > 0
    tau_o, t_o = tau[keep], sol["target"][keep]
    fb = fine[rows]
    tb0 = ft[rows][None, :]
    ok = ft > 0

    def xb(lt: float, t: np.ndarray) -> np.ndarray:  # the vertex of the tight rows, per target
        return np.linalg.solve(columns(consumer, fb, fs, math.exp(lt)), t.T).T

    def obj(lt: float, t: np.ndarray) -> np.ndarray:  # the objective along that vertex
        a = columns(consumer, tau_o, fs, math.exp(lt))
        return np.mean(np.log((a @ xb(lt, t).T) / t_o[:, None]), axis=0)

    e = 1e-4

    def grad(lt: float, t: np.ndarray) -> np.ndarray:
        return (obj(lt + e, t) - obj(lt - e, t)) / (2 * e)

    def curv(lt: float) -> float:
        f = [float(obj(lt + d, tb0)[0]) for d in (-e, 0.0, e)]
        return (f[0] - 2 * f[1] + f[2]) / (e * e)

    def slack(lt: float) -> np.ndarray:  # each fine row's WV over its target, minus 1
        r = np.full(fine.size, np.inf)
        r[ok] = (columns(consumer, fine[ok], fs, math.exp(lt)) @ xb(lt, tb0)[0]) / ft[ok] - 1.0
        return r

    lt_s = math.log(sol["T_c"])
    lo, hi = sol["lt_range"]
    if min(lt_s - lo, hi - lt_s) < _NEAR_LT:
        # the search's optimum at an end of its range, where the objective falls towards that
        # end: T_c stays there (the vertex of the moved targets at the search's T_c)
        out_dir = 1.0 if hi - lt_s < lt_s - lo else -1.0
        if float(grad(lt_s, tb0)[0]) * out_dir > 0:
            return None
        xs = xb(lt_s, tb)
        return [{"x": xi, "T_c": sol["T_c"]} for xi in xs] if np.all(xs > 0) else None
    # the stationary point along the vertex (Newton), within the search's tolerance
    lt, c2 = lt_s, math.nan
    for _ in range(6):
        c2 = curv(lt)
        if not c2 > 0:
            break
        step = float(grad(lt, tb0)[0]) / c2
        lt = min(max(lt - step, lt_s - _NEAR_LT), lt_s + _NEAR_LT)
        if abs(step) < 1e-11:
            break
    r = slack(lt)
    kink = None
    if not (c2 > 0 and np.min(r) >= -1e-9):
        # the vertex stops being feasible first where a third row becomes tight: the kink
        d = lt - lt_s if lt != lt_s else -math.copysign(_NEAR_LT, float(grad(lt_s, tb0)[0]))
        r = slack(lt_s + d)
        r0 = slack(lt_s)
        bad = np.flatnonzero(r < -1e-12)
        if bad.size == 0:
            return None
        cross = r0[bad] / (r0[bad] - r[bad])  # linear guess of where each row turns tight
        j = int(bad[int(np.argmin(cross))])

        def h(lt_: float, t: np.ndarray, tj: np.ndarray) -> np.ndarray:
            a = columns(consumer, fine[j : j + 1], fs, math.exp(lt_))[0]
            return (xb(lt_, t) @ a) / tj - 1.0

        tj0 = ft[j : j + 1]
        h0, h1 = float(h(lt_s, tb0, tj0)[0]), float(h(lt_s + d, tb0, tj0)[0])
        if abs(h0) < 1e-12:
            lt = lt_s
        elif h0 > 0 > h1:
            from scipy.optimize import brentq

            lt = float(brentq(lambda v: float(h(v, tb0, tj0)[0]), lt_s, lt_s + d, xtol=1e-14))
        else:
            return None
        if np.min(slack(lt)) < -1e-9:
            return None
        kink = (j, h)
    # the structure must give the search's optimum: the least-inflation problem at lt picks
    # this vertex, and its objective is not above the search's
    af = columns(consumer, fine, fs, math.exp(lt))
    f_v = float(obj(lt, tb0)[0])
    f_best = least_inflation(af, ft, af[np.searchsorted(fine, tau)], sol["target"])[1]
    if not (f_v <= f_best + 1e-10 and f_v <= sol["log_excess"] + 1e-10):
        return None
    # each nearby model: one Newton step of the optimum's condition from lt
    if kink is None:
        lts = lt - grad(lt, tb) / curv(lt)
    else:
        j, h = kink
        tj = np.array([target_wv(tm, fine[j : j + 1], fs, n, confidence, floor)[0] for tm in tms])
        dh = float((h(lt + 1e-6, tb0, ft[j : j + 1]) - h(lt - 1e-6, tb0, ft[j : j + 1]))[0])
        lts = lt - h(lt, tb, tj) / (dh / 2e-6)
    out = []
    for lt_m, t in zip(lts.tolist(), tb, strict=True):
        x = xb(lt_m, t[None, :])[0]
        if not np.all(x > 0):
            return None
        out.append({"x": x, "T_c": math.exp(lt_m)})
    return out
