"""The ONE datasheet table: per process its symbols, conversions and units.

Every datasheet number of the project (the ``gmwm fit`` text and JSON, ``gmwm export``, the
app's datasheet table and its download, the Monte Carlo study, the slope method) comes from
the quantities each process class declares (:attr:`engine.models.Process.quantities`, gathered
in :data:`QUANTITIES`) and :data:`DISPLAY` below, so one quantity has one name, one symbol and
one unit spelling everywhere. ``BI_FACTOR = sqrt(2 ln 2 / pi) = 0.6643`` is the Allan
deviation floor of bias-instability noise of coefficient B, over B (IEEE Std 952, annex C).
The conversions, the unit spellings and why: docs/methods.md, "Datasheet units";
docs/conventions.md, "Units and datasheet conversions".
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from functools import lru_cache, partial
from typing import TYPE_CHECKING, Any

import numpy as np

from ._quantity import Quantity, per_s, squared, times_s
from .errors import ExportError
from .models import PROCESS_TYPES

if TYPE_CHECKING:  # pragma: no cover
    from .models import Model, Process

__all__ = [
    "BI_FACTOR",
    "SI_UNIT",
    "G0",
    "ExportError",
    "Quantity",
    "Display",
    "QUANTITIES",
    "DISPLAY",
    "DatasheetRow",
    "squared",
    "per_s",
    "times_s",
    "param_unit",
    "si_factor",
    "norm_unit",
    "to_datasheet",
    "from_datasheet",
    "process_values",
    "process_from_values",
    "quantity_name",
    "allan_floor",
    "datasheet_rows",
    "datasheet",
]

#: ADEV of flicker (bias-instability) noise on its floor: ``sqrt(2 ln 2 / pi) B = 0.664 B``.
BI_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
G0 = 9.80665  # standard gravity, m/s^2
_DEG = math.pi / 180.0


def param_unit(code: str, name: str, unit: str = "") -> str:
    """Unit of a model parameter for a signal in ``unit`` (per-sample parametrisation).

    Read from the parameter's declaration on its process class
    (:attr:`engine.models.model.Param.unit`); ``""`` for a name no process declares.

    Parameters
    ----------
    code : str
        Process code (``"WN"``, ``"GM"`` ...); another process declaring ``name`` answers
        when the process ``code`` does not.
    name : str
        Parameter name (``"sigma2"``, ``"beta"`` ...).
    unit : str
        Signal unit (``""``: unknown, spelled ``u``).
    """
    cls = PROCESS_TYPES.get(code)
    for c in ([cls] if cls is not None else []) + list(PROCESS_TYPES.values()):
        spec = c.params().get(name)
        if spec is not None:
            return spec.unit(unit or "u")
    return ""


# --------------------------------------------------------------------------- signal units
# unit -> (sensor, factor to SI): rad/s for rates, m/s^2 for accelerations
_SI: dict[str, tuple[str, float]] = {
    "rad/s": ("gyroscope", 1.0),
    "mrad/s": ("gyroscope", 1e-3),
    "deg/s": ("gyroscope", _DEG),
    "dps": ("gyroscope", _DEG),
    "deg/h": ("gyroscope", _DEG / 3600.0),
    "deg/hr": ("gyroscope", _DEG / 3600.0),
    "rad/h": ("gyroscope", 1.0 / 3600.0),
    "rpm": ("gyroscope", 2.0 * math.pi / 60.0),
    "m/s^2": ("accelerometer", 1.0),
    "g": ("accelerometer", G0),
    "mg": ("accelerometer", 1e-3 * G0),
    "ug": ("accelerometer", 1e-6 * G0),
    "cm/s^2": ("accelerometer", 1e-2),
    "mm/s^2": ("accelerometer", 1e-3),
    "gal": ("accelerometer", 1e-2),
}
#: The SI signal unit of each sensor kind: the one map (datasheet check, projection, exports).
SI_UNIT: dict[str, str] = {"gyroscope": "rad/s", "accelerometer": "m/s^2"}


def norm_unit(unit: str) -> str:
    """Canonical spelling of a signal unit (``°/sec`` -> ``deg/s``, ``m/s2`` -> ``m/s^2``)."""
    u = unit.strip().lower().replace(" ", "").replace("°", "deg").replace("µ", "u")
    u = u.replace("²", "^2").replace("**", "^").replace("sec", "s").replace("degree", "deg")
    u = re.sub(r"^degs?(?=/)", "deg", u)
    u = u.replace("/s/s", "/s^2").replace("/s2", "/s^2").replace("s-2", "/s^2")
    u = u.replace("ms^-2", "m/s^2").replace("m/s^-2", "m/s^2").replace("m//s^2", "m/s^2")
    u = u.replace("rad.s^-1", "rad/s").replace("deg.s^-1", "deg/s")
    return u


def si_factor(unit: str, channel: str = "") -> tuple[str, float]:
    """Sensor kind and factor to SI of a signal unit.

    Parameters
    ----------
    unit : str
        E.g. ``"deg/s"``, ``"rad/s"``, ``"deg/h"``, ``"g"``, ``"mg"``, ``"m/s^2"``.
    channel : str
        Channel name, for the error message.

    Returns
    -------
    (kind, factor)
        ``kind`` is ``"gyroscope"`` (SI: rad/s) or ``"accelerometer"`` (SI: m/s^2); SI value
        = factor x value.

    Raises
    ------
    ExportError
        Missing or unknown unit.
    """
    where = f" of channel {channel!r}" if channel else ""
    known = "deg/s, rad/s, deg/h, mrad/s, g, mg, ug, m/s^2"
    if not unit or not unit.strip():
        raise ExportError(
            f"the unit{where} is unknown: SI conversion needs it; give it with "
            f"units={{{channel or 'name'!r}: 'deg/s'}} among {known}"
        )
    got = _SI.get(norm_unit(unit))
    if got is None:
        raise ExportError(
            f"unknown unit {unit!r}{where}: cannot convert to SI; use one of "
            f"{known} (units={{{channel or 'name'!r}: 'deg/s'}})"
        )
    return got


# --------------------------------------------------------------------------- the table
@dataclass(frozen=True)
class Display:
    """A datasheet display unit of a quantity: ``value = factor x (value in SI)``."""

    symbol: str
    name: str
    unit: str
    factor: float


#: Per code, its quantities in print order: those of each process class
#: (:attr:`engine.models.Process.quantities`; an AR1 shares the GM's) and the bias
#: instability ``BI`` (a quantity of the whole model, read from its Allan floor).
QUANTITIES: dict[str, tuple[Quantity, ...]] = {
    **{cls.quantities[0].code: cls.quantities for cls in PROCESS_TYPES.values()},
    "BI": (
        Quantity(
            "BI",
            "B",
            "bias instability",
            "B",
            lambda p, fs: p["B"],
            lambda v, fs: v,
            lambda u: u,
        ),
    ),
}

#: Datasheet display units per (sensor kind, symbol), from the value in SI units.
DISPLAY: dict[tuple[str, str], Display] = {
    ("gyroscope", "N"): Display("ARW", "angle random walk", "deg/sqrt(h)", 60.0 / _DEG),
    ("accelerometer", "N"): Display("VRW", "velocity random walk", "m/s/sqrt(h)", 60.0),
    ("gyroscope", "K"): Display("RRW", "rate random walk", "deg/h/sqrt(h)", 216000.0 / _DEG),
    ("accelerometer", "K"): Display("AccRW", "acceleration random walk", "m/s/h/sqrt(h)", 216000.0),
    ("gyroscope", "R"): Display("R", "rate ramp", "deg/h^2", 3600.0**2 / _DEG),
    ("accelerometer", "R"): Display("R", "acceleration ramp", "m/s/h^2", 3600.0**2),
    ("gyroscope", "B"): Display("B", "bias instability", "deg/h", 3600.0 / _DEG),
    ("accelerometer", "B"): Display("B", "bias instability", "mg", 1e3 / G0),
}


def _quantity(code: str, symbol: str) -> Quantity:
    cls = PROCESS_TYPES.get(code)
    for q in cls.quantities if cls is not None else QUANTITIES.get(code, ()):
        if q.symbol == symbol:
            return q
    raise ValueError(f"no datasheet quantity {symbol!r} for process {code!r}")


def quantity_name(q: Quantity, kind: str | None) -> str:
    """The quantity's name for a sensor kind (``acceleration random walk`` on accelerometers)."""
    return q.accel_name if kind == "accelerometer" and q.accel_name else q.name


def to_datasheet(code: str, value: float, fs: float, symbol: str | None = None) -> float:
    """Datasheet value of a one-parameter process (signed for DR).

    Parameters
    ----------
    code : {"WN", "QN", "RW", "DR"}
    value : float
        ``sigma2``, ``q2``, ``gamma2`` or ``omega`` (per sample).
    fs : float
        Sampling frequency (Hz).
    symbol : str, optional
        The quantity (default: the process's first, N, Q, K or R).
    """
    cls = PROCESS_TYPES.get(code)
    if cls is None or len(cls.param_names) != 1:
        raise ValueError(f"no one-parameter datasheet conversion for {code!r}")
    q = cls.quantities[0] if symbol is None else _quantity(code, symbol)
    return float(q.forward({q.param: value}, fs))


def from_datasheet(code: str, value: float, fs: float, symbol: str | None = None) -> float:
    """Per-sample parameter from a datasheet value (inverse of :func:`to_datasheet`)."""
    qs = QUANTITIES.get(code)
    if not qs:
        raise ValueError(f"no datasheet conversion for {code!r}")
    q = qs[0] if symbol is None else _quantity(code, symbol)
    if q.inverse is None:
        raise ValueError(f"{q.symbol} of {code} is not invertible alone")
    return float(q.inverse(value, fs))


def process_values(process: Process, fs: float) -> dict[str, float]:
    """Datasheet values ``{symbol: value}`` of a process with every value set (AR1 as GM)."""
    params = process.datasheet_params(fs)
    if params is None:
        nl = process.nonlinear
        raise ValueError(
            f"{process.code} {nl} = {getattr(process, str(nl))} outside (0, 1) has no "
            "correlation time"
        )
    return {q.symbol: float(q.forward(params, fs)) for q in process.quantities}


def process_from_values(code: str, values: Mapping[str, float], fs: float) -> Process:
    """The per-sample process of datasheet values (inverse of :func:`process_values`).

    ``values`` holds N (WN), Q (QN), K (RW), R (DR) or ``T_c`` and ``sigma_gm`` (GM, AR1):
    :meth:`engine.models.Process.from_datasheet` of the process ``code``.
    """
    cls = PROCESS_TYPES.get(code)
    if cls is None:
        raise ValueError(f"unknown process {code!r}; known: {', '.join(PROCESS_TYPES)}")
    return cls.from_datasheet(dict(values), fs)


# --------------------------------------------------------------------------- rows
@dataclass(frozen=True)
class DatasheetRow:
    """One datasheet quantity of one channel.

    ``low``/``high`` are the interval bounds (NaN when no interval is available);
    ``process`` is the process label (``WN``, ``GM_1`` ...) or ``model`` for quantities of the
    whole model (bias-instability floor).
    """

    channel: str
    process: str
    quantity: str
    symbol: str
    value: float
    unit: str
    low: float = math.nan
    high: float = math.nan
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN as None)."""
        d = asdict(self)
        for k in ("value", "low", "high"):
            v = d[k]
            d[k] = float(v) if math.isfinite(v) else None
        return d


def allan_floor(model: Model, fs: float, n_levels: int, *, points_per_octave: int = 16) -> dict:
    """Minimum of the model-implied Allan deviation over the analysed scales.

    Remembered per (model, fs, levels, points): an IEEE table's delta method evaluates it at
    the same shifted models for B and ``ADEV_min``, and a run plan at every length with the
    same number of levels (:func:`engine.inference.planning.plan_run`: a fifth of its CPU).

    Returns
    -------
    dict
        ``adev_min`` [u], ``T_s`` (Allan averaging time of the minimum, s), ``bias_instability``
        (``adev_min / BI_FACTOR``, u), ``at_edge`` (True when the minimum is at the shortest or
        longest scale: no floor inside, an upper bound), ``T_range_s``.
    """
    adev, t_s, at_edge, t_lo, t_hi = _allan_floor(model, fs, n_levels, points_per_octave)
    return {
        "adev_min": adev,
        "T_s": t_s,
        "bias_instability": adev / BI_FACTOR,
        "at_edge": at_edge,
        "T_range_s": [t_lo, t_hi],
    }


@lru_cache(maxsize=4096)
def _allan_floor(
    model: Model, fs: float, n_levels: int, points_per_octave: int
) -> tuple[float, float, bool, float, float]:
    """:func:`allan_floor`'s numbers: ADEV minimum, its T (s), at the edge, the T range (s)."""
    j = n_levels
    # Allan times T = m / fs, m = 2^(k) samples for k in [0, J - 1] -> WV at tau = 2m
    k = np.linspace(0.0, max(j - 1, 0), max(j - 1, 0) * points_per_octave + 1)
    m = 2.0**k
    avar = 2.0 * model.wv(2.0 * m, fs)
    avar = np.where(np.isfinite(avar) & (avar > 0), avar, np.inf)
    i = int(np.argmin(avar))
    adev = float(math.sqrt(avar[i])) if math.isfinite(avar[i]) else math.nan
    at_edge = bool(i == 0 or i == m.size - 1)
    return adev, float(m[i] / fs), at_edge, float(m[0] / fs), float(m[-1] / fs)


def _map_iv(iv: tuple[float, float] | None, fn: Callable[[float], float]) -> tuple[float, float]:
    """Interval of a monotone function of one parameter (either direction)."""
    if iv is None or not all(math.isfinite(v) for v in iv):
        return math.nan, math.nan
    try:
        a, b = fn(iv[0]), fn(iv[1])
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.nan, math.nan
    return (min(a, b), max(a, b))


def _forward_at(q: Quantity, name: str, params: Mapping[str, float], fs: float, x: float) -> float:
    """``q`` of ``params`` with the parameter ``name`` set to ``x`` (an interval's end)."""
    return float(q.forward({**params, name: x}, fs))


def _abs_iv(iv: tuple[float, float] | None) -> tuple[float, float] | None:
    if iv is None:
        return None
    lo, hi = iv
    if lo <= 0 <= hi:
        return 0.0, max(abs(lo), abs(hi))
    return min(abs(lo), abs(hi)), max(abs(lo), abs(hi))


def datasheet_rows(
    model: Model,
    fs: float,
    unit: str = "",
    *,
    channel: str = "",
    intervals: Mapping[str, tuple[float, float]] | None = None,
    si: bool = True,
    n_levels: int | None = None,
    extras: Mapping[str, float] | None = None,
) -> list[DatasheetRow]:
    """Datasheet rows of a model with every value set, from :data:`QUANTITIES`.

    Parameters
    ----------
    model : Model
    fs : float
        Sampling frequency (Hz).
    unit : str
        Signal unit (``""``: unknown, spelled ``u``).
    channel : str
        Channel name put in the rows.
    intervals : mapping of str to (float, float), optional
        Parameter intervals by unique name (``WN.sigma2``); quantities that are monotone
        functions of one parameter get the mapped interval.
    si : bool
        Add SI and datasheet-display rows (:data:`DISPLAY`) when the unit is known; an unknown
        unit adds a note row (value NaN).
    n_levels : int, optional
        Add the model's bias-instability floor (:func:`allan_floor`) over ``n_levels`` levels.
    extras : mapping, optional
        ``{"BI.B": B}``: a bias instability read by the slope method (process ``BI``).

    Returns
    -------
    list of DatasheetRow
        Per process in the model's order: for each quantity the native row, then SI and
        display rows; then ``BI`` (extras) and the floor (process ``model``).
    """
    u = unit or "u"
    ivs = dict(intervals or {})
    kind, f_si, note_si = None, math.nan, ""
    if si:
        try:
            kind, f_si = si_factor(unit, channel)
        except ExportError as e:
            note_si = f"no SI rows: {e}"
    su = SI_UNIT.get(kind or "", "")
    rows: list[DatasheetRow] = []

    def add(proc: str, q: Quantity, value: float, iv: tuple[float, float], note: str = "") -> None:
        name = quantity_name(q, kind)
        si_name = f"{name[:-1]}, SI)" if name.endswith(")") else f"{name} (SI)"
        rows.append(DatasheetRow(channel, proc, name, q.symbol, value, q.unit(u), *iv, note))
        if kind and q.si:
            c = f_si
            rows.append(
                DatasheetRow(
                    channel,
                    proc,
                    si_name,
                    q.symbol,
                    value * c,
                    q.unit(su),
                    iv[0] * c,
                    iv[1] * c,
                    note,
                )
            )
            d = DISPLAY.get((kind, q.symbol))
            if d is not None:
                c = f_si * d.factor
                rows.append(
                    DatasheetRow(
                        channel,
                        proc,
                        name if name.endswith(")") else d.name,
                        d.symbol,
                        value * c,
                        d.unit,
                        iv[0] * c,
                        iv[1] * c,
                        note,
                    )
                )

    for lab, p in zip(model.labels, model.processes, strict=True):
        if not p.is_set:
            continue
        params = p.datasheet_params(fs)
        if params is None:  # an AR1 with phi outside (0, 1): no correlation time
            nl = str(p.nonlinear)
            rows.append(
                DatasheetRow(
                    channel,
                    lab,
                    f"{p.code} coefficient (no correlation time: {nl} outside (0, 1))",
                    nl,
                    float(getattr(p, nl)),
                    "1",
                )
            )
            continue
        own = {n: ivs[f"{lab}.{n}"] for n in p.param_names if f"{lab}.{n}" in ivs}
        divs = p.datasheet_intervals(own, fs)
        for q in p.quantities:
            value = float(q.forward(params, fs))
            iv: tuple[float, float] = (math.nan, math.nan)
            if q.param:
                piv = divs.get(q.param)
                if q.magnitude:
                    piv = _abs_iv(piv)
                iv = _map_iv(piv, partial(_forward_at, q, q.param, params, fs))
            if q.magnitude:
                value = abs(value)
            note = "q = 2 beta sigma2_gm" if q.symbol == "q" else ""
            add(lab, q, value, iv, note)
    if extras and "BI.B" in extras:
        add("BI", QUANTITIES["BI"][0], float(extras["BI.B"]), (math.nan, math.nan))
    if n_levels is not None:
        fl = allan_floor(model, fs, n_levels)
        note = (
            f"min over T = {fl['T_range_s'][0]:.4g}..{fl['T_range_s'][1]:.4g} s of the implied "
            f"ADEV / {BI_FACTOR:.3f}, at T = {fl['T_s']:.4g} s"
        )
        if fl["at_edge"]:
            note += "; no floor inside the analysed scales: an upper bound"
        b = QUANTITIES["BI"][0]
        floor = Quantity(b.code, b.symbol, f"{b.name} (Allan floor)", "", b.forward, None, b.unit)
        add("model", floor, fl["bias_instability"], (math.nan, math.nan), note)
    if note_si:
        rows.append(DatasheetRow(channel, "model", "units", "", math.nan, "", note=note_si))
    return rows


def datasheet(
    model: Model,
    fs: float,
    unit: str = "",
    *,
    n_levels: int | None = None,
    extras: Mapping[str, float] | None = None,
) -> list[dict[str, Any]]:
    """Datasheet quantities of a model with every value set, as dictionaries.

    The rows of :func:`datasheet_rows` (same names, symbols and units as ``gmwm export
    --format datasheet``) without the note-only rows, as ``{"label", "quantity", "symbol",
    "value", "unit"}`` in the model's order.
    """
    return [
        {
            "label": r.process,
            "quantity": r.quantity,
            "symbol": r.symbol,
            "value": r.value,
            "unit": r.unit,
        }
        for r in datasheet_rows(model, fs, unit, n_levels=n_levels, extras=extras)
        if math.isfinite(r.value)
    ]
