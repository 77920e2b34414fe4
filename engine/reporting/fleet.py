"""Fleet acceptance: :func:`gather_fleet` fits a batch of logs and computes what a fleet
report shows (pure numerics; :func:`engine.reporting.render.render_fleet_html` draws it).

Per unit, in the worker that fits it, the log is loaded once, fitted by
:func:`engine.batch.fit_log` and its calibration report gathered from those fits; the caller
then adds the noise terms of every unit in datasheet units (:func:`noise_terms`), the verdicts
against limits (:func:`parse_limits`, checked on the fit's IEEE quantities) or a datasheet,
and the robust z-scores of every term across the units (:func:`robust_z`). Units whose log
cannot be read or fitted are in the report with their reason, never dropped. The verdict and
outlier rules: docs/methods.md, "Fleet acceptance"; the user's view: docs/reports.md.
"""

from __future__ import annotations

import inspect
import math
import os
import re
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._jsonutil import json_ready
from ..batch import (
    BatchFolder,
    BatchResult,
    LogFit,
    expand_paths,
    fit_log,
    options_fingerprint,
)
from ..models import WN
from ..units import BI_FACTOR, DISPLAY, DatasheetRow, ExportError, si_factor
from .data import CalibrationReport, ChannelReport, software_versions

__all__ = [
    "OUTLIER_Z",
    "OUTLIER_REL",
    "MIN_UNITS_Z",
    "Limit",
    "TermValue",
    "FleetUnit",
    "FleetReport",
    "robust_z",
    "parse_limits",
    "noise_terms",
    "ieee_terms",
    "temperature_terms",
    "gather_fleet",
]

#: Robust z-score beyond which a unit's term is an outlier (Iglewicz and Hoaglin 1993).
OUTLIER_Z = 3.5
#: Least relative difference from the fleet's median for an outlier (with a robust z beyond
#: OUTLIER_Z): units that agree within 10 % are alike for any datasheet.
OUTLIER_REL = 0.10
#: Fewest units with a term for its robust z-scores (with three, the MAD is one deviation).
MIN_UNITS_Z = 5
#: MAD of a normal sample / its SD.
_MAD_NORMAL = 1.4826
#: Mean absolute deviation of a normal sample / its SD, inverted (the MAD = 0 fallback).
_MEANAD_NORMAL = 1.253314

_SPEC = re.compile(r"\s*([A-Za-z_]+)\s*<=\s*(.+?)\s*")


def robust_z(x: Sequence[float] | np.ndarray) -> np.ndarray:
    """Robust z-scores ``(x - median) / (1.4826 MAD)`` of a sample (NaN entries stay NaN).

    With a MAD of 0 (more than half the values equal) the scale is ``1.253314`` times the
    mean absolute deviation from the median; when that is 0 too every z is 0. Fewer than
    :data:`MIN_UNITS_Z` finite values give NaN (too few to say what is usual: with three, the
    MAD is the smaller of two deviations and any unit can look like an outlier).

    Parameters
    ----------
    x : array_like, shape (n,)

    Returns
    -------
    ndarray, shape (n,)
    """
    a = np.asarray(x, float)
    z = np.full(a.shape, np.nan)
    ok = np.isfinite(a)
    if ok.sum() < MIN_UNITS_Z:
        return z
    v = a[ok]
    med = float(np.median(v))
    dev = np.abs(v - med)
    scale = _MAD_NORMAL * float(np.median(dev))
    if scale == 0.0:
        scale = _MEANAD_NORMAL * float(np.mean(dev))
    z[ok] = 0.0 if scale == 0.0 else (v - med) / scale
    return z


@dataclass(frozen=True)
class Limit:
    """An acceptance limit ``term <= value``: ``key`` as given (``arw``), its datasheet
    ``symbol`` (N, K, B, Q), the sensor ``kind``, the value in SI and as written;
    ``convention`` of a B limit: ``ieee`` (IEEE 952 B, floor / 0.664) or ``adev_min`` (the
    Allan-deviation minimum itself, ``bi_min<=``)."""

    key: str
    symbol: str
    kind: str
    si: float
    given: str
    convention: str = "ieee"

    @property
    def ieee_key(self) -> str:
        """The key of the IEEE quantity it limits (:data:`engine.fit.ieee.IEEE_KEYS`)."""
        return "ADEV_min" if self.symbol == "B" and self.convention == "adev_min" else self.symbol

    def in_unit(self, unit: str) -> float:
        """The limit in a channel's signal unit (N in unit/sqrt(Hz), B in unit ...)."""
        return self.si / si_factor(unit)[1]


def parse_limits(specs: Iterable[str]) -> list[Limit]:
    """Parse ``["arw<=0.3 deg/sqrt(h)", "bi<=5 deg/h"]`` (also one string with commas).

    Keys and units are the datasheet parser's (:func:`engine.inference.parse_datasheet`:
    ``arw``/``vrw``, ``rrw``/``accrw``, ``bi``, ``q``, in datasheet or native units); gyroscope
    and accelerometer limits may be mixed (each applies to the channels of its kind).

    Raises
    ------
    engine.inference.DatasheetError
        An item that is not ``KEY<=VALUE UNIT``, an unknown key or unit, a key given twice.
    """
    from ..inference.datasheet_check import DatasheetError, parse_datasheet

    out: list[Limit] = []
    seen: set[tuple[str, str]] = set()
    for text in specs:
        for raw in re.split(r"[;,]", text or ""):
            if not raw.strip():
                continue
            m = _SPEC.fullmatch(raw)
            if m is None:
                raise DatasheetError(
                    f"spec={raw.strip()!r} is not KEY<=VALUE UNIT (e.g. 'arw<=0.3 deg/sqrt(h)')"
                )
            spec = parse_datasheet(f"{m.group(1)}={m.group(2)}", source="spec=")
            ((sym, si),) = spec.values.items()
            conv = spec.bi_convention if sym == "B" else "ieee"
            if conv == "adev_min":
                si *= BI_FACTOR  # the spec stores the IEEE B of that minimum
            lim = Limit(m.group(1).lower(), sym, spec.kind, si, spec.given[sym], conv)
            if (spec.kind, lim.ieee_key) in seen:
                raise DatasheetError(f"spec={raw.strip()!r}: {sym} has a limit already")
            seen.add((spec.kind, lim.ieee_key))
            out.append(lim)
    return out


@dataclass(frozen=True)
class TermValue:
    """One noise term of one channel of one unit, in datasheet units.

    ``column`` is ``(process, symbol, unit)`` (``("WN", "ARW", "deg/sqrt(h)")``); ``native``
    the same value in the channel's own unit (for the limits); ``z`` the robust z-score
    across the units (NaN: fewer than :data:`MIN_UNITS_Z` units have it); ``note`` a mark
    shown beside the value (``"not compensated (p = 0.41)"``: a temperature sensitivity given
    as information only), ``""`` for none.
    """

    column: tuple[str, str, str]
    quantity: str
    value: float
    low: float
    high: float
    native: float
    native_symbol: str
    z: float = math.nan
    rel: float = math.nan
    note: str = ""

    @property
    def outlier(self) -> bool:
        """``|z| > OUTLIER_Z`` and a relative difference from the median ``|rel|`` above
        :data:`OUTLIER_REL`."""
        return bool(abs(self.z) > OUTLIER_Z and abs(self.rel) > OUTLIER_REL)


def _kind(unit: str, channel: str) -> str | None:
    try:
        return si_factor(unit, channel)[0]
    except ExportError:
        return None


def noise_terms(rows: Sequence[DatasheetRow], unit: str, channel: str = "") -> list[TermValue]:
    """The noise terms of a channel's datasheet rows, one per quantity, in datasheet units.

    The rows are :func:`engine.units.datasheet_rows`'s (native, SI, display per quantity);
    kept are the display rows of N, K, B and R (``ARW``, ``RRW``, ``B`` in deg/h ...) and the
    native rows of the others (``Q``, ``T_c``, ``sigma_gm``), without the GM driving noise
    (``q``, ``sqrt(q)``: functions of ``T_c`` and ``sigma_gm``). An unknown unit keeps the
    native rows.
    """
    kind = _kind(unit, channel)
    disp = {s: d for (k, s), d in DISPLAY.items() if k == kind}  # native symbol -> Display
    by_display = {(d.symbol, d.unit): s for s, d in disp.items()}
    native: dict[tuple[str, str], float] = {}
    out: list[TermValue] = []
    seen: set[tuple[str, str, str]] = set()
    for r in rows:
        if "SI" in r.quantity or r.symbol in ("q", "sqrt(q)", "") or not math.isfinite(r.value):
            continue
        col = (r.process, r.symbol, r.unit)
        if (r.symbol, r.unit) in by_display:  # a display row: ARW, RRW, B in deg/h ...
            base = by_display[(r.symbol, r.unit)]
            nat = native.get((r.process, base), r.value)
        elif r.symbol in disp:  # the native row of a displayed symbol: kept for the limits
            native[(r.process, r.symbol)] = r.value
            continue
        else:
            base, nat = r.symbol, r.value
        if col not in seen:
            seen.add(col)
            out.append(TermValue(col, r.quantity, r.value, r.low, r.high, nat, base))
    return out


#: The IEEE quantities with a fleet column of their own: those no process column holds (N with
#: its disguised share, the ADEV minimum of the model and of the data).
_IEEE_COLUMNS = ("N", "ADEV_min", "ADEV_data")
#: Column labels of the IEEE quantities that have no display symbol of their own.
_IEEE_LABEL = {"B": "B", "ADEV_min": "ADEV min", "ADEV_data": "ADEV min (data)", "Q": "Q", "R": "R"}


def _ieee_label(kind: str, key: str) -> str:
    """``ARW``/``VRW`` (N), ``RRW``/``AccRW`` (K), ``B``, ``ADEV min`` ... of an IEEE key."""
    d = DISPLAY.get((kind, key)) if key in ("N", "K") else None
    return d.symbol if d is not None else _IEEE_LABEL.get(key, key)


def ieee_terms(fit: Any) -> list[TermValue]:
    """The IEEE quantities of a fit (:attr:`engine.fit.GMWMResult.ieee`) that no process term
    holds, as noise terms of process ``IEEE``: ``ARW``/``VRW`` (N with its disguised share),
    ``ADEV min`` and ``ADEV min (data)`` (the vendors' bias-instability convention), in their
    datasheet units (B, K, Q, R are the process columns' own numbers)."""
    t = fit.ieee
    out = []
    for key, q in t.quantities.items():
        if key not in _IEEE_COLUMNS:
            continue  # B, K, Q, R: the process columns already hold them (same numbers)
        label = _ieee_label(t.kind, key)
        out.append(
            TermValue(
                ("IEEE", label, q.datasheet_unit),
                q.name,
                q.datasheet_value,
                q.datasheet_low,
                q.datasheet_high,
                q.native,
                key,
            )
        )
    return out


def temperature_terms(tf: Any) -> list[TermValue]:
    """The bias-temperature sensitivity of a channel with a temperature fit as a noise term of
    process ``temperature`` (symbol ``S_T``, in deg/h/degC or mg/degC with its interval: the
    :class:`engine.inference.temperature.TemperatureFit`'s own figures), marked when the
    channel was not compensated (its :attr:`~TermValue.note`, the fit's ``marker``); none
    without a temperature fit (the fleet's table shows a dash for that unit)."""
    if tf is None:
        return []
    lo, hi = tf.sensitivity_interval
    return [
        TermValue(
            (tf.PROCESS, tf.SYMBOL, tf.sensitivity_unit),
            tf.quantity,
            float(tf.sensitivity),
            float(lo),
            float(hi),
            float(tf.coef[0]),
            tf.SYMBOL,
            note=tf.marker,
        )
    ]


@dataclass(frozen=True, eq=False)
class FleetUnit:
    """One unit of the fleet.

    Attributes
    ----------
    name : str
        The log's file name (the path when two logs share it).
    anchor : str
        Its section's id in the page (``unit-3``).
    log : LogFit
        The batch's fits of the log (or its error).
    report : CalibrationReport or None
        The unit's calibration report (None when the log failed).
    error : str
        Why the unit has no report (``""`` when it has one).
    terms : dict of str to list of TermValue
        Per fitted channel, its noise terms.
    verdict : str
        ``pass``, ``marginal``, ``cannot tell`` (a limit the model cannot answer), ``fail``,
        ``not checked`` (no limit, no datasheet) or ``error`` (no fit).
    reasons : list of str
        What made the verdict (each failed or marginal check), and the outliers.
    """

    name: str
    anchor: str
    log: LogFit
    report: CalibrationReport | None
    error: str = ""
    terms: dict[str, list[TermValue]] = field(default_factory=dict)
    verdict: str = "not checked"
    reasons: list[str] = field(default_factory=list)

    @property
    def outliers(self) -> list[tuple[str, TermValue]]:
        """``(channel, term)`` of every outlying term."""
        return [(ch, t) for ch, ts in self.terms.items() for t in ts if t.outlier]

    @property
    def warnings(self) -> list[str]:
        """The fits' warnings, ``channel: warning`` (a term faster than one sample, a
        parameter on a bound, no convergence): shown beside the verdict."""
        if self.report is None:
            return []
        return [f"{ch}: {w}" for ch, c in self.report.channels.items() for w in c.warnings]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: source, status, verdict and reasons, terms with z-scores."""
        return json_ready(
            {
                "name": self.name,
                "anchor": self.anchor,
                "source": self.log.source,
                "error": self.error,
                "channel_errors": dict(self.log.channel_errors),
                "verdict": self.verdict,
                "reasons": list(self.reasons),
                "terms": {
                    ch: [
                        {
                            "process": t.column[0],
                            "symbol": t.column[1],
                            "unit": t.column[2],
                            "quantity": t.quantity,
                            "value": t.value,
                            "low": t.low,
                            "high": t.high,
                            "z": t.z,
                            "rel": t.rel,
                            "outlier": t.outlier,
                            "note": t.note,
                        }
                        for t in ts
                    ]
                    for ch, ts in self.terms.items()
                },
            }
        )


@dataclass(frozen=True, eq=False)
class FleetReport:
    """A fleet acceptance report: :func:`gather_fleet`'s result.

    Attributes
    ----------
    units : list of FleetUnit
        In the order of the paths (a pattern's matches sorted); failed ones included.
    batch : BatchResult
        The batch's numbers (:func:`engine.batch.fit_batch`'s result for the same logs).
    columns : dict of str to list of (process, symbol, unit)
        Per channel, the noise-term columns (every term any unit has, in order of appearance).
    limits : list of Limit
    datasheet : str
        The datasheet as given (``""`` without one).
    level : float
        Interval and datasheet-check level.
    provenance : dict
        Versions, settings, command line, date.
    """

    units: list[FleetUnit]
    batch: BatchResult
    columns: dict[str, list[tuple[str, str, str]]]
    limits: list[Limit]
    datasheet: str
    level: float
    provenance: dict[str, Any]

    @property
    def checked(self) -> bool:
        """True when there was something to check (limits or a datasheet)."""
        return bool(self.limits or self.datasheet)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (schema ``gmwm-fleet-report/1``): units, the batch summary, limits."""
        return json_ready(
            {
                "schema": "gmwm-fleet-report/1",
                "units": [u.to_dict() for u in self.units],
                "columns": {ch: [list(c) for c in cols] for ch, cols in self.columns.items()},
                "limits": [lim.__dict__ for lim in self.limits],
                "datasheet": self.datasheet,
                "level": self.level,
                "batch": self.batch.to_dict(),
                "provenance": self.provenance,
            }
        )


# --------------------------------------------------------------------------- the worker
def _unit_task(
    task: tuple[str, dict[str, Any], dict[str, Any]],
) -> tuple[LogFit, CalibrationReport | None, str]:
    """Worker: load one log, :func:`fit_log` it, gather its report from those fits.

    Returns ``(LogFit, report, report_error)``; a failure is kept as the log's error (or the
    report's, when the fits exist but their report could not be made).
    """
    from ..io import load_log
    from .data import gather_report

    path, kw, rkw = task
    t0 = time.perf_counter()
    try:
        log = load_log(path, fs=kw["fs"], **kw["load_options"])
        fit_kw = {k: v for k, v in kw.items() if k not in ("fs", "load_options")}
        lf = fit_log(log, **fit_kw)
    except Exception as e:  # noqa: BLE001 - a bad log is a result of the fleet
        msg = " ".join(str(e).split())
        return (
            LogFit(path, error=f"{type(e).__name__}: {msg}", elapsed_s=time.perf_counter() - t0),
            None,
            "",
        )
    try:
        # the log check fit_log made is the report's: not made twice (1 s per 1e6 x 6 samples)
        rep = gather_report(
            log, fits=lf.fits, temperatures=lf.temperature, qualification=lf.qualification, **rkw
        )
    except Exception as e:  # noqa: BLE001 - the fits stay in the batch
        return lf, None, f"{type(e).__name__}: {' '.join(str(e).split())}"
    if lf.channel_errors:  # channels not fitted stay in the report, in the log's order
        chans = dict(rep.channels)
        chans.update(
            {
                ch: ChannelReport(ch, log.units.get(ch, ""), error=e)
                for ch, e in lf.channel_errors.items()
            }
        )
        rep = replace(rep, channels={ch: chans[ch] for ch in log.names if ch in chans})
    return lf, rep, ""


def _unit_names(sources: Sequence[str]) -> list[str]:
    names = [Path(s.rstrip("/")).name or s for s in sources]
    return [s if names.count(n) > 1 else n for n, s in zip(names, sources, strict=True)]


def _datasheet_verdict(rep: CalibrationReport, level: float) -> list[tuple[str, str]]:
    """Per channel with a datasheet check: (verdict, reason)."""
    from scipy.stats import binom

    out = []
    for ch, c in rep.channels.items():
        chk = c.check
        if chk is None:
            continue
        below = chk.verdict.count("below")
        n = len(chk.verdict)
        allowed = int(binom.ppf(level, n, (1.0 - level) / 2.0))
        where = f"{ch}: datasheet model below the empirical {100 * level:g} % interval at "
        if below > allowed:
            out.append(("fail", f"{where}{below} of {n} scales (a correct one: <= {allowed})"))
        elif below:
            out.append(("marginal", f"{where}{below} of {n} scales (a correct one: <= {allowed})"))
        else:
            out.append(("pass", ""))
    return out


def _limit_verdicts(rep: CalibrationReport, limits: Sequence[Limit]) -> list[tuple[str, str]]:
    """Per limit and channel of its kind: (verdict, reason), on the fit's IEEE quantities."""
    out = []
    for ch, c in rep.channels.items():
        if c.fit is None:
            continue
        kind = _kind(c.unit, ch)
        t = c.fit.ieee
        for lim in limits:
            if kind != lim.kind:
                continue
            q = t.get(lim.ieee_key)
            if q is None:
                out.append(
                    (
                        "cannot tell",
                        f"{ch}: the model {c.fit.model.spec()} has no {lim.symbol} (no such "
                        f"term, and no AR1/GM faster than one sample): {lim.key} <= "
                        f"{lim.given} cannot be checked; fit a model with it",
                    )
                )
                continue
            what = f"{ch} {_ieee_label(t.kind, q.key)} {q.datasheet_value:.4g} {q.datasheet_unit}"
            if q.value > lim.si and not q.upper_bound:  # a minimum at the edge: a bound only
                out.append(("fail", f"{what} > limit {lim.given}"))
            elif q.value > lim.si or not q.has_interval:
                why = q.note or "no interval"
                out.append(("cannot tell", f"{what}: {why}; cannot say if <= {lim.given}"))
            elif q.high > lim.si:
                out.append(
                    (
                        "marginal",
                        f"{what} <= limit {lim.given}, but its interval reaches "
                        f"{q.datasheet_high:.4g}",
                    )
                )
            else:
                out.append(("pass", ""))
    return out


_RANK = {"pass": 0, "marginal": 1, "cannot tell": 2, "fail": 3}
#: :func:`engine.batch.fit_log`'s keywords (the fit options of every unit).
_FIT_OPTIONS = frozenset(inspect.signature(fit_log).parameters) - {"path"}


def gather_fleet(
    paths: Iterable[str | os.PathLike[str]],
    *,
    datasheet: str | os.PathLike[str] | Any | None = None,
    spec: Iterable[str] | Sequence[Limit] = (),
    level: float = 0.95,
    export_format: str | None = None,
    workers: int = 2,
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
    command_line: str = "",
    output: str | os.PathLike[str] | None = None,
    **options: Any,
) -> FleetReport:
    """Fit every log of a fleet and compute its acceptance report.

    Parameters
    ----------
    paths : iterable of path or glob pattern
        The units' logs (as :func:`engine.batch.fit_batch`).
    datasheet : str, path or DatasheetSpec, optional
        Datasheet values or file (as :func:`~.data.gather_report`), checked on every unit's
        channels of its kind (:func:`engine.check_datasheet`).
    spec : iterable of str or Limit
        Limits ``"arw<=0.3 deg/sqrt(h)"`` (:func:`parse_limits`).
    level : float
        Interval and datasheet-check level (0.95).
    export_format : str, optional
        An export format whose file each unit's section includes (default none).
    workers, executor, progress
        As :func:`engine.batch.fit_batch`: local processes, or any Executor (Dask).
    command_line : str
        Shown under "How it was made".
    output : path, optional
        A folder where each unit's JSON report is written as soon as it is fitted (as
        :func:`engine.batch.fit_batch`'s ``output``: :class:`engine.batch.BatchFolder`).
    **options
        :func:`engine.batch.fit_log`'s keywords: ``model`` or ``select``, ``channels``,
        ``fs``, ``levels``, ``weights``, ``load_options``.

    Returns
    -------
    FleetReport
        Units whose log failed are in it with their error.

    Raises
    ------
    engine.inference.DatasheetError
        A bad limit or datasheet (before any fit).
    TypeError, ValueError, engine.models.ModelError
        Bad options (as :func:`engine.batch.fit_batch`).
    """
    import datetime as _dt

    from .._parallel import executor_workers, parallel_map
    from ..inference.datasheet_check import DatasheetSpec, parse_datasheet
    from ..models import ModelError, parse_model

    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    unknown = sorted(set(options) - _FIT_OPTIONS)
    if unknown:
        raise TypeError(f"gather_fleet() got unknown option(s) {', '.join(unknown)}")
    limits = [s for s in spec if isinstance(s, Limit)]
    limits += parse_limits([s for s in spec if not isinstance(s, Limit)])
    ds: Any = datasheet
    if datasheet is not None and not isinstance(datasheet, DatasheetSpec):
        if not os.path.exists(datasheet):  # values: parsed once, here (a bad one fails now)
            ds = parse_datasheet(str(datasheet), source="datasheet")
    kw = {k: options.get(k) for k in sorted(_FIT_OPTIONS)}
    kw["weights"] = kw["weights"] or "ci"
    kw["channels"] = list(kw["channels"]) if kw["channels"] else None
    kw["load_options"] = dict(kw["load_options"] or {})
    kw["temperature"] = kw["temperature"] or "auto"
    if (kw["model"] is None) == (kw["select"] is None):
        raise ModelError("give a model to fit (model=) or a maximal model to select from (select=)")
    if kw["weights"] not in ("ci", "identity", "efficient"):
        raise ValueError(f"unknown weights {kw['weights']!r}: use 'ci', 'identity' or 'efficient'")
    if kw["model"] is not None:
        parse_model(kw["model"])
    rkw = {"level": level, "datasheet": ds, "export_format": export_format}
    t0 = time.perf_counter()
    fingerprint = options_fingerprint(kw)
    entries = expand_paths(paths)
    todo = [p for p, err in entries if not err]
    folder = None if output is None else BatchFolder(output, fingerprint)
    if folder is not None:  # as fit_batch(output=): each report written as its unit completes
        folder.check_summaries()
        folder.check_reports(todo)
    done = iter(
        parallel_map(
            _unit_task,
            [(p, kw, rkw) for p in todo],
            workers,
            executor=executor,
            progress=progress,
            chunksize=1,
            each=None if folder is None else (lambda _, r: folder.record(r[0])),
        )
    )
    results = [(LogFit(p, error=err), None, "") if err else next(done) for p, err in entries]
    settings = {
        **{k: v for k, v in kw.items() if k != "load_options"},
        "workers": executor_workers(executor, workers),
        "executor": "local" if executor is None else type(executor).__name__,
        "options_fingerprint": fingerprint,
    }
    batch = BatchResult([r[0] for r in results], settings, time.perf_counter() - t0)
    names = _unit_names([r[0].source for r in results])
    terms: list[dict[str, list[TermValue]]] = []
    fast: list[dict[str, tuple[str, ...]]] = []  # per unit and channel: sub-sample terms
    columns: dict[str, list[tuple[str, str, str]]] = {}
    for _lf, rep, _err in results:
        t: dict[str, list[TermValue]] = {}
        fast.append({})
        if rep is not None:
            for ch, c in rep.channels.items():
                if c.fit is not None:
                    n = c.fit.ieee.get("N")
                    fast[-1][ch] = tuple(s for s in (n.sources if n else ()) if s != WN.code)
                    t[ch] = (
                        noise_terms(c.rows, c.unit, ch)
                        + ieee_terms(c.fit)
                        + temperature_terms(c.temperature)
                    )
                    cols = columns.setdefault(ch, [])
                    cols += [v.column for v in t[ch] if v.column not in cols]
        terms.append(t)
    # robust z-scores per channel, column and quantity, across the units that have the term:
    # a quantity tells comparable units apart (a temperature sensitivity that was not
    # compensated is its own quantity, scored only among the units that share it)
    for ch in columns:
        groups = dict.fromkeys((v.column, v.quantity) for t in terms for v in t.get(ch, []))
        for col, qty in groups:
            where = [
                (i, j)
                for i, t in enumerate(terms)
                for j, v in enumerate(t.get(ch, []))
                if (v.column, v.quantity) == (col, qty)
            ]
            # a term of an AR1/GM faster than one sample has no z: its T_c means nothing
            where = [(i, j) for i, j in where if col[0] not in fast[i].get(ch, ())]
            vals = np.array([terms[i][ch][j].value for i, j in where], float)
            z = robust_z(vals)
            med = float(np.nanmedian(vals)) if np.isfinite(vals).any() else math.nan
            for (i, j), zi, v in zip(where, z, vals, strict=True):
                rel = (v - med) / abs(med) if med != 0 else (math.inf if v != med else 0.0)
                terms[i][ch][j] = replace(terms[i][ch][j], z=float(zi), rel=float(rel))
    units = []
    for k, ((lf, rep, rep_err), name, t) in enumerate(zip(results, names, terms, strict=True)):
        error = lf.error or rep_err
        if rep is None:
            units.append(FleetUnit(name, f"unit-{k + 1}", lf, None, error, {}, "error", [error]))
            continue
        checks = _limit_verdicts(rep, limits) + _datasheet_verdict(rep, level)
        verdict = "not checked"
        if checks:
            verdict = max((v for v, _ in checks), key=_RANK.__getitem__)
        reasons = [r for v, r in checks if v != "pass" and r]
        reasons += [f"{ch}: {c.error}" for ch, c in rep.channels.items() if c.error]
        unit = FleetUnit(name, f"unit-{k + 1}", lf, rep, "", t, verdict, reasons)
        unit.reasons.extend(
            f"outlier: {ch} {v.column[0]} {v.column[1]} {v.value:.4g} {v.column[2]} (robust z = "
            f"{v.z:.1f}, {100 * v.rel:+.0f} % from the median)"
            for ch, v in unit.outliers
        )
        units.append(unit)
    ds_text = ""
    if isinstance(ds, DatasheetSpec):
        ds_text = ds.describe() if isinstance(datasheet, DatasheetSpec) else str(datasheet)
    elif ds is not None:
        ds_text = f"file {datasheet}"
    provenance = {
        "versions": software_versions(),
        "settings": settings,
        "intervals": f"asymptotic sandwich, {100 * level:g} % two-sided",
        "outliers": f"robust z = (x - median) / ({_MAD_NORMAL} MAD), |z| > {OUTLIER_Z} and "
        f"|x - median| > {OUTLIER_REL:g} |median|",
        "command_line": command_line,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    return FleetReport(units, batch, columns, limits, ds_text, level, provenance)
