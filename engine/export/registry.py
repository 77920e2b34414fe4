"""The export formats by name: one :class:`Format` per format, and :func:`export`.

A new filter format (OpenVINS, Basalt, VINS ...) is one module with a writer
``writer(fits, **options) -> str`` (and a reader where one exists) that takes its numbers from
the one datasheet table (:mod:`engine.units`), plus one :func:`register` call below.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..fit import GMWMResult
from ..units import ExportError
from .datasheet import datasheet_csv, datasheet_table, datasheet_text
from .kalibr import kalibr_imu, read_kalibr
from .report import curves_csv, fit_report

if TYPE_CHECKING:  # pragma: no cover
    from ..inference import ParamInterval
    from ..io import ImuLog

__all__ = ["Format", "FORMATS", "register", "export"]


@dataclass(frozen=True)
class Format:
    """An export format: ``writer(fits, **options) -> text``; ``reader(path or text)``.

    The options every writer receives (and may ignore): ``intervals``, ``log``, ``units``,
    ``source``, ``rostopic``, ``allow_partial``.
    """

    name: str
    description: str
    writer: Callable[..., str]
    reader: Callable[[Any], Any] | None = None
    suffix: str = ".txt"


#: Registered formats by name, in registration order.
FORMATS: dict[str, Format] = {}


def register(fmt: Format) -> Format:
    """Add (or replace) a format; returns it."""
    FORMATS[fmt.name] = fmt
    return fmt


def _kalibr(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    return kalibr_imu(
        fits,
        units=kw.get("units"),
        rostopic=kw.get("rostopic", "/imu0"),
        source=kw.get("source", ""),
        allow_partial=kw.get("allow_partial", False),
    ).to_yaml()


def _json(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    rep = fit_report(
        fits,
        intervals=kw.get("intervals"),
        log=kw.get("log"),
        units=kw.get("units"),
        source=kw.get("source", ""),
    )
    return json.dumps(rep, indent=1, allow_nan=False) + "\n"


def _datasheet(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    return (
        datasheet_text(datasheet_table(fits, intervals=kw.get("intervals"), units=kw.get("units")))
        + "\n"
    )


def _datasheet_csv(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    return datasheet_csv(
        datasheet_table(fits, intervals=kw.get("intervals"), units=kw.get("units"))
    )


register(Format("kalibr", "Kalibr imu.yaml", _kalibr, read_kalibr, ".yaml"))
register(Format("json", "JSON report", _json, None, ".json"))


def _curves(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    return curves_csv(fits)


register(Format("csv", "CSV of the WV and implied curves", _curves, None, ".csv"))
register(Format("datasheet", "readable datasheet table", _datasheet, None, ".txt"))
register(Format("datasheet-csv", "datasheet CSV", _datasheet_csv, None, ".csv"))


def export(
    path: str | os.PathLike[str] | None,
    fits: Mapping[str, GMWMResult],
    fmt: str,
    *,
    intervals: Mapping[str, Sequence[ParamInterval]] | None = None,
    log: ImuLog | None = None,
    units: Mapping[str, str] | None = None,
    source: str = "",
    rostopic: str = "/imu0",
    allow_partial: bool = False,
) -> str:
    """Export fits in one format; writes ``path`` (unless None) and returns the text.

    Parameters
    ----------
    path : path or None
        Where to write the text.
    fits : mapping of channel name to GMWMResult
    fmt : str
        A name of :data:`FORMATS`: ``"kalibr"`` (Kalibr ``imu.yaml``), ``"json"`` (JSON
        report), ``"csv"`` (WV and implied curves), ``"datasheet"`` (readable datasheet
        table), ``"datasheet-csv"``.
    intervals, log, units, source, rostopic, allow_partial
        Passed to the format's writer (parameter intervals per channel, the log for the JSON
        report, signal unit per channel, source name, Kalibr topic, partial Kalibr file).
    """
    f = FORMATS.get(fmt)
    if f is None:
        raise ExportError(f"unknown export format {fmt!r}: use one of {', '.join(FORMATS)}")
    text = f.writer(
        fits,
        intervals=intervals,
        log=log,
        units=units,
        source=source,
        rostopic=rostopic,
        allow_partial=allow_partial,
    )
    if path is not None:
        Path(path).write_text(text)
    return text
