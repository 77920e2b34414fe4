"""The inner solve of the MGMWM: least squares over non-negative orthants and PSD cones.

For fixed AR1/GM parameters the implied moments are linear in the coefficients ``c``
(variances of independent processes, entries of the covariance matrices of shared ones), and
:class:`ConeLSQ` solves ``min ||b - A c||^2`` subject to ``c_i >= lower_i`` and every shared
covariance positive semi-definite: the relaxed problem first, then, when a covariance is not
PSD, Newton's method on the face of the cone where the minimum lies, accepted with a KKT
certificate, with an interior-point path as the fallback. The solver knows nothing of channels
or processes: columns are ``(block, a, b, group)`` (entry ``[a, b]`` of block ``block``, row
group ``group``), and the blocks listed in ``dims`` are PSD cones. The three stages in detail:
docs/methods.md, "The MGMWM's inner solve".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._optim import nnls

__all__ = ["ConeLSQ"]


class ConeLSQ:
    """``min ||b - ax c||^2`` over a product of bounded coordinates and PSD cones.

    Parameters
    ----------
    b : ndarray, shape (R,)
        Weighted right-hand side.
    cols : sequence of (block, a, b, group)
        One entry per coefficient: entry ``[a, b]`` of block ``block``; ``group`` indexes
        ``groups`` (unused when ``groups`` is None).
    dims : dict of int to int
        The blocks constrained to the PSD cone and their dimension g (every upper-triangle
        entry of such a block is a column). Their order fixes the order of the cones.
    lower : ndarray, shape (C,)
        Lower bound of every coefficient (0 or -inf; the PSD blocks' diagonals 0).
    groups : sequence of (rows, columns, non-negative), optional
        With a diagonal weighting the problem separates into independent row groups: the
        rows (a slice), the columns that touch them, and whether those columns are
        non-negative (else free). None for a full weighting matrix.

    Attributes
    ----------
    n_inner : int
        Residual evaluations / Newton steps of the PSD-constrained solves so far.
    n_coupled : int
        Solves where the relaxation was not PSD.
    """

    def __init__(
        self,
        b: np.ndarray,
        cols: Sequence[tuple[int, int, int, int]],
        dims: dict[int, int],
        lower: np.ndarray,
        groups: Sequence[tuple[slice, list[int], bool]] | None = None,
    ) -> None:
        self.b = b
        self.cols = list(cols)
        self.dims = dict(dims)
        self.full = list(self.dims)
        self.lower = lower
        self.groups = None if groups is None else list(groups)
        self.col_of = {(ti, a, b_): ci for ci, (ti, a, b_, _) in enumerate(self.cols)}
        self.n_inner = 0
        self.n_coupled = 0
        self._face: tuple[Any, np.ndarray] | None = None  # last certified face, solution
        self._passive: dict[tuple[int, tuple[int, ...]], np.ndarray] = {}  # NNLS warm starts

    def _matrices(self, c: np.ndarray) -> dict[int, np.ndarray]:
        """The PSD blocks' symmetric matrices of coefficients ``c``."""
        s = {ti: np.zeros((g, g)) for ti, g in self.dims.items()}
        for (ti, a, b, _), v in zip(self.cols, c, strict=True):
            if ti in s:
                s[ti][a, b] = s[ti][b, a] = float(v)
        return s

    def solve(self, ax: np.ndarray) -> tuple[float, np.ndarray, bool]:
        """Minimum for the weighted design ``ax`` (R x C).

        Returns (objective, coefficients, coupled): ``coupled`` is True when the relaxed
        minimiser was not PSD and the constrained problem was solved.
        """
        c = self._relaxed(ax)
        r = self.b - ax @ c
        s = self._matrices(c)
        if all(_is_psd(s[ti]) for ti in self.full):
            return float(r @ r), c, False
        self.n_coupled += 1
        f2, c2 = self._coupled(ax, s)
        return f2, c2, True

    def _relaxed(self, ax: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
        """Minimiser with diag(Sigma) >= 0 and h >= 0 only (exact); with ``keep`` (a mask of
        the columns), the other coefficients are held at 0."""
        c = np.zeros(len(self.cols))
        if keep is not None:
            if not np.any(keep):
                return c
            if self.groups is None:
                c[keep] = self._relaxed_full(ax[:, keep], self.lower[keep])
                return c
        if self.groups is not None:  # separable by row group
            for gi, (rows, idx, nonneg) in enumerate(self.groups):
                if keep is not None:
                    idx = [i for i in idx if keep[i]]
                if not idx:
                    continue
                a = ax[rows][:, idx]
                if nonneg:
                    # warm start from this group's previous positive set (the profile is
                    # evaluated at nearby points)
                    key = (gi, tuple(idx))
                    c[idx] = _nnls(a, self.b[rows], self._passive.get(key))
                    self._passive[key] = c[idx] > 0
                else:
                    c[idx] = _lstsq(a, self.b[rows])
            return c
        return self._relaxed_full(ax, self.lower)

    def _relaxed_full(self, ax: np.ndarray, lower: np.ndarray) -> np.ndarray:
        """Bounded least squares ``min ||b - ax c||, c >= lower`` (full weighting matrix)."""
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        norms[norms == 0] = 1.0
        an = ax / norms
        free = np.isinf(lower)
        if np.all(free):
            return np.linalg.lstsq(an, self.b, rcond=None)[0] / norms
        # the bounds are 0 or -inf: the free coefficients are eliminated (least squares on
        # the orthogonal complement of their columns), an NNLS gives the bounded ones
        out = np.zeros(ax.shape[1])
        if not np.any(free):
            out[:], _ = nnls(an, self.b, maxiter=50 * an.shape[1] + 50)
            return out / norms
        af = an[:, free]
        u, sv, _ = np.linalg.svd(af, full_matrices=False)
        u = u[:, sv > sv[0] * max(af.shape) * np.finfo(float).eps]
        an_b = an[:, ~free]
        out[~free], _ = nnls(
            an_b - u @ (u.T @ an_b), self.b - u @ (u.T @ self.b), maxiter=50 * an_b.shape[1] + 50
        )
        out[free] = np.linalg.lstsq(af, self.b - an_b @ out[~free], rcond=None)[0]
        return out / norms

    def _coupled(self, ax: np.ndarray, s0: dict[int, np.ndarray]) -> tuple[float, np.ndarray]:
        """The PSD-constrained inner problem, when the relaxed minimiser is not PSD.

        The minimiser then has a singular covariance. The first candidate with a certificate
        of optimality (the KKT conditions, :meth:`_uncertified`) wins:

        1. the covariances that are not PSD at 0 (the shared process is absent from the
           data), everything else exact by the relaxation (a bounded linear least squares);
        2. the face of the previous solve (which variances are 0, the rank r of every
           covariance): ``Sigma = D F F' D`` with F of shape g x r, Newton's method
           (:meth:`_face_newton`) from the previous solution (the profile is evaluated at
           nearby points);
        3. a log-barrier interior-point path (:meth:`_barrier`) that does not care about the
           rank of the minimiser; after each centring, its face (:meth:`_purify`) is
           polished as in 2 and certified. Without a certificate at the end of the path, the
           best of the path's end, its face and candidate 1.

        A factor of the minimiser's rank is a regular problem (a few Newton steps from a
        nearby point); a factor of a larger rank (e.g. square, as before) has a singular
        Jacobian at the minimiser and Gauss-Newton creeps towards it, hundreds of evaluations
        per solve, which made fits with an absent shared process take 5-120 s.
        """
        dscale = {ti: self._dscale(ax, ti) for ti in self.full}
        # 1. the non-PSD covariances (and any that the others push out of the cone) at 0
        zero = {ti for ti in self.full if not _is_psd(s0[ti])}
        while True:
            c = self._relaxed(ax, np.array([ti not in zero for ti, _, _, _ in self.cols]))
            s = self._matrices(c)
            bad = {ti for ti in self.full if ti not in zero and not _is_psd(s[ti])}
            if not bad:
                break
            zero |= bad
        r = self.b - ax @ c
        best = (float(r @ r), c)
        if not self._uncertified(ax, c, r, dscale):
            return self._done(best, None)

        def polish(
            c1: np.ndarray, face: tuple[np.ndarray, dict[int, int]]
        ) -> tuple[float, np.ndarray] | None:
            got = self._face_newton(ax, c1, face[0], face[1], dscale)
            if got is None or self._uncertified(ax, got[1], got[2], dscale):
                return None
            return got[0], got[1]

        # 2. the previous face
        if self._face is not None:
            got = polish(self._face[1], self._face[0])
            if got is not None:
                return self._done(got, self._face[0])

        # 3. the interior-point path, its faces polished
        def accept(cb: np.ndarray) -> tuple[tuple[float, np.ndarray], Any] | None:
            cp = self._purify(ax, cb, dscale)
            if cp is None:
                return None
            sp = self._matrices(cp)
            face = (cp != 0, {ti: _rank(sp[ti] / np.outer(d, d), 1e-9) for ti, d in dscale.items()})
            got = polish(cp, face)
            return None if got is None else (got, face)

        cb, got = self._barrier(ax, c, dscale, accept)
        if got is not None:
            return self._done(*got)
        for cand in (cb, self._purify(ax, cb, dscale)):
            if cand is not None:
                rc = self.b - ax @ cand
                best = min(best, (float(rc @ rc), cand), key=lambda v: v[0])
        return self._done(best, None)

    def _done(self, best: tuple[float, np.ndarray], face: Any) -> tuple[float, np.ndarray]:
        self._face = None if face is None else (face, best[1])
        return best

    def _dscale(self, ax: np.ndarray, ti: int) -> np.ndarray:
        """Scaling D of a covariance: unit entries of ``D^-1 Sigma D^-1`` on the diagonal
        change the weighted residual by about one unit."""
        g = self.dims[ti]
        return np.array(
            [
                1.0 / math.sqrt(max(float(np.linalg.norm(ax[:, self.col_of[(ti, a, a)]])), 1e-300))
                for a in range(g)
            ]
        )

    def _uncertified(
        self,
        ax: np.ndarray,
        c: np.ndarray,
        r: np.ndarray,
        dscale: dict[int, np.ndarray],
        tol: float = 1e-6,
    ) -> set[int]:
        """Where the KKT conditions of the PSD-constrained problem fail at ``c``.

        Optimality (the problem is convex): the gradient ``G`` of the objective with respect
        to every covariance is PSD (``G Sigma = 0`` holds at any stationary point of the
        factored problem and at 0, and is checked), and the gradient with respect to every
        non-negative coefficient is >= 0 (0 where the coefficient is positive). Tolerances
        are relative
        to ``||r||`` in the scaled coordinates: a violation by ``tol ||r||`` can lower the
        objective by about ``tol^2`` times itself. Returns the failing covariance terms
        (``-1`` for the non-negative coefficients); empty when certified.
        """
        lim = tol * max(float(np.linalg.norm(r)), 1e-300)
        grad = -2.0 * (ax.T @ r)
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        out: set[int] = set()
        for ci, (ti, _, _, _) in enumerate(self.cols):
            if ti in dscale or norms[ci] == 0:
                continue
            gn = grad[ci] / norms[ci]
            if gn < -lim or (c[ci] * norms[ci] > lim and gn > lim):
                out.add(-1)
        for ti, d in dscale.items():
            g = len(d)
            gm = np.empty((g, g))
            for a in range(g):
                for b in range(a, g):
                    ci = self.col_of[(ti, a, b) if (ti, a, b) in self.col_of else (ti, b, a)]
                    gm[a, b] = gm[b, a] = grad[ci] if a == b else 0.5 * grad[ci]
            gs = gm * np.outer(d, d)
            sm = np.zeros((g, g))
            for ci, (tj, a, b, _) in enumerate(self.cols):
                if tj == ti:
                    sm[a, b] = sm[b, a] = c[ci] / (d[a] * d[b])
            if np.linalg.eigvalsh(gs)[0] < -lim or np.linalg.norm(gs @ sm) > lim * float(
                np.linalg.norm(sm)
            ):
                out.add(ti)
        return out

    def _barrier(
        self,
        ax: np.ndarray,
        c0: np.ndarray,
        dscale: dict[int, np.ndarray],
        accept: Any = None,
        gap: float = 1e-12,
    ) -> tuple[np.ndarray, Any]:
        """The PSD-constrained inner problem by a log-barrier interior-point method.

        Minimises ``t ||b - ax c||^2 - sum log c_i - sum log det Sigma`` by damped Newton
        steps (the barrier Hessian of ``log det`` is ``tr(W E W E')`` with ``W = Sigma^-1``)
        for ``t`` increasing by 20 until the duality-gap bound ``m / t`` (m the barrier
        parameter) is below ``gap ||r||^2``. Unlike a factorisation, Newton's method does not
        slow down when the minimiser is singular. Works in scaled coordinates: non-negative
        coefficients times their column norm, covariances ``D^-1 Sigma D^-1``. After each
        centring with a relative gap below 1e-3, ``accept(c)`` may end the path with its
        (not None) result. Returns the coefficients at the end (strictly inside the cones)
        and that result.
        """
        ncol = len(self.cols)
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        norms[norms == 0] = 1.0
        scale = 1.0 / norms
        cones: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]] = []
        nn = np.ones(ncol, bool)
        for ti, d in dscale.items():
            idx = np.array([ci for ci, col in enumerate(self.cols) if col[0] == ti])
            ia = np.array([self.cols[ci][1] for ci in idx])
            ib = np.array([self.cols[ci][2] for ci in idx])
            scale[idx] = d[ia] * d[ib]
            nn[idx] = False
            sfac = np.where(ia == ib, 0.5, 1.0)
            cones.append((idx, ia, ib, sfac, len(d)))
        a = ax * scale
        qm = a.T @ a
        bnorm = max(float(np.linalg.norm(self.b)), 1e-300)
        v = c0 / scale
        delta = 1e-3 * bnorm / ncol
        v[nn] = np.maximum(v[nn], delta)
        for idx, ia, ib, _, g in cones:
            sm = np.zeros((g, g))
            sm[ia, ib] = sm[ib, ia] = v[idx]
            sm = _project_psd(sm) + delta * np.eye(g)
            v[idx] = sm[ia, ib]
        m = float(np.sum(nn) + sum(cn[4] for cn in cones))

        def barrier(
            v: np.ndarray, deriv: bool
        ) -> tuple[float, np.ndarray | None, np.ndarray | None]:
            """Barrier value (inf outside), and with deriv its gradient and Hessian."""
            if np.any(v[nn] <= 0):
                return math.inf, None, None
            val = -float(np.sum(np.log(v[nn])))
            gr = np.zeros(ncol)
            he = np.zeros((ncol, ncol))
            if deriv:
                gr[nn] = -1.0 / v[nn]
                he[nn, nn] = 1.0 / v[nn] ** 2
            for idx, ia, ib, sfac, g in cones:
                sm = np.zeros((g, g))
                sm[ia, ib] = sm[ib, ia] = v[idx]
                try:
                    low = np.linalg.cholesky(sm)
                except np.linalg.LinAlgError:
                    return math.inf, None, None
                val -= 2.0 * float(np.sum(np.log(np.diagonal(low))))
                if deriv:
                    wi = np.linalg.inv(sm)
                    gr[idx] = -2.0 * sfac * wi[ia, ib]
                    he[np.ix_(idx, idx)] = (
                        2.0
                        * np.outer(sfac, sfac)
                        * (
                            wi[np.ix_(ia, ia)] * wi[np.ix_(ib, ib)]
                            + wi[np.ix_(ia, ib)] * wi[np.ix_(ib, ia)]
                        )
                    )
            return val, gr, he

        r = self.b - a @ v
        t = m / max(float(r @ r), 1e-300)
        for _ in range(300):
            pv, pg, ph = barrier(v, True)
            r = self.b - a @ v
            g = -2.0 * t * (a.T @ r) + pg
            hm = 2.0 * t * qm + ph
            dj = 1.0 / np.sqrt(np.maximum(np.diagonal(hm), 1e-300))
            try:
                step = -dj * np.linalg.solve(hm * np.outer(dj, dj), g * dj)
            except np.linalg.LinAlgError:  # pragma: no cover - the barrier Hessian is PD
                break
            dec = -float(g @ step)
            self.n_inner += 1
            if dec <= 1e-8:
                if m / t <= gap * float(r @ r) or t > 1e300:
                    break
                if accept is not None and m / t <= 1e-3 * float(r @ r):
                    done = accept(v * scale)
                    if done is not None:
                        return v * scale, done
                t *= 20.0
                continue
            slope = float(g @ step)
            curv = t * float(step @ qm @ step)
            lin = -2.0 * t * float((a.T @ r) @ step)
            s_ = 1.0
            for _ in range(60):
                nv = barrier(v + s_ * step, False)[0]
                if nv < math.inf and s_ * lin + s_ * s_ * curv + nv - pv <= 0.25 * s_ * slope:
                    break
                s_ *= 0.5
            else:
                break
            v = v + s_ * step
        return v * scale, None

    def _purify(
        self, ax: np.ndarray, c: np.ndarray, dscale: dict[int, np.ndarray], rel: float = 1e-6
    ) -> np.ndarray | None:
        """The face of an interior solution: coefficients below ``rel`` (scaled) at 0, and each
        covariance ``U M U'`` with U its eigenvectors above ``rel`` times the largest; M and
        the positive coefficients by least squares on that face. None if that leaves the
        cones."""
        norms = np.sqrt(np.sum(ax * ax, axis=0))
        bnorm = max(float(np.linalg.norm(self.b)), 1e-300)
        blocks: list[np.ndarray] = []
        maps: list[tuple[Any, ...]] = []
        for ci, (ti, _, _, _) in enumerate(self.cols):
            if ti not in dscale and c[ci] * norms[ci] > rel * bnorm:
                blocks.append(ax[:, ci : ci + 1])
                maps.append(("h", ci))
        for ti, d in dscale.items():
            idx = [ci for ci, col in enumerate(self.cols) if col[0] == ti]
            g = len(d)
            sm = np.zeros((g, g))
            for ci in idx:
                _, a, b, _ = self.cols[ci]
                sm[a, b] = sm[b, a] = c[ci] / (d[a] * d[b])
            lam, vec = np.linalg.eigh(sm)
            keep = lam > rel * max(float(lam[-1]), bnorm)
            u = vec[:, keep]
            rk = u.shape[1]
            kl = [(k, l) for k in range(rk) for l in range(k, rk)]
            if not kl:
                continue
            tm = np.zeros((len(idx), len(kl)))
            for row, ci in enumerate(idx):
                _, a, b, _ = self.cols[ci]
                for j, (k, l) in enumerate(kl):
                    tm[row, j] = (
                        d[a] * d[b] * (u[a, k] * u[b, l] + (u[a, l] * u[b, k] if k != l else 0.0))
                    )
            blocks.append(ax[:, idx] @ tm)
            maps.append(("s", ti, idx, tm, u, kl))
        out = np.zeros(len(self.cols))
        if not blocks:
            return out
        x = _lstsq(np.hstack(blocks), self.b)
        pos = 0
        for mp in maps:
            if mp[0] == "h":
                if x[pos] < 0:
                    return None
                out[mp[1]] = x[pos]
                pos += 1
                continue
            _, ti, idx, tm, u, kl = mp
            xm = x[pos : pos + len(kl)]
            pos += len(kl)
            mm = np.zeros((u.shape[1], u.shape[1]))
            for (k, l), val in zip(kl, xm, strict=True):
                mm[k, l] = mm[l, k] = val
            if np.linalg.eigvalsh(mm)[0] < 0:
                return None
            out[idx] = tm @ xm
        return out

    def _face_newton(
        self,
        ax: np.ndarray,
        c0: np.ndarray,
        free: np.ndarray,
        ranks: dict[int, int],
        dscale: dict[int, np.ndarray],
    ) -> tuple[float, np.ndarray, np.ndarray] | None:
        """Minimum on a face: the non-negative coefficients in ``free`` (the others 0) and
        ``Sigma = D F F' D`` with F of shape g x rank, by Newton's method with the exact
        Hessian ``2 J'J + 2 (D G D kron I)`` (G the gradient with respect to Sigma), from
        ``c0``. None if a free coefficient ends negative (not the minimiser's face).
        Returns (objective, coefficients, residual)."""
        lin = np.array(
            [ci for ci, (ti, _, _, _) in enumerate(self.cols) if ti not in dscale and free[ci]],
            dtype=int,
        )
        s0 = self._matrices(c0)
        parts = [c0[lin]]
        cones = []
        pos = lin.size
        for ti, d in dscale.items():
            rk = ranks[ti]
            idx = np.array([ci for ci, col in enumerate(self.cols) if col[0] == ti])
            ia = np.array([self.cols[ci][1] for ci in idx])
            ib = np.array([self.cols[ci][2] for ci in idx])
            cones.append((ti, idx, ia, ib, d[ia] * d[ib], len(d), rk, pos))
            pos += len(d) * rk
            if rk:
                lam, vec = np.linalg.eigh(_project_psd(s0[ti] / np.outer(d, d)))
                lam, vec = lam[::-1][:rk], vec[:, ::-1][:, :rk]
                lam = np.maximum(lam, 1e-8 * max(float(lam[0]), 1e-12))
                parts.append((vec * np.sqrt(lam)).ravel())
        x = np.concatenate(parts)
        ncol = len(self.cols)

        def coef(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            c = np.zeros(ncol)
            dc = np.zeros((ncol, x.size))
            c[lin] = x[: lin.size]
            dc[lin, np.arange(lin.size)] = 1.0
            for _, idx, ia, ib, dd, g, rk, o in cones:
                if rk:
                    f_ = x[o : o + g * rk].reshape(g, rk)
                    c[idx] = dd * np.sum(f_[ia] * f_[ib], axis=1)
                    jb = np.zeros((idx.size, g, rk))
                    rows = np.arange(idx.size)
                    jb[rows, ia] += dd[:, None] * f_[ib]
                    jb[rows, ib] += dd[:, None] * f_[ia]
                    dc[idx, o : o + g * rk] = jb.reshape(idx.size, g * rk)
            return c, dc

        c, dc = coef(x)
        r = self.b - ax @ c
        f = float(r @ r)
        for _ in range(60 if x.size else 0):
            self.n_inner += 1
            jm = ax @ dc
            gc = -2.0 * (ax.T @ r)
            grad = dc.T @ gc
            hm = 2.0 * (jm.T @ jm)
            for _, idx, ia, ib, dd, g, rk, o in cones:
                if rk:
                    gt = np.zeros((g, g))
                    gt[ia, ib] = gt[ib, ia] = np.where(ia == ib, 1.0, 0.5) * gc[idx] * dd
                    hm[o : o + g * rk, o : o + g * rk] += 2.0 * np.kron(gt, np.eye(rk))
            lam, vec = np.linalg.eigh(hm)
            mu = max(0.0, -float(lam[0])) + 1e-12 * max(float(lam[-1]), 1e-300)
            step = -(vec @ ((vec.T @ grad) / (lam + mu)))
            s_ = 1.0
            for _ in range(40):
                cn, dcn = coef(x + s_ * step)
                rn = self.b - ax @ cn
                fn = float(rn @ rn)
                if fn <= f:
                    break
                s_ *= 0.5
            else:
                break
            x, c, dc, r = x + s_ * step, cn, dcn, rn
            done = f - fn <= 1e-15 * f
            f = fn
            if done:
                break
        if np.any(c[lin] < 0):
            return None
        return f, c, r


def _nnls(a: np.ndarray, b: np.ndarray, passive: np.ndarray | None = None) -> np.ndarray:
    """NNLS on unit-norm columns; ``passive``: the positive set of a previous, nearby solve
    (one least squares when it is still optimal)."""
    norms = np.sqrt(np.sum(a * a, axis=0))
    norms[norms == 0] = 1.0
    g, _ = nnls(a / norms, b, maxiter=50 * a.shape[1] + 50, passive=passive)
    return g / norms


def _lstsq(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    norms = np.sqrt(np.sum(a * a, axis=0))
    norms[norms == 0] = 1.0
    g = np.linalg.lstsq(a / norms, b, rcond=None)[0]
    return g / norms


def _is_psd(s: np.ndarray) -> bool:
    if s.size == 0:
        return True
    scale = max(float(np.max(np.abs(np.diagonal(s)))), 1e-300)
    return bool(np.linalg.eigvalsh(s)[0] >= -1e-12 * scale)


def _rank(s: np.ndarray, rel: float) -> int:
    """Rank of the projection of ``s`` onto the PSD cone: eigenvalues above ``rel`` times the
    largest."""
    lam = np.linalg.eigvalsh(0.5 * (s + s.T))
    top = float(lam[-1]) if lam.size else 0.0
    return int(np.sum(lam > rel * top)) if top > 0 else 0


def _project_psd(s: np.ndarray) -> np.ndarray:
    lam, vec = np.linalg.eigh(0.5 * (s + s.T))
    return (vec * np.clip(lam, 0.0, None)) @ vec.T
