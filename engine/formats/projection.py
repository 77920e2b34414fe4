"""From a fitted GMWM model to the noise model a navigation filter assumes: projection,
over-bound and the uncertainty of every exported number (:func:`project`).

``project(fit, consumer, ...)`` maps a fit onto a consumer model (``"WN+RW"``, ``"WN+GM"``,
``"WN"`` or a format name of :data:`FORMAT_CONSUMERS`) by one rule: an AR1/GM faster than the
filter's step joins the white noise, slower terms, RW and drift form the consumer's bias. With
``bound=True`` (the filter formats' default) the consumer's parameters are then chosen so that
its WV covers the fitted model's at every scale of the band with the least inflation
(:mod:`engine.formats.bound`). :class:`Projection` holds per exported parameter its value, the
plain conversion, the factor between them, the binding scale and a delta-method interval. The
rule, the bound, the factor and the intervals in detail: docs/methods.md, "The projection onto
a filter's noise model"; the user's view and the filter tests: docs/fit-to-filter.md.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from statistics import NormalDist
from typing import Any

import numpy as np

from ..fit import GMWMResult
from ..models import Model
from ..units import SI_UNIT, ExportError, si_factor
from .bound import (
    POINTS_PER_OCTAVE,
    Split,
    columns,
    fine_scales,
    floor_at,
    nearby_solutions,
    solve,
    solve_at_tcs,
    split_terms,
)
from .catalog import CONSUMER_PARAMS, FORMAT_CONSUMERS
from .options import DATA_BOUNDS
from .tails import TAIL_SPAN, TailFactors, tail_band

__all__ = [
    "DATA_BOUNDS",
    "MISFIT_SHARE",
    "misfit",
    "CONSUMER_PARAMS",
    "FORMAT_CONSUMERS",
    "ProjectedParam",
    "Projection",
    "project",
    "log_inflation_at_tc",
    "consumer_of",
]

#: A fit disagrees with its data when its WV is outside the empirical interval at more than
#: this share of the scales. If the fit were the truth, each scale would be outside with
#: probability 0.05 (the interval's level), so with J = 19 scales 7 or more outside has
#: binomial probability 2e-5. The share is not set lower because the best fits of real logs
#: are outside at a few scales too (the ADIS16405 gyro_x 2*GM+WN+RW fit at 5 of 19, where the
#: eta3 interval is a few percent wide); its WN+RW fit is outside at 14 of 19.
MISFIT_SHARE = 1.0 / 3.0

#: The sandwich covariance of each fit's free parameters (fits are immutable).
_COV: weakref.WeakKeyDictionary[GMWMResult, np.ndarray] = weakref.WeakKeyDictionary()

#: Each fit's projections by :func:`project`'s arguments (fits, tail factors and projections are
#: immutable): the export menu's preview and the download after it, or two formats of the same
#: consumer, project once.
_PROJECTIONS: weakref.WeakKeyDictionary[GMWMResult, dict[tuple[Any, ...], Projection]] = (
    weakref.WeakKeyDictionary()
)


def misfit(fit: GMWMResult, channel: str = "") -> str:
    """One line when the fitted WV is outside the empirical interval at more than
    :data:`MISFIT_SHARE` of the scales (``""`` otherwise): how many scales, below and above,
    and the smallest ratio fitted / empirical WV with its scale.

    Examples
    --------
    >>> import numpy as np
    >>> import engine as eg
    >>> m = eg.parse_model("WN(1e-6) + GM(beta=0.5, sigma2_gm=1e-6)")
    >>> x = m.simulate(2**15, rng=np.random.default_rng(3), fs=100.0)
    >>> misfit(eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0), "WN"), "gyro_x")[:60]
    'gyro_x (WN): model and data disagree: the fitted WV is outsi'
    """
    wv = fit.wv
    tau = np.asarray(wv.tau_samples, float)
    lo, hi = np.asarray(wv.ci_low, float), np.asarray(wv.ci_high, float)
    mw = fit.model.wv(tau, float(fit.fs))
    below, above = mw < lo, mw > hi
    out = int(np.sum(below | above))
    if out <= MISFIT_SHARE * tau.size:
        return ""
    with np.errstate(divide="ignore", invalid="ignore"):
        r = mw / np.asarray(wv.variance, float)
    j = int(np.nanargmin(r))
    return (
        f"{channel or 'channel'} ({fit.model.spec()}): model and data disagree: the fitted WV "
        f"is outside the empirical {100 * (1 - wv.alpha):g} % interval at {out} of {tau.size} "
        f"scales ({int(np.sum(below))} below, {int(np.sum(above))} above; more than "
        f"{100 * MISFIT_SHARE:.3g} % flags a misfit), down to x{r[j]:.2g} of the empirical WV "
        f"at tau = {tau[j] / fit.fs:.4g} s"
    )


def consumer_of(consumer: str) -> str:
    """The consumer model (a key of :data:`CONSUMER_PARAMS`) of a model or format name."""
    c = consumer.strip()
    if c.upper() in CONSUMER_PARAMS:
        return c.upper()
    if c.lower() in FORMAT_CONSUMERS:
        return FORMAT_CONSUMERS[c.lower()]
    raise ExportError(
        f"unknown consumer {consumer!r}: use a consumer model ({', '.join(CONSUMER_PARAMS)}) "
        f"or a filter format ({', '.join(FORMAT_CONSUMERS)})"
    )


@dataclass(frozen=True)
class ProjectedParam:
    """One exported parameter.

    Attributes
    ----------
    name : str
        ``N``, ``K``, ``sigma_b`` or ``T_c``.
    value : float
        The exported value (bounded unless the projection is plain), before ``--inflate``.
    plain : float
        The plain conversion (the rule without the bound).
    unit : str
    factor : float
        ``value / plain`` (nan when the plain value is 0).
    binding_tau_s : float
        The WV scale (s) at which the bound is tight for this parameter (nan: not binding).
    binds : str
        The fitted term that dominates the target WV at that scale (``GM_1``), or why the
        value was set otherwise.
    low, high : float
        Its interval at ``level`` (nan when not computed or not identified).
    level : float
    """

    name: str
    value: float
    plain: float
    unit: str
    factor: float = math.nan
    binding_tau_s: float = math.nan
    binds: str = ""
    low: float = math.nan
    high: float = math.nan
    level: float = 0.95

    def describe(self) -> str:
        """``K = 1.2e-05 rad/s^2/sqrt(Hz) [9e-06, 1.6e-05] x3.1: bounds GM_1 at tau = 82 s``."""
        iv = (
            f" [{self.low:.4g}, {self.high:.4g}] ({100 * self.level:g} %)"
            if math.isfinite(self.low) and math.isfinite(self.high)
            else ""
        )
        s = f"{self.name} = {self.value:.6g} {self.unit}{iv}"
        if math.isfinite(self.factor):
            s += f"; x{self.factor:.3g} over the plain conversion {self.plain:.6g}"
        if math.isfinite(self.binding_tau_s):
            s += f"; binding at tau = {self.binding_tau_s:.4g} s ({self.binds})"
        elif self.binds:
            s += f"; {self.binds}"
        return s

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN as None)."""

        def f(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "name": self.name,
            "value": f(self.value),
            "plain": f(self.plain),
            "unit": self.unit,
            "factor": f(self.factor),
            "binding_tau_s": f(self.binding_tau_s),
            "binds": self.binds,
            "low": f(self.low),
            "high": f(self.high),
            "level": self.level,
        }


@dataclass(frozen=True, eq=False)
class Projection:
    """A fitted model projected onto a consumer's noise model (and bounded).

    Attributes
    ----------
    channel : str
    consumer : str
        ``WN+RW``, ``WN+GM`` or ``WN``.
    sensor : str or None
        ``gyroscope``, ``accelerometer`` or None (unknown unit: values in the log's unit).
    unit : str
        The signal unit of the values (``rad/s``, ``m/s^2`` or the log's).
    fs, fs_filter : float
        Log and filter rates (Hz).
    band : (float, float)
        WV scales (s) over which the bound holds.
    horizon_s : float
    confidence : float or None
        None: the bound is against the fitted WV; else its upper limit at this level.
    bounded : bool
        False: the plain conversion.
    params : dict of str to ProjectedParam
    assignment : dict of str to str
        Where each fitted term went and why.
    tau_s, fitted_wv, target_wv, consumer_wv : ndarray
        The scales of the band (s) and the WVs there (unit^2): fitted model, bound target,
        exported consumer model.
    notes, warnings : list of str
    data : str
        What of the empirical WV the bound covers too (a key of :data:`DATA_BOUNDS`;
        ``"none"``: the fitted model alone, or not bounded).
    misfit : str
        :func:`misfit` of the fit (``""`` when model and data agree).
    tail_factor, tail_tau_s, tail_level : float
        The largest tail factor (:mod:`engine.formats.tails`) applied to the data bound in the
        band, its scale (s; nan when none exceeds 1) and the quantile's two-sided level (nan:
        no tail factors).
    tail_band : (float, float) or None
        The scales (s) at which the tail factors apply when a horizon was given
        (:func:`~.tails.tail_band`: those near it); None: every scale of the band, or no tail
        factors.
    """

    channel: str
    consumer: str
    sensor: str | None
    unit: str
    fs: float
    fs_filter: float
    band: tuple[float, float]
    horizon_s: float
    confidence: float | None
    bounded: bool
    params: dict[str, ProjectedParam]
    assignment: dict[str, str]
    tau_s: np.ndarray
    fitted_wv: np.ndarray
    target_wv: np.ndarray
    consumer_wv: np.ndarray
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    data: str = "none"
    misfit: str = ""
    tail_factor: float = 1.0
    tail_tau_s: float = math.nan
    tail_level: float = math.nan
    tail_band: tuple[float, float] | None = None

    def value(self, name: str) -> float:
        """The exported value of parameter ``name``."""
        return self.params[name].value

    @property
    def per_sample(self) -> dict[str, float]:
        """Per filter step (``dt_f = 1/fs_filter``): ``sigma_N`` = ``N sqrt(fs_filter)``
        (std of the white noise averaged over a step), ``sigma_K`` = ``K / sqrt(fs_filter)``
        (std of the bias random walk's increment per step), ``phi_b`` = ``exp(-dt_f / T_c)``
        and ``sigma_b`` for a Gauss-Markov bias."""
        out = {"sigma_N": self.value("N") * math.sqrt(self.fs_filter)}
        if "K" in self.params:
            out["sigma_K"] = self.value("K") / math.sqrt(self.fs_filter)
        if "T_c" in self.params:
            out["phi_b"] = math.exp(-1.0 / (self.fs_filter * self.value("T_c")))
            out["sigma_b"] = self.value("sigma_b")
        return out

    @property
    def inflation(self) -> dict[str, float]:
        """The consumer's WV over the bound's target across the band: ``geometric_mean`` (the
        objective the bound minimises) and ``max``, with ``max_tau_s`` where the largest sits
        (nan when the target is 0 over the band)."""
        ok = self.target_wv > 0
        if not np.any(ok):
            return {"geometric_mean": math.nan, "max": math.nan, "max_tau_s": math.nan}
        r = self.consumer_wv[ok] / self.target_wv[ok]
        j = int(np.argmax(r))
        return {
            "geometric_mean": float(np.exp(np.mean(np.log(r)))),
            "max": float(r[j]),
            "max_tau_s": float(self.tau_s[ok][j]),
        }

    def at_tc_keeping_q(self, tc: float, why: str) -> Projection:
        """This Gauss-Markov (``WN+GM``) projection at the correlation time ``tc`` (s) with its
        driving noise ``q = 2 sigma_b^2 / T_c`` kept: ``sigma_b`` times ``sqrt(tc / T_c)``,
        the consumer's WV recomputed (the rest unchanged). What a file with one ``T_c`` for
        every channel writes unbounded (KF-GINS's largest ``T_c``): ``why`` says so in the
        two parameters' ``binds``; their intervals are not computed (nan: the file's ``T_c``
        is another channel's).

        Raises
        ------
        ExportError
            Not a ``WN+GM`` projection, or ``tc`` not a positive time.
        """
        if "T_c" not in self.params:
            raise ExportError(f"{self.channel}: a {self.consumer} projection has no T_c")
        if not (math.isfinite(tc) and tc > 0):
            raise ExportError(f"tc must be a positive correlation time in s, got {tc!r}")
        own, sb = self.params["T_c"], self.params["sigma_b"]
        value = sb.value * math.sqrt(tc / own.value)
        nan = math.nan
        params = dict(self.params)
        params["T_c"] = replace(
            own, value=tc, factor=tc / own.plain if own.plain > 0 else nan, binds=why,
            binding_tau_s=nan, low=nan, high=nan,
        )  # fmt: skip
        params["sigma_b"] = replace(
            sb, value=value, factor=value / sb.plain if sb.plain > 0 else nan, binds=why,
            binding_tau_s=nan, low=nan, high=nan,
        )  # fmt: skip
        x = np.array([self.value("N") ** 2 * self.fs, value**2])  # per-sample variances
        cwv = columns(self.consumer, self.tau_s * self.fs, self.fs, tc) @ x
        return replace(self, params=params, consumer_wv=cwv)

    def header_lines(self) -> list[str]:
        """Comment lines: what was projected, bounded, and each value with its interval."""
        data = {
            "low": " and the empirical WV's lower 95 % limit (at its dyadic scales)",
            "estimate": " and the empirical WV (at its dyadic scales)",
            "high": " and the empirical WV's upper 95 % limit (at its dyadic scales)",
        }.get(self.data, "")
        what = (
            "the WV of the fitted terms that are white at the filter step ("
            + (", ".join(k for k, v in self.assignment.items() if v.startswith("WN")) or "none")
            + "; NOT the bias terms, which the estimator's states carry)"
            if self.consumer == "WN"
            else "the fitted model's "
            + ("WV" if self.confidence is None else f"upper {100 * self.confidence:g} % limit")
        )
        how = (
            "plain conversion (no bound)"
            if not self.bounded
            else (
                f"bounded: its WV >= {what}{data} at every scale tau = "
                f"{self.band[0]:.4g} .. {self.band[1]:.4g} s "
                f"(horizon {self.horizon_s:.4g} s: the longest time the filter runs unaided) "
                "with the least inflation (WV over target: geometric mean "
                f"x{self.inflation['geometric_mean']:.3g}, largest "
                f"x{self.inflation['max']:.3g} at tau = {self.inflation['max_tau_s']:.4g} s)"
            )
        )
        lines = [
            f"{self.channel}: projected onto {self.consumer} at filter rate "
            f"{self.fs_filter:g} Hz; {how}",
            "  " + "; ".join(f"{k} -> {v}" for k, v in self.assignment.items()),
        ]
        if math.isfinite(self.tail_level):
            where, scales = (
                ("at every dyadic scale of the band", "of the band")
                if self.tail_band is None
                else (
                    f"at the dyadic scales tau = {self.tail_band[0]:.4g} .. "
                    f"{self.tail_band[1]:.4g} s (those within x{TAIL_SPAN:g} of the horizon)",
                    f"tau = {self.tail_band[0]:.4g} .. {self.tail_band[1]:.4g} s (those within "
                    f"x{TAIL_SPAN:g} of the horizon)",
                )
            )
            lines.append(
                "  tails: the data bound's variance x"
                f"{self.tail_factor:.3g} at tau = {self.tail_tau_s:.4g} s (the largest tail "
                f"factor: the Gaussian {100 * self.tail_level:g} % quantile of the file covers "
                f"the data's Haar coefficients' {where})"
                if math.isfinite(self.tail_tau_s)
                else f"  tails: no scale {scales} needs more than the data bound's variance "
                f"(the data's {100 * self.tail_level:g} % quantiles are Gaussian's or less)"
            )
        lines += [f"  {p.describe()}" for p in self.params.values()]
        lines += [f"  note: {n}" for n in self.notes]
        if self.misfit:
            lines.append(f"  warning: {self.misfit}")
        return lines

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "channel": self.channel,
            "consumer": self.consumer,
            "sensor": self.sensor,
            "unit": self.unit,
            "fs": self.fs,
            "fs_filter": self.fs_filter,
            "band_s": list(self.band),
            "horizon_s": self.horizon_s,
            "confidence": self.confidence,
            "bounded": self.bounded,
            "params": {k: p.to_dict() for k, p in self.params.items()},
            "per_sample": self.per_sample,
            "inflation": {k: (v if math.isfinite(v) else None) for k, v in self.inflation.items()},
            "assignment": dict(self.assignment),
            "notes": list(self.notes),
            "warnings": list(self.warnings),
            "data": self.data,
            "misfit": self.misfit,
            "tails": (
                None
                if not math.isfinite(self.tail_level)
                else {
                    "level": self.tail_level,
                    "factor": self.tail_factor,
                    "tau_s": self.tail_tau_s if math.isfinite(self.tail_tau_s) else None,
                }
                | ({} if self.tail_band is None else {"band_s": list(self.tail_band)})
            ),
        }


def _values(sol: dict[str, Any], consumer: str, fs: float, f_si: float) -> dict[str, float]:
    """Exported values (SI) of a solution."""
    x = sol["x"]
    v = {"N": math.sqrt(max(x[0], 0.0) / fs) * f_si}
    if consumer == "WN+RW":
        v["K"] = math.sqrt(max(x[1], 0.0) * fs) * f_si
    elif consumer == "WN+GM":
        v["sigma_b"] = math.sqrt(max(x[1], 0.0)) * f_si
        v["T_c"] = float(sol["T_c"])
    return v


def _with_u(model: Model, free: list[tuple[int, str]], u: np.ndarray) -> Model:
    procs = list(model.processes)
    for (i, name), ui in zip(free, u, strict=True):
        value = procs[i].params()[name].from_unconstrained(float(ui))
        procs[i] = procs[i].with_values(**{name: value})
    return Model(tuple(procs))


@dataclass(frozen=True)
class _Setup:
    """What :func:`project` derives from its arguments before it solves (checked)."""

    cons: str
    fs: float
    fs_f: float
    n: int
    hz: float
    hi_s: float
    sensor: str | None
    f_si: float
    si_unit: str
    tau: np.ndarray
    use: str
    floor: tuple[np.ndarray, np.ndarray] | None
    tail: tuple[float, float, float]
    tail_band: tuple[float, float]
    conf: float | None
    tau_h: float


def _setup(
    fit: GMWMResult,
    consumer: str,
    fs_filter: float | None,
    horizon_s: float | None,
    band: Sequence[float] | None,
    confidence: float | None,
    bound: bool,
    channel: str,
    unit: str | None,
    data: str,
    tails: TailFactors | None,
    tc: float | None,
) -> _Setup:
    cons = consumer_of(consumer)
    fs = float(fit.fs)
    fs_f = fs if fs_filter is None else float(fs_filter)
    if not (math.isfinite(fs_f) and fs_f > 0):
        raise ExportError(f"fs_filter must be a positive rate in Hz, got {fs_filter!r}")
    n = int(fit.wv.n)
    hz = n / fs if horizon_s is None else float(horizon_s)
    if not (math.isfinite(hz) and hz > 0):
        raise ExportError(f"horizon_s must be a positive time in s, got {horizon_s!r}")
    lo_s, hi_s = (2.0 / fs_f, hz) if band is None else (float(band[0]), float(band[1]))
    lo_s = max(lo_s, 2.0 / fs)
    if not (math.isfinite(lo_s) and math.isfinite(hi_s) and 0 < lo_s <= hi_s):
        raise ExportError(
            f"band must be two WV scales in s with {2.0 / fs:g} <= low <= high, got "
            f"{band!r} (horizon {hz:g} s)"
        )
    if confidence is not None and not 0 < float(confidence) < 1:
        raise ExportError(f"confidence must be in (0, 1), got {confidence!r}")
    u = (unit if unit is not None else fit.wv.unit) or ""
    try:
        sensor, f_si = si_factor(u, channel)
        si_unit = SI_UNIT[sensor]
    except ExportError:
        sensor, f_si, si_unit = None, 1.0, u or "u"
    # scales: even numbers of log samples, POINTS_PER_OCTAVE per octave
    t0, t1 = lo_s * fs, max(hi_s * fs, lo_s * fs)
    k = max(int(math.ceil(POINTS_PER_OCTAVE * math.log2(t1 / t0))) + 1, 2)
    tau = np.unique(np.maximum(2.0 * np.round(np.geomspace(t0, t1, k) / 2.0), 2.0))
    if data not in DATA_BOUNDS:
        raise ExportError(f"data must be one of {', '.join(DATA_BOUNDS)}, got {data!r}")
    use = data if bound and cons != "WN" else "none"
    floor = None
    if use != "none":
        td = np.asarray(fit.wv.tau_samples, float)
        wd = np.asarray(getattr(fit.wv, DATA_BOUNDS[use]), float)
        inb = (td >= tau[0] * (1 - 1e-9)) & (td <= tau[-1] * (1 + 1e-9))
        floor = (td[inb], wd[inb])
        tau = np.unique(np.concatenate([tau, td[inb]]))
    tail = (1.0, math.nan, math.nan)
    tband = (math.nan, math.nan)
    if tails is not None:
        if not math.isclose(float(tails.fs), fs, rel_tol=1e-9):
            raise ExportError(
                f"tails were computed at {tails.fs:g} Hz, the fit at {fs:g} Hz: compute them "
                "from the signal the fit was made from"
            )
        if floor is not None and floor[0].size:
            # the scales near the horizon given (all of the band without one): tails.TAIL_SPAN
            tband = tail_band(float(floor[0][0] / fs), float(floor[0][-1] / fs), horizon_s)
            floor = (floor[0], floor[1] * tails.at(floor[0], *tband))
            tf, tt = tails.largest(*tband)
            tail = (tf, tt, float(tails.level))
    conf = None if confidence is None else float(confidence)
    tau_h = hz * fs
    if tc is not None and not (math.isfinite(float(tc)) and float(tc) > 0):
        raise ExportError(f"tc must be a positive correlation time in s, got {tc!r}")
    if tc is not None and not (math.isfinite(float(tc)) and float(tc) > 0):
        raise ExportError(f"tc must be a positive correlation time in s, got {tc!r}")
    return _Setup(
        cons, fs, fs_f, n, hz, hi_s, sensor, f_si, si_unit, tau, use, floor, tail, tband, conf,
        tau_h,
    )  # fmt: skip


def log_inflation_at_tc(
    fit: GMWMResult,
    tcs: Sequence[float],
    *,
    fs_filter: float | None = None,
    horizon_s: float | None = None,
    band: Sequence[float] | None = None,
    confidence: float | None = None,
    channel: str = "",
    unit: str | None = None,
    data: str = "low",
    tails: TailFactors | None = None,
) -> np.ndarray:
    """``log`` of :attr:`Projection.inflation`'s geometric mean of the bounded ``WN+GM``
    projection at each fixed correlation time of ``tcs`` (s): what ``project(fit, "WN+GM",
    tc=c, ci=None, ...)`` gives, with the bound's target computed once for all of them
    (KF-GINS's search of one ``T_c`` for a file). ``inf`` where no bias of that ``T_c``
    bounds the WV, or where :func:`project` refuses the fit. Arguments as :func:`project`.
    """
    st = _setup(
        fit, "WN+GM", fs_filter, horizon_s, band, confidence, True, channel, unit, data,
        tails, None,
    )  # fmt: skip
    out = np.full(len(tcs), math.inf)
    sols = solve_at_tcs(fit.model, st.fs, st.fs_f, st.tau, st.n, st.conf, st.tau_h, st.floor, tcs)
    for i, (c, sol) in enumerate(zip(tcs, sols, strict=True)):
        if sol is not None and np.all(sol["x"] > 0) and math.isfinite(sol["log_excess"]):
            out[i] = sol["log_excess"]
            continue
        try:  # the cases where project() sets a value otherwise: its own answer
            p = project(
                fit, "WN+GM", fs_filter=fs_filter, horizon_s=horizon_s, band=band,
                confidence=confidence, channel=channel, unit=unit, ci=None, data=data,
                tc=c, tails=tails,
            )  # fmt: skip
        except ExportError:
            continue
        out[i] = math.log(p.inflation["geometric_mean"])
    return out


def project(
    fit: GMWMResult,
    consumer: str,
    *,
    fs_filter: float | None = None,
    horizon_s: float | None = None,
    band: Sequence[float] | None = None,
    confidence: float | None = None,
    bound: bool = True,
    channel: str = "",
    unit: str | None = None,
    ci: str | None = "asymptotic",
    level: float = 0.95,
    data: str = "low",
    tc: float | None = None,
    tails: TailFactors | None = None,
) -> Projection:
    """Project a fitted model onto a consumer's noise model and bound it (module docstring).

    Parameters
    ----------
    fit : GMWMResult
        One channel's fit.
    consumer : str
        ``"WN+RW"``, ``"WN+GM"``, ``"WN"``, or a format name (:data:`FORMAT_CONSUMERS`).
    fs_filter : float, optional
        The rate (Hz) the filter steps at; default the log's rate.
    horizon_s : float, optional
        Longest WV scale (s) of the bound; default the log length ``n / fs``.
    band : (float, float), optional
        WV scales (s) of the bound; default ``(2 / fs_filter, horizon_s)``.
    confidence : float, optional
        Bound the upper ``confidence`` limit of the fitted WV instead of the WV (e.g. 0.95).
    bound : bool
        False: the plain conversion (no bound).
    channel : str
        Channel name for messages.
    unit : str, optional
        The signal unit (default ``fit.wv.unit``); a known gyroscope/accelerometer unit gives
        SI values, another unit the log's own.
    ci : {"asymptotic", None}
        The intervals of the exported values (delta method on the sandwich covariance); None
        skips them.
    level : float
        Interval level.
    data : {"low", "estimate", "high", "none"}
        The bound also covers this of the empirical WV (``fit.wv``) at its dyadic scales in
        the band: the lower limit of its interval (default), the estimate, the upper limit,
        or nothing (the fitted model alone). Not used by the ``WN`` consumer (white part only)
        nor without ``bound``.
    tc : float, optional
        ``WN+GM`` with ``bound``: the Gauss-Markov bias's correlation time (s), fixed instead
        of searched (a file with one ``T_c`` for several channels, as KF-GINS's ``corrtime``).
    tails : TailFactors, optional
        The channel's tail factors (:func:`engine.formats.tails.tail_factors` of the signal
        the fit was made from): the data bound's variance at each dyadic scale is multiplied
        by its factor, so that the Gaussian quantile of the file covers the data's. Used
        only with a data bound (``data`` not ``"none"``); None: no tail factor.

    Returns
    -------
    Projection

    Raises
    ------
    ExportError
        Unknown consumer, bad rates or band, or a parameter the consumer needs that nothing in
        the fit can set.

    Examples
    --------
    A white noise plus a Gauss-Markov of correlation time ~1 s, for a filter that knows
    only white noise and a random walk: the GM becomes the bias's random walk, and both
    values are raised just enough that the filter's WV bounds the fitted one at every scale:

    >>> import numpy as np
    >>> import engine as eg
    >>> m = eg.parse_model("WN(1e-6) + GM(beta=0.5, sigma2_gm=1e-8)")
    >>> x = m.simulate(2**15, rng=np.random.default_rng(3), fs=100.0)
    >>> fit = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0, unit="rad/s"), "WN + GM")
    >>> p = eg.formats.project(fit, "WN+RW")
    >>> p.assignment
    {'GM': 'bias (T_c 1.052 s >= filter step)', 'WN': 'WN'}
    >>> for name, q in p.params.items():
    ...     print(name, f"{q.value:.3e} {q.unit} ({q.binds}; plain {q.plain:.3e})")
    N 1.669e-04 rad/s/sqrt(Hz) (bounds GM; plain 9.998e-05)
    K 8.356e-07 rad/s/s/sqrt(Hz) (bounds GM; plain 1.310e-04)
    """
    try:
        key: tuple[Any, ...] | None = (
            consumer_of(consumer), fs_filter, horizon_s,
            None if band is None else tuple(map(float, band)),
            confidence, bound, channel, unit, ci, level, data, tc, tails,
        )  # fmt: skip
        hash(key)
    except (TypeError, ValueError):
        key = None  # arguments _project refuses with its own message
    kept = _PROJECTIONS.get(fit) if key is not None else None
    if kept is not None and key in kept:
        return kept[key]
    p = _project(
        fit, consumer, fs_filter, horizon_s, band, confidence, bound, channel, unit, ci, level,
        data, tc, tails,
    )  # fmt: skip
    if key is not None:
        _PROJECTIONS.setdefault(fit, {})[key] = p
    return p


def _project(
    fit: GMWMResult,
    consumer: str,
    fs_filter: float | None,
    horizon_s: float | None,
    band: Sequence[float] | None,
    confidence: float | None,
    bound: bool,
    channel: str,
    unit: str | None,
    ci: str | None,
    level: float,
    data: str,
    tc: float | None,
    tails: TailFactors | None,
) -> Projection:
    """:func:`project` itself (it keeps what this returns per fit and arguments)."""
    st = _setup(
        fit, consumer, fs_filter, horizon_s, band, confidence, bound, channel, unit, data,
        tails, tc,
    )  # fmt: skip
    cons, fs, fs_f, n, hz, hi_s = st.cons, st.fs, st.fs_f, st.n, st.hz, st.hi_s
    sensor, f_si, si_unit, tau, use, floor = (
        st.sensor,
        st.f_si,
        st.si_unit,
        st.tau,
        st.use,
        st.floor,
    )
    tail, conf, tau_h = st.tail, st.conf, st.tau_h
    tc_fixed = float(tc) if tc is not None and cons == "WN+GM" and bound else None
    sol = solve(fit.model, fs, fs_f, cons, tau, n, conf, tau_h, bound, floor, tc_fixed)
    sp: Split = sol["split"]
    vals = _values(sol, cons, fs, f_si)
    rate_warnings = _rate_warnings(fit, fs, fs_f, tau_h, sp, channel)
    plain_sol = dict(sol, x=None)
    pl = sol["plain"]
    plain_x = [pl["sigma2"]] + (
        [pl["gamma2"]] if cons == "WN+RW" else [pl["sb2"]] if cons == "WN+GM" else []
    )
    plain_sol["x"], plain_sol["T_c"] = np.array(plain_x), pl.get("T_c")
    plain = _values(plain_sol, cons, fs, f_si)
    warnings: list[str] = list(rate_warnings)
    notes: list[str] = []
    where = f"{channel or 'channel'} ({fit.model.spec()})"
    units = {
        "N": f"{si_unit}/sqrt(Hz)",
        "K": f"{si_unit}/s/sqrt(Hz)",
        "sigma_b": si_unit,
        "T_c": "s",
    }
    # binding scales
    binding: dict[str, tuple[float, str]] = {}
    if bound and "A" in sol:
        x = sol["x"]
        fine = fine_scales(tau)
        a = columns(cons, fine, fs, sol["T_c"])
        cw = a @ x
        active = np.flatnonzero(cw <= sol["target_at"](fine) * (1.0 + 1e-3))
        comps = fit.model.components(fine, fs)
        names = ["N", "K" if cons == "WN+RW" else "sigma_b"]
        for i in range(min(len(x), 2)):
            if x[i] <= 0 or active.size == 0:
                continue
            share = x[i] * a[active, i] / cw[active]
            j = int(active[int(np.argmax(share))])
            dom = max(comps, key=lambda lab: comps[lab][j])
            fl = 0.0 if floor is None else float(floor_at(fine[j : j + 1], *floor)[0])
            if fl > 0 and fl >= cw[j] * (1.0 - 1e-3):
                dom = f"the empirical WV's {_DATA_WORDS[use]}"
                ft = 1.0 if tails is None else float(tails.at(fine[j : j + 1], *st.tail_band)[0])
                if ft > 1.0:
                    dom += f" x tail factor {ft:.3g}"
            binding[names[i]] = (float(fine[j] / fs), f"bounds {dom}")
        if cons == "WN+GM" and "sigma_b" in binding:
            binding["T_c"] = (
                binding["sigma_b"][0],
                "least-inflation search over T_c"
                if tc_fixed is None
                else "one T_c for the file's channels (their least total inflation)",
            )
    # zero terms the consumer needs positive
    reasons: dict[str, str] = {}
    if vals["N"] <= 0:
        raise ExportError(
            f"{where}: the white-noise density comes out 0 (no WN, QN or fast GM term, and "
            "the bound needs none): the consumer needs N > 0; fit a model with WN"
        )
    bias = "K" if cons == "WN+RW" else "sigma_b" if cons == "WN+GM" else None
    if bias is not None and vals[bias] <= 0:
        if plain[bias] > 0:
            vals[bias] = plain[bias]
            reasons[bias] = "plain conversion kept: the bound needs no bias within the band"
            notes.append(
                f"{bias}: the white noise alone bounds the fitted WV up to {hi_s:.4g} s; the "
                f"plain conversion {plain[bias]:.4g} is kept (the consumer needs {bias} > 0)"
            )
        else:
            # the bias whose WV equals the target at the longest scale of the band
            col = columns(cons, tau[-1:], fs, sol.get("T_c") or tau[-1] / fs)[0, 1]
            xb = float(sol["target"][-1] / col)
            if not xb > 0:
                raise ExportError(
                    f"{where}: no term of the fit sets the consumer's bias ({bias}) and the "
                    "fitted WV is 0 at the horizon: fit a model with RW or a slow GM"
                )
            vals[bias] = math.sqrt(xb * fs) * f_si if bias == "K" else math.sqrt(xb) * f_si
            if cons == "WN+GM":
                vals["T_c"] = float(sol.get("T_c") or tau[-1] / fs)
            reasons[bias] = "set from the fitted WV at the horizon (no bias term in the fit)"
            warnings.append(
                f"{where}: the fit has no bias term (RW, slow GM, drift) and the consumer "
                f"needs {bias} > 0: {bias} = {vals[bias]:.4g} {units[bias]} is the bias whose "
                f"WV equals the fitted WV at tau = {tau[-1] / fs:.4g} s (it does not lower the "
                "WV inside the band)"
            )
    elif bias is not None and not plain[bias] > 0:
        warnings.append(
            f"{where}: the fit has no bias term (RW, slow GM, drift) and the consumer needs "
            f"{bias} > 0: {bias} = {vals[bias]:.4g} {units[bias]} is the least-inflation "
            f"bound's, which trades a little white noise for a bias over the band "
            f"{tau[0] / fs:.4g} .. {tau[-1] / fs:.4g} s (no fitted term sets it)"
        )
    # intervals (delta method in log of each value, on the sandwich covariance)
    ivs: dict[str, tuple[float, float]] = {}
    if ci is not None:
        if ci != "asymptotic":
            raise ExportError(f"ci must be 'asymptotic' or None, got {ci!r}")
        ivs = _intervals(
            fit,
            cons,
            fs,
            fs_f,
            tau,
            n,
            conf,
            tau_h,
            bound,
            f_si,
            vals,
            level,
            floor,
            tc_fixed,
            sol,
        )
    params: dict[str, ProjectedParam] = {}
    for name in CONSUMER_PARAMS[cons]:
        v, p0 = vals[name], plain[name]
        bt, what = binding.get(name, (math.nan, reasons.get(name, "")))
        if not bound and not what:
            what = "plain conversion"
        lo, hi = ivs.get(name, (math.nan, math.nan))
        params[name] = ProjectedParam(
            name,
            float(v),
            float(p0),
            units[name],
            float(v / p0) if p0 > 0 else math.nan,
            bt,
            what,
            lo,
            hi,
            level,
        )
    if cons == "WN":
        notes.append("sensor_msgs/Imu covariance: the white part only (bias terms are states)")
    if bound:
        cwv = columns(cons, tau, fs, vals.get("T_c")) @ _x_of(vals, cons, fs, f_si)
    else:
        cwv = columns(cons, tau, fs, plain.get("T_c")) @ np.asarray(plain_sol["x"])
    return Projection(
        channel=channel,
        consumer=cons,
        sensor=sensor,
        unit=si_unit,
        fs=fs,
        fs_filter=fs_f,
        band=(float(tau[0] / fs), float(tau[-1] / fs)),
        horizon_s=hz,
        confidence=None if confidence is None else float(confidence),
        bounded=bound,
        params=params,
        assignment=dict(sp.assignment),
        tau_s=tau / fs,
        fitted_wv=fit.model.wv(tau, fs) * f_si**2,
        target_wv=sol["target"] * f_si**2,
        consumer_wv=cwv * f_si**2,
        notes=notes,
        warnings=warnings,
        data=use,
        misfit=misfit(fit, channel),
        tail_factor=tail[0],
        tail_tau_s=tail[1],
        tail_level=tail[2],
        tail_band=None if horizon_s is None or not math.isfinite(tail[2]) else st.tail_band,
    )


_DATA_WORDS = {"low": "lower limit", "estimate": "estimate", "high": "upper limit"}


def _rate_warnings(
    fit: GMWMResult, fs: float, fs_f: float, tau_h: float, sp: Split, channel: str
) -> list[str]:
    """A filter rate above the log's (the log says nothing about the noise above its Nyquist
    frequency), and the fitted terms whose role (white noise or bias) the filter rate changes
    against the log's rate."""
    out: list[str] = []
    if math.isclose(fs_f, fs, rel_tol=1e-9):
        return out
    where = f"{channel or 'channel'} ({fit.model.spec()})"
    if fs_f > fs:
        out.append(
            f"{where}: the filter rate {fs_f:g} Hz exceeds the log's {fs:g} Hz: the log says "
            f"nothing about the noise between {fs / 2:g} and {fs_f / 2:g} Hz; the per-sample "
            "values assume its white noise continues there (record at the filter's rate)"
        )
    at_log = split_terms(fit.model, fs, fs, tau_h).assignment
    for lab, role in sp.assignment.items():
        if at_log.get(lab, role) != role:
            out.append(
                f"{where}: {lab} changes role with the filter rate: {role} at {fs_f:g} Hz, "
                f"but {at_log[lab]} at the log's {fs:g} Hz"
            )
    return out


def _x_of(vals: dict[str, float], cons: str, fs: float, f_si: float) -> np.ndarray:
    """Per-sample variances (native unit) of exported values."""
    x = [(vals["N"] / f_si) ** 2 * fs]
    if cons == "WN+RW":
        x.append((vals["K"] / f_si) ** 2 / fs)
    elif cons == "WN+GM":
        x.append((vals["sigma_b"] / f_si) ** 2)
    return np.array(x)


def _intervals(
    fit: GMWMResult,
    cons: str,
    fs: float,
    fs_f: float,
    tau: np.ndarray,
    n: int,
    confidence: float | None,
    tau_h: float,
    bound: bool,
    f_si: float,
    vals: dict[str, float],
    level: float,
    floor: tuple[np.ndarray, np.ndarray] | None = None,
    tc: float | None = None,
    base: dict[str, Any] | None = None,
) -> dict[str, tuple[float, float]]:
    """Delta-method intervals of the log of each exported value (``base``: the fit's own
    :func:`~engine.formats.bound.solve`, from which the moved models' solutions follow by
    :func:`~engine.formats.bound.nearby_solutions`)."""
    from ..fit.asymptotic import free_params, param_cov, wv_cov_model

    free = free_params(fit)
    if not free:
        return {}
    cov = _COV.get(fit)
    if cov is None:  # a fit is immutable: its covariance is computed once
        cov = _COV[fit] = param_cov(fit, wv_cov_model(fit.model, fit.wv), free)
    procs = fit.model.processes
    u0 = np.array(
        [procs[i].params()[nm].to_unconstrained(float(getattr(procs[i], nm))) for i, nm in free]
    )
    names = [k for k in CONSUMER_PARAMS[cons] if vals.get(k, 0) > 0]
    steps = [1e-4 * max(1.0, abs(float(u))) for u in u0]
    models = []
    for k, h in enumerate(steps):
        for sgn in (1.0, -1.0):
            uu = u0.copy()
            uu[k] += sgn * h
            try:
                models.append(_with_u(fit.model, free, uu))
            except ValueError:
                return {}
    # the moved models' projections: the base solution's vertex moved with them (one small
    # solve each), or, when the base is not such a vertex, each solved afresh
    near = (
        nearby_solutions(base, models, fs, fs_f, cons, n, confidence, tau_h, floor)
        if bound and base is not None
        else None
    )
    logs = []
    for i, m in enumerate(models):
        sol = (
            near[i]
            if near is not None
            else solve(
                m, fs, fs_f, cons, tau, n, confidence, tau_h, bound, floor, tc, vals.get("T_c")
            )
        )
        v = _values(sol, cons, fs, f_si)
        logs.append([math.log(v[nm]) if v.get(nm, 0) > 0 else math.nan for nm in names])
    grad = np.zeros((len(names), len(free)))
    for k, h in enumerate(steps):
        grad[:, k] = (np.array(logs[2 * k]) - np.array(logs[2 * k + 1])) / (2 * h)
    z = NormalDist().inv_cdf(0.5 + level / 2)
    out = {}
    for i, nm in enumerate(names):
        if not np.all(np.isfinite(grad[i])):
            continue
        se = math.sqrt(max(float(grad[i] @ cov @ grad[i]), 0.0))
        # set by the empirical WV (the data bound), not by the fit: no interval (a relative
        # standard error below 1e-9 is the rounding of the vertex arithmetic, not the fit's)
        if not se > 1e-9:
            continue
        out[nm] = (vals[nm] * math.exp(-z * se), vals[nm] * math.exp(z * se))
    return out
