"""Session state of the GMWM app: data, channel, cached wavelet variance, model and fit.

No widgets here: :class:`AppState` is a plain ``param.Parameterized`` that the views read and
the widgets drive, so it can be tested without a browser. Data flows one way::

    file -> ImuLog -> WaveletVariance (computed once per channel, cached) -> fit_gmwm -> result

Changing the model refits on the cached WV; it never recomputes the WV. Every public action
returns ``True`` on success; on failure it sets :attr:`AppState.error` to a sentence that says
what went wrong and how to fix it, and leaves the previous (valid) state in place.

Heavy work (reading a file, computing a WV) is split from the state change so that the app
can run it in a worker thread: :meth:`AppState.read` and :meth:`AppState.precompute` /
:meth:`AppState.warm` touch no parameter, :meth:`AppState.install`, :meth:`AppState.select_channel`
... then find the WV in the cache and are fast.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import param

import engine as eg
from gmwm_app.limits import check_path, check_upload_size

__all__ = [
    "AppState",
    "LoadedData",
    "PreparedQuery",
    "SliderSpec",
    "PROCESS_CODES",
    "demo_path",
    "read_log",
    "format_value",
]

log = logging.getLogger(__name__)

#: Process codes in the order of the add buttons.
PROCESS_CODES: tuple[str, ...] = ("WN", "QN", "RW", "DR", "AR1", "GM")

#: Readable names of the processes (for the process list).
PROCESS_NAMES: dict[str, str] = {
    "WN": "white noise",
    "QN": "quantization noise",
    "RW": "random walk",
    "DR": "drift",
    "AR1": "AR(1)",
    "GM": "Gauss-Markov",
}

#: Sources a session can load from.
SOURCES: tuple[str, ...] = ("demo", "upload", "path", "scenario")


def demo_path() -> Path:
    """Path of the bundled demo log (package data: :func:`engine.demo.demo_path`).

    The environment variable ``GMWM_APP_DEMO`` overrides it (tests, benchmarks).
    """
    env = os.environ.get("GMWM_APP_DEMO")
    if env:
        return Path(env)
    from engine.demo import demo_path as bundled

    return bundled()


def format_value(v: float, digits: int = 4) -> str:
    """A number for display: ``0.001005`` -> ``1.005e-03``, ``12.5`` -> ``12.5``."""
    if v is None or not math.isfinite(v):
        return "n/a"
    if v == 0:
        return "0"
    a = abs(v)
    if 1e-3 <= a < 1e5:
        return f"{v:.{digits}g}"
    return f"{v:.{digits - 1}e}"


# ---------------------------------------------------------------------------------------------
# reading files
# ---------------------------------------------------------------------------------------------
def read_log(
    path: str | os.PathLike[str], *, fs: float | None = None, segment: str | None = None
) -> Any:
    """Read an IMU log with the engine's loader (``engine.load_log``).

    Parameters
    ----------
    path : str or path-like
        CSV/TSV/text, NPY/NPZ, HDF5 log or WV summary HDF5 file.
    fs : float, optional
        Sampling frequency (Hz) to use when the file has none.

    Returns
    -------
    ImuLog

    Raises
    ------
    ValueError
        (``engine.LoadError``) with a message naming the file and the fix.
    """
    from engine.io import load_log  # imported here: the app module loads without h5py work

    return load_log(path, fs=fs, segment=segment)


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
        ``(channel, fs, robust) -> WaveletVariance``.
    elapsed_s : float
        Time spent reading the file (s).
    """

    log: Any
    source: str
    name: str
    path: str = ""
    wv_cache: dict[tuple[str, float, bool], eg.WaveletVariance] = field(default_factory=dict)
    elapsed_s: float = 0.0
    computations: int = 0
    load: dict[str, Any] = field(default_factory=dict)  # load_log options (segment)


@dataclass
class Inference:
    """95% asymptotic intervals (``ParamInterval`` list) and J-test of one fit."""

    result: Any
    intervals: list[Any]
    j_test: Any = None  # engine.inference.JTest, None when it cannot be computed
    j_error: str = ""


@dataclass
class PreparedQuery:
    """What :meth:`AppState.prepare_query` read for a URL query (settings, data, problems)."""

    settings: dict[str, Any]
    loaded: LoadedData | None
    problems: list[str]


@dataclass(frozen=True)
class SliderSpec:
    """A "what if" slider generated from a parameter (no widget: the app builds it).

    The slider moves ``x = log10(value)`` (``log10(1 - phi)`` for an AR1 ``phi``) over
    ``[lo, hi]``, 3 decades either side of the current value.
    """

    name: str  # unique parameter name, e.g. "GM_1.beta"
    label: str  # process label, e.g. "GM_1"
    param: str  # engine parameter name, e.g. "beta"
    unit: str
    transform: str  # "log10" or "log10(1-x)"
    lo: float
    hi: float
    x: float  # slider position

    def value_of(self, x: float) -> float:
        """Parameter value at slider position ``x``."""
        return 1.0 - 10.0**x if self.transform == "log10(1-x)" else 10.0**x

    @staticmethod
    def position_of(transform: str, value: float) -> float:
        """Slider position of a parameter value."""
        if transform == "log10(1-x)":
            return math.log10(max(1.0 - value, 1e-15))
        return math.log10(abs(value))


def _retag_fs(wv: eg.WaveletVariance, fs: float) -> eg.WaveletVariance:
    """The same WV at another sampling frequency (the variances do not depend on fs)."""
    classical = None if wv.classical is None else dataclasses.replace(wv.classical, fs=fs)
    return dataclasses.replace(wv, fs=fs, classical=classical)


def _wv_from_cache(
    cache: Mapping[tuple[str, float, bool], eg.WaveletVariance],
    channel: str,
    fs: float,
    robust: bool,
) -> eg.WaveletVariance | None:
    """A cached WV for (channel, fs, robust), derived without recomputation when possible."""
    hit = cache.get((channel, fs, robust))
    if hit is not None:
        return hit
    for (ch, _fs, rob), wv in list(cache.items()):
        if ch != channel:
            continue
        if rob == robust:
            return _retag_fs(wv, fs)
        if not robust and rob and wv.classical is not None:
            return _retag_fs(wv.classical, fs)
    return None


# ---------------------------------------------------------------------------------------------
# the state
# ---------------------------------------------------------------------------------------------
class AppState(param.Parameterized):
    """Everything one browser session knows: data, channel, WV, model, fit, what-if values.

    Parameters are set by the action methods (``load_*``, ``select_channel``, ``set_fs``,
    ``set_robust``, ``add_process``, ``remove_process``, ``set_model``, ``set_whatif_value``,
    ``from_query``); views watch :attr:`revision`, which increases after every change.
    """

    # data
    source = param.Selector(default="demo", objects=list(SOURCES), doc="Where the data came from.")
    path = param.String(
        default="",
        doc="Server path of the loaded file (source 'path'); "
        "the scenario key for source 'scenario'.",
    )
    filename = param.String(default="", doc="Name of the loaded file.")
    channels = param.List(default=[], item_type=str, doc="Channel names of the loaded log.")
    channel = param.String(default="", doc="Selected channel.")
    fs = param.Number(default=None, allow_None=True, doc="Sampling frequency (Hz).")
    fs_source = param.String(default="", doc="Where fs came from: file, time column, user ...")
    n = param.Integer(default=0, doc="Samples of the selected channel.")
    duration_s = param.Number(default=0.0, doc="Duration of the selected channel (s).")
    unit = param.String(default="", doc="Unit of the selected channel.")
    is_summary = param.Boolean(default=False, doc="The file holds WV summaries, no raw data.")
    robust = param.Boolean(default=False, doc="Robust (Tukey biweight) WV.")
    wv = param.ClassSelector(
        class_=eg.WaveletVariance,
        default=None,
        allow_None=True,
        doc="Empirical WV of the selected channel (from the cache).",
    )
    # model and fit
    model = param.ClassSelector(class_=eg.Model, default=eg.Model(), doc="Current model.")
    result = param.ClassSelector(
        class_=eg.GMWMResult,
        default=None,
        allow_None=True,
        doc="Fit of the current model, None for an empty model.",
    )
    whatif = param.Boolean(default=False, doc="Draw the what-if values instead of the fit.")
    whatif_values = param.Dict(default={}, doc="What-if values by unique parameter name.")
    weights = param.String(default="ci", doc="GMWM weighting ('ci' or 'identity').")
    # model selection and inference (see gmwm_app/selection_view.py)
    selection = param.Parameter(default=None, doc="Last WVIC ranking (SelectionResult).")
    show_intervals = param.Boolean(default=False, doc="Show 95% intervals and the J-test.")
    # messages
    error = param.String(default="", doc="Last error, in words (empty when fine).")
    notice = param.String(default="", doc="Information (not an error), e.g. a URL fallback.")
    revision = param.Integer(default=0, doc="Increases after every change the views draw.")

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        self._log: Any = None
        self._wv_cache: dict[tuple[str, float, bool], eg.WaveletVariance] = {}
        self._lock = threading.Lock()
        self.wv_computations = 0  # how many WVs this session computed (for tests/diagnostics)
        self._inference: dict[int, Inference] = {}  # per fit (id of the GMWMResult)

    # ---------------------------------------------------------------------------------
    # helpers
    # ---------------------------------------------------------------------------------
    @property
    def log(self) -> Any:
        """The loaded ``ImuLog`` (None before the first load)."""
        return self._log

    def report_error(self, message: str) -> bool:
        """Show ``message`` as the error of the page (state otherwise unchanged); False."""
        self.param.update(error=message, revision=self.revision + 1)
        return False

    _fail = report_error

    def _guard(self, action: str, fn: Callable[[], bool]) -> bool:
        """Run ``fn``; any exception becomes a message in :attr:`error` (never raised)."""
        try:
            return fn()
        except (ValueError, KeyError, OSError, TypeError, IndexError) as e:
            return self._fail(f"{action}: {_message(e)}")
        except Exception as e:  # the UI must keep working
            log.exception("unexpected error while %s", action)
            return self._fail(f"{action}: unexpected {type(e).__name__}: {e}")

    # ---------------------------------------------------------------------------------
    # reading (thread-safe: no parameter changes)
    # ---------------------------------------------------------------------------------
    @staticmethod
    def read(
        source: str,
        *,
        path: str | os.PathLike[str] | None = None,
        data: bytes | str | None = None,
        filename: str = "",
        segment: str | None = None,
    ) -> LoadedData:
        """Read a log from a source. Heavy; touches no state, safe in a worker thread.

        Parameters
        ----------
        source : {"demo", "upload", "path"}
            The bundled demo, uploaded bytes (``data`` + ``filename``), or a server ``path``.

        Raises
        ------
        ValueError
            Missing/unreadable file or a file the loader rejects (message says why).
        """
        t0 = time.perf_counter()
        if source == "demo":
            p = demo_path()
            if not p.exists():
                raise ValueError(
                    f"the demo log {p} is missing: run `python data/make_demo.py` "
                    "in the repository, or load a file"
                )
            lg = read_log(p)
            out = LoadedData(lg, "demo", p.name, str(p))
        elif source == "path":
            if not path or not str(path).strip():
                raise ValueError("no path given: type the path of a log file on the server")
            p = Path(str(path).strip()).expanduser()
            check_path(p)  # only the configured folders (gmwm-app --data-dir), checked first
            if not p.exists():  # so that nothing is said about files outside them
                raise ValueError(f"no such file on the server: {p}")
            if p.is_dir():
                raise ValueError(f"{p} is a folder: give the path of a log file")
            out = LoadedData(read_log(p, segment=segment), "path", p.name, str(p))
        elif source == "upload":
            if data is None or len(data) == 0:
                raise ValueError(f"the uploaded file {filename or ''} is empty".replace("  ", " "))
            if isinstance(data, str):
                data = data.encode("utf-8")
            check_upload_size(len(data), filename)
            name = Path(filename or "upload.csv").name
            suffix = "".join(Path(name).suffixes[-2:]) or ".csv"
            fd, tmp = tempfile.mkstemp(prefix="gmwm_upload_", suffix=suffix)
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(data)
                try:
                    lg = read_log(tmp, segment=segment)
                except ValueError as e:  # name the user's file, not the temporary one
                    raise ValueError(
                        str(e).replace(tmp, name).replace(Path(tmp).name, name)
                    ) from None
            finally:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
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
        out.elapsed_s = time.perf_counter() - t0
        if segment:
            out.load["segment"] = segment
        return out

    @staticmethod
    def precompute(
        loaded: LoadedData,
        channel: str | None = None,
        fs: float | None = None,
        robust: bool = False,
    ) -> None:
        """Compute the WV of one channel of ``loaded`` into its cache (worker-thread safe).

        Errors are not raised here; :meth:`install` reports them.
        """
        lg = loaded.log
        names = _channel_names(lg)
        if not names:
            return
        ch = channel if channel in names else names[0]
        try:
            f = float(fs) if fs else float(lg.fs)
            if _wv_from_cache(loaded.wv_cache, ch, f, robust) is None:
                AppState._store(loaded.wv_cache, ch, f, robust, _compute_wv(lg, ch, f, robust))
                loaded.computations += 1
        except Exception:  # reported when installed
            pass

    def warm(
        self, channel: str | None = None, fs: float | None = None, robust: bool | None = None
    ) -> None:
        """Compute a WV of the current log into the cache (worker-thread safe, no state change).

        :meth:`select_channel`, :meth:`set_fs` and :meth:`set_robust` then find it cached.
        """
        with self._lock:  # the log and its cache, together (a new log brings a new cache)
            lg, cache = self._log, self._wv_cache
        if lg is None:
            return
        ch = channel or self.channel
        f = float(fs or self.fs or lg.fs)
        rob = self.robust if robust is None else bool(robust)
        try:
            with self._lock:
                if _wv_from_cache(cache, ch, f, rob) is not None:
                    return
            wv = _compute_wv(lg, ch, f, rob)
            with self._lock:
                self._store(cache, ch, f, rob, wv)
                self.wv_computations += 1
        except Exception:  # reported by the state change that follows
            pass

    # ---------------------------------------------------------------------------------
    # WV cache
    # ---------------------------------------------------------------------------------
    @staticmethod
    def _store(cache: dict, ch: str, fs: float, robust: bool, wv: eg.WaveletVariance) -> None:
        cache[(ch, fs, robust)] = wv
        if robust and wv.classical is not None:
            cache.setdefault((ch, fs, False), wv.classical)

    def get_wv(self, channel: str, fs: float, robust: bool) -> eg.WaveletVariance:
        """The WV of a channel: from the cache, or computed once and cached.

        Raises
        ------
        ValueError
            Channel unknown, series unusable (NaN, too short), or a robust WV asked of a
            summary file.
        """
        with self._lock:
            wv = _wv_from_cache(self._wv_cache, channel, fs, robust)
            if wv is not None:
                self._wv_cache[(channel, fs, robust)] = wv
                return wv
        wv = _compute_wv(self._log, channel, fs, robust)
        with self._lock:
            self._store(self._wv_cache, channel, fs, robust, wv)
            self.wv_computations += 1
        return wv

    # ---------------------------------------------------------------------------------
    # data actions
    # ---------------------------------------------------------------------------------
    def load_demo(self) -> bool:
        """Load the bundled demo log (keeps the model; refits it on the new WV)."""
        return self._guard("Could not load the demo", lambda: self.install(self.read("demo")))

    def load_path(self, path: str | os.PathLike[str]) -> bool:
        """Load a log from a path on the server."""
        return self._guard(
            f"Could not load {path}", lambda: self.install(self.read("path", path=path))
        )

    def load_upload(self, data: bytes | str | None, filename: str) -> bool:
        """Load an uploaded file (its bytes and its name; the suffix picks the format)."""
        return self._guard(
            f"Could not load the uploaded file {filename}",
            lambda: self.install(self.read("upload", data=data, filename=filename)),
        )

    def install(
        self,
        loaded: LoadedData,
        *,
        channel: str | None = None,
        fs: float | None = None,
        robust: bool | None = None,
    ) -> bool:
        """Make a read log the session's data; select a channel, compute (or reuse) its WV.

        The channel is ``channel`` if given, else the current one if the new log has it, else
        the first. The model is kept and refitted (an empty model becomes the form of a teaching
        scenario's true model); if it does not fit the new data it is cleared (with a
        message). Nothing changes if the new data cannot be used.
        """

        def run() -> bool:
            lg = loaded.log
            names = _channel_names(lg)
            if not names:
                raise ValueError(f"{loaded.name} has no usable channel")
            msgs = []
            ch = channel if channel is not None else self.channel
            if ch not in names:
                if channel is not None:
                    msgs.append(
                        f"channel {channel!r} is not in {loaded.name}; "
                        f"showing {names[0]} (channels: {', '.join(names)})"
                    )
                ch = names[0]
            f_file = float(lg.fs)
            f = f_file if fs is None else _check_fs(fs)
            rob = self.robust if robust is None else bool(robust)
            if lg.is_summary and rob and not _summary_has_robust(lg, ch):
                msgs.append(
                    f"{loaded.name} holds a classical WV summary only; "
                    "the robust WV needs the raw log"
                )
                rob = False
            cache = dict(loaded.wv_cache)
            wv = _wv_from_cache(cache, ch, f, rob)
            computed = 0
            if wv is None:
                wv = _compute_wv(lg, ch, f, rob)
                computed = 1
            self._store(cache, ch, f, rob, wv)
            model = self.model
            if loaded.source == "scenario" and not len(model):
                # a teaching scenario starts with the form of its true model
                from engine.teaching import SCENARIOS

                if loaded.path in SCENARIOS:
                    model = SCENARIOS[loaded.path].model.cleared()
            fit = self._fit_or_none(wv, model)
            new_model, result = (
                (model, fit) if isinstance(fit, eg.GMWMResult) else (eg.Model(), None)
            )
            if fit is not None and not isinstance(fit, eg.GMWMResult):
                msgs.append(f"the model {model.spec()} was cleared: {fit}")
            with self._lock:
                self._log = lg
                self._wv_cache = cache
                self.wv_computations += computed + loaded.computations
            fs_src = "user" if fs is not None and f != f_file else _fs_source(lg)
            self.param.update(
                source=loaded.source,
                path=loaded.path if loaded.source in ("path", "scenario") else "",
                filename=loaded.name,
                channels=list(names),
                channel=ch,
                fs=f,
                fs_source=fs_src,
                robust=rob,
                is_summary=bool(lg.is_summary),
                wv=wv,
                **self._data_info(lg, ch, wv),
                **self._model_update(new_model, result),
                error="; ".join(msgs),
                notice="; ".join(lg.meta.get("notes", []) or []),
                revision=self.revision + 1,
            )
            return not msgs

        return self._guard(f"Could not use {loaded.name}", run)

    def _data_info(self, lg: Any, ch: str, wv: eg.WaveletVariance) -> dict[str, Any]:
        n = int(wv.n if lg.is_summary else np.size(lg.channels[ch]))
        return {"n": n, "duration_s": n / float(wv.fs), "unit": _unit_of(lg, ch)}

    def select_channel(self, channel: str) -> bool:
        """Show another channel: its cached WV (computed on first use) and a refit."""

        def run() -> bool:
            if self._log is None:
                raise ValueError("load a log first")
            if channel not in self.channels:
                raise ValueError(
                    f"there is no channel {channel!r}; channels: {', '.join(self.channels)}"
                )
            rob = self.robust
            msgs = []
            if self.is_summary and rob and not _summary_has_robust(self._log, channel):
                rob = False
                msgs.append("this summary file has no robust WV; showing the classical one")
            wv = self.get_wv(channel, float(self.fs), rob)
            return self._switch_wv(wv, channel=channel, robust=rob, msgs=msgs)

        return self._guard(f"Could not show channel {channel}", run)

    def set_fs(self, fs: float) -> bool:
        """Use another sampling frequency (Hz); the WV is re-labelled, not recomputed."""

        def run() -> bool:
            f = _check_fs(fs)
            if self._log is None:
                raise ValueError("load a log first")
            wv = self.get_wv(self.channel, f, self.robust)
            return self._switch_wv(
                wv, fs=f, fs_source="user" if f != float(self._log.fs) else _fs_source(self._log)
            )

        return self._guard("Could not set the sampling frequency", run)

    def set_robust(self, robust: bool) -> bool:
        """Switch between the classical and the robust (biweight) WV."""

        def run() -> bool:
            if self._log is None:
                self.param.update(robust=bool(robust))
                return True
            if self.is_summary and robust and not _summary_has_robust(self._log, self.channel):
                raise ValueError(
                    "this file holds a classical WV summary only; the robust WV needs the raw log"
                )
            wv = self.get_wv(self.channel, float(self.fs), bool(robust))
            return self._switch_wv(wv, robust=bool(robust))

        return self._guard("Could not switch the robust WV", run)

    def _switch_wv(
        self, wv: eg.WaveletVariance, msgs: list[str] | None = None, **changes: Any
    ) -> bool:
        """Install a new WV (channel/fs/robust change) and refit the model on it."""
        msgs = list(msgs or [])
        fit = self._fit_or_none(wv, self.model)
        if fit is None or isinstance(fit, eg.GMWMResult):
            model, result = self.model, fit
        else:
            msgs.append(f"the model {self.model.spec()} was cleared: {fit}")
            model, result = eg.Model(), None
        ch = changes.get("channel", self.channel)
        self.param.update(
            wv=wv,
            **changes,
            **self._data_info(self._log, ch, wv),
            **self._model_update(model, result),
            error="; ".join(msgs),
            revision=self.revision + 1,
        )
        return not msgs

    # ---------------------------------------------------------------------------------
    # model actions
    # ---------------------------------------------------------------------------------
    def _fit_or_none(
        self, wv: eg.WaveletVariance, model: eg.Model, start: eg.Model | None = None
    ) -> eg.GMWMResult | str | None:
        """Fit ``model`` (structure only, so a spec always gives the same fit) or say why not."""
        if len(model) == 0:
            return None
        try:
            return eg.fit_gmwm(
                wv, start if start is not None else model.cleared(), weights=self.weights
            )
        except (eg.ModelError, eg.FitError, ValueError) as e:
            return _message(e)

    def _model_update(self, model: eg.Model, result: eg.GMWMResult | None) -> dict[str, Any]:
        shown = result.model if result is not None else model
        values = {k: v for k, v in shown.values().items() if v is not None}
        return {"model": shown, "result": result, "whatif_values": values}

    def set_model(self, model: eg.Model | str) -> bool:
        """Replace the model (a Model or a spec like ``"WN+RW+2*GM"``) and refit.

        An empty spec clears the model. An unidentifiable model leaves everything as it was
        and sets :attr:`error`.
        """

        def run() -> bool:
            m = (
                eg.Model()
                if isinstance(model, str) and not model.strip()
                else eg.parse_model(model)
            )
            return self._apply_model(m)

        return self._guard("Could not set the model", run)

    def _apply_model(self, m: eg.Model, start: eg.Model | None = None) -> bool:
        if len(m) and self.wv is None:
            raise ValueError("load data before building a model")
        if len(m):
            m.validate(self.wv.n_levels)
        fit = self._fit_or_none(self.wv, m, start) if self.wv is not None else None
        if isinstance(fit, str):
            return self._fail(f"Cannot fit {m.spec()}: {fit}")
        self.param.update(**self._model_update(m, fit), error="", revision=self.revision + 1)
        return True

    def add_process(self, code: str) -> bool:
        """Add one process (``"WN"``, ``"QN"``, ``"RW"``, ``"DR"``, ``"AR1"``, ``"GM"``), refit.

        Refits on the cached WV. A model that cannot be identified (a second WN, AR1 mixed
        with GM, more parameters than WV levels) is refused with a message.
        """

        def run() -> bool:
            c = str(code).strip().upper()
            if c not in PROCESS_CODES:
                raise ValueError(f"unknown process {code!r}; use one of {', '.join(PROCESS_CODES)}")
            new = eg.Model(self.model.processes + (eg.parse_model(c).processes[0],))
            try:
                new.validate(None if self.wv is None else self.wv.n_levels)
            except eg.ModelError as e:
                return self._fail(f"Cannot add {c}: {e}")
            return self._apply_model(new)

        return self._guard(f"Could not add {code}", run)

    def remove_process(self, index: int) -> bool:
        """Remove the process at ``index`` (position in :attr:`model`, i.e. in the labels)."""

        def run() -> bool:
            procs = list(self.model.processes)
            if not 0 <= index < len(procs):
                raise IndexError(
                    f"there is no process number {index + 1} (the model has {len(procs)})"
                )
            del procs[index]
            return self._apply_model(eg.Model(tuple(procs)))

        return self._guard("Could not remove the process", run)

    def clear_model(self) -> bool:
        """Remove every process: only the empirical WV is shown."""
        return self.set_model("")

    # ---------------------------------------------------------------------------------
    # what-if
    # ---------------------------------------------------------------------------------
    def set_whatif(self, on: bool) -> bool:
        """Turn the what-if mode on (curves follow the sliders) or off (curves show the fit)."""
        vals = dict(self.whatif_values)
        if on:
            vals = {**self._default_values(), **vals}
        self.param.update(whatif=bool(on), whatif_values=vals, revision=self.revision + 1)
        return True

    def set_whatif_value(self, name: str, value: float) -> bool:
        """Set one what-if parameter (unique name like ``GM_1.beta``); curves move, no fit."""

        def run() -> bool:
            if name not in self.model.param_names:
                raise ValueError(f"the model has no parameter {name!r}")
            v = float(value)
            if not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {value}")
            self.whatif_model({name: v})  # validates the value (e.g. beta > 0)
            self.param.update(
                whatif_values={**self.whatif_values, name: v}, error="", revision=self.revision + 1
            )
            return True

        return self._guard("Could not set the what-if value", run)

    def reset_whatif(self) -> bool:
        """What-if values back to the fitted ones."""
        self.param.update(
            whatif_values=self._model_update(self.model, self.result)["whatif_values"]
            or self._default_values(),
            error="",
            revision=self.revision + 1,
        )
        return True

    def fit_from_whatif(self) -> bool:
        """Refit, using the what-if values as extra starting values."""
        return self._guard(
            "Could not fit",
            lambda: self._apply_model(self.model.cleared(), start=self.whatif_model()),
        )

    def _default_values(self) -> dict[str, float]:
        """Fitted values where known, else rough guesses read off the WV."""
        vals = {k: v for k, v in self.model.values().items() if v is not None}
        if self.wv is None:
            return vals
        for name, v in _guess_values(self.model, self.wv).items():
            vals.setdefault(name, v)
        return vals

    def whatif_model(self, override: Mapping[str, float] | None = None) -> eg.Model:
        """The model with the what-if values (guesses where none), every value set."""
        vals = {**self._default_values(), **self.whatif_values, **(override or {})}
        procs = []
        for lab, p in zip(self.model.labels, self.model.processes, strict=True):
            procs.append(p.with_values(**{n: vals[f"{lab}.{n}"] for n in p.param_names}))
        return eg.Model(tuple(procs))

    def slider_specs(self) -> list[SliderSpec]:
        """One log-scaled slider per parameter, 3 decades either side of its current value."""
        if not len(self.model) or self.wv is None:
            return []
        vals = {**self._default_values(), **self.whatif_values}
        guesses = _guess_values(self.model, self.wv)
        out = []
        for lab, p in zip(self.model.labels, self.model.processes, strict=True):
            for name in p.param_names:
                full = f"{lab}.{name}"
                v = vals.get(full)
                transform = "log10(1-x)" if (p.code, name) == ("AR1", "phi") else "log10"
                if v is None or v == 0 or (transform == "log10(1-x)" and v >= 1):
                    v = guesses[full]
                x = SliderSpec.position_of(transform, v)
                lo, hi = x - 3.0, x + 3.0
                if transform == "log10(1-x)":
                    hi = min(hi, 0.0)  # phi >= 0
                    lo = min(lo, hi - 3.0)
                out.append(
                    SliderSpec(
                        full,
                        lab,
                        name,
                        eg.param_unit(p.code, name, self.unit),
                        transform,
                        lo,
                        hi,
                        x,
                    )
                )
        return out

    # ---------------------------------------------------------------------------------
    # what the views draw
    # ---------------------------------------------------------------------------------
    def display_model(self) -> eg.Model | None:
        """The model whose curves are drawn: the what-if one, the fit, or None."""
        if not len(self.model) or self.wv is None:
            return None
        if self.whatif:
            try:
                return self.whatif_model()
            except (ValueError, KeyError):
                return self.result.model if self.result is not None else None
        return self.result.model if self.result is not None else None

    def display_objective(self) -> float | None:
        """GMWM objective of the drawn model (the fit's, or the what-if values')."""
        m = self.display_model()
        if m is None:
            return None
        if not self.whatif and self.result is not None:
            return float(self.result.objective)
        omega, _ = eg.weight_matrix(self.wv, self.weights)
        r = self.wv.variance - m.wv(self.wv.tau_samples, self.wv.fs)
        return float(r @ omega @ r)

    def warnings(self) -> list[str]:
        """Warnings about the fit: parameters at a bound, the fit's own warnings (an AR1/GM
        faster than one sample), no convergence."""
        res = self.result
        if res is None:
            return []
        out = []
        if res.at_bound:
            out.append(
                f"at a bound: {', '.join(res.at_bound)} (the model may be larger than "
                "the data support; try removing that process)"
            )
        out += list(res.warnings)  # e.g. an AR1/GM faster than one sample
        if not res.converged:
            out.append(f"not converged: {res.message}")
        return out

    # ---------------------------------------------------------------------------------
    # model selection and inference (compute_* are worker-thread safe: no parameter change)
    # ---------------------------------------------------------------------------------
    def compute_ranking(
        self, spec: str, *, progress: Callable[[int, int], None] | None = None
    ) -> tuple[eg.WaveletVariance, Any]:
        """Rank models by WVIC on the current WV: every sub-model of a maximal model
        (``"3*GM+WN+QN+RW+DR"``) or candidates separated by commas (``"WN+RW, GM+WN"``)."""
        from engine.inference import rank_models

        wv = self.wv
        if wv is None:
            raise ValueError("load data before ranking models")
        parts = [p.strip() for p in (spec or "").split(",") if p.strip()]
        if not parts:
            raise ValueError(
                "type a maximal model (e.g. 3*GM+WN+QN+RW+DR) or candidate "
                "models separated by commas"
            )
        try:
            if len(parts) == 1:
                sel = rank_models(wv, max_model=parts[0], weights=self.weights, progress=progress)
            else:
                sel = rank_models(wv, parts, weights=self.weights, progress=progress)
        except (eg.ModelError, eg.FitError) as e:
            raise ValueError(_message(e)) from None
        return wv, sel

    def install_ranking(self, out: tuple[eg.WaveletVariance, Any]) -> bool:
        """Show a ranking from :meth:`compute_ranking` (refused if the data changed since)."""
        wv, sel = out
        if wv is not self.wv:
            return self._fail("The data changed while ranking: rank again")
        self.param.update(selection=sel, error="", revision=self.revision + 1)
        return True

    def rank(self, spec: str, *, progress: Callable[[int, int], None] | None = None) -> bool:
        """:meth:`compute_ranking` then :meth:`install_ranking` (synchronous)."""
        return self._guard(
            "Could not rank the models",
            lambda: self.install_ranking(self.compute_ranking(spec, progress=progress)),
        )

    def compute_inference(self, result: eg.GMWMResult) -> Inference:
        """95% asymptotic intervals and the J-test of a fit (worker-thread safe)."""
        from engine.inference import j_test, param_intervals

        try:
            intervals = param_intervals(result, method="asymptotic", level=0.95)
        except (eg.FitError, np.linalg.LinAlgError) as e:
            raise ValueError(f"no intervals for {result.model.spec()}: {_message(e)}") from None
        try:
            return Inference(result, intervals, j_test(result), "")
        except (eg.FitError, ValueError, np.linalg.LinAlgError) as e:
            return Inference(result, intervals, None, _message(e))

    def install_inference(self, inf: Inference) -> bool:
        """Cache intervals and J-test of a fit (at most 32 fits kept) and redraw."""
        if len(self._inference) >= 32:
            self._inference.pop(next(iter(self._inference)))
        self._inference[id(inf.result)] = inf
        self.param.update(revision=self.revision + 1)
        return True

    def inference(self, result: eg.GMWMResult | None = None) -> Inference | None:
        """The cached intervals and J-test of a fit (the current one by default), or None."""
        res = self.result if result is None else result
        inf = self._inference.get(id(res)) if res is not None else None
        return inf if inf is not None and inf.result is res else None

    def set_show_intervals(self, on: bool) -> bool:
        """Show (or hide) the interval columns and the goodness-of-fit badge."""
        self.param.update(show_intervals=bool(on), revision=self.revision + 1)
        return True

    # ---------------------------------------------------------------------------------
    # URL round trip and export
    # ---------------------------------------------------------------------------------
    def to_query(self) -> dict[str, str]:
        """The shareable state as URL query parameters (all strings).

        E.g. ``{"source": "demo", "channel": "gyro_x", "fs": "100", "robust": "0",
        "model": "2*GM+WN+RW"}``; ``path`` is added for a server file.
        """
        q = {"source": self.source}
        if self.source == "path" and self.path:
            q["path"] = self.path
        if self.source == "scenario" and self.path:
            q["scenario"] = self.path
        if self.channel:
            q["channel"] = self.channel
        if self.fs:
            q["fs"] = f"{self.fs:.12g}"
        q["robust"] = "1" if self.robust else "0"
        if len(self.model):
            q["model"] = self.model.spec()
        return q

    def parse_query(self, query: Mapping[str, Any]) -> dict[str, Any]:
        """Read URL query parameters (strings or lists of strings) into settings.

        Returns ``{"source", "path", "channel", "fs", "robust", "model", "problems"}``;
        unreadable values are left out and described in ``problems``.
        """
        q = {k: (v[-1] if isinstance(v, (list, tuple)) and v else v) for k, v in query.items()}
        q = {k: (v.decode() if isinstance(v, bytes) else str(v)) for k, v in q.items()}
        out: dict[str, Any] = {"problems": []}
        src = q.get("source", "").strip().lower()
        if src == "path" or (not src and q.get("path")):
            out["source"], out["path"] = "path", q.get("path", "")
        elif src == "scenario":
            out["source"], out["path"] = "scenario", q.get("scenario", "")
        elif src == "upload":
            out["source"] = None  # an upload cannot be replayed from a link
            out["problems"].append(
                "the link refers to an uploaded file, which is not part of "
                "the link: upload it again"
            )
        elif src in ("", "demo"):
            out["source"] = "demo" if src == "demo" else None
        else:
            out["source"] = None
            out["problems"].append(f"unknown source {src!r} in the link (use demo or path)")
        if q.get("channel"):
            out["channel"] = q["channel"].strip()
        if q.get("fs"):
            try:
                out["fs"] = _check_fs(float(q["fs"]))
            except ValueError:
                out["problems"].append(f"fs={q['fs']!r} in the link is not a positive number of Hz")
        if "robust" in q:
            r = q["robust"].strip().lower()
            if r in ("1", "true", "yes", "on"):
                out["robust"] = True
            elif r in ("0", "false", "no", "off", ""):
                out["robust"] = False
            else:
                out["problems"].append(f"robust={q['robust']!r} in the link is not 0 or 1")
        if "model" in q:
            out["model"] = q["model"].strip()
        return out

    def prepare_query(
        self, query: Mapping[str, Any], default_source: str = "demo", default_path: str = ""
    ) -> PreparedQuery:
        """Read the data a URL query asks for and precompute its WV (worker-thread safe).

        A server path that cannot be read falls back to the demo (with a message).
        """
        s = self.parse_query(query)
        problems = list(s["problems"])
        src = s.get("source") or default_source
        path = s.get("path") if s.get("source") in ("path", "scenario") else default_path
        loaded = None
        try:
            loaded = self.read(src, path=path)
        except ValueError as e:
            problems.append(_message(e))
            if src != "demo":
                try:
                    loaded = self.read("demo")
                    problems.append("showing the demo instead")
                except ValueError as e2:
                    problems.append(_message(e2))
        if loaded is not None:
            self.precompute(loaded, s.get("channel"), s.get("fs"), bool(s.get("robust", False)))
        return PreparedQuery(s, loaded, problems)

    def from_query(
        self,
        query: Mapping[str, Any],
        prepared: PreparedQuery | None = None,
        default_source: str = "demo",
        default_path: str = "",
    ) -> bool:
        """Restore a session from URL query parameters (see :meth:`to_query`).

        Parameters
        ----------
        query : mapping
            Query parameters, e.g. ``pn.state.location.query_params`` (values may be lists).
        prepared : PreparedQuery, optional
            The data already read by :meth:`prepare_query` (in a worker thread).
        default_source, default_path
            Data to load when the query names none (the demo, or the app's FILE argument).

        Returns
        -------
        bool
            True when everything in the query could be honoured; otherwise :attr:`error`
            lists what could not (the rest is applied).
        """
        if prepared is None:
            prepared = self.prepare_query(query, default_source, default_path)
        s = prepared.settings
        problems = list(prepared.problems)
        if prepared.loaded is not None:
            self.install(
                prepared.loaded, channel=s.get("channel"), fs=s.get("fs"), robust=s.get("robust")
            )
            if self.error:
                problems.append(self.error)
        elif s.get("robust") is not None:
            self.param.update(robust=s["robust"])
        if s.get("model") is not None and (s["model"] or len(self.model)):
            if not self.set_model(s["model"]):
                problems.append(self.error)
        if problems:
            self.param.update(error="; ".join(dict.fromkeys(problems)), revision=self.revision + 1)
            return False
        return True

    def data_info(self) -> dict[str, Any]:
        """Description of the data (for exports and the info panel)."""
        return {
            "source": self.source,
            "file": self.filename,
            "path": self.path,
            "channel": self.channel,
            "channels": list(self.channels),
            "fs_hz": self.fs,
            "fs_source": self.fs_source,
            "n_samples": self.n,
            "duration_s": self.duration_s,
            "unit": self.unit,
            "robust_wv": self.robust,
            "wv_summary_file": self.is_summary,
        }

    def export_dict(self) -> dict[str, Any]:
        """JSON-ready export: the fit (``GMWMResult.to_dict()``), datasheet values, data info.

        Without a fit, the empirical WV alone (``"fit": null``).
        """
        out: dict[str, Any] = {
            "app": "gmwm-app",
            "query": self.to_query(),
            "data": self.data_info(),
        }
        if self.result is not None:
            out["fit"] = self.result.to_dict()
            out["datasheet"] = eg.datasheet(self.result.model, float(self.fs), self.unit)
            out["warnings"] = self.warnings()
        else:
            out["fit"] = None
            out["wv"] = None if self.wv is None else self.wv.to_dict()
        if self.whatif and len(self.model):
            m = self.whatif_model()
            out["whatif"] = {
                "model_values": m.spec(values=True),
                "objective": self.display_objective(),
            }
        return out

    def export_json(self) -> str:
        """:meth:`export_dict` as indented JSON text."""
        return json.dumps(self.export_dict(), indent=2, allow_nan=False, default=_json_default)

    def export_filename(self) -> str:
        """A file name for the JSON export, e.g. ``gmwm_demo_imu_gyro_x_2GM+WN+RW.json``."""
        stem = Path(self.filename or "data").stem
        spec = self.model.spec().replace("*", "") or "wv"
        return f"gmwm_{stem}_{self.channel or 'none'}_{spec}.json"


# ---------------------------------------------------------------------------------------------
# module helpers
# ---------------------------------------------------------------------------------------------
def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"cannot export {type(o).__name__} to JSON")


def _message(e: BaseException) -> str:
    """An exception as a sentence (KeyError's quotes removed)."""
    if isinstance(e, KeyError) and e.args:
        return str(e.args[0])
    return str(e) or type(e).__name__


def _check_fs(fs: Any) -> float:
    try:
        f = float(fs)
    except (TypeError, ValueError):
        raise ValueError(f"fs must be a positive number of Hz, got {fs!r}") from None
    if not math.isfinite(f) or f <= 0:
        raise ValueError(f"fs must be a positive number of Hz, got {fs!r}")
    return f


def _channel_names(lg: Any) -> list[str]:
    return list(lg.names)


def _summary_has_robust(lg: Any, ch: str) -> bool:
    wv = lg.wv.get(ch)
    return wv is not None and bool(wv.robust)


def _fs_source(lg: Any) -> str:
    return str(getattr(lg, "fs_source", "file") or "file")


def _unit_of(lg: Any, ch: str) -> str:
    units = getattr(lg, "units", None) or {}
    u = units.get(ch, "")
    if not u and lg.is_summary and ch in lg.wv:
        u = lg.wv[ch].unit
    return str(u or "")


def _compute_wv(lg: Any, ch: str, fs: float, robust: bool) -> eg.WaveletVariance:
    """WV of one channel of a log (a summary file's stored WV, re-labelled to ``fs``)."""
    if lg is None:
        raise ValueError("load a log first")
    if lg.is_summary:
        if ch not in lg.wv:
            raise ValueError(f"there is no channel {ch!r} in the summary file")
        wv = lg.wv[ch]
        if robust and not wv.robust:
            raise ValueError(
                "this file holds a classical WV summary only; the robust WV needs the raw log"
            )
        if not robust and wv.robust:
            if wv.classical is None:
                raise ValueError("this summary file holds a robust WV only")
            wv = wv.classical
        return wv if wv.fs == fs else _retag_fs(wv, fs)
    if ch not in lg.channels:
        raise ValueError(f"there is no channel {ch!r}; channels: {', '.join(lg.channels)}")
    x = lg.channels[ch]
    try:
        return eg.wavelet_variance(x, fs=fs, robust=robust, unit=_unit_of(lg, ch))
    except (ValueError, TypeError) as e:
        raise ValueError(f"channel {ch}: {_message(e)}") from None


def _guess_values(model: eg.Model, wv: eg.WaveletVariance) -> dict[str, float]:
    """Rough starting values read off the WV (for what-if sliders before a fit).

    AR1/GM correlation times are spread geometrically over the scales; each variance-like
    parameter is half the largest value whose curve stays below the empirical WV.
    """
    tau = wv.tau_samples.astype(float)
    nl = [i for i, p in enumerate(model.processes) if p.nonlinear is not None]
    tcs = np.geomspace(tau[-1] / 4, max(tau[0], 2.0), len(nl)) if nl else []
    out: dict[str, float] = {}
    for k, i in enumerate(nl):
        lab, p = model.labels[i], model.processes[i]
        phi = math.exp(-1.0 / float(tcs[k]))
        if p.code == "GM":
            out[f"{lab}.beta"] = -math.log(phi) * wv.fs
        else:
            out[f"{lab}.phi"] = phi
    pos = wv.variance > 0
    for lab, p in zip(model.labels, model.processes, strict=True):
        if p.nonlinear is not None:
            nlv = math.exp(-out[f"{lab}.beta"] / wv.fs) if p.code == "GM" else out[f"{lab}.phi"]
        else:
            nlv = None
        basis = np.asarray(p.basis(tau, wv.fs, nlv), float)
        ok = pos & (basis > 0)
        h = 0.5 * float(np.min(wv.variance[ok] / basis[ok])) if np.any(ok) else 1e-12
        h = max(h, 1e-300)
        name = p.param_names[-1] if p.nonlinear else p.param_names[0]
        out[f"{lab}.{name}"] = math.sqrt(h) if p.code == "DR" else h
    return out
