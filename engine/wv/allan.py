"""Overlapping Allan variance and deviation with intervals (for comparison and teaching).

With ``m`` the averaging time in samples and ``S`` the cumulative sum of the de-meaned series,
``AVAR(m) = sum_t (S_{t+2m} - 2 S_{t+m} + S_t)^2 / (2 m^2 (N - 2m + 1))``, which is exactly
twice the Haar wavelet variance at scale ``tau = 2m``
(``docs/conventions.md``: ``nu2_j = AVAR(2^(j-1))/2``).
The divisor counts the ``N - 2m + 1`` terms actually summed (the R ``avar`` package sums one
term fewer than its divisor counts; that defect is not reproduced).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from .._jsonutil import JsonFields, columns_table, interval_columns
from ._kernel import as_series, check_fs_alpha, cumsum_demeaned, second_difference_sums
from .classical import SeriesSettings, WaveletVariance, default_levels, eta3_interval

__all__ = ["AllanVariance", "allan_variance"]


# -------------------------------------------------------------------------------------------
# Allan variance
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class AllanVariance(SeriesSettings, JsonFields):
    """Overlapping Allan variance of one series, with its ``1 - alpha`` interval.

    Attributes
    ----------
    tau_samples : ndarray of int, shape (K,)
        Averaging times ``m`` in samples (increasing).
    avar, ci_low, ci_high : ndarray of float, shape (K,)
        Allan variance and its interval, in (signal unit)^2.
    n_terms : ndarray of int, shape (K,)
        Number of overlapping differences summed, ``N - 2m + 1``.
    interval : str
        ``"chi2"`` (chi-square, Percival's eta3 degrees of freedom) or ``"rel"`` (the
        ``1/sqrt(2 (N/m - 1))`` relative error of the inertial-sensor literature).
    unit : str
        Signal unit (the AVAR is in unit^2).

    ``n``, ``fs`` and ``alpha`` are :class:`~engine.wv.classical.SeriesSettings`'s.
    """

    tau_samples: np.ndarray
    avar: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    n_terms: np.ndarray
    interval: str = "chi2"
    unit: str = ""

    json_fields = (
        "n fs tau_samples tau_s avar adev ci_low ci_high adev_low adev_high n_terms alpha "
        "interval unit"
    )

    @property
    def tau_s(self) -> np.ndarray:
        """Averaging times in seconds, ``m / fs``."""
        return self.tau_samples / self.fs

    @property
    def adev(self) -> np.ndarray:
        """Allan deviation ``sqrt(avar)`` [unit]."""
        return np.sqrt(self.avar)

    @property
    def adev_low(self) -> np.ndarray:
        """Lower end of the Allan deviation interval."""
        return np.sqrt(self.ci_low)

    @property
    def adev_high(self) -> np.ndarray:
        """Upper end of the Allan deviation interval."""
        return np.sqrt(self.ci_high)

    @property
    def wv_tau_samples(self) -> np.ndarray:
        """The Haar WV scales that match these averaging times, ``tau = 2 m`` samples."""
        return 2 * self.tau_samples

    def __len__(self) -> int:
        return int(self.tau_samples.size)

    @classmethod
    def from_wv(cls, wv: WaveletVariance) -> AllanVariance:
        """The octave Allan variance implied by a classical Haar WV: ``AVAR(2^(j-1)) = 2 nu2_j``.

        Exact (no recomputation); the interval is twice the WV's eta3 interval, which is what
        :func:`allan_variance` gives with ``interval="chi2"``.
        """
        if wv.robust:
            raise ValueError("a robust WV is not an Allan variance; use wv.classical")
        return cls(
            tau_samples=(wv.tau_samples // 2).astype(np.int64),
            avar=2.0 * wv.variance,
            ci_low=2.0 * wv.ci_low,
            ci_high=2.0 * wv.ci_high,
            n_terms=np.asarray(wv.n_coef, dtype=np.int64),
            n=int(wv.n),
            fs=float(wv.fs),
            alpha=float(wv.alpha),
            interval="chi2",
            unit=wv.unit,
        )

    def to_wv(self) -> WaveletVariance:
        """The Haar WV at scales ``2m`` (``nu2 = AVAR / 2``); needs octave averaging times."""
        lv = np.log2(self.tau_samples.astype(float)) + 1
        if self.tau_samples[0] != 1 or not np.allclose(lv, np.arange(1, lv.size + 1)):
            raise ValueError("only octave averaging times 1, 2, 4, ... map to WV levels 1..J")
        return WaveletVariance.from_arrays(
            self.avar / 2.0,
            n=self.n,
            fs=self.fs,
            ci_low=self.ci_low / 2.0,
            ci_high=self.ci_high / 2.0,
            alpha=self.alpha,
            unit=self.unit,
        )

    def table(self) -> str:
        """Readable table with units."""
        return columns_table(
            f"Overlapping Allan deviation; N = {self.n} samples, fs = {self.fs:g} Hz, "
            f"{100 * (1 - self.alpha):g}% interval: {self.interval}",
            [
                ("m [samples]", ">12d", self.tau_samples),
                ("tau [s]", ">12.5g", self.tau_s),
                (f"ADEV [{self.unit or 'u'}]", ">16.6e", self.adev),
                *interval_columns(self.alpha, self.adev_low, self.adev_high),
                ("terms", ">10d", self.n_terms),
            ],
        )


def _octave_taus(n: int) -> np.ndarray:
    return 2 ** np.arange(default_levels(n), dtype=np.int64)


def _decade_taus(n: int) -> np.ndarray:
    """1, 2, 4, 10, 20, 40, 100, ... up to ``(N - 1) / 2`` (allantools' ``"decade"``)."""
    out = []
    k = 0
    mmax = (n - 1) // 2
    while True:
        row = [v * 10**k for v in (1, 2, 4) if v * 10**k <= mmax]
        if not row:
            break
        out += row
        k += 1
    return np.asarray(out, dtype=np.int64)


def allan_variance(
    x: Any,
    *,
    fs: float = 1.0,
    taus: str | Sequence[int] | np.ndarray | None = None,
    alpha: float = 0.05,
    interval: str = "chi2",
    unit: str = "",
) -> AllanVariance:
    """Overlapping Allan variance and deviation with intervals.

    Parameters
    ----------
    x : array_like, shape (N,)
        One channel (rate or acceleration samples), ``N >= 4``. The mean is removed before the
        cumulative sum (it does not change the AVAR, and it keeps the digits).
    fs : float
        Sampling frequency (Hz).
    taus : None, "octave", "decade" or array_like of int
        Averaging times in **samples**: ``None``/``"octave"`` gives ``1, 2, 4, ...,
        2^(J-1)`` with ``J = floor(log2(N - 1))`` (the WV levels); ``"decade"`` gives
        ``1, 2, 4, 10, 20, 40, ...``; an array gives those averaging times (positive integers,
        each at most ``(N - 1) / 2``), returned sorted and without duplicates.
    alpha : float
        Interval level ``1 - alpha``.
    interval : {"chi2", "rel"}
        ``"chi2"``: ``[eta AVAR / chi2_{1-a/2}(eta), eta AVAR / chi2_{a/2}(eta)]`` with
        Percival's ``eta = max((N - 2m + 1) / (2m), 1)`` degrees of freedom, so that the AVAR
        interval is exactly twice the WV's. ``"rel"``: the Allan *deviation* interval
        ``ADEV (1 -/+ z_{1-a/2} / sqrt(2 (N/m - 1)))`` used in IEEE Std 952 and the
        ``avar`` package (a normal approximation; its lower end is floored at 1e-3 ADEV).
    unit : str
        Signal unit, carried for display.

    Returns
    -------
    AllanVariance

    Notes
    -----
    ``AVAR(m) = sum_t (S_{t+2m} - 2 S_{t+m} + S_t)^2 / (2 m^2 (N - 2m + 1))`` with ``S`` the
    cumulative sum (leading 0) of the de-meaned series: O(N) per averaging time, one float64
    copy of the series as extra memory. At octave averaging times it equals ``2 x`` the Haar
    WV of :func:`engine.wavelet_variance` (to rounding; the sums are the same).

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = np.random.default_rng(0).normal(0.0, 0.1, 2**12)
    >>> av = eg.allan_variance(x, fs=100.0)
    >>> print(f"{av.tau_s[0]:.2f} s: {av.avar[0]:.2e}")  # sigma2 / m at m = 1 sample
    0.01 s: 9.99e-03
    """
    a = as_series(x)
    n = a.size
    check_fs_alpha(fs, alpha)
    if interval not in ("chi2", "rel"):
        raise ValueError(f"interval must be 'chi2' or 'rel', got {interval!r}")
    mmax = (n - 1) // 2
    if taus is None or (isinstance(taus, str) and taus == "octave"):
        ms = _octave_taus(n)
    elif isinstance(taus, str):
        if taus != "decade":
            raise ValueError(
                f"taus={taus!r}: use None, 'octave', 'decade' or an array of "
                "averaging times in samples"
            )
        ms = _decade_taus(n)
    else:
        t = np.asarray(taus)
        if t.ndim != 1 or t.size == 0:
            raise ValueError("taus must be a non-empty 1-D array of averaging times in samples")
        if t.dtype.kind == "f":
            if not np.all(np.isfinite(t)) or np.any(t != np.round(t)):
                raise ValueError(
                    f"taus are averaging times in samples and must be integers, "
                    f"got {t[np.flatnonzero(t != np.round(t))[0]]!r}"
                )
        elif t.dtype.kind not in "iu":
            raise ValueError(f"taus must be integers (samples), got dtype {t.dtype}")
        ms = np.unique(t.astype(np.int64))
        if ms[0] < 1 or ms[-1] > mmax:
            bad = ms[0] if ms[0] < 1 else ms[-1]
            raise ValueError(
                f"averaging time {bad} samples is out of range: a series of {n} "
                f"samples supports 1 to {mmax}"
            )
    s = cumsum_demeaned(a)
    sums = second_difference_sums(s, n, ms)
    terms = n - 2 * ms + 1
    m_f = ms.astype(float)
    avar = sums / (2.0 * m_f**2 * terms)
    if interval == "chi2":
        lo, hi = eta3_interval(avar, terms, 2 * ms, alpha)
    else:
        z = float(special.ndtri(1 - alpha / 2))
        rel = 1.0 / np.sqrt(2.0 * (n / m_f - 1.0))
        adev = np.sqrt(avar)
        lo = (adev * np.maximum(1.0 - z * rel, 1e-3)) ** 2
        hi = (adev * (1.0 + z * rel)) ** 2
    return AllanVariance(
        tau_samples=ms,
        avar=avar,
        ci_low=lo,
        ci_high=hi,
        n_terms=terms,
        n=int(n),
        fs=float(fs),
        alpha=float(alpha),
        interval=interval,
        unit=unit,
    )
