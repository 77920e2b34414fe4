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

The GMWM is then fitted on ``y_t - sum_p c_p (T_t - T_ref)^p``; :class:`TemperatureFit`
keeps both wavelet variances (raw and compensated). Sensitivities are reported in datasheet
units: deg/h per degC for gyroscopes, mg per degC for accelerometers (``engine.units``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..fit import GMWMResult, fit_gmwm
from ..io import ImuLog, LoadError
from ..io.timecols import is_temperature
from ..models import Model
from ..units import ExportError, si_factor
from ..wv import WaveletVariance

__all__ = ["TemperatureFit", "fit_temperature", "temperature_sensitivity", "find_temperature"]

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
        The GMWM of the compensated signal, and of the raw one (same model).
    wv, wv_raw : WaveletVariance
        Their wavelet variances.
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

    @property
    def interval(self) -> np.ndarray:
        """``(degree, 2)`` intervals of :attr:`coef` (normal quantile at ``level``)."""
        from scipy import stats

        z = float(stats.norm.ppf(0.5 + self.level / 2))
        return np.column_stack([self.coef - z * self.se, self.coef + z * self.se])

    def line(self) -> str:
        """One line: the sensitivity with its interval and the temperature range."""
        lo, hi = self.sensitivity_interval
        t0, t1 = self.temperature_range
        return (
            f"{self.channel}: temperature sensitivity {self.sensitivity:.4g} "
            f"[{lo:.4g}, {hi:.4g}] {self.sensitivity_unit} ({100 * self.level:g} %, "
            f"'{self.temperature}' from {t0:.3g} to {t1:.3g} degC)"
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
            "wv_raw": self.wv_raw.to_dict() if self.wv_raw is not None else None,
            "notes": list(self.notes),
            "summary": self.line(),
        }

    def compensate(self, y: np.ndarray, temp: np.ndarray) -> np.ndarray:
        """``y - sum_p c_p (T - T_ref)^p``."""
        dt = np.asarray(temp, dtype=float) - self.t_ref
        out = np.asarray(y, dtype=float).copy()
        for p, c in enumerate(self.coef, start=1):
            out -= c * dt**p
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


def _block_means(a: np.ndarray, k: int) -> np.ndarray:
    b = a.size // k
    return a[: b * k].reshape(k, b).mean(axis=1)


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
) -> TemperatureFit:
    """Fit the bias-temperature polynomial, then the GMWM of the compensated signal.

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

    Returns
    -------
    TemperatureFit

    Raises
    ------
    ValueError
        Lengths differ, NaN temperatures, a constant temperature, fewer than 16 x 256 samples,
        or a degree other than 1 or 2.
    """
    from ..wv import wavelet_variance

    y = np.asarray(y, dtype=float)
    temp = np.asarray(temp, dtype=float)
    if degree not in (1, 2):
        raise ValueError(f"degree must be 1 or 2, got {degree}")
    if y.shape != temp.shape or y.ndim != 1:
        raise ValueError(
            f"the temperature '{temperature}' has {temp.size} samples and {channel} "
            f"{y.size}: they must be sampled together"
        )
    if y.size < 16 * BLOCKS:
        raise ValueError(f"{channel}: {y.size} samples are too few for a temperature fit (4096)")
    if not np.all(np.isfinite(temp)):
        raise ValueError(f"the temperature '{temperature}' has NaN/Inf samples")
    if np.ptp(temp) == 0:
        raise ValueError(f"the temperature '{temperature}' is constant: nothing to fit")
    t_ref = float(np.mean(temp))
    dt = temp - t_ref
    yb = _block_means(y, BLOCKS)
    xb = np.column_stack([_block_means(dt**p, BLOCKS) for p in range(1, degree + 1)])
    dy = np.diff(yb)
    dx = np.column_stack([np.ones(dy.size), np.diff(xb, axis=0)])
    beta, *_ = np.linalg.lstsq(dx, dy, rcond=None)
    resid = dy - dx @ beta
    cov = _newey_west(dx, resid, NW_LAG)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    b = y.size // BLOCKS
    coef, se_c = beta[1:], se[1:]
    notes: list[str] = []
    cond = np.linalg.cond(dx)
    if cond > 1e6:
        notes.append(
            "the temperature changes at a constant rate over the log: its effect cannot be told "
            "from a drift (DR)"
        )
    from scipy import stats

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
        float(beta[0]) / b,
        level,
        (float(np.min(temp)), float(np.max(temp))),
        sens,
        (min(lo, hi), max(lo, hi)),
        sunit,
        notes=tuple(notes),
    )
    yc = tf.compensate(y, temp)
    kw: dict[str, Any] = {
        "fs": fs,
        "levels": levels,
        "unit": unit,
        "robust": robust,
        "eff": eff,
        "alpha": alpha,
    }
    wv = wavelet_variance(yc, **kw)
    wv_raw = wavelet_variance(y, **kw)
    fit = fit_raw = None
    if model is not None:
        fit = fit_gmwm(wv, model, weights=weights)
        fit_raw = fit_gmwm(wv_raw, model, weights=weights)
    return TemperatureFit(
        **{**tf.__dict__, "fit": fit, "fit_raw": fit_raw, "wv": wv, "wv_raw": wv_raw}
    )
