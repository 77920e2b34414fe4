"""The IEEE Std 952 / 1293 quantities of a fit: the numbers an IMU user looks for first.

One table per fitted channel, whatever structure was fitted (:func:`ieee_table`, carried by
:attr:`engine.fit.GMWMResult.ieee`): ``N`` (angle / velocity random walk, including the white
noise of an AR1/GM faster than one sample), ``B`` (bias instability, IEEE 952: the model's
Allan floor / 0.664), ``ADEV_min`` and ``ADEV_data`` (the Allan-deviation minimum of the model
and of the data, as vendors quote it), and ``K``, ``Q``, ``R`` when the model has the term,
each with a two-sided interval by the delta method (``ADEV_data``: the WV's own interval).
The table of keys, intervals and units: docs/methods.md, "The IEEE quantities of a fit"; the
user's view: docs/ieee.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any, Protocol

import numpy as np

from ..models import DR, QN, RW, WN, Model, Process
from ..units import BI_FACTOR, DISPLAY, SI_UNIT, ExportError, allan_floor, si_factor
from ..wv import WaveletVariance
from ._varpro import TC_FLAG
from .asymptotic import delta_bounds

__all__ = ["IeeeQuantity", "IeeeTable", "ieee_table", "white_share", "IEEE_KEYS"]

#: Keys of the table in print order, with their name.
IEEE_KEYS: dict[str, str] = {
    "N": "random walk (white noise density)",
    "B": "bias instability (IEEE 952: Allan floor / 0.664)",
    "ADEV_min": "bias instability (Allan deviation minimum, model)",
    "ADEV_data": "bias instability (Allan deviation minimum, data)",
    "K": "rate random walk",
    "Q": "quantization",
    "R": "rate ramp",
}
_DELTA = "delta method (sandwich covariance of the fit)"
_CHI2 = "chi-square (eta3) interval of the empirical WV at that scale"


class _Fit(Protocol):
    """What :func:`ieee_table` needs of a fit (a :class:`engine.fit.GMWMResult`)."""

    @property
    def model(self) -> Model: ...

    @property
    def wv(self) -> WaveletVariance: ...

    @property
    def omega(self) -> np.ndarray: ...

    @property
    def at_bound(self) -> list[str]: ...

    @property
    def fs(self) -> float: ...

    @property
    def param_records(self) -> Any: ...


@dataclass(frozen=True)
class IeeeQuantity:
    """One IEEE quantity of one channel with its interval, in SI and datasheet units.

    Attributes
    ----------
    key : str
        ``N``, ``B``, ``ADEV_min``, ``ADEV_data``, ``K``, ``Q`` or ``R`` (:data:`IEEE_KEYS`).
    name : str
        Readable name for the sensor kind (``angle random walk``, ``velocity random walk`` ...).
    value, low, high : float
        Estimate and ``level`` interval in ``unit`` (NaN bounds: no interval, see ``note``).
    unit : str
        SI unit (``rad/s/sqrt(Hz)`` ...) or, for an unknown signal unit, the signal's.
    datasheet_value, datasheet_low, datasheet_high : float
        The same in ``datasheet_unit``.
    datasheet_unit : str
        ``deg/sqrt(h)``, ``m/s/sqrt(h)``, ``deg/h``, ``mg``, ``deg/h/sqrt(h)`` ... (the SI unit
        where the quantity has no datasheet unit, the signal's when it is unknown).
    native : float
        The value in the channel's own signal unit (``deg/s/sqrt(Hz)`` for a deg/s gyro).
    native_unit : str
    tau_s : float
        Averaging time of a minimum (``ADEV_min``, ``ADEV_data``, and ``B``'s floor) [s]; NaN
        for the others.
    interval : str
        How the interval was made.
    sources : tuple of str
        The fitted terms it comes from (``("WN", "GM_2")``).
    note : str
        Caveats: a term on its bound, a floor at the edge of the analysed scales.
    upper_bound : bool
        True for a minimum at the edge of the analysed scales: no floor inside them, the
        value only bounds the floor from above.
    """

    key: str
    name: str
    value: float
    low: float
    high: float
    unit: str
    datasheet_value: float
    datasheet_low: float
    datasheet_high: float
    datasheet_unit: str
    native: float
    native_unit: str
    tau_s: float = math.nan
    interval: str = ""
    sources: tuple[str, ...] = ()
    note: str = ""
    upper_bound: bool = False

    @property
    def has_interval(self) -> bool:
        """True when both interval ends are finite."""
        return math.isfinite(self.low) and math.isfinite(self.high)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None): ``value, low, high, unit, datasheet_value,
        datasheet_unit`` and the rest of the fields."""
        out: dict[str, Any] = {}
        for k in (
            "name",
            "value",
            "low",
            "high",
            "unit",
            "datasheet_value",
            "datasheet_low",
            "datasheet_high",
            "datasheet_unit",
            "native",
            "native_unit",
            "tau_s",
            "interval",
            "note",
        ):
            v = getattr(self, k)
            out[k] = (float(v) if math.isfinite(v) else None) if isinstance(v, float) else v
        out["sources"] = list(self.sources)
        out["upper_bound"] = self.upper_bound
        return out


@dataclass(frozen=True)
class IeeeTable:
    """The IEEE quantities of one fitted channel (:func:`ieee_table`).

    Attributes
    ----------
    kind : str
        ``gyroscope``, ``accelerometer`` or ``""`` (unknown signal unit: values in it).
    unit : str
        The signal unit.
    level : float
        Two-sided interval level.
    quantities : dict of str to IeeeQuantity
        By key, in :data:`IEEE_KEYS` order; only those the model has.
    """

    kind: str
    unit: str
    level: float
    quantities: dict[str, IeeeQuantity] = field(default_factory=dict)

    def __getitem__(self, key: str) -> IeeeQuantity:
        return self.quantities[key]

    def __contains__(self, key: object) -> bool:
        return key in self.quantities

    def get(self, key: str) -> IeeeQuantity | None:
        """The quantity ``key`` or None when the model has none."""
        return self.quantities.get(key)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{key: entry}`` (the ``ieee`` entry of ``gmwm fit/select/report
        --json``)."""
        return {k: q.to_dict() for k, q in self.quantities.items()}

    def lines(self) -> list[str]:
        """Readable rows: name, datasheet value with interval and unit, SI value."""
        pct = f"{100 * self.level:g} %"
        out = []
        for q in self.quantities.values():
            iv = (
                f"[{q.datasheet_low:.4g}, {q.datasheet_high:.4g}]"
                if math.isfinite(q.datasheet_low) and math.isfinite(q.datasheet_high)
                else "(no interval)"
            )
            at = f" at tau = {q.tau_s:.4g} s" if math.isfinite(q.tau_s) else ""
            out.append(
                f"  {q.key:<9} {q.name:<52} {q.datasheet_value:>10.4g} {iv:<24} "
                f"{q.datasheet_unit}{at}"
            )
        return [f"  IEEE quantities ({pct} intervals):", *out] if out else []


@lru_cache(maxsize=4096)
def white_share(model: Model, fs: float) -> tuple[float, tuple[str, ...]]:
    """White-noise variance per sample of a fitted model, disguised share included.

    Remembered per (model, fs): the delta method evaluates N at the same shifted models for
    every length a run plan tries.

    ``s2 = sigma2(WN) + sum S(0)`` over the AR1/GM terms whose correlation time is below
    one sample (``TC_FLAG``): at every Haar scale such a term acts as white noise of variance
    its spectral density at 0 (:meth:`engine.models.Process.white_equivalent`, an AR1
    ``sigma2 / (1 - phi)^2``).

    Returns
    -------
    s2, sources
        The variance [u^2] and the labels of the terms it comes from (empty: the model has
        no white noise at all, ``s2`` is then NaN).
    """
    s2, src = 0.0, []
    for lab, p in zip(model.labels, model.processes, strict=True):
        if p.code == WN.code:
            s2 += float(p.linear_coef())
            src.append(lab)
        elif p.nonlinear is not None and p.is_set:
            phi = p.nl_value(fs)
            if phi is None:
                continue
            tc = -1.0 / math.log(phi) if 0.0 < phi < 1.0 else (math.inf if phi >= 1 else 0.0)
            if tc < TC_FLAG:
                if p.linear_coef() > 0:
                    s2 += float(p.white_equivalent(fs))
                src.append(lab)
    return (s2 if src else math.nan), tuple(src)


# each quantity of a model in the signal unit u, through the process classes' own quantities
def _n(m: Model, fs: float) -> float:
    s2, _ = white_share(m, fs)
    return float(WN.quantities[0].forward({"sigma2": max(s2, 0.0)}, fs))


def _one(cls: type[Process]) -> Callable[[Model, float], float]:
    q = cls.quantities[0]

    def value(m: Model, fs: float) -> float:
        for p in m.processes:
            if p.code == cls.code:
                vals = {n: float(x or 0.0) for n, x in zip(p.param_names, p.values, strict=True)}
                v = float(q.forward(vals, fs))
                return abs(v) if q.magnitude or cls is DR else v
        return math.nan

    return value


def _floor(n_levels: int) -> Callable[[Model, float], float]:
    """The model's Allan-deviation minimum over ``n_levels`` levels (B and ``ADEV_min`` are
    the same floor, which :func:`engine.units.allan_floor` remembers per model)."""

    def adev_min(m: Model, fs: float) -> float:
        return float(allan_floor(m, fs, n_levels)["adev_min"])

    return adev_min


def _kind_of(unit: str) -> tuple[str, float]:
    try:
        return si_factor(unit)
    except ExportError:
        return "", math.nan


def ieee_table(res: _Fit, *, level: float = 0.95, vmat: np.ndarray | None = None) -> IeeeTable:
    """The IEEE quantities of a one-WV fit, with intervals (see the module docstring).

    Parameters
    ----------
    res : GMWMResult
        A fit: its model (every value set), WV, weighting matrix and ``at_bound``.
    level : float
        Two-sided interval level in (0, 1).
    vmat : ndarray (J, J), optional
        Covariance of the WV for the delta method (default: the model-implied one,
        :func:`engine.fit.asymptotic.wv_cov_model`, computed here).

    Returns
    -------
    IeeeTable

    Examples
    --------
    A white noise of 0.3 deg/sqrt(h) plus a rate random walk of 3 deg/h/sqrt(h), sampled at
    100 Hz, fitted as WN+RW:

    >>> import numpy as np
    >>> import engine as eg
    >>> spec = eg.inference.parse_datasheet("arw=0.3 deg/sqrt(h), rrw=3 deg/h/sqrt(h)")
    >>> x = spec.model(100.0, "deg/s").simulate(2**17, rng=np.random.default_rng(2), fs=100.0)
    >>> t = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0, unit="deg/s"), "WN+RW").ieee
    >>> n = t["N"]
    >>> print(f"{n.datasheet_value:.2f} {n.datasheet_unit}, in [{n.datasheet_low:.2f}, "
    ...       f"{n.datasheet_high:.2f}]")
    0.30 deg/sqrt(h), in [0.30, 0.30]
    """
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    model, fs, wv = res.model, res.fs, res.wv
    unit = wv.unit
    kind, f_si = _kind_of(unit)
    fl = allan_floor(model, fs, wv.n_levels)
    gyro = kind == "gyroscope"
    # per key: (value function, unit spelling from a signal unit, datasheet symbol, sources)
    specs: list[tuple[str, Callable[[Model, float], float], Callable[[str], str], str]] = []
    s2, n_src = white_share(model, fs)
    if n_src:
        specs.append(("N", _n, WN.quantities[0].unit, "N"))
    floor = _floor(wv.n_levels)
    specs.append(("B", lambda m, f: floor(m, f) / BI_FACTOR, lambda x: x, "B"))
    specs.append(("ADEV_min", floor, lambda x: x, "B"))
    for cls in (RW, QN, DR):
        q = cls.quantities[0]
        if any(p.code == cls.code for p in model.processes):
            specs.append((q.symbol, _one(cls), q.unit, q.symbol))
    names = {
        "N": "angle random walk" if gyro else ("velocity random walk" if kind else IEEE_KEYS["N"]),
        "K": "rate random walk" if gyro or not kind else "acceleration random walk",
        "R": "rate ramp" if gyro or not kind else "acceleration ramp",
    }
    bounds = delta_bounds(res, [sp[1] for sp in specs], level, vmat=vmat)
    out: dict[str, IeeeQuantity] = {}
    for (key, fn, spell, dsym), (lo, hi) in zip(specs, bounds, strict=True):
        value = fn(model, fs)
        src: tuple[str, ...]
        if key == "N":
            src = n_src
        elif key in ("B", "ADEV_min"):
            src = tuple(model.labels)
        else:
            src = tuple(
                lab
                for lab, p in zip(model.labels, model.processes, strict=True)
                if p.code == {"K": RW.code, "Q": QN.code, "R": DR.code}[key]
            )
        note = ""
        bound = [b for b in res.at_bound if b.split(".")[0] in src]
        if bound and not math.isfinite(lo):
            note = f"on a bound ({', '.join(bound)}): no interval"
        tau = math.nan
        if key in ("B", "ADEV_min"):
            tau = fl["T_s"]
            if fl["at_edge"]:
                note = (
                    "no floor inside the analysed scales (minimum at their edge, "
                    f"T = {tau:.4g} s): an upper bound of the floor"
                )
        if key == "N" and s2 > 0 and not n_src == (WN.code,):
            folded = [s for s in n_src if s != WN.code]
            if folded:
                note = (note + "; " if note else "") + (
                    f"includes the white-noise equivalent of {', '.join(folded)} (correlation "
                    "time below one sample)"
                )
        out[key] = _quantity(
            key,
            names.get(key, IEEE_KEYS[key]),
            value,
            lo,
            hi,
            unit,
            kind,
            f_si,
            spell,
            dsym,
            tau,
            _DELTA,
            src,
            note,
        )
        if key in ("B", "ADEV_min") and fl["at_edge"]:
            out[key] = replace(out[key], upper_bound=True)
    # the data's own Allan-deviation minimum, with the WV's interval at that scale
    var = np.asarray(wv.variance, float)
    ok = np.isfinite(var) & (var > 0)
    if ok.any():
        j = int(np.argmin(np.where(ok, var, np.inf)))
        v, lo, hi = (math.sqrt(2.0 * float(a[j])) for a in (var, wv.ci_low, wv.ci_high))
        note = ""
        if j in (0, var.size - 1):
            note = "minimum at the edge of the analysed scales: an upper bound"
        if not math.isclose(level, 1.0 - wv.alpha, abs_tol=1e-12):
            note = (note + "; " if note else "") + f"interval at {100 * (1 - wv.alpha):g} %"
        tau = float(wv.tau_s[j]) / 2.0
        out["ADEV_data"] = _quantity(
            "ADEV_data",
            IEEE_KEYS["ADEV_data"],
            v,
            lo,
            hi,
            unit,
            kind,
            f_si,
            lambda x: x,
            "B",
            tau,
            _CHI2,
            (),
            note,
            upper_bound=j in (0, var.size - 1),
        )
    order = {k: i for i, k in enumerate(IEEE_KEYS)}
    return IeeeTable(
        kind, unit, float(level), dict(sorted(out.items(), key=lambda kv: order[kv[0]]))
    )


def _quantity(
    key: str,
    name: str,
    value: float,
    lo: float,
    hi: float,
    unit: str,
    kind: str,
    f_si: float,
    spell: Callable[[str], str],
    dsym: str,
    tau: float,
    interval: str,
    sources: tuple[str, ...],
    note: str,
    *,
    upper_bound: bool = False,
) -> IeeeQuantity:
    """One quantity from its value in the signal unit: SI and datasheet conversions."""
    u = unit or "u"
    if kind:
        d = DISPLAY.get((kind, dsym))
        f, si_unit = f_si, spell(SI_UNIT[kind])
        c = f_si * (d.factor if d is not None else 1.0)
        ds_unit = d.unit if d is not None else si_unit
    else:  # unknown unit: everything in the signal's own unit
        f, c, si_unit = 1.0, 1.0, spell(u)
        ds_unit = si_unit
    return IeeeQuantity(
        key,
        name,
        value * f,
        lo * f,
        hi * f,
        si_unit,
        value * c,
        lo * c,
        hi * c,
        ds_unit,
        value,
        spell(u),
        tau,
        interval,
        sources,
        note,
        upper_bound,
    )
