"""Tail factors of the export bound: how much more variance than the empirical WV a
Gaussian filter needs so that its quantile covers the data's (:func:`tail_factors`).

A Kalman filter assumes Gaussian errors: at a given scale its error has the spread of a
normal law of the variance it carries. The data bound of
:func:`engine.formats.projection.project` makes that variance at least the data's (the
empirical WV, or a limit of its interval). For a sensor whose errors at the scales a filter
integrates over are heavier-tailed than Gaussian (the ADIS16405 accelerometers: the kurtosis
of their 10 s mean differences is 4-11, docs/filters.md), the right variance still leaves the
filter overconfident on the largest errors. The tail factor of a scale is the least factor on
the variance that makes the Gaussian ``level`` quantile (two sided) of the file cover the
data's:

``f_j = max(1, (q_j / (z * rms_j))^2)``, ``z = Phi^-1((1 + level) / 2)``,

with ``q_j`` the ``level`` quantile of the absolute Haar coefficients ``|W_{j,t}|`` of the
de-meaned signal at scale ``tau_j = 2^j`` samples (docs/conventions.md) and ``rms_j`` their
root mean square (the square root of the WV). For Gaussian coefficients ``q_j = z rms_j``: the
factor is 1. By default (``confidence=0.95``) ``q_j`` is the **lower confidence limit** of the
quantile (distribution-free, from the binomial law of the count of coefficients below it, on
the ``eta_j = max(M_j / 2^j, 1)`` independent coefficients of the eta3 interval), so a factor
above 1 says the data give evidence of tails heavier than Gaussian at that scale, in the
spirit of the data bound's default (its interval's lower limit). With ``confidence=None`` the
point estimate.

Level. The default ``level`` is 0.999 (z = 3.29), the tail a filter's chi-square gates work
in (an innovation gate at 3-3.3 sigma). On the ADIS16405 logs (docs/filters.md, "Tails";
``tests/benchmarks/bench_filter.py --recorded --tails``): at 0.95 (z = 1.96) the
accelerometers' quantile ratios are 0.72-1.14, Gaussian's or less (a heavy-tailed law with the
right variance has a narrower core), so no factor; at 0.99 the factors are at most 1.4 and the
10 s aiding cells keep 9-14 % of epochs above the NEES band; at 0.995 5-6 %; at 0.999 the
factors are 1.5-3.6 at 10-41 s on the accelerometers and at most 1.05 on the gyros, the cells
1.2-2.4 % above with a mean NEES of 0.71-0.75. The level was chosen on that benchmark, and is a
parameter.

Span. A filter aided every ``T`` s integrates its errors over ``T`` and, through its bias
state, over a few ``T``; a burst shorter than that is averaged with the quiet time around it.
So the tail factors matter for the scales near the filter's horizon, not below: when the
horizon ``H`` is given (``project(..., horizon_s=H)``, ``gmwm export --horizon``) they apply at
the scales ``H / TAIL_SPAN .. H`` only (:func:`tail_band`), and the data bound alone below.
With ``TAIL_SPAN = 4`` and the advised horizon of 4 aiding intervals that is the scales from
one aiding interval to the horizon. On the ADIS16405 accelerometers (bursts at 10-41 s) the
tails at 20-41 s then serve a filter aided every 10 s and no longer force the file of one aided
every 100 s up at 100-1000 s (docs/filters.md, "The tails' span": 15 of 18 accelerometer cells
with a horizon of 4 aiding intervals against 12; a span of 2 or 8 gives the same cells, 16 lets
the 20-41 s bump back into the 100 s cells). Without a horizon (the aiding unknown) they apply
at every scale of the band.
"""

from __future__ import annotations

import functools
import math
import weakref
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..wv import as_series, iter_sampled_haar_coefficients

if TYPE_CHECKING:
    from ..io import ImuLog

__all__ = [
    "TAIL_LEVEL",
    "TAIL_SPAN",
    "TailFactors",
    "quantile_factor",
    "tail_band",
    "tail_factors",
    "log_tail_factors",
]

#: Default two-sided level of the quantile the file must cover (module docstring).
TAIL_LEVEL = 0.999

#: With a horizon ``H`` given, the tail factors apply at the scales ``H / TAIL_SPAN .. H``
#: (module docstring, "Span").
TAIL_SPAN = 4.0


def tail_band(lo_s: float, hi_s: float, horizon_s: float | None) -> tuple[float, float]:
    """The scales (s) of a bound's band ``lo_s .. hi_s`` at which the tail factors apply: the
    whole band without a horizon, else ``max(lo_s, horizon_s / TAIL_SPAN) .. hi_s`` (module
    docstring, "Span"; empty, ``lo > hi``, when the band ends below ``horizon_s / TAIL_SPAN``).

    >>> tail_band(0.02, 400.0, 400.0)
    (100.0, 400.0)
    >>> tail_band(0.02, 1e4, None)
    (0.02, 10000.0)
    """
    if horizon_s is None:
        return float(lo_s), float(hi_s)
    return max(float(lo_s), float(horizon_s) / TAIL_SPAN), float(hi_s)


@functools.lru_cache(maxsize=16)
def _gauss_quantile(level: float) -> float:
    """``Phi^-1((1 + level) / 2)``: the two-sided ``level`` quantile of a standard normal."""
    from scipy.stats import norm

    return float(norm.ppf(0.5 + level / 2.0))


def quantile_factor(
    w: np.ndarray,
    level: float = TAIL_LEVEL,
    confidence: float | None = 0.95,
    eta: float | None = None,
) -> tuple[float, float]:
    """The quantile ratio and the tail factor of one sample of zero-mean coefficients.

    Parameters
    ----------
    w : ndarray
        Coefficients (one scale's Haar coefficients, or any zero-mean sample).
    level : float
        Two-sided level in (0, 1): the ``level`` quantile of ``|w|`` against the Gaussian's.
    confidence : float or None
        The lower ``confidence`` limit of that quantile (None: the point estimate).
    eta : float, optional
        The number of independent values in ``w`` (default ``w.size``): the binomial count
        of the lower limit.

    Returns
    -------
    ratio, factor : float
        ``q / (z rms)`` (1 for Gaussian data) and ``max(1, ratio^2)``.
    """
    a = np.abs(np.asarray(w, float))
    if a.size < 2:
        raise ValueError(f"quantile_factor needs at least 2 values, got {a.size}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if confidence is not None and not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1) or None, got {confidence!r}")
    n = max(int(eta if eta is not None else a.size), 1)
    k = None if confidence is None else int(_lower_ranks([n], level, confidence)[0])
    return _ratio_factor(a, level, None if k is None else (k, n))


def _lower_ranks(n: Sequence[int], level: float, confidence: float) -> np.ndarray:
    """Per count ``n`` of independent values, the largest ``k`` with ``P(Binomial(n, level)
    >= k) >= confidence``: the ``k``-th of ``n`` independent values is below the true
    ``level`` quantile with that probability; never the largest (``k <= n - 1``: the maximum
    of overlapping coefficients exceeds the maximum of the ``n`` independent ones it stands
    for). One vectorised call for all the scales of a channel."""
    from scipy.stats import binom

    nn = np.asarray(n, dtype=np.int64)
    return np.minimum(binom.ppf(1.0 - confidence, nn, level).astype(np.int64), nn - 1)


def _ratio_factor(
    a: np.ndarray, level: float, rank: tuple[int, int] | None, sq: np.ndarray | None = None
) -> tuple[float, float]:
    """:func:`quantile_factor` of the absolute values ``a`` (overwritten: partitioned in
    place), at the ``level`` quantile (``rank`` None) or the ``k / n`` one (``rank = (k,
    n)``); the quantile as ``np.quantile``'s default (linear) method gives it. ``sq``: a
    scratch array of at least ``a.size`` values for the squares (none allocated)."""
    rms = math.sqrt(float(np.mean(np.multiply(a, a, out=None if sq is None else sq[: a.size]))))
    if not rms > 0:
        return math.nan, 1.0
    p = level
    if rank is not None:
        k, n = rank
        if k < 1:
            return 0.0, 1.0  # too few values to show anything at this level
        p = k / n
    v = p * (a.size - 1)
    lo = int(math.floor(v))
    hi = min(lo + 1, a.size - 1)
    a.partition(lo)  # one order statistic (partitioning at two is 6x slower); the next one
    # is the least of those above it
    x0 = float(a[lo])
    x1 = float(np.min(a[lo + 1 :])) if hi > lo else x0
    g = v - lo
    q = x1 - (x1 - x0) * (1.0 - g) if g >= 0.5 else x0 + (x1 - x0) * g
    ratio = q / (_gauss_quantile(level) * rms)
    return ratio, max(1.0, ratio * ratio)


@dataclass(frozen=True, eq=False)
class TailFactors:
    """Tail factors of one channel per dyadic scale (:func:`tail_factors`).

    Attributes
    ----------
    tau_samples : ndarray of float
        Scales ``2^j`` (log samples).
    ratio : ndarray
        ``q_j / (z rms_j)`` per scale (module docstring; 1 for Gaussian coefficients).
    factor : ndarray
        ``max(1, ratio^2)``: the factor on the data bound's variance at that scale.
    fs : float
        Sampling rate (Hz) of the signal.
    level : float
    confidence : float or None
    channel : str
        The channel's name (messages).
    """

    tau_samples: np.ndarray
    ratio: np.ndarray
    factor: np.ndarray
    fs: float
    level: float = TAIL_LEVEL
    confidence: float | None = 0.95
    channel: str = field(default="")

    def at(self, tau: Any, lo_s: float = 0.0, hi_s: float = math.inf) -> np.ndarray:
        """The factor at scales ``tau`` (log samples): the scale's own at a dyadic scale of
        this object within ``lo_s .. hi_s`` (s; :func:`tail_band`), 1 elsewhere."""
        t = np.asarray(tau, float)
        out = np.ones_like(t)
        i = np.clip(np.searchsorted(self.tau_samples, t), 0, self.tau_samples.size - 1)
        ts = t / self.fs
        hit = (
            np.isclose(self.tau_samples[i], t, rtol=1e-9, atol=0.0)
            & (ts >= lo_s * (1 - 1e-9))
            & (ts <= hi_s * (1 + 1e-9))
        )
        out[hit] = self.factor[i[hit]]
        return out

    def largest(self, lo_s: float = 0.0, hi_s: float = math.inf) -> tuple[float, float]:
        """The largest factor over the scales ``lo_s .. hi_s`` (s) and its scale (s); ``(1,
        nan)`` when none exceeds 1."""
        t = self.tau_samples / self.fs
        ok = (t >= lo_s * (1 - 1e-9)) & (t <= hi_s * (1 + 1e-9)) & (self.factor > 1.0)
        if not np.any(ok):
            return 1.0, math.nan
        j = int(np.flatnonzero(ok)[np.argmax(self.factor[ok])])
        return float(self.factor[j]), float(t[j])


def tail_factors(
    x: Any,
    *,
    fs: float = 1.0,
    level: float = TAIL_LEVEL,
    confidence: float | None = 0.95,
    levels: int | None = None,
    channel: str = "",
    segments: Sequence[tuple[int, int]] = (),
) -> TailFactors:
    """Per dyadic scale, the least factor on the variance whose Gaussian ``level`` quantile
    covers the data's (module docstring).

    Parameters
    ----------
    x : array_like
        One channel's signal (its mean is removed).
    fs : float
        Sampling rate (Hz).
    level : float
        Two-sided level of the quantile (default :data:`TAIL_LEVEL`).
    confidence : float or None
        The quantile's lower confidence limit (default 0.95) or, None, its point estimate.
    levels : int, optional
        Number of scales (default ``floor(log2(N - 1))``, docs/conventions.md).
    channel : str
        Its name, for messages.
    segments : sequence of (start, stop), optional
        Sample ranges to use (the still parts of a flight, :attr:`engine.io.ImuLog.segments`):
        each scale's coefficients are pooled over the ranges, as the segmented WV pools them,
        and no coefficient spans two ranges. Default: the whole signal.

    Returns
    -------
    TailFactors

    Notes
    -----
    At scale ``2^j`` every ``max(1, 2^j / 8)``-th coefficient is used
    (:func:`engine.wv.sampled_haar_coefficients`: the coefficients ``2^j`` apart are the
    independent ones; 8 per such span keep the quantile's precision): ``O(N)`` for all
    scales, about 0.1 s of CPU for a 10^6-sample channel.

    Examples
    --------
    Gaussian white noise: no scale asks for more variance than its WV.

    >>> import numpy as np
    >>> x = np.random.default_rng(0).normal(size=2**14)
    >>> float(tail_factors(x, fs=100.0).factor.max())
    1.0
    """
    a = as_series(x)
    parts = [a[s:e] for s, e in segments] if segments else [a]
    n = max(p.size for p in parts)
    if n < 3:
        raise ValueError(f"tail_factors needs at least 3 samples (in one segment), got {n}")
    parts = [p for p in parts if p.size >= 3]
    big = int(math.floor(math.log2(n - 1)))
    nl = big if levels is None else int(levels)
    if not 1 <= nl <= big:
        raise ValueError(f"levels must be in 1..{big} for {n} samples, got {levels!r}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if confidence is not None and not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1) or None, got {confidence!r}")
    # one level at a time, each part's coefficients in a buffer of its own that the next
    # level overwrites (their absolute values are partitioned in place), the squares in one
    # scratch array: no allocation of N values per level
    tops = [min(nl, int(math.floor(math.log2(p.size - 1)))) for p in parts]
    coefs = [
        iter_sampled_haar_coefficients(p, top, per_scale=8, reuse=True)
        for p, top in zip(parts, tops, strict=True)
    ]
    sq = np.empty(sum(p.size for p in parts))
    taus = [float(1 << j) for j in range(1, nl + 1)]
    etas = [max(int(max(sum(max((p.size - t + 1) / t, 0.0) for p in parts), 1.0)), 1) for t in taus]
    ks = None if confidence is None else _lower_ranks(etas, level, confidence).tolist()
    ratios, factors = [], []
    for j in range(1, nl + 1):
        cs = [next(c) for c, top in zip(coefs, tops, strict=True) if top >= j]
        a = cs[0] if len(cs) == 1 else np.concatenate(cs)
        np.abs(a, out=a)
        if a.size < 2:
            raise ValueError(f"quantile_factor needs at least 2 values, got {a.size}")
        ratio, f = _ratio_factor(a, level, None if ks is None else (ks[j - 1], etas[j - 1]), sq)
        ratios.append(ratio)
        factors.append(f)
    return TailFactors(
        np.array(taus),
        np.array(ratios),
        np.array(factors),
        float(fs),
        float(level),
        confidence,
        channel,
    )


#: The tail factors of each loaded log's channels, computed once per log and channel (a log is
#: immutable): the export menu's preview and its downloads, and the three Gauss-Markov-bias
#: formats of one session, share them.
_LOG_TAILS: weakref.WeakKeyDictionary[ImuLog, dict[str, TailFactors]] = weakref.WeakKeyDictionary()


def log_tail_factors(log: ImuLog, channels: Iterable[str]) -> dict[str, TailFactors]:
    """:func:`tail_factors` (default level and confidence) of the ``channels`` of ``log``
    that it holds: what :func:`engine.export` applies to a filter file's data bound when it is
    given the log. Each channel's are computed once per log (kept while the log lives)."""
    names = set(log.names)
    kept = _LOG_TAILS.setdefault(log, {})
    out = {}
    for ch in channels:
        if ch not in names:
            continue
        if ch not in kept:
            kept[ch] = tail_factors(log[ch], fs=float(log.fs), channel=ch, segments=log.segments)
        out[ch] = kept[ch]
    return out
