"""What a calibration report shows, computed: :func:`gather_report` (pure numerics, no plotting).

Every number comes from the engine's own operations, called as ``gmwm fit --json --ci
asymptotic`` calls them, so that the report and the command agree to the last digit:

* the fits: :func:`engine.batch.fit_log` (one model, or the WVIC-best sub-model, per channel);
* the overlapping Allan deviation and its 95 % interval:
  :meth:`engine.wv.AllanVariance.from_wv` (``AVAR(2^(j-1)) = 2 nu2_j``, exact);
* the IEEE Std 952 slope guides: the lines of each process's slope
  (:attr:`engine.models.Process.allan_slope`) read at its :attr:`~engine.models.Process.read_tau`
  through the fitted datasheet value (N, K, Q, R), and the bias-instability floor
  (:func:`engine.units.allan_floor`);
* the Welch PSD (:func:`scipy.signal.welch`) and the model's PSD from the processes' spectral
  densities (:meth:`engine.models.Process.psd`), both averaged over the same logarithmic
  frequency bands;
* the parameter intervals (:func:`engine.inference.param_intervals`), the datasheet rows
  (:func:`engine.units.datasheet_rows`), the J-test (:func:`engine.inference.j_test`);
* the datasheet check (:func:`engine.inference.check_datasheet`) and the export text
  (:func:`engine.formats.export`).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import math
import os
import platform
import warnings as _warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from .._jsonutil import json_ready
from .._version import __version__
from ..fit import FitError, GMWMResult
from ..formats import FORMATS, misfit
from ..inference.selection import DEFAULT_SELECT
from ..io import ImuLog, log_of
from ..models import DR, QN, RW, WN
from ..units import BI_FACTOR, DatasheetRow, ExportError, allan_floor, datasheet_rows, si_factor
from ..wv import AllanVariance

__all__ = [
    "DEFAULT_SELECT",
    "SlopeGuide",
    "Spectrum",
    "ChannelReport",
    "CalibrationReport",
    "file_sha256",
    "software_versions",
    "welch_psd",
    "gather_report",
]

#: A report's progress callback, ``progress(stage, done, total)``: stage ``"fits"`` (a step per
#: channel), ``"intervals"`` (a step per channel's numbers, and the export), ``"figures"`` and
#: ``"writing"`` (:func:`~.render.render_html`); the command line draws a bar per stage.
Progress = Callable[[str, int, int], None]

#: Frequency bands per decade of the displayed PSD (the Welch estimate averaged over each).
PSD_BANDS_PER_DECADE = 24


@dataclass(frozen=True)
class SlopeGuide:
    """An IEEE Std 952 line on the Allan deviation: ``ADEV(T) = value (T / read_tau_s)^slope``.

    ``code`` is the process (``WN``, ``RW``, ``QN``, ``DR``) or ``BI`` (the floor, slope 0,
    ``value`` = the model's minimum ADEV, ``symbol`` ``B`` = value / BI_FACTOR).
    """

    code: str
    symbol: str
    slope: float
    read_tau_s: float
    value: float
    unit: str
    datasheet_value: float  # N, K, Q, R (= value) or B (= value / BI_FACTOR)
    display_value: float = math.nan  # datasheet_value in display_unit (deg/sqrt(h) ...)
    display_unit: str = ""

    def adev(self, t: np.ndarray) -> np.ndarray:
        """The line at averaging times ``t`` [s]."""
        return self.value * (np.asarray(t, float) / self.read_tau_s) ** self.slope


@dataclass(frozen=True, eq=False)
class Spectrum:
    """One-sided PSD [unit^2/Hz] of a channel and of its fitted model, band-averaged.

    ``f`` (Hz) are the band centres (mean frequency of the Welch bins in the band),
    ``welch`` the Welch estimate, ``model`` the model's PSD and ``components`` each process's
    (deterministic drift has none), all averaged over the same Welch bins; ``nperseg`` the
    Welch segment length.
    """

    f: np.ndarray
    welch: np.ndarray
    model: np.ndarray
    components: dict[str, np.ndarray]
    nperseg: int


@dataclass(frozen=True, eq=False)
class Timeline:
    """A channel in time, for the plot of a flight's still segments: ``t`` (s) and the
    envelope ``low``/``high`` of the samples in each of at most :data:`TIMELINE_POINTS`
    blocks; ``segments`` the analysed ranges in seconds."""

    t: np.ndarray
    low: np.ndarray
    high: np.ndarray
    segments: list[tuple[float, float]]


#: Blocks of the timeline plot (its envelope keeps every spike visible).
TIMELINE_POINTS = 2000


def timeline(x: np.ndarray, fs: float, segments: Sequence[tuple[int, int]]) -> Timeline:
    """The min/max envelope of ``x`` over at most :data:`TIMELINE_POINTS` blocks, and the
    ``segments`` (samples) in seconds."""
    block = max(1, -(-x.size // TIMELINE_POINTS))
    starts = np.arange(0, x.size, block)  # the last block may be shorter
    a = np.asarray(x, dtype=np.float64)
    low, high = np.minimum.reduceat(a, starts), np.maximum.reduceat(a, starts)
    t = (starts + (np.minimum(starts + block, x.size) - starts) / 2) / fs
    return Timeline(t, low, high, [(p / fs, q / fs) for p, q in segments])


@dataclass(frozen=True, eq=False)
class ChannelReport:
    """Everything the report shows of one channel (``error``: why it has no fit)."""

    name: str
    unit: str
    fit: GMWMResult | None = None
    error: str = ""
    allan: AllanVariance | None = None
    guides: list[SlopeGuide] = field(default_factory=list)
    spectrum: Spectrum | None = None
    intervals: list[Any] = field(default_factory=list)
    rows: list[DatasheetRow] = field(default_factory=list)
    jtest: Any = None
    notes: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    check: Any = None
    timeline: Timeline | None = None
    #: :func:`engine.formats.misfit` of the fit: one line when model and data disagree
    #: (``""`` when they agree, or without a fit); the page shows it beside the fit and the
    #: export, whatever the export's format.
    misfit: str = ""
    #: The bias-temperature fit (:class:`engine.inference.temperature.TemperatureFit`) when
    #: the log has a temperature channel: :attr:`fit` is then that of the compensated signal
    #: when the compensation was applied (``temperature.applied``), of the raw one otherwise.
    temperature: Any = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the fit (as ``gmwm fit --json``), intervals, datasheet rows, J-test,
        Allan deviation, slope guides, warnings, the misfit line, notes, the datasheet
        check and the temperature fit (None without a temperature channel)."""
        d: dict[str, Any] = {"channel": self.name, "unit": self.unit, "error": self.error}
        if self.fit is not None:
            d["fit"] = self.fit.to_dict()
        d["intervals"] = [iv.to_dict() for iv in self.intervals]
        d["datasheet"] = [r.to_dict() for r in self.rows]
        d["j_test"] = self.jtest.to_dict() if self.jtest is not None else None
        d["allan"] = self.allan.to_dict() if self.allan is not None else None
        d["slope_guides"] = [g.__dict__ for g in self.guides]
        d["ieee"] = self.fit.ieee.to_dict() if self.fit is not None else None
        if self.spectrum is not None:
            d["psd"] = {"f": self.spectrum.f, "welch": self.spectrum.welch}
            d["psd"].update(model=self.spectrum.model, nperseg=self.spectrum.nperseg)
        d["warnings"], d["notes"] = list(self.warnings), dict(self.notes)
        d["misfit"] = self.misfit
        d["datasheet_check"] = self.check.to_dict() if self.check is not None else None
        d["temperature"] = self.temperature.to_dict() if self.temperature is not None else None
        return json_ready(d)


@dataclass(frozen=True, eq=False)
class CalibrationReport:
    """A calibration report of one log: :func:`gather_report`'s result.

    Attributes
    ----------
    log : dict
        File (as given), name, size, sha256, format, channels, fs and its source, samples,
        duration, units, time-column report, notes, sensor and description, and the log
        check before the fit (``qualification``, :meth:`engine.io.Qualification.to_dict`).
    channels : dict of str to ChannelReport
    export : dict
        ``format`` and ``text`` (the export file), or ``error``; empty without a format.
    datasheet : str
        The datasheet as given (values or file), ``""`` without one.
    provenance : dict
        Versions, model or selection, weights, interval method, command line, date.
    warnings : list of str
        Warnings about the whole log (unknown fs, Python warnings raised while fitting).
    """

    log: dict[str, Any]
    channels: dict[str, ChannelReport]
    export: dict[str, str]
    datasheet: str
    provenance: dict[str, Any]
    warnings: list[str]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (schema ``gmwm-calibration-report/1``)."""
        return json_ready(
            {
                "schema": "gmwm-calibration-report/1",
                "log": self.log,
                "channels": {k: c.to_dict() for k, c in self.channels.items()},
                "export": self.export,
                "datasheet": self.datasheet,
                "provenance": self.provenance,
                "warnings": self.warnings,
            }
        )


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def welch_psd(
    x: np.ndarray, fs: float, fit: GMWMResult | None = None, *, bands: int = PSD_BANDS_PER_DECADE
) -> Spectrum:
    """Welch PSD of a series and the PSD of a fitted model, averaged over log-spaced bands.

    Parameters
    ----------
    x : ndarray, shape (N,)
        The series (N >= 16); the segments are de-meaned (``detrend="constant"``).
    fs : float
        Sampling frequency (Hz).
    fit : GMWMResult, optional
        Its model's one-sided PSD ``2 S(f / fs) / fs`` [unit^2/Hz], with ``S`` the two-sided
        density in cycles/sample of each process (:meth:`engine.models.Process.psd`).
    bands : int
        Bands per decade; each band's value is the mean over the Welch bins it holds (bins
        of one band at low frequency stay single).

    Returns
    -------
    Spectrum
        Segment length ``2^floor(log2(N / 8))`` (at most 2^18): eight segments with Hann
        windows and 50 % overlap, so the lowest frequency is about ``8 fs / N``.
    """
    from scipy.signal import welch

    a = np.asarray(x, float)
    if a.size < 16:
        raise ValueError(f"the PSD needs at least 16 samples, got {a.size}")
    nperseg = int(min(2 ** int(math.log2(a.size / 8)), 2**18))
    f, p = welch(a, fs=fs, nperseg=nperseg)
    f, p = f[1:], p[1:]  # the zero frequency (the mean, removed)
    comps: dict[str, np.ndarray] = {}
    if fit is not None:
        for lab, proc in zip(fit.model.labels, fit.model.processes, strict=True):
            s = 2.0 * proc.psd(f / fs, fs) / fs
            if np.any(s > 0):
                comps[lab] = s
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-12), int(np.ceil(bands * np.log10(f[-1] / f[0]))))
    idx = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, None)
    keep = np.unique(idx)
    count = np.bincount(idx)[keep]

    def band(v: np.ndarray) -> np.ndarray:
        return np.bincount(idx, weights=v)[keep] / count

    comps = {k: band(v) for k, v in comps.items()}
    total = np.sum(list(comps.values()), axis=0) if comps else np.full(keep.size, np.nan)
    return Spectrum(band(f), band(p), total, comps, nperseg)


#: The IEEE quantities drawn as slope lines, with the process class that owns the slope.
_GUIDED = {"N": WN, "K": RW, "Q": QN, "R": DR}


def slope_guides(fit: GMWMResult) -> list[SlopeGuide]:
    """The IEEE slope lines of a fit's quantities (:attr:`engine.fit.GMWMResult.ieee`): -1/2
    through N (white noise, its disguised share included), +1/2 through K, -1 through Q, +1
    through R (each present and non-zero) and the bias-instability floor at the model's ADEV
    minimum (when it lies inside the analysed scales)."""
    t = fit.ieee
    out: list[SlopeGuide] = []
    for key, cls in _GUIDED.items():
        q = t.get(key)
        if q is None or not q.native > 0 or cls.allan_slope is None or cls.read_tau is None:
            continue  # absent, or a term fitted at 0: no line
        out.append(
            SlopeGuide(
                cls.code,
                key,
                cls.allan_slope,
                cls.read_tau,
                q.native,
                q.native_unit,
                q.native,
                q.datasheet_value,
                q.datasheet_unit,
            )
        )
    fl = allan_floor(fit.model, fit.fs, fit.wv.n_levels)
    b = t["B"]
    if not fl["at_edge"] and math.isfinite(b.native):
        out.append(
            SlopeGuide(
                "BI",
                "B",
                0.0,
                b.tau_s,
                b.native * BI_FACTOR,
                b.native_unit,
                b.native,
                b.datasheet_value,
                b.datasheet_unit,
            )
        )
    return out


def _log_info(log: ImuLog, source: str) -> dict[str, Any]:
    meta = log.meta
    info: dict[str, Any] = {
        "file": source,
        "name": Path(source).name,
        "format": meta.get("format"),
        "channels": log.names,
        "fs": log.fs,
        "fs_source": log.fs_source,
        "n": log.n,
        "duration_s": log.duration_s,
        "units": {ch: log.units.get(ch, "") for ch in log.names},
        "time_report": meta.get("time_report"),
        "segment": meta.get("segment"),
        "segments": meta.get("segments"),
        "notes": list(meta.get("notes", [])),
        "sensor": meta.get("sensor", ""),
        "description": meta.get("description", ""),
    }
    if os.path.isfile(source):
        info["size_bytes"] = os.path.getsize(source)
        info["sha256"] = file_sha256(source)
    return info


def _dist_version(name: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


def software_versions() -> dict[str, str]:
    """Versions of the engine, Python and the libraries whose numbers or drawing a report
    shows (numpy, scipy, h5py, bokeh, jinja2): its "How it was made" table."""
    import h5py
    import scipy

    return {
        "gmwm engine": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "bokeh": _dist_version("bokeh"),
        "jinja2": _dist_version("jinja2"),
        "scipy": scipy.__version__,
        "h5py": h5py.__version__,
    }


def _channel(
    log: ImuLog,
    name: str,
    fit: GMWMResult,
    *,
    level: float,
    datasheet: Any,
    temperature: Any = None,
) -> ChannelReport:
    """The numbers of one fitted channel; a step that cannot be done leaves a note.
    ``temperature``: its :class:`~engine.inference.temperature.TemperatureFit` (the PSD is
    then that of the signal the fit is of: compensated when the fit was applied)."""
    from ..inference import j_test, param_intervals
    from ..inference.datasheet_check import DatasheetError, check_datasheet, read_datasheet

    wv = fit.wv
    notes: dict[str, str] = {}
    intervals: list[Any] = []
    try:
        intervals = param_intervals(fit, method="asymptotic", level=level)
    except (FitError, ValueError, np.linalg.LinAlgError) as e:
        notes["intervals"] = str(e)
    rows = datasheet_rows(
        fit.model,
        fit.fs,
        wv.unit,
        channel=name,
        intervals={iv.name: (iv.low, iv.high) for iv in intervals},
        n_levels=wv.n_levels,
    )
    jt = None
    try:
        jt = j_test(fit)
    except (FitError, ValueError, np.linalg.LinAlgError) as e:
        notes["j_test"] = str(e)
    allan = AllanVariance.from_wv(wv) if not wv.robust else None
    spectrum = None
    if log.is_summary:
        notes["psd"] = "a WV summary file holds no samples: no PSD"
    else:
        x = (log if temperature is None else temperature.compensated_log(log))[name]
        if log.segments:  # a flight: the PSD of its longest still segment, not of the motion
            a, b = max(log.segments, key=lambda ab: ab[1] - ab[0])
            notes["psd"] = f"the PSD is that of the longest still segment, samples {a} to {b}"
            x = x[a:b]
        spectrum = welch_psd(x, fit.fs, fit)  # the fit's fs (an app session may set it)
    check = None
    if datasheet is not None:
        try:
            kind = si_factor(wv.unit, name)[0]
        except ExportError as e:
            notes["datasheet_check"] = str(e)
        else:
            try:
                ds = (
                    read_datasheet(datasheet, channel=name, kind=kind)
                    if isinstance(datasheet, Path)
                    else datasheet
                )
                check = check_datasheet(wv, ds, fit=fit, level=level)
            except DatasheetError as e:
                notes["datasheet_check"] = str(e)
    warn = list(fit.warnings)
    if fit.at_bound:
        warn.append(f"at a bound: {', '.join(fit.at_bound)}")
    if not fit.converged:
        warn.append(fit.message)
    return ChannelReport(
        name,
        wv.unit,
        fit,
        "",
        allan,
        slope_guides(fit),
        spectrum,
        intervals,
        rows,
        jt,
        notes,
        warn,
        check,
        timeline(log[name], log.fs, log.segments) if log.segments else None,
        misfit(fit, name),
        temperature,
    )


def gather_report(
    source: str | os.PathLike[str] | ImuLog,
    *,
    model: str | None = None,
    select: str | None = None,
    channels: Sequence[str] | None = None,
    fs: float | None = None,
    levels: int | None = None,
    weights: str = "ci",
    level: float = 0.95,
    datasheet: str | os.PathLike[str] | Any | None = None,
    export_format: str | None = "kalibr",
    load_options: dict[str, Any] | None = None,
    command_line: str = "",
    fits: Mapping[str, GMWMResult] | None = None,
    drop_warmup: bool = False,
    temperature: str | None = "auto",
    temperatures: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
    qualification: Mapping[str, Any] | None = None,
) -> CalibrationReport:
    """Load a log, fit every channel and compute everything a calibration report shows.

    Parameters
    ----------
    source : path or ImuLog
        The log (any format :func:`engine.load_log` reads), or a log already loaded.
    model : str, optional
        The model of every channel (``"GM+WN+RW"``). Without ``model`` and ``select``, each
        channel gets the WVIC-best sub-model of :data:`DEFAULT_SELECT`.
    select : str, optional
        Per channel, the WVIC-best sub-model of this maximal model.
    channels : sequence of str, optional
        Channels to report (default: all).
    fs, levels, weights, load_options
        As :func:`engine.batch.fit_log` (``fs`` and ``load_options`` only with a path).
    level : float
        Interval level of the parameter intervals and the datasheet check (0.95).
    datasheet : str, path or DatasheetSpec, optional
        Datasheet values (``"arw=0.3 deg/sqrt(h), bi=5 deg/h"``), a datasheet file (Kalibr
        ``imu.yaml``, gmwm JSON report, datasheet CSV) or a DatasheetSpec: checked against
        every channel of its sensor kind (the other channels say why they were not).
    export_format : str or None
        An :data:`engine.formats.FORMATS` name whose text the report includes (default
        ``"kalibr"``); None for none.
    command_line : str
        How the report was asked for, shown under "How it was made".
    fits : mapping of str to GMWMResult, optional
        Fits already made of channels of ``source`` (an app session's, a batch's): reported
        as they are, nothing is refitted; ``model``, ``select``, ``channels``, ``levels`` and
        ``weights`` must then be left out (they were the fits').
    drop_warmup : bool
        Drop the warm-up the log check finds (:func:`engine.io.drop_warmup`) before fitting.
    temperature : str, optional
        The temperature channel, as :func:`engine.batch.fit_log`'s: ``"auto"`` (the default:
        a channel named like a temperature, if any), ``"none"`` or its name. Each channel with
        one is fitted on its compensated signal, and its page shows the sensitivity in
        datasheet units and both WVs (raw and compensated). Not used with ``fits``.
    temperatures : mapping of str to TemperatureFit, optional
        With ``fits``: the temperature fits those fits were made with (a batch's
        :attr:`engine.batch.LogFit.temperature`, an app session's).
    progress : callable (stage, done, total), optional
        Called after each channel's fit (stage ``"fits"``) and each channel's numbers and the
        export (``"intervals"``): :data:`Progress`.
    qualification : mapping, optional
        With ``fits``: the log check those fits were made after (a batch's
        :attr:`engine.batch.LogFit.qualification`), reported as it is instead of checking
        the log again.

    Returns
    -------
    CalibrationReport
        Channels that cannot be fitted are in it with their error, never dropped.

    Raises
    ------
    engine.io.LoadError, engine.fit.FitError, engine.models.ModelError
        The log cannot be read, or no channel can be fitted.
    TypeError
        ``fits`` with fitting options, or naming a channel the log does not have.
    """
    from ..batch import fit_log
    from ..formats import export
    from ..inference.datasheet_check import DatasheetSpec, parse_datasheet
    from ..inference.temperature import compensate_channels
    from ..io import drop_warmup as cut_warmup
    from ..io import qualify_log

    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if fits is not None:
        given = {"model": model, "select": select, "channels": channels, "levels": levels}
        clash = [k for k, v in given.items() if v is not None] + (["weights"] * (weights != "ci"))
        if clash:
            raise TypeError(
                f"gather_report(): {', '.join(clash)} cannot be given with fits= (the fits "
                "were made with their own)"
            )
        if not fits:
            raise TypeError("gather_report(): fits= is empty; give at least one channel's fit")
    elif model is None and select is None:
        select = DEFAULT_SELECT
    if qualification is not None and fits is None:
        raise TypeError(
            "gather_report(): qualification= goes with fits= (the check those fits followed)"
        )
    ds: Any = None
    ds_text = ""
    if isinstance(datasheet, DatasheetSpec):
        ds, ds_text = datasheet, datasheet.describe()
    elif datasheet is not None:
        if os.path.exists(datasheet):
            ds, ds_text = Path(datasheet), f"file {datasheet}"
        else:
            ds, ds_text = parse_datasheet(str(datasheet), source="datasheet"), str(datasheet)
    log = log_of(source, fs=fs, load_options=load_options, caller="gather_report")
    src = log.source or str(source)
    if drop_warmup and fits is None:
        log = cut_warmup(
            log, qualify_log(log, list(channels) if channels else None).suggested_start
        )
    if fits is not None:
        unknown = [ch for ch in fits if ch not in log.names]
        if unknown:
            raise TypeError(
                f"gather_report(): fits= names channel(s) {unknown} that {src} does not have "
                f"(it has {', '.join(log.names)})"
            )
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        if fits is not None:
            fitted, channel_errors = dict(fits), {}
            temps = dict(temperatures or {})
            check = (
                dict(qualification)
                if qualification is not None
                else qualify_log(log, list(fitted)).to_dict()
            )
            weights = ", ".join(dict.fromkeys(f.weights for f in fitted.values()))
        else:
            lf = fit_log(
                log,
                model=model,
                select=select,
                channels=channels,
                levels=levels,
                weights=weights,
                temperature=temperature,
                progress=None if progress is None else partial(progress, "fits"),
                json_report=False,  # the report's own numbers follow; fit_log's JSON unused
            )
            fitted, channel_errors, temps = lf.fits, lf.channel_errors, lf.temperature
            check = lf.qualification
        chans: dict[str, ChannelReport] = {}
        todo = list(fitted) + list(channel_errors)
        steps = len(todo) + bool(export_format)
        if progress is not None:
            progress("intervals", 0, steps)
        for k, ch in enumerate(todo):
            if ch in fitted:
                tf = temps.get(ch)
                chans[ch] = _channel(
                    log,
                    ch,
                    fitted[ch],
                    level=level,
                    datasheet=ds,
                    temperature=tf,
                )
            else:
                chans[ch] = ChannelReport(ch, log.units.get(ch, ""), error=channel_errors[ch])
            if progress is not None:
                progress("intervals", k + 1, steps)
        chans = {ch: chans[ch] for ch in log.names if ch in chans}
    log_warnings = [f"{w.category.__name__}: {w.message}" for w in caught]
    if log.fs_source == "default":
        log_warnings.insert(
            0,
            f"{src} does not say its sampling frequency: fs = 1 Hz ASSUMED, so every time in "
            "seconds and every datasheet value is per sample",
        )
    exp: dict[str, str] = {}
    if export_format:
        exp["format"] = export_format
        try:
            f = FORMATS.get(export_format)
            one_sensor = f is not None and f.takes("allow_partial")  # Kalibr: the keys fitted
            exp["text"] = export(  # the tail factors of the signal the fits were made on
                None,
                fitted,
                export_format,
                log=compensate_channels(log, temps.values()),
                allow_partial=one_sensor,
            )
        except (ExportError, ValueError) as e:
            exp["error"] = str(e)
        if progress is not None:
            progress("intervals", steps, steps)
    provenance = {
        "versions": software_versions(),
        "model": model or "",
        "select": select or "",
        "fits_given": fits is not None,
        "models": {ch: c.fit.model.spec(values=True) for ch, c in chans.items() if c.fit},
        "weights": weights,
        "intervals": f"asymptotic sandwich, {100 * level:g} % two-sided",
        "j_test": (
            "asymptotic chi-square, V from the fitted model (the WV's own estimator, a drift's "
            "share included; no p-value where not calibrated)"
        ),
        "wv": "classical Haar WV (MODWT), eta3 95 % intervals",
        "command_line": command_line,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    info = _log_info(log, src)
    info["qualification"] = check  # the log check before the fit (engine.io.qualify)
    return CalibrationReport(info, chans, exp, ds_text, provenance, log_warnings)
