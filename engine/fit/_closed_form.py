"""Closed form of the model-implied covariance of the Haar WV, in O(J^2) operations.

:func:`engine.inference.wv_cov_model` needs, for every pair of levels ``j <= k``, the frequency
integral ``C_jk`` of the two levels' squared Haar gains times the model's squared spectral
density (``Cov(nu_j, nu_k) = 2 C_jk / max(M_j, M_k)``). It is a sum of 25 values of one
generalised autocovariance of the lag, in closed form for QN, WN, RW and AR1/GM terms (partial
fractions), summed in exact integer and decimal arithmetic where the terms cancel, so the
result equals the exact infinite-lag value. The derivation: docs/methods.md, "The closed-form
WV covariance".
"""

from __future__ import annotations

import decimal
import math
from decimal import Decimal
from functools import lru_cache

import numpy as np

_W = {-2: 1, -1: -4, 0: 6, 1: -4, 2: 1}  # |1 - z^m|^4 = sum_d w_d z^(d m)
_PMAX = 4  # RW x RW: x^-4
# (d, e) up to the symmetry (d, e) -> (-d, -e), which leaves |d m + e M| unchanged, and its count
_HALF = [
    (d, e, 1 if d == e == 0 else 2)
    for d in range(-2, 3)
    for e in range(-2, 3)
    if d > 0 or (d == 0 and e >= 0)
]


def _kernel_scale(p: int) -> int:
    """``K_p(n) = (-1)^p |n| prod_{i<p} (n^2 - i^2) / scale`` (``K_0 = 2 delta / 2``)."""
    return 2 * math.factorial(2 * p - 1) if p else 2


@lru_cache(maxsize=8)
def _pairs(levels: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column (0-based) of the pairs ``j <= k``."""
    return np.triu_indices(levels)


@lru_cache(maxsize=8)
def _exact_kernels(levels: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """``Z_p = int |H_j|^2 |H_k|^2 x^(2-p) df`` for ``p = 0..4`` and every pair ``j <= k`` as
    exact fractions: (numerators, denominators), each ``[p]`` an object array of Python
    integers over the pairs."""
    jj, kk = _pairs(levels)
    mj = np.array([1 << j for j in jj.tolist()], dtype=object)
    mk = np.array([1 << k for k in kk.tolist()], dtype=object)
    acc = [np.zeros(jj.size, dtype=object) for _ in range(_PMAX + 1)]
    for d, e, cnt in _HALF:
        w = cnt * _W[d] * _W[e]
        n = np.abs(d * mj + e * mk)
        acc[0] = acc[0] + 2 * w * (n == 0).astype(object)
        v = n
        for p in range(1, _PMAX + 1):
            acc[p] = acc[p] + (-w if p % 2 else w) * v
            v = v * (n * n - p * p)
    den = 16 * mj * mj * mk * mk
    return acc, [den * _kernel_scale(p) for p in range(_PMAX + 1)]


@lru_cache(maxsize=8)
def poly_kernels(levels: int) -> np.ndarray:
    """``Z_p`` (shape (5, J, J), symmetric, non-negative): each entry the correctly rounded
    float of its exact rational value."""
    jj, kk = _pairs(levels)
    nums, dens = _exact_kernels(levels)
    z = np.zeros((_PMAX + 1, levels, levels))
    for p in range(_PMAX + 1):
        vals = [a / b for a, b in zip(nums[p], dens[p], strict=True)]  # int / int: exact rounding
        z[p, jj, kk] = vals
        z[p, kk, jj] = vals
    return z


@lru_cache(maxsize=8)
def _decimal_kernels(levels: int, prec: int) -> list[np.ndarray]:
    """``Z_0..Z_3`` per pair (object arrays of Decimal at ``prec`` digits)."""
    nums, dens = _exact_kernels(levels)
    with decimal.localcontext() as ctx:
        ctx.prec = prec
        return [
            np.array([Decimal(a) / Decimal(b) for a, b in zip(nums[p], dens[p], strict=True)])
            for p in range(4)
        ]


def _digits(phis: list[float]) -> int:
    """Decimal digits for the AR1 pieces, a multiple of 16 (so the kernels' cache is shared):
    the partial fractions cancel about ``8 log10(1 / (1 - |phi|))`` digits (measured up to
    ``1 - phi = 1e-10`` at J = 22; the lag sums are exact integers), two AR1s another
    ``log10(1 / |(phi_a - phi_b)(1 - phi_a phi_b)|)``; 24 digits more leave about 15 correct
    after the cancellation.
    """
    worst = min((1.0 - abs(p) for p in phis), default=1.0)
    d = 24 + math.ceil(8 * max(0.0, -math.log10(max(worst, 1e-300))))
    gaps = [abs((a - b) * (1 - a * b)) for i, a in enumerate(phis) for b in phis[i + 1 :] if a != b]
    if gaps:
        d += math.ceil(max(0.0, -math.log10(min(gaps))))
    return 16 * math.ceil(d / 16)


def _ar_pieces(
    phi: Decimal, levels: int, zd: list[np.ndarray]
) -> tuple[list[np.ndarray], np.ndarray]:
    """For one AR1 and every pair ``j <= k``: ``I_p = int |H_j|^2 |H_k|^2 x^2 / (y x^p) df``
    (p = 0..3) and ``J_2 = int |H_j|^2 |H_k|^2 / y^2 df`` (object arrays of Decimal; the
    caller's decimal context).

    The lag sums ``s1 = sum w_d w_e phi^|n|`` and ``s2 = sum w_d w_e |n| phi^|n|`` (``n = d m +
    e M``) factor off the diagonal: there ``M >= 2m``, so ``|n| = |e| M + sign(e) d m`` for
    ``e != 0`` and ``s1 = 2 E_k B_j + 6 C_j``, ``s2 = 2 (m E_k B'_j + M E'_k B_j) + 6 m C'_j``
    with the per-level sums ``B = sum_d w_d phi^(d m) = (1 - phi^m)^4 / phi^(2m)``,
    ``B' = sum_d d w_d phi^(d m)``, ``C = sum_d w_d phi^(|d| m)``, ``C' = sum_d |d| w_d
    phi^(|d| m)``, ``E = sum_{e>0} w_e phi^(e M)``, ``E' = sum_{e>0} e w_e phi^(e M)``.
    """
    jj, kk = _pairs(levels)
    one = Decimal(1)
    p1 = [phi]  # phi^(2^l), l = 0..J+1
    for _ in range(levels + 1):
        p1.append(p1[-1] * p1[-1])
    lv = [(p1[l], p1[l + 1], one / p1[l], one / p1[l + 1]) for l in range(levels)]
    big_b = np.array([(one - a) ** 4 * ib for a, _, _, ib in lv], dtype=object)
    big_b1 = np.array([2 * (b - ib) - 4 * (a - ia) for a, b, ia, ib in lv], dtype=object)
    big_c = np.array([6 - 8 * a + 2 * b for a, b, _, _ in lv], dtype=object)
    big_c1 = np.array([-8 * a + 4 * b for a, b, _, _ in lv], dtype=object)
    big_e = np.array([-4 * a + b for a, b, _, _ in lv], dtype=object)
    big_e1 = np.array([-4 * a + 2 * b for a, b, _, _ in lv], dtype=object)
    mj = np.array([Decimal(1 << j) for j in jj.tolist()], dtype=object)
    mk = np.array([Decimal(1 << k) for k in kk.tolist()], dtype=object)
    ek, bj = big_e[kk], big_b[jj]
    s1 = 2 * ek * bj + 6 * big_c[jj]
    s2 = 2 * (mj * ek * big_b1[jj] + mk * big_e1[kk] * bj) + 6 * mj * big_c1[jj]
    for i in np.flatnonzero(jj == kk).tolist():  # the diagonal: n = (d + e) m
        j = int(jj[i])
        pw = [one, p1[j], p1[j + 1], p1[j] * p1[j + 1], p1[j + 2]]
        s1[i] = sum(cnt * _W[d] * _W[e] * pw[abs(d + e)] for d, e, cnt in _HALF)
        s2[i] = sum(
            cnt * _W[d] * _W[e] * abs(d + e) * (1 << j) * pw[abs(d + e)] for d, e, cnt in _HALF
        )
    r = one - phi * phi
    den = 16 * mj * mj * mk * mk
    i_p = [s1 / (r * den)]
    j_p = (s1 * ((one + phi * phi) / r**3) + s2 / (r * r)) / den
    c = (one - phi) ** 2
    for p in range(1, 4):
        i_p.append((zd[p] - phi * i_p[-1]) / c)
    for p in range(1, 3):
        j_p = (i_p[p] - phi * j_p) / c
    return i_p, j_p


def closed_form_c(
    levels: int,
    q2: float,
    sigma2: float,
    gamma2: float,
    ar: list[tuple[float, float]],
) -> np.ndarray:
    """``C_jk = int |H_j|^2 |H_k|^2 S^2 df`` (J x J) for ``S = q2 x + sigma2 + gamma2 / x +
    sum_a s_a / y(phi_a)``.

    Parameters
    ----------
    levels : int
        J (levels 1..J).
    q2, sigma2, gamma2 : float
        Total QN, WN and RW parameters (0 when absent).
    ar : list of (phi, s)
        Each AR1 (a GM in its AR1 form), ``|phi| < 1``, with its innovation variance ``s``.
    """
    z = poly_kernels(levels)
    coef = (q2 * q2, 2 * q2 * sigma2, sigma2 * sigma2 + 2 * q2 * gamma2, 2 * sigma2 * gamma2)
    out = gamma2 * gamma2 * z[4]
    for p, cf in enumerate(coef):
        out = out + cf * z[p]
    if not ar:
        return out
    jj, kk = _pairs(levels)
    acc = np.zeros(jj.size)
    prec = _digits([p for p, _ in ar])
    zd = _decimal_kernels(levels, prec)
    with decimal.localcontext() as ctx:
        ctx.prec = prec
        ctx.Emin, ctx.Emax = decimal.MIN_EMIN, decimal.MAX_EMAX
        ctx.traps[decimal.Underflow] = False
        phis = [Decimal(phi) for phi, _ in ar]
        pieces = [_ar_pieces(phi, levels, zd) for phi in phis]
        for a, (s, (i_p, j2)) in enumerate(zip([s for _, s in ar], pieces, strict=True)):
            # 2 s (q2 / (x y) + sigma2 / (x^2 y) + gamma2 / (x^3 y)) + s^2 / (x^2 y^2)
            acc += 2 * s * (q2 * i_p[1].astype(float) + sigma2 * i_p[2].astype(float))
            acc += 2 * s * gamma2 * i_p[3].astype(float) + s * s * j2.astype(float)
            for b in range(a + 1, len(ar)):
                pa, pb = phis[a], phis[b]
                if pa == pb:  # 1/(x^2 y^2)
                    val = j2
                else:  # 1/(y_a y_b) = (phi_b/y_b - phi_a/y_a) / ((phi_b - phi_a)(1 - phi_a phi_b))
                    val = (pb * pieces[b][0][2] - pa * i_p[2]) / ((pb - pa) * (1 - pa * pb))
                acc += 2 * s * ar[b][1] * val.astype(float)
    out[jj, kk] += acc
    out[kk, jj] = out[jj, kk]
    return out
