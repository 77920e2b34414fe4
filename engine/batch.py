"""Calibrating a fleet: fit every channel of many logs, one report per log, and the spread of
every parameter across the units.

:func:`fit_batch` maps :func:`fit_log` over the logs with :func:`engine._parallel.parallel_map`
(in process, on local processes, or on any ``concurrent.futures.Executor``: a Dask cluster's
``Client.get_executor()`` spreads a lab's logs over many machines). A log that cannot be read
or fitted is a result, not a failure of the batch: its error is kept and the other logs
complete. :func:`fleet_summary` gives, per channel and quantity (the model's parameters and
the datasheet quantities of :mod:`engine.units`, each with its unit), the number of units,
mean, SD, min, max and the coefficient of variation across the fitted units.

Each log is loaded by the worker that fits it, so on a cluster every worker must see the
logs at the same paths (a shared file system); the reports are written by the caller.
"""

from __future__ import annotations

import csv
import datetime as _dt
import glob
import hashlib
import io as _io
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._files import open_regular, read_regular, write_atomic
from ._jsonutil import json_ready
from ._parallel import executor_workers, parallel_map
from ._version import __version__
from .errors import ExportError
from .fit import FitError, GMWMResult, fit_gmwm
from .formats.common import csv_cells
from .models import ModelError, parse_model
from .units import datasheet_rows

if TYPE_CHECKING:  # pragma: no cover - engine.io is imported on use (it costs h5py)
    from .io import ImuLog

__all__ = [
    "LogFit",
    "FleetRow",
    "BatchResult",
    "BatchFolder",
    "BATCH_RECORD",
    "fit_log",
    "fit_batch",
    "fleet_summary",
    "unit_values",
    "options_fingerprint",
    "export_fleet",
]

#: The record an output folder of :func:`fit_batch` keeps of what it wrote (see
#: :class:`BatchFolder`).
BATCH_RECORD = ".gmwm-batch.json"


@dataclass(frozen=True, eq=False)
class LogFit:
    """The fits of every channel of one log, or why the log could not be fitted.

    Attributes
    ----------
    source : str
        The log's path.
    fits : dict of str to GMWMResult
        Channel name to its fit (empty when the log failed).
    report : str
        The log's JSON report (``engine.export`` format ``json``), ``""`` when it failed.
    error : str
        Why the log failed (``""`` when it was fitted).
    channel_errors : dict of str to str
        Channels of a fitted log that could not be fitted (e.g. a constant channel).
    fs, n : float, int
        Sampling frequency (Hz) and samples per channel.
    elapsed_s : float
        Time taken to load and fit the log (s), where it ran.
    resumed : bool
        Not fitted again: its report was read back from the output folder of an earlier run
        with the same log and options (:class:`BatchFolder`); ``fits`` is then empty and
        ``values`` holds its summary quantities (:func:`unit_values`).
    qualification : dict
        What the log check found before the fit (:meth:`engine.io.Qualification.to_dict`),
        empty when the log failed or was resumed.
    temperature : dict of str to TemperatureFit
        Per channel with a temperature channel beside it (``temperature=`` of
        :func:`fit_log`), its bias-temperature fit; the channel's fit in :attr:`fits` is then
        that of the compensated signal when the fit says so
        (:attr:`~engine.inference.temperature.TemperatureFit.applied`,
        :mod:`engine.inference.temperature`).
    temperature_recorded : dict of str to dict
        A resumed log's :meth:`temperature_status`, as recorded when it was fitted (empty
        otherwise: :attr:`temperature` holds the fits).
    warmup_dropped : int
        Samples cut from the start of the log as its warm-up before the fit (``drop_warmup=True``
        of :func:`fit_log`; 0: none). With :attr:`temperature`, what :meth:`prepared` needs to
        give the signal the fits were made on.
    """

    source: str
    fits: dict[str, GMWMResult] = field(default_factory=dict)
    report: str = ""
    error: str = ""
    channel_errors: dict[str, str] = field(default_factory=dict)
    fs: float = math.nan
    n: int = 0
    elapsed_s: float = 0.0
    resumed: bool = False
    values: tuple[tuple[tuple[str, ...], float], ...] = ()
    qualification: dict[str, Any] = field(default_factory=dict)
    temperature: dict[str, Any] = field(default_factory=dict)
    temperature_recorded: dict[str, dict[str, Any]] = field(default_factory=dict)
    warmup_dropped: int = 0

    @property
    def ok(self) -> bool:
        """True when at least one channel was fitted."""
        return not self.error

    @property
    def warnings(self) -> list[str]:
        """The fits' warnings (e.g. an AR1/GM faster than one sample), each as
        ``"SOURCE [CHANNEL]: WARNING"``."""
        return [f"{self.source} [{ch}]: {w}" for ch, r in self.fits.items() for w in r.warnings]

    def status(self) -> dict[str, Any]:
        """JSON-ready status: source, ok, error, channels fitted and their models."""
        return json_ready(
            {
                "source": self.source,
                "ok": self.ok,
                "error": self.error,
                "fs": self.fs,
                "n": self.n,
                "models": {ch: r.model.spec(values=True) for ch, r in self.fits.items()},
                "channel_errors": dict(self.channel_errors),
                "warnings": {ch: list(r.warnings) for ch, r in self.fits.items() if r.warnings},
                "elapsed_s": self.elapsed_s,
                "resumed": self.resumed,
                "qualification": self.qualification or None,
                "temperature": self.temperature_status() or None,
            }
        )

    def prepared(self, log: ImuLog) -> ImuLog:
        """The log as the fits saw it: without the :attr:`warmup_dropped` first samples, and
        each channel of :attr:`temperature` compensated where its fit says so
        (:meth:`~engine.inference.temperature.TemperatureFit.compensated_log`).

        Parameters
        ----------
        log : ImuLog
            This log as loaded (:attr:`source`, with the batch's load options).

        Returns
        -------
        ImuLog
            The signal of every fit in :attr:`fits`: what a filter file's tail factors and any
            other figure computed from the samples must read (:func:`export_fleet`).

        Raises
        ------
        engine.units.ExportError
            A resumed log (its temperature fits are not kept), or a log whose length is not
            the one fitted (the file changed since).
        """
        from .inference.temperature import compensate_channels
        from .io import drop_warmup

        if self.resumed:
            raise ExportError(
                f"{self.source}: read back from an earlier run's report, whose fits are not "
                "kept: fit the log again (write into a new folder)"
            )
        out = drop_warmup(log, self.warmup_dropped)
        if out.n != self.n:
            raise ExportError(
                f"{self.source}: {log.n:,} samples now, {self.n + self.warmup_dropped:,} when "
                "it was fitted: the file changed since; fit it again"
            )
        return compensate_channels(out, self.temperature.values())

    def temperature_status(self) -> dict[str, dict[str, Any]]:
        """Per channel with a temperature fit: its line, temperature channel, sensitivity
        with its interval and unit, whether it was compensated and the test's p-value, and
        the raw signal's fit beside a compensated one (JSON-ready); a resumed log's as
        recorded when it was fitted (:attr:`temperature_recorded`)."""
        if self.resumed:
            return dict(self.temperature_recorded)
        return json_ready(
            {
                ch: {
                    "line": tf.line(),
                    "temperature": tf.temperature,
                    "sensitivity": tf.sensitivity,
                    "sensitivity_interval": list(tf.sensitivity_interval),
                    "sensitivity_unit": tf.sensitivity_unit,
                    "compensated": tf.applied,
                    "p_value": tf.p_value,
                    "fit_raw_model": tf.fit_raw.model.spec(values=True)
                    if tf.fit_raw is not None
                    else None,
                }
                for ch, tf in self.temperature.items()
            }
        )


@dataclass(frozen=True)
class FleetRow:
    """The spread of one quantity of one channel across the fitted units.

    ``kind`` is ``"parameter"`` (the model's parameter, e.g. ``WN.sigma2`` in ``(deg/s)^2``)
    or ``"datasheet"`` (e.g. ``WN angle random walk N`` in ``deg/sqrt(h)``); ``sd`` is the
    sample SD (``n - 1``; NaN for one unit), ``cv`` the coefficient of variation
    ``sd / |mean|`` (dimensionless; NaN for a zero mean).
    """

    channel: str
    kind: str
    process: str
    quantity: str
    symbol: str
    unit: str
    n_units: int
    mean: float
    sd: float
    min: float
    max: float
    cv: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN as None)."""
        return json_ready(dict(self.__dict__))


def _check_choice(model: Any, select: Any) -> None:
    if (model is None) == (select is None):
        raise ModelError("give a model to fit (model=) or a maximal model to select from (select=)")


def fit_log(
    path: str | os.PathLike[str] | ImuLog,
    *,
    model: str | None = None,
    select: str | None = None,
    channels: Sequence[str] | None = None,
    fs: float | None = None,
    levels: int | None = None,
    weights: str = "ci",
    load_options: Mapping[str, Any] | None = None,
    drop_warmup: bool = False,
    temperature: str | None = "auto",
    progress: Callable[[int, int], None] | None = None,
    json_report: bool = True,
) -> LogFit:
    """Load one log, check it (:func:`engine.io.qualify_log`) and fit every channel (or
    ``channels``).

    Parameters
    ----------
    path : path or ImuLog
        A log :func:`engine.io.load_log` reads (or a WV summary file), or a log already
        loaded (then ``fs`` and ``load_options`` must be left out: they were the loader's).
    model : str, optional
        The model of every channel, e.g. ``"GM+WN+RW"``.
    select : str, optional
        Instead of ``model``: per channel, the WVIC-best sub-model of this maximal model
        (:func:`engine.inference.rank_models`).
    channels : sequence of str, optional
        Channels to fit (default: all).
    fs : float, optional
        Sampling frequency (Hz), overriding the file.
    levels : int, optional
        Number of WV levels J.
    weights : {"ci", "identity", "efficient"}
        GMWM weights (``efficient``: two-step ``Omega = V^-1``).
    load_options : mapping, optional
        More :func:`engine.io.load_log` keywords (``segment``, ``scale``, ``units``, ``topic``).
    drop_warmup : bool
        Drop the warm-up the log check finds (:attr:`engine.io.Qualification.suggested_start`)
        before the fit.
    temperature : str, optional
        The temperature channel (:func:`engine.inference.temperature.fit_log_temperature`):
        ``"auto"`` (the default; None too: a channel named like a temperature, if any),
        ``"none"`` or its name. Each channel with one is fitted on its compensated signal,
        and the same model on the raw signal beside it (:attr:`LogFit.temperature`).
    progress : callable (done, total), optional
        Called after each channel's fit (or failure).
    json_report : bool
        Make the log's JSON report (:attr:`LogFit.report`, the ``json`` export of the fits);
        False leaves it empty, for a caller that reports the fits itself
        (:func:`engine.reporting.gather_report`).

    Returns
    -------
    LogFit
        With ``error == ""``; raises on a log that cannot be loaded or whose every channel
        fails (:class:`engine.io.LoadError`, :class:`engine.fit.FitError` ...).
    """
    from .formats import export
    from .inference.temperature import find_temperature, fit_log_temperature
    from .io import drop_warmup as cut_warmup
    from .io import log_of, pick_channel, qualify_log

    _check_choice(model, select)
    t0 = time.perf_counter()
    log = log_of(path, fs=fs, load_options=load_options, caller="fit_log")
    src = log.source if log is path else str(path)
    names = [pick_channel(src, log.names, c) for c in channels] if channels else log.names
    if temperature not in (None, "auto", "none"):  # a name the log lacks: the log's error
        find_temperature(log, temperature)
    check = qualify_log(log, names)
    loaded, cut = log, 0
    if drop_warmup and check.suggested_start:
        cut = int(check.suggested_start)
        log = cut_warmup(log, cut)
        check = qualify_log(log, names)
    fits: dict[str, GMWMResult] = {}
    errors: dict[str, str] = {}
    temps: dict[str, Any] = {}
    if progress is not None:
        progress(0, len(names))
    for k, ch in enumerate(names):
        try:
            tf = fit_log_temperature(log, ch, temperature or "auto", levels=levels, weights=weights)
            wv = tf.wv if tf is not None else log.wavelet_variance(ch, levels=levels)
            fits[ch] = _fit_channel(wv, model, select, weights)
            if tf is not None:  # the same model on the raw signal, for the page's comparison
                raw = None  # (none when not compensated: the fit is of the raw signal)
                if tf.wv_raw is not None:
                    raw = fit_gmwm(tf.wv_raw, parse_model(fits[ch].model.spec()), weights=weights)
                temps[ch] = replace(tf, fit=fits[ch], fit_raw=raw)
        except (FitError, ModelError, ValueError) as e:
            errors[ch] = f"{type(e).__name__}: {e}"
        if progress is not None:
            progress(k + 1, len(names))
    if not fits:
        raise FitError(
            "no channel could be fitted: " + "; ".join(f"{c}: {e}" for c, e in errors.items())
        )
    out = LogFit(
        src,
        fits,
        "",
        "",
        errors,
        float(log.fs),
        log.n,
        qualification=check.to_dict(),
        temperature=temps,
        warmup_dropped=cut,
    )
    if json_report:  # its projections' tail factors read the signal the fits were made on
        report = export(None, fits, "json", log=out.prepared(loaded), source=src)
        out = replace(out, report=report)
    return replace(out, elapsed_s=time.perf_counter() - t0)


_FIT_LOG_OPTIONS = frozenset(
    (
        "model",
        "select",
        "channels",
        "fs",
        "levels",
        "weights",
        "load_options",
        "drop_warmup",
        "temperature",
    )
)


def _fit_channel(wv: Any, model: str | None, select: str | None, weights: str) -> GMWMResult:
    if select is not None:
        from .inference import rank_models

        best = rank_models(wv, max_model=select, weights=weights).best
        if best.result is None:  # pragma: no cover - rank_models raises when nothing fits
            raise FitError(f"no sub-model of {select} could be fitted: {best.error}")
        return best.result
    if model is None:
        raise ModelError("give a model to fit (model=) or a maximal model to select from (select=)")
    return fit_gmwm(wv, parse_model(model), weights=weights)


def _fit_log_task(task: tuple[str, dict[str, Any]]) -> LogFit:
    """Worker: :func:`fit_log`, with any failure kept as the log's error."""
    path, kw = task
    t0 = time.perf_counter()
    try:
        return fit_log(path, **kw)
    except Exception as e:  # noqa: BLE001 - a bad log is a result of the batch
        msg = " ".join(str(e).split())
        return LogFit(path, error=f"{type(e).__name__}: {msg}", elapsed_s=time.perf_counter() - t0)


def expand_paths(patterns: Iterable[str | os.PathLike[str]]) -> list[tuple[str, str]]:
    """Paths and glob patterns to ``(path, error)`` pairs in the order given (each pattern's
    matches sorted, repeats dropped); a pattern that matches nothing gives ``(pattern,
    "LoadError: no file matches ...")``, a path ``(path, "")``."""
    out: list[tuple[str, str]] = []
    seen: set[str] = set()
    for pat in patterns:
        p = str(pat)
        if glob.has_magic(p) and not os.path.exists(p):
            hits = sorted(glob.glob(p))
            if not hits:
                out.append((p, f"LoadError: no file matches {p!r}"))
        else:
            hits = [p]
        for h in hits:
            if h not in seen:
                seen.add(h)
                out.append((h, ""))
    return out


def fit_batch(
    paths: Iterable[str | os.PathLike[str]],
    *,
    workers: int = 2,
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
    output: str | os.PathLike[str] | None = None,
    **options: Any,
) -> BatchResult:
    """Fit every channel of every log, in parallel, and summarise the fleet.

    Parameters
    ----------
    paths : iterable of path or glob pattern
        The logs (``"lab/unit_*.h5"`` is expanded, sorted); a pattern that matches nothing is
        reported as a failed log.
    workers : int
        Local worker processes (1: in process).
    executor : concurrent.futures.Executor, optional
        Runs the logs instead of the local pool (e.g. a Dask ``Client.get_executor()``; its
        workers must see the logs at the same paths). The results do not depend on it.
    progress : callable (done, total), optional
        Called after every log.
    output : path, optional
        A folder (:class:`BatchFolder`) where each log's report is written as soon as it is
        fitted; logs already fitted there with the same content and options are not fitted
        again (resumed). A file there that the batch did not write is never overwritten
        (ValueError before any fit). The summaries are written by :meth:`BatchResult.save`.
    **options
        The keywords of :func:`fit_log`, the same for every log: ``model`` or ``select``,
        ``channels``, ``fs``, ``levels``, ``weights``, ``load_options``, ``drop_warmup``,
        ``temperature``.

    Returns
    -------
    BatchResult
        Failed logs are in it with their error; none raises.

    Examples
    --------
    The bundled demo log and a pattern that matches nothing:

    >>> import engine as eg
    >>> b = eg.fit_batch(
    ...     [eg.demo_path(), "no_such_unit_*.h5"], workers=1, model="WN+RW", channels=["gyro_x"]
    ... )
    >>> [bool(lf.error) for lf in b.logs]
    [False, True]
    >>> {k: f"{v:.3e}" for k, v in b.logs[0].fits["gyro_x"].params.items()}
    {'WN.sigma2': '2.514e-03', 'RW.gamma2': '1.561e-09'}
    """
    unknown = sorted(set(options) - _FIT_LOG_OPTIONS)
    if unknown:
        raise TypeError(f"fit_batch() got unknown option(s) {', '.join(unknown)}")
    kw = {k: options.get(k) for k in sorted(_FIT_LOG_OPTIONS)}
    kw["weights"] = kw["weights"] or "ci"
    kw["channels"] = list(kw["channels"]) if kw["channels"] else None
    kw["load_options"] = dict(kw["load_options"] or {})
    kw["temperature"] = kw["temperature"] or "auto"
    _check_choice(kw["model"], kw["select"])
    if kw["weights"] not in ("ci", "identity", "efficient"):
        raise ValueError(f"unknown weights {kw['weights']!r}: use 'ci', 'identity' or 'efficient'")
    if kw["model"] is not None:
        parse_model(kw["model"])  # a bad spec is the caller's error, not every log's
    t0 = time.perf_counter()
    fingerprint = options_fingerprint(kw)
    folder = None if output is None else BatchFolder(output, fingerprint)
    if folder is not None:
        folder.check_summaries()
    entries = expand_paths(paths)
    todo = [p for p, err in entries if not err]
    resumed = {p: lf for p in todo if folder is not None and (lf := folder.resumed(p))}
    run = [p for p in todo if p not in resumed]
    if folder is not None:  # a report would replace a file the batch did not write: now
        folder.check_reports(run)
    done = parallel_map(
        _fit_log_task,
        [(p, kw) for p in run],
        workers,
        executor=executor,
        progress=progress,
        chunksize=1,
        each=None if folder is None else (lambda _, lf: folder.record(lf)),
    )
    settings = {
        **{k: v for k, v in kw.items() if k != "load_options"},
        "workers": executor_workers(executor, workers),
        "executor": "local" if executor is None else type(executor).__name__,
        "options_fingerprint": fingerprint,
    }
    fitted = dict(zip(run, done, strict=True)) | resumed
    logs = [LogFit(p, error=err) if err else fitted[p] for p, err in entries]
    return BatchResult(logs, settings, time.perf_counter() - t0)


def unit_values(lf: LogFit) -> list[tuple[tuple[str, ...], float]]:
    """The summary quantities of one fitted log: ``((channel, kind, process, quantity,
    symbol, unit), value)`` for every parameter and datasheet quantity, and the bias-temperature
    sensitivity of a channel with a temperature fit (process ``temperature``; quantity
    :attr:`~engine.inference.temperature.TemperatureFit.quantity`, which says when it was not
    compensated, so that such units are pooled apart; see :func:`fleet_summary`)."""
    out: list[tuple[tuple[str, ...], float]] = []
    for ch, res in lf.fits.items():
        for r in res.param_records:
            out.append(((ch, "parameter", r.label, r.full_name, r.name, r.unit), float(r.value)))
        for d in datasheet_rows(
            res.model, res.fs, res.wv.unit, channel=ch, n_levels=res.wv.n_levels
        ):
            out.append(((ch, "datasheet", d.process, d.quantity, d.symbol, d.unit), float(d.value)))
        tf = lf.temperature.get(ch)
        if tf is not None:  # the bias-temperature sensitivity, a datasheet figure too
            key = (ch, "datasheet", tf.PROCESS, tf.quantity, tf.SYMBOL, tf.sensitivity_unit)
            out.append((key, float(tf.sensitivity)))
    return out


def fleet_summary(logs: Iterable[LogFit]) -> list[FleetRow]:
    """Per channel and quantity, the spread across the fitted logs (:class:`FleetRow`).

    Quantities are the model's parameters (by their unique names, e.g. ``GM_1.beta``) and the
    datasheet quantities of :func:`engine.units.datasheet_rows`, each keyed with its unit
    (logs in different units are never pooled). Rows are in order of first appearance.
    """
    values: dict[tuple[str, ...], list[float]] = {}
    for lf in logs:
        for key, value in lf.values if lf.resumed else unit_values(lf):
            values.setdefault(key, []).append(value)
    rows = []
    for (ch, kind, proc, qty, sym, unit), vals in values.items():
        v = np.array([x for x in vals if math.isfinite(x)])
        if v.size == 0:
            continue
        mean = float(v.mean())
        sd = float(v.std(ddof=1)) if v.size > 1 else math.nan
        cv = sd / abs(mean) if mean != 0 and math.isfinite(sd) else math.nan
        rows.append(
            FleetRow(ch, kind, proc, qty, sym, unit, int(v.size), mean, sd, v.min(), v.max(), cv)
        )
    return rows


_CSV_FIELDS = (
    *("channel", "kind", "process", "quantity", "symbol", "unit", "n_units"),
    *("mean", "sd", "min", "max", "cv"),
)


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Every log's fits (or error) and the fleet's spread.

    Attributes
    ----------
    logs : list of LogFit
        In the order of the paths (a pattern's matches sorted).
    settings : dict
        model, select, weights, channels, fs, levels, workers, executor.
    elapsed_s : float
        Wall time of the batch (s).
    """

    logs: list[LogFit]
    settings: dict[str, Any]
    elapsed_s: float

    @property
    def fitted(self) -> list[LogFit]:
        """The logs that were fitted."""
        return [lf for lf in self.logs if lf.ok]

    @property
    def failed(self) -> list[LogFit]:
        """The logs that failed, each with its ``error``."""
        return [lf for lf in self.logs if not lf.ok]

    @property
    def warnings(self) -> list[str]:
        """Every fitted log's :attr:`LogFit.warnings`, in the order of the logs."""
        return [w for lf in self.fitted for w in lf.warnings]

    @property
    def rows(self) -> list[FleetRow]:
        """:func:`fleet_summary` of the fitted logs."""
        return fleet_summary(self.fitted)

    def summary_csv(self) -> str:
        """The fleet summary as CSV (one row per channel and quantity; ``cv`` dimensionless)."""
        buf = _io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(_CSV_FIELDS)
        for r in self.rows:
            w.writerow(
                [
                    *csv_cells(getattr(r, k) for k in _CSV_FIELDS[:7]),
                    *(f"{getattr(r, k):.6e}" for k in _CSV_FIELDS[7:]),
                ]
            )
        return buf.getvalue()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: settings, counts, every log's status, the fleet summary rows."""
        return json_ready(
            {
                "settings": self.settings,
                "n_logs": len(self.logs),
                "n_fitted": len(self.fitted),
                "n_failed": len(self.failed),
                "elapsed_s": self.elapsed_s,
                "logs": [lf.status() for lf in self.logs],
                "summary": [r.to_dict() for r in self.rows],
                "warnings": self.warnings,
            }
        )

    def table(self, kind: str = "datasheet") -> str:
        """Readable fleet table of one ``kind`` of rows (``"datasheet"`` or ``"parameter"``)."""
        head = (
            f"fleet of {len(self.logs)} log(s): {len(self.fitted)} fitted, "
            f"{len(self.failed)} failed ({self.elapsed_s:.1f} s on "
            f"{self.settings['workers']} worker(s))"
        )
        rows = [r for r in self.rows if r.kind == kind]
        cells = [
            [
                r.channel,
                r.process,
                r.quantity,
                r.unit,
                str(r.n_units),
                f"{r.mean:.4g}",
                f"{r.sd:.3g}",
                f"{r.min:.4g}",
                f"{r.max:.4g}",
                f"{100 * r.cv:.1f} %" if math.isfinite(r.cv) else "n/a",
            ]
            for r in rows
        ]
        cols = ["channel", "process", "quantity", "unit", "units", "mean", "SD", "min", "max"]
        cols.append("CV")
        widths = [max(len(c), *(len(x[i]) for x in cells)) for i, c in enumerate(cols)]
        lines = [head, "  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True))]
        lines += ["  ".join(x.ljust(w) for x, w in zip(c, widths, strict=True)) for c in cells]
        lines += [f"failed: {lf.source}: {lf.error}" for lf in self.failed]
        return "\n".join(lines)

    def save(self, directory: str | os.PathLike[str]) -> dict[str, Any]:
        """Write one JSON report per fitted log (``<name>.json``, numbered when two logs share
        a name), ``summary.csv`` and ``summary.json`` (dated: ``written_utc``) through a
        :class:`BatchFolder` (which refuses to overwrite a file it did not write); returns the
        paths written."""
        fp = str(self.settings.get("options_fingerprint") or options_fingerprint(self.settings))
        return BatchFolder(directory, fp).finish(self)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _file_sha256(path: str | os.PathLike[str]) -> str | None:
    """SHA-256 of a regular file's content (read in 1 MB blocks), None when unreadable."""
    h = hashlib.sha256()
    try:
        with open_regular(path) as fh:
            while block := fh.read(1 << 20):
                h.update(block)
    except (OSError, ValueError):
        return None
    return h.hexdigest()


def options_fingerprint(options: Mapping[str, Any]) -> str:
    """SHA-256 of the fit options of a batch (workers and executor excluded: they do not
    change the results) and of this package's version."""
    keep = {k: v for k, v in options.items() if k not in ("workers", "executor", "progress")}
    text = json.dumps(json_ready(keep), sort_keys=True, default=str) + __version__
    return _sha256(text.encode())


class BatchFolder:
    """An output folder of :func:`fit_batch`: writes each log's report as it completes, the
    summaries at the end, and keeps a record (:data:`BATCH_RECORD`) of what it wrote.

    * it never overwrites a file it did not write (an input named ``summary.csv``, a report
      edited since): the one-line ValueError names the file and writes nothing;
    * a second run with the same options resumes the folder: a log whose content (SHA-256) and
      options match a recorded report is not fitted again (:attr:`LogFit.resumed`);
    * every file is written atomically (:func:`engine._files.write_atomic`).

    Parameters
    ----------
    directory : path
        The folder (created with its parents when missing).
    fingerprint : str
        :func:`options_fingerprint` of the batch's fit options.
    """

    def __init__(self, directory: str | os.PathLike[str], fingerprint: str) -> None:
        self.path = Path(directory)
        self.path.mkdir(parents=True, exist_ok=True)
        self._record = self._read_record()
        if self._record.get("options") != fingerprint:  # other options: nothing to resume
            self._record["units"] = {}
        self._record["options"] = fingerprint
        self._inputs: dict[str, str | None] = {}

    def _read_record(self) -> dict[str, Any]:
        p = self.path / BATCH_RECORD
        if not p.exists() and not p.is_symlink():
            return {"files": {}, "units": {}}
        bad = ValueError(
            f"'{p}' is not a record written by gmwm batch: the folder holds files of "
            "another program; choose another output folder"
        )
        try:
            d = json.loads(read_regular(p, str(p)))
        except (ValueError, OSError):
            raise bad from None
        ok = isinstance(d, dict) and isinstance(d.get("files"), dict)
        if not ok or not isinstance(d.get("units"), dict):
            raise bad
        return d

    def fingerprint(self, source: str) -> str | None:
        """SHA-256 of a log's content and of the options (None when unreadable)."""
        if source not in self._inputs:
            h = _file_sha256(source)
            self._inputs[source] = (
                None if h is None else _sha256((h + str(self._record["options"])).encode())
            )
        return self._inputs[source]

    def check_writable(self, name: str) -> None:
        """ValueError unless ``name`` is absent from the folder or a file this batch wrote and
        that is unchanged since."""
        p = self.path / name
        if not p.exists() and not p.is_symlink():
            return
        known = self._record["files"].get(name)
        if p.is_symlink() or known is None or _file_sha256(p) != known:
            raise ValueError(
                f"'{p}' exists and was not written by gmwm batch (or was changed since): "
                "nothing was overwritten; move it away or choose another output folder"
            )

    def check_summaries(self) -> None:
        """Refuse now (before any fit) a folder whose summary files are not this program's."""
        for name in ("summary.csv", "summary.json"):
            self.check_writable(name)

    def check_reports(self, sources: Iterable[str]) -> None:
        """Refuse now the logs whose report would replace a file this batch did not write
        (see :meth:`check_writable`)."""
        for src in sources:
            self.check_writable(self._report_name(src))

    def write(self, name: str, text: str) -> Path:
        """Write ``name`` atomically (after :meth:`check_writable`) and record it."""
        data = text.encode("utf-8")
        if self._record["files"].get(name) != _sha256(data) or not (self.path / name).exists():
            self.check_writable(name)
            write_atomic(self.path / name, data)
            self._record["files"][name] = _sha256(data)
            self._save()
        return self.path / name

    def _save(self) -> None:
        write_atomic(self.path / BATCH_RECORD, json.dumps(self._record, indent=1) + "\n")

    def _report_name(self, source: str) -> str:
        unit = self._record["units"].get(source)
        if unit is not None:
            return str(unit["report"])
        used = {str(u["report"]) for u in self._record["units"].values()} | {"summary.json"}
        stem = Path(source.rstrip("/")).name.split(".")[0] or "log"
        name, k = f"{stem}.json", 2
        while name in used:
            name, k = f"{stem}_{k}.json", k + 1
        return name

    def resumed(self, source: str) -> LogFit | None:
        """The log's result from an earlier run (same content, same options, its report
        unchanged), or None."""
        unit = self._record["units"].get(source)
        fp = self.fingerprint(source)
        if unit is None or fp is None or unit.get("fingerprint") != fp:
            return None
        if not isinstance(unit.get("temperature"), dict):  # recorded before it was kept:
            return None  # fitted again, so that its status says what temperature did

        p = self.path / str(unit["report"])
        if _file_sha256(p) != self._record["files"].get(str(unit["report"])):
            return None
        values = tuple((tuple(map(str, k)), float(v)) for k, v in unit.get("values", []))
        return LogFit(
            source,
            report=p.read_text(encoding="utf-8"),
            fs=float(unit.get("fs", math.nan)),
            n=int(unit.get("n", 0)),
            resumed=True,
            values=values,
            temperature_recorded=dict(unit["temperature"]),
        )

    def record(self, lf: LogFit) -> None:
        """Write a fitted log's report now and record it (a failed log is not recorded)."""
        if not lf.ok or lf.resumed:
            return
        name = self._report_name(lf.source)
        self._record["units"][lf.source] = {
            "report": name,
            "fingerprint": self.fingerprint(lf.source),
            "fs": lf.fs,
            "n": lf.n,
            "values": [[list(k), v] for k, v in unit_values(lf)],
            "temperature": lf.temperature_status(),
        }
        self.write(name, lf.report)

    def finish(self, result: BatchResult) -> dict[str, Any]:
        """Write every fitted log's report (those not yet written), ``summary.csv`` and
        ``summary.json`` (dated ``written_utc``, with the resumed logs counted); returns the
        paths."""
        self.check_summaries()
        reports: dict[str, str] = {}
        for lf in result.fitted:
            self.record(lf)
            reports[lf.source] = str(self.path / self._record["units"][lf.source]["report"])
        d = result.to_dict()
        d["reports"] = reports
        d["written_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        d["n_resumed"] = sum(lf.resumed for lf in result.logs)
        self.write("summary.csv", result.summary_csv())
        self.write("summary.json", json.dumps(d, indent=1, allow_nan=False) + "\n")
        return {
            "reports": reports,
            "summary_csv": str(self.path / "summary.csv"),
            "summary_json": str(self.path / "summary.json"),
        }


def export_fleet(
    path: str | os.PathLike[str] | None,
    logs: Sequence[LogFit],
    fmt: str,
    *,
    fs: float | None = None,
    load_options: Mapping[str, Any] | None = None,
    tails: bool = True,
    **options: Any,
) -> str:
    """One filter file for every fitted unit of a batch: the **fleet file**
    (``engine.export(..., fleet=)``: per axis the largest N and K of the units' own bounded
    exports, so that no unit is exported overconfident; docs/filters.md, "One file for a
    fleet"). Writes ``path`` (unless None) and returns the text.

    Parameters
    ----------
    path : path or None
    logs : sequence of LogFit
        The batch's logs (:attr:`BatchResult.logs`); the failed ones are left out (the caller
        says so), a resumed one (no fits kept) is refused.
    fmt : str
        A WN+RW or white-noise filter format of :data:`engine.formats.FORMATS`.
    fs, load_options
        How each log is loaded again for its tail factors (as :func:`fit_batch` loaded it).
    tails : bool
        Each unit's tail factors (default True), from the signal its fits were made on
        (:meth:`LogFit.prepared`: its warm-up cut and its temperature compensation, as
        :func:`fit_log` made them), as ``gmwm export`` reads them from its log.
    **options
        More :func:`engine.export` keywords (``filter_rate``, ``horizon_s``, ``data`` ...).

    Raises
    ------
    engine.units.ExportError
        No fitted log, a resumed log, or what :func:`engine.export` refuses.
    """
    from .formats import export
    from .io import log_of

    fitted = [lf for lf in logs if lf.ok]
    if not fitted:
        raise ExportError("no fitted log to export a fleet file from")
    for lf in fitted:
        if lf.resumed:
            raise ExportError(
                f"{lf.source}: read back from an earlier run's report, whose fits are not "
                "kept: a fleet file needs every unit's fits (write into a new folder)"
            )

    def log_for(lf: LogFit) -> ImuLog | None:
        if not tails:
            return None
        loaded = log_of(lf.source, fs=fs, load_options=load_options, caller="export_fleet")
        return lf.prepared(loaded)

    first, rest = fitted[0], fitted[1:]
    return export(
        path,
        first.fits,
        fmt,
        log=log_for(first),
        source=first.source,
        tails=tails,
        fleet=[(lf.source, lf.fits, log_for(lf)) for lf in rest],
        **options,
    )
