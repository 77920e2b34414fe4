"""Haar MODWT wavelet cross-covariance (WCCV) and the k x k matrix of WV and WCCV.

For two channels the unbiased lag-0 WCCV at level j is ``(1 / M_j) sum_t W^x_{j,t} W^y_{j,t}``
over the boundary-free Haar coefficients (the WV when ``x`` is ``y``); all pairs of k channels
come from one cumulative sum per channel, in cache-sized blocks. Its interval uses the
long-run variance of the product series (a lag-window estimate, Student quantile), or a
Gaussian equivalent-degrees-of-freedom approximation at the top levels; the diagonal of
:func:`wv_matrix` keeps the WV's eta3 interval. The estimator and the interval's choices:
docs/methods.md, "The wavelet cross-covariance"; the user's view: docs/multichannel.md.

References: Whitcher, Guttorp & Percival (2000), J. Geophys. Res. 105(D11) (the WCCV);
Xu, Guerrier, Molinari & Karemera, the multivariate paper, section III.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import special

from .._jsonutil import JsonFields, columns_table, interval_columns
from ..units import squared
from ._kernel import as_series, check_fs_alpha, cumsum_demeaned
from .classical import (
    LevelScales,
    SeriesSettings,
    WaveletVariance,
    default_levels,
    eta3_interval,
    level_grid,
)

__all__ = [
    "WaveletCrossCovariance",
    "WVMatrix",
    "wavelet_cross_covariance",
    "wv_matrix",
]

# samples per block (t) of the cache-blocked sums; a power of two
_BLOCK = 1 << 14
# lag window: b = _BW_FACTOR * 2^j samples, r = _R steps, bins of s = b / r = 2^(j-1)
_BW_FACTOR = 4
_R = 8
# lag-window interval only where M_j >= _MIN_BINS bins of s samples (df >= 30)
_MIN_BINS = 16 * _R
# sum_h w(h)^2 / b of the lag window (r = 8; 1.0698 at s = 1, 1.0658 for s >= 4)
_SUM_W2 = 1.0658


def _t_quantile(alpha: float, df: np.ndarray) -> np.ndarray:
    """Two-sided Student quantile ``t_{1 - alpha/2}(df)`` (normal for df > 1e6)."""
    df = np.asarray(df, dtype=float)
    q = special.stdtrit(np.minimum(df, 1e6), 1.0 - alpha / 2.0)
    return np.where(df > 1e6, special.ndtri(1.0 - alpha / 2.0), q)


@dataclass(frozen=True, eq=False, kw_only=True)
class LagWindowIntervals(SeriesSettings, LevelScales, JsonFields):
    """The per-level settings and intervals that a WCCV and a WV matrix share (keyword-only
    fields; the entries' shapes are the subclass's).

    Attributes
    ----------
    levels, tau_samples : ndarray of int, shape (J,)
        Levels ``1..J`` and scales ``2^j`` (samples).
    ci_low, ci_high, std_error
        ``1 - alpha`` interval ``nu -/+ t_{1-alpha/2}(df) std_error`` and the asymptotic
        standard error ``sqrt(sigma2_LR / M_j)`` of every entry.
    ci_method : tuple of str, length J
        ``"lag-window"`` (weighted overlapping batch means) or ``"gaussian-edf"`` per level.
    bandwidth : ndarray of int, shape (J,)
        Lag-window half-width ``2 b`` in samples (0 where the Gaussian approximation is used).
    df : ndarray, shape (J,)
        Degrees of freedom of the Student quantile of the (off-diagonal) intervals.
    n_coef : ndarray of int, shape (J,)
        ``M_j``.

    ``n`` (samples per series), ``fs`` and ``alpha`` are :class:`SeriesSettings`'s.
    """

    levels: np.ndarray
    tau_samples: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    std_error: np.ndarray
    ci_method: tuple[str, ...]
    bandwidth: np.ndarray
    df: np.ndarray
    n_coef: np.ndarray


@dataclass(frozen=True, eq=False, kw_only=True)
class WaveletCrossCovariance(LagWindowIntervals):
    """Empirical Haar WCCV (lag 0) of two series, with its asymptotic interval.

    Attributes
    ----------
    covariance : ndarray, shape (J,)
        WCCV ``nu_xy_j`` in ``unit_x * unit_y``.
    variance_x, variance_y : ndarray, shape (J,)
        The WV of each series (by-products of the same pass).
    names : tuple of str
        Names of the two series.
    unit : str
        Unit of the WCCV (e.g. ``"(deg/s)^2"``), empty when unknown.

    The levels, intervals (shape (J,)) and settings are :class:`LagWindowIntervals`'s.
    """

    covariance: np.ndarray
    variance_x: np.ndarray
    variance_y: np.ndarray
    names: tuple[str, str] = ("x", "y")
    unit: str = ""

    json_fields = (
        "names n fs alpha unit levels tau_samples tau_s covariance ci_low ci_high std_error "
        "correlation ci_method bandwidth df n_coef"
    )

    @property
    def correlation(self) -> np.ndarray:
        """Wavelet correlation ``nu_xy / sqrt(nu_xx nu_yy)`` per level (nan where a WV is 0)."""
        den = np.sqrt(self.variance_x * self.variance_y)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 0, self.covariance / np.where(den > 0, den, 1.0), np.nan)

    def table(self) -> str:
        """Readable table."""
        u = f" [{self.unit}]" if self.unit else ""
        return columns_table(
            f"Haar wavelet cross-covariance of {self.names[0]} and {self.names[1]}{u}; "
            f"N = {self.n}, fs = {self.fs:g} Hz",
            [
                ("level", ">5d", self.levels),
                ("tau [s]", ">11.5g", self.tau_s),
                ("WCCV", ">13.5e", self.covariance),
                *interval_columns(self.alpha, self.ci_low, self.ci_high),
                ("corr", ">7.3f", self.correlation),
                # the method column is set off by two spaces
                (" interval", "", [" " + m for m in self.ci_method]),
            ],
        )


@dataclass(frozen=True, eq=False, kw_only=True)
class WVMatrix(LagWindowIntervals):
    """Wavelet variances (diagonal) and cross-covariances (off-diagonal) of k channels.

    ``values[j - 1]`` is the k x k matrix at level j: symmetric, the WV of channel p at
    ``[p, p]`` and the WCCV of channels p and q at ``[p, q]``. It is the input of
    :func:`engine.fit_mgmwm` and what the app's k x k grid draws (the multivariate paper,
    Fig. 2).

    Attributes
    ----------
    channels : tuple of str, length k
        Channel names, in matrix order.
    values : ndarray, shape (J, k, k)
        Estimates. The intervals and standard errors (:class:`LagWindowIntervals`) have the
        same shape: eta3 chi-square intervals on the diagonal, normal with the lag-window
        long-run variance off it; lag-window standard errors for every entry (the Gaussian
        EDF approximation at the top levels).
    units : tuple of str, length k
        Unit of each channel (empty when unknown).
    """

    channels: tuple[str, ...]
    values: np.ndarray
    units: tuple[str, ...] = ()

    #: the ``to_dict()`` keys; matrices as nested lists ``[level][p][q]``
    json_fields = (
        "channels units n fs alpha levels tau_samples tau_s values ci_low ci_high std_error "
        "correlation ci_method bandwidth df n_coef"
    )

    # ---- shape and names -----------------------------------------------------------------
    @property
    def k(self) -> int:
        """Number of channels."""
        return len(self.channels)

    def index(self, channel: str | int) -> int:
        """Position of a channel (by name, or an index checked against k)."""
        if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool):
            if not -self.k <= channel < self.k:
                raise IndexError(f"channel index {channel} is out of range for {self.k} channels")
            return int(channel) % self.k
        try:
            return self.channels.index(channel)
        except ValueError:
            raise KeyError(
                f"unknown channel {channel!r}; the channels are {', '.join(self.channels)}"
            ) from None

    def _unit(self, p: int) -> str:
        return self.units[p] if p < len(self.units) else ""

    def _common(self) -> dict[str, Any]:
        """The fields a one-channel or one-pair view shares with the matrix."""
        return {
            f: getattr(self, f) for f in ("levels", "tau_samples", "n_coef", "n", "fs", "alpha")
        }

    # ---- views ----------------------------------------------------------------------------
    @property
    def correlation(self) -> np.ndarray:
        """Wavelet correlation matrices, shape (J, k, k): ``nu_pq / sqrt(nu_pp nu_qq)``."""
        d = np.sqrt(np.maximum(np.einsum("jpp->jp", self.values), 0.0))
        den = d[:, :, None] * d[:, None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 0, self.values / np.where(den > 0, den, 1.0), np.nan)

    def wv(self, channel: str | int) -> WaveletVariance:
        """The WV of one channel (equal to :func:`engine.wavelet_variance` of it)."""
        p = self.index(channel)
        return WaveletVariance(
            **self._common(),
            variance=self.values[:, p, p],
            ci_low=self.ci_low[:, p, p],
            ci_high=self.ci_high[:, p, p],
            unit=self._unit(p),
        )

    def pair(self, a: str | int, b: str | int) -> WaveletCrossCovariance:
        """The WCCV of two channels as a :class:`WaveletCrossCovariance`."""
        p, q = self.index(a), self.index(b)
        up, uq = self._unit(p), self._unit(q)
        unit = (squared(up) if up == uq else f"{up}*{uq}") if up and uq else ""
        return WaveletCrossCovariance(
            **self._common(),
            covariance=self.values[:, p, q],
            ci_low=self.ci_low[:, p, q],
            ci_high=self.ci_high[:, p, q],
            std_error=self.std_error[:, p, q],
            variance_x=self.values[:, p, p],
            variance_y=self.values[:, q, q],
            ci_method=self.ci_method,
            bandwidth=self.bandwidth,
            df=self.df,
            names=(self.channels[p], self.channels[q]),
            unit=unit,
        )

    def select(self, channels: Sequence[str | int]) -> WVMatrix:
        """The sub-matrix of some channels, in the given order (no recomputation)."""
        idx = [self.index(c) for c in channels]
        if len(set(idx)) != len(idx):
            raise ValueError(f"channels repeat in {list(channels)}")
        ix = np.ix_(range(self.n_levels), idx, idx)
        return replace(
            self,
            channels=tuple(self.channels[i] for i in idx),
            values=self.values[ix],
            ci_low=self.ci_low[ix],
            ci_high=self.ci_high[ix],
            std_error=self.std_error[ix],
            units=tuple(self._unit(i) for i in idx),
        )

    def truncate(self, levels: int) -> WVMatrix:
        """The first ``levels`` levels (no recomputation)."""
        if not 1 <= levels <= self.n_levels:
            raise ValueError(f"levels must be between 1 and {self.n_levels}, got {levels}")
        s = slice(0, levels)
        per_level = (
            "levels",
            "tau_samples",
            "values",
            "ci_low",
            "ci_high",
            "std_error",
            "bandwidth",
            "df",
            "n_coef",
        )
        return replace(
            self,
            ci_method=self.ci_method[:levels],
            **{f: getattr(self, f)[s] for f in per_level},
        )

    def table(self) -> str:
        """Readable summary: the WV of each channel and the wavelet correlation of each pair."""
        rho = self.correlation
        names = list(self.channels)
        lines = [
            f"WV / WCCV matrix of {self.k} channels ({', '.join(names)}); N = {self.n}, "
            f"fs = {self.fs:g} Hz",
            f"{'level':>5} {'tau [s]':>10} "
            + " ".join(f"{'WV ' + c:>14}" for c in names)
            + " "
            + " ".join(
                f"{'r ' + names[p] + '/' + names[q]:>14}"
                for p in range(self.k)
                for q in range(p + 1, self.k)
            ),
        ]
        for i in range(self.n_levels):
            lines.append(
                f"{self.levels[i]:>5d} {self.tau_s[i]:>10.4g} "
                + " ".join(f"{self.values[i, p, p]:>14.5e}" for p in range(self.k))
                + " "
                + " ".join(
                    f"{rho[i, p, q]:>14.3f}" for p in range(self.k) for q in range(p + 1, self.k)
                )
            )
        return "\n".join(lines)


# -------------------------------------------------------------------------------------------
# computation
# -------------------------------------------------------------------------------------------
def _product_sums(s: np.ndarray, n: int, levels: int) -> np.ndarray:
    """``sum_t D_t D_t'`` per level, shape (J, k, k); ``s`` is (k, n + 1) cumulative sums.

    Blocks of t with every level inside, so the regions ``s[:, a - 2^i : b - 2^i]`` that
    consecutive levels share stay in the CPU cache (as the univariate WV).
    """
    k = s.shape[0]
    out = np.zeros((levels, k, k))
    buf = np.empty((k, _BLOCK))
    for a in range(2, n + 1, _BLOCK):
        b = min(a + _BLOCK, n + 1)
        for j in range(1, levels + 1):
            m = 1 << (j - 1)
            lo = max(a, 2 * m)
            if lo >= b:
                break
            d = buf[:, : b - lo]
            np.multiply(s[:, lo - m : b - m], -2.0, out=d)
            d += s[:, lo:b]
            d += s[:, lo - 2 * m : b - 2 * m]
            out[j - 1] += d @ d.T
    return out


def _window_norms(r: int, s: int, m_used: int) -> float:
    """Denominator ``||g||^2 - (sum g)^2 / M`` of the weighted batch-means estimator."""
    g2 = s * r * (2 * r * r + 1) / 3.0
    g1 = float(r * r * s)
    return g2 - g1 * g1 / m_used


def _long_run_variances(
    s: np.ndarray, n: int, j: int, nu: np.ndarray, pairs: list[tuple[int, int]]
) -> np.ndarray:
    """Lag-window long-run variance of ``W^p W^q`` at level j for each pair (p, q).

    Weighted overlapping batch means on bins of ``2^(j-1)`` coefficients (see the module
    docstring); one streaming pass over the level in blocks, carrying ``2r - 2`` bins.
    """
    k = s.shape[0]
    m = 1 << (j - 1)
    sbin = m
    m_coef = n - 2 * m + 1
    nb = m_coef // sbin
    m_used = nb * sbin
    npairs = len(pairs)
    pi = np.array([p for p, _ in pairs])
    qi = np.array([q for _, q in pairs])
    scale = float(1 << j) ** 2  # the coefficients are D / 2^j
    centre = np.array([nu[p, q] for p, q in pairs])[:, None] * (sbin * scale)
    blk = max(_BLOCK, sbin)  # a multiple of the bin width (powers of two)
    carry = np.zeros((npairs, 0))
    acc = np.zeros(npairs)
    n_t = 0
    buf = np.empty((k, blk))
    for i0 in range(0, m_used, blk):
        i1 = min(i0 + blk, m_used)
        t0, t1 = i0 + 2 * m, i1 + 2 * m  # positions in the cumulative sums
        d = buf[:, : i1 - i0]
        np.multiply(s[:, t0 - m : t1 - m], -2.0, out=d)
        d += s[:, t0:t1]
        d += s[:, t0 - 2 * m : t1 - 2 * m]
        prod = d[pi] * d[qi]  # (npairs, len), divided by 4^j at the end
        y = prod.reshape(npairs, -1, sbin).sum(axis=2) - centre  # de-meaned bin sums
        y = np.concatenate([carry, y], axis=1)
        if y.shape[1] >= 2 * _R - 1:
            c = np.concatenate([np.zeros((npairs, 1)), np.cumsum(y, axis=1)], axis=1)
            box = c[:, _R:] - c[:, :-_R]  # sums of R consecutive bins
            c2 = np.concatenate([np.zeros((npairs, 1)), np.cumsum(box, axis=1)], axis=1)
            t = c2[:, _R:] - c2[:, :-_R]  # staircase-triangular sums over 2R - 1 bins
            acc += np.einsum("pi,pi->p", t, t)
            n_t += t.shape[1]
            carry = y[:, -(2 * _R - 2) :]
        else:
            carry = y
    return acc / max(n_t, 1) / _window_norms(_R, sbin, m_used) / (scale * scale)


def _compute(
    series: list[np.ndarray],
    levels: int,
    alpha: float,
    ci: bool,
    *,
    names: Sequence[str],
    fs: float,
    units: Sequence[str] = (),
) -> WVMatrix:
    """Values, standard errors and intervals of all pairs of k series (shared code)."""
    n = series[0].size
    k = len(series)
    s = np.empty((k, n + 1))
    for p, x in enumerate(series):
        s[p] = cumsum_demeaned(x)
    grid = level_grid(n, levels)
    lv, tau, m_j = grid["levels"], grid["tau_samples"], grid["n_coef"]
    sums = _product_sums(s, n, levels)
    vals = sums / (tau.astype(float) ** 2 * m_j)[:, None, None]
    vals = 0.5 * (vals + np.transpose(vals, (0, 2, 1)))  # exact symmetry
    pairs = [(p, q) for p in range(k) for q in range(p, k)]
    se = np.full((levels, k, k), np.nan)
    method: list[str] = []
    bandwidth = np.zeros(levels, dtype=int)
    eta = np.maximum(m_j / tau, 1.0)
    df = eta.copy()
    for j in lv:
        i = j - 1
        nu = vals[i]
        m = 1 << (j - 1)
        if ci and (m_j[i] // m) >= _MIN_BINS:
            lrv = _long_run_variances(s, n, int(j), nu, pairs)
            var = np.maximum(lrv, 0.0) / m_j[i]
            method.append("lag-window")
            b = _BW_FACTOR * (1 << j)
            bandwidth[i] = 2 * b
            df[i] = 2.0 * m_j[i] / (_SUM_W2 * b)
        else:
            var = np.array([(nu[p, p] * nu[q, q] + nu[p, q] ** 2) / eta[i] for p, q in pairs])
            method.append("gaussian-edf")
        for (p, q), v in zip(pairs, var, strict=True):
            se[i, p, q] = se[i, q, p] = math.sqrt(v)
    z = _t_quantile(alpha, df)[:, None, None]
    lo = vals - z * se
    hi = vals + z * se
    for p in range(k):
        lo[:, p, p], hi[:, p, p] = eta3_interval(vals[:, p, p], m_j, tau, alpha)
    return WVMatrix(
        channels=tuple(names),
        **grid,
        values=vals,
        ci_low=lo,
        ci_high=hi,
        std_error=se,
        ci_method=tuple(method),
        bandwidth=bandwidth,
        df=df,
        n=int(n),
        fs=float(fs),
        alpha=float(alpha),
        units=tuple(units),
    )


def _levels(n: int, levels: int | None) -> int:
    jmax = default_levels(n)
    if levels is None:
        return jmax
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)):
        raise TypeError(f"levels must be an integer, got {levels!r}")
    if not 1 <= levels <= jmax:
        raise ValueError(
            f"levels={levels} is out of range: series of {n} samples support 1 to {jmax} levels"
        )
    return int(levels)


def wavelet_cross_covariance(
    x: Any,
    y: Any,
    *,
    fs: float = 1.0,
    levels: int | None = None,
    alpha: float = 0.05,
    names: tuple[str, str] = ("x", "y"),
    unit: str = "",
) -> WaveletCrossCovariance:
    """Empirical Haar MODWT wavelet cross-covariance (lag 0) of two series, with intervals.

    ``nu_xy_j = mean_t W^x_{j,t} W^y_{j,t}`` over the ``M_j = N - 2^j + 1`` boundary-free
    coefficients (unbiased); equal to the WV when ``x`` is ``y``.

    Parameters
    ----------
    x, y : array_like, shape (N,)
        Two series of the same length, ``N >= 4``, sampled together. Means are removed first.
    fs : float
        Sampling frequency in Hz.
    levels : int, optional
        Number of levels J; default ``floor(log2(N - 1))``.
    alpha : float
        Interval level ``1 - alpha``: normal interval with the long-run variance of the
        product of the coefficient series (lag-window estimate; see the module docstring).
    names : tuple of str
        Labels of the two series (for tables).
    unit : str
        Unit of the WCCV, carried for display.

    Returns
    -------
    WaveletCrossCovariance

    Raises
    ------
    ValueError
        Series of different lengths, too short, non-finite, or bad settings.
    """
    a = as_series(x)
    b = as_series(y)
    if a.size != b.size:
        raise ValueError(
            f"the two series have different lengths ({a.size} and {b.size} "
            "samples): a cross-covariance needs series sampled together"
        )
    check_fs_alpha(fs, alpha)
    lv = _levels(a.size, levels)
    pair = (str(names[0]), str(names[1]))
    return replace(_compute([a, b], lv, alpha, True, names=pair, fs=fs).pair(0, 1), unit=unit)


def _is_log(data: Any) -> bool:
    """An ImuLog or alike (a ``channels`` mapping and ``fs``): numerics never import io."""
    return isinstance(getattr(data, "channels", None), Mapping) and hasattr(data, "fs")


def _gather(
    data: Any,
    channels: Sequence[str | int] | None,
    fs: float | None,
    units: Sequence[str] | Mapping[str, str] | None,
) -> tuple[list[str], list[np.ndarray], float, list[str]]:
    """Channels, series, fs and units from an (N, k) array, a mapping or an ImuLog."""
    log_units: Mapping[str, str] = {}
    if _is_log(data):
        if not data.channels:
            raise ValueError(
                f"{getattr(data, 'source', 'the log')} holds no raw samples "
                "(a WV summary file?): a cross-covariance needs the raw channels"
            )
        mapping: Mapping[str, Any] = data.channels
        log_units = getattr(data, "units", {}) or {}
        fs = float(data.fs) if fs is None else fs
    elif isinstance(data, Mapping):
        mapping = data
    else:
        arr = np.asarray(data)
        if arr.ndim != 2:
            raise ValueError(
                f"give an (N, k) array with one column per channel, a mapping "
                f"name -> series or an ImuLog; got an array of shape {arr.shape}"
            )
        mapping = {f"x{i}": arr[:, i] for i in range(arr.shape[1])}
        if channels is not None and all(isinstance(c, str) for c in channels):
            if len(channels) != arr.shape[1]:
                raise ValueError(
                    f"{len(channels)} channel names for an array with {arr.shape[1]} columns"
                )
            mapping = dict(zip(map(str, channels), mapping.values(), strict=True))
    names = list(mapping)
    if channels is None:
        chosen = names
    else:
        chosen = []
        for c in channels:
            if isinstance(c, (int, np.integer)) and not isinstance(c, bool):
                if not -len(names) <= c < len(names):
                    raise KeyError(
                        f"channel index {c} is out of range: there are {len(names)} "
                        f"channels ({', '.join(names)})"
                    )
                chosen.append(names[int(c)])
            elif c in mapping:
                chosen.append(str(c))
            else:
                raise KeyError(f"unknown channel {c!r}; the channels are {', '.join(names)}")
    if len(set(chosen)) != len(chosen):
        raise ValueError(f"channels repeat in {chosen}")
    if len(chosen) < 2:
        raise ValueError(
            f"a WV/WCCV matrix needs at least 2 channels, got {len(chosen)} "
            f"({', '.join(chosen) or 'none'}); use wavelet_variance for one"
        )
    series = []
    for c in chosen:
        try:
            series.append(as_series(mapping[c]))
        except (ValueError, TypeError) as e:
            raise type(e)(f"channel {c!r}: {e}") from None
    sizes = {c: a.size for c, a in zip(chosen, series, strict=True)}
    if len(set(sizes.values())) > 1:
        desc = ", ".join(f"{c}: {v}" for c, v in sizes.items())
        raise ValueError(
            f"the channels have different lengths ({desc} samples): the WCCV "
            "needs channels sampled together; trim them to a common span"
        )
    if isinstance(units, Mapping):
        unit_list = [str(units.get(c, "")) for c in chosen]
    elif units is not None:
        if len(units) != len(chosen):
            raise ValueError(f"{len(units)} units for {len(chosen)} channels")
        unit_list = [str(u) for u in units]
    else:
        unit_list = [str(log_units.get(c, "")) for c in chosen]
    return chosen, series, 1.0 if fs is None else fs, unit_list


def wv_matrix(
    data: Any,
    *,
    channels: Sequence[str | int] | None = None,
    fs: float | None = None,
    levels: int | None = None,
    alpha: float = 0.05,
    units: Sequence[str] | Mapping[str, str] | None = None,
    ci: bool = True,
) -> WVMatrix:
    """WV (diagonal) and WCCV (off-diagonal) of k channels at every level, with intervals.

    Parameters
    ----------
    data : ndarray (N, k), mapping of name to series, or ImuLog
        The channels, sampled together (same length). An array's columns are named
        ``x0, x1, ..`` unless ``channels`` gives k names.
    channels : sequence of str or int, optional
        Which channels, in which order (names or indices); default all.
    fs : float, optional
        Sampling frequency in Hz; default the log's, else 1.
    levels : int, optional
        Number of levels J; default ``floor(log2(N - 1))``.
    alpha : float
        Interval level ``1 - alpha``.
    units : sequence or mapping of str, optional
        Channel units (default: the log's).
    ci : bool
        Compute the lag-window standard errors (one more O(N) pass per level and pair of
        channels). With False, the Gaussian EDF approximation is used at every level.

    Returns
    -------
    WVMatrix

    Raises
    ------
    ValueError
        Fewer than 2 channels, different lengths, non-finite samples, bad settings.
    KeyError
        Unknown channel name or index.

    Notes
    -----
    One cumulative sum per channel, then for every level ``sum_t D_t D_t'`` (k x k, BLAS) in
    cache-sized blocks: O(N J k^2) flops, ``k (N + 1)`` float64 of extra memory. The
    diagonal is bit-for-bit the same arithmetic as :func:`engine.wavelet_variance` up to the
    summation order (agreement to about 1e-15 relative).
    """
    names, series, fs_v, unit_list = _gather(data, channels, fs, units)
    check_fs_alpha(fs_v, alpha)
    lv = _levels(series[0].size, levels)
    return _compute(series, lv, alpha, ci, names=names, fs=fs_v, units=unit_list)
