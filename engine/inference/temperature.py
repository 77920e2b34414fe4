"""The bias-temperature relation of a channel, its sensitivity in datasheet units, and the
GMWM of the compensated signal.

Model: ``y_t = b + sum_p c_p (T_t - T_ref)^p + e_t`` (``p = 1..degree``), with ``e`` the
stochastic error the GMWM describes (WN, RW, GM, DR ...). The coefficients are estimated
before the stochastic model, by least squares on the **first differences of block means**
(``K = 256`` blocks): differencing turns a random walk into white noise (it is the GLS
estimator for RW noise), the intercept of the differenced regression is the drift (so a DR
is not taken for temperature), and the remaining short-memory noise (the WN's MA(1), a GM
shorter than a block) is covered by Newey-West standard errors (lag 4). A temperature that
rises linearly over the whole log is, in these differences, a constant: it cannot be told
from a drift, and the fit says so (its interval is then very wide).

A sensor's own temperature may lag the logged one (a board sensor, a case): with
``lag="auto"`` (the default) the fit also tries a first-order thermal lag, the polynomial in
``T_lag`` with ``dT_lag/dt = (T - T_lag) / tau`` (:func:`lagged_temperature`), ``tau`` by
profiling the same regression's residual sum of squares, and keeps it only when the data
support it: a BIC lower than the polynomial's on the differenced block means.

On a log cut into still segments (a flight's still parts, ``ImuLog.segments``), the block
means are taken within each segment and differenced within it only, so that each segment
keeps its own offset (the bias may move while the vehicle moves), and the differences of
every segment are pooled in one regression; the compensated signal's WV pools the segments
as the log's own WV does. The lag is not tried there (its profile filters the whole log's
block structure).

Compensate only what the data show: with ``compensate="auto"`` (what ``temperature="auto"``
asks of :func:`fit_log_temperature`) the relation is taken out only when the joint Wald test
that every coefficient is 0 rejects at the fit's level (the Newey-West covariance above; for
degree 1, the sensitivity's interval excludes 0). A log whose temperature barely moves beyond
a slow ramp, a flight's still parts, give a sensitivity the data cannot tell from 0, and taking
it out only adds its own error, times the temperature's range, to the signal (the ArduPilot
flight of ``docs/drone-logs.md``: RW.gamma2 1.99e-10 compensated against 5.80e-11 raw). The
fit then says so (:attr:`TemperatureFit.applied`, its :meth:`~TemperatureFit.line`) and its
WV is the raw one. A temperature channel named by the caller is always compensated.

The GMWM is then fitted on ``y_t - sum_p c_p (T_t - T_ref)^p``; :class:`TemperatureFit`
keeps both wavelet variances (raw and compensated) and says which one to fit (``wv``).
Sensitivities are reported in datasheet units: deg/h per degC for gyroscopes, mg per degC
for accelerometers (``engine.units``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..fit import GMWMResult, fit_gmwm
from ..io import ImuLog, LoadError
from ..io.timecols import is_temperature
from ..models import Model
from ..units import ExportError, si_factor
from ..wv import WaveletVariance

__all__ = [
    "TemperatureFit",
    "fit_temperature",
    "fit_log_temperature",
    "temperature_sensitivity",
    "find_temperature",
    "temperature_series",
    "lagged_temperature",
    "compensate_channels",
]

BLOCKS = 256
NW_LAG = 4
_G = 9.80665


@dataclass(frozen=True, eq=False)
class TemperatureFit:
    """Temperature compensation of one channel and the GMWM of the compensated signal.

    Attributes
    ----------
    channel, temperature : str
        The signal channel and the temperature channel.
    unit : str
        Signal unit.
    degree : int
        Polynomial degree (1: linear).
    t_ref : float
        Reference temperature (degC): the mean over the log.
    coef, se : ndarray, shape (degree,)
        ``c_p`` in unit per degC^p, and their standard errors.
    drift : float
        Drift per sample (unit) of the differenced regression's intercept.
    level : float
        Level of :attr:`interval`.
    temperature_range : (float, float)
        Lowest and highest temperature in the log (degC).
    sensitivity, sensitivity_interval, sensitivity_unit
        ``c_1`` in datasheet units (deg/h per degC, mg per degC), its interval; the signal
        unit per degC when the unit is not a known one.
    fit, fit_raw : GMWMResult
        The GMWM the caller takes away (of the compensated signal when :attr:`applied`, of
        the raw one otherwise), and the raw signal's beside a compensated one (same model;
        None when not applied: there is nothing to compare).
    wv, wv_raw : WaveletVariance
        Their wavelet variances: :attr:`wv` is the one to fit, whatever :attr:`applied`.
    applied : bool
        Whether the relation is taken out of the signal: always for a temperature channel
        named by the caller; with ``compensate="auto"`` only when the data show an effect
        (the joint Wald test that every coefficient is 0, Newey-West covariance, rejects at
        ``level``; for degree 1: the sensitivity's interval excludes 0).
    p_value : float
        That test's p-value (chi-squared with ``degree`` degrees of freedom).
    notes : tuple of str
        What the fit could not tell (a temperature rising at a constant rate, like a drift).
    tau_s : float
        Time constant (s) of the first-order thermal lag the polynomial is in (``T`` replaced
        by :func:`lagged_temperature`); 0: the temperature as logged.
    tau_interval : (float, float)
        Profile-likelihood interval of ``tau_s`` at ``level`` (``0`` as its low end: a lag
        shorter than the data can tell; ``inf`` as its high end: longer than the log); ``(0,
        0)`` without a lag.
    lag_bic : float
        BIC of the best lag minus that of the polynomial alone, on the differenced block means
        (the lag is kept when it is negative); NaN when no lag was tried.
    fs : float
        Sampling frequency (Hz) of the fitted log (the lag's time step).
    """

    channel: str
    temperature: str
    unit: str
    degree: int
    t_ref: float
    coef: np.ndarray
    se: np.ndarray
    drift: float
    level: float
    temperature_range: tuple[float, float]
    sensitivity: float
    sensitivity_interval: tuple[float, float]
    sensitivity_unit: str
    fit: GMWMResult | None = None
    fit_raw: GMWMResult | None = None
    wv: WaveletVariance | None = None
    wv_raw: WaveletVariance | None = None
    notes: tuple[str, ...] = field(default=())
    tau_s: float = 0.0
    tau_interval: tuple[float, float] = (0.0, 0.0)
    lag_bic: float = math.nan
    fs: float = math.nan
    applied: bool = True
    p_value: float = math.nan

    #: The sensitivity as a datasheet figure of a fleet (``engine.batch.unit_values``, the
    #: fleet report's tables): its process, quantity and symbol.
    PROCESS: ClassVar[str] = "temperature"
    QUANTITY: ClassVar[str] = "bias temperature sensitivity"
    SYMBOL: ClassVar[str] = "S_T"
    #: The quantity of a sensitivity that was not taken out of the signal (information only:
    #: a fleet pools it apart from the compensated units').
    QUANTITY_NOT_APPLIED: ClassVar[str] = "bias temperature sensitivity, not compensated"

    @property
    def quantity(self) -> str:
        """:attr:`QUANTITY` when :attr:`applied`, :attr:`QUANTITY_NOT_APPLIED` otherwise."""
        return self.QUANTITY if self.applied else self.QUANTITY_NOT_APPLIED

    @property
    def marker(self) -> str:
        """``""`` when :attr:`applied`; otherwise ``"not compensated (p = 0.41)"``, the mark
        beside a sensitivity shown as information only (the fleet's tables)."""
        return "" if self.applied else f"not compensated (p = {self.p_value:.2g})"

    @property
    def interval(self) -> np.ndarray:
        """``(degree, 2)`` intervals of :attr:`coef` (normal quantile at ``level``)."""
        from scipy import stats

        z = float(stats.norm.ppf(0.5 + self.level / 2))
        return np.column_stack([self.coef - z * self.se, self.coef + z * self.se])

    def line(self, anyway: str | None = None) -> str:
        """One line: the sensitivity with its interval and the temperature range, and, when
        not :attr:`applied`, that it is not compensated and how to compensate anyway
        (``anyway``: how, in the caller's words; by default the argument to name)."""
        lo, hi = self.sensitivity_interval
        t0, t1 = self.temperature_range
        lag = ""
        if self.tau_s > 0:
            a, b = self.tau_interval
            lag = f", lagging it by tau = {self.tau_s:.3g} s [{a:.3g}, {b:.3g}]"
        out = (
            f"{self.channel}: temperature sensitivity {self.sensitivity:.4g} "
            f"[{lo:.4g}, {hi:.4g}] {self.sensitivity_unit} ({100 * self.level:g} %, "
            f"'{self.temperature}' from {t0:.3g} to {t1:.3g} degC{lag})"
        )
        if self.applied:
            return out
        if anyway is None:
            anyway = f"name it, temperature='{self.temperature}', to compensate anyway"
        return (
            f"{out}: not distinguishable from 0 (p = {self.p_value:.2g}), not compensated "
            f"({anyway})"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (the fits as their own ``to_dict``)."""
        iv = self.interval
        return {
            "channel": self.channel,
            "temperature": self.temperature,
            "unit": self.unit,
            "degree": self.degree,
            "t_ref_degC": self.t_ref,
            "coef": [float(c) for c in self.coef],
            "coef_unit": [f"{self.unit}/degC^{p}" for p in range(1, self.degree + 1)],
            "se": [float(s) for s in self.se],
            "interval": [[float(a), float(b)] for a, b in iv],
            "level": self.level,
            "drift_per_sample": self.drift,
            "temperature_range_degC": list(self.temperature_range),
            "sensitivity": self.sensitivity,
            "sensitivity_interval": list(self.sensitivity_interval),
            "sensitivity_unit": self.sensitivity_unit,
            "fit": self.fit.to_dict() if self.fit is not None else None,
            "fit_raw_model": self.fit_raw.model.spec(values=True) if self.fit_raw else None,
            "fit_raw": self.fit_raw.to_dict() if self.fit_raw is not None else None,
            "wv_raw": self.wv_raw.to_dict() if self.wv_raw is not None else None,
            "notes": list(self.notes),
            "lag_tau_s": self.tau_s,
            "lag_tau_interval_s": list(self.tau_interval),
            "lag_bic": self.lag_bic,
            "compensated": self.applied,
            "p_value": self.p_value,
            "summary": self.line(),
        }

    def compensated_log(self, log: ImuLog) -> ImuLog:
        """The log as :attr:`wv` sees it: :attr:`channel` compensated (:meth:`compensate`, its
        temperature channel :attr:`temperature` read from the log) when :attr:`applied`, the
        log itself otherwise; everything else as it was (its segments too: its WV pools
        them)."""
        if not self.applied:
            return log
        y = self.compensate(log[self.channel], temperature_series(log, self.temperature))
        return replace(log, channels={**log.channels, self.channel: y})

    def compensate(self, y: np.ndarray, temp: np.ndarray) -> np.ndarray:
        """``y - sum_p c_p (T - T_ref)^p``, ``T`` lagged by :attr:`tau_s` when it is > 0."""
        t = np.asarray(temp, dtype=float)
        if self.tau_s > 0:
            t = lagged_temperature(t, self.tau_s, self.fs)
        dt = t - self.t_ref
        out = np.asarray(y, dtype=float).copy()
        for p, c in enumerate(self.coef, start=1):
            out -= c * dt**p
        return out


def compensate_channels(log: ImuLog, fits: Iterable[TemperatureFit | None]) -> ImuLog:
    """The log with the channel of each of ``fits`` compensated where that fit says so
    (:meth:`TemperatureFit.compensated_log`, one after the other; None entries skipped): the
    signal the fits' GMWMs were made on, which any figure of the samples (a filter file's tail
    factors, a PSD) must read. ``log`` itself when none is compensated."""
    out = log
    for tf in fits:
        if tf is not None:
            out = tf.compensated_log(out)
    return out


def temperature_sensitivity(value: float, unit: str, channel: str = "") -> tuple[float, str]:
    """A coefficient in ``unit`` per degC as a datasheet figure: deg/h per degC (gyro), mg
    per degC (accelerometer); ``(value, unit + "/degC")`` for an unknown unit."""
    try:
        kind, factor = si_factor(unit, channel)
    except ExportError:
        return float(value), f"{unit or 'unit'}/degC"
    if kind == "gyroscope":
        return float(value) * factor * 180 / math.pi * 3600, "deg/h/degC"
    return float(value) * factor / _G * 1000, "mg/degC"


def lagged_temperature(temp: np.ndarray, tau_s: float, fs: float) -> np.ndarray:
    """The temperature seen through a first-order lag: ``dT_lag/dt = (T - T_lag) / tau``.

    Exact for a temperature constant over each sample interval:
    ``T_lag[t] = a T_lag[t-1] + (1 - a) T[t]`` with ``a = exp(-1 / (tau fs))``, starting at
    ``T_lag[0] = T[0]`` (the sensor at the logged temperature when the log starts).

    Parameters
    ----------
    temp : ndarray, shape (n,)
        The logged temperature (degC).
    tau_s : float
        Time constant (s), > 0.
    fs : float
        Sampling frequency (Hz).
    """
    from scipy.signal import lfilter

    t = np.asarray(temp, dtype=float)
    a = math.exp(-1.0 / (tau_s * fs))
    out, _ = lfilter([1.0 - a], [1.0, -a], t, zi=[a * t[0]])
    return np.asarray(out)


def _block_means(a: np.ndarray, k: int) -> np.ndarray:
    b = a.size // k
    return a[: b * k].reshape(k, b).mean(axis=1)


def _segment_differences(a: np.ndarray, parts: Sequence[tuple[int, int]], b: int) -> np.ndarray:
    """First differences of the means of consecutive blocks of ``b`` samples, within each
    part ``a[start:stop]`` (at most :data:`BLOCKS` blocks a part), pooled: no difference
    spans two parts, so that each keeps its own offset."""
    out = []
    for lo, hi in parts:
        k = min((hi - lo) // b, BLOCKS)
        if k >= 2:
            out.append(np.diff(a[lo : lo + k * b].reshape(k, b).mean(axis=1)))
    return np.concatenate(out) if out else np.zeros(0)


def _newey_west(x: np.ndarray, e: np.ndarray, lag: int) -> np.ndarray:
    """HAC covariance of OLS coefficients (Bartlett kernel)."""
    xtx_inv = np.linalg.inv(x.T @ x)
    u = x * e[:, None]
    s = u.T @ u
    for l in range(1, lag + 1):
        w = 1 - l / (lag + 1)
        g = u[l:].T @ u[:-l]
        s += w * (g + g.T)
    return np.asarray(xtx_inv @ s @ xtx_inv)


def find_temperature(log: ImuLog, choice: str = "auto", *, channel: str = "") -> str | None:
    """The temperature channel of a log: ``"auto"`` (an auxiliary or signal channel named
    like a temperature: the one sharing ``channel``'s prefix, ``imu1_temperature`` for
    ``imu1_gyro_x``, else the first), ``"none"``, or a channel name.

    Raises
    ------
    LoadError
        A named channel that the log does not have.
    """
    if choice == "none":
        return None
    names = list(log.aux) + list(log.channels)
    if choice == "auto":
        temps = [n for n in names if is_temperature(n) and n != channel]
        prefix = channel.split("_", 1)[0] + "_" if "_" in channel else None
        same = [n for n in temps if prefix and n.startswith(prefix)]
        return (same or temps)[0] if temps else None
    if choice not in names:
        raise LoadError(
            f"file '{log.source}': temperature={choice!r} is not a channel of the log "
            f"(channels: {', '.join(names) or 'none'}); use 'auto', 'none' or one of them"
        )
    return choice


def temperature_series(log: ImuLog, name: str) -> np.ndarray:
    """The samples of the temperature channel ``name`` of a log (an auxiliary channel, or a
    signal channel named like a temperature)."""
    return np.asarray(log.aux[name] if name in log.aux else log.channels[name], dtype=float)


#: Time constants tried for the lag, per log: from a quarter of a block to twice the log.
LAG_GRID = 48
#: Windows per block of the temperature the lag's profile filters (its exact window means).
LAG_WINDOWS = 16


def _window_means(a: np.ndarray, count: int, length: float) -> np.ndarray:
    """Means of ``a`` over ``count`` consecutive windows of ``length`` samples (a fraction
    allowed: the samples are taken as held over their interval), from sample 0."""
    c = np.concatenate([[0.0], np.cumsum(a - a[0])])  # de-meaned: no digits lost
    edges = np.interp(np.arange(count + 1) * length, np.arange(c.size), c)
    return np.diff(edges) / length + a[0]


def _profile_lag(
    temp: np.ndarray,
    fs: float,
    block_s: float,
    rss: Any,
    k: int,
    level: float,
) -> tuple[float, tuple[float, float], float]:
    """The lag's time constant minimising ``rss`` (the differenced block-means regression's
    residual sum of squares with the lagged temperature), its profile-likelihood interval
    (``k log(RSS(tau) / RSS_min) <= chi2_1(level)``, ``k`` differences) and the BIC of the
    lag minus that of no lag (``k log(RSS_lag / RSS_0) + log k``: one more parameter)."""
    from scipy import optimize, stats

    duration = temp.size / fs
    grid = np.geomspace(block_s / 4, 2 * duration, LAG_GRID)
    # the lag filters the temperature's means over LAG_WINDOWS windows per block (their block
    # means are the samples' exactly): 4096 values whatever the log's length
    coarse = _window_means(temp, BLOCKS * LAG_WINDOWS, block_s * fs / LAG_WINDOWS)
    fs_c = LAG_WINDOWS / block_s

    def f(log_tau: float) -> float:
        return rss(lagged_temperature(coarse, math.exp(log_tau), fs_c))

    vals = np.array([f(math.log(t)) for t in grid])
    i = int(np.argmin(vals))
    lo_i, hi_i = max(i - 1, 0), min(i + 1, grid.size - 1)
    best = optimize.minimize_scalar(
        f,
        bounds=(math.log(grid[lo_i]), math.log(grid[hi_i])),
        method="bounded",
        options={"xatol": 1e-3},
    )
    tau, r_min = math.exp(best.x), min(float(best.fun), float(vals[i]))
    if vals[i] < best.fun:
        tau = float(grid[i])
    r0 = rss(coarse)
    dbic = k * math.log(r_min / r0) + math.log(k) if r0 > 0 else math.nan
    crit = float(stats.chi2.ppf(level, 1))
    excess = k * np.log(vals / r_min) - crit  # > 0 outside the interval

    def g(log_tau: float) -> float:
        return k * math.log(f(log_tau) / r_min) - crit

    def edge(side: range, default: float) -> float:
        prev = math.log(tau)
        for j in side:
            if excess[j] > 0:
                return math.exp(optimize.brentq(g, *sorted((prev, math.log(grid[j]))), xtol=1e-3))
            prev = math.log(grid[j])
        return default

    below = range(int(np.searchsorted(grid, tau)) - 1, -1, -1)
    above = range(int(np.searchsorted(grid, tau)), grid.size)
    return tau, (edge(below, 0.0), edge(above, math.inf)), dbic


def fit_log_temperature(
    log: ImuLog,
    name: str,
    choice: str = "auto",
    *,
    model: Model | str | None = None,
    levels: int | None = None,
    robust: bool = False,
    eff: float = 0.6,
    alpha: float = 0.05,
    weights: str = "ci",
    compensate: bool | str | None = None,
) -> TemperatureFit | None:
    """The temperature compensation of channel ``name`` of a log (:func:`fit_temperature` on
    the log's temperature channel, its fs, unit and names), or None when there is none to fit.

    Parameters
    ----------
    log : ImuLog
        The loaded log.
    name : str
        The signal channel.
    choice : str or None
        The temperature channel (:func:`find_temperature`): ``"auto"``, ``"none"`` or a
        channel name.
    model, levels, robust, eff, alpha, weights
        As :func:`fit_temperature`.
    compensate : {None, True, "auto"}
        As :func:`fit_temperature`; None: ``"auto"`` for ``choice="auto"`` (compensated only
        when the data show an effect), True for a channel named (always compensated).

    Returns
    -------
    TemperatureFit or None
        None for ``"none"``, a log without a temperature channel, a WV summary (no samples),
        and, with ``"auto"``, a temperature channel the fit cannot use (constant, NaN
        samples, fewer than 4096 samples). On a log cut into still segments the fit is on
        the segments, each with its own offset (:func:`fit_temperature`'s ``segments``),
        under the same rule.

    Raises
    ------
    LoadError
        A named temperature channel that the log does not have.
    ValueError
        A named temperature channel the fit cannot use (as :func:`fit_temperature`).
    """
    if log.is_summary or choice == "none":
        return None
    tname = find_temperature(log, choice, channel=name)
    if tname is None:
        return None
    if compensate is None:
        compensate = "auto" if choice == "auto" else True
    try:
        return fit_temperature(
            log[name],
            temperature_series(log, tname),
            fs=log.fs,
            model=model,
            unit=log.unit_of(name),
            channel=name,
            temperature=tname,
            levels=levels,
            robust=robust,
            eff=eff,
            alpha=alpha,
            weights=weights,
            segments=log.segments,
            compensate=compensate,
        )
    except ValueError:
        if choice != "auto":
            raise
        return None  # found by its name but unusable (constant, too short, NaN): none


def fit_temperature(
    y: np.ndarray,
    temp: np.ndarray,
    *,
    fs: float,
    model: Model | str | None = None,
    degree: int = 1,
    level: float = 0.95,
    unit: str = "",
    channel: str = "x",
    temperature: str = "temperature",
    levels: int | None = None,
    robust: bool = False,
    eff: float = 0.6,
    alpha: float = 0.05,
    weights: str = "ci",
    lag: bool | str = "auto",
    segments: Sequence[tuple[int, int]] = (),
    compensate: bool | str = True,
) -> TemperatureFit:
    """Fit the bias-temperature polynomial, then the GMWM of the compensated signal (or, with
    ``compensate="auto"`` and no effect the data can tell from 0, of the raw one).

    Parameters
    ----------
    y, temp : ndarray, shape (n,)
        The signal and the temperature (degC) sampled with it.
    fs : float
        Sampling frequency (Hz).
    model : Model or str, optional
        The stochastic model fitted on the compensated (and on the raw) signal; None: no fit.
    degree : int
        Polynomial degree, 1 or 2.
    level : float
        Interval level of the coefficients.
    unit, channel, temperature : str
        Signal unit and names, for the sensitivity's datasheet unit and the messages.
    levels, robust, eff, alpha, weights
        As :func:`engine.fit_gmwm` / :meth:`engine.io.ImuLog.wavelet_variance` (the WVs of
        both signals).
    lag : {"auto", True, False}
        The first-order thermal lag: ``"auto"`` fits it and keeps it when its BIC is lower
        than the polynomial's alone (:attr:`TemperatureFit.lag_bic`), True always keeps it,
        False (or ``"none"``) does not try it.
    segments : sequence of (start, stop), optional
        Sample ranges to fit on (the still parts of a flight, ``ImuLog.segments``): block
        means of ``sum(stop - start) // 256`` samples within each segment, differenced within
        it (each segment keeps its own offset), pooled; the WVs pool the segments; ``T_ref``
        and the temperature range are over the segments; no lag is tried. Empty: the whole
        series.
    compensate : {True, "auto"}
        True: take the relation out of the signal whatever its size (a temperature channel
        the user named). ``"auto"``: only when the joint Wald test that all the coefficients
        are 0 (their Newey-West covariance, chi-squared with ``degree`` degrees of freedom)
        rejects at ``level``; for degree 1, when the sensitivity's interval excludes 0.
        Otherwise :attr:`TemperatureFit.applied` is False and :attr:`TemperatureFit.wv` is
        the raw signal's: a sensitivity the data cannot tell from 0 would only add its own
        error, times the temperature's range, to the signal.

    Returns
    -------
    TemperatureFit

    Raises
    ------
    ValueError
        Lengths differ, NaN temperatures, a constant temperature, fewer than 16 x 256 samples
        (in the segments), a degree other than 1 or 2, another ``lag``, or a segment outside
        the series.
    """
    from ..wv import wavelet_variance
    from ..wv.pooled import pooled_wavelet_variance

    y = np.asarray(y, dtype=float)
    temp = np.asarray(temp, dtype=float)
    if degree not in (1, 2):
        raise ValueError(f"degree must be 1 or 2, got {degree}")
    if lag not in ("auto", "none", True, False):
        raise ValueError(f"lag must be 'auto', True or False, got {lag!r}")
    if compensate not in (True, "auto"):
        raise ValueError(f"compensate must be True or 'auto', got {compensate!r}")
    if y.shape != temp.shape or y.ndim != 1:
        raise ValueError(
            f"the temperature '{temperature}' has {temp.size} samples and {channel} "
            f"{y.size}: they must be sampled together"
        )
    parts = [(int(lo), int(hi)) for lo, hi in segments] or [(0, y.size)]
    if any(not 0 <= lo < hi <= y.size for lo, hi in parts):
        raise ValueError(
            f"{channel}: segments {parts} must be (start, stop) sample ranges within its "
            f"{y.size} samples"
        )
    still = np.concatenate([temp[a:b] for a, b in parts]) if segments else temp
    n_still = int(still.size)
    if n_still < 16 * BLOCKS:
        where = " in its segments" if segments else ""
        raise ValueError(
            f"{channel}: {n_still} samples{where} are too few for a temperature fit (4096)"
        )
    if not np.all(np.isfinite(still)):
        raise ValueError(f"the temperature '{temperature}' has NaN/Inf samples")
    if np.ptp(still) == 0:
        raise ValueError(f"the temperature '{temperature}' is constant: nothing to fit")
    t_ref = float(np.mean(still))
    bl = n_still // BLOCKS  # samples per block
    dy = _segment_differences(y, parts, bl)
    if dy.size < 4 * (degree + 2):
        raise ValueError(
            f"{channel}: its segments are too short for a temperature fit ({dy.size} "
            f"differences of block means of {bl} samples; each segment needs 2 blocks)"
        )

    def design(t: np.ndarray) -> np.ndarray:
        powers = range(1, degree + 1)
        if segments:
            dx = np.column_stack(
                [_segment_differences((t - t_ref) ** p, parts, bl) for p in powers]
            )
        else:  # the whole series, or the lag profile's window means of it (any length)
            xb = np.column_stack([_block_means((t - t_ref) ** p, BLOCKS) for p in powers])
            dx = np.diff(xb, axis=0)
        return np.column_stack([np.ones(dy.size), dx])

    def rss(t: np.ndarray) -> float:
        d = design(t)
        r = dy - d @ np.linalg.lstsq(d, dy, rcond=None)[0]
        return float(r @ r)

    tau, tau_iv, dbic = 0.0, (0.0, 0.0), math.nan
    if lag not in (False, "none") and not segments:
        block_s = (y.size // BLOCKS) / fs
        tau, tau_iv, dbic = _profile_lag(temp, fs, block_s, rss, dy.size, level)
        if not (lag is True or dbic < 0):
            tau, tau_iv = 0.0, (0.0, 0.0)
    dx = design(lagged_temperature(temp, tau, fs) if tau > 0 else temp)
    beta, *_ = np.linalg.lstsq(dx, dy, rcond=None)
    resid = dy - dx @ beta
    jac = dx
    if tau > 0:  # tau estimated too: its column (d/d log tau) in the sandwich widens the SEs
        h = 0.05
        up = design(lagged_temperature(temp, tau * math.exp(h), fs))
        down = design(lagged_temperature(temp, tau * math.exp(-h), fs))
        jac = np.column_stack([dx, (up - down)[:, 1:] @ beta[1:] / (2 * h)])
    cov = _newey_west(jac, resid, NW_LAG)[: dx.shape[1], : dx.shape[1]]
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    coef, se_c = beta[1:], se[1:]
    from scipy import stats

    # the joint Wald test that every temperature coefficient is 0 (degree 1: (c / se)^2)
    wald = float(coef @ np.linalg.lstsq(cov[1:, 1:], coef, rcond=None)[0])
    p_value = float(stats.chi2.sf(wald, degree))
    applied = compensate is True or p_value < 1 - level
    notes: list[str] = []
    cond = np.linalg.cond(dx)
    if cond > 1e6:
        notes.append(
            "the temperature changes at a constant rate over the log: its effect cannot be told "
            "from a drift (DR)"
        )
    z = float(stats.norm.ppf(0.5 + level / 2))
    sens, sunit = temperature_sensitivity(float(coef[0]), unit, channel)
    lo, _ = temperature_sensitivity(float(coef[0] - z * se_c[0]), unit, channel)
    hi, _ = temperature_sensitivity(float(coef[0] + z * se_c[0]), unit, channel)
    tf = TemperatureFit(
        channel,
        temperature,
        unit,
        degree,
        t_ref,
        coef,
        se_c,
        float(beta[0]) / bl,
        level,
        (float(np.min(still)), float(np.max(still))),
        sens,
        (min(lo, hi), max(lo, hi)),
        sunit,
        notes=tuple(notes),
        tau_s=tau,
        tau_interval=tau_iv,
        lag_bic=dbic,
        fs=float(fs),
        applied=applied,
        p_value=p_value,
    )
    kw: dict[str, Any] = {
        "fs": fs,
        "levels": levels,
        "unit": unit,
        "robust": robust,
        "eff": eff,
        "alpha": alpha,
    }

    def wv_of(x: np.ndarray) -> WaveletVariance:
        if segments:  # the still parts pooled, as ImuLog.wavelet_variance does
            return pooled_wavelet_variance([x[lo:hi] for lo, hi in parts], **kw)
        return wavelet_variance(x, **kw)

    # not applied: the raw WV is the one to fit, and none is drawn beside it
    raw = wv_of(y)
    wv = wv_of(tf.compensate(y, temp)) if applied else raw
    wv_raw = raw if applied else None
    fit = fit_raw = None
    if model is not None:
        fit = fit_gmwm(wv, model, weights=weights)
        fit_raw = fit_gmwm(wv_raw, model, weights=weights) if wv_raw is not None else None
    return TemperatureFit(
        **{**tf.__dict__, "fit": fit, "fit_raw": fit_raw, "wv": wv, "wv_raw": wv_raw}
    )
