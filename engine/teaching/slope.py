"""Allan variance and the slope method (AVSM); the common form of the estimators.

These are the *other* estimators of a latent error model, kept for comparison and teaching:

* :func:`allan_variance`: overlapping Allan variance and deviation with intervals. With
  ``m`` the averaging time in samples and ``S`` the cumulative sum of the de-meaned series,
  ``AVAR(m) = sum_t (S_{t+2m} - 2 S_{t+m} + S_t)^2 / (2 m^2 (N - 2m + 1))``, which is exactly
  twice the Haar wavelet variance at scale ``tau = 2m``
  (``docs/conventions.md``: ``nu2_j = AVAR(2^(j-1))/2``).
  The divisor counts the ``N - 2m + 1`` terms actually summed (the R ``avar`` package sums one
  term fewer than its divisor counts; that defect is not reproduced).
* :func:`avsm`: the Allan variance slope method as IEEE Std 952 reads it: a line of fixed
  slope through a user-chosen region of the log-log Allan deviation, read at a fixed
  averaging time; :func:`avsm_auto`: the "automatic" read-off of the ROS calibration tools.
* the wavelet functional moments (ARMAV, GMWFM) are in :mod:`engine.fit.gmwfm`.

Every estimator returns a :class:`MethodEstimate`, the common form that the app and the Monte
Carlo study put side by side; :func:`from_gmwm` converts a GMWM fit to it.

References: IEEE Std 952-1997, annex C; El-Sheimy, Hou & Niu (2008), IEEE TIM 57(1);
Guerrier, Jurado, Khaghani et al. (2020), IEEE TIM (the GMWM paper); Jurado, Schubert Kabban
& Raquet (2019), NAVIGATION 66(1).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..fit.estimate import MethodEstimate, model_components
from ..models import PROCESS_TYPES, RW, WN, Model, Process
from ..units import BI_FACTOR, QUANTITIES, process_from_values
from ..wv import (
    WaveletVariance,
)
from ..wv.allan import AllanVariance, allan_variance

__all__ = ["avsm", "avsm_auto", "SLOPES", "READ_TAU"]


def _sloped() -> dict[str, tuple[float, float]]:
    """The slope method's terms that are processes (those with one Allan-deviation slope):
    ``{code: (allan_slope, read_tau)}``."""
    out = {}
    for cls in PROCESS_TYPES.values():
        if cls.allan_slope is None:
            continue
        if cls.read_tau is None:
            raise TypeError(f"process {cls.code} has an allan_slope but no read_tau")
        out[cls.code] = (cls.allan_slope, cls.read_tau)
    return out


_SLOPED = _sloped()

#: Slopes of the log-log Allan *deviation* of each term (IEEE Std 952, annex C): each process's
#: :attr:`~engine.models.Process.allan_slope` (QN -1, WN -1/2, RW +1/2, DR +1) and the bias
#: instability ``BI`` (a floor, slope 0; not a process of the model), in slope order.
SLOPES: dict[str, float] = dict(
    sorted(
        {**{code: slope for code, (slope, _) in _SLOPED.items()}, "BI": 0.0}.items(),
        key=lambda kv: kv[1],
    )
)

#: Averaging time (s) at which the fixed-slope line equals the datasheet coefficient (each
#: process's :attr:`~engine.models.Process.read_tau`): ``ADEV^2 = 3Q^2/T^2`` (Q at sqrt 3 s),
#: ``N^2/T`` (N at 1 s), ``K^2 T/3`` (K at 3 s), ``R^2 T^2/2`` (R at sqrt 2 s).
READ_TAU: dict[str, float] = {code: tau for code, (_, tau) in _SLOPED.items()}

_AVSM_ORDER = tuple(SLOPES)


# -------------------------------------------------------------------------------------------
# slope method
# -------------------------------------------------------------------------------------------
def _as_allan(data: Any, fs: float | None, unit: str) -> AllanVariance:
    if isinstance(data, AllanVariance):
        return data
    if isinstance(data, WaveletVariance):
        classical = data.classical if data.robust else data
        if classical is None:
            raise ValueError(
                "data: this robust WaveletVariance carries no classical WV (it was built from "
                "stored values); the slope method reads the Allan variance, so give the series "
                "or a classical WaveletVariance"
            )
        return AllanVariance.from_wv(classical)
    return allan_variance(data, fs=1.0 if fs is None else fs, unit=unit)


def _slope_estimate(
    av: AllanVariance, lines: dict[str, dict[str, Any]], method: str, notes: list[str]
) -> MethodEstimate:
    """Build the estimate from fitted lines ``{code: {"intercept", "slope", ...}}``."""
    procs: list[Process] = []
    extras: dict[str, float] = {}
    u = av.unit or "u"
    for code in _AVSM_ORDER:
        if code not in lines:
            continue
        ln = lines[code]
        q = QUANTITIES[code][0]  # the datasheet coefficient the line reads (N, Q, K, R, B)
        if code == "BI":
            value = 10.0 ** ln["intercept"] / BI_FACTOR
            extras["BI.B"] = value
            ln["read_tau_s"] = None
        else:
            t = READ_TAU[code]
            value = 10.0 ** (ln["intercept"] + ln["slope"] * math.log10(t))
            ln["read_tau_s"] = t
            procs.append(process_from_values(code, {q.symbol: value}, av.fs))
        ln["reading"] = {"name": q.symbol, "value": float(value), "unit": q.unit(u)}
    model = Model(tuple(procs))
    tau = av.wv_tau_samples
    comps = model_components(model, tau, av.fs)
    if "BI.B" in extras:
        comps["BI"] = np.full(tau.shape, 0.5 * (BI_FACTOR * extras["BI.B"]) ** 2)
    implied = np.sum(np.array(list(comps.values())), axis=0) if comps else np.zeros(tau.shape)
    return MethodEstimate(
        method=method,
        model=model,
        params={k: v for k, v in model.values().items() if v is not None},  # all set
        tau_samples=tau,
        implied=implied,
        components=comps,
        fs=av.fs,
        unit=av.unit,
        extras=extras,
        objective=None,
        notes=tuple(notes),
        details={"lines": lines},
    )


def avsm(
    data: AllanVariance | WaveletVariance | Any,
    regions: Mapping[str, tuple[float, float]],
    *,
    fs: float | None = None,
    unit: str = "",
) -> MethodEstimate:
    """The Allan variance slope method, read as IEEE Std 952 does.

    For each process, a line of the process's fixed slope is fitted by least squares to the
    log10 Allan deviation over the chosen region of averaging times (with a fixed slope the
    intercept is the mean of ``log10 ADEV - slope log10 tau``), and the datasheet coefficient
    is the line's value at a fixed averaging time:

    ========  ===========  ====================  ===========================================
    process   ADEV slope   read at               engine parameter
    ========  ===========  ====================  ===========================================
    QN        -1           Q at tau = sqrt(3) s  ``q2 = (Q fs)^2``
    WN        -1/2         N at tau = 1 s        ``sigma2 = N^2 fs``
    BI        0            floor / 0.664 = B     extra ``BI.B`` (no engine process)
    RW        +1/2         K at tau = 3 s        ``gamma2 = K^2 / fs``
    DR        +1           R at tau = sqrt(2) s  ``omega = R / fs``
    ========  ===========  ====================  ===========================================

    Parameters
    ----------
    data : AllanVariance, WaveletVariance or array_like
        An Allan variance, a classical WV (its octave AVAR ``2 nu2`` is used) or a raw series
        (its octave AVAR is computed with ``fs``).
    regions : mapping of str to (float, float)
        Averaging-time region in **seconds**, inclusive, per process code among ``QN``,
        ``WN``, ``BI``, ``RW``, ``DR``; ``math.inf`` is allowed as the upper end. Each region
        must contain at least one averaging time of ``data``.
    fs : float, optional
        Sampling frequency (Hz) of a raw series.
    unit : str
        Signal unit of a raw series.

    Returns
    -------
    MethodEstimate
        ``method="AVSM"``; ``details["lines"]`` holds each fitted line for plotting.

    Notes
    -----
    The slope method ignores every process but the one it reads in a region: where
    processes overlap, or where few clusters make the Allan deviation noisy (its last
    points), it is biased and does not improve with the log length (the GMWM paper, sec. I).
    The log-average over a region is itself biased low by Jensen's inequality.
    """
    av = _as_allan(data, fs, unit)
    if not regions:
        raise ValueError("give at least one region, e.g. {'WN': (0.01, 10.0)} (seconds)")
    lines: dict[str, dict[str, Any]] = {}
    x = np.log10(av.tau_s)
    with np.errstate(divide="ignore"):
        y = np.log10(av.adev)
    for code, reg in regions.items():
        if code not in SLOPES:
            raise ValueError(
                f"unknown process {code!r} for the slope method; use one of "
                f"{', '.join(_AVSM_ORDER)}"
            )
        lo, hi = (float(v) for v in reg)
        if not (lo <= hi and lo >= 0):
            raise ValueError(f"region {code}=({lo}, {hi}) s is not an interval of averaging times")
        sel = (av.tau_s >= lo * (1 - 1e-9)) & (av.tau_s <= hi * (1 + 1e-9)) & np.isfinite(y)
        if not np.any(sel):
            raise ValueError(
                f"region {code}=({lo:g}, {hi:g}) s holds no averaging time of the Allan "
                f"variance (available: {av.tau_s[0]:g} to {av.tau_s[-1]:g} s)"
            )
        slope = SLOPES[code]
        b = float(np.mean(y[sel] - slope * x[sel]))
        lines[code] = {
            "slope": slope,
            "intercept": b,
            "tau_lo": float(av.tau_s[sel][0]),
            "tau_hi": float(av.tau_s[sel][-1]),
            "n_points": int(np.sum(sel)),
        }
    notes = [
        f"slope method (IEEE Std 952) on {av.interval} Allan deviation at {len(av)} averaging times"
    ]
    notes += [
        f"{c}: slope {ln['slope']:+g} over {ln['tau_lo']:.4g}-{ln['tau_hi']:.4g} s "
        f"({ln['n_points']} points)"
        for c, ln in lines.items()
    ]
    return _slope_estimate(av, lines, "AVSM", notes)


def avsm_auto(
    data: AllanVariance | WaveletVariance | Any,
    *,
    fs: float | None = None,
    unit: str = "",
    read: str = "line",
) -> MethodEstimate:
    """The "automatic" slope read-off of the ROS IMU-calibration tools.

    ``read="line"`` (default), as in the MathWorks example *Inertial sensor noise analysis
    using Allan variance* that ROS tools such as ``imu_utils`` and ``allan_variance_ros``
    follow: the local log-log slope between consecutive points of the Allan deviation is
    computed; the point where it is closest to -1/2 carries a line of slope -1/2, read at
    tau = 1 s (white noise N); the point where it is closest to +1/2 carries a line of slope
    +1/2, read at tau = 3 s (random walk K). ``read="curve"``: N and K are the Allan deviation
    curve itself at 1 s and 3 s (log-log interpolation, clamped to the measured range), as
    many users read a Kalibr noise density. Either way the bias instability is the smallest
    Allan deviation divided by 0.664.

    Parameters
    ----------
    data : AllanVariance, WaveletVariance or array_like
        As for :func:`avsm`. Dense averaging times (e.g. ``allan_variance(x, taus="decade")``
        or a log-spaced array) mimic the tools more closely; octave times work too.
    fs, unit
        For a raw series.
    read : {"line", "curve"}
        Where the values are read (see above).

    Returns
    -------
    MethodEstimate
        ``method="AVSM-auto"`` with ``WN``, ``RW`` and the extra ``BI.B``.
    """
    av = _as_allan(data, fs, unit)
    if len(av) < 2:
        raise ValueError("the automatic read-off needs at least two averaging times")
    x = np.log10(av.tau_s)
    with np.errstate(divide="ignore"):
        y = np.log10(av.adev)
    if not np.all(np.isfinite(y)):
        raise ValueError("the Allan deviation is zero at some averaging time (constant signal?)")
    if read not in ("line", "curve"):
        raise ValueError(f"read must be 'line' or 'curve', got {read!r}")
    local = np.diff(y) / np.diff(x)
    lines: dict[str, dict[str, Any]] = {}
    if read == "line":
        notes = [
            "automatic read-off (ROS tools / MathWorks example): line through the point "
            "of closest local slope"
        ]
    else:
        notes = ["automatic read-off of the Allan deviation curve at 1 s (N) and 3 s (K)"]
    for code in (WN.code, RW.code):
        slope = SLOPES[code]
        if read == "line":
            i = int(np.argmin(np.abs(local - slope)))
            lines[code] = {
                "slope": slope,
                "intercept": float(y[i] - slope * x[i]),
                "tau_lo": float(av.tau_s[i]),
                "tau_hi": float(av.tau_s[i + 1]),
                "n_points": 1,
                "local_slope": float(local[i]),
            }
            notes.append(
                f"{code}: closest local slope {local[i]:+.3f} (target {slope:+g}) at "
                f"{av.tau_s[i]:.4g} s"
            )
        else:
            lt = math.log10(READ_TAU[code])
            yt = float(np.interp(lt, x, y))
            lines[code] = {
                "slope": slope,
                "intercept": yt - slope * lt,
                "tau_lo": READ_TAU[code],
                "tau_hi": READ_TAU[code],
                "n_points": 1,
            }
            if not x[0] <= lt <= x[-1]:
                notes.append(
                    f"{code}: {READ_TAU[code]:g} s is outside the measured averaging "
                    "times; the nearest end was read"
                )
    k = int(np.argmin(y))
    lines["BI"] = {
        "slope": 0.0,
        "intercept": float(y[k]),
        "tau_lo": float(av.tau_s[k]),
        "tau_hi": float(av.tau_s[k]),
        "n_points": 1,
    }
    return _slope_estimate(av, lines, "AVSM-auto", notes)
