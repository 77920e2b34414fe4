"""A datasheet's noise values as a model: :class:`DatasheetSpec` and :func:`parse_datasheet`.

A datasheet states a few numbers: angle (gyroscope) or velocity (accelerometer) random walk,
bias instability, rate (or acceleration) random walk, sometimes quantization.
:class:`DatasheetSpec` holds them in SI units (converted through the one datasheet table,
:mod:`engine.units`) and gives the GMWM processes they imply (:meth:`DatasheetSpec.model`);
:func:`parse_datasheet` reads them from a line of text (``gmwm plan --datasheet``, ``gmwm check
--datasheet``). Reading them from a file (:func:`engine.inference.datasheet_check.
read_datasheet`: Kalibr YAML, JSON, CSV) and checking them against a log's WV
(:func:`engine.inference.datasheet_check.check_datasheet`) live beside the check; this module
needs neither the loaders nor PyYAML, so that ``gmwm plan --datasheet`` does not load them.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ..models import GM, QN, RW, WN, Model
from ..units import BI_FACTOR, DISPLAY, SI_UNIT, ExportError, quantity_name, si_factor
from .datasheet_keys import ADEV_MIN_KEYS, DATASHEET_KEYS, DatasheetError
from .datasheet_keys import CONVENTION as _CONVENTION
from .datasheet_keys import KEY_KIND as _KEY_KIND
from .datasheet_keys import ORDER as _ORDER
from .datasheet_keys import QUANTITY_OF as _QUANTITY
from .datasheet_keys import convert_value as _convert

__all__ = ["DatasheetSpec", "parse_datasheet"]


@dataclass(frozen=True, eq=False)
class DatasheetSpec:
    """Datasheet noise values of one sensor, in SI units.

    Attributes
    ----------
    kind : {"gyroscope", "accelerometer"}
        Sensor kind (SI signal unit rad/s or m/s^2).
    values : dict of str to float
        ``N`` white-noise density [SI/sqrt(Hz)], ``K`` random-walk density [SI/s/sqrt(Hz)],
        ``B`` bias instability [SI], ``Q`` quantization [SI*s]; only the given ones.
    given : dict of str to str
        The values as the user wrote them (``"0.3 deg/sqrt(h)"``), by symbol.
    source : str
        Where they come from (``command line``, a file and its key).
    bi_convention : {"ieee", "adev_min"}
        How B was declared: ``ieee`` (IEEE 952 B, the Allan floor / 0.664) or ``adev_min``
        (the Allan-deviation minimum itself, e.g. Analog Devices' "in-run bias stability";
        ``values["B"]`` then holds that minimum / 0.664, so the check draws the same floor).
    also : DatasheetSpec or None
        The other sensor kind's values of the same datasheet (gyroscope and accelerometer
        items given together); :meth:`for_kind` picks one.
    gm : tuple of (float, float)
        Gauss-Markov terms ``(T_c [s], sigma_b [SI])`` (a filter file's Gauss-Markov bias, a
        datasheet CSV's GM rows); each adds ``GM(beta = 1/T_c, sigma2_gm = sigma_b^2)``.
    """

    kind: str
    values: dict[str, float]
    given: dict[str, str] = field(default_factory=dict)
    source: str = ""
    bi_convention: str = "ieee"
    also: DatasheetSpec | None = None
    gm: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in SI_UNIT:
            raise DatasheetError(f"sensor kind {self.kind!r}: use gyroscope or accelerometer")
        bad = [k for k in self.values if k not in _ORDER]
        if bad:
            raise DatasheetError(f"unknown datasheet symbol(s) {bad}: use N, K, B, Q")
        for tc, sb in self.gm:
            if not (math.isfinite(tc) and tc > 0 and math.isfinite(sb) and sb >= 0):
                raise DatasheetError(
                    f"{self.source or 'datasheet'}: a Gauss-Markov term needs T_c > 0 s and "
                    f"sigma_b >= 0, got T_c {tc!r}, sigma_b {sb!r}"
                )
        if not self.values and not self.gm:
            raise DatasheetError(
                "the datasheet has no value: give at least one of ARW/VRW, RRW, BI, Q"
            )
        if self.bi_convention not in ("ieee", "adev_min"):
            raise DatasheetError(
                f"bias-instability convention {self.bi_convention!r}: use ieee or adev_min"
            )
        if self.also is not None and (self.also.kind == self.kind or self.also.also is not None):
            raise DatasheetError("a datasheet holds at most one part per sensor kind")

    @property
    def kinds(self) -> tuple[str, ...]:
        """The sensor kinds the datasheet has values for."""
        return (self.kind,) + ((self.also.kind,) if self.also is not None else ())

    def for_kind(self, kind: str) -> DatasheetSpec:
        """The part of the datasheet for one sensor kind (``gyroscope``/``accelerometer``).

        Raises
        ------
        DatasheetError
            The datasheet has no value for that kind.
        """
        for part in (self, self.also):
            if part is not None and part.kind == kind:
                return replace(part, also=None)  # its own values, GM terms and convention
        raise DatasheetError(
            f"the datasheet ({self.describe()}) has no {kind} value; give "
            f"{'arw/rrw' if kind == 'gyroscope' else 'vrw/accrw'} items for it"
        )

    def for_unit(self, unit: str) -> DatasheetSpec:
        """The part for a channel's signal unit (itself when it has one part only)."""
        if self.also is None:
            return self
        try:
            kind = si_factor(unit)[0]
        except ExportError as e:
            raise DatasheetError(f"{e}; the datasheet check needs the log's unit") from e
        return self.for_kind(kind)

    @classmethod
    def from_values(
        cls,
        values: Mapping[str, tuple[float, str]] | Sequence[tuple[str, float, str]],
        *,
        source: str = "",
    ) -> DatasheetSpec:
        """From ``{key: (value, unit)}`` (or ``[(key, value, unit), ...]``, where a key may come
        once per sensor kind) with keys of :data:`DATASHEET_KEYS` (``arw``, ``bi`` ...).

        Gyroscope and accelerometer values may be given together (``arw`` and ``vrw``, or
        ``bi`` in deg/h and in mg): the result then holds one part per kind
        (:meth:`for_kind`). ``bi_min``/``bis``/``adev_min`` (or ``bi=VALUE UNIT (adev min)``)
        declare the bias instability as the Allan-deviation minimum, ``bi`` (or
        ``(ieee)``) as the IEEE 952 B = floor / 0.664.

        Raises
        ------
        DatasheetError
            Unknown key or unit, a symbol given twice for one sensor kind.
        """
        si: dict[str, dict[str, float]] = {}
        given: dict[str, dict[str, str]] = {}
        conv: dict[str, str] = {}
        triples = (
            [(k, v, u) for k, (v, u) in values.items()]
            if isinstance(values, Mapping)
            else list(values)
        )
        for key, value, unit in triples:
            k = key.strip().lower()
            sym = DATASHEET_KEYS.get(k)
            if sym is None:
                raise DatasheetError(
                    f"unknown datasheet key {key!r}: use {', '.join(DATASHEET_KEYS)}"
                )
            convention = "adev_min" if k in ADEV_MIN_KEYS else "ieee"
            m = _CONVENTION.search(unit)
            if m is not None:
                if sym != "B":
                    raise DatasheetError(
                        f"{key} = {value} {unit}: a convention in parentheses is for bi only"
                    )
                convention = "ieee" if m.group(1).lower().startswith("ieee") else "adev_min"
                unit = unit[: m.start()].strip()
            kind, v = _convert(sym, float(value), unit, f"{source or 'datasheet'} {key}")
            if _KEY_KIND.get(k, kind) != kind:
                raise DatasheetError(
                    f"{key} = {value} {unit}: {k.upper()} is a {_KEY_KIND[k]} value"
                )
            if sym in si.get(kind, {}):
                raise DatasheetError(f"{key!r} gives the {kind}'s {sym} a second time")
            text = f"{value:g} {unit}"
            if sym == "B":
                conv[kind] = convention
                if convention == "adev_min":  # stored as the IEEE B of that floor
                    v, text = v / BI_FACTOR, f"{text} (ADEV minimum)"
            si.setdefault(kind, {})[sym] = v
            given.setdefault(kind, {})[sym] = text
        kinds = sorted(si, key=list(SI_UNIT).index) or ["gyroscope"]
        parts = [
            cls(kd, si.get(kd, {}), given.get(kd, {}), source, conv.get(kd, "ieee")) for kd in kinds
        ]
        if len(parts) == 1:
            return parts[0]
        first, second = parts
        return cls(first.kind, first.values, first.given, source, first.bi_convention, also=second)

    @property
    def si_unit(self) -> str:
        """``rad/s`` or ``m/s^2``."""
        return SI_UNIT[self.kind]

    def in_unit(self, unit: str) -> dict[str, float]:
        """The values in a signal unit ``unit`` (N in unit/sqrt(Hz) ...).

        Raises
        ------
        DatasheetError
            Unknown unit, or a unit of the other sensor kind.
        """
        try:
            kind, f = si_factor(unit)
        except ExportError as e:
            raise DatasheetError(f"{e}; the datasheet check needs the log's unit") from e
        if kind != self.kind:
            raise DatasheetError(
                f"the datasheet is a {self.kind}'s ({self.si_unit}) but the channel is in "
                f"{unit} ({kind})"
            )
        return {s: v / f for s, v in self.values.items()}

    def model(self, fs: float, unit: str) -> Model | None:
        """The GMWM processes of the datasheet (WN, RW, QN; per sample, in ``unit``), or None."""
        vals = self.in_unit(unit)
        cls = {"N": WN, "K": RW, "Q": QN}
        procs = [cls[s].from_datasheet({s: vals[s]}, fs) for s in ("Q", "N", "K") if s in vals]
        f = self._factor(unit)
        procs += [GM(beta=1.0 / tc, sigma2_gm=(sb / f) ** 2) for tc, sb in self.gm]
        return Model(tuple(procs)) if procs else None

    def _factor(self, unit: str) -> float:
        """SI per ``unit`` (checked as :meth:`in_unit` does)."""
        self.in_unit(unit)
        return si_factor(unit)[1]

    def floor_wv(self, unit: str) -> float:
        """The WV of the bias-instability floor, ``(BI_FACTOR B)^2 / 2`` [unit^2] (0 without B)."""
        b = self.in_unit(unit).get("B", 0.0)
        return (BI_FACTOR * b) ** 2 / 2.0

    def rows(self) -> list[dict[str, Any]]:
        """Per value: symbol, name, value in SI and in the datasheet unit, with units."""
        out = []
        for s in _ORDER:
            if s not in self.values:
                continue
            q = _QUANTITY[s]
            v = self.values[s]
            d = DISPLAY.get((self.kind, s))
            out.append(
                {
                    "symbol": s,
                    "name": quantity_name(q, self.kind),
                    "si": v,
                    "si_unit": q.unit(self.si_unit),
                    "display": None if d is None else v * d.factor,
                    "display_symbol": None if d is None else d.symbol,
                    "display_unit": None if d is None else d.unit,
                    "given": self.given.get(s, ""),
                }
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (``schema: gmwm-datasheet/1``); :func:`read_datasheet` reads it back."""
        d: dict[str, Any] = {
            "schema": "gmwm-datasheet/1",
            "kind": self.kind,
            "source": self.source,
            "values": {r["symbol"]: [r["si"], r["si_unit"]] for r in self.rows()},
            "rows": self.rows(),
            "bi_convention": self.bi_convention,
            "gm": [{"T_c": tc, "sigma_b": sb, "sigma_b_unit": self.si_unit} for tc, sb in self.gm],
        }
        if self.also is not None:
            d["also"] = self.also.to_dict()
        return d

    def describe(self) -> str:
        """One line: ``ARW 0.3 deg/sqrt(h), B 5 deg/h`` (datasheet units; the other sensor's
        part after a semicolon; a B declared as the ADEV minimum says so)."""
        parts = []
        for r in self.rows():
            if r["display"] is not None:
                parts.append(f"{r['display_symbol']} {r['display']:.4g} {r['display_unit']}")
            else:
                parts.append(f"{r['symbol']} {r['si']:.4g} {r['si_unit']}")
            if r["symbol"] == "B" and self.bi_convention == "adev_min":
                parts[-1] += f" (ADEV minimum {self.given.get('B', '').split(' (')[0]})"
        parts += [f"GM T_c {tc:.4g} s sigma_b {sb:.4g} {self.si_unit}" for tc, sb in self.gm]
        text = ", ".join(parts)
        return text if self.also is None else f"{text}; {self.also.describe()}"


def parse_datasheet(text: str, *, source: str = "command line") -> DatasheetSpec:
    """Parse ``"arw=0.3 deg/sqrt(h), bi=5 deg/h, rrw=2 deg/h/sqrt(h)"``.

    Items are separated by commas or semicolons, each ``KEY=VALUE UNIT``; keys are those of
    :data:`DATASHEET_KEYS` (``arw``/``vrw``, ``rrw``/``accrw``, ``bi``, ``q``), units the
    datasheet units of :data:`engine.units.DISPLAY` (``deg/sqrt(h)``, ``m/s/sqrt(h)``,
    ``deg/h/sqrt(h)``, ``m/s/h/sqrt(h)``, ``deg/h``, ``mg``) or a signal unit's native one
    (``deg/s/sqrt(Hz)``, ``rad/s^2/sqrt(Hz)``, ``m/s^2/sqrt(Hz)``, ``rad/s``, ``deg`` ...).

    Raises
    ------
    DatasheetError
        An item that is not ``KEY=VALUE UNIT``, or any error of :meth:`DatasheetSpec.from_values`.
    """
    items: list[tuple[str, float, str]] = []
    for raw in re.split(r"[;,]", text or ""):
        if not raw.strip():
            continue
        key, sep, rest = raw.partition("=")
        m = re.fullmatch(
            r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)(?![\d.])\s*(\S.*?)?\s*", rest
        )
        if not sep or not key.strip() or m is None:
            raise DatasheetError(f"datasheet item {raw.strip()!r} is not KEY=VALUE UNIT")
        value = float(m.group(1))  # the pattern admits only numbers float() reads
        if not m.group(2):
            raise DatasheetError(
                f"datasheet item {raw.strip()!r} has no unit (e.g. arw=0.3 deg/sqrt(h))"
            )
        # a key may come once per sensor kind (bi in deg/h and in mg): from_values checks
        items.append((key.strip().lower(), value, m.group(2)))
    return DatasheetSpec.from_values(items, source=source)
