"""The datasheet keys and units the datasheet check and the fleet limits accept.

``arw=0.3 deg/sqrt(h)``: :data:`DATASHEET_KEYS` maps a key to its datasheet symbol (N, K, B,
Q), :data:`UNITS` the accepted spellings of each symbol's units to SI (from the one unit table,
:mod:`engine.units`), :func:`convert_value` turns one value into SI. Used by
:mod:`engine.inference.datasheet_spec` (parsing) and :mod:`engine.inference.datasheet_check`
(reading files).
"""

from __future__ import annotations

import math
import re

from ..errors import DatasheetError
from ..units import DISPLAY, QUANTITIES, si_factor

__all__ = [
    "DATASHEET_KEYS",
    "ADEV_MIN_KEYS",
    "CONVENTION",
    "KEY_KIND",
    "ORDER",
    "QUANTITY_OF",
    "SIGNAL_UNITS",
    "UNITS",
    "DatasheetError",
    "canon_unit",
    "convert_value",
    "unit_table",
]


#: Accepted keys (lower case) -> datasheet symbol of :data:`engine.units.QUANTITIES`.
DATASHEET_KEYS: dict[str, str] = {
    "arw": "N",
    "vrw": "N",
    "n": "N",
    "wn": "N",
    "rrw": "K",
    "accrw": "K",
    "k": "K",
    "rw": "K",
    "bi": "B",
    "b": "B",
    "bi_min": "B",
    "bis": "B",
    "adev_min": "B",
    "q": "Q",
    "qn": "Q",
}
#: Datasheet symbol -> its quantity (N of WN, K of RW, Q of QN, B of the model's floor).
QUANTITY_OF = {q.symbol: q for qs in QUANTITIES.values() for q in qs}
ORDER = ("N", "K", "B", "Q")
#: Keys that declare the bias instability as the Allan-deviation minimum itself (the vendors'
#: "in-run bias stability", allan_variance_ros), not as the IEEE 952 B = floor / 0.664.
ADEV_MIN_KEYS = frozenset({"bi_min", "bis", "adev_min"})
#: ``bi=VALUE UNIT (adev min)`` / ``(ieee)``: the convention written after the unit.
CONVENTION = re.compile(
    r"\s*\(\s*(adev[\s_-]*min(?:imum)?|adev|ieee(?:\s*952)?)\s*\)\s*$", re.IGNORECASE
)
KEY_KIND = {
    "arw": "gyroscope",
    "rrw": "gyroscope",
    "vrw": "accelerometer",
    "accrw": "accelerometer",
}
#: Signal units whose native datasheet units are accepted (``deg/s/sqrt(Hz)``, ``g*s`` ...).
SIGNAL_UNITS = ("rad/s", "deg/s", "deg/h", "mrad/s", "m/s^2", "g", "mg", "ug")


def canon_unit(unit: str) -> str:
    """A unit spelling reduced for comparison: ``(deg/s)/sqrt(Hz)`` == ``deg/s/rtHz``."""
    u = unit.strip().lower().replace(" ", "").replace("°", "deg").replace("√", "sqrt")
    u = u.replace("µ", "u").replace("**", "^").replace("²", "^2")
    u = re.sub(r"sqrt\(([a-z]+)\)", r"sqrt\1", u)
    u = u.replace("(", "").replace(")", "")
    u = re.sub(r"\brt(hz|h|s)", r"sqrt\1", u).replace("/rt", "/sqrt")
    u = u.replace("hr", "h").replace("sec", "s").replace("dps", "deg/s").replace("degs", "deg")
    return u


def unit_table() -> dict[str, dict[str, tuple[str, str, float]]]:
    """Per symbol: canonical unit -> (kind, spelling, factor to SI), from engine.units."""
    table: dict[str, dict[str, tuple[str, str, float]]] = {s: {} for s in ORDER}
    for sym in ORDER:
        q = QUANTITY_OF[sym]
        for u in SIGNAL_UNITS:
            kind, f = si_factor(u)
            spelled = q.unit(u)
            table[sym].setdefault(canon_unit(spelled), (kind, spelled, f))
        for (kind, dsym), d in DISPLAY.items():
            if dsym == sym:
                table[sym].setdefault(canon_unit(d.unit), (kind, d.unit, 1.0 / d.factor))
    return table


UNITS = unit_table()


def convert_value(sym: str, value: float, unit: str, where: str) -> tuple[str, float]:
    """(kind, SI value) of one datasheet value with its unit."""
    got = UNITS[sym].get(canon_unit(unit))
    if got is None:
        ok = ", ".join(dict.fromkeys(s for _, s, _ in UNITS[sym].values()))
        raise DatasheetError(f"{where}: unit {unit!r} is not a unit of {sym}; use one of {ok}")
    if not math.isfinite(value) or value < 0:
        raise DatasheetError(f"{where}: {value!r} is not a non-negative number")
    return got[0], value * got[2]
