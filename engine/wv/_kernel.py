"""The Haar WV kernel shared by the classical and robust WV, the Allan variance and the WCCV.

Input checks of a series (:func:`as_series`) and of ``fs``/``alpha``
(:func:`check_fs_alpha`), the de-meaned cumulative sum ``S`` with a leading 0
(:func:`cumsum_demeaned`), and the cache-blocked sums of squared second differences
``sum_t (S_t - 2 S_{t-m} + S_{t-2m})^2`` (:func:`second_difference_sums`), whose dot products
go through :func:`sumsq_kernel` (see :mod:`engine._blas`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .._blas import blas_threads
from .._checks import check_fs

__all__ = [
    "as_series",
    "check_fs_alpha",
    "cumsum_demeaned",
    "haar_from_cumsum",
    "second_difference_sums",
    "sumsq_kernel",
]

# Block length (samples) of the cache-blocked classical WV.  Every level of a block reads the
# regions S[a-2^k : b-2^k], k = 0..J, which are shared between consecutive levels, so a block
# of this size keeps all of them in the CPU cache.
_BLOCK = 1 << 15
# Values of one level per block of haar_from_cumsum (its output and the three reads in cache).
_HAAR_BLOCK = 1 << 16


def as_series(x: Any) -> np.ndarray:
    """One channel as a 1-D numeric array, checked for a wavelet variance.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, 1) or (1, N)
        Numeric samples (integer, boolean or float), ``N >= 4``, all finite.

    Returns
    -------
    ndarray, shape (N,)
        ``x`` as an array (no copy when it already is one; the dtype is kept).

    Raises
    ------
    TypeError
        Non-numeric data.
    ValueError
        Not one-dimensional, fewer than 4 samples, or NaN/Inf samples (the first is named).
    """
    a = np.asarray(x)
    if a.dtype.kind not in "fiu" and a.dtype != bool:
        raise TypeError(f"the series must be numeric, got dtype {a.dtype}")
    a = np.ravel(a) if a.ndim > 1 and 1 in a.shape else a
    if a.ndim != 1:
        raise ValueError(f"the series must be one-dimensional, got shape {a.shape}")
    if a.size < 4:
        raise ValueError(f"the series has {a.size} samples; a wavelet variance needs at least 4")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        bad = np.flatnonzero(~np.isfinite(a))
        raise ValueError(
            f"the series contains {bad.size} NaN/Inf value(s), first at sample {bad[0]}; "
            "remove or interpolate them first"
        )
    return a


def check_fs_alpha(fs: float, alpha: float) -> None:
    """Raise ValueError unless ``fs`` is a positive number of Hz and ``0 < alpha < 1``.

    Parameters
    ----------
    fs, alpha : float
        Sampling frequency (Hz) and interval level ``1 - alpha``.
    """
    check_fs(fs)
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")


def haar_from_cumsum(
    s: np.ndarray,
    m: int,
    at: np.ndarray | None = None,
    *,
    step: int = 1,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Haar MODWT coefficients of the level with half-width ``m = 2^(j-1)`` from the cumulative
    sum ``s`` (length ``N + 1``) of the de-meaned series: ``W_{j,t} = (S_{t+2m} - 2 S_{t+m} +
    S_t) / 2^j``, for every ``step``-th ``t`` from 0 (``(N - 2m) // step + 1`` values) or only
    at the offsets ``at``.

    The one Haar-coefficient formula of the package (classical and robust WV, V from data,
    the export's tail factors). Without ``at`` the values are written into ``out`` when given
    (a float64 array of that length: no allocation), each operation in the order of the
    formula, so they are the same to the last bit as an evaluation with temporaries.
    """
    if at is not None:
        return (s[at + 2 * m] - 2.0 * s[at + m] + s[at]) / (2.0 * m)
    cnt = (s.size - 1 - 2 * m) // step + 1
    w = np.empty(cnt) if out is None else out
    # in blocks of _HAAR_BLOCK values, so that the four passes over a block stay in cache
    for i in range(0, cnt, _HAAR_BLOCK):
        e = min(i + _HAAR_BLOCK, cnt)
        b, lo, hi = w[i:e], i * step, (e - 1) * step + 1
        np.multiply(s[m + lo : m + hi : step], 2.0, out=b)
        np.subtract(s[2 * m + lo : 2 * m + hi : step], b, out=b)
        np.add(b, s[lo:hi:step], out=b)
        np.divide(b, 2.0 * m, out=b)
    return w


def cumsum_demeaned(x: np.ndarray) -> np.ndarray:
    """Cumulative sum of ``x - mean(x)`` in float64, with a leading 0 (length N + 1).

    The mean is removed before summing (docs/conventions.md: a cumulative sum of a series with an
    offset loses digits on long logs).  Two passes, one float64 array of extra memory.
    """
    s = np.empty(x.size + 1, dtype=np.float64)
    s[0] = 0.0
    np.subtract(x, np.mean(x, dtype=np.float64), out=s[1:], dtype=np.float64)
    np.cumsum(s[1:], out=s[1:])
    return s


_DOT_CHUNK = 8192  # OpenBLAS computes a dot product of <= 10,000 elements in the caller


def _chunked_sumsq(a: np.ndarray, b: np.ndarray) -> float:
    """``a @ b`` in chunks small enough that a multi-threaded BLAS keeps them in this thread."""
    total = 0.0
    for i in range(0, a.size, _DOT_CHUNK):
        total += float(np.dot(a[i : i + _DOT_CHUNK], b[i : i + _DOT_CHUNK]))
    return total


def sumsq_kernel() -> Callable[[np.ndarray, np.ndarray], float]:
    """The dot product for sums of squares of long vectors: BLAS dot, whole when the BLAS pool
    has one thread, otherwise in chunks that a multi-threaded OpenBLAS keeps in the calling
    thread (split over its threads, this small product is slower, and 4-30x slower as soon as
    anything else keeps a core busy; see engine._blas)."""
    return np.dot if blas_threads() == 1 else _chunked_sumsq


def second_difference_sums(s: np.ndarray, n: int, ms: np.ndarray) -> np.ndarray:
    """``sum_t (S_t - 2 S_{t-m} + S_{t-2m})^2`` over ``t = 2m..n`` for increasing ``ms``.

    ``s`` is the cumulative sum with a leading 0 (:func:`cumsum_demeaned`). Loops over
    cache-sized blocks of t with every m inside a block, so that the regions of ``s`` that
    consecutive m share stay in cache; the WV's level sums (m = 2^(j-1)) and the Allan
    variance's (any m) both use it.
    """
    sums = np.zeros(len(ms))
    buf = np.empty(_BLOCK)
    # the per-block sum of squares by BLAS dot (3x faster than einsum), see sumsq_kernel
    sumsq = sumsq_kernel()
    for a in range(2, n + 1, _BLOCK):
        b = min(a + _BLOCK, n + 1)
        for i, m in enumerate(ms):
            m = int(m)
            lo = max(a, 2 * m)
            if lo >= b:
                break  # larger m start even later
            d = buf[: b - lo]
            np.multiply(s[lo - m : b - m], -2.0, out=d)
            d += s[lo:b]
            d += s[lo - 2 * m : b - 2 * m]
            sums[i] += sumsq(d, d)
    return sums
