"""Robust Haar wavelet variance: Tukey biweight M-estimates of location and scale per level.

Per level j the location ``mu_j`` and scale ``s_j`` of the wavelet coefficients solve the
biweight equations jointly (constant ``c`` from :func:`biweight_constant`, so that the scale's
Gaussian efficiency is ``eff``), and the robust WV is ``nu_j = s_j^2 + mu_j^2``: consistent for
the classical WV's target under Gaussian coefficients, with or without a drift.
:func:`robust_wv` computes it in one blocked pass per level from power sums, with the numbers of
the direct computation. The definition, the root finding, quantised logs, the ADIS16405 ratios
and the algorithm: docs/methods.md, "The robust wavelet variance"; the user's view:
docs/calibrate.md.

Reference: Guerrier, Molinari & Victoria-Feser (2014), robust WV.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from .._blas import blas_threads
from ._kernel import haar_from_cumsum, sumsq_kernel

__all__ = [
    "biweight_constant",
    "robust_scale_biweight",
    "gaussian_psi2_mean",
    "biweight_location_scale",
    "robust_wv",
    "robust_wv_hermite",
]


@lru_cache(maxsize=64)
def _biweight_moments(c: float) -> tuple[float, float, float]:
    """E[g], E[z^2 g], E[g^2] for g(z) = psi(z)^2 = z^2 (1 - z^2/c^2)^4 1{|z|<=c}, Z ~ N(0,1)."""
    from scipy import integrate

    def g(z: float) -> float:
        return z * z * (1 - z * z / (c * c)) ** 4

    def phi(z: float) -> float:
        return math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

    e_g = 2 * integrate.quad(lambda z: g(z) * phi(z), 0, c, epsabs=1e-13)[0]
    e_z2g = 2 * integrate.quad(lambda z: z * z * g(z) * phi(z), 0, c, epsabs=1e-13)[0]
    e_g2 = 2 * integrate.quad(lambda z: g(z) ** 2 * phi(z), 0, c, epsabs=1e-13)[0]
    return e_g, e_z2g, e_g2


def _biweight_efficiency(c: float) -> float:
    a, z2g, g2 = _biweight_moments(c)
    m = z2g - a
    q = g2 - a * a
    return 0.5 * m * m / q


@lru_cache(maxsize=64)
def biweight_constant(eff: float = 0.6) -> float:
    """Tukey biweight constant c whose scale M-estimator has Gaussian efficiency ``eff``.

    The estimator solves ``mean(psi(W / sigma)^2) = E[psi(Z)^2]`` with the biweight
    ``psi(r) = r (1 - r^2/c^2)^2`` on ``|r| <= c``; its efficiency relative to the sample
    variance is ``0.5 M^2 / Q`` (Guerrier, Molinari & Victoria-Feser 2014, robust WV).
    eff = 0.6 gives c of about 4.40.
    """
    from scipy import optimize

    if not 0.0 < eff < 0.99:
        raise ValueError(f"eff must be in (0, 0.99), got {eff}")
    return float(optimize.brentq(lambda c: _biweight_efficiency(c) - eff, 0.5, 60.0, xtol=1e-10))


@lru_cache(maxsize=16)
def robust_wv_hermite(eff: float = 0.6, order: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Hermite weights of the influence function of the robust WV under Gaussian coefficients.

    For coefficients ``W = mu + s Z`` (``Z ~ N(0, 1)``) the robust WV ``nu = s^2 + mu^2`` of
    :func:`robust_wv` has the influence function

        IF(W) = s^2 f(Z) + 2 mu s h(Z),
        f(z) = 2 (g(z) - E g) / E[z g'(z)],   g = psi^2   (the scale equation, even)
        h(z) = psi(z) / E[psi'(z)]                        (the location equation, odd)

    and with the Hermite expansions ``f = sum a_n He_n``, ``h = sum b_n He_n`` the covariance of
    two such functions of jointly Gaussian coefficients with correlation ``r`` is
    ``sum_n n! a_n^2 r^n`` (Mehler). The classical WV (``W^2``) has ``f = He_2``,
    ``h = He_1``; the robust one has the same first terms (``2! a_2^2 = 2``, ``b_1 = 1``:
    it is consistent) and more: at lag 0 the even weights sum to ``2 / eff``.

    Parameters
    ----------
    eff : float
        Gaussian efficiency of the robust WV (its biweight constant, :func:`biweight_constant`).
    order : int
        Highest Hermite degree kept; the mass of the higher degrees (below 1e-5 of the total
        at ``order=16``) is added to the last even and odd entries, so that each array sums to
        its function's variance.

    Returns
    -------
    even, odd : ndarray, shape (order + 1,)
        ``n! a_n^2`` (non-zero at even ``n >= 2``) and ``n! b_n^2`` (odd ``n``).

    References
    ----------
    Hampel, Ronchetti, Rousseeuw & Stahel (1986), Robust Statistics, ch. 5 (M-estimators of
    location and scale); Arcones (1994), Ann. Probab. 22, Limit theorems for nonlinear
    functionals of a stationary Gaussian sequence of vectors.
    """
    from scipy import integrate, special

    c = biweight_constant(eff)
    e_g, e_z2g, e_g2 = _biweight_moments(c)
    m = e_z2g - e_g  # E[z g'(z)] (Stein)

    def gauss(z: float) -> float:
        return math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

    def psi(z: float) -> float:
        return z * (1 - z * z / (c * c)) ** 2

    def moment(fn: Callable[[float], float]) -> float:  # E[fn(Z)] for fn even, 0 off [-c, c]
        return 2 * integrate.quad(lambda z: fn(z) * gauss(z), 0, c, epsabs=1e-14, limit=200)[0]

    e_psi_prime = moment(lambda z: z * psi(z))  # E[psi'] = E[z psi] (Stein)
    e_psi2 = moment(lambda z: psi(z) ** 2)
    even, odd = np.zeros(order + 1), np.zeros(order + 1)
    for n in range(1, order + 1):

        def term(z: float, n: int = n) -> float:
            # even n: E[(g - E g) He_n] = E[g He_n] for n >= 1 (g = psi^2, 0 off [-c, c])
            f = 2 * psi(z) ** 2 / m if n % 2 == 0 else psi(z) / e_psi_prime
            return f * float(special.eval_hermitenorm(n, z))

        e = moment(term)
        (even if n % 2 == 0 else odd)[n] = e * e / math.factorial(n)
    top_even, top_odd = order - order % 2, order - 1 + order % 2
    even[top_even] += max(4 * (e_g2 - e_g * e_g) / (m * m) - even.sum(), 0.0)
    odd[top_odd] += max(e_psi2 / e_psi_prime**2 - odd.sum(), 0.0)
    even.flags.writeable = odd.flags.writeable = False
    return even, odd


def robust_scale_biweight(w: np.ndarray, eff: float = 0.6) -> float:
    """Biweight M-estimate of the scale of ``w`` about ZERO (squared): the older robust WV.

    Solves ``mean(psi(w / sigma)^2) = E[psi(Z)^2]`` for ``sigma^2`` (upper root; with no root,
    beyond the breakdown point, the grid point nearest the peak). This is the R ``wv``
    package's definition; it estimates ``E[W^2]`` only when the coefficients have mean zero
    (a drift biases it). :func:`wavelet_variance` no longer uses it: its robust WV is
    ``s^2 + mu^2`` from the joint biweight location and scale (:func:`robust_wv`).
    """
    from scipy import optimize

    c = biweight_constant(eff)
    a_c = _biweight_moments(c)[0]
    w = np.asarray(w, dtype=np.float64)
    # start from the MAD (robust) and bracket the root on a log scale
    mad = np.median(np.abs(w)) * 1.482602218505602
    if mad <= 0:
        mad = float(np.sqrt(np.mean(w * w)))
    if mad <= 0:
        return 0.0
    w2 = w / mad
    np.square(w2, out=w2)
    c2 = c * c
    r2 = np.empty_like(w2)
    u = np.empty_like(w2)
    sumsq = sumsq_kernel()

    def f(log_s2: float) -> float:
        # mean of r2 (1 - r2/c^2)^4 over r2 = w2 / s2 <= c^2, in preallocated buffers
        # (squares instead of a power: this runs ~8 times per level on every coefficient)
        np.multiply(w2, math.exp(-log_s2), out=r2)
        r2i = r2[r2 <= c2]
        ui = u[: r2i.size]
        np.multiply(r2i, -1.0 / c2, out=ui)
        ui += 1.0
        np.square(ui, out=ui)
        np.square(ui, out=ui)
        return float(sumsq(r2i, ui)) / w.size - a_c

    # f is negative for sigma -> 0 (every point outside c) and for sigma -> inf (psi -> 0) and
    # positive in between; the consistent estimate is the upper root, where f decreases.
    step = 0.5
    f0 = f(0.0)
    if f0 > 0:
        lo, hi = 0.0, step
        while f(hi) > 0:
            lo, hi = hi, hi + step
            if hi > 80:  # pragma: no cover - cannot happen for finite data
                return float(np.mean(w * w))
    else:
        hi, lo, f_prev = 0.0, -step, f0
        while True:
            f_lo = f(lo)
            if f_lo > 0:
                break
            if f_lo < f_prev or lo < -80:
                # past the peak without a root (contamination beyond the breakdown point):
                # take the closest value, as minimising (f)^2 would
                return float(np.exp(lo + step) * mad * mad)
            hi, lo, f_prev = lo, lo - step, f_lo
    root = optimize.brentq(f, lo, hi, xtol=1e-12)
    return float(np.exp(root) * mad * mad)


# ---------------------------------------------------------------------------------------
# the robust WV: joint biweight location and scale per level (fast power-sum path)
# ---------------------------------------------------------------------------------------


_PILOT = 1 << 16  # coefficients in the pilot subsample
_BLOCK = 1 << 16  # block length of the power-sum pass
_DOT_CHUNK = 8192  # a multi-threaded OpenBLAS computes a dot of <= 10,000 elements in the caller
# trust region of the power-sum pass around the pilot: |d| <= _D, rho in [_RHO_LO, _RHO_HI]
_D, _RHO_LO, _RHO_HI = 0.2, 0.8, 1.25
_TOL = 1e-14  # Newton convergence: step in mu/s and in log s


@lru_cache(maxsize=64)
def gaussian_psi2_mean(c: float) -> float:
    """``E[psi(Z)^2]`` for the biweight ``psi`` with constant ``c`` and ``Z ~ N(0, 1)``.

    Closed form from the truncated Gaussian moments ``m_{2k} = E[Z^{2k}; |Z| <= c]``
    (``m_0 = 2 Phi(c) - 1``, ``m_{2k} = (2k - 1) m_{2k-2} - 2 c^{2k-1} phi(c)``) and
    ``psi(z)^2 = sum_k C(4, k) (-1/c^2)^k z^{2k+2}``.
    """
    phi = math.exp(-0.5 * c * c) / math.sqrt(2 * math.pi)
    m = [math.erf(c / math.sqrt(2.0))]
    for k in range(1, 6):
        m.append((2 * k - 1) * m[-1] - 2 * c ** (2 * k - 1) * phi)
    return float(sum(math.comb(4, k) * (-1.0 / c**2) ** k * m[k + 1] for k in range(5)))


# ---- polynomials in r (coefficients of r^0..r^10) of the sums the iteration needs ----------


def _poly_table(c: float) -> np.ndarray:
    """Rows: psi, psi', psi' r, psi^2, psi psi', psi psi' r, weight (1 - u)^2 (u = r^2/c^2)."""
    from numpy.polynomial import polynomial as P

    one_u = np.array([1.0, 0.0, -1.0 / c**2])  # 1 - r^2/c^2
    # float arrays: NumPy's stubs type the product of two untyped arrays as never returning
    psi: npt.NDArray[np.float64] = P.polymul([0.0, 1.0], P.polymul(one_u, one_u))
    dpsi: npt.NDArray[np.float64] = P.polymul(one_u, [1.0, 0.0, -5.0 / c**2])
    rows = [
        psi,
        dpsi,
        P.polymul(dpsi, [0.0, 1.0]),
        P.polymul(psi, psi),
        P.polymul(psi, dpsi),
        P.polymul(P.polymul(psi, dpsi), [0.0, 1.0]),
    ]
    out = np.zeros((len(rows), 11))
    for i, p in enumerate(rows):
        out[i, : p.size] = p
    return out


def _direct_means(w: np.ndarray, mu: float, s: float, c: float) -> np.ndarray:
    """Means over ``w`` of psi, psi', psi' r, psi^2, psi psi', psi psi' r at r = (w - mu)/s."""
    r = (w - mu) / s
    r = r[np.abs(r) <= c]
    u = r * r / (c * c)
    psi = r * (1 - u) ** 2
    dpsi = (1 - u) * (1 - 5 * u)
    pd = psi * dpsi
    return (
        np.array(
            [psi.sum(), dpsi.sum(), (dpsi * r).sum(), (psi * psi).sum(), pd.sum(), (pd * r).sum()]
        )
        / w.size
    )


class _OutOfRegion(Exception):
    """A Newton iterate left the trust region of the power-sum pass."""


def _newton(
    means: Callable[[float, float], np.ndarray], a: float, mu: float, s: float, tol: float = _TOL
) -> tuple[float, float] | None:
    """Newton on (mu, log s) for mean psi = 0, mean psi^2 = a, with backtracking on the
    squared residual; None unless it converges to the upper scale root
    (d mean psi^2 / d log s < 0 there) within 20 evaluations (from a usable start it needs at
    most about 6; without a root nearby it would wander)."""
    evals = [0]

    def means_counted(m: float, sc: float) -> np.ndarray:
        evals[0] += 1
        if evals[0] > 20:
            raise _NoConvergence
        return means(m, sc)

    try:
        return _newton_steps(means_counted, a, mu, s, tol)
    except _NoConvergence:
        return None


class _NoConvergence(Exception):
    """Newton's evaluation budget is spent."""


def _newton_steps(
    means: Callable[[float, float], np.ndarray], a: float, mu: float, s: float, tol: float
) -> tuple[float, float] | None:
    v = means(mu, s)
    while True:
        g, dg, dgr, f, fd, fdr = v
        f -= a
        # derivatives in (delta, log s) with mu = mu + s delta: dr/d delta = -1, dr/d log s = -r
        j11, j12, j21, j22 = -dg, -dgr, -2.0 * fd, -2.0 * fdr
        det = j11 * j22 - j12 * j21
        if not np.isfinite(det) or det == 0.0:
            return None
        delta = -(j22 * g - j12 * f) / det
        dt = -(-j21 * g + j11 * f) / det
        step = max(abs(delta), abs(dt))
        # converged: the step is below tol, or the rounding of mu (a large mean, e.g. a drift
        # at a coarse level, relative to a small scale)
        tol_k = max(tol, 8e-16 * abs(mu) / s)
        if step < tol_k:
            return (mu, s) if j22 < 0 else None
        lam = min(1.0, 0.5 / step)  # damp far steps; a good start never needs it
        merit = g * g + f * f
        for _ in range(8):
            mu_n, s_n = mu + s * lam * delta, s * math.exp(lam * dt)
            v_n = means(mu_n, s_n)
            if v_n[0] ** 2 + (v_n[3] - a) ** 2 < merit or lam * step < tol_k:
                break
            lam *= 0.5
        else:
            return None  # no descent: no root near this start
        mu, s, v = mu_n, s_n, v_n


def _scale_root(w: np.ndarray, mu: float, s: float, c: float, a: float) -> float:
    """Upper root in s of mean psi((w - mu)/s)^2 = a (bracketing in log s from s, then Brent);
    with no root, the maximiser of the left side."""
    from scipy import optimize

    def f(t: float) -> float:
        return float(_direct_means(w, mu, math.exp(t), c)[3]) - a

    t0, step = math.log(s), 0.25
    f0 = f(t0)
    if f0 > 0:
        lo, hi = t0, t0 + step
        while f(hi) > 0:
            lo, hi = hi, hi + step
    else:
        hi, lo, f_prev = t0, t0 - step, f0
        while True:
            f_lo = f(lo)
            if f_lo > 0:
                break
            if f_lo < f_prev or lo < t0 - 80:
                # past the peak without a root: the maximiser of f
                res = optimize.minimize_scalar(
                    lambda t: -f(t),
                    bounds=(lo, hi + step),
                    method="bounded",
                    options={"xatol": 1e-13},
                )
                return math.exp(float(res.x))
            hi, lo, f_prev = lo, lo - step, f_lo
    return math.exp(optimize.brentq(f, lo, hi, xtol=1e-15, rtol=1e-15))


def _one_step(w: np.ndarray, mu: float, s: float, c: float, a: float) -> tuple[float, float]:
    """Fallback: the biweight location at the start scale (reweighting), then the upper
    scale root (or the maximiser) about that location."""
    for _ in range(200):
        r = (w - mu) / s
        keep = np.abs(r) <= c
        wt = (1 - r[keep] ** 2 / (c * c)) ** 2
        if not wt.sum() > 0:
            break
        nxt = float(np.dot(wt, w[keep]) / wt.sum())
        done = abs(nxt - mu) <= 1e-14 * s
        mu = nxt
        if done:
            break
    return mu, _scale_root(w, mu, s, c, a)


def _start(w: np.ndarray) -> tuple[float, float]:
    """Median and normalised MAD (or the RMS about the median when the MAD is 0)."""
    med = float(np.median(w))
    dev = np.abs(w - med)
    s = float(np.median(dev)) * 1.482602218505602
    if s <= 0:
        s = float(np.sqrt(np.mean(dev * dev)))
    return med, s


def biweight_location_scale(w: np.ndarray, c: float) -> tuple[float, float]:
    """Joint biweight M-estimates ``(mu, s)`` of location and scale of ``w`` (direct method).

    Parameters
    ----------
    w : ndarray
        Coefficients of one level.
    c : float
        Biweight constant (:func:`biweight_constant`), used by both equations.

    Returns
    -------
    (mu, s) : tuple of float
        The robust WV of the level is ``s**2 + mu**2``. All coefficients equal give
        ``(w[0], 0.0)``.
    """
    w = np.asarray(w, dtype=np.float64)
    if w.size == 0:
        raise ValueError("no coefficients")
    mu, s = _start(w)
    if s <= 0:
        return float(w[0]), 0.0
    a = gaussian_psi2_mean(c)
    res = _newton(lambda m, sc: _direct_means(w, m, sc, c), a, mu, s)
    if res is None:
        res = _one_step(w, mu, s, c, a)
    return float(res[0]), float(res[1])


# ---- the power-sum pass ---------------------------------------------------------------------


def _dot_kernel() -> Callable[[np.ndarray, np.ndarray], float]:
    if blas_threads() == 1:
        return np.dot

    def chunked(x: np.ndarray, y: np.ndarray) -> float:
        return sum(
            float(np.dot(x[i : i + _DOT_CHUNK], y[i : i + _DOT_CHUNK]))
            for i in range(0, x.size, _DOT_CHUNK)
        )

    return chunked


def _power_pass(
    s: np.ndarray, m: int, mu0: float, s0: float, lim: float, upper: float
) -> tuple[np.ndarray, np.ndarray]:
    """Power sums ``sum y^k`` (k = 0..10) over ``|y| <= lim`` and the values with
    ``lim < |y| <= upper``, for ``y = (W - mu0)/s0`` of the level with ``m = 2^(j-1)``."""
    n1 = s.size  # N + 1
    k1 = 1.0 / (2.0 * m * s0)
    k0 = mu0 / s0
    sums = np.zeros(11)
    band: list[np.ndarray] = []
    dot = _dot_kernel()
    y = np.empty(_BLOCK)
    ay = np.empty(_BLOCK)
    p2 = np.empty(_BLOCK)
    p3 = np.empty(_BLOCK)
    p4 = np.empty(_BLOCK)
    p5 = np.empty(_BLOCK)
    count = 0
    for lo in range(2 * m, n1, _BLOCK):
        hi = min(lo + _BLOCK, n1)
        b = hi - lo
        yb, ab = y[:b], ay[:b]
        np.multiply(s[lo - m : hi - m], -2.0, out=yb)
        yb += s[lo:hi]
        yb += s[lo - 2 * m : hi - 2 * m]
        yb *= k1
        yb -= k0
        np.abs(yb, out=ab)
        out = np.flatnonzero(ab > lim)
        if out.size:
            v = yb[out]
            band.append(v[np.abs(v) <= upper])
            yb[out] = 0.0
        count += b - out.size
        q2, q3, q4, q5 = p2[:b], p3[:b], p4[:b], p5[:b]
        np.multiply(yb, yb, out=q2)
        np.multiply(q2, yb, out=q3)
        np.multiply(q2, q2, out=q4)
        np.multiply(q4, yb, out=q5)
        sums[1] += float(np.sum(yb))
        sums[2] += dot(yb, yb)
        sums[3] += dot(yb, q2)
        sums[4] += dot(q2, q2)
        sums[5] += dot(q2, q3)
        sums[6] += dot(q3, q3)
        sums[7] += dot(q3, q4)
        sums[8] += dot(q4, q4)
        sums[9] += dot(q4, q5)
        sums[10] += dot(q5, q5)
    sums[0] = count
    return sums, (np.concatenate(band) if band else np.empty(0))


@lru_cache(maxsize=1)
def _binomials() -> np.ndarray:
    b = np.zeros((11, 11))
    for k in range(11):
        for i in range(k + 1):
            b[k, i] = math.comb(k, i)
    return b


def _power_means(
    sums: np.ndarray, band: np.ndarray, n_coef: int, c: float, table: np.ndarray
) -> Callable[[float, float], np.ndarray]:
    """``means(d, rho)`` of the six sums at r = (y - d)/rho, from the core's power sums and
    the band; raises _OutOfRegion outside the trust region."""
    binom = _binomials()
    k = np.arange(11)

    def means(d: float, rho: float) -> np.ndarray:
        if abs(d) > _D or not _RHO_LO <= rho <= _RHO_HI:
            raise _OutOfRegion
        # sum (y - d)^k = sum_i C(k, i) (-d)^(k-i) sum y^i, then / rho^k
        pw = (-d) ** np.maximum(k[:, None] - k[None, :], 0)
        rk = np.tril(binom * pw) @ sums / rho**k
        total = table @ rk
        if band.size:
            r = (band - d) / rho
            total = total + _direct_means(r, 0.0, 1.0, c) * r.size
        return total / n_coef

    return means


def _level(
    s: np.ndarray, n: int, m: int, c: float, a: float, table: np.ndarray
) -> tuple[float, float]:
    """(mu, s) of the level with m = 2^(j-1) from the cumulative sum ``s`` (length n + 1)."""
    n_coef = n - 2 * m + 1
    if n_coef <= 2 * _PILOT:
        return biweight_location_scale(haar_from_cumsum(s, m), c)
    wp = haar_from_cumsum(s, m, at=np.arange(0, n_coef, n_coef // _PILOT))
    mu0, s0 = _start(wp)
    if s0 > 0:
        pilot = _newton(lambda mm, sc: _direct_means(wp, mm, sc, c), a, mu0, s0, tol=1e-10)
        if pilot is not None and pilot[1] > 0:
            mu0, s0 = pilot
            sums, band = _power_pass(s, m, mu0, s0, c * _RHO_LO - _D, c * _RHO_HI + _D)
            means = _power_means(sums, band, n_coef, c, table)
            try:
                res = _newton(lambda mm, sc: means((mm - mu0) / s0, sc / s0), a, mu0, s0)
            except _OutOfRegion:
                res = None
            if res is not None:
                return res
    # no usable pilot, or the iteration left the trust region: the direct computation
    return biweight_location_scale(haar_from_cumsum(s, m), c)


def robust_wv(
    s: np.ndarray,
    n: int,
    levels: int,
    c: float,
    progress: Callable[[int, int], object] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust WV ``nu_j = s_j^2 + mu_j^2`` of levels 1..J from the de-meaned cumulative sum.

    Parameters
    ----------
    s : ndarray, shape (n + 1,)
        Cumulative sum of the de-meaned series with a leading 0.
    n : int
        Series length.
    levels : int
        Number of levels J (each needs ``2^j <= n``).
    c : float
        Biweight constant (:func:`biweight_constant`).
    progress : callable, optional
        Called as ``progress(j, levels)`` after level j is done.

    Returns
    -------
    nu, mu, scale : ndarray, shape (J,)
        Robust WV, biweight location and scale of each level's coefficients.
    """
    a = gaussian_psi2_mean(c)
    table = _poly_table(c)
    nu, mus, scs = np.empty(levels), np.empty(levels), np.empty(levels)
    for j in range(1, levels + 1):
        mu, sc = _level(s, n, 1 << (j - 1), c, a, table)
        mus[j - 1], scs[j - 1] = mu, sc
        nu[j - 1] = sc * sc + mu * mu
        if progress is not None:
            progress(j, levels)
    return nu, mus, scs
