"""Reports: :func:`fit_report` (JSON of every channel's fit, its intervals, datasheet rows,
Allan floor, its projections onto filter noise models and Kalibr numbers) and
:func:`curves_csv` (the empirical and implied WV curves)."""

from __future__ import annotations

import csv
import io as _io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._files import write_atomic
from .._jsonutil import json_ready
from .._version import __version__
from ..fit import GMWMResult
from ..io.log import channel_axis
from ..units import ExportError, allan_floor, si_factor, squared
from .common import csv_cells, fmt_float, source_text
from .datasheet import datasheet_table
from .kalibr import kalibr_imu
from .projection import consumer_of, misfit, project
from .tails import TailFactors

if TYPE_CHECKING:  # pragma: no cover
    from ..inference import ParamInterval
    from ..io import ImuLog

__all__ = ["fit_report", "write_report", "curves_csv", "DEFAULT_REPORT_CONSUMERS"]

#: The projections a report carries when none are requested.
DEFAULT_REPORT_CONSUMERS: tuple[str, ...] = ("WN+RW",)


def fit_report(
    fits: Mapping[str, GMWMResult],
    *,
    intervals: Mapping[str, Sequence[ParamInterval]] | None = None,
    log: ImuLog | None = None,
    units: Mapping[str, str] | None = None,
    source: str | os.PathLike[str] = "",
    kalibr: bool = True,
    consumers: Sequence[str] | None = None,
    projection: str = "bound",
    filter_rate: float | None = None,
    horizon_s: float | None = None,
    band: Sequence[float] | None = None,
    confidence: float | None = None,
    ci: str | None = "asymptotic",
    data: str = "low",
    tails: Mapping[str, TailFactors] | None = None,
) -> dict[str, Any]:
    """A JSON-ready report of every channel's fit.

    Parameters
    ----------
    fits : mapping of channel name to GMWMResult
    intervals : mapping, optional
        Parameter intervals per channel (:func:`engine.inference.param_intervals`).
    log : ImuLog, optional
        The log (its rate, length, units, time report).
    units : mapping, optional
        Signal unit per channel (default each WV's unit).
    source : str or path
        Source name.
    kalibr : bool
        Add the Kalibr numbers.
    consumers : sequence of str, optional
        The filter noise models or filter formats to project each fit onto
        (:func:`engine.formats.projection.project`; default :data:`DEFAULT_REPORT_CONSUMERS`,
        the WN + RW of Kalibr/OpenVINS/PX4 ...). Duplicates of one consumer model are kept
        under each requested name.
    projection : {"bound", "plain", "fit"}
        ``"bound"`` (default): projected and over-bounded; ``"plain"``: the rule alone;
        ``"fit"``: no projections (the report of the fit alone).
    filter_rate, horizon_s, band, confidence, ci, data
        The projection's filter rate (Hz, default the log's), horizon (s), band (s),
        confidence of the bounded WV limit, intervals (``"asymptotic"`` or None) and what of
        the empirical WV the bound covers (:data:`~engine.formats.options.DATA_BOUNDS`).
    tails : mapping of channel name to TailFactors, optional
        The projections' tail factors (:mod:`engine.formats.tails`; none by default).

    Returns
    -------
    dict
        ``schema`` (``"gmwm-report/1"``), ``engine_version``, ``source``, ``log`` (fs, n,
        units, time report and notes when ``log`` is given), ``projection`` (mode, consumers
        and options), and ``channels``: per channel the unit, sensor kind and axis, the fit
        (:meth:`GMWMResult.to_dict`), its intervals, the datasheet rows, the Allan floor and
        ``misfit`` (:func:`~engine.formats.projection.misfit`: one line when model and
        data disagree, else ``""``), ``projections`` (per requested consumer
        :meth:`Projection.to_dict`: each value with
        its plain conversion, factor, binding scale, interval and level; or ``{"error":
        reason}``); ``kalibr`` (or the reason it is missing). NaN values are ``null``.

    Raises
    ------
    ExportError
        An unknown consumer or projection mode.
    """
    if projection not in ("bound", "plain", "fit"):
        raise ExportError(f"projection must be 'bound', 'plain' or 'fit', got {projection!r}")
    cons = list(DEFAULT_REPORT_CONSUMERS if consumers is None else consumers)
    if projection == "fit":
        cons = []
    for c in cons:  # unknown names fail here, before any work
        consumer_of(c)
    units = dict(units or {})
    opts: dict[str, Any] = {
        "filter_rate": filter_rate,
        "horizon_s": horizon_s,
        "band_s": None if band is None else [float(v) for v in band],
        "confidence": confidence,
        "ci": ci,
        "bound": projection == "bound",
        "data": data,
    }
    chans: dict[str, Any] = {}
    for ch, res in fits.items():
        unit = units.get(ch, res.wv.unit) or ""
        try:
            kind: str | None = si_factor(unit, ch)[0]
        except ExportError:
            kind = None
        ivs = (intervals or {}).get(ch)
        chans[ch] = {
            "unit": unit,
            "sensor": kind,
            "axis": channel_axis(ch),
            "fit": res.to_dict(),
            "intervals": [iv.to_dict() for iv in ivs] if ivs else None,
            "datasheet": [
                r.to_dict()
                for r in datasheet_table(
                    {ch: res}, intervals={ch: ivs} if ivs else None, units={ch: unit}
                )
            ],
            "allan_floor": allan_floor(res.model, res.fs, res.wv.n_levels),
            "misfit": misfit(res, ch),
            "projections": {
                c: _projection(res, c, ch, unit, opts, (tails or {}).get(ch)) for c in cons
            },
        }
    out: dict[str, Any] = {
        "schema": "gmwm-report/1",
        "engine_version": __version__,
        "source": source_text(source) or (source_text(log.source) if log is not None else ""),
        "projection": {"mode": projection, "consumers": cons, **opts},
        "channels": chans,
    }
    if log is not None:
        out["log"] = {
            "fs": log.fs,
            "fs_source": log.fs_source,
            "n": log.n,
            "units": dict(log.units),
            "format": log.meta.get("format"),
            "time_report": log.meta.get("time_report"),
            "segment": log.meta.get("segment"),
            "scale": log.meta.get("scale"),
            "notes": log.meta.get("notes", []),
        }
    if kalibr:
        try:
            out["kalibr"] = kalibr_imu(
                fits, units=units or None, source=out["source"], allow_partial=True
            ).to_dict()
        except ExportError as e:
            out["kalibr"] = {"error": str(e)}
    return json_ready(out)


def _projection(
    res: GMWMResult,
    consumer: str,
    channel: str,
    unit: str,
    opts: Mapping[str, Any],
    tails: TailFactors | None = None,
) -> dict[str, Any]:
    """One channel's projection as a dictionary, or ``{"error": reason}``."""
    try:
        p = project(
            res,
            consumer,
            fs_filter=opts["filter_rate"],
            horizon_s=opts["horizon_s"],
            band=opts["band_s"],
            confidence=opts["confidence"],
            bound=opts["bound"],
            channel=channel,
            unit=unit,
            ci=opts["ci"],
            data=opts["data"],
            tails=tails,
        )
    except ExportError as e:
        return {"error": str(e)}
    return p.to_dict()


def write_report(
    path: str | os.PathLike[str], fits: Mapping[str, GMWMResult], **kwargs: Any
) -> Path:
    """Write :func:`fit_report` as strict JSON (no NaN); returns the path."""
    p = Path(path)
    write_atomic(p, json.dumps(fit_report(fits, **kwargs), indent=1, allow_nan=False) + "\n")
    return p


def curves_csv(fits: GMWMResult | Mapping[str, GMWMResult]) -> str:
    """CSV of the empirical WV, its interval and the implied WV (total and per process).

    Columns: ``channel, level, tau_samples, tau_s, wv, ci_low, ci_high, implied`` then one
    column per process label (``GM_1, WN, RW`` ...; the union over channels, empty where a
    channel's model lacks the process), and ``wv_unit``. Numbers are written with 17
    significant digits (exact round trip).
    """
    if isinstance(fits, GMWMResult):
        fits = {"x": fits}
    labels: list[str] = []
    for res in fits.values():
        labels += [lab for lab in res.components if lab not in labels]
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            "channel",
            "level",
            "tau_samples",
            "tau_s",
            "wv",
            "ci_low",
            "ci_high",
            "implied",
            *labels,
            "wv_unit",
        ]
    )
    for ch, res in fits.items():
        wv = res.wv
        for i in range(wv.n_levels):
            comp = [
                fmt_float(res.components[lab][i]) if lab in res.components else "" for lab in labels
            ]
            w.writerow(
                csv_cells(
                    [
                        ch,
                        int(wv.levels[i]),
                        int(wv.tau_samples[i]),
                        fmt_float(wv.tau_s[i]),
                        fmt_float(wv.variance[i]),
                        fmt_float(wv.ci_low[i]),
                        fmt_float(wv.ci_high[i]),
                        fmt_float(res.implied[i]),
                        *comp,
                        squared(wv.unit) if wv.unit else "",
                    ]
                )
            )
    return buf.getvalue()
