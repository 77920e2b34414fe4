"""Small numerical kernels of the fit path: SciPy's where it is as fast, the project's where not.

Measured per call on the fit's own problems by ``tests/benchmarks/bench_optim.py`` (the table is
in docs/performance.md); SciPy is imported by every command that loads a log anyway:

* :func:`nnls`: non-negative least squares, :func:`scipy.optimize.nnls` (compiled);
* the Nelder-Mead of the fit's local search is :func:`scipy.optimize.minimize` itself
  (``engine.fit._varpro.local``; the former copy here made the same iterates in the same time);
* :func:`least_squares`: box-bounded non-linear least squares (projected Levenberg-Marquardt),
  for the wavelet functional moments fit, kept;
* :func:`chi2_isf`: the chi-square inverse survival function, kept (accuracy, see there).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "nnls",
    "least_squares",
    "LSQResult",
    "chi2_isf",
    "gamma_p",
]


# -----------------------------------------------------------------------------------------
# non-negative least squares
# -----------------------------------------------------------------------------------------
def nnls(a: np.ndarray, b: np.ndarray, maxiter: int | None = None) -> tuple[np.ndarray, float]:
    """Solve ``min ||a x - b||_2`` subject to ``x >= 0``: :func:`scipy.optimize.nnls`.

    SciPy's compiled Lawson-Hanson solver: 22 us for a 19 x 6 problem from zero against
    140 us for the former NumPy implementation warm-started at the previous positive set
    (docs/performance.md).

    Parameters
    ----------
    a : ndarray, shape (m, n)
        Design matrix.
    b : ndarray, shape (m,)
        Right-hand side.
    maxiter : int, optional
        Maximum number of iterations; default ``3 n``.

    Returns
    -------
    x : ndarray, shape (n,)
        The non-negative solution.
    rnorm : float
        The residual norm ``||a x - b||``.
    """
    from scipy.optimize import nnls as scipy_nnls  # on first use: `import engine` stays light

    x, rnorm = scipy_nnls(a, b, maxiter=maxiter)
    return x, float(rnorm)


# -----------------------------------------------------------------------------------------
# box-bounded non-linear least squares
# -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LSQResult:
    """Result of :func:`least_squares`: best point, ``0.5 ||r||^2``, evaluations, success."""

    x: np.ndarray
    cost: float
    nfev: int
    success: bool


def least_squares(
    fun: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    *,
    ftol: float = 1e-12,
    xtol: float = 1e-10,
    max_nfev: int = 2000,
) -> LSQResult:
    """Minimise ``0.5 ||fun(x)||^2`` subject to ``lb <= x <= ub`` (projected Levenberg-Marquardt).

    Kept rather than :func:`scipy.optimize.least_squares`: 0.8x its CPU time on a bounded fit
    of a log WV (``bench_optim.py``), to the same cost.

    Each iteration takes a central-difference Jacobian (one-sided next to a bound), freezes the
    variables held at a bound by the gradient, and solves the damped normal equations
    ``(J'J + lam diag(J'J)) d = -J'r`` (Marquardt's scaling), projecting ``x + d`` into the box;
    ``lam`` shrinks 4x after a successful step and grows 4x after a failed one. It stops when
    a step lowers the cost by less than ``ftol`` of it and moves ``x`` by less than
    ``xtol (xtol + ||x||)``, or when no damping lowers the cost any more (a minimum to
    rounding).

    Parameters
    ----------
    fun : callable
        Residual vector of a 1-d array.
    x0 : ndarray (n,)
        Start (projected into the box).
    lb, ub : ndarray (n,)
        Bounds.
    ftol, xtol : float
        Relative tolerances on the cost and on the step.
    max_nfev : int
        Maximum number of residual evaluations.

    Returns
    -------
    LSQResult

    References
    ----------
    Marquardt (1963), J. SIAM 11(2); Nocedal & Wright (2006), Numerical Optimization, 10.3.
    """
    lb = np.asarray(lb, float)
    ub = np.asarray(ub, float)
    x = np.clip(np.asarray(x0, float), lb, ub)
    n = x.size
    nfev = 0

    def f(v: np.ndarray) -> np.ndarray:
        nonlocal nfev
        nfev += 1
        return np.asarray(fun(v), float)

    r = f(x)
    cost = float(r @ r)
    lam = 1e-3
    eps3 = np.finfo(float).eps ** (1 / 3)
    success = False
    jac = np.empty((r.size, n))
    while nfev < max_nfev:
        for i in range(n):
            h = eps3 * max(1.0, abs(x[i]))
            e = np.zeros(n)
            e[i] = h
            if x[i] - h >= lb[i] and x[i] + h <= ub[i]:
                jac[:, i] = (f(x + e) - f(x - e)) / (2 * h)
            elif x[i] + h <= ub[i]:
                jac[:, i] = (f(x + e) - r) / h
            else:
                jac[:, i] = (r - f(x - e)) / h
        g = jac.T @ r
        free = ~(((x <= lb) & (g > 0)) | ((x >= ub) & (g < 0)))
        a = (jac.T @ jac)[np.ix_(free, free)]
        dg = np.diagonal(a)
        dg = np.maximum(dg, 1e-12 * max(float(dg.max(initial=0.0)), 1e-300))
        moved = False
        while nfev < max_nfev and lam < 1e16:
            d = np.zeros(n)
            try:
                d[free] = -np.linalg.solve(a + lam * np.diag(dg), g[free])
            except np.linalg.LinAlgError:
                lam *= 4
                continue
            xn = np.clip(x + d, lb, ub)
            rn = f(xn)
            cn = float(rn @ rn)
            if cn < cost:
                moved = True
                break
            lam *= 4
        if not moved:
            success = True  # no damping lowers the cost: a minimum to rounding
            break
        step = float(np.linalg.norm(xn - x))
        drop = cost - cn
        x, r, cost = xn, rn, cn
        lam = max(lam / 4, 1e-12)
        if drop <= ftol * cost and step <= xtol * (xtol + float(np.linalg.norm(x))):
            success = True
            break
    return LSQResult(x=x, cost=0.5 * cost, nfev=nfev, success=success)


# -----------------------------------------------------------------------------------------
# chi-square quantiles
# -----------------------------------------------------------------------------------------
def _log1pmx(d: float) -> float:
    """``log(1 + d) - d`` without cancellation for small ``d``."""
    if abs(d) > 0.1:
        return math.log1p(d) - d
    # -d^2/2 + d^3/3 - d^4/4 + ...
    total, term, k = 0.0, d, 1
    while True:
        term *= -d
        k += 1
        add = term / k
        total += add
        if abs(add) <= 1e-17 * abs(total):
            return total


def _log_prefactor(a: float, x: float) -> float:
    """``log(x^a e^-x / Gamma(a + 1))``, accurate for large ``a`` and ``x`` near ``a``."""
    if a < 10.0:
        return a * math.log(x) - x - math.lgamma(a + 1.0)
    # a log x - x - lgamma(a + 1) = a log1pmx((x - a) / a) - log(2 pi a) / 2 - stirling(a)
    ia = 1.0 / a
    ia2 = ia * ia
    stirling = ia * (1 / 12 - ia2 * (1 / 360 - ia2 * (1 / 1260 - ia2 / 1680)))
    return a * _log1pmx((x - a) / a) - 0.5 * math.log(2.0 * math.pi * a) - stirling


def _series_sum(start_ratio: Callable[[np.ndarray], np.ndarray], n_hint: float) -> float:
    """``1 + sum_n prod_{i<=n} r_i``, ratios ``r_i`` of index array ``i`` (1-based), blockwise."""
    total, last, start = 1.0, 1.0, 1
    block = int(min(max(64.0, n_hint), 4e6))
    for _ in range(64):
        ratios = start_ratio(start + np.arange(block, dtype=float))
        terms = last * np.cumprod(ratios)
        total += float(np.sum(terms))
        last = float(terms[-1])
        start += block
        if (last <= 1e-17 * total and ratios[-1] < 1.0) or last == 0.0:
            break
    return total


def _gamma_pq(a: float, x: float) -> tuple[float, float]:
    """Regularised incomplete gamma ``(P(a, x), Q(a, x))``, each with full relative accuracy."""
    if x <= 0.0:
        return 0.0, 1.0
    if x <= a or x < a + 1.0:
        # P = x^a e^-x / Gamma(a+1) * sum_n x^n / ((a+1)...(a+n))
        s = _series_sum(lambda i: x / (a + i), x - a + 12.0 * math.sqrt(x + 1.0) + 32.0)
        p = min(1.0, math.exp(_log_prefactor(a, x)) * s)
        return p, 1.0 - p
    if a >= 100.0:
        # Q = x^(a-1) e^-x / Gamma(a) * sum_n (a-1)...(a-n) / x^n; the remainder
        # Q(a - n, x) is negligible long before a - n reaches 0 when a >= 100, x >= a + 1
        s = _series_sum(lambda i: np.maximum(a - i, 0.0) / x, 12.0 * math.sqrt(x) + 32.0)
        q = min(1.0, math.exp(_log_prefactor(a, x) + math.log(a / x)) * s)
        return 1.0 - q, q
    # small a, x > a + 1: Legendre's continued fraction (modified Lentz), fast here
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 10_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    q = min(1.0, math.exp(_log_prefactor(a, x) + math.log(a / x)) * x * h)
    return 1.0 - q, q


def gamma_p(a: float, x: float) -> float:
    """Regularised lower incomplete gamma function ``P(a, x)`` (``scipy.special.gammainc``).

    Power series below ``a + 1``; above it the downward series of ``Q`` for ``a >= 100`` and
    Legendre's continued fraction otherwise, with the prefactor
    ``x^a e^-x / Gamma(a + 1)`` from Stirling's series so that large ``a`` keeps full
    accuracy.
    """
    if a <= 0.0:
        raise ValueError(f"a must be > 0, got {a}")
    return _gamma_pq(a, x)[0]


def _chi2_isf_one(df: float, p: float) -> float:
    if not 0.0 < p < 1.0:
        if p == 0.0:
            return math.inf
        if p == 1.0:
            return 0.0
        raise ValueError(f"p must be in [0, 1], got {p}")
    a = 0.5 * df
    # Wilson-Hilferty start: chi2 = df (1 - 2/(9 df) + z sqrt(2/(9 df)))^3, z = Phi^-1(1 - p)
    z = _norm_isf(p)
    c = 2.0 / (9.0 * df)
    base = 1.0 - c + z * math.sqrt(c)
    if base > 0:
        u = math.log(0.5 * df * base**3)  # log of the gamma(a) variable
    else:  # far lower tail: P(a, y) ~ y^a / Gamma(a + 1)
        u = (math.log1p(-p) + math.lgamma(a + 1.0)) / a
    # Newton on u = log y for h(u) = log F(y) - log target (F = P in the lower half, where
    # p >= 1/2, and h = log target - log Q in the upper half; both increase with u), which
    # is nearly linear in the tails; kept inside a bracket, bisected when it leaves it
    upper = p < 0.5
    log_t = math.log(p) if upper else math.log1p(-p)
    lo, hi = -math.inf, math.inf
    for _ in range(200):
        y = math.exp(u)
        if y == 0.0:  # underflow, far lower tail: log P = a u - lgamma(a + 1)
            h = a * u - math.lgamma(a + 1.0) - log_t
            if h >= 0 or upper:
                break
            lo, u = u, u - h / a
            continue
        pp, qq = _gamma_pq(a, y)
        f = qq if upper else pp
        if f <= 0.0:
            h = math.inf if upper else -math.inf
        else:
            h = (log_t - math.log(f)) if upper else (math.log(f) - log_t)
        if h > 0:
            hi = min(hi, u)
        elif h < 0:
            lo = max(lo, u)
        else:
            break
        log_dens = _log_prefactor(a, y) + math.log(a / y)  # log of y^(a-1) e^-y / Gamma(a)
        slope = math.exp(log_dens + u - math.log(f)) if f > 0 else 0.0
        step = h / slope if slope > 0 and math.isfinite(h) else math.nan
        tol = 4e-16 * (1.0 + abs(u))  # rounding level of u (h carries ~1e-14 of noise)
        if abs(step) <= tol:
            u -= step
            break
        u_new = u - step
        if not (lo < u_new < hi):  # Newton left the bracket: bisect, or walk towards the root
            if math.isfinite(lo) and math.isfinite(hi):
                u_new = 0.5 * (lo + hi)
            else:
                u_new = u + (1.0 if h < 0 else -1.0)
        if hi - lo <= tol:
            break
        u = u_new
    y = math.exp(u)
    return 2.0 * y


def _norm_isf(p: float) -> float:
    """Standard normal upper quantile (Acklam's rational approximation, |rel err| < 1.2e-9)."""
    q = 1.0 - p
    if q < 0.02425:
        t = math.sqrt(-2.0 * math.log(q))
        return -_acklam_tail(t)
    if q > 1.0 - 0.02425:
        t = math.sqrt(-2.0 * math.log(1.0 - q))
        return _acklam_tail(t)
    r = q - 0.5
    s = r * r
    num = (
        (
            ((-3.969683028665376e01 * s + 2.209460984245205e02) * s - 2.759285104469687e02) * s
            + 1.383577518672690e02
        )
        * s
        - 3.066479806614716e01
    ) * s + 2.506628277459239e00
    den = (
        (
            ((-5.447609879822406e01 * s + 1.615858368580409e02) * s - 1.556989798598866e02) * s
            + 6.680131188771972e01
        )
        * s
        - 1.328068155288572e01
    ) * s + 1.0
    return num * r / den


def _acklam_tail(t: float) -> float:
    num = (
        (
            ((-7.784894002430293e-03 * t - 3.223964580411365e-01) * t - 2.400758277161838e00) * t
            - 2.549732539343734e00
        )
        * t
        + 4.374664141464968e00
    ) * t + 2.938163982698783e00
    den = (
        ((7.784695709041462e-03 * t + 3.224671290700398e-01) * t + 2.445134137142996e00) * t
        + 3.754408661907416e00
    ) * t + 1.0
    return -num / den


def chi2_isf(df: np.ndarray | float, p: np.ndarray | float) -> np.ndarray:
    """Chi-square inverse survival function: ``x`` with ``P(chi2_df > x) = p``.

    Kept rather than ``scipy.special.chdtri`` (180x faster, but it loses ~1e-5 relative in the
    far lower tail of ``df >= 1e8``, ``tests/engine/test_optim.py``); it costs ~2 ms per WV's
    levels.

    Equals ``scipy.special.chdtri(df, p)`` (relative difference below 1e-12 over the
    degrees of freedom of wavelet variances, 1 to 1e8).

    Parameters
    ----------
    df : array_like
        Degrees of freedom (> 0).
    p : array_like
        Upper-tail probabilities in [0, 1].

    Returns
    -------
    ndarray
        The quantiles, broadcast over ``df`` and ``p``.
    """
    d, q = np.broadcast_arrays(np.asarray(df, dtype=float), np.asarray(p, dtype=float))
    out = np.empty(d.shape)
    cache: dict[tuple[float, float], float] = {}
    for idx in np.ndindex(d.shape):
        key = (float(d[idx]), float(q[idx]))
        if key not in cache:
            if not key[0] > 0:
                raise ValueError(f"degrees of freedom must be > 0, got {key[0]}")
            cache[key] = _chi2_isf_one(*key)
        out[idx] = cache[key]
    return out
