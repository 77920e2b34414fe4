"""The wavelet variance of several pieces of one sensor's record, pooled.

A flight log is still only part of the time (before take-off, after landing, on the bench).
The WV of the still pieces together is the mean of every piece's boundary-free squared
coefficients: at level j, ``nu2_j = sum_s M_{j,s} nu2_{j,s} / sum_s M_{j,s}`` with
``M_{j,s} = n_s - 2^j + 1`` the coefficients of piece ``s`` (a piece shorter than ``2^j``
adds nothing at level j). No coefficient spans two pieces, so the motion between them never
enters. The interval is Percival's eta3 with ``M_j = sum_s M_{j,s}``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .classical import WaveletVariance, default_levels, eta3_interval, wavelet_variance

__all__ = ["pooled_wavelet_variance"]


def pooled_wavelet_variance(
    pieces: Sequence[np.ndarray],
    *,
    fs: float = 1.0,
    levels: int | None = None,
    robust: bool = False,
    eff: float = 0.6,
    alpha: float = 0.05,
    unit: str = "",
) -> WaveletVariance:
    """The Haar WV of several pieces of one series, weighted by their coefficient counts.

    Parameters
    ----------
    pieces : sequence of 1-D arrays
        The pieces (e.g. the still segments of a flight), each of at least 4 samples.
    fs : float
        Sampling frequency (Hz).
    levels : int, optional
        Number of levels J; default :func:`default_levels` of the longest piece. A level
        needs at least one piece of ``2^j + 1`` samples.
    robust, eff, alpha, unit
        As :func:`wavelet_variance` (a robust pooled WV weights each piece's robust WV).

    Returns
    -------
    WaveletVariance
        ``n`` is the total length; ``n_coef`` the pooled ``M_j``; one piece gives exactly
        :func:`wavelet_variance` of it.

    Raises
    ------
    ValueError
        No piece, a piece of fewer than 4 samples, or more levels than the longest allows.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).normal(size=3000)
    >>> wv = pooled_wavelet_variance([x[:1000], x[2000:]], levels=5)
    >>> wv.n, wv.n_coef[0]
    (2000, 1998)
    """
    xs = [np.asarray(p, dtype=np.float64) for p in pieces]
    if not xs or any(x.ndim != 1 or x.size < 4 for x in xs):
        raise ValueError("pieces must be one or more 1-D arrays of at least 4 samples each")
    longest = max(x.size for x in xs)
    J = default_levels(longest) if levels is None else int(levels)
    if J < 1 or J > default_levels(longest):
        raise ValueError(
            f"levels={J} is outside 1..{default_levels(longest)} (the longest piece has "
            f"{longest} samples)"
        )
    tau = 2 ** np.arange(1, J + 1)
    total = np.zeros(J)
    m_all = np.zeros(J, dtype=np.int64)
    for x in xs:
        jx = min(J, default_levels(x.size))
        wv = wavelet_variance(x, fs=fs, levels=jx, robust=robust, eff=eff, alpha=alpha)
        total[:jx] += wv.variance * wv.n_coef
        m_all[:jx] += wv.n_coef
    nu = total / m_all
    lo, hi = eta3_interval(nu, m_all, tau, alpha)
    return WaveletVariance(
        levels=np.arange(1, J + 1),
        tau_samples=tau,
        variance=nu,
        ci_low=lo,
        ci_high=hi,
        n_coef=m_all,
        n=int(sum(x.size for x in xs)),
        fs=float(fs),
        robust=robust,
        eff=eff,
        alpha=alpha,
        unit=unit,
    )
