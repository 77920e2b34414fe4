"""Reading data for a session: sources, the loaded log, and its WV cache (no widgets).

Worker-thread safe: nothing here changes a session's state. :func:`read_source` reads the
demo, an upload, a server path or a teaching scenario into a :class:`LoadedData`;
:func:`precompute` fills its WVs, ``(channel, fs, robust) -> WaveletVariance``, which become
the session's WV cache when the data are installed (:class:`gmwm_app.wv_cache.WVCache`, kept
by :class:`gmwm_app.state.AppState` with the log; every tab reads its WVs from there).
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
import weakref
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import engine as eg
from engine.inference.temperature import (
    TemperatureFit,
    compensate_channels,
    find_temperature,
    fit_log_temperature,
)
from engine.io import ImuLog, Qualification, qualify_log
from engine.io import drop_warmup as drop_warmup_of
from engine.wv import check_fs as engine_check_fs
from gmwm_app.hdf5_guard import check_hdf5, is_hdf5
from gmwm_app.limits import check_path, check_upload_size
from gmwm_app.wv_cache import WVKey, store_wv, wv_from_cache

__all__ = [
    "LoadedData",
    "PreparedQuery",
    "read_log",
    "read_source",
    "precompute",
    "compute_wv",
    "check_fs",
    "channel_names",
    "summary_has_robust",
    "fs_source",
    "unit_of",
    "message_of",
    "wv_matrix_of",
    "read_demo",
    "shared_wvs",
    "clear_shared",
    "log_check_line",
    "warmup_start",
    "temperature_fit_of",
    "temperature_line",
    "compensated_series",
    "is_compensated",
    "fitted_log",
    "temperature_unusable",
    "COMPENSATION",
    "compensation_mode",
]

#: The temperature compensation choices of a session (``AppState.compensate``): ``auto``
#: (as ``gmwm fit --temperature auto``: compensated when the joint Wald test of the
#: temperature terms rejects at 5 %), ``always`` (as ``--temperature COLUMN``: whatever the
#: test says), ``off`` (as ``--temperature none``: the raw signal).
COMPENSATION: tuple[str, ...] = ("auto", "always", "off")


def compensation_mode(value: Any) -> str:
    """A compensation choice of :data:`COMPENSATION` from what a link or a saved session
    holds: the choice itself, or the switch of before (True or on: ``auto``; False or off:
    ``off``).

    Raises
    ------
    ValueError
        Anything else, naming the value and the choices.
    """
    if isinstance(value, bool):
        return "auto" if value else "off"
    text = str(value).strip().lower()
    if text in COMPENSATION:
        return text
    if text in ("1", "true", "yes", "on"):
        return "auto"
    if text in ("0", "false", "no", "none"):
        return "off"
    raise ValueError(
        f"temperature compensation {value!r} is not one of {', '.join(COMPENSATION)} "
        "(or 0 for off, 1 for auto)"
    )


log = logging.getLogger(__name__)


def read_log(path: str | os.PathLike[str] | bytes, **options: Any) -> ImuLog:
    """Read an IMU log with the engine's loader (``engine.load_log``, imported on first use:
    the app module loads without h5py work).

    Parameters
    ----------
    path : str, path-like or bytes
        CSV/TSV/text, NPY/NPZ, HDF5 log or WV summary HDF5 file, or its content (an upload).
    **options
        ``load_log``'s keyword arguments: here ``name`` (the uploaded file's name, for
        content: its extension and the name in messages), ``fs`` (Hz, when the file has none)
        and ``segment``.

    Returns
    -------
    ImuLog

    Raises
    ------
    ValueError
        (``engine.LoadError``) with a message naming the file and the fix.
    """
    from engine.io import load_log

    return load_log(path, **options)


# The demo log and the WVs computed of it are shared by every session of the process: a
# class opening the app at once would otherwise read the same file and compute the same WV
# once per page (about 0.2 s of a worker thread and 10 MB each). The shared log's arrays are
# read-only, so that no session can change another's data; each session gets its own WV
# cache (a copy of the shared one), to which it adds what it computes.
_SHARED_LOCK = threading.Lock()
_SHARED_DEMO: dict[tuple[str, int, int], ImuLog] = {}  # (path, mtime_ns, size) -> log
_SHARED_WVS: weakref.WeakKeyDictionary[ImuLog, dict[WVKey, eg.WaveletVariance]] = (
    weakref.WeakKeyDictionary()
)


def read_demo(path: str | os.PathLike[str]) -> ImuLog:
    """The demo log at ``path``, read once per process while the file is unchanged.

    Parameters
    ----------
    path : str or path-like
        The demo log (``gmwm_app.state.demo_path()``).

    Returns
    -------
    ImuLog
        The log shared by every session (its arrays are read-only); :func:`shared_wvs`
        holds the WVs computed of it.
    """
    p = Path(path)
    st = p.stat()
    key = (str(p.resolve()), st.st_mtime_ns, st.st_size)
    with _SHARED_LOCK:
        hit = _SHARED_DEMO.get(key)
    if hit is not None:
        return hit
    lg = read_log(p)
    for arr in lg.channels.values():
        if isinstance(arr, np.ndarray):
            arr.flags.writeable = False
    with _SHARED_LOCK:
        if key not in _SHARED_DEMO:  # another thread may have read it meanwhile
            _SHARED_DEMO.clear()  # one demo at a time (a changed file replaces it)
            _SHARED_DEMO[key] = lg
            _SHARED_WVS[lg] = {}
        return _SHARED_DEMO[key]


def shared_wvs(lg: ImuLog) -> dict[WVKey, eg.WaveletVariance] | None:
    """A copy of the WVs shared with every session for ``lg`` (None: ``lg`` is not shared)."""
    with _SHARED_LOCK:
        wvs = _SHARED_WVS.get(lg)
        return None if wvs is None else dict(wvs)


def clear_shared() -> None:
    """Forget the shared demo log and its WVs (the next session reads the file again)."""
    with _SHARED_LOCK:
        _SHARED_DEMO.clear()
        _SHARED_WVS.clear()


@dataclass
class LoadedData:
    """A log read from a source, with the WVs precomputed for it (filled by a worker thread).

    Attributes
    ----------
    log : ImuLog
        The loaded log.
    source : str
        ``"demo"``, ``"upload"`` or ``"path"``.
    name : str
        File name shown to the user.
    path : str
        Server path (empty for uploads).
    wv_cache : dict
        ``(channel, fs, robust, compensated) -> WaveletVariance``.
    elapsed_s : float
        Time spent reading the file (s).
    computations : int
        WVs computed for it (by :func:`precompute`).
    load : dict
        The ``load_log`` options it was read with (``segment``).
    wv_errors : dict
        ``(channel, fs, robust, compensated) -> message``: WVs :func:`precompute` could not
        compute (the install reports the message instead of computing the WV again).
    """

    log: ImuLog
    source: str
    name: str
    path: str = ""
    wv_cache: dict[WVKey, eg.WaveletVariance] = field(default_factory=dict)
    elapsed_s: float = 0.0
    computations: int = 0
    load: dict[str, Any] = field(default_factory=dict)
    wv_errors: dict[WVKey, str] = field(default_factory=dict)


@dataclass
class PreparedQuery:
    """What :meth:`AppState.prepare_query` read for a URL query (settings, data, problems)."""

    settings: dict[str, Any]
    loaded: LoadedData | None
    problems: list[str]


def read_source(
    source: str,
    *,
    path: str | os.PathLike[str] | None = None,
    data: bytes | str | None = None,
    filename: str = "",
    segment: str | None = None,
    demo: Path | None = None,
    segments: str | None = None,
    drop_warmup: int = 0,
) -> LoadedData:
    """Read a log from a source. Heavy; touches no state, safe in a worker thread.

    Parameters
    ----------
    source : {"demo", "upload", "path"}
        The bundled demo, uploaded bytes (``data`` + ``filename``), or a server ``path``.
    segments : str, optional
        A flight log's parts to analyse (uploads and paths): ``"auto"`` (its still segments)
        or ``"START:STOP,..."`` samples (``engine.load_log``'s ``segments``).
    demo : Path
        The demo log (``gmwm_app.state.demo_path()``).
    drop_warmup : int
        Samples dropped from the start as a warm-up (:func:`engine.io.drop_warmup`), after
        ``segment``; 0 keeps them.

    Raises
    ------
    ValueError
        Missing/unreadable file or a file the loader rejects (message says why).
    """
    t0 = time.perf_counter()
    if source == "demo":
        p = Path(demo) if demo is not None else Path("data/demo_imu.h5")
        if not p.exists():
            raise ValueError(
                f"the demo log {p} is missing: run `python data/make_demo.py` "
                "in the repository, or load a file"
            )
        lg = read_demo(p)
        out = LoadedData(lg, "demo", p.name, str(p), wv_cache=shared_wvs(lg) or {})
    elif source == "path":
        if not path or not str(path).strip():
            raise ValueError("no path given: type the path of a log file on the server")
        given = str(path).strip()  # messages name the path as the user gave it
        p = check_path(given)  # only the configured folders (gmwm-app --data-dir), first
        if not p.exists():  # so that nothing is said about files outside them
            raise ValueError(f"no such file on the server: '{given}'")
        if p.is_file():  # the HDF5 library may hang or crash on a damaged file
            with open(p, "rb") as fh:  # (not a FIFO or a device: the loader refuses those)
                if is_hdf5(fh.read(2056), p.name):
                    check_hdf5(str(p), given)
        lg = read_log(p, segment=segment, name=given, segments=segments)
        out = LoadedData(lg, "path", p.name, str(p))
    elif source == "upload":
        if data is None or len(data) == 0:
            raise ValueError(f"the uploaded file {filename or ''} is empty".replace("  ", " "))
        if isinstance(data, str):
            data = data.encode("utf-8")
        check_upload_size(len(data), filename)
        name = Path(filename or "upload.csv").name
        # no copies of the content (an upload may be 200 MB): the guard sends it as a
        # buffer, the loader reads it in place (bytes) through io.BytesIO
        if is_hdf5(bytes(data[:2056]), name):  # see gmwm_app.hdf5_guard
            check_hdf5(data, name)
        lg = read_log(data, segment=segment, name=name, segments=segments)
        out = LoadedData(lg, "upload", name, "")
    elif source == "scenario":  # a simulated teaching log (engine.teaching), key in path
        from engine.teaching import get_scenario, simulate_scenario

        try:
            sc = get_scenario(str(path or "").strip())
        except KeyError as e:
            raise ValueError(e.args[0]) from None
        out = LoadedData(simulate_scenario(sc), "scenario", f"scenario {sc.key}", sc.key)
    else:
        raise ValueError(f"unknown data source {source!r}: use demo, upload or path")
    if not out.log.is_summary and not out.log.channels:
        raise ValueError(f"{out.name} has no data channel")
    if drop_warmup:  # a new log: none of the whole log's WVs (the demo's shared ones) apply
        out = LoadedData(drop_warmup_of(out.log, drop_warmup), out.source, out.name, out.path)
    out.elapsed_s = time.perf_counter() - t0
    if segment:
        out.load["segment"] = segment
    if segments:
        out.load["segments"] = segments
    if drop_warmup:
        out.load["drop_warmup"] = int(drop_warmup)
    return out


def precompute(
    loaded: LoadedData,
    channel: str | None = None,
    fs: float | None = None,
    robust: bool = False,
    compensate: str = "auto",
) -> None:
    """Compute the WV of one channel of ``loaded`` into its cache (worker-thread safe): that of
    the temperature-compensated signal when the choice ``compensate`` (:data:`COMPENSATION`)
    compensates the channel (:func:`is_compensated`), and then the raw signal's too (the Fit
    view draws it in grey beside it).

    A WV that cannot be computed (e.g. a channel of NaN) is not raised here: its message is
    kept in ``loaded.wv_errors`` (and logged), and the install that follows reports it on the
    page (the data cannot be shown without it). Anything else is raised.

    The log check of that channel (:func:`log_check_line`, a tenth of a second on a long log)
    is run here too, so the install on the server loop finds it cached.
    """
    lg = loaded.log
    names = channel_names(lg)
    if not names:
        return
    ch = channel if channel in names else names[0]
    log_check_line(lg, ch)
    f = float(fs) if fs else float(lg.fs)
    comp = is_compensated(lg, ch, compensate)
    for c in (comp, False) if comp else (False,):
        if wv_from_cache(loaded.wv_cache, ch, f, robust, c) is not None:
            continue
        try:
            wv = compute_wv(lg, ch, f, robust, compensate=c)
        except ValueError as e:
            log.warning("%s: no WV of %s: %s", loaded.name, ch, message_of(e))
            loaded.wv_errors[(ch, f, robust, c)] = message_of(e)
            return
        store_wv(loaded.wv_cache, ch, f, robust, c, wv)
        loaded.computations += 1
        with _SHARED_LOCK:  # a shared log: the next sessions find this WV computed
            if lg in _SHARED_WVS:
                store_wv(_SHARED_WVS[lg], ch, f, robust, c, wv)


def message_of(e: BaseException) -> str:
    """An exception as a sentence (KeyError's quotes removed)."""
    if isinstance(e, KeyError) and e.args:
        return str(e.args[0])
    return str(e) or type(e).__name__


def check_fs(fs: Any) -> float:
    """``fs`` as a positive finite number of Hz; ValueError naming the bad value."""
    try:
        f = float(fs)  # the field's text or number
    except (TypeError, ValueError):
        f = math.nan
    try:
        return engine_check_fs(f)
    except ValueError:
        raise ValueError(f"fs must be a positive number of Hz, got {fs!r}") from None


def channel_names(lg: ImuLog) -> list[str]:
    """Channel names of a log (raw or WV summary), in file order."""
    return list(lg.names)


def summary_has_robust(lg: ImuLog, ch: str) -> bool:
    """Whether a WV summary file holds a robust WV for ``ch``."""
    wv = lg.wv.get(ch)
    return wv is not None and bool(wv.robust)


def fs_source(lg: ImuLog) -> str:
    """Where a log's fs came from (``"file"``, ``"time column"`` ...)."""
    return str(getattr(lg, "fs_source", "file") or "file")


def unit_of(lg: ImuLog, ch: str) -> str:
    """Unit of channel ``ch`` of a log (empty when the file names none)."""
    return str(lg.unit_of(ch))


def compute_wv(
    lg: ImuLog,
    ch: str,
    fs: float,
    robust: bool,
    progress: Callable[[int, int], object] | None = None,
    compensate: bool = True,
) -> eg.WaveletVariance:
    """WV of one channel of a log (a summary file's stored WV, re-labelled to ``fs``); with
    ``compensate`` and a temperature channel beside it that the fit can use
    (:func:`temperature_fit_of`), the WV of its compensated signal (the relation taken out
    whatever its test says: :func:`is_compensated` decides whether a session asks for it).

    ``progress(j, J)`` is called as each level of a computed WV is done (see
    :func:`engine.wavelet_variance`); not for a summary file's stored WV.
    """
    if lg is None:
        raise ValueError("load a log first")
    try:
        tf = temperature_fit_of(lg, ch, "always") if compensate else None
        if tf is not None:  # the compensated signal, as `gmwm fit --temperature T` fits it
            lg = tf.compensated_log(lg)  # (a log cut into segments: still pooled)
        return lg.wavelet_variance(ch, robust=robust, fs=fs, progress=progress)
    except (ValueError, TypeError) as e:
        raise ValueError(f"channel {ch}: {message_of(e)}") from None


#: Per loaded log, the log as a session's fits see it (:func:`fitted_log`), per choice and
#: channels: one object, so that the export's tail factors (cached per log object,
#: :func:`engine.formats.tails.log_tail_factors`) are computed once.
_FITTED_LOGS: weakref.WeakKeyDictionary[ImuLog, dict[tuple[str, tuple[str, ...]], ImuLog]] = (
    weakref.WeakKeyDictionary()
)
_FITTED_LOCK = threading.Lock()


def fitted_log(lg: ImuLog, channels: Iterable[str], compensate: str) -> ImuLog:
    """The log as a session's fits of ``channels`` see it: each channel that the choice
    ``compensate`` (:data:`COMPENSATION`) compensates (:func:`is_compensated`) with its
    bias-temperature relation taken out, as its WV was computed (:func:`compute_wv`); the log
    itself when none is. What a filter file's tail factors must read (``engine.export``'s
    ``log``), as ``gmwm batch --export`` reads each unit's prepared log. Cached per log."""
    chans = tuple(c for c in channels if c in set(channel_names(lg)))
    comp = tuple(c for c in chans if is_compensated(lg, c, compensate))
    if not comp:
        return lg
    key = (compensation_mode(compensate), comp)
    with _FITTED_LOCK:
        hit = _FITTED_LOGS.get(lg, {}).get(key)
    if hit is not None:
        return hit
    # what compute_wv takes out of each
    out = compensate_channels(lg, [temperature_fit_of(lg, c, "always") for c in comp])
    with _FITTED_LOCK:
        _FITTED_LOGS.setdefault(lg, {})[key] = out
    return out


def compensated_series(lg: ImuLog, ch: str, tf: TemperatureFit | None) -> np.ndarray:
    """The samples of channel ``ch`` with the bias-temperature relation ``tf`` taken out
    (:meth:`~engine.inference.temperature.TemperatureFit.compensate`); the raw samples when
    ``tf`` is None."""
    return np.asarray((lg if tf is None else tf.compensated_log(lg)).channels[ch])


def is_compensated(lg: ImuLog | None, ch: str, compensate: str) -> bool:
    """Whether the WV of ``ch`` that a session with the choice ``compensate``
    (:data:`COMPENSATION`) shows is that of a temperature-compensated signal: not ``off``,
    and a temperature fit of the channel that this choice applies
    (:func:`temperature_fit_of`; with ``auto``, only when its test rejects). The fourth
    element of the session's WV keys."""
    mode = compensation_mode(compensate)
    tf = temperature_fit_of(lg, ch, mode) if mode != "off" and lg is not None else None
    return bool(tf is not None and tf.applied)


def wv_matrix_of(
    lg: ImuLog, channels: Sequence[str], fs: float, compensate: str = "off"
) -> tuple[eg.wv.WVMatrix, str]:
    """The WV/WCCV matrix of some channels of a log, and a notice (truncation, compensation).

    Channels of different lengths are truncated to the shortest (the notice says so). Each
    channel that the choice ``compensate`` (:data:`COMPENSATION`) compensates
    (:func:`is_compensated`) is taken with its bias-temperature relation taken out, as the
    Fit tab's WV is (the notice names them).

    Raises
    ------
    ValueError
        No raw data (a WV summary file), too few or unusable channels.
    """
    if lg is None:
        raise ValueError("load a log first")
    if lg.is_summary:
        raise ValueError(
            f"{getattr(lg, 'source', '') or 'this file'} is a wavelet-variance "
            "summary without raw samples: the wavelet cross-covariance needs "
            "the raw channels of a log (CSV, NPY/NPZ or HDF5)"
        )
    chans = tuple(channels)
    mode = compensation_mode(compensate)
    fits = {c: temperature_fit_of(lg, c, mode) if mode != "off" else None for c in chans}
    series = {c: compensated_series(lg, c, fits[c]) for c in chans}
    sizes = {c: int(a.size) for c, a in series.items()}
    n = min(sizes.values())
    notes = []
    if len(set(sizes.values())) > 1:
        desc = ", ".join(f"{c}: {v:,}" for c, v in sizes.items())
        notes.append(
            f"The channels have different lengths ({desc} samples); all are "
            f"truncated to the shortest, {n:,} samples."
        )
        series = {c: a[:n] for c, a in series.items()}
    done = [f"{c} ('{tf.temperature}')" for c, tf in fits.items() if tf and tf.applied]
    if done:
        notes.append(
            f"Temperature-compensated ({mode}), as on the Fit tab: {', '.join(done)}; the "
            "sidebar's 'Temperature compensation' choice turns it off."
        )
    units = {c: str((getattr(lg, "units", None) or {}).get(c, "")) for c in chans}
    wvm = eg.wv.wv_matrix(series, channels=list(chans), fs=float(fs), units=units)
    return wvm, " ".join(notes)


#: The log check's line per log and channel, computed once per loaded log (it dies with it).
_CHECKS: weakref.WeakKeyDictionary[ImuLog, dict[str, Qualification]] = weakref.WeakKeyDictionary()
_CHECKS_LOCK = threading.Lock()


def _log_check(lg: ImuLog, channel: str) -> Qualification | None:
    """The log check (:func:`engine.io.qualify_log`) of one channel; None for a WV summary
    (no samples). Cached per log and channel."""
    if lg.is_summary:
        return None
    with _CHECKS_LOCK:
        done = _CHECKS.setdefault(lg, {})
        if channel in done:
            return done[channel]
    q = qualify_log(lg, [channel])
    with _CHECKS_LOCK:
        done[channel] = q
    return q


def log_check_line(lg: ImuLog, channel: str) -> str:
    """What the log check (:func:`engine.io.qualify_log`) found in one channel, in one line;
    ``""`` for a clean channel or a WV summary (no samples). Cached per log and channel."""
    q = _log_check(lg, channel)
    return q.line() if q is not None and (q.findings or q.dropped) else ""


def warmup_start(lg: ImuLog, channel: str) -> int:
    """The first sample after the warm-up the log check found in one channel (of the mean or
    of the bias wander, its triad judged together: :attr:`Qualification.suggested_start`);
    0 without one."""
    q = _log_check(lg, channel)
    return q.suggested_start if q is not None else 0


#: The temperature fit per log, channel and whether it is forced (``always``), or why there
#: is none (once per loaded log).
_TEMPS: weakref.WeakKeyDictionary[
    ImuLog, dict[tuple[str, bool], tuple[TemperatureFit | None, str]]
] = weakref.WeakKeyDictionary()


def _temperature_of(
    lg: ImuLog, channel: str, force: bool = False
) -> tuple[TemperatureFit | None, str]:
    """The temperature fit of a channel and ``""``, or None and why there is none (``""``:
    no temperature channel beside it). ``force``: the relation taken out whatever its test
    says (the ``auto`` fit itself when it already is). Cached per log, channel and ``force``."""
    with _CHECKS_LOCK:
        done = _TEMPS.setdefault(lg, {})
        if (channel, force) in done:
            return done[(channel, force)]
    out: tuple[TemperatureFit | None, str] = (None, "")
    if force:
        auto, why = _temperature_of(lg, channel)
        if auto is None or auto.applied:
            out = (auto, why)
        else:  # the same relation, taken out: as `gmwm fit --temperature COLUMN`
            out = (fit_log_temperature(lg, channel, auto.temperature, compensate=True), "")
    else:
        tname = None if lg.is_summary else find_temperature(lg, "auto", channel=channel)
        if tname is not None:
            try:  # by its name (a channel the fit cannot use says why), as `--temperature auto`
                out = (fit_log_temperature(lg, channel, tname, compensate="auto"), "")
            except ValueError as e:  # constant temperature, too short, NaN
                out = (None, message_of(e))
    with _CHECKS_LOCK:
        done[(channel, force)] = out
    return out


def temperature_fit_of(lg: ImuLog, channel: str, compensate: str = "auto") -> TemperatureFit | None:
    """The bias-temperature fit of one channel of a log under the choice ``compensate``
    (:data:`COMPENSATION`; :func:`engine.inference.temperature.fit_log_temperature`,
    temperature channel found automatically; a log cut into still segments on its segments):
    with ``auto`` and ``off``, compensated only when the data show an effect, as ``gmwm fit
    --temperature auto`` (``off`` shows it, :func:`is_compensated` leaves it out); with
    ``always``, compensated whatever the test says, as ``--temperature COLUMN``. None: no
    temperature channel, a WV summary, or a relation that cannot be fitted (a constant
    temperature, too few samples; :func:`temperature_unusable` says why). Cached per log,
    channel and choice."""
    return _temperature_of(lg, channel, compensation_mode(compensate) == "always")[0]


def temperature_unusable(lg: ImuLog, channel: str) -> str:
    """Why the temperature channel beside a channel cannot compensate it, in one phrase (the
    fit cannot use it: a constant temperature, too few samples, NaN); ``""`` when it can (a
    sensitivity the test cannot tell from 0 included: ``always`` takes it out), or when it
    has no temperature channel."""
    return _temperature_of(lg, channel)[1]


#: What the info line says of the choice in force (:func:`temperature_line`).
_COMPENSATED = (
    "the WV and the fit are of the temperature-compensated signal (the raw signal's WV in grey)"
)
_RAW = "the WV and the fit are of the raw signal"


def temperature_line(lg: ImuLog, channel: str, compensate: str = "auto") -> str:
    """The one line the Fit view says of a channel with a temperature channel beside it: the
    sensitivity with its interval in datasheet units, the choice in force
    (:data:`COMPENSATION`; for ``auto`` with its test's p-value), and whether the WV and the
    fit are of the compensated signal or of the raw one; ``""`` without one."""
    mode = compensation_mode(compensate)
    tf = temperature_fit_of(lg, channel, mode)
    if tf is None:
        return ""
    p = f"p = {tf.p_value:.2g}"
    if mode == "off":
        return f"{tf.line(anyway=_ANYWAY)}; compensation off: {_RAW}"
    if mode == "always":
        return (
            f"{tf.line()}; compensation always ({p}, taken out whatever the test): {_COMPENSATED}"
        )
    if not tf.applied:  # the line says so and gives p: the sensitivity is information only
        return f"{tf.line(anyway=_ANYWAY)}; compensation auto: {_RAW}"
    return f"{tf.line()}; compensation auto ({p} < {1 - tf.level:.2g}): {_COMPENSATED}"


#: How a session compensates anyway what ``auto`` leaves in.
_ANYWAY = "choose 'always' to compensate anyway"
