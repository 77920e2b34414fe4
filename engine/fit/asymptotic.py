"""The asymptotic theory of a GMWM fit: the model-implied covariance of the WV, the Jacobian of
the implied WV in the unconstrained coordinates, and the sandwich intervals.

It needs no fitting, and the fit needs it (:meth:`engine.fit.GMWMResult.conf_int`, the
efficient weights of :mod:`engine.fit.covariance`), so it sits in the fitting layer;
:mod:`engine.inference` (intervals, J-test, selection) and :mod:`engine.formats` (the
projection's intervals) build on it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from statistics import NormalDist
from typing import Any

import numpy as np

from ..fit.result import FitError
from ..models import Model, Param, Process
from ..wv import WaveletVariance
from ..wv.robust import robust_wv_hermite
from ._closed_form import closed_form_c

__all__ = [
    "spectral_density",
    "frequency_grid",
    "wv_cov_model",
    "inverse_cov",
    "coefficient_cross_cov",
    "mean_coefficient_cov",
    "drift_share",
    "free_params",
    "jacobian",
    "param_cov",
    "asymptotic_bounds",
    "delta_bounds",
]


def spectral_density(p: Process, f: np.ndarray, fs: float) -> np.ndarray:
    """Two-sided spectral density on f in cycles/sample (0 < f <= 1/2); RW generalised.

    The process's own :meth:`engine.models.Process.psd`.
    """
    return p.psd(f, fs)


def frequency_grid(levels: int, model: Model, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on (0, 1/2] and weights of the periodic trapezoid rule for an even integrand (the
    node f = 0, weight ``1 / (2F)``, is left out: add it where the integrand is not 0 there).

    With ``2F`` equispaced nodes on a period, the rule is exact for trigonometric polynomials
    of degree below ``2F``: the Haar gains of levels j, k have degree ``2^j + 2^k``, so
    ``F = 2^(J+1)`` integrates white-noise-like terms exactly; AR1/GM terms need ``F`` above a
    few correlation times (the rule then equals the lag-domain sum up to a negligible wrap).
    """
    need = 2 ** (levels + 1)
    for p in model.processes:
        ar = p.psd_terms(fs).ar
        if ar is not None and 0 < ar[0] < 1:
            # a few correlation times, but no more than 8x the longest scale: beyond the
            # series' span a near-unit-root AR1 acts as a random walk
            need = max(need, int(min(-16.0 / math.log(ar[0]), 2.0 ** (levels + 4))))
    f_nodes = 1 << int(math.ceil(math.log2(need)))
    f = np.arange(1, f_nodes + 1) / (2.0 * f_nodes)
    w = np.full(f_nodes, 1.0 / f_nodes)  # 2 / (2F): the mirrored node counts twice
    w[-1] = 0.5 / f_nodes  # f = 1/2 is its own mirror image
    return f, w


def wv_cov_model(model: Model, wv: WaveletVariance) -> np.ndarray:
    """Asymptotic Gaussian covariance of the WV implied by a model (full J x J matrix), for the
    WV's own estimator (classical or robust) and with the share of a drift.

    ``V = V_2 + V_1 + V_rob``, each ``/ max(M_j, M_k)``:

    * ``V_2``, the classical WV of the zero-mean noise:
      ``(2 / max(M_j, M_k)) int_{-1/2}^{1/2} |H_j|^2 |H_k|^2 S^2 df``, in closed form
      (:mod:`engine.fit._closed_form`: 25 lags of one generalised autocovariance per pair of
      levels, exact integer sums for QN/WN/RW, decimal arithmetic for AR1/GM), about 1 ms for
      22 levels without AR1/GM terms, 10-20 ms per AR1/GM term;
    * ``V_1``, a drift's share: its coefficients have the mean ``mu_j = omega tau_j / 4``, so
      ``nu_j`` has the first-order term ``2 mu_j mean_t(e_{j,t})`` with ``e`` the noise's
      coefficients, whose mean is ``tau_j / 4`` times the noise's increment over the log
      divided by its length. ``V_1 = 4 mu_j mu_k (tau_j tau_k / 16) D / max(M_j, M_k)`` with
      ``D = gamma2 + sum 2 var_AR (1 - phi^M) / M`` (``M = max(M_j, M_k)``): the random walk's
      share is the classical first-order term (the noise's spectrum of the increments at
      ``f = 0``); the AR1/GM share is that of the finite log (it vanishes as ``M`` grows);
    * ``V_rob``, for a robust WV (``wv.robust``) only: the higher Hermite terms of its
      influence function (:func:`engine.wv.robust.robust_wv_hermite`),
      ``sum_{n >= 3} w_n sum_tau cov_jk(tau)^n / (s_j s_k)^(n - 2)`` (even ``n`` times
      ``s_j^2 s_k^2``, odd ``n`` times ``4 mu_j mu_k s_j s_k``) with ``cov_jk`` the
      cross-covariance of the noise's level-j and level-k coefficients at lag ``tau``
      (:func:`coefficient_cross_cov`) and ``s_j^2`` its value at ``(j, j, 0)``. The classical
      WV is the case ``w_2 = 2``, ``w_1 = 1`` and no other term; the robust WV's variance is
      ``1 / eff`` times the classical one for uncorrelated coefficients and less for
      correlated ones (the coarse levels).

    Without these two parts the J-test rejected the true model in 36-39 % of
    robust GM+WN logs (2^16 samples) and in 18 % of WN+RW+DR logs with a strong drift (2^20)
    at 5 %: ``docs/jtest.md``.

    Parameters
    ----------
    model : Model
        Every parameter set (e.g. ``result.model``).
    wv : WaveletVariance
        Gives the levels, ``M_j``, fs and the estimator (``robust``, ``eff``).
    """
    if not model.is_set:
        raise FitError("wv_cov_model needs a model with every value set (a fitted model)")
    poly, ar = _spectral_pieces(model, wv.fs)
    c = _closed_form_of(wv.n_levels, (poly[1], poly[0], poly[-1], tuple(ar)))
    m_j = wv.n_coef.astype(float)
    m_max = np.maximum.outer(m_j, m_j)
    mu = _coefficient_means(model, wv)
    v = 2.0 * c / m_max
    if np.any(mu > 0):
        v = v + drift_share(model, wv)
    if getattr(wv, "robust", False):
        v = v + _robust_excess(wv, poly, ar, mu) / m_max
    return v


#: The last closed-form ``C`` per spectrum, with its levels (a few entries: one per model a
#: caller asks about in turn, e.g. a run plan's lengths).
_C_SEEN: dict[tuple[float, float, float, tuple[tuple[float, float], ...]], np.ndarray] = {}


def inverse_cov(v: np.ndarray) -> np.ndarray:
    """Symmetric inverse of a covariance, with eigenvalues floored for stability: the efficient
    GMWM's weights ``Omega = V^-1`` (the GMWM paper, Corollary 1)."""
    vals, vecs = np.linalg.eigh((v + v.T) / 2)
    vals = np.maximum(vals, vals.max() * 1e-12)
    inv = (vecs / vals) @ vecs.T
    return (inv + inv.T) / 2


def _closed_form_of(
    levels: int, spectrum: tuple[float, float, float, tuple[tuple[float, float], ...]]
) -> np.ndarray:
    """:func:`engine.fit._closed_form.closed_form_c` of ``spectrum`` = ``(q2, sigma2, gamma2,
    ar)`` at ``levels``, remembered. ``C_jk`` depends on the two levels only, not on how many
    there are, so the ``C`` of more levels gives that of fewer as its leading block, bit for
    bit: a run plan evaluates one model at 20-30 lengths (19-30 levels) and pays for the
    AR1/GM pieces (10-20 ms each) once."""
    c = _C_SEEN.get(spectrum)
    if c is None or c.shape[0] < levels:
        c = closed_form_c(levels, *spectrum[:3], list(spectrum[3]))
        if len(_C_SEEN) >= 16:
            _C_SEEN.clear()
        _C_SEEN[spectrum] = c
    return c[:levels, :levels].copy()


def _coefficient_means(model: Model, wv: Any) -> np.ndarray:
    """``mu_j``: the mean of the level-j coefficients, from the deterministic terms (a drift:
    ``|omega| tau_j / 4``)."""
    tau = 2.0 ** np.arange(1, wv.n_levels + 1)
    mu = np.zeros(tau.size)
    for p in model.processes:
        if p.deterministic:
            mu = mu + np.sqrt(np.maximum(p.wv(tau, wv.fs), 0.0))
    return mu


def drift_share(model: Model, wv: WaveletVariance) -> np.ndarray:
    """The first-order share of a drift in the covariance of the WV (the ``V_1`` of
    :func:`wv_cov_model`): ``4 mu_j mu_k Cov(ebar_j, ebar_k)`` (:func:`mean_coefficient_cov`);
    zero without a drift.

    Parameters
    ----------
    model : Model
        Every parameter set.
    wv : WaveletVariance
        Gives the levels, ``M_j``, ``n`` and fs.
    """
    mu = _coefficient_means(model, wv)
    if not np.any(mu > 0):
        return np.zeros((mu.size, mu.size))
    poly, ar = _spectral_pieces(model, wv.fs)
    return 4.0 * np.outer(mu, mu) * mean_coefficient_cov(poly, ar, wv.n, wv.n_coef)


def mean_coefficient_cov(
    poly: dict[int, float], ar: list[tuple[float, float]], n: int, n_coef: np.ndarray
) -> np.ndarray:
    """Covariance of the means over ``t`` of the noise's Haar coefficients, ``Cov(ebar_j,
    ebar_k)``, for a log of ``n`` samples (what a drift's first-order share of V needs).

    The sum over the ``M_j`` coefficients of level j is a weighted sum of the increments
    ``D_u = X_u - X_(u-1)``, ``u = 1..n-1``, with weights ``P_j = tau_j / 4`` on the plateau and
    ramps ``H_j(r) = sum_{d <= r} G_j(d)`` over the first and last ``2^j`` increments (``G_j``
    the triangle of :func:`coefficient_cross_cov`), so for a random walk (iid increments of
    variance gamma2) ``Cov = gamma2 sum_u W_j(u) W_k(u) / (M_j M_k)`` exactly, and for white
    noise ``sigma2 sum_s w_j(s) w_k(s) / (M_j M_k)`` with ``w`` the weights on the samples (the
    increments' weights differenced). An AR1/GM term adds ``P_j P_k 2 var (1 - phi^M) /
    (M_j M_k)``, ``M = min(M_j, M_k)`` (the variance of the difference of its values at the
    two ends; the ramps' smoothing is left out). QN adds nothing of this order.

    Parameters
    ----------
    poly, ar
        The spectral pieces (``{1: q2, 0: sigma2, -1: gamma2}``, AR1 ``(phi, s)`` pairs).
    n : int
        Log length.
    n_coef : ndarray, shape (J,)
        ``M_j``.

    Returns
    -------
    ndarray (J, J)
    """
    m_j = np.asarray(n_coef, float)
    rw, wn = _increment_sums(int(n), tuple(int(m) for m in m_j))
    cov = poly[-1] * rw + poly[0] * wn
    plateau = 2.0 ** np.arange(1, m_j.size + 1) / 4.0  # H_j's last value, tau_j / 4
    m_min = np.minimum.outer(m_j, m_j)
    for phi, s in ar:
        if 0.0 < phi < 1.0:
            var = s / (1.0 - phi * phi)
            cov = cov + np.outer(plateau, plateau) * 2.0 * var * (1.0 - phi**m_min)
    return cov / np.outer(m_j, m_j)


@functools.lru_cache(maxsize=16)
def _increment_sums(n: int, n_coef: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``sum_u W_j(u) W_k(u)`` and ``sum_s w_j(s) w_k(s)`` of :func:`mean_coefficient_cov` (the
    random walk's and the white noise's factors, which depend on the log's length only: cached,
    a ranking asks for them twice).

    Each level's weights are piecewise polynomials of degree 2 or less in the index (the ramp up
    ``H_j``, the plateau, the ramp down; :func:`_weight4`), so on each stretch between the
    breakpoints of a pair the product is a polynomial of degree 4 or less, summed exactly from
    its first five values (Newton's forward differences, in Python integers). The cost is
    ``O(J^2)`` time and memory whatever ``n`` (it built arrays of ``2^J`` and ``n`` values
    before: 512 MiB each for 3.6e8 samples).
    """
    n_lev = len(n_coef)
    inc = n - 1  # increments
    rw = np.empty((n_lev, n_lev))
    wn = np.empty((n_lev, n_lev))
    halves = [1 << j for j in range(n_lev)]  # m = 2^(j-1), j = 1..J
    for b in range(n_lev):
        mb = halves[b]
        short = 2 * (2 * mb - 1)  # both ramps of the coarser level, K = 2m - 1 increments each
        for a in range(b + 1):
            ma = halves[a]
            if short <= inc:  # a plateau between the ramps: its length adds P_a P_b per increment
                rw4, wn4 = _pair_sums4(ma, mb, short)
                rw4 += (inc - short) * (2 * ma * ma) * (2 * mb * mb)
            else:  # the coarsest levels of a short log: the ramps meet
                rw4, wn4 = _pair_sums4(ma, mb, inc)
            scale = 16.0 * ma * mb
            rw[a, b] = rw4 / scale
            wn[a, b] = wn4 / scale
    iu = np.triu_indices(n_lev, 1)
    rw[iu[::-1]] = rw[iu]
    wn[iu[::-1]] = wn[iu]
    rw.setflags(write=False)
    wn.setflags(write=False)
    return rw, wn


@functools.lru_cache(maxsize=2048)
def _pair_sums4(ma: int, mb: int, inc: int) -> tuple[int, int]:
    """``16 ma mb`` times ``sum_u W_a(u) W_b(u)`` and ``sum_s w_a(s) w_b(s)`` over a log of
    ``inc`` increments, exact (cached: for long logs they are asked at ``inc = 2 (2 mb - 1)``
    only, whatever the length)."""
    big = functools.partial(_product4, _weight4, ma, mb, inc)
    small = functools.partial(_product4, _sample_weight4, ma, mb, inc)
    rw4 = _piecewise_sum(big, _weight_breaks(ma, inc) | _weight_breaks(mb, inc), 1, inc + 1)
    wn4 = _piecewise_sum(
        small, _sample_weight_breaks(ma, inc) | _sample_weight_breaks(mb, inc), 0, inc + 1
    )
    return rw4, wn4


def _ramp4(r: int, m: int) -> int:
    """``4 m H(r)``, an integer: the ramp ``H(r) = sum_{d <= r} G(d)`` of a level with
    ``m = 2^(j-1)`` (``G`` its triangle ``1..m..1 / 2m``), 0 below ``r = 0`` and ``m / 2``
    (``tau_j / 4``) from ``r = 2m - 2`` on. Quadratic pieces: ``(r + 1)(r + 2) / 4m`` for
    ``r < m``, then ``(m + 1) / 4 + (t (m - 1) - t (t - 1) / 2) / 2m`` with ``t = r - m + 1``."""
    if r < 0:
        return 0
    if r < m:
        return (r + 1) * (r + 2)
    if r < 2 * m - 1:
        t = r - m + 1
        return m * (m + 1) + 2 * t * (m - 1) - t * (t - 1)
    return 2 * m * m


def _weight4(m: int, inc: int, u: int) -> int:
    """``4 m W(u)``: the weight of increment ``u`` (``1..inc``, 0 elsewhere) in the sum of one
    level's coefficients, ``H(min(K - 1, inc - u)) - H(K - 1 - u)``, ``K = 2m - 1``."""
    if u < 1 or u > inc:
        return 0
    return _ramp4(inc - u, m) - _ramp4(2 * m - 2 - u, m)


def _sample_weight4(m: int, inc: int, s: int) -> int:
    """``4 m w(s)``: the weight of sample ``s`` (``0..inc``), the increments' weights
    differenced."""
    return _weight4(m, inc, s + 1) - _weight4(m, inc, s)


def _weight_breaks(m: int, inc: int) -> set[int]:
    """The first indices of the stretches on which :func:`_weight4` is one polynomial: the
    breaks of ``H(c - u)`` (``u = c + 1, c - m + 1, c - 2m + 2``) for ``c = inc`` and
    ``c = 2m - 2``, and the ends of the range."""
    breaks = {1, inc + 1}
    for c in (inc, 2 * m - 2):
        breaks.update((c + 1, c - m + 1, c - 2 * m + 2))
    return breaks


def _sample_weight_breaks(m: int, inc: int) -> set[int]:
    """The breaks of :func:`_sample_weight4`: those of both shifted weights, and its range."""
    w = _weight_breaks(m, inc)
    return w | {u - 1 for u in w} | {0, inc + 1}


def _product4(weight: Callable[[int, int, int], int], ma: int, mb: int, inc: int, u: int) -> int:
    """The product of two levels' (scaled, integer) weights at ``u``."""
    return weight(ma, inc, u) * weight(mb, inc, u)


def _piecewise_sum(f: Callable[[int], int], breaks: set[int], start: int, stop: int) -> int:
    """Exact ``sum_{start <= u < stop} f(u)`` for an ``f`` that is a polynomial of degree 4 or
    less on each stretch between consecutive breaks (``start`` and ``stop`` among them): each
    stretch of ``L`` terms is ``sum_k Delta^k f(lo) C(L, k + 1)`` (Newton's forward
    differences), in Python integers."""
    points = sorted(u for u in breaks if start <= u <= stop)
    total = 0
    for lo, hi in zip(points[:-1], points[1:], strict=True):
        length = hi - lo
        if length <= 5:
            total += sum(f(u) for u in range(lo, hi))
            continue
        diffs = [f(lo + i) for i in range(5)]
        for k in range(5):
            total += diffs[0] * math.comb(length, k + 1)
            diffs = [y - x for x, y in zip(diffs[:-1], diffs[1:], strict=True)]
    return total


def _spectral_pieces(model: Model, fs: float) -> tuple[dict[int, float], list[tuple[float, float]]]:
    """The model's spectrum as :class:`engine.models.PsdTerms` pieces, summed over processes:
    ``{1: q2, 0: sigma2, -1: gamma2}`` and the AR1 pieces ``(phi, s)``."""
    # S = q2 x + sigma2 + gamma2 / x + sum s / y(phi): the processes' spectral pieces
    poly = {1: 0.0, 0: 0.0, -1: 0.0}
    ar: list[tuple[float, float]] = []
    for p in model.processes:
        if p.linear_coef() == 0:
            continue  # fitted at zero: contributes nothing (its phi/beta is arbitrary)
        terms = p.psd_terms(fs)  # a drift has none: no first-order contribution
        for power, coef in terms.poly.items():
            if power not in poly:  # pragma: no cover - no process has such a spectrum yet
                raise TypeError(
                    f"wv_cov_model has no closed form for {p.code}'s spectral term x^{power}"
                )
            poly[power] += coef
        if terms.ar is not None:
            ar.append(terms.ar)
    return poly, ar


def coefficient_cross_cov(
    poly: dict[int, float],
    ar: list[tuple[float, float]],
    j: int,
    k: int,
    extent: int = 0,
    cache: dict[Any, Any] | None = None,
) -> np.ndarray:
    """Cross-covariance of the level-j and level-k Haar coefficients of a zero-mean noise at
    every lag, up to a shift: ``Cov(e_{j,t}, e_{k,t+tau+d})`` with ``d = 2^(j-1) - 2^(k-1)``
    (lag ``tau`` in circular order, 0 first; sums over all lags, which is what the robust WV's
    covariance needs, do not depend on the shift).

    On increments the level-j Haar filter is the triangle ``G_j = (1, 2, .., m, .., 2, 1) / 2^j``
    (``H_j(z) = (1 - z) G_j(z)``, ``m = 2^(j-1)``), whose gain is ``e^(-2 pi i f (m - 1))
    A_j(f)`` with ``A_j = sin^2(pi f m) / (2^j sin^2(pi f))`` (``A_j(0) = tau_j / 4``). The
    cross-spectrum without the shift is ``A_j A_k x S`` with the spectrum of the increments
    ``x S = q2 x^2 + sigma2 x + gamma2 + sum s x / y`` (no singularity at ``f = 0``: a random
    walk is covered), inverted by FFT on ``L`` nodes, ``L`` a power of two at least
    ``2^j + 2^k + 4 + extent``: exact for QN/WN/RW (finite support), and for AR1/GM up to the
    wrap-around ``phi^L`` (``extent``: a few correlation times).

    Parameters
    ----------
    poly, ar
        The spectral pieces (``{1: q2, 0: sigma2, -1: gamma2}``, AR1 ``(phi, s)`` pairs).
    j, k : int
        Levels.
    extent : int
        Extra lags for AR1/GM terms.
    cache : dict, optional
        Spectra and gains by FFT size, kept between calls on the same ``poly, ar``.
    """
    n_fft = 1 << int(math.ceil(math.log2((1 << j) + (1 << k) + 4 + extent)))
    memo = {} if cache is None else cache
    if memo.get("n_fft") != n_fft:  # one FFT size at a time: at most a few arrays kept
        memo.clear()
        f = np.arange(n_fft // 2 + 1) / n_fft
        sin2 = np.sin(np.pi * f) ** 2
        x = 4.0 * sin2
        xs = poly[1] * x * x + poly[0] * x + poly[-1]
        for phi, s in ar:
            xs = xs + s * x / ((1.0 - phi) ** 2 + phi * x)
        memo.update(n_fft=n_fft, base=(f, sin2, xs))
    f, sin2, xs = memo["base"]

    def gain_of(lev: int) -> np.ndarray:
        m = 1 << (lev - 1)
        a = np.empty_like(f)
        a[0] = m / 2.0  # m^2 / 2^j
        a[1:] = np.sin(np.pi * f[1:] * m) ** 2 / (2.0 * m * sin2[1:])
        return a

    top = max(j, k)
    if memo.get("top") != top:
        memo.update(top=top, top_gain=gain_of(top))
    gain = xs * memo["top_gain"] * (memo["top_gain"] if j == k else gain_of(min(j, k)))
    return np.fft.irfft(gain, n_fft)


#: Levels further apart than this get no robust excess in their covariance: their coefficients'
#: correlation is below about 2^(-band/2), so the excess (Hermite degree >= 3) is below about
#: 1 % of their classical covariance, itself small; leaving them out keeps the cost to
#: O(band J) FFTs instead of O(J^2).
_ROBUST_BAND = 6


def _robust_excess(
    wv: WaveletVariance, poly: dict[int, float], ar: list[tuple[float, float]], mu: np.ndarray
) -> np.ndarray:
    """``max(M_j, M_k) V_rob`` of :func:`wv_cov_model`: the robust WV's Hermite terms beyond
    the classical ones (degree 3 and up)."""
    even, odd = robust_wv_hermite(float(wv.eff), 10)
    extent = 0
    for phi, _ in ar:
        if 0.0 < phi < 1.0:
            extent = max(extent, int(min(-16.0 / math.log(phi), 2.0 ** (wv.n_levels + 2))))
    n = wv.n_levels
    levels = list(range(1, n + 1))
    s = np.empty(n)
    out = np.zeros((n, n))
    memo: dict[Any, Any] = {}
    diag = {}
    for a in range(n):
        diag[a] = coefficient_cross_cov(poly, ar, levels[a], levels[a], extent, memo)
        s[a] = math.sqrt(max(diag[a][0], 0.0))
    for b in range(n):  # the larger level outer: one FFT size per b for the pairs a < b
        for a in range(max(b - _ROBUST_BAND, 0), b + 1):
            if s[a] == 0.0 or s[b] == 0.0:
                continue
            cov = diag.pop(a) if a == b else None
            if cov is None:
                cov = coefficient_cross_cov(poly, ar, levels[a], levels[b], extent, memo)
            r = cov / (s[a] * s[b])
            rn = r * r
            tot_even = tot_odd = 0.0
            for deg in range(3, even.size):
                rn = rn * r
                w = even[deg] if deg % 2 == 0 else odd[deg]
                if w == 0.0:
                    continue
                sum_rn = float(rn.sum())
                if deg % 2 == 0:
                    tot_even += w * sum_rn
                else:
                    tot_odd += w * sum_rn
            out[a, b] = out[b, a] = (
                s[a] ** 2 * s[b] ** 2 * tot_even + 4.0 * mu[a] * mu[b] * s[a] * s[b] * tot_odd
            )
    return out


def free_params(res: Any) -> list[tuple[int, str]]:
    """(process index, parameter name) of the free parameters: not on a boundary, and not
    belonging to an AR1/GM whose variance is 0 (its phi/beta is then not identified)."""
    out = []
    for i, (lab, p) in enumerate(zip(res.model.labels, res.model.processes, strict=True)):
        if p.linear_coef() <= 0:
            continue
        for name in p.param_names:
            if f"{lab}.{name}" not in res.at_bound:
                out.append((i, name))
    return out


def _spec(model: Model, i: int, name: str) -> Param:
    """The declaration of parameter ``name`` of process ``i`` (its transform, its sign)."""
    return model.processes[i].params()[name]


def _set(model: Model, free: list[tuple[int, str]], u: np.ndarray) -> Model:
    """The model with the free parameters set from unconstrained coordinates ``u``."""
    procs = list(model.processes)
    for (i, name), ui in zip(free, u, strict=True):
        value = _spec(model, i, name).from_unconstrained(float(ui))
        procs[i] = procs[i].with_values(**{name: value})
    return Model(tuple(procs))


def _u0(model: Model, free: list[tuple[int, str]]) -> np.ndarray:
    """Unconstrained coordinates of the free parameters (each by its class's transform)."""
    return np.array(
        [
            _spec(model, i, n).to_unconstrained(float(getattr(model.processes[i], n)))
            for i, n in free
        ]
    )


def _steps(model: Model, free: list[tuple[int, str]], u0: np.ndarray) -> list[float]:
    """Central-difference steps in the unconstrained coordinates: ``1e-5 max(1, |u|)`` for the
    log and atanh coordinates; ``1e-5 |omega|`` for a parameter whose size alone is identified
    (:attr:`engine.models.Param.magnitude`: a drift's omega), which is taken as is at any
    scale (``1e-9`` per sample for a gyro) and whose reported size ``|omega|`` has a kink at 0:
    a step of ``1e-5`` across it made the rate ramp's gradient ``|omega| / 1e-5`` times too
    small, and its interval as much too narrow."""
    return [
        1e-5 * (abs(u) if _spec(model, i, name).magnitude and u != 0 else max(1.0, abs(u)))
        for (i, name), u in zip(free, u0, strict=True)
    ]


def jacobian(res: Any, free: list[tuple[int, str]] | None = None) -> np.ndarray:
    """d nu / d u (J x p) at the estimate, u the unconstrained coordinates of free parameters."""
    free = free_params(res) if free is None else free
    tau = tuple(res.wv.tau_samples.tolist())
    return _jacobian(res.model, tuple(free), tau, res.fs).copy()


@functools.lru_cache(maxsize=256)
def _jacobian(
    model: Model, free: tuple[tuple[int, str], ...], scales: tuple[float, ...], fs: float
) -> np.ndarray:
    """:func:`jacobian` of a model at the scales ``scales`` (samples), remembered: a run plan
    asks for it at every length it tries, and it depends on the number of levels only."""
    fr = list(free)
    u0 = _u0(model, fr)
    tau = np.asarray(scales)
    jac = np.empty((tau.size, len(fr)))
    # a model's WV is the sum of its processes' (Model.wv): a step in one parameter moves only
    # its process's term, so the difference is taken of that term alone (no Model rebuilt)
    for k, ((i, name), h) in enumerate(zip(fr, _steps(model, fr, u0), strict=True)):
        proc, spec = model.processes[i], _spec(model, i, name)
        up = proc.with_values(**{name: spec.from_unconstrained(float(u0[k] + h))})
        dn = proc.with_values(**{name: spec.from_unconstrained(float(u0[k] - h))})
        jac[:, k] = (up.wv(tau, fs) - dn.wv(tau, fs)) / (2 * h)
    jac.flags.writeable = False
    return jac


def param_cov(res: Any, vmat: np.ndarray, free: list[tuple[int, str]] | None = None) -> np.ndarray:
    """The sandwich covariance ``(A' W A)^-1 A' W V W A (A' W A)^-1`` of the free parameters
    (:func:`free_params`, in that order) in their unconstrained coordinates (log of variances
    and beta, atanh of phi, omega as is).

    Parameters
    ----------
    res : GMWMResult
        The fit (model, WV, Omega, at_bound).
    vmat : ndarray (J, J)
        Covariance of the WV.
    free : list of (process index, parameter name), optional
        Default :func:`free_params` of ``res``.

    Returns
    -------
    ndarray (p, p)
    """
    free = free_params(res) if free is None else free
    a = jacobian(res, free)
    w = res.omega
    bread = _equilibrated_pinv(a.T @ w @ a)
    return bread @ a.T @ w @ vmat @ w @ a @ bread


def _equilibrated_pinv(m: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a symmetric information matrix after scaling it to a unit diagonal.

    A parameter that the data barely inform (a random walk in a short log: its information is
    1e-20 of the white noise's) is a badly *scaled* direction, not a missing one: a plain
    ``pinv`` drops it below its relative cutoff and reports a variance of 0. Scaled, its
    variance comes out as large as it is. Parameters with no information at all (a zero
    diagonal) keep ``pinv``'s 0.
    """
    d = np.diagonal(m).copy()
    s = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 1.0)
    return s[:, None] * np.linalg.pinv(s[:, None] * m * s[None, :]) * s[None, :]


def asymptotic_bounds(res: Any, vmat: np.ndarray, level: float) -> list[tuple[float, float]]:
    """Wald bounds of every parameter (in ``res.param_records`` order) at two-sided ``level``.

    The sandwich ``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2)
    in the unconstrained coordinates (log of variances and beta, atanh of phi, omega as is),
    mapped back, so the bounds respect the parameter space. A parameter on a boundary (or of
    an AR1/GM with zero variance) gets ``nan`` bounds; a drift's bounds are of ``|omega|``.

    Parameters
    ----------
    res : GMWMResult
        The fit (model, WV, Omega, at_bound).
    vmat : ndarray (J, J)
        Covariance of the WV.
    level : float
        Two-sided coverage in (0, 1).
    """
    free = free_params(res)
    cov = param_cov(res, vmat, free)
    se = np.sqrt(np.maximum(np.diagonal(cov), 0.0))
    z = NormalDist().inv_cdf(0.5 + level / 2)
    u0 = _u0(res.model, free)
    bounds = {}
    magnitude = set()
    for k, (i, name) in enumerate(free):
        spec = _spec(res.model, i, name)
        lo = spec.from_unconstrained(u0[k] - z * se[k])
        hi = spec.from_unconstrained(u0[k] + z * se[k])
        bounds[(res.model.labels[i], name)] = (min(lo, hi), max(lo, hi))
        if spec.magnitude:
            magnitude.add((res.model.labels[i], name))
    out = []
    for r in res.param_records:
        lo, hi = bounds.get((r.label, r.name), (math.nan, math.nan))
        if (r.label, r.name) in magnitude:  # its sign is not identified: report |value|
            lo, hi = (max(lo, 0.0), hi) if r.value >= 0 else (lo, hi)
        out.append((float(lo), float(hi)))
    return out


@functools.lru_cache(maxsize=256)
def _shifted(
    model: Model, free: tuple[tuple[int, str], ...]
) -> tuple[tuple[float, Model, Model], ...]:
    """The delta method's central differences: per free parameter, its step in the
    unconstrained coordinates (:func:`_steps`) and the models one step up and one step down.
    Remembered per model: a run plan evaluates the IEEE table of one model at every length it
    tries (:func:`engine.inference.planning.plan_run`: a sixth of its CPU)."""
    fr = list(free)
    u0 = _u0(model, fr)
    out = []
    for k, h in enumerate(_steps(model, fr, u0)):
        up, dn = u0.copy(), u0.copy()
        up[k] += h
        dn[k] -= h
        out.append((h, _set(model, fr, up), _set(model, fr, dn)))
    return tuple(out)


def delta_bounds(
    res: Any,
    fns: Sequence[Callable[[Model, float], float]],
    level: float,
    *,
    vmat: np.ndarray | None = None,
) -> list[tuple[float, float]]:
    """Delta-method bounds of positive functions of a fitted model, on the log scale.

    For each ``g = fn(model, fs)``: ``se = sqrt(d' C d)`` with ``d`` the central-difference
    gradient of ``g`` in the unconstrained coordinates of the free parameters
    (:func:`free_params`) and ``C`` their sandwich covariance (:func:`param_cov`); the bounds
    are ``g exp(-/+ z se / g)`` (positive, like the parameters' own).

    Parameters
    ----------
    res : GMWMResult
        The fit (model, WV, Omega, at_bound).
    fns : sequence of callables ``(model, fs) -> float``
        The quantities.
    level : float
        Two-sided coverage in (0, 1).
    vmat : ndarray (J, J), optional
        Covariance of the WV (default :func:`wv_cov_model` of the fit).

    Returns
    -------
    list of (low, high)
        NaN bounds for a quantity that is not positive or that depends on no free parameter
        (all its terms on a bound).
    """
    free = free_params(res)
    if not free:
        return [(math.nan, math.nan)] * len(fns)
    try:
        cov = param_cov(res, wv_cov_model(res.model, res.wv) if vmat is None else vmat, free)
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - degenerate V
        return [(math.nan, math.nan)] * len(fns)
    z = NormalDist().inv_cdf(0.5 + level / 2)
    shifted = _shifted(res.model, tuple(free))
    out = []
    for fn in fns:
        g0 = fn(res.model, res.fs)
        if not (math.isfinite(g0) and g0 > 0):
            out.append((math.nan, math.nan))
            continue
        d = np.array([(fn(a, res.fs) - fn(b, res.fs)) / (2 * h) for h, a, b in shifted])
        var = float(d @ cov @ d)
        if not (math.isfinite(var) and var > 0):
            out.append((math.nan, math.nan))
            continue
        s = min(math.sqrt(var) / g0, 700.0 / z)  # beyond: an interval of no information
        out.append((g0 * math.exp(-z * s), g0 * math.exp(z * s)))
    return out
