"""Replicates: one univariate model fitted to several recordings of the same sensor.

The objective is summed over the recordings (each with its own weights); the same variable
projection as :func:`engine.fit.fit_gmwm` with the stacked moments.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import optimize

from ..model import Model, ModelError, parse_model
from ..processes import AR1, TC_MAX_FACTOR, TC_MIN, Process
from ..units import param_unit
from ..wavelet import WaveletVariance, wavelet_variance
from .gmwm import FitError, GMWMResult, _warning_lines, fit_gmwm, weight_matrix

__all__ = ["ReplicateResult", "fit_replicates"]


def _nnls(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    norms = np.sqrt(np.sum(a * a, axis=0))
    norms[norms == 0] = 1.0
    g, _ = optimize.nnls(a / norms, b, maxiter=50 * a.shape[1] + 50)
    return g / norms


def _local(
    fun, x0: np.ndarray, step: float, lo: float, hi: float
) -> tuple[float, np.ndarray, bool]:
    """Nelder-Mead with restarts on a shrinking simplex until a restart stops improving."""
    x = np.clip(np.asarray(x0, float), lo, hi)
    f = fun(x)
    converged = False
    d = x.size
    for _ in range(8):
        simplex = np.vstack(
            [x]
            + [
                np.clip(x + step * e, lo, hi) if x[i] + step <= hi else x - step * e
                for i, e in enumerate(np.eye(d))
            ]
        )
        res = optimize.minimize(
            fun,
            x,
            method="Nelder-Mead",
            options={
                "xatol": 1e-6,
                "fatol": 1e-10 * max(f, 1e-300),
                "maxfev": 300 * d + 200,
                "initial_simplex": simplex,
            },
        )
        fn = float(res.fun)
        if fn < f * (1 - 1e-10):
            x, f = np.clip(np.asarray(res.x, float), lo, hi), fn
            step = max(step / 8, 1e-5)
        else:
            converged = bool(res.success) or fn <= f
            break
    return f, x, converged


def _grid_axis(tau_max: float, npts: int) -> np.ndarray:
    return np.linspace(math.log(0.25), math.log(4.0 * tau_max), npts)


# -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ReplicateResult:
    """Result of :func:`fit_replicates`: one model fitted to several recordings.

    Attributes
    ----------
    model : Model
        The fitted model (AR1/GM most persistent first).
    wvs : list of WaveletVariance
        The replicates' WVs.
    weights : list of ndarray (J_r,)
        Diagonal weights of each replicate.
    weights_name : str
        ``"ci"``, ``"identity"`` or ``"user"``.
    objective : float
        Sum over replicates of ``(nu_hat_r - nu)' Omega_r (nu_hat_r - nu)``.
    objectives : list of float
        Each replicate's term.
    implied : list of ndarray (J_r,)
        Implied WV at each replicate's scales.
    components : dict of str to ndarray
        Implied WV of each process at the scales of the longest replicate.
    converged, at_bound, n_evaluations, method, message, elapsed_s
        As :class:`engine.GMWMResult`.
    """

    model: Model
    wvs: list[WaveletVariance]
    weights: list[np.ndarray]
    weights_name: str
    objective: float
    objectives: list[float]
    implied: list[np.ndarray]
    components: dict[str, np.ndarray]
    converged: bool
    at_bound: list[str] = field(default_factory=list)
    n_evaluations: int = 0
    method: str = ""
    message: str = ""
    elapsed_s: float = 0.0

    @property
    def fs(self) -> float:
        return self.wvs[0].fs

    @property
    def params(self) -> dict[str, float]:
        """Estimated values by unique name (``WN.sigma2``, ``GM_1.beta`` ...)."""
        m = self.model
        return {
            f"{lab}.{n}": float(v)
            for lab, p in zip(m.labels, m.processes, strict=True)
            for n, v in zip(p.param_names, p.values, strict=True)
        }

    def summary(self) -> str:
        """Readable summary."""
        u = self.wvs[0].unit
        lines = [
            f"GMWM replicate fit of {self.model.spec()} to {len(self.wvs)} recordings",
            f"  data: N = {', '.join(str(w.n) for w in self.wvs)} samples, fs = {self.fs:g} Hz",
            f"  weights: {self.weights_name}; objective = {self.objective:.6g} (sum); "
            f"{self.method}, {self.n_evaluations} evaluations, "
            f"{1e3 * self.elapsed_s:.1f} ms",
            "",
            f"  {'parameter':<16} {'value':>14}  unit",
        ]
        for lab, p in zip(self.model.labels, self.model.processes, strict=True):
            for name, v in zip(p.param_names, p.values, strict=True):
                lines.append(f"  {lab + '.' + name:<16} {v:>14.6e}  {param_unit(p.code, name, u)}")
        lines += ["", "  objective by replicate: " + ", ".join(f"{v:.4g}" for v in self.objectives)]
        lines += _warning_lines(self.at_bound, self.converged, self.message)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        u = self.wvs[0].unit
        return {
            "kind": "replicates",
            "model": self.model.spec(),
            "model_values": self.model.spec(values=True),
            "fs": float(self.fs),
            "n": [int(w.n) for w in self.wvs],
            "weights": self.weights_name,
            "objective": float(self.objective),
            "objectives": list(self.objectives),
            "params": [
                {
                    "process": p.code,
                    "label": lab,
                    "name": n,
                    "value": float(v),
                    "unit": param_unit(p.code, n, u),
                }
                for lab, p in zip(self.model.labels, self.model.processes, strict=True)
                for n, v in zip(p.param_names, p.values, strict=True)
            ],
            "implied": [v.tolist() for v in self.implied],
            "components": {k: v.tolist() for k, v in self.components.items()},
            "converged": bool(self.converged),
            "at_bound": list(self.at_bound),
            "method": self.method,
            "n_evaluations": int(self.n_evaluations),
            "wv": [w.to_dict() for w in self.wvs],
        }


class _RProblem:
    """Stacked WVs of several replicates and one univariate model (NNLS inner problem)."""

    def __init__(self, model: Model, wvs: list[WaveletVariance], ws: list[np.ndarray]):
        self.model = model
        self.fs = wvs[0].fs
        self.tau = np.concatenate([w.tau_samples.astype(float) for w in wvs])
        sw = np.sqrt(np.concatenate(ws))
        self.sw = sw
        self.b = sw * np.concatenate([w.variance for w in wvs])
        self.procs = model.processes
        self.slots = [i for i, p in enumerate(self.procs) if p.nonlinear is not None]
        self.fixed = [
            None if p.nonlinear else p.basis(self.tau, self.fs) * np.ones_like(self.tau)
            for p in self.procs
        ]
        self.tc_min = TC_MIN
        self.tc_max = TC_MAX_FACTOR * max(
            max(w.n for w in wvs), 2 ** (max(w.n_levels for w in wvs) + 1)
        )
        self.n_eval = 0

    def phi_of(self, i: int, u: float) -> float:
        if isinstance(self.procs[i], AR1) and u < -50:
            return 0.0
        tc = math.exp(min(max(u, math.log(self.tc_min)), math.log(self.tc_max)))
        return math.exp(-1.0 / tc)

    def solve(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        self.n_eval += 1
        cols = list(self.fixed)
        for i, ui in zip(self.slots, u, strict=True):
            cols[i] = self.procs[i].basis(self.tau, self.fs, self.phi_of(i, float(ui)))
        a = self.sw[:, None] * np.column_stack(cols)
        h = _nnls(a, self.b)
        r = self.b - a @ h
        return float(r @ r), h

    def profile(self, u: np.ndarray) -> float:
        return self.solve(np.asarray(u, float))[0]


def fit_replicates(
    wvs: Sequence[WaveletVariance | Any],
    model: Model | Process | str,
    *,
    weights: str | Sequence[np.ndarray] = "ci",
    fs: float | None = None,
    levels: int | None = None,
) -> ReplicateResult:
    """Fit one univariate model to several recordings of the same sensor.

    ``theta_hat = argmin sum_r (nu_hat_r - nu(theta))' Omega_r (nu_hat_r - nu(theta))``: the
    replicates may have different lengths (and numbers of levels); each keeps its own
    weights. Solved by variable projection as :func:`engine.fit_gmwm` (exact NNLS for the
    variances; a grid, the replicates' own fits and Nelder-Mead for the AR1/GM terms).

    Parameters
    ----------
    wvs : sequence of WaveletVariance or array_like
        The replicates' WVs, or raw series (WV computed with ``fs``). At least 2.
    model : Model, Process or str
        E.g. ``"2*GM+WN+RW"``.
    weights : "ci", "identity" or sequence of (J_r,) arrays
        Diagonal weights per replicate (the univariate ``"ci"`` by default).
    fs : float, optional
        Sampling frequency of raw series; must agree with the WVs' fs.
    levels : int, optional
        Use only the first ``levels`` levels of every replicate.

    Returns
    -------
    ReplicateResult
    """
    t0 = time.perf_counter()
    m = parse_model(model)
    items = list(wvs)
    if len(items) < 2:
        raise FitError(
            f"a replicate fit needs at least 2 recordings, got {len(items)}; use fit_gmwm for one"
        )
    out: list[WaveletVariance] = []
    for r, it in enumerate(items):
        try:
            if isinstance(it, WaveletVariance):
                wv = it
            else:
                wv = wavelet_variance(it, fs=1.0 if fs is None else fs)
        except (ValueError, TypeError) as e:
            raise FitError(f"replicate {r + 1}: {e}") from None
        if levels is not None:
            if not 1 <= levels <= wv.n_levels:
                raise FitError(
                    f"replicate {r + 1}: levels={levels} is out of range (it has "
                    f"{wv.n_levels} levels)"
                )
            wv = wv.truncate(levels)
        if not np.any(wv.variance > 0):
            raise FitError(f"replicate {r + 1}: the WV is 0 at every level (constant signal)")
        out.append(wv)
    fs0 = out[0].fs
    for r, wv in enumerate(out):
        if not math.isclose(wv.fs, fs0, rel_tol=1e-9):
            raise FitError(
                f"replicate {r + 1} has fs = {wv.fs:g} Hz but replicate 1 has "
                f"{fs0:g} Hz: replicates of one sensor share fs"
            )
    if fs is not None and not math.isclose(fs, fs0, rel_tol=1e-9):
        raise FitError(f"fs={fs} Hz disagrees with the replicates' fs={fs0} Hz")
    m.validate(sum(w.n_levels for w in out))
    if isinstance(weights, str):
        ws = []
        for r, wv in enumerate(out):
            try:
                ws.append(np.diagonal(weight_matrix(wv, weights)[0]).copy())
            except FitError as e:
                raise FitError(f"replicate {r + 1}: {e}") from None
        wname = weights
    else:
        ws = [np.asarray(v, float) for v in weights]
        if len(ws) != len(out) or any(
            v.shape != (wv.n_levels,) for v, wv in zip(ws, out, strict=False)
        ):
            raise FitError("give one (J_r,) weight vector per replicate")
        if any(np.any(~np.isfinite(v)) or np.any(v < 0) for v in ws):
            raise FitError("the weights must be finite and non-negative")
        wname = "user"
    prob = _RProblem(m.cleared(), out, ws)
    lo, hi = math.log(prob.tc_min), math.log(prob.tc_max)
    k = len(prob.slots)
    if k == 0:
        u = np.zeros(0)
        converged, method, msg = True, "closed-form", "closed-form non-negative least squares"
    else:
        tau_max = max(float(w.tau_samples[-1]) for w in out)
        axis = _grid_axis(tau_max, {1: 60, 2: 36, 3: 18}.get(k, 10))
        cands = [np.array(c) for c in itertools.combinations(axis[::-1], k)]
        # the replicates' own fits (GM/AR1 most persistent first) are candidates too
        for wv, w in zip(out, ws, strict=True):
            try:
                fr: GMWMResult = fit_gmwm(wv, m.cleared(), weights=w)
            except (FitError, ModelError):  # pragma: no cover - a degenerate replicate
                continue
            tcs = [
                -1.0 / math.log(q.nl_value(fs0))
                for q in fr.model.processes
                if q.nonlinear and 0 < q.nl_value(fs0) < 1
            ]
            if len(tcs) == k:
                cands.append(np.log(np.array(sorted(tcs, reverse=True))))
        if m.is_set:
            tcs = [-1.0 / math.log(q.nl_value(fs0)) for q in m.processes if q.nonlinear]
            cands.append(np.log(np.array(sorted(tcs, reverse=True))))
        scored = sorted(((prob.profile(c), i) for i, c in enumerate(cands)))
        step = float(axis[1] - axis[0])
        results: list[tuple[float, np.ndarray, bool]] = []
        for _, i in scored[:4]:
            c = cands[i]
            if any(np.max(np.abs(c - r[1])) < 1.5 * step for r in results):
                continue
            results.append(_local(prob.profile, c, step / 2, lo, hi))
        _, u, converged = min(results, key=lambda r: r[0])
        method = "grid+nelder-mead"
        msg = (
            "converged"
            if converged
            else "the local search stopped before meeting its "
            "tolerance; the estimate may be slightly above the minimum"
        )
    _, h = prob.solve(u)
    nl_vals = {i: prob.phi_of(i, float(ui)) for i, ui in zip(prob.slots, u, strict=True)}
    procs = [p.from_fit(float(h[i]), nl_vals.get(i), fs0) for i, p in enumerate(prob.procs)]
    nonlin = sorted(
        (q for q in procs if q.nonlinear is not None),
        key=lambda q: -(q.phi if isinstance(q, AR1) else math.exp(-q.beta / fs0)),
    )
    fitted = Model(tuple(nonlin + [q for q in procs if q.nonlinear is None]))
    implied = [fitted.wv(w.tau_samples, fs0) for w in out]
    objs = [
        float(np.sum(wt * (w.variance - im) ** 2))
        for w, wt, im in zip(out, ws, implied, strict=True)
    ]
    longest = max(out, key=lambda w: w.n_levels)
    at_bound = []
    for lab, q in zip(fitted.labels, fitted.processes, strict=True):
        if q.linear_coef() == 0.0:
            at_bound.append(f"{lab}.{q.param_names[-1] if q.nonlinear else q.param_names[0]}")
        if q.nonlinear is not None:
            phi = q.phi if isinstance(q, AR1) else math.exp(-q.beta / fs0)
            if 0 < phi < 1:
                tc = -1.0 / math.log(phi)
                if tc <= prob.tc_min * 1.0001 or tc >= prob.tc_max / 1.0001:
                    at_bound.append(f"{lab}.{q.nonlinear}")
    return ReplicateResult(
        model=fitted,
        wvs=out,
        weights=ws,
        weights_name=wname,
        objective=float(sum(objs)),
        objectives=objs,
        implied=implied,
        components=fitted.components(longest.tau_samples, fs0),
        converged=converged,
        at_bound=at_bound,
        n_evaluations=prob.n_eval,
        method=method,
        message=msg,
        elapsed_s=time.perf_counter() - t0,
    )
