"""Datasheet quantities and unit spelling, shared by :mod:`engine.models` and :mod:`engine.units`.

Each process class lists its datasheet quantities (:class:`Quantity`) as a class attribute;
:mod:`engine.units` builds the datasheet rows from them. The unit-spelling helpers live here
so that both layers use one spelling (``deg/s`` -> ``deg/s^2``, ``(deg/s)^2`` ...); their public
home is :mod:`engine.units`. Conventions: ``docs/conventions.md``, "Units and datasheet
conversions".
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

__all__ = ["Quantity", "squared", "per_s", "times_s", "sqrt0"]


def squared(unit: str) -> str:
    """``(deg/s)^2`` for ``deg/s``, ``g^2`` for ``g``, ``u^2`` when the unit is unknown.

    The one spelling of a squared unit (CLI, JSON, app: the app only prints ``^2`` as ``²``).
    """
    u = unit or "u"
    return f"({u})^2" if any(c in u for c in "/* ^") else f"{u}^2"


def per_s(unit: str) -> str:
    """``unit / s`` simplified: ``deg/s`` -> ``deg/s^2``, ``m/s^2`` -> ``m/s^3``, ``g/s``."""
    u = unit or "u"
    if u.endswith("/s"):
        return u + "^2"
    m = re.fullmatch(r"(.*)/s\^(\d)", u)
    if m:
        return f"{m.group(1)}/s^{int(m.group(2)) + 1}"
    return f"{u}/s"


def times_s(unit: str) -> str:
    """``unit * s`` simplified: ``deg/s`` -> ``deg``, ``m/s^2`` -> ``m/s``, ``g`` -> ``g*s``."""
    u = unit or "u"
    if u.endswith("/s"):
        return u[:-2]
    m = re.fullmatch(r"(.*)/s\^(\d)", u)
    if m:
        k = int(m.group(2)) - 1
        return f"{m.group(1)}/s" + (f"^{k}" if k > 1 else "")
    return f"{u}*s"


def sqrt0(x: float) -> float:
    """``sqrt(max(x, 0))``: a datasheet root of a variance fitted at (or rounded below) zero."""
    return math.sqrt(max(x, 0.0))


@dataclass(frozen=True)
class Quantity:
    """One datasheet quantity of a process.

    ``forward(params, fs)`` maps the process's per-sample parameters (a dict by parameter
    name; AR1 is first mapped to GM) to the datasheet value, ``inverse(value, fs)`` gives the
    parameter ``param`` back (None when the quantity is not invertible alone); ``unit(u)`` is
    the unit for a signal in ``u``; ``si`` says whether an SI row is printed; ``magnitude``
    that the sign is not identified by the WV (rows report ``|value|``).
    """

    code: str
    symbol: str
    name: str
    param: str
    forward: Callable[[Mapping[str, float], float], float]
    inverse: Callable[[float, float], float] | None
    unit: Callable[[str], str]
    si: bool = True
    magnitude: bool = False
    accel_name: str = ""
