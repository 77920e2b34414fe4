"""Second moments of the MGMWM: the covariance of the stacked WV/WCCV moments implied by a
model (:func:`moment_covariance`, for the efficient weights and the intervals) and the
asymptotic intervals of a fit (:func:`conf_int`).
"""

from __future__ import annotations

import itertools
import math
from statistics import NormalDist
from typing import Any

import numpy as np

from ..fit import FitError
from ..fit.result import ParamTable
from ..models import Model, Param, Process
from ..wv import WVMatrix
from .spec import MultiModel, phi_of_nl

__all__ = ["moment_covariance", "conf_int"]


def moment_covariance(model: MultiModel, wvm: WVMatrix) -> np.ndarray:
    """Asymptotic Gaussian covariance of the stacked WV/WCCV moments implied by a model.

    Moments are stacked pair by pair (``(0,0), (0,1), .., (1,1), ..``), levels inside. With
    ``S(f) = sum_a s_a(f) C_a`` the model's spectral matrix (``s_a`` the spectral density of a
    process per unit variance, ``C_a`` its k x k coefficient matrix) and ``G_j = |H_j|^2`` the
    Haar squared gain,

        Cov(nu_pq_j, nu_rs_l) = 1 / max(M_j, M_l) int G_j G_l (S_pr S_qs + S_ps S_qr) df

    (Isserlis' formula for the products of the coefficient series; with p = q = r = s it is
    the univariate :func:`engine.inference.wv_cov_model`). The integrals
    ``int G_j G_l s_a s_b df`` are computed once per pair of process shapes.

    Parameters
    ----------
    model : MultiModel
        Every value set (e.g. ``result.model``).
    wvm : WVMatrix
        Gives the levels, ``M_j`` and fs.

    Returns
    -------
    ndarray, shape (P J, P J)
        ``P = k (k + 1) / 2`` pairs.
    """
    from ..fit.asymptotic import frequency_grid

    if not model.is_set:
        raise FitError("moment_covariance needs a model with every value set (a fitted model)")
    fs, k, nj = wvm.fs, model.k, wvm.n_levels
    shapes: dict[tuple[str, float | None], list[Any]] = {}
    for t in model.terms():
        c, phi = model.term_values(t, fs)
        if t.proto.deterministic or not np.any(c != 0):
            continue  # deterministic, or absent
        key = (t.code, None if phi is None else float(phi))
        if key not in shapes:
            unit = t.proto.cleared().from_fit(1.0, phi, fs)
            shapes[key] = [unit, np.zeros((k, k))]
        shapes[key][1][np.ix_(t.chans, t.chans)] += c
    units = [v[0] for v in shapes.values()]
    cmats = [v[1] for v in shapes.values()]
    ns = len(units)
    f, wts = frequency_grid(nj, Model(tuple(units)), fs)
    integ = np.zeros((ns, ns, nj, nj))
    inv_m2 = 1.0 / 4.0 ** np.arange(nj)
    chunk = 1 << 14
    for a0 in range(0, f.size, chunk):
        fc, wc = f[a0 : a0 + chunk], wts[a0 : a0 + chunk]
        x = np.pi * fc
        sin_m, cos_m = np.sin(x), np.cos(x)
        base = 1.0 / (sin_m * sin_m)
        gains = np.empty((nj, fc.size))
        for j in range(nj):
            sin2 = sin_m * sin_m
            gains[j] = sin2 * sin2 * base * inv_m2[j]
            sin_m, cos_m = 2.0 * sin_m * cos_m, 1.0 - 2.0 * sin2
        g = [gains * u.psd(fc, fs) for u in units]
        for a in range(ns):
            ga = g[a] * wc
            for b in range(a, ns):
                # einsum, not BLAS: on a loaded machine a threaded BLAS spins on these small
                # products (100x slower); the flops are negligible either way
                integ[a, b] += np.einsum("jf,lf->jl", ga, g[b])
    # f = 0, the periodic trapezoid rule's first node, which frequency_grid leaves out: G_j s is
    # finite there and non-zero only for a random walk (per unit gamma2, m^2 / 4, m = 2^(j-1))
    g0 = [u.psd_terms(fs).poly.get(-1, 0.0) * (4.0 ** np.arange(nj) / 4) for u in units]
    for a in range(ns):
        for b in range(a, ns):
            integ[a, b] += (0.5 / f.size) * np.outer(g0[a], g0[b])
    for a in range(ns):
        for b in range(a + 1, ns):
            integ[b, a] = integ[a, b].T
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    npairs = len(pairs)
    v = np.zeros((npairs * nj, npairs * nj))
    for a in range(ns):
        for b in range(ns):
            ca, cb = cmats[a], cmats[b]
            prod = np.array(
                [[ca[p, r] * cb[q, s] + ca[p, s] * cb[q, r] for r, s in pairs] for p, q in pairs]
            )
            if np.any(prod != 0):
                v += np.kron(prod, integ[a, b])
    m_j = wvm.n_coef.astype(float)
    v /= np.tile(np.maximum.outer(m_j, m_j), (npairs, npairs))
    return 0.5 * (v + v.T)


def conf_int(res: Any, alpha: float = 0.05) -> ParamTable:
    """Two-sided ``1 - alpha`` asymptotic intervals of every estimate of an MGMWM fit.

    The sandwich covariance of the GMM estimator, ``(A' W A)^-1 A' W V W A (A' W A)^-1``
    (the GMWM paper, Theorem 2; the multivariate paper, Theorem 1), with ``W`` the fit's
    ``omega``, ``V`` the model-implied covariance of the stacked moments
    (:func:`moment_covariance`) and ``A`` the derivative of the stacked implied moments by
    central differences, in unconstrained coordinates mapped back (as the univariate
    :func:`engine.inference.param_intervals`): each process parameter by the transform its
    class declares (:attr:`engine.models.Param.transform`: log of variances and of beta,
    atanh of phi and theta, a drift as it is), a covariance's diagonal by log and the
    covariances between channels as they are. A
    parameter on a boundary (a variance at 0, an entry of a singular or diagonal-restricted
    covariance, a correlation time at the edge, the phi/beta of a process with no variance)
    gets ``nan`` bounds: the normal approximation does not hold there.

    Parameters
    ----------
    res : MGMWMResult
        The fit.
    alpha : float
        ``1 - alpha`` two-sided coverage (0.05: the 2.5 % and 97.5 % quantiles).

    Returns
    -------
    ParamTable
        One row per :attr:`MGMWMResult.param_records`.
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    model: MultiModel = res.model
    wvm: WVMatrix = res.wvm
    fs, k = wvm.fs, model.k
    tau = wvm.tau_samples.astype(float)
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    terms = model.terms()
    at_bound = set(res.at_bound)
    # the state: a covariance and phi/beta per shared term, a process per independent one
    state: dict[int, Any] = {}
    coords: list[tuple[int, Any]] = []  # (term, coordinate) of the free parameters
    names: list[str] = []
    for ti, t in enumerate(terms):
        if t.shared:
            sp = model.shared_process(t.label)
            cov = np.asarray(sp.cov, float)
            state[ti] = (cov, sp.nl)
            g = sp.channels
            live = [
                cov[a, a] > 0 and f"{t.label}.cov[{c},{c}]" not in at_bound for a, c in enumerate(g)
            ]
            singular = f"{t.label}.cov (singular)" in at_bound
            if t.nonlinear and any(live) and f"{t.label}.{t.proto.nonlinear}" not in at_bound:
                coords.append((ti, "nl"))
                names.append(f"{t.label}.{t.proto.nonlinear}")
            for a, b in itertools.combinations_with_replacement(range(len(g)), 2):
                if singular or not (live[a] and live[b]) or (a != b and t.diagonal):
                    continue
                coords.append((ti, (a, b)))
                names.append(f"{t.label}.cov[{g[a]},{g[b]}]")
        else:
            p: Process = t.proto
            state[ti] = p
            c = model.channels[t.chans[0]]
            if p.linear_coef() <= 0:
                continue
            for i, name in enumerate(p.param_names):
                if f"{c}.{t.label}.{name}" not in at_bound:
                    coords.append((ti, i))
                    names.append(f"{c}.{t.label}.{name}")

    def nl_param(ti: int) -> Param:
        """The declaration of a shared term's non-linear parameter (its transform)."""
        proto = terms[ti].proto
        return proto.params()[str(proto.nonlinear)]

    def forward(ti: int, co: Any) -> float:
        t, st = terms[ti], state[ti]
        if not t.shared:
            return float(st.to_unconstrained(fs)[co])
        cov, nl = st
        if co == "nl":
            return nl_param(ti).to_unconstrained(nl)
        a, b = co
        return math.log(cov[a, a]) if a == b else float(cov[a, b])

    def moments(u: np.ndarray) -> np.ndarray:
        st = dict(state)
        for (ti, co), ui in zip(coords, u, strict=True):
            t = terms[ti]
            if not t.shared:
                p = st[ti]
                v = p.to_unconstrained(fs)
                v[co] = ui
                st[ti] = p.from_unconstrained(v, fs)
                continue
            cov, nl = st[ti]
            if co == "nl":
                nl = nl_param(ti).from_unconstrained(ui)
            else:
                a, b = co
                cov = cov.copy()
                cov[a, b] = cov[b, a] = math.exp(ui) if a == b else ui
            st[ti] = (cov, nl)
        arr = np.zeros((tau.size, k, k))
        for ti, t in enumerate(terms):
            if t.shared:
                c, nl = st[ti]
                phi = phi_of_nl(t.proto, nl, fs) if t.nonlinear else None
            else:
                p = st[ti]
                c, phi = np.array([[p.linear_coef()]]), p.nl_value(fs)
            b = t.proto.basis(tau, fs, phi) * np.ones_like(tau)
            arr[np.ix_(range(tau.size), t.chans, t.chans)] += b[:, None, None] * c[None, :, :]
        return np.concatenate([arr[:, p, q] for p, q in pairs])

    u0 = np.array([forward(ti, co) for ti, co in coords])
    jac = np.empty((len(pairs) * tau.size, u0.size))
    for j in range(u0.size):
        h = 1e-5 * max(1.0, abs(u0[j]))
        up, dn = u0.copy(), u0.copy()
        up[j] += h
        dn[j] -= h
        jac[:, j] = (moments(up) - moments(dn)) / (2 * h)
    w = res.omega
    vmat = moment_covariance(model, wvm)
    bread = np.linalg.pinv(jac.T @ w @ jac)
    cov_u = bread @ jac.T @ w @ vmat @ w @ jac @ bread
    se = np.sqrt(np.maximum(np.diagonal(cov_u), 0.0))
    z = NormalDist().inv_cdf(1.0 - alpha / 2.0)
    bounds: dict[str, tuple[float, float]] = {}
    for j, ((ti, co), name) in enumerate(zip(coords, names, strict=True)):
        t = terms[ti]
        magnitude = False  # the parameter's WV depends on its size only (a drift's omega)
        if not t.shared:
            p = state[ti]
            ends = []
            for sgn in (-1.0, 1.0):
                v = p.to_unconstrained(fs)
                v[co] = u0[j] + sgn * z * se[j]
                ends.append(float(p.from_unconstrained(v, fs).values[co]))
            magnitude = p.params()[p.param_names[co]].magnitude
        elif co == "nl":
            spec = nl_param(ti)
            ends = [spec.from_unconstrained(u0[j] + sgn * z * se[j]) for sgn in (-1.0, 1.0)]
        else:
            a, b = co
            back = math.exp if a == b else float
            ends = [back(u0[j] - z * se[j]), back(u0[j] + z * se[j])]
        lo, hi = min(ends), max(ends)
        if magnitude and lo < 0 <= u0[j]:  # its sign is not identified: an interval of |value|
            lo = 0.0
        bounds[name] = (lo, hi)
    recs = res.param_records
    return ParamTable(
        names=tuple(r.full_name for r in recs),
        estimate=np.array([r.value for r in recs]),
        lower=np.array([bounds.get(r.full_name, (math.nan, math.nan))[0] for r in recs]),
        upper=np.array([bounds.get(r.full_name, (math.nan, math.nan))[1] for r in recs]),
        units=tuple(r.unit for r in recs),
        level=1.0 - alpha,
    )
