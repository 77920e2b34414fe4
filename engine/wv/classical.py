"""Haar MODWT wavelet variance (WV) with intervals: classical, or robust (biweight per level).

The kernel (checks, cumulative sum, block sums) is :mod:`engine.wv._kernel`; the biweight
scale estimator of the robust WV is :mod:`engine.wv.robust`.

Conventions (see ``docs/conventions.md``): level ``j = 1..J``, scale ``tau_j = 2^j`` samples,
``M_j = N - 2^j + 1`` boundary-free coefficients,

    W_{j,t} = (sum of the latest 2^(j-1) samples - sum of the 2^(j-1) before them) / 2^j,

and the WV ``nu2_j = mean_t W_{j,t}^2``. With ``S`` the cumulative sum of the de-meaned series
and ``m = 2^(j-1)``, ``W_{j,t} = (S_t - 2 S_{t-m} + S_{t-2m}) / 2^j``.

Reference: Percival & Walden (2000), *Wavelet Methods for Time Series Analysis*, ch. 8;
Guerrier et al. (2020), the GMWM paper, section II.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any, TypedDict, overload

import numpy as np

from .._checks import check_fs
from .._jsonutil import JsonFields, columns_table, interval_columns
from .._optim import chi2_isf
from ..units import squared
from ._kernel import (
    as_series,
    check_fs_alpha,
    cumsum_demeaned,
    haar_from_cumsum,
    second_difference_sums,
)
from .robust import biweight_constant, robust_wv

__all__ = [
    "WaveletVariance",
    "wavelet_variance",
    "default_levels",
    "max_levels",
    "haar_coefficients",
    "sampled_haar_coefficients",
    "iter_sampled_haar_coefficients",
    "eta3_interval",
    "LevelScales",
    "SeriesSettings",
    "level_grid",
    "axis_columns",
]


def default_levels(n: int) -> int:
    """Default number of levels ``J = floor(log2(N - 1))``: the largest J with ``M_J >= 2``.

    Parameters
    ----------
    n : int
        Series length (samples), at least 3.
    """
    return _log2_levels(n, 3, n - 1)


def max_levels(n: int) -> int:
    """Largest number of levels a WV of ``n`` samples accepts: ``floor(log2(N))``, R's count.

    It exceeds :func:`default_levels` only when N is a power of two; the last level then has a
    single coefficient (``M_J = 1``): its WV is that coefficient squared (the robust WV too),
    with ``eta_J = 1`` degree of freedom, so its interval spans a factor of about 5,100
    (``[nu / 5.02, nu / 0.00098]`` at 95 %).

    Parameters
    ----------
    n : int
        Series length (samples), at least 2.
    """
    return _log2_levels(n, 2, n)


def _log2_levels(n: int, least: int, m: int) -> int:
    """``floor(log2(m))`` (exact, integer) for a series of ``n >= least`` samples."""
    if n < least:
        raise ValueError(f"a series of {n} samples is too short for a wavelet variance (need >= 4)")
    return int(m).bit_length() - 1


class LevelGrid(TypedDict):
    """The per-level axes of :func:`level_grid` (keyword arguments of the results)."""

    levels: np.ndarray
    tau_samples: np.ndarray
    n_coef: np.ndarray


def level_grid(n: int, levels: int) -> LevelGrid:
    """The per-level axes of a result of ``levels`` levels over ``n`` samples.

    Returns
    -------
    dict
        ``levels`` (1..J), ``tau_samples`` (``2^j``) and ``n_coef`` (``M_j = N - 2^j + 1``,
        at least 0), as keyword arguments of the results' constructors.
    """
    lv = np.arange(1, levels + 1)
    tau = 2**lv
    return LevelGrid(levels=lv, tau_samples=tau, n_coef=np.maximum(n - tau + 1, 0))


@dataclass(frozen=True, eq=False, kw_only=True)
class SeriesSettings:
    """The length, rate and interval level an interval result carries (keyword-only fields;
    the Allan variance, the WCCV and the WV matrix).

    Attributes
    ----------
    n, fs, alpha : int, float, float
        Series length (samples), sampling frequency (Hz), interval level ``1 - alpha``.
    """

    n: int
    fs: float = 1.0
    alpha: float = 0.05


class LevelScales:
    """``tau_s``, ``n_levels`` and ``len`` of a per-level result with ``levels``,
    ``tau_samples`` (2^j) and ``fs`` attributes (the WV, the WCCV and the WV matrix)."""

    levels: np.ndarray
    tau_samples: np.ndarray
    fs: float

    @property
    def tau_s(self) -> np.ndarray:
        """Scales in seconds, ``2^j / fs``."""
        return self.tau_samples / self.fs

    @property
    def n_levels(self) -> int:
        """Number of levels J."""
        return int(self.levels.size)

    def __len__(self) -> int:
        return self.n_levels


@dataclass(frozen=True, eq=False)
class WaveletVariance(LevelScales, JsonFields):
    """Empirical Haar wavelet variance of one series, with its intervals.

    Attributes
    ----------
    levels : ndarray of int, shape (J,)
        Levels ``1..J``.
    tau_samples : ndarray of int, shape (J,)
        Scales ``2^j`` in samples.
    variance, ci_low, ci_high : ndarray of float, shape (J,)
        WV and its ``1 - alpha`` interval, in (signal unit)^2.
    n_coef : ndarray of int, shape (J,)
        Boundary-free coefficients ``M_j`` per level.
    n : int
        Series length (samples).
    fs : float
        Sampling frequency (Hz).
    robust, eff, alpha
        Settings: robust (Tukey biweight) or classical, its Gaussian efficiency, interval level.
    unit : str
        Signal unit (the WV is in unit^2); empty when unknown.
    classical : WaveletVariance or None
        For a robust WV, the classical one of the same series (for side-by-side views).
    """

    levels: np.ndarray
    tau_samples: np.ndarray
    variance: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    n_coef: np.ndarray
    n: int
    fs: float = 1.0
    robust: bool = False
    eff: float = 0.6
    alpha: float = 0.05
    unit: str = ""
    classical: WaveletVariance | None = field(default=None, repr=False)

    #: the per-level arrays (what :meth:`truncate` slices)
    _PER_LEVEL = ("levels", "tau_samples", "variance", "ci_low", "ci_high", "n_coef")
    #: the ``to_dict()`` keys: the ``gmwm wv --json`` object
    json_fields = (
        "n fs levels tau_samples tau_s variance ci_low ci_high n_coef robust eff alpha unit"
    )

    def truncate(self, levels: int) -> WaveletVariance:
        """The first ``levels`` levels of this WV (no recomputation)."""
        if not 1 <= levels <= self.n_levels:
            raise ValueError(f"levels must be between 1 and {self.n_levels}, got {levels}")
        s = slice(0, levels)
        classical = None if self.classical is None else self.classical.truncate(levels)
        return replace(
            self, classical=classical, **{f: getattr(self, f)[s] for f in self._PER_LEVEL}
        )

    def with_fs(self, fs: float) -> WaveletVariance:
        """The same WV at another sampling frequency ``fs`` (Hz), without recomputation.

        The variances, intervals and sample scales do not depend on ``fs``; only the scales
        in seconds (:attr:`tau_s`) do. The classical companion of a robust WV is re-tagged too.

        Parameters
        ----------
        fs : float
            The new sampling frequency, > 0.

        Returns
        -------
        WaveletVariance
            A new WV; this one is unchanged.
        """
        fs = check_fs(fs)
        classical = None if self.classical is None else self.classical.with_fs(fs)
        return replace(self, fs=fs, classical=classical)

    def table(self) -> str:
        """Readable table with units."""
        kind = f"robust (biweight, eff={self.eff:g})" if self.robust else "classical"
        return columns_table(
            f"Haar wavelet variance, {kind}; N = {self.n} samples, fs = {self.fs:g} Hz",
            [
                ("level", ">5d", self.levels),
                ("tau [samples]", ">14d", self.tau_samples),
                ("tau [s]", ">12.5g", self.tau_s),
                (f"WV [{squared(self.unit)}]", ">16.6e", self.variance),
                *interval_columns(self.alpha, self.ci_low, self.ci_high),
                ("M_j", ">10d", self.n_coef),
            ],
        )

    @classmethod
    def from_sums(
        cls,
        sums: np.ndarray,
        n: int,
        *,
        fs: float,
        alpha: float = 0.05,
        eff: float = 0.6,
        unit: str = "",
    ) -> WaveletVariance:
        """The classical WV of levels ``1..len(sums)`` from the per-level sums of squares
        ``sums[j-1] = sum_t (S_t - 2 S_{t-m} + S_{t-2m})^2`` (``m = 2^(j-1)``, ``S`` the
        cumulative sum of the de-meaned series of ``n`` samples): ``nu_j = sums / (4^j M_j)``
        with its eta3 interval. Shared by the in-memory and the streamed WV."""
        tau = 2.0 ** np.arange(1, len(sums) + 1)
        nu = np.asarray(sums, dtype=float) / (tau**2 * (n - tau + 1))
        return cls.from_arrays(nu, n=n, fs=fs, alpha=alpha, eff=eff, unit=unit)

    @classmethod
    def from_arrays(
        cls,
        variance: np.ndarray,
        *,
        n: int,
        fs: float = 1.0,
        ci_low: np.ndarray | None = None,
        ci_high: np.ndarray | None = None,
        alpha: float = 0.05,
        robust: bool = False,
        eff: float = 0.6,
        unit: str = "",
    ) -> WaveletVariance:
        """Build a WV from stored numbers (e.g. a summary file); missing intervals are eta3.

        Parameters
        ----------
        variance : array_like, shape (J,)
            WV at levels 1..J.
        n : int
            Length of the series it was computed from (samples); gives ``M_j``.
        """
        v = np.asarray(variance, dtype=float)
        if v.ndim != 1 or v.size == 0:
            raise ValueError("variance must be a non-empty 1-D array")
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            raise ValueError("variance must be finite and non-negative at every level")
        grid = level_grid(n, v.size)
        if ci_low is None or ci_high is None:
            ci_low, ci_high = eta3_interval(v, grid["n_coef"], grid["tau_samples"], alpha)
        return cls(
            **grid,
            variance=v,
            ci_low=np.asarray(ci_low, float),
            ci_high=np.asarray(ci_high, float),
            n=int(n),
            fs=float(fs),
            robust=robust,
            eff=eff,
            alpha=alpha,
            unit=unit,
        )


def eta3_interval(
    variance: np.ndarray, n_coef: np.ndarray, tau: np.ndarray, alpha: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """Percival's eta3 chi-square interval of a WV.

    ``eta_j = max(M_j / 2^j, 1)``, interval
    ``[eta nu2 / chi2_{1-a/2}(eta), eta nu2 / chi2_{a/2}(eta)]``.
    """
    eta = np.maximum(np.asarray(n_coef, float) / np.asarray(tau, float), 1.0)
    # chi2.ppf(p, eta) = chi2_isf(eta, 1 - p) (scipy.special.chdtri, without SciPy's import)
    lo = eta * variance / chi2_isf(eta, alpha / 2)
    hi = eta * variance / chi2_isf(eta, 1 - alpha / 2)
    return lo, hi


def _classical_sums(s: np.ndarray, n: int, levels: int) -> np.ndarray:
    """Sum over t of (S_t - 2 S_{t-m} + S_{t-2m})^2 for every level (m = 2^(j-1))."""
    return second_difference_sums(s, n, 1 << np.arange(levels))


def haar_coefficients(x: Any, level: int) -> np.ndarray:
    """Boundary-free Haar MODWT coefficients ``W_{j,t}`` of one level (length ``N - 2^j + 1``).

    The mean is removed first; the coefficients do not depend on it.
    """
    a = as_series(x)
    m = 1 << (level - 1)
    if 2 * m > a.size:
        raise ValueError(f"level {level} needs at least {2 * m} samples, the series has {a.size}")
    return haar_from_cumsum(cumsum_demeaned(a), m)


def sampled_haar_coefficients(x: Any, levels: int, per_scale: int = 8) -> list[np.ndarray]:
    """Boundary-free Haar MODWT coefficients of levels ``1 .. levels``, every
    ``max(1, 2^j // per_scale)``-th at level ``j`` (one cumulative sum for every level).

    The coefficients ``2^j`` apart are the nearly independent ones, so ``per_scale`` of them
    per such span keep the information of the whole level at ``O(N / 2^j)`` cost: what a
    statistic of a level's distribution (a quantile) needs, in ``O(N)`` for all levels.
    """
    return list(iter_sampled_haar_coefficients(x, levels, per_scale))


def iter_sampled_haar_coefficients(
    x: Any, levels: int, per_scale: int = 8, *, reuse: bool = False
) -> Iterator[np.ndarray]:
    """:func:`sampled_haar_coefficients` one level at a time (level 1 first).

    With ``reuse=True`` every level is written into one buffer of ``N - 1`` values, which
    the next level overwrites: use (or copy) each level before asking for the next one. The
    caller may overwrite it (sort it in place). For a long channel this saves an allocation
    of ``N`` values per level, and the page faults of touching it.
    """
    a = as_series(x)
    if levels < 1 or 1 << levels > a.size:
        raise ValueError(f"levels must be in 1..log2(N) = {int(np.log2(a.size))}, got {levels}")
    s = cumsum_demeaned(a)
    buf = np.empty(a.size - 1) if reuse else None
    for j in range(1, levels + 1):
        m = 1 << (j - 1)
        step = max(1, (2 * m) // per_scale)
        cnt = (a.size - 2 * m) // step + 1
        yield haar_from_cumsum(s, m, step=step, out=None if buf is None else buf[:cnt])


def axis_columns(x: Any) -> np.ndarray | None:
    """``x`` as an ``(N, k)`` array when it holds several axes (k >= 2 columns), else None.

    Raises
    ------
    ValueError
        A 2-D array with more columns than rows (``(3, N)``: one row per axis): transpose it.
    """
    if not isinstance(x, np.ndarray) and not isinstance(x, (list, tuple)):
        return None
    a = np.asarray(x)
    if a.ndim != 2 or min(a.shape) < 2:
        return None
    if a.shape[1] > a.shape[0]:
        raise ValueError(
            f"an array of shape {a.shape} has more columns than rows: give one column per "
            f"axis, shape (N, k) (transpose it: x.T)"
        )
    return a


@overload
def wavelet_variance(
    x: np.ndarray[tuple[int], Any],
    *,
    fs: float = ...,
    levels: int | None = ...,
    robust: bool = ...,
    eff: float = ...,
    alpha: float = ...,
    unit: str = ...,
    progress: Callable[[int, int], object] | None = ...,
) -> WaveletVariance: ...


@overload
def wavelet_variance(
    x: np.ndarray[tuple[int, int], Any],
    *,
    fs: float = ...,
    levels: int | None = ...,
    robust: bool = ...,
    eff: float = ...,
    alpha: float = ...,
    unit: str = ...,
    progress: Callable[[int, int], object] | None = ...,
) -> list[WaveletVariance]: ...


@overload
def wavelet_variance(
    x: Any,
    *,
    fs: float = ...,
    levels: int | None = ...,
    robust: bool = ...,
    eff: float = ...,
    alpha: float = ...,
    unit: str = ...,
    progress: Callable[[int, int], object] | None = ...,
) -> WaveletVariance: ...


def wavelet_variance(
    x: Any,
    *,
    fs: float = 1.0,
    levels: int | None = None,
    robust: bool = False,
    eff: float = 0.6,
    alpha: float = 0.05,
    unit: str = "",
    progress: Callable[[int, int], object] | None = None,
) -> WaveletVariance | list[WaveletVariance]:
    """Empirical Haar MODWT wavelet variance at levels 1..J with intervals.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, k)
        One channel, float32/float64 or integer, ``N >= 4``. The mean is removed first. An
        ``(N, k)`` array (``k >= 2`` axes, e.g. a 3-axis gyroscope) gives one WV per column,
        as a list.
    fs : float
        Sampling frequency in Hz (scales in seconds are ``2^j / fs``).
    levels : int, optional
        Number of levels J; default ``floor(log2(N - 1))`` (every level with ``M_j >= 2``).
        Up to ``floor(log2(N))`` is accepted (R's count; :func:`max_levels`): that differs
        only when N is a power of two, and then the last level has ONE coefficient, one
        degree of freedom and an interval spanning a factor of about 5,100.
    robust : bool
        Robust WV: per level, the Tukey biweight M-estimates of location ``mu_j`` and scale
        ``s_j`` of the coefficients, and ``nu_j = s_j^2 + mu_j^2`` (consistent for the
        classical WV's target ``E[W^2]`` under Gaussian noise, with or without a drift, whose
        coefficients have mean ``omega tau / 4``). On quantized logs, where many fine-level
        coefficients are tied, the robust WV is not the classical one even without outliers:
        the coefficients are not Gaussian there (see docs/calibrate.md, "Robust WV").
    eff : float
        Gaussian efficiency of the robust estimator, in (0, 0.99); 0.6 by default.
    alpha : float
        Interval level: ``1 - alpha`` (eta3 chi-square interval, widened by ``1/sqrt(eff)``
        for the robust WV, as in the R ``wv`` package).
    unit : str
        Signal unit, carried for display.
    progress : callable, optional
        Called as ``progress(j, J)`` once per level, as level j is done (for a progress bar).
        The robust WV takes seconds on long logs and calls it as it goes; the classical WV
        computes every level in one pass and makes its J calls at the end.

    Returns
    -------
    WaveletVariance, or list of WaveletVariance for an ``(N, k)`` array

    Notes
    -----
    Classical WV: one cumulative sum of the de-meaned series (float64), then for each level
    ``sum_t (S_t - 2 S_{t-m} + S_{t-2m})^2 / (4^j M_j)``, computed in cache-sized blocks:
    O(N J) flops, one float64 copy of the series as extra memory.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> x = np.random.default_rng(0).normal(0.0, 0.1, 2**12)  # white noise, sigma2 = 0.01
    >>> wv = eg.wavelet_variance(x, fs=100.0)
    >>> wv.n_levels, int(wv.tau_samples[0])
    (11, 2)
    >>> print(f"{wv.variance[0]:.2e}")  # sigma2 / tau = 0.01 / 2
    5.00e-03
    """
    cols = axis_columns(x)
    if cols is not None:  # one WV per axis
        return [
            wavelet_variance(
                np.ascontiguousarray(cols[:, k]),
                fs=fs,
                levels=levels,
                robust=robust,
                eff=eff,
                alpha=alpha,
                unit=unit,
                progress=progress,
            )
            for k in range(cols.shape[1])
        ]
    a = as_series(x)
    n = a.size
    check_fs_alpha(fs, alpha)
    jmax = max_levels(n)
    if levels is None:
        levels = default_levels(n)
    levels = int(levels)
    if levels < 1 or levels > jmax:
        raise ValueError(
            f"levels={levels} is out of range: a series of {n} samples supports 1 to {jmax} levels"
        )
    if robust and not 0 < eff < 0.99:
        raise ValueError(f"eff must be in (0, 0.99), got {eff}")
    s = cumsum_demeaned(a)
    sums = _classical_sums(s, n, levels)
    classical = WaveletVariance.from_sums(sums, n, fs=fs, alpha=alpha, eff=eff, unit=unit)
    nu, lo, hi = classical.variance, classical.ci_low, classical.ci_high
    if not robust:
        if progress is not None:
            for j in classical.levels:
                progress(int(j), levels)
        return classical
    nu_r = robust_wv(s, n, levels, biweight_constant(eff), progress)[0]
    coef = np.sqrt(1.0 / eff)
    rel_lo = (nu - lo) / np.where(nu > 0, nu, 1.0)
    rel_hi = (hi - nu) / np.where(nu > 0, nu, 1.0)
    lo_r = nu_r * (1.0 - coef * rel_lo)
    lo_r = np.where(lo_r > 0, lo_r, nu_r * 1e-3)
    hi_r = nu_r * (1.0 + coef * rel_hi)
    return replace(
        classical, variance=nu_r, ci_low=lo_r, ci_high=hi_r, robust=True, classical=classical
    )
