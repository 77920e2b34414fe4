"""The delta method of the virtual sensor (:mod:`engine.multivariate.virtual`): the derivatives
of the MGMWM's implied moments (:func:`implied_jacobian`), the estimator's sandwich covariance
(:func:`parameter_covariance`), the variance of an implied WV of given weights
(:func:`delta_variance`), the noise of estimated optimal weights in criterion units
(:func:`weight_noise`), the shrinkage towards the plain average (:func:`kept_share`) and the
winner's curse of weights that passed the fallback test (:func:`selection_bias`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._optim import chi2_isf
from ..wv import WVMatrix
from .spec import MultiModel

__all__ = [
    "implied_jacobian",
    "parameter_covariance",
    "delta_variance",
    "weight_noise",
    "kept_share",
    "selection_bias",
]


def _stack(arr: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    """A (J, k, k) array as the MGMWM's stacked moments (pair by pair, levels inside)."""
    return np.concatenate([arr[:, p, q] for p, q in pairs])


def implied_jacobian(model: MultiModel, tau: np.ndarray, fs: float) -> np.ndarray:
    """Derivatives ``(P J, n)`` of the stacked implied moments (pair by pair, levels inside,
    as :func:`engine.multivariate.moment_covariance`) by the free parameters: every entry of a
    shared covariance (the diagonal only for a diagonal one) and every variance of a live
    process (analytic: ``basis x`` the entry's indicator), and the phi of a live AR1/GM
    (central difference of its basis). Processes with no variance are left out (boundary)."""
    k = model.k
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    cols = []
    for t in model.terms():
        c, phi = model.term_values(t, fs)
        c = np.asarray(c, float)
        ch = list(t.chans)
        live = np.diagonal(c) > 0
        if not np.any(live):
            continue
        b = t.proto.basis(tau, fs, phi) * np.ones_like(tau)
        for a in range(len(ch)):
            for d in range(a, len(ch)):
                if not (live[a] and live[d]) or (a != d and t.diagonal):
                    continue
                e = np.zeros((k, k))
                e[ch[a], ch[d]] = e[ch[d], ch[a]] = 1.0
                cols.append(_stack(b[:, None, None] * e, pairs))
        if t.nonlinear and phi is not None:
            h = 1e-6 * max(1.0 - abs(phi), 1e-6)
            db = (t.proto.basis(tau, fs, phi + h) - t.proto.basis(tau, fs, phi - h)) / (2 * h)
            full = np.zeros((k, k))
            full[np.ix_(ch, ch)] = c
            cols.append(_stack(db[:, None, None] * full, pairs))
    return np.column_stack(cols) if cols else np.zeros((len(pairs) * tau.size, 0))


def parameter_covariance(result: Any) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of the implied moments and the estimator's covariance: ``(D, cov)``
    with ``D`` (P, J, n) the :func:`implied_jacobian` by pair and level (columns scaled to
    unit norm, the parameters rescaled alike) and ``cov`` (n, n) the sandwich
    ``(A' W A)^-1 A' W V W A (A' W A)^-1`` (``W`` the fit's ``omega``, ``V``
    :func:`engine.multivariate.moment_covariance`), so that ``D cov D'`` is the delta-method
    covariance of the implied moments."""
    from .moments import moment_covariance

    wvm: WVMatrix = result.wvm
    k, nj = wvm.k, wvm.n_levels
    n_pairs = k * (k + 1) // 2
    jac = implied_jacobian(result.model, wvm.tau_samples.astype(float), wvm.fs)
    if jac.shape[1] == 0:
        return np.zeros((n_pairs, nj, 0)), np.zeros((0, 0))
    norms = np.linalg.norm(jac, axis=0)
    jac = jac / np.where(norms > 0, norms, 1.0)  # scale-free columns for the pseudo-inverse
    om = np.asarray(result.omega, float)
    bread = np.linalg.pinv(jac.T @ om @ jac, rcond=1e-12, hermitian=True)
    meat = jac.T @ om @ moment_covariance(result.model, wvm) @ om @ jac
    return jac.reshape(n_pairs, nj, -1), bread @ meat @ bread


def delta_variance(deriv: np.ndarray, cov: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Delta-method variance of ``w' N(j; theta_hat) w`` at every level, from
    :func:`parameter_covariance`'s ``(D, cov)``: ``(c' D_j) cov (c' D_j)'`` with
    ``c_pq = w_p w_q (2 - [p = q])``."""
    k = w.size
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    c = np.array([w[p] * w[q] * (1.0 if p == q else 2.0) for p, q in pairs])
    m = np.einsum("a,ajn->jn", c, deriv)  # (J, n_params)
    return np.maximum(np.einsum("jn,nm,jm->j", m, cov, m), 0.0)


def weight_noise(
    deriv: np.ndarray,
    cov: np.ndarray,
    m: np.ndarray,
    sel: np.ndarray,
    a: np.ndarray,
    w: np.ndarray,
    level: float = 0.05,
) -> tuple[float, float, np.ndarray]:
    """The noise of estimated weights, in criterion units: ``(S, q)``.

    ``w`` minimises the band matrix ``M = sum_j N(j; theta_hat) / a_j`` of the fitted model;
    its error ``d = w - w*`` (``1' d = 0``) is, to first order, ``d = G (theta_hat - theta)``
    with ``G`` from the KKT system ``[[M, 1], [1', 0]] [dw; dmu] = [-dM w; 0]`` (``a_j`` held
    fixed), so ``Cov(d) = G cov G'``. Then

    * ``S = tr(M Cov(d)) = E[d' M d]``, the expected excess criterion of the estimated weights
      over the optimum (exact for a quadratic: ``N w* = mu 1``, so ``(w* + d)' N (w* + d) =
      w*' N w* + d' N d``); the in-sample criterion is ``S`` below the optimum and the
      out-of-sample one ``S`` above it, so the in-sample gain is optimistic by ``2 S``;
    * ``q``: the ``1 - level`` point of ``d' M d`` (the in-sample improvement over the plain
      average when the average is the optimum), a sum of weighted chi-squares matched by
      a scaled chi-square in mean and variance (Satterthwaite: ``S`` and ``2 tr((Cov(d) M)^2)``).

    Parameters
    ----------
    deriv, cov : ndarray
        :func:`parameter_covariance`'s derivatives (P, J, n) and covariance (n, n).
    m : ndarray (k, k)
        The band matrix of the fitted model.
    sel, a : ndarray
        The criterion's levels and their divisors (:func:`band_matrix`).
    w : ndarray (k,)
        ``optimal_weights(m)``.
    level : float
        Upper-tail probability of ``q``.

    Returns
    -------
    (float, float, ndarray (k, k))
        ``S``, ``q`` (both 0 without free parameters) and ``Cov(d)``.
    """
    k = w.size
    if cov.size == 0:
        return 0.0, 0.0, np.zeros((k, k))
    dn = np.zeros((deriv.shape[1], k, k, deriv.shape[2]))
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    for i, (p, q) in enumerate(pairs):
        dn[:, p, q] = dn[:, q, p] = deriv[i]
    dm = np.einsum("jpqn,j->pqn", dn[sel], 1.0 / a[sel])  # (k, k, n)
    scale = float(np.max(np.abs(m))) or 1.0
    kkt = np.zeros((k + 1, k + 1))
    kkt[:k, :k] = m / scale
    kkt[:k, k] = kkt[k, :k] = 1.0
    rhs = np.zeros((k + 1, dm.shape[2]))
    rhs[:k] = -np.einsum("pqn,q->pn", dm, w) / scale
    g = np.linalg.lstsq(kkt, rhs, rcond=1e-13)[0][:k]  # (k, n): dw by parameter
    cov_d = g @ cov @ g.T
    cm = cov_d @ m
    m1, m2 = float(np.trace(cm)), float(np.trace(cm @ cm))
    if not (m1 > 0 and m2 > 0):
        return max(m1, 0.0), 0.0, cov_d
    return m1, float(m2 / m1 * chi2_isf(m1 * m1 / m2, level)), cov_d


def kept_share(gap: float | np.ndarray, excess: float, threshold: float) -> np.ndarray:
    """``lambda`` of :func:`virtual_sensor`: 0 when the in-sample improvement ``gap`` is within
    its noise (``<= max(threshold, excess)``), else ``1 - excess / gap``."""
    gap = np.asarray(gap, float)
    keep = gap > max(threshold, excess)
    return np.where(keep, 1.0 - excess / np.where(keep, gap, 1.0), 0.0)


def selection_bias(
    u0: np.ndarray, m: np.ndarray, cov_d: np.ndarray, excess: float, threshold: float
) -> float:
    """Expected out-of-sample minus reported criterion of the shrunk weights, given that they
    did not fall back, when the optimum is ``1/k + u0``: ``E[2 lambda (u0' M d + d' M d - S)
    | lambda > 0]`` over ``d ~ N(0, Cov(d))`` (4096 fixed draws). The reported criterion
    counts ``E[d' M d] = S`` as if ``lambda`` did not depend on ``d``; the test and the
    shrinkage favour draws with a large ``d' M (2 u0 + d)``, so without this term the gain of
    the weights that pass is optimistic (the winner's curse)."""
    vals, vecs = np.linalg.eigh(0.5 * (cov_d + cov_d.T))
    root = vecs * np.sqrt(np.clip(vals, 0.0, None))
    z = np.random.default_rng(0).standard_normal((4096, u0.size))
    d = z @ root.T
    md = d @ m
    cross, quad = md @ u0, np.einsum("bp,bp->b", md, d)
    lam = kept_share(u0 @ m @ u0 + 2 * cross + quad, excess, threshold)
    kept = lam > 0
    if not np.any(kept):
        return 0.0
    return float(np.mean((2 * lam * (cross + quad - excess))[kept]))
