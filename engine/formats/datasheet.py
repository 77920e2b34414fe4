"""The datasheet export: every channel's rows from the one table (:mod:`engine.units`).

* :func:`datasheet_table`: one row per datasheet quantity and channel (angle/velocity random
  walk, rate/acceleration random walk, quantization, rate ramp, Gauss-Markov correlation time
  and driving-noise PSD, bias-instability floor), in the log's unit, in SI and in the usual
  datasheet unit, with intervals when parameter intervals are given;
* :func:`datasheet_text`, :func:`datasheet_csv`: the rows as a table or CSV.

The conversions, names, symbols and units are those of :data:`engine.units.QUANTITIES` and
:data:`engine.units.DISPLAY` (the ``gmwm fit`` summary and the app print the same rows).
**Bias-instability floor** ``B = min_T ADEV(T) / 0.664`` with ADEV the Allan deviation implied
by the fitted model (``AVAR(T) = 2 nu2(tau)`` at ``tau = 2 T fs`` samples), over the analysed
scales ``T = 1/fs .. 2^(J-1)/fs`` (:func:`engine.units.allan_floor`); when the implied ADEV
has no minimum inside the scales, B is an upper bound and the row says so.
"""

from __future__ import annotations

import csv
import io as _io
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from ..fit import GMWMResult
from ..units import DatasheetRow, ExportError, datasheet_rows
from .common import csv_cells, fmt_float, text_lines

if TYPE_CHECKING:  # pragma: no cover
    from ..inference import ParamInterval

__all__ = ["datasheet_table", "datasheet_text", "datasheet_csv"]


def _intervals_map(intervals: Sequence[ParamInterval] | None) -> dict[str, tuple[float, float]]:
    if not intervals:
        return {}
    return {iv.name: (float(iv.low), float(iv.high)) for iv in intervals}


def datasheet_table(
    fits: GMWMResult | Mapping[str, GMWMResult],
    *,
    intervals: Sequence[ParamInterval] | Mapping[str, Sequence[ParamInterval]] | None = None,
    units: Mapping[str, str] | None = None,
    si: bool = True,
) -> list[DatasheetRow]:
    """Datasheet quantities of fitted models, per channel, with units and intervals.

    Parameters
    ----------
    fits : GMWMResult or mapping of channel name to GMWMResult
        One fit (named ``"x"``), or one per channel.
    intervals : sequence of ParamInterval, or mapping of channel to them, optional
        Parameter intervals (:func:`engine.inference.param_intervals`); quantities that are
        monotone functions of one parameter get the mapped interval.
    units : mapping of str to str, optional
        Signal unit per channel; default ``fit.wv.unit``.
    si : bool
        Add SI and datasheet-unit rows (needs a known unit; unknown units give only the
        native rows, with a note).

    Returns
    -------
    list of DatasheetRow
        In channel order, then the model's process order, then the bias-instability floor.
    """
    if isinstance(fits, GMWMResult):
        fits = {"x": fits}
        if intervals is not None and not isinstance(intervals, Mapping):
            intervals = {"x": intervals}
    elif intervals is not None and not isinstance(intervals, Mapping):
        raise ExportError("with several channels give intervals as {channel: [ParamInterval]}")
    rows: list[DatasheetRow] = []
    for ch, res in fits.items():
        unit = (units or {}).get(ch, res.wv.unit) or ""
        ivs = _intervals_map((intervals or {}).get(ch))
        rows += datasheet_rows(
            res.model,
            res.fs,
            unit,
            channel=ch,
            intervals=ivs,
            si=si,
            n_levels=res.wv.n_levels,
        )
    return rows


def datasheet_text(rows: Sequence[DatasheetRow]) -> str:
    """A readable table of :func:`datasheet_table` rows."""
    out = [f"{'channel':<10} {'process':<8} {'quantity':<40} {'value':>12} {'interval':>27}  unit"]
    for r in rows:
        if not math.isfinite(r.value):
            out.append(f"{r.channel:<10} {r.process:<8} {r.note}")
            continue
        ivl = (
            f"[{r.low:.4g}, {r.high:.4g}]" if math.isfinite(r.low) and math.isfinite(r.high) else ""
        )
        out.append(
            f"{r.channel:<10} {r.process:<8} {r.quantity:<40} {r.value:>12.5g} {ivl:>27}  {r.unit}"
        )
    return text_lines(out, end="")


def datasheet_csv(rows: Sequence[DatasheetRow]) -> str:
    """CSV of :func:`datasheet_table` rows (empty cells for missing intervals)."""
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["channel", "process", "quantity", "symbol", "value", "low", "high", "unit", "note"])
    for r in rows:
        w.writerow(
            csv_cells(
                [
                    r.channel,
                    r.process,
                    r.quantity,
                    r.symbol,
                    fmt_float(r.value),
                    fmt_float(r.low),
                    fmt_float(r.high),
                    r.unit,
                    r.note,
                ]
            )
        )
    return buf.getvalue()
