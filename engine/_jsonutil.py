"""JSON-ready values: NaN/Inf become None (JSON's null), NumPy scalars and arrays plain Python;
and the plain-text column tables of the per-level results."""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, cast

import numpy as np

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "json_ready",
    "json_fields",
    "JsonFields",
    "FieldsDict",
    "columns_table",
    "interval_columns",
]


def json_ready(o: Any) -> Any:
    """``o`` with every non-finite float replaced by None and NumPy types made plain Python.

    Dictionaries (keys as strings), lists and tuples are converted recursively; other values
    are returned as they are. ``json.dumps(json_ready(o), allow_nan=False)`` then always works
    for numbers, whatever the strings contain.
    """
    if isinstance(o, dict):
        return {str(k): json_ready(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_ready(v) for v in o]
    if isinstance(o, np.ndarray):
        return json_ready(o.tolist())
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def json_fields(obj: Any, names: str | Iterable[str]) -> dict[str, Any]:
    """``{name: json_ready(getattr(obj, name))}`` for ``names`` (an iterable, or one string of
    names separated by spaces), in that order.

    The ``to_dict`` of a result whose JSON form is a list of its attributes (arrays become
    lists, NumPy scalars plain Python, NaN None): the WV, the Allan variance, the WCCV and
    the WV matrix.
    """
    if isinstance(names, str):
        names = names.split()
    return {name: json_ready(getattr(obj, name)) for name in names}


class JsonFields:
    """Mixin: ``to_dict()`` is :func:`json_fields` of the names in the class's ``json_fields``
    (one string, names separated by spaces)."""

    json_fields: ClassVar[str] = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the attributes named in ``json_fields``, in that order
        (arrays as lists, NaN as None)."""
        return json_fields(self, self.json_fields)


class FieldsDict:
    """Mixin for a dataclass: ``to_dict()`` is ``dataclasses.asdict`` (every field by name,
    values as they are)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: every field by name."""
        # the mixin's classes are dataclasses, which the type of ``self`` cannot say
        return dataclasses.asdict(cast("DataclassInstance", self))


def _placement(spec: str) -> str:
    """The alignment and width that open a format spec (``">12"`` of ``">12.4e"``)."""
    m = re.match(r"[<>^]?\d*", spec)
    return m.group() if m else ""


#: One column of :func:`columns_table`: (heading, format spec, one value per row).
Column = tuple[str, str, "Sequence[Any] | np.ndarray"]


def interval_columns(
    alpha: float, low: Sequence[float] | np.ndarray, high: Sequence[float] | np.ndarray
) -> list[Column]:
    """The two :func:`columns_table` columns of a ``1 - alpha`` interval, e.g. ``95% low``."""
    ci = f"{100 * (1 - alpha):g}%"
    return [(ci + " low", ">12.4e", low), (ci + " high", ">12.4e", high)]


def columns_table(title: str, columns: Sequence[Column]) -> str:
    """A plain-text table: a title line, a header line and one line per row.

    Parameters
    ----------
    title : str
        First line.
    columns : sequence of (heading, spec, values)
        One per column: ``spec`` is a format spec (e.g. ``">12.4e"``) whose alignment and
        width also place the heading; every ``values`` has one entry per row. Columns are
        separated by one space.
    """
    head = " ".join(format(h, _placement(spec)) for h, spec, _ in columns)
    rows = zip(*(v for _, _, v in columns), strict=True)
    body = [" ".join(format(v, c[1]) for v, c in zip(row, columns, strict=True)) for row in rows]
    return "\n".join([title, head, *body])
