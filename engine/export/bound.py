"""The projection rule and the over-bound of :mod:`engine.export.projection`: which fitted
terms are white at the filter step and which form the bias (:func:`split_terms`), the
consumers' WV columns (:func:`columns`), the least-inflation linear programme
(:func:`least_inflation_lp`) with cutting planes on a fine grid of scales (:func:`refine`),
and one projection of a model (:func:`solve`). Quantities are per log sample, in the log's
unit; :func:`engine.export.projection.project` converts them to the consumer's units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._optim import chi2_isf
from ..models import Model, ar1_wv
from ..units import ExportError

__all__ = [
    "POINTS_PER_OCTAVE",
    "Split",
    "gm_of",
    "split_terms",
    "target_ratio",
    "fine_scales",
    "refine",
    "columns",
    "least_inflation_lp",
    "solve",
]

#: Scales of the bound per octave (the cutting planes add scales of an 8x finer grid).
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


def gm_of(p: Any, fs: float) -> tuple[float, float]:
    """(phi, stationary variance) of a GM or AR1 process."""
    if p.code == "GM":
        return math.exp(-float(p.beta) / fs), float(p.sigma2_gm)
    phi = float(p.phi)
    return phi, float(p.sigma2) / (1.0 - phi * phi)


def split_terms(model: Model, fs: float, fs_f: float, tau_h: float) -> Split:
    """Apply the rule: which fitted terms are white at the filter step, which are bias."""
    dt_f = 1.0 / fs_f
    m = max(fs / fs_f, 1.0)
    sp = Split(0.0, [], 0.0, [], 0.0, 0.0, {})
    for lab, p in zip(model.labels, model.processes, strict=True):
        if p.code == "WN":
            sp.wn += float(p.sigma2)
            sp.fast.append((lab, p))
            sp.assignment[lab] = "WN"
        elif p.code == "QN":
            sp.wn += 3.0 * float(p.q2) / m
            sp.fast.append((lab, p))
            sp.assignment[lab] = "WN (QN's white equivalent at the filter rate, 3 q2 / m)"
        elif p.code in ("GM", "AR1"):
            phi, s2 = gm_of(p, fs)
            tc = -1.0 / (fs * math.log(phi)) if 0.0 < phi < 1.0 else 0.0
            if tc < dt_f:
                sp.wn += s2 * (1.0 + phi) / (1.0 - phi)
                sp.fast.append((lab, p))
                sp.assignment[lab] = (
                    f"WN (T_c {tc:.3g} s < filter step {dt_f:.3g} s: white noise, "
                    "equivalent sigma2_gm (1+phi)/(1-phi))"
                )
            else:
                beta = 1.0 / tc
                sp.slow.append((lab, beta, s2))
                sp.rw_k2 += 2.0 * beta * s2
                sp.assignment[lab] = f"bias (T_c {tc:.4g} s >= filter step)"
        elif p.code == "RW":
            sp.gamma2 += float(p.gamma2)
            sp.rw_k2 += float(p.gamma2) * fs
            sp.assignment[lab] = "bias"
        elif p.code == "DR":
            om = float(p.omega)
            sp.omega = om
            sp.rw_k2 += 0.75 * om * om * tau_h * fs  # RW with the drift's WV at the horizon
            sp.assignment[lab] = "bias (random walk with the drift's WV at the horizon)"
        else:  # pragma: no cover - every process code is handled above
            raise ExportError(f"no projection rule for process {p.code}")
    sp.slow.sort(key=lambda t: t[1])
    return sp


def target_ratio(tau: np.ndarray, n: int, confidence: float | None) -> np.ndarray:
    """Target / fitted WV: 1, or the upper limit of the eta3 interval at ``confidence``,
    ``eta / chi2_{(1-c)/2}(eta)`` with ``eta = max((n - tau + 1) / tau, 1)`` (CONVENTIONS)."""
    if confidence is None:
        return np.ones_like(tau)
    eta = np.maximum((n - tau + 1.0) / tau, 1.0)
    return eta / chi2_isf(eta, 1.0 - (1.0 - float(confidence)) / 2.0)


def fine_scales(tau: np.ndarray) -> np.ndarray:
    """Every even scale between the band's ends up to 8 x POINTS_PER_OCTAVE per octave."""
    k = int(math.ceil(8 * POINTS_PER_OCTAVE * math.log2(tau[-1] / tau[0]))) + 1
    return np.unique(np.concatenate([tau, 2.0 * np.round(np.geomspace(tau[0], tau[-1], k) / 2)]))


def refine(
    a_of: Any,
    x: np.ndarray,
    tau: np.ndarray,
    target: np.ndarray,
    fine: np.ndarray,
    fine_target: np.ndarray,
    ref: np.ndarray,
) -> np.ndarray:
    """Cutting planes: add the scales of ``fine`` where the bound fails and solve again (up
    to 5 times); a remaining shortfall scales x up, so the bound holds at every fine scale."""
    for _ in range(5):
        short = fine_target / (a_of(fine) @ x)
        if short.max() <= 1.0 + 1e-12:
            return x
        add = fine[short > 1.0]
        tau = np.concatenate([tau, add])
        target = np.concatenate([target, fine_target[short > 1.0]])
        x2, f = least_inflation_lp(a_of(tau), target, ref)
        if not math.isfinite(f):
            break
        x = x2
    short = float(np.max(fine_target / (a_of(fine) @ x)))
    return x * max(short, 1.0) * (1.0 + 1e-12)


def columns(consumer: str, tau: np.ndarray, fs: float, tc: float | None) -> np.ndarray:
    """WV per unit variance of the consumer's terms (per log sample) at scales ``tau``."""
    cols = [1.0 / tau]
    if consumer == "WN+RW":
        cols.append((tau**2 + 2.0) / (12.0 * tau))
    elif consumer == "WN+GM":
        phi = math.exp(-1.0 / (fs * float(tc)))
        cols.append(ar1_wv(tau, phi, 1.0 - phi * phi))
    return np.column_stack(cols)


def least_inflation_lp(a: np.ndarray, t: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, float]:
    """min sum_i x_i / ref_i subject to A x >= t, x >= 0 (HiGHS on the scaled x_i / ref_i).

    ``ref`` holds the plain conversion's variances, so the objective is the sum of the squared
    factors over the plain conversion (the least inflation); inf when the columns are not
    usable (a Gauss-Markov column out of numerical range)."""
    from scipy.optimize import linprog

    if not (np.all(np.isfinite(a)) and np.all(a > 0)):
        return np.full(a.shape[1], np.nan), math.inf
    a_s = a * ref / t[:, None]
    r = linprog(
        np.ones(a.shape[1]),
        A_ub=-a_s,
        b_ub=-np.ones_like(t),
        bounds=[(0, None)] * a.shape[1],
    )
    if r.status != 0:
        return np.full(a.shape[1], np.nan), math.inf
    return np.maximum(r.x, 0.0) * ref, float(r.fun)


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
) -> dict[str, Any]:
    """The projection of one model: plain and bounded variances (native unit, per sample)."""
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
    if consumer == "WN":
        tmodel = Model(tuple(p for _, p in sp.fast)) if sp.fast else None
    else:
        tmodel = model

    def target_at(t: np.ndarray) -> np.ndarray:
        base = tmodel.wv(t, fs) if tmodel is not None else np.zeros_like(t)
        return base * target_ratio(t, n, confidence)

    target = target_at(tau)
    out["target_at"] = target_at
    out["target"] = target
    if not bound:
        x = [plain["sigma2"]]
        tc = plain.get("T_c")
        if consumer == "WN+RW":
            x.append(plain["gamma2"])
        elif consumer == "WN+GM":
            x.append(plain["sb2"])
        out["x"], out["T_c"] = np.array(x), tc
        return out
    # reference variances of the objective: the plain conversion, or (a term that the rule
    # leaves at 0) the term alone matching the target at the band's shortest (WN) or longest
    # (bias) scale
    t_ref = 1.0 / sp.slow[0][1] if sp.slow else tau_h / fs
    a_ref = columns(consumer, tau[[0, -1]], fs, plain.get("T_c", t_ref))
    ref = np.array(
        [
            plain["sigma2"] if plain["sigma2"] > 0 else target[0] / a_ref[0, 0],
            *([plain.get("gamma2", plain.get("sb2", 0.0))] if consumer != "WN" else []),
        ]
    )
    if consumer != "WN" and not ref[1] > 0:
        ref[1] = target[-1] / a_ref[-1, 1]
    if consumer != "WN+GM":
        a = columns(consumer, tau, fs, None)
        x, _ = least_inflation_lp(a, target, ref)
        fine = fine_scales(tau)
        ft = target_at(fine)
        x = refine(lambda t: columns(consumer, t, fs, None), x, tau, target, fine, ft, ref)
        # a plain conversion that already bounds the fit at every fine scale and costs no
        # more than the LP's solution is kept exactly (e.g. a WN+RW fit for a WN+RW consumer)
        xp = np.array([plain["sigma2"], *([plain["gamma2"]] if consumer == "WN+RW" else [])])
        if (
            np.all(xp > 0)
            and np.all(columns(consumer, fine, fs, None) @ xp >= ft)
            and float(np.sum(xp / ref)) <= float(np.sum(x / ref)) * (1.0 + 1e-6)
        ):
            x = xp
        out["x"], out["T_c"], out["A"] = x, None, a
        return out
    # Gauss-Markov bias: 1-D search over log T_c of the least-inflation objective, from the
    # band's shortest scale to ten horizons
    from scipy.optimize import minimize_scalar

    lo, hi = math.log(tau[0] / fs), math.log(10.0 * max(tau[-1], tau_h) / fs)

    def obj(lt: float) -> float:
        return least_inflation_lp(columns(consumer, tau, fs, math.exp(lt)), target, ref)[1]

    grid = np.linspace(lo, hi, 16)
    vals = [obj(g) for g in grid]
    k = int(np.argmin(vals))
    if not math.isfinite(vals[k]):
        raise ExportError("no Gauss-Markov bias bounds the fitted WV over the band")
    a_, b_ = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    r = minimize_scalar(obj, bounds=(a_, b_), method="bounded", options={"xatol": 1e-4})
    lt = float(r.x) if r.fun <= vals[k] else float(grid[k])
    tc = math.exp(lt)
    a = columns(consumer, tau, fs, tc)
    x, _ = least_inflation_lp(a, target, ref)
    fine = fine_scales(tau)
    x = refine(lambda t: columns(consumer, t, fs, tc), x, tau, target, fine, target_at(fine), ref)
    out["x"], out["T_c"], out["A"] = x, tc, a
    return out
