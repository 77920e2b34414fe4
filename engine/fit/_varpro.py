"""Variable projection: the one search every GMWM-type fit runs.

Each latent process has non-negative linear coefficients (variances) and AR1/GM terms also one
non-linear parameter, searched in the coordinate ``u`` the process declares
(:meth:`engine.models.Process.search_nl`: an AR1 or a GM ``u = log(correlation time in
samples)``; terms of one kind are interchangeable, so a candidate lists each kind's
coordinates in decreasing order). For fixed ``u`` the
minimum over the linear part is an inner problem solved exactly (NNLS for a univariate or a
replicate fit, a conic PSD solve for the multivariate fit); the outer search over ``u`` is a
grid of correlation times (:func:`grid_axis`, :func:`grid_candidates`), the best candidates by
branch and bound (:func:`best_candidates`), local Nelder-Mead searches (:func:`local`) and, in
:func:`engine.fit.fit_gmwm`, the sub-models' optima as anchors (:func:`nested_search`,
:func:`corner_anchors`); the lowest objective wins (:func:`search`). Correlation times shorter
than one sample are kept and flagged (:func:`sub_sample_warnings`). The steps, that choice and
the protocol a problem object ``prob`` implements (``k``, ``lo``, ``hi``, ``axis``,
``profile``, optional ``lower_bounds``): docs/methods.md, "The variable-projection search";
why it reaches the global minimum: docs/fitting.md.

Reference: Golub & Pereyra (2003), Separable nonlinear least squares: the variable projection
method and its applications, Inverse Problems 19(2).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from .._optim import nnls
from ..models import GM, TC_MAX_FACTOR, TC_MIN, WN, Model, Process
from ..units import param_unit
from ..wv import WaveletVariance
from .result import FitError

__all__ = [
    "NNLSProblem",
    "sqrt_weight",
    "grid_axis",
    "grid_candidates",
    "best_candidates",
    "local",
    "search",
    "drop_one",
    "corner_anchors",
    "start_coordinates",
    "nested_search",
    "persistent_first",
    "fitted_model",
    "search_message",
    "at_bound",
    "TC_FLAG",
    "sub_sample_message",
    "sub_sample_warnings",
    "fitted_fields",
]

# AR1/GM correlation times (samples) below this are flagged after every fit: one sample.
TC_FLAG = 1.0
# Tolerances of the Nelder-Mead run that checks a local minimum (:func:`local`): coordinates
# (log correlation times) and objective (relative).
CHECK_XATOL = 1e-4
CHECK_FATOL = 1e-8
# A local search whose best point comes this close to a minimum already found (in grid steps,
# every coordinate) without being below it stops there (:func:`local`, :func:`search`).
MERGE = 0.25
# Candidates whose exact profile branch and bound computes at once (``profile_many``).
_CHUNK = 32


def sqrt_weight(omega: np.ndarray) -> np.ndarray:
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


def grid_axis(tau_max: float, k: int) -> np.ndarray:
    """Log correlation times (samples) explored per AR1/GM term: 0.25 to 4x the largest scale.

    60 points for one term, 36 for two, 18 for three, 10 beyond (the candidates grow as
    ``C(n, k)``): the axis a GM declares (:meth:`engine.models.Process.search_axis`).
    """
    return np.asarray(GM().search_axis(tau_max, k))


class SearchGroup(NamedTuple):
    """The terms of one kind in a problem's search coordinates (interchangeable terms).

    ``proto``: one of them (its class declares the coordinate); ``cols``: their columns in the
    design (process indices); ``start``: the position of their first coordinate in ``u``;
    ``lo``, ``hi``: the coordinate's range; ``axis``: its grid.
    """

    proto: Process
    cols: np.ndarray
    start: int
    lo: float
    hi: float
    axis: np.ndarray

    @property
    def n(self) -> int:
        """Number of terms of this kind."""
        return int(self.cols.size)

    @property
    def span(self) -> slice:
        """Their coordinates' slice of ``u``."""
        return slice(self.start, self.start + self.n)


def search_groups(model: Model, tau_max: float, n_max: int) -> list[SearchGroup]:
    """The model's non-linear terms grouped by kind, in the model's order, each with the
    coordinate range and grid its process declares (:meth:`engine.models.Process.search_range`,
    :meth:`~engine.models.Process.search_axis`)."""
    idx = [i for i, p in enumerate(model.processes) if p.nonlinear is not None]
    groups: list[SearchGroup] = []
    start = 0
    for _, run in itertools.groupby(idx, key=lambda i: type(model.processes[i])):
        cols = np.array(list(run), dtype=int)
        proto = model.processes[int(cols[0])]
        lo, hi = proto.search_range(n_max)
        axis = np.asarray(proto.search_axis(tau_max, int(cols.size)), dtype=float)
        groups.append(SearchGroup(proto, cols, start, lo, hi, axis))
        start += int(cols.size)
    return groups


def grid_candidates(axis: np.ndarray, k: int) -> list[tuple[float, ...]]:
    """Candidate coordinates: distinct AR1/GM terms are interchangeable, so each candidate
    lists decreasing correlation times."""
    return list(itertools.combinations(axis[::-1], k))


# -------------------------------------------------------------------------------------------
# the univariate inner problem
# -------------------------------------------------------------------------------------------
class NNLSProblem:
    """The weighted NNLS sub-problem for a univariate model and (stacked) WV moments.

    ``min_{h >= 0} ||A (nu_hat - X(phi) h)||^2`` with ``X`` the processes' WV shapes at the
    scales ``tau`` (samples). A replicate fit stacks its recordings' scales and moments with a
    block-diagonal ``A``.

    Parameters
    ----------
    model : Model
        The model structure (values ignored).
    tau : ndarray (M,)
        Scales in samples.
    fs : float
        Sampling frequency (Hz).
    a : ndarray (M, M)
        Square root of the weighting matrix (:func:`sqrt_weight`).
    nu : ndarray (M,)
        Empirical WV at ``tau``.
    n_max : int
        Longest series length (samples), which sets the largest correlation time searched.
    """

    def __init__(
        self,
        model: Model,
        tau: np.ndarray,
        fs: float,
        a: np.ndarray,
        nu: np.ndarray,
        n_max: int,
        tau_max: float | None = None,
    ):
        self.model = model
        self.tau = np.asarray(tau, dtype=float)
        self.fs = fs
        self.a = a
        self.b = a @ nu
        self.bb = float(self.b @ self.b)
        self.nl_idx = [i for i, p in enumerate(model.processes) if p.nonlinear is not None]
        self.k = len(self.nl_idx)
        self.p = len(model.processes)
        # the range of correlation times that at_bound reports against (AR1/GM)
        self.tc_min = TC_MIN
        self.tc_max = TC_MAX_FACTOR * n_max
        # each kind's search coordinate, as its process declares it
        t_max = float(self.tau.max() if tau_max is None else tau_max)
        self.groups = search_groups(model, t_max, n_max)
        self._range_of = {int(i): (g.lo, g.hi) for g in self.groups for i in g.cols.tolist()}
        self.lo: float | np.ndarray
        self.hi: float | np.ndarray
        self.spacing: float | np.ndarray
        if len(self.groups) <= 1:  # one kind (or none): scalars, one axis
            lo, hi = (self.groups[0].lo, self.groups[0].hi) if self.groups else (-1.0, 1.0)
            self.lo, self.hi = lo, hi
            self.axis = self.groups[0].axis if self.groups else np.linspace(-1.0, 1.0, 2)
            self.spacing = float(self.axis[1] - self.axis[0])
        else:  # one range and one grid spacing per coordinate
            self.lo = np.concatenate([np.full(g.n, g.lo) for g in self.groups])
            self.hi = np.concatenate([np.full(g.n, g.hi) for g in self.groups])
            self.axis = self.groups[0].axis
            self.spacing = np.concatenate(
                [np.full(g.n, float(g.axis[1] - g.axis[0])) for g in self.groups]
            )
        # constant columns of the linear processes
        self.x_fixed = np.zeros((self.tau.size, self.p))
        for i, pr in enumerate(model.processes):
            if pr.nonlinear is None:
                self.x_fixed[:, i] = pr.basis(self.tau, self.fs)
        # the weighted constant columns, once (a diagonal A, the usual case, as a vector)
        diag = not np.count_nonzero(a - np.diag(np.diagonal(a)))
        self._a_diag: np.ndarray | None = np.ascontiguousarray(np.diagonal(a)) if diag else None
        self._c_fixed = self._weigh(self.x_fixed)
        self._memo: dict[bytes, float] = {}
        self._nl_dead: dict[bytes, bool] = {}
        self.n_eval = 0
        # the hot path of profile(): each kind's columns at once (basis_many), unless an AR1's
        # phi may be 0
        self._fast = not any(model.processes[i].phi_can_vanish for i in self.nl_idx)
        self._c_work = self._c_fixed.copy()  # the weighted design of the point profiled
        # per kind: its span of u, its columns of the design (a slice when they are adjacent)
        # and its process's column kernel (the scale terms prepared once)
        self._kernels = [
            (
                g.span,
                slice(int(g.cols[0]), int(g.cols[-1]) + 1)
                if np.array_equal(g.cols, np.arange(g.cols[0], g.cols[-1] + 1))
                else g.cols,
                g.proto.search_kernel(self.tau, self.fs, g.lo, g.hi),
            )
            for g in self.groups
        ]
        # the positive set of the last NNLS and the other columns: the next point's, most
        # often (see _inner)
        self._active: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._tol = 1e-12 * math.sqrt(self.bb)
        from scipy.linalg.lapack import dposv  # on first use: `import engine` stays light

        self._dposv = dposv

    @classmethod
    def from_wv(cls, model: Model, wv: WaveletVariance, a: np.ndarray) -> NNLSProblem:
        """The problem of one WV (all its levels)."""
        return cls(
            model,
            wv.tau_samples,
            wv.fs,
            a,
            wv.variance,
            max(wv.n, 2 ** (wv.n_levels + 1)),
            float(wv.tau_samples[-1]),
        )

    # the non-linear coordinates: each process's own (AR1, GM: log correlation time, samples)
    def phi_of(self, i: int, u: float) -> float:
        """The fitter's non-linear value of process i (AR1, GM: phi) at its coordinate u."""
        lo, hi = self._range_of[i]
        return float(self.model.processes[i].search_nl(u, lo, hi))

    def phis_of(self, u: np.ndarray | Sequence[float]) -> tuple[float, ...]:
        """The non-linear value of every non-linear term from the search coordinates."""
        return tuple(self.phi_of(i, float(ui)) for i, ui in zip(self.nl_idx, u, strict=True))

    def _column(self, i: int, phi: float) -> np.ndarray:
        """The WV shape of non-linear term ``i`` at ``phi`` (unweighted, a new array)."""
        return np.asarray(self.model.processes[i].basis(self.tau, self.fs, phi), float)

    def candidates(self) -> list[tuple[float, ...]]:
        """The grid's candidates: per kind the combinations of its axis (interchangeable
        terms, coordinates decreasing), and every pairing of the kinds."""
        if len(self.groups) <= 1:
            return grid_candidates(self.axis, self.k)
        per = [grid_candidates(g.axis, g.n) for g in self.groups]
        return [tuple(x for part in combo for x in part) for combo in itertools.product(*per)]

    def embed(self, sub: Model, u: Sequence[float]) -> tuple[float, ...] | None:
        """The point of this problem that a sub-model's optimum ``u`` stands for (its
        coordinates in their groups, each group's decreasing); with one non-linear term fewer,
        the best point of the line along the missing term's axis (:func:`corner_anchors`).
        None when ``sub`` is not a sub-model of this problem's model."""
        by_kind: dict[type, list[float]] = {}
        nl = [q for q in sub.processes if q.nonlinear is not None]
        for q, x in zip(nl, u, strict=True):
            by_kind.setdefault(type(q), []).append(float(x))
        parts: list[list[float]] = []
        free = None
        for gi, g in enumerate(self.groups):
            xs = sorted(by_kind.pop(type(g.proto), []), reverse=True)
            if len(xs) == g.n - 1 and free is None:
                free = gi
            elif len(xs) != g.n:
                return None
            parts.append(xs)
        if by_kind:
            return None
        if free is None:
            return tuple(x for xs in parts for x in xs)
        line = [
            tuple(
                x
                for gi, xs in enumerate(parts)
                for x in (sorted([*xs, float(t)], reverse=True) if gi == free else xs)
            )
            for t in self.groups[free].axis
        ]
        return best_candidates(self, line, 1)[0][1]

    def design(self, phis: tuple[float, ...]) -> np.ndarray:
        """The (M, p) matrix of WV shapes for the AR1/GM coefficients ``phis``."""
        x = self.x_fixed.copy()
        for i, phi in zip(self.nl_idx, phis, strict=True):
            x[:, i] = self._column(i, phi)
        return x

    def _weigh(self, x: np.ndarray) -> np.ndarray:
        """``A x`` (rows of ``x`` are scales)."""
        if self._a_diag is None:
            return self.a @ x
        return self._a_diag[:, None] * x if x.ndim == 2 else self._a_diag * x

    def _inner(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and ``h >= 0`` for the weighted design ``c = A X``.

        The search moves by small steps, so the positive set of the previous solution is tried
        first: the least-squares solution on that set (its normal equations) is the NNLS
        solution when it is positive and no other column's gradient ``c_j' r`` is positive
        (the KKT conditions, sufficient for this convex problem: up to ``1e-12 ||b|| ||c_j||``).
        Otherwise SciPy's Lawson-Hanson solves it from scratch, on unit-norm columns.
        """
        self.n_eval += 1
        gram = c.T @ c
        cb = c.T @ self.b
        h = None if self._active is None else self._on_active_set(gram, cb)
        if h is None:
            norms = np.sqrt(np.diagonal(gram))
            norms = np.where(norms == 0, 1.0, norms)
            g, _ = nnls(c / norms, self.b, maxiter=50 * self.p)
            h = g / norms
            pos = h > 0
            s = np.flatnonzero(pos)
            self._active = (s, s[:, None], np.flatnonzero(~pos))
        r = self.b - c @ h
        return float(r @ r), h

    def _on_active_set(self, gram: np.ndarray, cb: np.ndarray) -> np.ndarray | None:
        """The NNLS solution if the last positive set is still its positive set, else None
        (normal equations ``gram h = cb`` on the set, by Cholesky; KKT on the others)."""
        assert self._active is not None
        s, s_col, rest = self._active
        h = np.zeros(self.p)
        if s.size:
            _, hs, info = self._dposv(gram[s_col, s], cb[s])  # 3 us, np.linalg.solve 15
            if info or min(hs.tolist()) <= 0:  # (a list's min: a few entries)
                return None
            h[s] = hs
        if rest.size:
            grad = (cb - gram @ h)[rest]
            if max(grad.tolist()) > 0 and np.any(grad > self._tol * np.sqrt(gram[rest, rest])):
                return None
        return h

    def solve(self, phis: tuple[float, ...]) -> tuple[float, np.ndarray, np.ndarray]:
        """Objective, h >= 0 and the design matrix for fixed non-linear values."""
        x = self.design(phis)
        c = self._c_fixed.copy()
        for i in self.nl_idx:
            c[:, i] = self._weigh(x[:, i])
        f, h = self._inner(c)
        return f, h, x

    def profile(self, u: np.ndarray) -> float:
        """The profiled objective at the search coordinates ``u`` (each point solved once: a
        search comes back to its starts and anchors)."""
        u = np.asarray(u, dtype=float)
        key = u.tobytes()
        f = self._memo.get(key)
        if f is None:
            if self._fast and self.k:  # phi_of and _column of each kind's terms at once
                ul = u.tolist()
                c = self._c_work
                a_diag = self._a_diag
                for span, cols, kernel in self._kernels:
                    x = kernel(ul[span])  # (n, M)
                    c[:, cols] = (x * a_diag).T if a_diag is not None else self.a @ x.T
            else:
                c = self._c_fixed.copy()
                for i, ui in zip(self.nl_idx, u, strict=True):
                    c[:, i] = self._weigh(self._column(i, self.phi_of(i, float(ui))))
            f, h = self._inner(c)
            self._memo[key] = f
            if self.k:  # an AR1/GM term at zero variance: the point is on a sub-model's surface
                self._nl_dead[key] = min(h[self.nl_idx].tolist()) <= 0.0
        return f

    def nl_term_dead(self, u: np.ndarray) -> bool:
        """Whether an AR1/GM term has zero variance at ``u``, a point :meth:`profile` solved
        (False for a point it did not): there the objective is a sub-model's, whose optimum an
        anchor of :func:`nested_search` stands for."""
        return self._nl_dead.get(np.asarray(u, dtype=float).tobytes(), False)

    def profile_many(self, u: np.ndarray) -> np.ndarray:
        """:meth:`profile` at each row of ``u`` (C, k), the exact NNLS of all rows at once.

        Every positive set of the ``p`` columns is solved by least squares (unit-norm columns,
        one batched solve) and the objective is the smallest ``||b - c h||^2`` among the
        solutions with ``h > 0`` on their set: each is a feasible point, and the NNLS solution
        is the least-squares solution on its own positive set, so that minimum is the NNLS
        optimum. For the grid's exact profiles (:func:`best_candidates`).
        """
        u = np.asarray(u, dtype=float)
        keys = [row.tobytes() for row in u]
        out = np.array([self._memo.get(key, math.nan) for key in keys])
        todo = np.flatnonzero(np.isnan(out))
        if not todo.size:
            return out
        if not (self._fast and self.k) or self.p > 6:
            for i in todo:
                out[i] = self.profile(u[i])
            return out
        uu = u[todo]
        c = np.repeat(self._c_fixed[None], todo.size, axis=0)  # (B, M, p)
        for grp in self.groups:
            pr = grp.proto
            nls = np.asarray(pr.search_nl(uu[:, grp.span], grp.lo, grp.hi), dtype=float)
            cols = pr.basis_many(self.tau, self.fs, nls.ravel()).reshape(todo.size, grp.n, -1)
            c[:, :, grp.cols] = (
                self._weigh(cols.transpose(2, 0, 1).reshape(self.tau.size, -1))
                .reshape(self.tau.size, todo.size, grp.n)
                .transpose(1, 0, 2)
            )
        norms = np.sqrt(np.einsum("bmi,bmi->bi", c, c))
        norms[norms == 0] = 1.0
        cn = c / norms[:, None, :]
        gram = np.einsum("bmi,bmj->bij", cn, cn)
        cb = np.einsum("bmi,m->bi", cn, self.b)
        masks = self._subsets()  # (S, p)
        both = masks[:, :, None] & masks[:, None, :]
        eye = np.eye(self.p, dtype=bool)
        g = np.where(both, gram[:, None], np.where(eye, 1.0, 0.0))  # (B, S, p, p)
        rhs = np.where(masks, cb[:, None, :], 0.0)
        try:
            h = np.linalg.solve(g, rhs[..., None])[..., 0]  # (B, S, p), 0 off the set
        except np.linalg.LinAlgError:
            for i in todo:
                out[i] = self.profile(u[i])
            return out
        ok = np.all((h > 0) | ~masks, axis=2)
        r = self.b[None, None, :] - np.einsum("bmp,bsp->bsm", cn, h)
        f = np.where(ok, np.einsum("bsm,bsm->bs", r, r), np.inf).min(axis=1)
        f = np.minimum(f, self.bb)  # h = 0
        self.n_eval += todo.size
        for i, val in zip(todo, f.tolist(), strict=True):
            out[i] = self._memo[keys[i]] = val
        return out

    def _subsets(self) -> np.ndarray:
        """Every non-empty subset of the ``p`` columns, as (2^p - 1, p) masks."""
        n = np.arange(1, 2**self.p)
        return (n[:, None] >> np.arange(self.p)) & 1 == 1

    def lower_bounds(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unconstrained weighted least squares of all candidates at once (batched QR).

        It bounds the non-negative one from below and equals it where every coefficient is
        non-negative.
        """
        nc = u.shape[0]
        xs = np.repeat(self.x_fixed[None, :, :], nc, axis=0)
        for col, i in enumerate(self.nl_idx):
            pr = self.model.processes[i]
            # the grid's candidates share a few axis values: each column formed once
            vals, where = np.unique(u[:, col], return_inverse=True)
            nls = pr.search_nl(vals, -math.inf, math.inf)  # unclipped
            xs[:, :, i] = np.asarray(pr.basis(self.tau, self.fs, nls)).reshape(vals.size, -1)[where]
        if self._a_diag is None:
            cmat = np.einsum("ij,cjk->cik", self.a, xs)
        else:  # a diagonal A (the usual case) as a vector
            cmat = xs * self._a_diag[None, :, None]
        norms = np.sqrt(np.sum(cmat * cmat, axis=1, keepdims=True))
        norms[norms == 0] = 1.0
        cn = cmat / norms
        with np.errstate(all="ignore"):
            q, r = np.linalg.qr(cn)
            qb = np.einsum("cjk,j->ck", q, self.b)
            lower = self.bb - np.sum(qb * qb, axis=1)
            try:
                coef = np.linalg.solve(r, qb[:, :, None])[:, :, 0]
                feasible = np.all(coef >= 0, axis=1) & np.all(np.isfinite(coef), axis=1)
            except np.linalg.LinAlgError:
                feasible = np.zeros(nc, dtype=bool)
        lower = np.where(np.isfinite(lower), np.maximum(lower, 0.0), 0.0)
        return lower, feasible


# -------------------------------------------------------------------------------------------
# the outer search
# -------------------------------------------------------------------------------------------
def best_candidates(
    prob: Any, cands: Sequence[Sequence[float]], keep: int
) -> list[tuple[float, tuple[float, ...]]]:
    """Exact profiled objective of the ``keep`` best candidates, best first.

    With ``prob.lower_bounds``, by branch and bound: candidates are evaluated exactly in
    increasing order of their lower bound until the bound exceeds the ``keep``-th best exact
    value (the same candidates as profiling all of them).
    """
    u = np.asarray(cands, dtype=float)  # (C, k)
    if hasattr(prob, "lower_bounds"):
        lower, exact = prob.lower_bounds(u)
    else:
        lower = np.array([prob.profile(c) for c in u])
        exact = np.ones(u.shape[0], dtype=bool)
    order = np.argsort(lower, kind="stable")
    best: list[tuple[float, tuple[float, ...]]] = []
    many = getattr(prob, "profile_many", None)
    vals: dict[int, float] = {}
    for n, c in enumerate(order):
        if len(best) >= keep and lower[c] > best[-1][0] * (1 + 1e-12):
            break
        if not exact[c] and c not in vals and many is not None:  # the next few at once
            nxt = [int(d) for d in order[n : n + _CHUNK] if not exact[d]]
            vals.update(zip(nxt, many(u[nxt]).tolist(), strict=True))
        if exact[c]:
            val = float(lower[c])
        else:
            val = vals[c] if c in vals else prob.profile(u[c])
        best.append((val, tuple(u[c])))
        best.sort(key=lambda t: t[0])
        best = best[:keep]
    return best


def local(
    fun: Callable[[np.ndarray], float],
    u0: Sequence[float] | np.ndarray,
    step: Any,
    lo: Any,
    hi: Any,
    *,
    maxfev: int | None = None,
    known: Sequence[tuple[float, np.ndarray]] = (),
    merge: Any = 0.0,
    stop: Callable[[np.ndarray, float], bool] | None = None,
) -> tuple[float, np.ndarray, bool]:
    """Local minimum of ``fun`` from ``u0`` (clipped into ``[lo, hi]``).

    Nelder-Mead (:func:`scipy.optimize.minimize`) from a simplex of side ``step``, restarted
    on a simplex 8x smaller until a restart no longer lowers the objective (Nelder-Mead copes
    with the kinks where the set of zero variances changes, where gradient methods stall).
    At most 8 restarts of at most ``maxfev`` evaluations each (default ``400 k``).

    A run from a point it did not improve on meets ``xatol = 1e-6`` (coordinates) and
    ``fatol = 1e-10`` (relative). A restart after an improving run is a check: it stops at
    ``CHECK_XATOL`` and ``CHECK_FATOL``, since what it is for is finding a lower point, not
    locating it; when it finds one (lower by more than ``1e-10`` relative) the next run starts
    from there at the full tolerance. On the imu1 gyro_x ranking no check ever found a lower
    point, and checks cost half of all evaluations at the full tolerance.

    ``known`` lists local minima ``(f, u)`` already found by other runs on the same function
    (:func:`search`): when the best point of a run comes within ``merge`` of one of them in
    every coordinate and is not below it, the run is heading for that minimum and stops there
    (it returns that minimum: a run that finds it again adds nothing to the search's lowest).
    ``stop(u, f)``, when given, is asked of each iteration's best point: True stops the run
    there (it returns that point, not converged; :func:`search` then drops the run).

    Returns
    -------
    f, u, converged
        The objective, the coordinates and whether the last run met its tolerance.
    """
    from scipy import optimize  # on first use: `import engine` stays light (test_public_api)

    x = np.clip(np.asarray(u0, float), lo, hi)
    k = x.size
    maxfev = 400 * k if maxfev is None else maxfev
    f = fun(x)
    converged = False
    check = False  # the previous run lowered the objective: this one checks its minimum
    hit: list[tuple[float, np.ndarray]] = []

    stopped: list[tuple[float, np.ndarray]] = []

    def merged(intermediate_result: Any) -> None:  # (SciPy passes the best point by this name)
        r = intermediate_result  # the run's best point: in a known minimum's basin?
        for fk, uk in known:
            if r.fun >= fk and np.all(np.abs(r.x - uk) <= merge):
                hit.append((fk, uk))
                raise StopIteration
        if stop is not None and stop(r.x, float(r.fun)):
            stopped.append((float(r.fun), np.array(r.x, float)))
            raise StopIteration

    for _ in range(8):
        simplex = np.vstack([x] + [x + step * e for e in np.eye(k)])
        res = optimize.minimize(
            fun,
            x,
            method="Nelder-Mead",
            callback=merged if known or stop is not None else None,
            options={
                "initial_simplex": simplex,
                "xatol": CHECK_XATOL if check else 1e-6,
                "fatol": (CHECK_FATOL if check else 1e-10) * max(f, 1e-300),
                "maxfev": maxfev,
            },
        )
        if hit:
            return hit[0][0], np.array(hit[0][1], float), True
        if stopped:
            return stopped[0][0], stopped[0][1], False
        fn = float(res.fun)
        if fn < f * (1 - 1e-10):
            x, f = np.asarray(res.x, float), fn
            step = max(step / 8, 1e-5) if isinstance(step, float) else np.maximum(step / 8, 1e-5)
            check = not check
        else:
            converged = bool(res.success) or fn <= f
            break
    return f, x, converged


def search(
    prob: Any,
    starts: Sequence[Sequence[float]] = (),
    *,
    keep: int = 3,
    anchors: Sequence[Sequence[float]] = (),
    anchor_minima: Sequence[float | None] = (),
) -> tuple[float, np.ndarray, bool]:
    """The variable-projection search over the non-linear coordinates (see the module notes).

    Parameters
    ----------
    prob
        A problem with ``k``, ``lo``, ``hi``, ``axis``, ``profile`` (and optionally
        ``lower_bounds``), see the module docstring.
    starts : sequence of (k,) coordinates
        Extra candidates next to the grid (user values, other fits).
    keep : int
        Number of best candidates the local search starts from (0: no grid, the anchors
        only).
    anchors : sequence of (k,) coordinates
        Points every one of which starts a local search of its own, whatever its grid rank
        (:func:`nested_search`: the sub-models' optima), so the result is at or below each.
    anchor_minima : sequence of float or None
        Per anchor, the objective of the sub-model optimum it is (same coordinates, a
        one-parameter term fewer), or None. An anchor whose objective here equals it (the
        extra term stays at zero variance) is a local minimum already: it starts no local
        search, and a run that comes near it merges into it.

    Notes
    -----
    With anchors, a local search whose best point has an AR1/GM term at zero variance and is
    not below the lowest anchor stops (``prob.nl_term_dead``): it is on a sub-model's
    surface, where the objective is at least that sub-model's optimum, which an anchor
    already stands for.

    Returns
    -------
    f, u, converged
    """
    grid = prob.candidates() if hasattr(prob, "candidates") else grid_candidates(prob.axis, prob.k)
    cands = grid + [tuple(s) for s in starts]
    best = best_candidates(prob, cands, keep) if keep else []
    spacing = getattr(prob, "spacing", None)
    if spacing is None:
        spacing = float(prob.axis[1] - prob.axis[0])

    def near(a: Any, b: Any) -> bool:  # within 1.5 grid steps in every coordinate
        if isinstance(spacing, float):
            return bool(np.max(np.abs(np.asarray(a) - b)) < 1.5 * spacing)
        return bool(np.max(np.abs(np.asarray(a) - b) / spacing) < 1.5)

    results: list[tuple[float, np.ndarray, bool]] = []
    found: list[tuple[float, np.ndarray]] = []  # the converged local minima, for local()
    merge = MERGE * spacing
    # the anchors (the sub-models' optima) profiled first: a sub-model optimum whose extra
    # term stays at zero variance here is a local minimum of this model already
    pts = [np.clip(np.asarray(a, float), prob.lo, prob.hi) for a in anchors]
    vals = [prob.profile(a) for a in pts]
    mins = list(anchor_minima) + [None] * (len(pts) - len(anchor_minima))
    settled = [fs is not None and fa >= fs * (1 - 1e-12) for fa, fs in zip(vals, mins, strict=True)]
    found += [(fa, a) for fa, a, ok in zip(vals, pts, settled, strict=True) if ok]
    floor = min(vals, default=math.inf)
    dead = getattr(prob, "nl_term_dead", None)
    on_sub: Callable[[np.ndarray, float], bool] | None = None
    if dead is not None and pts:

        def on_sub(u: np.ndarray, f: float) -> bool:
            return f >= floor and dead(u)

    def run(u0: Any) -> tuple[float, np.ndarray, bool] | None:
        hits: list[bool] = []

        def stop(u: np.ndarray, f: float) -> bool:
            hits.append(on_sub is not None and on_sub(u, f))
            return hits[-1]

        r = local(
            prob.profile,
            u0,
            spacing / 2,
            prob.lo,
            prob.hi,
            known=found,
            merge=merge,
            stop=stop if on_sub is not None else None,
        )
        if hits and hits[-1]:  # on a sub-model's surface, above an anchor: nothing new
            passed.append(r[1])
            return None
        if r[2]:
            found.append((r[0], r[1]))
        return r

    passed: list[np.ndarray] = []  # where the runs dropped for being on a sub-model's stopped
    for _, u0 in best:
        # a start next to a local minimum already found adds nothing
        if any(near(u0, r[1]) for r in results) or any(near(u0, d) for d in passed):
            continue
        r = run(u0)
        if r is not None:
            results.append(r)
    # the anchors, best first: each is a result in its own right, so the fit is at or below
    # every one of them; a local search starts from the best one, unless it is a minimum
    # already (settled) or a local minimum already found is next to it and not above it (the
    # same basin: a sub-model's optimum with the larger model's extra term at 0 is often the
    # larger model's too), and from every other that is neither settled nor next to a start
    # or a minimum searched
    ranked = sorted(zip(vals, pts, settled, strict=True), key=lambda t: t[0])
    minima = list(results)
    seen = [np.asarray(u0, float) for _, u0 in best] + [r[1] for r in results] + passed
    for k, (fa, a0, ok) in enumerate(ranked):
        results.append((fa, a0, True))
        if ok:
            continue
        if k and any(near(a0, d) for d in seen):
            continue
        if not k and any(r[0] <= fa * (1 + 1e-8) and near(a0, r[1]) for r in minima):
            continue
        seen.append(a0)
        r = run(a0)
        if r is not None:
            results.append(r)
    return min(results, key=lambda r: r[0])


def drop_one(model: Model) -> list[Model]:
    """The distinct sub-models of ``model`` with one term fewer (none for a one-term model)."""
    out: dict[str, Model] = {}
    for i in range(len(model.processes)):
        procs = model.processes[:i] + model.processes[i + 1 :]
        if procs:
            sub = Model(tuple(p.cleared() for p in procs))
            out.setdefault(sub.spec(), sub)
    return list(out.values())


def corner_anchors(
    prob: Any, optima: Sequence[tuple[float, ...]], subs: Sequence[Model] | None = None
) -> list[tuple[float, ...]]:
    """The sub-models' optima as points of ``prob`` (the degenerate corners of its space).

    A sub-model with the same AR1/GM terms (a one-parameter term dropped) has the same
    coordinates: its optimum is a point of ``prob`` whose profiled objective is at most the
    sub-model's (the dropped term's variance may stay 0). A sub-model with one AR1/GM term
    fewer gives a line of such points, the dropped term's correlation time free: every point
    of ``prob.axis`` on it is profiled and the best one is the anchor.

    Parameters
    ----------
    prob
        The problem (``k``, ``axis``, ``profile``, optionally ``lower_bounds``).
    optima : sequence of tuples
        Each sub-model's optimal coordinates (``k`` or ``k - 1`` of them; AR1/GM terms are
        interchangeable, so the order does not matter).
    subs : sequence of Model, optional
        The sub-model of each optimum: a problem with non-linear terms of several kinds
        places each coordinate in its kind's group (``prob.embed``).

    Returns
    -------
    list of (k,) tuples, correlation times decreasing.
    """
    out: list[tuple[float, ...]] = []
    for j, u in enumerate(optima):
        if subs is not None and len(getattr(prob, "groups", ())) > 1:
            point = prob.embed(subs[j], u)
            if point is not None:
                out.append(point)
            continue
        if len(u) == prob.k:
            out.append(tuple(sorted(u, reverse=True)))
        elif len(u) == prob.k - 1:
            line = [tuple(sorted((*u, float(t)), reverse=True)) for t in prob.axis]
            out.append(best_candidates(prob, line, 1)[0][1])
    return out


def nested_search(
    model: Model,
    make_prob: Callable[[Model], Any],
    cache: dict[str, tuple[float, tuple[float, ...]]],
    starts: Sequence[Sequence[float]] = (),
    *,
    keep: int = 3,
    polish: bool = False,
) -> tuple[float, np.ndarray, bool, Any, int]:
    """:func:`search` of ``model`` anchored at the optima of its sub-models.

    The sub-models with one term fewer (:func:`drop_one`) give anchors (:func:`corner_anchors`):
    every one with one AR1/GM term fewer is searched first (recursively, each once: ``cache``
    maps a model's spec to its optimum ``(objective, coordinates)``), and one with a
    one-parameter term fewer when ``cache`` already holds it (a ranking fits the smaller
    candidates first, so there it always does). Since a sub-model's optimum is a point of the
    larger model's space with the dropped term at 0, the anchor's objective is at most the
    sub-model's and the search returns the lowest of its anchors and local minima: the fit of
    a model is never above the fit of those sub-models (by induction, of every sub-model with
    the same one-parameter terms, and in a ranking of every smaller candidate).

    Parameters
    ----------
    model : Model
        The structure to fit.
    make_prob : callable
        ``make_prob(model)`` returns its problem (the same data and weights for every model).
    cache : dict
        Optima already found for this data and these weights (filled in).
    starts : sequence of (k,) coordinates
        Extra anchors of ``model`` (e.g. the user's values): the fit is at or below each.
    keep : int
        As in :func:`search`.
    polish : bool
        ``model``'s own search has no grid (``keep = 0``): local searches from ``starts`` and
        from the anchors only, for a refit near a known optimum (its sub-models, when they
        are searched here, keep their grid).

    Returns
    -------
    f, u, converged, prob, n_eval
        The objective, coordinates and convergence of ``model``'s search, its problem, and
        the profile evaluations of the whole nested search.
    """
    n_eval = 0

    def run(m: Model, top: bool) -> tuple[float, np.ndarray, bool, Any]:
        nonlocal n_eval
        prob = make_prob(m)
        anchors_u = []
        subs = []
        for sub in drop_one(m):
            key = sub.spec()
            if key not in cache:
                if sum(q.nonlinear is not None for q in sub.processes) == prob.k:
                    continue  # a one-parameter term dropped: an anchor only when known
                f_s, u_s, _, _ = run(sub, False)
                cache[key] = (f_s, tuple(float(x) for x in u_s))
            anchors_u.append(cache[key][1])
            subs.append(sub)
        if top and m.spec() in cache:  # found before (as another model's sub-model)
            anchors_u.append(cache[m.spec()][1])
            subs.append(m)
        if prob.k == 0:
            f, u, conv = prob.profile(np.zeros(0)), np.zeros(0), True
        else:
            anchors: list[Sequence[float]] = []
            minima: list[float | None] = []  # a sub-model optimum at the same coordinates
            for opt, sub in zip(anchors_u, subs, strict=True):
                for a in corner_anchors(prob, [opt], [sub]):
                    anchors.append(a)
                    minima.append(cache[sub.spec()][0] if len(opt) == prob.k else None)
            anchors += list(starts) if top else []
            f, u, conv = search(
                prob,
                keep=0 if top and polish else keep,
                anchors=anchors,
                anchor_minima=minima,
            )
        n_eval += prob.n_eval
        return f, u, conv, prob

    f, u, conv, prob = run(model, True)
    key = model.spec()
    if key not in cache or f < cache[key][0]:
        cache[key] = (f, tuple(float(x) for x in u))
    return f, u, conv, prob, n_eval


# -------------------------------------------------------------------------------------------
# the fitted model
# -------------------------------------------------------------------------------------------
def _phi(q: Process, fs: float) -> float:
    phi = q.nl_value(fs)
    if phi is None:
        raise ValueError(f"{q.code} has no value for {q.nonlinear}: the model is not fitted")
    return phi


def start_coordinates(model: Model, fs: float) -> tuple[float, ...] | None:
    """The search coordinates of a model whose non-linear values are all given (the user's
    starting point), each kind's decreasing; None when one is unknown or out of the search's
    reach (:meth:`engine.models.Process.search_of_nl`: an AR1 with ``phi <= 0``)."""
    coords: dict[type, list[float]] = {}
    for p in model.processes:
        if p.nonlinear is None:
            continue
        nl = p.nl_value(fs)
        u = None if nl is None else p.search_of_nl(nl)
        if u is None or not math.isfinite(u):
            return None
        coords.setdefault(type(p), []).append(u)
    return tuple(x for xs in coords.values() for x in sorted(xs, reverse=True))


def persistent_first(procs: Sequence[Process], fs: float) -> Model:
    """The fitted model with its AR1/GM terms most persistent first, then the others."""
    nonlin = sorted((q for q in procs if q.nonlinear is not None), key=lambda q: -_phi(q, fs))
    return Model(tuple(nonlin + [q for q in procs if q.nonlinear is None]))


def search_message(converged: bool) -> str:
    """The message of a fit by :func:`search` (whether the local search met its tolerance)."""
    if converged:
        return "converged"
    return (
        "the local search stopped before meeting its tolerance; the estimate may be "
        "slightly above the minimum"
    )


def fitted_model(prob: NNLSProblem, u: np.ndarray, fs: float) -> Model:
    """The fitted model at the optimum ``u`` of the correlations: each process with its
    NNLS variance and its correlation, AR1/GM most persistent first.

    Parameters
    ----------
    prob : NNLSProblem
        The problem that was searched.
    u : ndarray
        The optimum (the log correlation times of its AR1/GM; empty without them).
    fs : float
        Sampling frequency (Hz).

    Returns
    -------
    Model
        Every parameter set.
    """
    phis = prob.phis_of(u)
    _, h, _ = prob.solve(phis)
    nl_vals = dict(zip(prob.nl_idx, phis, strict=True))
    procs = [
        p.from_fit(float(h[i]), nl_vals.get(i), fs) for i, p in enumerate(prob.model.processes)
    ]
    return persistent_first(procs, fs)


def at_bound(fitted: Model, fs: float, tc_min: float, tc_max: float) -> list[str]:
    """Parameters on the boundary of their space: a variance at 0, a correlation time at the
    edge of the explored range ``[tc_min, tc_max]`` (samples)."""
    out = []
    for lab, q in zip(fitted.labels, fitted.processes, strict=True):
        if q.linear_coef() == 0.0:
            out.append(f"{lab}.{q.param_names[-1] if q.nonlinear else q.param_names[0]}")
        if q.nonlinear is None:
            continue
        tc = q.correlation_time(fs)
        if tc is not None:  # AR1, GM: against the explored correlation times
            if tc > 0 and (tc <= tc_min * 1.0001 or tc >= tc_max / 1.0001):
                out.append(f"{lab}.{q.nonlinear}")
            continue
        # another coordinate: at the edge of the range its process declares
        u = q.search_of_nl(_phi(q, fs))
        lo, hi = q.search_range(int(tc_max / TC_MAX_FACTOR))
        if u is None or u <= lo + 1e-4 or u >= hi - 1e-4:
            out.append(f"{lab}.{q.nonlinear}")
    return out


def sub_sample_message(label: str, q: Process, fs: float, unit: str = "") -> str | None:
    """The warning for one fitted AR1/GM term whose correlation time is below ``TC_FLAG`` (one
    sample), else None.

    Parameters
    ----------
    label : str
        The term as the result names it (``GM_2``, ``gyro_x.GM_1`` ...).
    q : Process
        The fitted process (every value set).
    fs : float
        Sampling frequency (Hz).
    unit : str
        Signal unit (for the white-noise equivalent).

    Notes
    -----
    At scales much longer than its correlation time an AR1(phi, sigma2) has the WV of a WN of
    variance ``sigma2 / (1 - phi)^2`` (a GM: ``sigma2_gm (1 + phi) / (1 - phi)``): the
    *white-noise equivalent* a datasheet's noise density should count.
    """
    tc = q.correlation_time(fs)
    if tc is None or tc >= TC_FLAG:
        return None
    dt = 1.0 / fs
    head = (
        f"{label}: correlation time {tc * dt:.3g} s = {tc:.2g} samples, shorter than one "
        f"sample (1/fs = {dt:g} s)"
    )
    if q.linear_coef() == 0.0:
        return (
            f"{head}: its variance is 0 (absent from the fit), so its {q.nonlinear} means "
            "nothing; drop it"
        )
    equiv = q.white_equivalent(fs)
    return (
        f"{head}: white noise in disguise, with neighbouring samples correlated (e.g. by the "
        f"sensor's filter), not a physical correlation time; its WN-equivalent sigma2 = "
        f"{equiv:.4g} {param_unit(WN.code, 'sigma2', unit)} (N = {math.sqrt(equiv / fs):.4g} "
        f"{unit or 'u'}/sqrt(Hz)) belongs to the noise density (add it to WN's)"
    )


def sub_sample_warnings(fitted: Model, fs: float, unit: str = "", prefix: str = "") -> list[str]:
    """:func:`sub_sample_message` of every AR1/GM term of ``fitted`` whose correlation time is
    below one sample; ``prefix`` (e.g. a channel name and a dot) goes before the labels."""
    out = []
    for lab, q in zip(fitted.labels, fitted.processes, strict=True):
        msg = sub_sample_message(prefix + lab, q, fs, unit)
        if msg is not None:
            out.append(msg)
    return out


def fitted_fields(
    fitted: Model, wv: WaveletVariance, tc_min: float, tc_max: float
) -> dict[str, Any]:
    """The fields of a one-WV fit's result (GMWM, GMWFM) that follow from its fitted model.

    Parameters
    ----------
    fitted : Model
        The fitted model.
    wv : WaveletVariance
        The WV it was fitted to.
    tc_min, tc_max : float
        The explored range of correlation times (samples), for :func:`at_bound`.

    Returns
    -------
    dict
        ``model``, ``wv``, ``components`` (the implied WV of each process), ``implied``
        (their sum), ``at_bound`` and ``warnings`` (:func:`sub_sample_warnings`).
    """
    comps = fitted.components(wv.tau_samples, wv.fs)
    return {
        "model": fitted,
        "wv": wv,
        "components": comps,
        "implied": np.sum(np.array(list(comps.values())), axis=0),
        "at_bound": at_bound(fitted, wv.fs, tc_min, tc_max),
        "warnings": sub_sample_warnings(fitted, wv.fs, wv.unit),
    }
