"""GMWM: fit a composite latent model by matching the empirical and the implied wavelet variance.

``theta_hat = argmin (nu_hat - nu(theta))' Omega (nu_hat - nu(theta))``.

Every process has one non-negative linear coefficient ``h`` (variance-like) and AR1/GM also one
non-linear parameter (phi). The implied WV is ``X(phi) h``, so for fixed phi the minimum over
``h >= 0`` is a non-negative least-squares problem solved exactly (variable projection):

* models made only of QN, WN, RW and DR: closed form (the GMWM paper, eq. 6-7, with h >= 0);
* models with AR1/GM: a deterministic grid over the correlation times of the AR1/GM terms
  (all candidates at once, bounded by the unconstrained least-squares lower bound), then a
  local Nelder-Mead search on the profiled objective from the best candidates, repeated until
  the objective stops improving. The search space is the log correlation time.

Reference: Guerrier, Skaloud, Stebler & Victoria-Feser (2013), JASA 108(502);
Guerrier, Jurado, Khaghani et al. (2020), IEEE TIM (the GMWM paper).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._optim import nelder_mead, nnls
from .model import Model, parse_model
from .processes import AR1, GM, TC_MAX_FACTOR, TC_MIN, Process, _ar1_wv_pos
from .units import param_unit
from .wavelet import WaveletVariance, wavelet_variance

__all__ = ["fit_gmwm", "GMWMResult", "weight_matrix", "FitError"]


class FitError(ValueError):
    """The data or the settings do not allow a fit (says what and how to fix it)."""


@dataclass(frozen=True)
class ParamRecord:
    """One estimated parameter with its label and unit."""

    process: str
    index: int
    label: str
    name: str
    value: float
    unit: str

    @property
    def full_name(self) -> str:
        return f"{self.label}.{self.name}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "process": self.process,
            "index": self.index,
            "name": self.name,
            "value": float(self.value),
            "unit": self.unit,
        }


@dataclass(frozen=True, eq=False)
class GMWMResult:
    """Result of :func:`fit_gmwm`.

    Attributes
    ----------
    model : Model
        The fitted model, every parameter set (AR1/GM most persistent first).
    wv : WaveletVariance
        The empirical WV the model was fitted to.
    omega : ndarray, shape (J, J)
        Weighting matrix.
    weights : str
        ``"ci"``, ``"identity"`` or ``"user"``.
    objective : float
        ``(nu_hat - nu)' Omega (nu_hat - nu)`` at the estimate.
    implied : ndarray, shape (J,)
        Model-implied WV at the empirical scales.
    components : dict[str, ndarray]
        Implied WV of each process by label (``WN``, ``GM_1`` ...), summing to ``implied``.
    converged : bool
        True when the local search met its tolerance.
    at_bound : list[str]
        Parameters estimated on the boundary of their space (a variance at 0, a correlation
        time at the edge of the explored range): a sign that the model may be too large.
    n_evaluations : int
        Number of profiled-objective evaluations.
    method : str
        ``"closed-form"`` or ``"grid+nelder-mead"``.
    message : str
        Human-readable convergence note.
    elapsed_s : float
        Wall time of the fit (s).
    """

    model: Model
    wv: WaveletVariance
    omega: np.ndarray
    weights: str
    objective: float
    implied: np.ndarray
    components: dict[str, np.ndarray]
    converged: bool
    at_bound: list[str] = field(default_factory=list)
    n_evaluations: int = 0
    method: str = ""
    message: str = ""
    elapsed_s: float = 0.0

    @property
    def fs(self) -> float:
        return self.wv.fs

    @property
    def param_records(self) -> list[ParamRecord]:
        """Parameters with process code, index among its kind, label, name, value and unit."""
        out = []
        m = self.model
        for lab, idx, p in zip(m.labels, m.indices, m.processes, strict=True):
            for name, v in zip(p.param_names, p.values, strict=True):
                out.append(
                    ParamRecord(
                        p.code, idx, lab, name, float(v), param_unit(p.code, name, self.wv.unit)
                    )
                )
        return out

    @property
    def params(self) -> dict[str, float]:
        """Estimated values by unique name (``WN.sigma2``, ``GM_1.beta`` ...)."""
        return {r.full_name: r.value for r in self.param_records}

    def implied_at(self, tau_samples: np.ndarray) -> np.ndarray:
        """Implied WV at other scales (samples), e.g. for a smooth curve."""
        return self.model.wv(tau_samples, self.fs)

    def summary(self) -> str:
        """Readable summary: model, data, parameters with units and datasheet values, fit."""
        from .units import datasheet

        w = self.wv
        lines = [
            f"GMWM fit of {self.model.spec()}",
            f"  data: N = {w.n} samples, fs = {w.fs:g} Hz, {w.n_levels} WV levels"
            f"{' (robust WV)' if w.robust else ''}",
            f"  weights: {self.weights}; objective = {self.objective:.6g}; "
            f"{self.method}, {self.n_evaluations} evaluations, {1e3 * self.elapsed_s:.1f} ms",
            "",
            f"  {'parameter':<16} {'value':>14}  unit",
        ]
        for r in self.param_records:
            lines.append(f"  {r.full_name:<16} {r.value:>14.6e}  {r.unit}")
        ds = datasheet(self.model, w.fs, w.unit, n_levels=w.n_levels)
        if ds:
            lines += ["", "  datasheet view (as gmwm export --format datasheet):"]
            for row in ds:
                lines.append(
                    f"  {row['label']:<8} {row['quantity']:<40} {row['symbol']:<8} "
                    f"{row['value']:>12.5g}  {row['unit']}"
                )
        lines += _warning_lines(self.at_bound, self.converged, self.message)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (the ``gmwm fit --json`` object)."""
        return {
            "model": self.model.spec(),
            "model_values": self.model.spec(values=True),
            "n": int(self.wv.n),
            "fs": float(self.wv.fs),
            "weights": self.weights,
            "objective": float(self.objective),
            "params": [r.to_dict() for r in self.param_records],
            "implied": [float(v) for v in self.implied],
            "components": {k: [float(x) for x in v] for k, v in self.components.items()},
            "converged": bool(self.converged),
            "at_bound": list(self.at_bound),
            "method": self.method,
            "n_evaluations": int(self.n_evaluations),
            "wv": self.wv.to_dict(),
        }


def weight_matrix(wv: WaveletVariance, weights: str | np.ndarray = "ci") -> tuple[np.ndarray, str]:
    """The weighting matrix Omega for a WV.

    Parameters
    ----------
    weights : {"ci", "identity"} or array
        ``"ci"``: ``diag(1 / (ci_high - ci_low)^2)`` (the R packages' default);
        ``"identity"``; a (J,) vector of diagonal weights or a (J, J) symmetric positive
        (semi-)definite matrix.
    """
    j = wv.n_levels
    if isinstance(weights, str):
        if weights == "ci":
            width = wv.ci_high - wv.ci_low
            if np.any(~np.isfinite(width)) or np.any(width <= 0):
                bad = int(np.flatnonzero(~(np.isfinite(width) & (width > 0)))[0]) + 1
                raise FitError(
                    f"the WV interval at level {bad} is empty or not finite, so "
                    "weights='ci' is undefined (constant signal?); "
                    "use another weighting"
                )
            return np.diag(1.0 / width**2), "ci"
        if weights == "identity":
            return np.eye(j), "identity"
        raise FitError(f"unknown weights {weights!r}: use 'ci', 'identity' or a matrix")
    w = np.asarray(weights, dtype=float)
    if w.ndim == 1:
        w = np.diag(w)
    if w.shape != (j, j):
        raise FitError(
            f"the weight matrix has shape {w.shape}, the WV has {j} levels: "
            f"give a ({j},) vector or a ({j}, {j}) matrix"
        )
    if not np.all(np.isfinite(w)) or not np.allclose(w, w.T, rtol=1e-10, atol=0):
        raise FitError("the weight matrix must be finite and symmetric")
    return w, "user"


def _sqrt_weight(omega: np.ndarray) -> np.ndarray:
    """A with A'A = Omega (so the objective is ||A (nu_hat - nu)||^2)."""
    if np.count_nonzero(omega - np.diag(np.diagonal(omega))) == 0:
        d = np.diagonal(omega)
        if np.any(d < 0):
            raise FitError("the weight matrix has a negative diagonal weight")
        return np.diag(np.sqrt(d))
    vals, vecs = np.linalg.eigh(omega)
    if vals.min() < -1e-10 * max(vals.max(), 1e-300):
        raise FitError("the weight matrix is not positive semi-definite")
    return (vecs * np.sqrt(np.clip(vals, 0, None))).T


# -------------------------------------------------------------------------------------------
# profiled objective
# -------------------------------------------------------------------------------------------
class _Problem:
    """The weighted NNLS sub-problem for a model structure and a WV."""

    def __init__(self, model: Model, wv: WaveletVariance, a: np.ndarray):
        self.model = model
        self.tau = wv.tau_samples.astype(float)
        self.fs = wv.fs
        self.a = a
        self.b = a @ wv.variance
        self.bb = float(self.b @ self.b)
        self.nl_idx = [i for i, p in enumerate(model.processes) if p.nonlinear is not None]
        self.k = len(self.nl_idx)
        self.p = len(model.processes)
        self.tc_min = TC_MIN
        self.tc_max = TC_MAX_FACTOR * max(wv.n, 2 ** (wv.n_levels + 1))
        # constant columns of the linear processes
        self.x_fixed = np.zeros((self.tau.size, self.p))
        for i, pr in enumerate(model.processes):
            if pr.nonlinear is None:
                self.x_fixed[:, i] = pr.basis(self.tau, self.fs)
        self.is_gm = [isinstance(pr, GM) for pr in model.processes]
        self.n_eval = 0
        self._passive: np.ndarray | None = None

    # the non-linear coordinate: log of the correlation time (samples); AR1 may also be < 0
    def phi_of(self, i: int, u: float) -> float:
        """phi from the search coordinate of process i."""
        pr = self.model.processes[i]
        if isinstance(pr, AR1) and u < -50:
            return 0.0
        tc = math.exp(min(max(u, math.log(self.tc_min)), math.log(self.tc_max)))
        return math.exp(-1.0 / tc)

    def design(self, phis: tuple[float, ...]) -> np.ndarray:
        x = self.x_fixed.copy()
        for i, phi in zip(self.nl_idx, phis, strict=True):
            if 0.0 < phi < 1.0:  # hot path: what basis() computes, without its checks
                col = _ar1_wv_pos(self.tau, phi)
                x[:, i] = col * (1.0 - phi * phi) if self.is_gm[i] else col
            else:
                x[:, i] = self.model.processes[i].basis(self.tau, self.fs, phi)
        return x

    def solve(self, phis: tuple[float, ...]) -> tuple[float, np.ndarray, np.ndarray]:
        """Objective, h >= 0 and the design matrix for fixed non-linear values."""
        self.n_eval += 1
        x = self.design(phis)
        c = self.a @ x
        norms = np.sqrt(np.sum(c * c, axis=0))
        norms[norms == 0] = 1.0
        # warm start from the previous solve's positive set (Nelder-Mead moves little)
        g, _ = nnls(c / norms, self.b, maxiter=50 * self.p, passive=self._passive)
        self._passive = g > 0
        h = g / norms
        r = self.b - c @ h
        return float(r @ r), h, x

    def profile(self, u: np.ndarray) -> float:
        phis = tuple(self.phi_of(i, float(ui)) for i, ui in zip(self.nl_idx, u, strict=True))
        return self.solve(phis)[0]


def _warning_lines(at_bound: Any, converged: bool, message: str) -> list[str]:
    """The warning lines that end a fit summary (parameters at a bound, no convergence)."""
    lines: list[str] = []
    if at_bound:
        lines += ["", f"  warning: at a bound: {', '.join(at_bound)}"]
    if not converged:
        lines += ["", f"  warning: {message}"]
    return lines


def _grid_axis(prob: _Problem) -> np.ndarray:
    """Log correlation times (samples) explored per AR1/GM term: 0.25 to 4x the largest scale."""
    lo, hi = math.log(0.25), math.log(4.0 * float(prob.tau[-1]))
    return np.linspace(lo, hi, {1: 60, 2: 36, 3: 18}.get(prob.k, 10))


def _grid_spacing(prob: _Problem) -> float:
    g = _grid_axis(prob)
    return float(g[1] - g[0])


def _grid(prob: _Problem) -> list[tuple[float, ...]]:
    """Candidate search coordinates (log correlation times) for the AR1/GM terms."""
    g = _grid_axis(prob)
    # distinct AR1/GM terms are interchangeable: candidates with decreasing correlation times
    return list(itertools.combinations(g[::-1], prob.k))


def _grid_search(
    prob: _Problem, cands: list[tuple[float, ...]], keep: int
) -> list[tuple[float, tuple]]:
    """Exact profiled objective of the best candidates, found by branch and bound.

    The unconstrained weighted least squares (all candidates at once, batched QR) is a lower
    bound of the non-negative one; candidates are evaluated exactly in increasing order of
    that bound until the bound exceeds the ``keep``-th best exact value.
    """
    u = np.asarray(cands, dtype=float)  # (C, k)
    nc = u.shape[0]
    xs = np.repeat(prob.x_fixed[None, :, :], nc, axis=0)
    phis = np.exp(-1.0 / np.exp(u))
    for col, i in enumerate(prob.nl_idx):
        xs[:, :, i] = prob.model.processes[i].basis(prob.tau, prob.fs, phis[:, col])
    cmat = np.einsum("ij,cjk->cik", prob.a, xs)
    norms = np.sqrt(np.sum(cmat * cmat, axis=1, keepdims=True))
    norms[norms == 0] = 1.0
    cn = cmat / norms
    with np.errstate(all="ignore"):
        q, r = np.linalg.qr(cn)
        qb = np.einsum("cjk,j->ck", q, prob.b)
        lower = prob.bb - np.sum(qb * qb, axis=1)
        try:
            coef = np.linalg.solve(r, qb[:, :, None])[:, :, 0]
            feasible = np.all(coef >= 0, axis=1) & np.all(np.isfinite(coef), axis=1)
        except np.linalg.LinAlgError:
            feasible = np.zeros(nc, dtype=bool)
    lower = np.where(np.isfinite(lower), np.maximum(lower, 0.0), 0.0)
    order = np.argsort(lower, kind="stable")
    best: list[tuple[float, tuple]] = []
    for c in order:
        if len(best) >= keep and lower[c] > best[-1][0] * (1 + 1e-12):
            break
        if feasible[c]:
            val = float(lower[c])
        else:
            val = prob.profile(u[c])
        best.append((val, tuple(u[c])))
        best.sort(key=lambda t: t[0])
        best = best[:keep]
    return best


def _local(prob: _Problem, u0: tuple[float, ...], step: float) -> tuple[float, np.ndarray, bool]:
    """Local minimum of the profiled objective from ``u0`` (log correlation times).

    Nelder-Mead from a simplex of the grid's size, restarted on a smaller simplex until a
    restart no longer lowers the objective (Nelder-Mead copes with the kinks where the set
    of zero variances changes, where gradient methods stall).
    """
    lo, hi = math.log(prob.tc_min), math.log(prob.tc_max)
    x = np.clip(np.asarray(u0, float), lo, hi)
    f = prob.profile(x)
    converged = False
    for _ in range(8):
        simplex = np.vstack([x] + [x + step * e for e in np.eye(prob.k)])
        res = nelder_mead(
            prob.profile, simplex, xatol=1e-6, fatol=1e-10 * max(f, 1e-300), maxfev=400 * prob.k
        )
        fn = float(res.fun)
        if fn < f * (1 - 1e-10):
            x, f = np.asarray(res.x, float), fn
            step = max(step / 8, 1e-5)
        else:
            converged = bool(res.success) or fn <= f
            break
    return f, x, converged


def fit_gmwm(
    wv_or_signal: WaveletVariance | np.ndarray | Any,
    model: Model | Process | str,
    *,
    fs: float | None = None,
    weights: str | np.ndarray = "ci",
    levels: int | None = None,
    robust: bool = False,
    eff: float = 0.6,
) -> GMWMResult:
    """Fit a latent model by GMWM.

    Parameters
    ----------
    wv_or_signal : WaveletVariance or array_like
        A WV (from :func:`wavelet_variance` or a summary file) or a raw signal, whose WV is then
        computed with ``fs``, ``robust`` and ``eff``.
    model : Model, Process or str
        E.g. ``WN() + RW() + 2 * GM()`` or ``"2*GM+WN+RW"``. Values given in the model are
        used as extra starting points.
    fs : float, optional
        Sampling frequency (Hz) of a raw signal; for a WV it must agree with ``wv.fs``.
    weights : {"ci", "identity"} or array
        Weighting matrix Omega, see :func:`weight_matrix`.
    levels : int, optional
        Use only the first ``levels`` WV levels.
    robust, eff
        Robust WV settings when a raw signal is given.

    Returns
    -------
    GMWMResult

    Raises
    ------
    ModelError
        Unparseable or unidentifiable model.
    FitError
        Data or weights that do not allow a fit (constant signal, too few levels ...).
    """
    t0 = time.perf_counter()
    m = parse_model(model)
    if isinstance(wv_or_signal, WaveletVariance):
        wv = wv_or_signal
        if fs is not None and not math.isclose(fs, wv.fs, rel_tol=1e-9):
            raise FitError(f"fs={fs} Hz disagrees with the WV's fs={wv.fs} Hz")
    else:
        wv = wavelet_variance(wv_or_signal, fs=1.0 if fs is None else fs, robust=robust, eff=eff)
    if levels is not None:
        if not 1 <= levels <= wv.n_levels:
            raise FitError(f"levels={levels} is out of range: the WV has {wv.n_levels} levels")
        wv = wv.truncate(levels)
    m.validate(wv.n_levels)
    if not np.any(wv.variance > 0):
        raise FitError(
            "the wavelet variance is zero at every level (constant signal): "
            "there is no noise to model"
        )
    omega, wname = weight_matrix(wv, weights)
    prob = _Problem(m, wv, _sqrt_weight(omega))

    if prob.k == 0:
        f, h, x = prob.solve(())
        u = np.zeros(0)
        converged, method, msg = True, "closed-form", "closed-form non-negative least squares"
    else:
        cands = _grid(prob)
        # starting values from the user's model, if any
        extra = []
        given = [m.processes[i].nl_value(wv.fs) for i in prob.nl_idx]
        if all(v is not None and 0 < v < 1 for v in given):
            tcs = sorted((-1.0 / math.log(v) for v in given), reverse=True)
            extra.append(tuple(math.log(t) for t in tcs))
        best = _grid_search(prob, cands + extra, keep=3)
        spacing = _grid_spacing(prob)
        results: list[tuple[float, np.ndarray, bool]] = []
        for _, u0 in best:
            # a start next to a local minimum already found adds nothing
            if any(np.max(np.abs(np.asarray(u0) - r[1])) < 1.5 * spacing for r in results):
                continue
            results.append(_local(prob, u0, spacing / 2))
        f, u, converged = min(results, key=lambda r: r[0])
        phis = tuple(prob.phi_of(i, float(ui)) for i, ui in zip(prob.nl_idx, u, strict=True))
        f, h, x = prob.solve(phis)
        method = "grid+nelder-mead"
        msg = (
            "converged"
            if converged
            else "the local search stopped before meeting its tolerance; the estimate may be "
            "slightly above the minimum"
        )

    # build the fitted model; AR1/GM most persistent first
    procs: list[Process] = []
    nl_vals = dict(
        zip(
            prob.nl_idx,
            (prob.phi_of(i, float(ui)) for i, ui in zip(prob.nl_idx, u, strict=True)),
            strict=True,
        )
    )
    for i, p in enumerate(m.processes):
        procs.append(p.from_fit(float(h[i]), nl_vals.get(i), wv.fs))
    nonlin = sorted(
        (q for q in procs if q.nonlinear is not None),
        key=lambda q: -(q.phi if isinstance(q, AR1) else math.exp(-q.beta / wv.fs)),
    )
    lin = [q for q in procs if q.nonlinear is None]
    fitted = Model(tuple(nonlin + lin))
    comps = fitted.components(wv.tau_samples, wv.fs)
    implied = np.sum(np.array(list(comps.values())), axis=0)
    resid = wv.variance - implied
    objective = float(resid @ omega @ resid)

    at_bound = []
    for lab, q in zip(fitted.labels, fitted.processes, strict=True):
        if q.linear_coef() == 0.0:
            at_bound.append(f"{lab}.{q.param_names[-1] if q.nonlinear else q.param_names[0]}")
        if q.nonlinear is not None:
            phi = q.phi if isinstance(q, AR1) else math.exp(-q.beta / wv.fs)
            if phi > 0:
                tc = -1.0 / math.log(phi) if phi < 1 else math.inf
                if tc <= prob.tc_min * 1.0001 or tc >= prob.tc_max / 1.0001:
                    at_bound.append(f"{lab}.{q.nonlinear}")
    return GMWMResult(
        model=fitted,
        wv=wv,
        omega=omega,
        weights=wname,
        objective=objective,
        implied=implied,
        components=comps,
        converged=converged,
        at_bound=at_bound,
        n_evaluations=prob.n_eval,
        method=method,
        message=msg,
        elapsed_s=time.perf_counter() - t0,
    )


__all__ += ["ParamRecord"]
