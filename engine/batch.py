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
import glob
import io as _io
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._files import write_atomic
from ._jsonutil import json_ready
from ._parallel import executor_workers, parallel_map
from .fit import FitError, GMWMResult, fit_gmwm
from .formats.common import csv_cells
from .models import ModelError, parse_model
from .units import datasheet_rows

if TYPE_CHECKING:  # pragma: no cover - engine.io is imported on use (it costs h5py)
    from .io import ImuLog

__all__ = ["LogFit", "FleetRow", "BatchResult", "fit_log", "fit_batch", "fleet_summary"]


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
    """

    source: str
    fits: dict[str, GMWMResult] = field(default_factory=dict)
    report: str = ""
    error: str = ""
    channel_errors: dict[str, str] = field(default_factory=dict)
    fs: float = math.nan
    n: int = 0
    elapsed_s: float = 0.0

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
) -> LogFit:
    """Load one log and fit every channel (or ``channels``).

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

    Returns
    -------
    LogFit
        With ``error == ""``; raises on a log that cannot be loaded or whose every channel
        fails (:class:`engine.io.LoadError`, :class:`engine.fit.FitError` ...).
    """
    from .formats import export
    from .io import log_of, pick_channel

    _check_choice(model, select)
    t0 = time.perf_counter()
    log = log_of(path, fs=fs, load_options=load_options, caller="fit_log")
    src = log.source if log is path else str(path)
    names = [pick_channel(src, log.names, c) for c in channels] if channels else log.names
    fits: dict[str, GMWMResult] = {}
    errors: dict[str, str] = {}
    for ch in names:
        try:
            wv = log.wavelet_variance(ch, levels=levels)
            fits[ch] = _fit_channel(wv, model, select, weights)
        except (FitError, ModelError, ValueError) as e:
            errors[ch] = f"{type(e).__name__}: {e}"
    if not fits:
        raise FitError(
            "no channel could be fitted: " + "; ".join(f"{c}: {e}" for c, e in errors.items())
        )
    report = export(None, fits, "json", log=log, source=src)
    return LogFit(src, fits, report, "", errors, float(log.fs), log.n, time.perf_counter() - t0)


_FIT_LOG_OPTIONS = frozenset(
    ("model", "select", "channels", "fs", "levels", "weights", "load_options")
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
    **options
        The keywords of :func:`fit_log`, the same for every log: ``model`` or ``select``,
        ``channels``, ``fs``, ``levels``, ``weights``, ``load_options``.

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
    _check_choice(kw["model"], kw["select"])
    if kw["weights"] not in ("ci", "identity", "efficient"):
        raise ValueError(f"unknown weights {kw['weights']!r}: use 'ci', 'identity' or 'efficient'")
    if kw["model"] is not None:
        parse_model(kw["model"])  # a bad spec is the caller's error, not every log's
    t0 = time.perf_counter()
    entries = expand_paths(paths)
    todo = [p for p, err in entries if not err]
    done = parallel_map(
        _fit_log_task,
        [(p, kw) for p in todo],
        workers,
        executor=executor,
        progress=progress,
        chunksize=1,
    )
    settings = {
        **{k: v for k, v in kw.items() if k != "load_options"},
        "workers": executor_workers(executor, workers),
        "executor": "local" if executor is None else type(executor).__name__,
    }
    fitted = iter(done)
    logs = [LogFit(p, error=err) if err else next(fitted) for p, err in entries]
    return BatchResult(logs, settings, time.perf_counter() - t0)


def fleet_summary(logs: Iterable[LogFit]) -> list[FleetRow]:
    """Per channel and quantity, the spread across the fitted logs (:class:`FleetRow`).

    Quantities are the model's parameters (by their unique names, e.g. ``GM_1.beta``) and the
    datasheet quantities of :func:`engine.units.datasheet_rows`, each keyed with its unit
    (logs in different units are never pooled). Rows are in order of first appearance.
    """
    values: dict[tuple[str, str, str, str, str, str], list[float]] = {}
    for lf in logs:
        for ch, res in lf.fits.items():
            for r in res.param_records:
                key = (ch, "parameter", r.label, r.full_name, r.name, r.unit)
                values.setdefault(key, []).append(float(r.value))
            for d in datasheet_rows(
                res.model, res.fs, res.wv.unit, channel=ch, n_levels=res.wv.n_levels
            ):
                key = (ch, "datasheet", d.process, d.quantity, d.symbol, d.unit)
                values.setdefault(key, []).append(float(d.value))
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
        a name), ``summary.csv`` and ``summary.json``; returns the paths written."""
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        reports: dict[str, str] = {}
        used: set[str] = {"summary"}
        for lf in self.fitted:
            stem = Path(lf.source.rstrip("/")).name.split(".")[0] or "log"
            name, k = stem, 2
            while name in used:
                name, k = f"{stem}_{k}", k + 1
            used.add(name)
            p = out / f"{name}.json"
            write_atomic(p, lf.report)
            reports[lf.source] = str(p)
        write_atomic(out / "summary.csv", self.summary_csv())
        d = self.to_dict()
        d["reports"] = reports
        write_atomic(out / "summary.json", json.dumps(d, indent=1, allow_nan=False) + "\n")
        return {
            "reports": reports,
            "summary_csv": str(out / "summary.csv"),
            "summary_json": str(out / "summary.json"),
        }
