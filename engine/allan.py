"""Allan variance and the slope method (AVSM); the common form of the estimators.

These are the *other* estimators of a latent error model, kept for comparison and teaching:

* :func:`allan_variance`: overlapping Allan variance and deviation with intervals. With
  ``m`` the averaging time in samples and ``S`` the cumulative sum of the de-meaned series,
  ``AVAR(m) = sum_t (S_{t+2m} - 2 S_{t+m} + S_t)^2 / (2 m^2 (N - 2m + 1))``, which is exactly
  twice the Haar wavelet variance at scale ``tau = 2m`` (CONVENTIONS: ``nu2_j = AVAR(2^(j-1))/2``).
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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import special

from .fit import GMWMResult
from .models import Model, Process
from .units import BI_FACTOR, QUANTITIES, datasheet, param_unit, process_from_values
from .wv import (
    WaveletVariance,
    as_series,
    cumsum_demeaned,
    default_levels,
    eta3_interval,
    second_difference_sums,
)

__all__ = [
    "AllanVariance",
    "allan_variance",
    "MethodEstimate",
    "from_gmwm",
    "avsm",
    "avsm_auto",
    "compare_table",
    "BI_FACTOR",
    "SLOPES",
    "READ_TAU",
]

#: Slopes of the log-log Allan *deviation* of each process (IEEE Std 952, annex C).
SLOPES: dict[str, float] = {"QN": -1.0, "WN": -0.5, "BI": 0.0, "RW": 0.5, "DR": 1.0}

#: Averaging time (s) at which the fixed-slope line equals the datasheet coefficient:
#: ``ADEV^2 = 3Q^2/T^2`` (Q at sqrt 3 s), ``N^2/T`` (N at 1 s), ``K^2 T/3`` (K at 3 s),
#: ``R^2 T^2/2`` (R at sqrt 2 s).
READ_TAU: dict[str, float] = {"QN": math.sqrt(3.0), "WN": 1.0, "RW": 3.0, "DR": math.sqrt(2.0)}

_AVSM_ORDER = ("QN", "WN", "BI", "RW", "DR")


# -------------------------------------------------------------------------------------------
# Allan variance
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class AllanVariance:
    """Overlapping Allan variance of one series, with its ``1 - alpha`` interval.

    Attributes
    ----------
    tau_samples : ndarray of int, shape (K,)
        Averaging times ``m`` in samples (increasing).
    avar, ci_low, ci_high : ndarray of float, shape (K,)
        Allan variance and its interval, in (signal unit)^2.
    n_terms : ndarray of int, shape (K,)
        Number of overlapping differences summed, ``N - 2m + 1``.
    n : int
        Series length (samples).
    fs : float
        Sampling frequency (Hz).
    alpha : float
        Interval level ``1 - alpha``.
    interval : str
        ``"chi2"`` (chi-square, Percival's eta3 degrees of freedom) or ``"rel"`` (the
        ``1/sqrt(2 (N/m - 1))`` relative error of the inertial-sensor literature).
    unit : str
        Signal unit (the AVAR is in unit^2).
    """

    tau_samples: np.ndarray
    avar: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    n_terms: np.ndarray
    n: int
    fs: float = 1.0
    alpha: float = 0.05
    interval: str = "chi2"
    unit: str = ""

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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "n": int(self.n),
            "fs": float(self.fs),
            "tau_samples": [int(v) for v in self.tau_samples],
            "tau_s": [float(v) for v in self.tau_s],
            "avar": [float(v) for v in self.avar],
            "adev": [float(v) for v in self.adev],
            "ci_low": [float(v) for v in self.ci_low],
            "ci_high": [float(v) for v in self.ci_high],
            "adev_low": [float(v) for v in self.adev_low],
            "adev_high": [float(v) for v in self.adev_high],
            "n_terms": [int(v) for v in self.n_terms],
            "alpha": float(self.alpha),
            "interval": self.interval,
            "unit": self.unit,
        }

    def table(self) -> str:
        """Readable table with units."""
        u = self.unit or "u"
        ci = f"{100 * (1 - self.alpha):g}%"
        lines = [
            f"Overlapping Allan deviation; N = {self.n} samples, fs = {self.fs:g} Hz, "
            f"{ci} interval: {self.interval}",
            f"{'m [samples]':>12} {'tau [s]':>12} {'ADEV [' + u + ']':>16} {ci + ' low':>12} "
            f"{ci + ' high':>12} {'terms':>10}",
        ]
        for i in range(len(self)):
            lines.append(
                f"{self.tau_samples[i]:>12d} {self.tau_s[i]:>12.5g} {self.adev[i]:>16.6e} "
                f"{self.adev_low[i]:>12.4e} {self.adev_high[i]:>12.4e} {self.n_terms[i]:>10d}"
            )
        return "\n".join(lines)


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
    """
    a = as_series(x)
    n = a.size
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"fs must be a positive number of Hz, got {fs}")
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
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


# -------------------------------------------------------------------------------------------
# the common result form
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MethodEstimate:
    """One estimator's answer, in the form shared by GMWM, ARMAV/GMWFM and the slope method.

    Attributes
    ----------
    method : str
        ``"GMWM"``, ``"ARMAV"``, ``"GMWFM(f)"``, ``"AVSM"`` or ``"AVSM-auto"``.
    model : Model
        The processes the method estimated, every value set (per-sample parameters, as
        everywhere in the engine).
    params : dict[str, float]
        Values by the engine's unique names (``WN.sigma2``, ``QN.q2``, ``RW.gamma2``,
        ``DR.omega``, ``GM_1.beta`` ...).
    tau_samples : ndarray of int, shape (J,)
        The empirical Haar WV scales (samples); for an Allan variance, ``2m``.
    implied : ndarray, shape (J,)
        The WV the estimate implies at those scales (half the implied AVAR at ``m = tau/2``).
    components : dict[str, ndarray]
        Implied WV of each process by label (``WN``, ``GM_1`` ...; ``BI`` for the slope
        method's bias-instability floor), summing to ``implied``.
    fs : float
        Sampling frequency (Hz).
    unit : str
        Signal unit.
    extras : dict[str, float]
        Quantities outside the engine's processes, e.g. ``BI.B``: the bias instability B
        [unit] of the slope method (flicker noise, whose AVAR floor is ``(0.664 B)^2``).
    objective : float or None
        The minimised objective (GMWM/GMWFM), None for the slope methods.
    notes : tuple of str
        How the estimate was made (weights, regions, slopes found ...).
    details : dict
        JSON-ready method-specific data; for the slope methods ``lines``: per process the
        fitted line ``log10 ADEV = intercept + slope log10 tau_s`` over ``[tau_lo, tau_hi]``
        seconds with the averaging time and value read off it.
    """

    method: str
    model: Model
    params: dict[str, float]
    tau_samples: np.ndarray
    implied: np.ndarray
    components: dict[str, np.ndarray]
    fs: float
    unit: str = ""
    extras: dict[str, float] = field(default_factory=dict)
    objective: float | None = None
    notes: tuple[str, ...] = ()
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def tau_s(self) -> np.ndarray:
        """WV scales in seconds."""
        return self.tau_samples / self.fs

    @property
    def implied_avar(self) -> np.ndarray:
        """Implied Allan variance at averaging times ``tau_samples / 2``."""
        return 2.0 * self.implied

    @property
    def implied_adev(self) -> np.ndarray:
        """Implied Allan deviation at averaging times ``tau_samples / 2``."""
        return np.sqrt(2.0 * self.implied)

    def implied_at(self, tau_samples: np.ndarray) -> np.ndarray:
        """Implied WV at other scales (samples), e.g. for a smooth curve."""
        tau = np.asarray(tau_samples, dtype=float)
        out = self.model.wv(tau, self.fs) if len(self.model) else np.zeros_like(tau)
        b = self.extras.get("BI.B")
        if b is not None:
            out = out + 0.5 * (BI_FACTOR * b) ** 2
        return out

    def datasheet(self) -> list[dict[str, Any]]:
        """Datasheet rows (see :func:`engine.datasheet`), plus the bias instability if any."""
        return datasheet(self.model, self.fs, self.unit, extras=self.extras)

    def summary(self) -> str:
        """Readable summary: method, parameters with units, datasheet view, notes."""
        lines = [
            f"{self.method} estimate of {self.model.spec() or '(no process)'}",
            f"  fs = {self.fs:g} Hz, {self.tau_samples.size} scales",
        ]
        if self.objective is not None:
            lines[-1] += f", objective = {self.objective:.6g}"
        lines += ["", f"  {'parameter':<16} {'value':>14}  unit"]
        for name, v in self.params.items():
            lab, pname = name.split(".", 1)
            code = lab.split("_")[0]
            lines.append(f"  {name:<16} {v:>14.6e}  {param_unit(code, pname, self.unit)}")
        for name, v in self.extras.items():
            lines.append(f"  {name:<16} {v:>14.6e}  {self.unit or 'u'}")
        ds = self.datasheet()
        if ds:
            lines += ["", "  datasheet view:"]
            for row in ds:
                lines.append(
                    f"  {row['label']:<8} {row['quantity']:<40} {row['symbol']:<8} "
                    f"{row['value']:>12.5g}  {row['unit']}"
                )
        if self.notes:
            lines += [""] + [f"  note: {s}" for s in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "method": self.method,
            "model": self.model.spec(),
            "model_values": self.model.spec(values=True),
            "params": {k: float(v) for k, v in self.params.items()},
            "extras": {k: float(v) for k, v in self.extras.items()},
            "fs": float(self.fs),
            "unit": self.unit,
            "tau_samples": [int(v) for v in self.tau_samples],
            "implied": [float(v) for v in self.implied],
            "components": {k: [float(x) for x in v] for k, v in self.components.items()},
            "objective": None if self.objective is None else float(self.objective),
            "notes": list(self.notes),
            "details": self.details,
        }


def from_gmwm(res: GMWMResult, method: str = "GMWM") -> MethodEstimate:
    """A GMWM fit in the common form (same model, parameters, implied WV and components)."""
    notes = [f"GMWM, weights {res.weights}, {res.method}"]
    if res.at_bound:
        notes.append(f"at a bound: {', '.join(res.at_bound)}")
    return MethodEstimate(
        method=method,
        model=res.model,
        params=dict(res.params),
        tau_samples=np.asarray(res.wv.tau_samples),
        implied=np.asarray(res.implied),
        components=dict(res.components),
        fs=float(res.wv.fs),
        unit=res.wv.unit,
        objective=float(res.objective),
        notes=tuple(notes),
        details={"weights": res.weights, "at_bound": list(res.at_bound)},
    )


def _components(model: Model, tau: np.ndarray, fs: float) -> dict[str, np.ndarray]:
    return model.components(tau, fs) if len(model) else {}


# -------------------------------------------------------------------------------------------
# slope method
# -------------------------------------------------------------------------------------------
def _as_allan(data: Any, fs: float | None, unit: str) -> AllanVariance:
    if isinstance(data, AllanVariance):
        return data
    if isinstance(data, WaveletVariance):
        return AllanVariance.from_wv(data if not data.robust else data.classical)
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
    comps = _components(model, tau, av.fs)
    if "BI.B" in extras:
        comps["BI"] = np.full(tau.shape, 0.5 * (BI_FACTOR * extras["BI.B"]) ** 2)
    implied = np.sum(np.array(list(comps.values())), axis=0) if comps else np.zeros(tau.shape)
    return MethodEstimate(
        method=method,
        model=model,
        params=model.values(),
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
    for code in ("WN", "RW"):
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


# -------------------------------------------------------------------------------------------
# side by side
# -------------------------------------------------------------------------------------------
def compare_table(estimates: Sequence[MethodEstimate], truth: Model | None = None) -> str:
    """A text table of the parameters of several estimates (and the truth), side by side."""
    names: list[str] = []
    for e in estimates:
        for k in list(e.params) + list(e.extras):
            if k not in names:
                names.append(k)
    tv = truth.values() if truth is not None else {}
    for k in tv:
        if k not in names:
            names.append(k)
    heads = [e.method for e in estimates] + (["truth"] if truth is not None else [])
    lines = [f"{'parameter':<14}" + "".join(f"{h:>14}" for h in heads)]
    for k in names:
        row = f"{k:<14}"
        for e in estimates:
            v = e.params.get(k, e.extras.get(k))
            row += f"{v:>14.5e}" if v is not None else f"{'-':>14}"
        if truth is not None:
            v = tv.get(k)
            row += f"{v:>14.5e}" if v is not None else f"{'-':>14}"
        lines.append(row)
    return "\n".join(lines)
