"""The MGMWM problem: stacked moments, the profiled objective and its non-linear search.

For fixed non-linear parameters (each in the search coordinate ``u`` its class declares, as in
the univariate fit: AR1, GM a log correlation time, MA1 atanh theta) the
implied WV/WCCV moments are linear in the coefficients (independent variances, shared
covariance matrices): :class:`MProblem` builds that design and solves the inner problem
exactly with :class:`engine.multivariate._cone.ConeLSQ`. :func:`search` minimises the profiled
objective over ``u``: starts from the univariate fit of every channel, a scan of each shared
phi/beta, then Nelder-Mead on the profiled objective with restarts and a per-block polish.
Everything is deterministic.

The Nelder-Mead runs are the variable-projection core's :func:`engine.fit._varpro.local`
(the optimiser of every GMWM-type fit). Its starting strategy, :func:`engine.fit._varpro.search`,
is not used: it scores a grid of candidates whose correlation times decrease along the
coordinates, which is right when the AR1/GM terms are interchangeable (one univariate model)
but not here, where each coordinate belongs to one channel or one shared group (channel a's
GM may be slower or faster than channel b's), and a full grid over k coordinates (one per
channel plus the shared ones) grows as ``n^k`` conic solves. The univariate fits of the
channels give far better starts at the cost of one univariate fit per channel.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..fit import FitError, fit_gmwm
from ..fit._varpro import local
from ..models import Model, ModelError, Process
from ..wv import WVMatrix
from ._cone import ConeLSQ
from .spec import MultiModel, SharedProcess, find_label, nl_of_phi, phi_of_nl

__all__ = ["MProblem", "search", "fitted_model", "boundary_estimates"]


class MProblem:
    """Stacked WV/WCCV moments of a multivariate model, with the exact inner solve.

    Moments are stacked pair by pair (upper triangle, diagonal included), levels inside:
    row ``P J + j`` is level j + 1 of pair P. The objective is ``||A (y - X c)||^2`` with
    ``A`` the diagonal square root of the weights, or a full square root of ``Omega``.
    """

    def __init__(
        self,
        mm: MultiModel,
        wvm: WVMatrix,
        w: np.ndarray | None = None,
        omega: np.ndarray | None = None,
    ):
        self.mm = mm
        self.k = mm.k
        self.fs = wvm.fs
        self.tau = wvm.tau_samples.astype(float)
        nj = self.tau.size
        self.nj = nj
        self.terms = mm.terms()
        self.pairs = [(p, q) for p in range(self.k) for q in range(p, self.k)]
        self.y = np.concatenate([wvm.values[:, p, q] for p, q in self.pairs])
        if omega is None:
            if w is None:
                raise ValueError("MProblem needs weights: w (per level and pair) or omega (full)")
            sw = np.sqrt(np.concatenate([w[:, p, q] for p, q in self.pairs]))
            # diagonal weights (sw) or a full omega's root (a_full): exactly one is set
            self.sw: np.ndarray | None = sw
            self.a_full: np.ndarray | None = None
            self.b = sw * self.y
        else:
            self.sw = None
            vals, vecs = np.linalg.eigh(0.5 * (omega + omega.T))
            self.a_full = (vecs * np.sqrt(np.clip(vals, 0.0, None))).T
            self.b = self.a_full @ self.y
        # columns: (term index, local row a, local column b, pair index)
        self.cols: list[tuple[int, int, int, int]] = []
        self.pair_cols: list[list[int]] = []
        for pi, (p, q) in enumerate(self.pairs):
            idx = []
            for ti, t in enumerate(self.terms):
                if p in t.chans and q in t.chans and (p == q or (t.shared and not t.diagonal)):
                    idx.append(len(self.cols))
                    self.cols.append((ti, t.chans.index(p), t.chans.index(q), pi))
            self.pair_cols.append(idx)
        self.lower = np.array(
            [
                0.0 if self.pairs[pi][0] == self.pairs[pi][1] else -np.inf
                for _, _, _, pi in self.cols
            ]
        )
        self.fixed = [
            None if t.nonlinear else t.proto.basis(self.tau, self.fs) * np.ones_like(self.tau)
            for t in self.terms
        ]
        self.slots = [ti for ti, t in enumerate(self.terms) if t.nonlinear]
        # each non-linear term's search coordinate: its range and scan, as its class declares
        n_max = max(wvm.n, 2 ** (wvm.n_levels + 1))
        self.ranges = {ti: self.terms[ti].proto.search_range(n_max) for ti in self.slots}
        self.lo = np.array([self.ranges[ti][0] for ti in self.slots])
        self.hi = np.array([self.ranges[ti][1] for ti in self.slots])
        self.scans = {ti: _scan(self.terms[ti].proto, float(self.tau[-1])) for ti in self.slots}
        self.step = np.array([self.scans[ti][1] - self.scans[ti][0] for ti in self.slots])
        self.full = [ti for ti, t in enumerate(self.terms) if t.shared and not t.diagonal]
        self.n_eval = 0
        groups = (
            None
            if self.a_full is not None
            else [
                (slice(pi * nj, (pi + 1) * nj), self.pair_cols[pi], p == q)
                for pi, (p, q) in enumerate(self.pairs)
            ]
        )
        self.cone = ConeLSQ(
            self.b,
            self.cols,
            {ti: len(self.terms[ti].chans) for ti in self.full},
            self.lower,
            groups,
        )

    # -- non-linear coordinates: each term's own (AR1, GM: log correlation time in samples) --
    def phi_of(self, ti: int, u: float) -> float:
        """The fitter's non-linear value (AR1, GM: phi; MA1: theta) of term ``ti`` at ``u``."""
        lo, hi = self.ranges[ti]
        return float(self.terms[ti].proto.search_nl(u, lo, hi))

    def u_of(self, ti: int, phi: float | None, default: float) -> float:
        """The coordinate of term ``ti`` at the fitter's value ``phi``, clipped into its range;
        ``default`` when there is no value or the search cannot reach it."""
        u = None if phi is None else self.terms[ti].proto.search_of_nl(phi)
        if u is None or not math.isfinite(u):
            return default
        lo, hi = self.ranges[ti]
        return min(max(u, lo), hi)

    def at_edge(self, ti: int, u: float) -> bool:
        """Is term ``ti``'s coordinate at an edge of its range (AR1, GM: a correlation time
        within 0.01 % of the shortest or the longest searched)?"""
        lo, hi = self.ranges[ti]
        return u <= lo + _EDGE or u >= hi - _EDGE

    def bases(self, u: np.ndarray) -> list[np.ndarray]:
        """The WV basis of every term: fixed, or at the coordinates ``u`` of the AR1/GM slots."""
        nl = {ti: float(ui) for ti, ui in zip(self.slots, u, strict=True)}
        return [
            fixed
            if fixed is not None
            else self.terms[ti].proto.basis(self.tau, self.fs, self.phi_of(ti, nl[ti]))
            for ti, fixed in enumerate(self.fixed)
        ]

    # -- inner problem ---------------------------------------------------------------------
    def design(self, bases: list[np.ndarray]) -> np.ndarray:
        """Weighted design ``A X`` (R x C)."""
        x = np.zeros((self.y.size, len(self.cols)))
        for ci, (ti, _, _, pi) in enumerate(self.cols):
            x[pi * self.nj : (pi + 1) * self.nj, ci] = bases[ti]
        if self.a_full is not None:
            return self.a_full @ x
        assert self.sw is not None, "diagonal weights are set when a_full is not"
        return self.sw[:, None] * x

    def _assemble(self, c: np.ndarray) -> tuple[dict[int, float], dict[int, np.ndarray]]:
        h: dict[int, float] = {}
        s: dict[int, np.ndarray] = {
            ti: np.zeros((len(t.chans), len(t.chans)))
            for ti, t in enumerate(self.terms)
            if t.shared
        }
        for (ti, a, b, _), v in zip(self.cols, c, strict=True):
            if self.terms[ti].shared:
                s[ti][a, b] = s[ti][b, a] = float(v)
            else:
                h[ti] = float(v)
        return h, s

    def solve(self, u: np.ndarray) -> tuple[float, dict[int, float], dict[int, np.ndarray], bool]:
        """Objective and linear coefficients at fixed non-linear values.

        Returns (objective, independent variances by term, shared matrices by term, coupled).
        """
        self.n_eval += 1
        ax = self.design(self.bases(u))
        f, c, coupled = self.cone.solve(ax)
        h, s = self._assemble(c)
        return f, h, s, coupled

    def profile(self, u: np.ndarray) -> float:
        """The profiled objective at log correlation times ``u``."""
        return self.solve(np.asarray(u, float))[0]

    @property
    def n_inner(self) -> int:
        """Newton steps of the PSD-constrained inner solves so far."""
        return self.cone.n_inner


_EDGE = math.log(1.0001)  # a coordinate this close to the end of its range is at a bound
_SCAN = 40  # points of the scan of a shared term's coordinate


def _scan(proto: Process, tau_max: float) -> np.ndarray:
    """The scan of a shared term's coordinate: :data:`_SCAN` points over the span of the grid
    its class declares (:meth:`engine.models.Process.search_axis`; AR1, GM: log correlation
    times from 0.25 to 4x the largest scale)."""
    axis = np.asarray(proto.search_axis(tau_max, 1), dtype=float)
    return np.linspace(axis[0], axis[-1], _SCAN)


def _maxfev(u: Any) -> int:
    """Evaluations per Nelder-Mead run: every one is an inner conic solve, so fewer than the
    core's default."""
    return 300 * len(u) + 200


def fitted_model(
    model: MultiModel, prob: MProblem, u: np.ndarray, h: dict[int, float], s: dict[int, np.ndarray]
) -> MultiModel:
    phis = {ti: prob.phi_of(ti, float(ui)) for ti, ui in zip(prob.slots, u, strict=True)}
    fs = prob.fs
    models = {c: list(m.processes) for c, m in model.models.items()}
    shared = []
    for ti, t in enumerate(prob.terms):
        phi = phis.get(ti)
        if t.shared:
            cov = s[ti]
            nl = None if phi is None else nl_of_phi(t.proto, phi, fs)
            shared.append(
                SharedProcess(
                    t.label, tuple(model.channels[i] for i in t.chans), None, nl, t.diagonal
                )
            )
            for a, p in enumerate(t.chans):
                c = model.channels[p]
                i = model.index(t.label, c)
                models[c][i] = (
                    t.proto.from_fit(float(cov[a, a]), phi, fs)
                    if t.nonlinear
                    else t.proto.from_fit(float(cov[a, a]), None, fs)
                )
        else:
            c = model.channels[t.chans[0]]
            i = model.models[c].labels.index(t.label)
            models[c][i] = t.proto.from_fit(float(h[ti]), phi, fs)
    out = MultiModel(
        model.channels, {c: Model(tuple(v)) for c, v in models.items()}, [sp for sp in shared]
    )
    # covariances are set directly: fitted ones may be singular (PSD, not PD)
    fixed = []
    shared_terms = [ti for ti, t in enumerate(prob.terms) if t.shared]
    for sp, ti in zip(out.shared, shared_terms, strict=True):
        fixed.append(replace(sp, cov=np.array(s[ti], dtype=float)))
    out.shared = tuple(fixed)
    return out


def boundary_estimates(fitted: MultiModel, prob: MProblem, u: np.ndarray) -> list[str]:
    out = []
    for t in fitted.terms():
        if t.shared:
            sp = fitted.shared_process(t.label)
            cov = np.asarray(sp.cov)
            for a, c in enumerate(sp.channels):
                if cov[a, a] == 0.0:
                    out.append(f"{t.label}.cov[{c},{c}]")
            if not t.diagonal and cov.shape[0] > 1:
                lam = np.linalg.eigvalsh(cov)
                if lam[0] <= 1e-10 * max(float(lam[-1]), 1e-300):
                    out.append(f"{t.label}.cov (singular)")
        elif t.proto.linear_coef() == 0.0:
            p = t.proto
            name = p.param_names[-1] if p.nonlinear else p.param_names[0]
            out.append(f"{fitted.channels[t.chans[0]]}.{t.label}.{name}")
    for ti, ui in zip(prob.slots, u, strict=True):
        if prob.at_edge(ti, float(ui)):
            t = prob.terms[ti]
            key = t.label if t.shared else f"{fitted.channels[t.chans[0]]}.{t.label}"
            out.append(f"{key}.{t.proto.nonlinear}")
    return out


def search(
    prob: MProblem, model: MultiModel, wvm: WVMatrix, w: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Non-linear search: univariate starts, scans of shared phi/beta, Nelder-Mead, polish."""
    fs = wvm.fs
    lo, hi = prob.lo, prob.hi
    fallback = math.log(float(prob.tau[0]))  # a term without a usable value starts here
    # univariate fits of every channel give per-channel starting values
    uni: dict[str, Model] = {}
    for p, c in enumerate(model.channels):
        m = model.models[c].cleared()
        if m.is_linear:
            continue
        try:
            uni[c] = fit_gmwm(wvm.wv(p), m, weights=w[:, p, p]).model
        except (FitError, ModelError) as e:
            raise FitError(f"channel {c}: {e}") from None

    def uni_u(ti: int, c: str, label: str) -> float:
        """Start from channel c's univariate fit (AR1/GM most persistent first)."""
        i = find_label(uni[c], label)
        phi = None if i is None else uni[c].processes[i].nl_value(fs)
        return prob.u_of(ti, phi, fallback)

    u0 = np.empty(len(prob.slots))
    shared_slots = []
    for si, ti in enumerate(prob.slots):
        t = prob.terms[ti]
        if t.shared:
            shared_slots.append(si)
            u0[si] = np.median([uni_u(ti, model.channels[p], t.label) for p in t.chans])
        else:
            u0[si] = uni_u(ti, model.channels[t.chans[0]], t.label)
    starts = [u0]
    # user values as another start
    user = []
    for ti in prob.slots:
        t = prob.terms[ti]
        if t.shared:
            phi = phi_of_nl(t.proto, model.shared_process(t.label).nl, fs)
        else:
            phi = t.proto.nl_value(fs)  # None when the value is unknown
        user.append(phi)
    given = [prob.u_of(ti, v, math.nan) for ti, v in zip(prob.slots, user, strict=True)]
    if not any(math.isnan(v) for v in given):
        starts.append(np.array(given))
    # each shared phi/beta: the channels' univariate values and a scan, others held
    best_u = min(starts, key=prob.profile).copy()
    for si in shared_slots:
        ti = prob.slots[si]
        t = prob.terms[ti]
        cands = [uni_u(ti, model.channels[p], t.label) for p in t.chans] + list(prob.scans[ti])
        vals = []
        for cval in cands:
            uu = best_u.copy()
            uu[si] = cval
            vals.append((prob.profile(uu), cval))
        best_u[si] = min(vals)[1]
    starts.append(best_u)
    step = prob.step
    results: list[tuple[float, np.ndarray, bool]] = []
    for st in starts:
        if any(np.max(np.abs(st - r[1])) < 1e-9 for r in results):
            continue
        results.append(local(prob.profile, st, step, lo, hi, maxfev=_maxfev(st)))
    f, u, conv = min(results, key=lambda r: r[0])
    # polish block by block (a channel's own AR1/GM terms, then the shared ones)
    blocks: dict[Any, list[int]] = {}
    for si, ti in enumerate(prob.slots):
        t = prob.terms[ti]
        blocks.setdefault("shared" if t.shared else t.chans[0], []).append(si)
    if len(blocks) > 1:
        for _ in range(3):
            improved = False
            for idx in blocks.values():

                def sub(v: np.ndarray, idx: list[int] = idx, base: np.ndarray = u) -> float:
                    uu = base.copy()
                    uu[idx] = v
                    return prob.profile(uu)

                fb, vb, _ = local(sub, u[idx], step[idx] / 4, lo[idx], hi[idx], maxfev=_maxfev(idx))
                if fb < f * (1 - 1e-10):
                    u = u.copy()
                    u[idx] = vb
                    f, improved = fb, True
            if not improved:
                break
        f2, u2, conv2 = local(prob.profile, u, step / 8, lo, hi, maxfev=_maxfev(u))
        if f2 <= f:
            f, u, conv = f2, u2, conv2
    return u, conv
