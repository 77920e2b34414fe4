"""Session state of the GMWM app: data, channel, cached wavelet variance, model and fit.

No widgets here: :class:`AppState` is a plain ``param.Parameterized`` that the views read and
the widgets drive, so it can be tested without a browser. Data flows one way::

    file -> ImuLog -> WaveletVariance (computed once per channel, cached) -> fit_gmwm -> result

Changing the model refits on the cached WV (:class:`gmwm_app.wv_cache.WVCache`); it never
recomputes the WV. Every public action returns ``True`` on success; on failure it sets
:attr:`AppState.error` to a sentence that says what went wrong and how to fix it (and logs
it), and leaves the previous (valid) state in place. Each action changes its parameters in one
``param.update``, so that a view depending on several of them draws once.

The actions live with their ideas: the data and model actions here, the what-if mode in
:mod:`gmwm_app.whatif`, the URL round trip in :mod:`gmwm_app.query`, ranking and inference in
:mod:`gmwm_app.selection_state`, the JSON export in :mod:`gmwm_app.fit_export` (mixins of
:class:`AppState`).

Heavy work (reading a file, computing a WV) is split from the state change so that the app
can run it in a worker thread: :meth:`AppState.read` and :meth:`AppState.precompute` /
:meth:`AppState.warm` touch no parameter, :meth:`AppState.install`, :meth:`AppState.select_channel`
... then find the WV in the cache and are fast.
"""

from __future__ import annotations

import logging
import math
import os
import threading
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path
from typing import Any, cast

import numpy as np
import param

import engine as eg
from engine.inference.temperature import find_temperature
from engine.io import ImuLog
from engine.io import drop_warmup as drop_warmup_of
from gmwm_app.boundary import EXPECTED
from gmwm_app.data import (
    COMPENSATION,
    LoadedData,
    channel_names,
    check_fs,
    compensation_mode,
    compute_wv,
    fs_source,
    is_compensated,
    log_check_line,
    message_of,
    precompute,
    read_source,
    summary_has_robust,
    temperature_line,
    temperature_unusable,
    unit_of,
    warmup_start,
    wv_matrix_of,
)
from gmwm_app.fit_export import ExportMixin
from gmwm_app.query import QueryMixin
from gmwm_app.selection_state import Inference, Offload, SelectionMixin
from gmwm_app.whatif import SliderSpec, WhatIfMixin
from gmwm_app.wv_cache import WVCache, WVKey, wv_from_cache

__all__ = [
    "AppState",
    "WEIGHTS",
    "Inference",
    "PROCESS_CODES",
    "demo_path",
    "format_value",
    "state_param",
]

log = logging.getLogger(__name__)

#: Process codes in the order of the add buttons: the engine's processes, in its order.
PROCESS_CODES: tuple[str, ...] = tuple(eg.models.PROCESS_TYPES)

#: Readable names of the processes (for the process list): each process's own.
PROCESS_NAMES: dict[str, str] = {c: cls.display_name for c, cls in eg.models.PROCESS_TYPES.items()}

#: The GMWM weights a session can fit with (:func:`engine.fit_gmwm`'s ``weights``).
WEIGHTS: tuple[str, ...] = ("ci", "identity", "efficient")

#: Sources a session can load from.
SOURCES: tuple[str, ...] = ("demo", "upload", "path", "scenario")

#: The data choices a widget sets alone, each shown by the state itself
#: (:meth:`AppState._data_changed`): the channel and the robust WV by a WV job, fs at once.
DATA_CHOICES: tuple[str, ...] = ("channel", "fs", "robust")

#: How a front end computes a WV off its event loop with its progress shown:
#: ``wv_job(message, work, apply, fail)`` calls ``work(report)`` in a worker (``report(j, J)``
#: as level ``j`` of ``J`` is done), then ``apply(result)`` or ``fail(error)`` on the loop (the
#: app: :meth:`gmwm_app.jobs.Jobs.load` with ``progress``).
WVJob = Callable[
    [
        str,
        Callable[[Callable[[int, int], object]], Any],
        Callable[[Any], Any],
        Callable[[BaseException], Any],
    ],
    Any,
]


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
# the state
# ---------------------------------------------------------------------------------------------
class AppState(QueryMixin, WhatIfMixin, SelectionMixin, ExportMixin, param.Parameterized):
    """Everything one browser session knows: data, channel, WV, model, fit, what-if values.

    Parameters are set by the action methods (``load_*``, ``select_channel``, ``set_fs``,
    ``set_robust``, ``add_process``, ``remove_process``, ``set_model``, ``set_whatif_value``,
    ``from_query``), each change in one ``param.update`` (:meth:`_publish`): a view depends on
    the parameters it draws (``param.depends``/``pn.bind``) and redraws once per action.
    """

    # data
    source: param.Selector[str] = param.Selector(
        default="demo", objects=list(SOURCES), doc="Where the data came from."
    )
    path = param.String(
        default="",
        doc="Server path of the loaded file (source 'path'); "
        "the scenario key for source 'scenario'.",
    )
    filename = param.String(default="", doc="Name of the loaded file.")
    channels = param.List(default=[], item_type=str, doc="Channel names of the loaded log.")
    channel: param.Selector[str] = param.Selector(
        default="",
        objects=[""],
        check_on_set=True,
        label="Channel",
        doc="Selected channel, one of :attr:`channels` (its choices follow the loaded log; '' "
        "before one is). Set by its widget or a test alone, the state computes its WV as a "
        "job (:attr:`AppState.wv_job`) and shows it (:meth:`AppState._data_changed`).",
    )
    fs = param.Number(
        default=None,
        allow_None=True,
        bounds=(0.0, None),
        inclusive_bounds=(False, True),
        label="Sampling frequency fs [Hz]",
        doc="Sampling frequency (Hz). Set alone (by its widget), the WV is re-labelled; a value "
        ":meth:`AppState.set_fs` refuses is reported and the previous one put back.",
    )
    fs_source = param.String(default="", doc="Where fs came from: file, time column, user ...")
    n = param.Integer(default=0, doc="Samples of the selected channel.")
    duration_s = param.Number(default=0.0, doc="Duration of the selected channel (s).")
    unit = param.String(default="", doc="Unit of the selected channel.")
    is_summary = param.Boolean(default=False, doc="The file holds WV summaries, no raw data.")
    robust = param.Boolean(
        default=False,
        label="Robust WV (Tukey biweight, 60% efficiency), beside the classical one",
        doc="Robust (Tukey biweight) WV. Set alone (by its widget), the state computes it as a "
        "job (:attr:`AppState.wv_job`) and shows it.",
    )
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
    weights: param.Selector[str] = param.Selector(
        default="ci",
        objects=list(WEIGHTS),
        label="Weights",
        doc="GMWM weighting: 'ci' (the R default), 'identity' or 'efficient' (two-step, "
        "Omega = V^-1 with V from the first fit's model). Set by its widget, a URL or "
        ":meth:`AppState.set_weights`, it refits the model (:meth:`AppState._weights_changed`).",
    )
    # model selection and inference (see gmwm_app/selection_view.py)
    selection = param.Parameter(default=None, doc="Last WVIC ranking (SelectionResult).")
    show_intervals = param.Boolean(default=False, doc="Show 95% intervals and the J-test.")
    inferred = param.ClassSelector(
        class_=Inference,
        default=None,
        allow_None=True,
        doc="The intervals and J-test installed last (the views showing them depend on it).",
    )
    loads = param.Integer(
        default=0,
        doc="Data installs: a reload of the (shared) demo log is a new load, whose fits are "
        "new ones (e.g. the session panel's fits of other channels are forgotten).",
    )
    # messages
    error = param.String(default="", doc="Last error, in words (empty when fine).")
    notice = param.String(default="", doc="Information (not an error), e.g. a URL fallback.")
    log_check = param.String(
        default="",
        doc="What the log check (engine.io.qualify_log) found in the channel shown, one line; "
        "empty for a clean log or a WV summary.",
    )
    warmup_start = param.Integer(
        default=0,
        bounds=(0, None),
        doc="The first sample after the warm-up the log check found in the channel shown (of "
        "the mean or of the bias wander), 0 without one: what 'Drop the warm-up' keeps from.",
    )
    temperature = param.String(
        default="",
        doc="With a temperature channel beside the channel shown: its bias-temperature "
        "sensitivity with its interval, the compensation choice in force (for auto with "
        "its test's p-value) and whether the WV and the fit are of the compensated or the "
        "raw signal, one line; empty otherwise.",
    )
    compensate: param.Selector[str] = param.Selector(
        default="auto",
        objects=list(COMPENSATION),
        label="Temperature compensation",
        doc="When the channel shown has a temperature channel beside it, whether the WV "
        "fitted is that of its temperature-compensated signal (its bias-temperature relation "
        "taken out, engine.inference.temperature): auto, when the test of the relation "
        "rejects at 5 % (gmwm fit --temperature auto); always, whatever the test says "
        "(--temperature COLUMN); off, the raw signal's (--temperature none). No effect "
        "without one.",
    )
    temperature_channel = param.String(
        default="",
        doc="The temperature channel beside the channel shown ('' when none: the "
        "compensation switch is hidden).",
    )
    compensation_unavailable = param.String(
        default="",
        doc="Why the temperature channel beside the channel shown cannot compensate it, one "
        "phrase ('' when it can, or when there is none): the switch is then disabled.",
    )
    wv_raw = param.ClassSelector(
        class_=eg.WaveletVariance,
        default=None,
        allow_None=True,
        doc="While the channel shown is compensated: the WV of the raw (uncompensated) "
        "signal, drawn beside the fitted one; None otherwise.",
    )

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        self._log: ImuLog | None = None
        self._wv_cache = WVCache()  # of self._log (the two change together, under _lock)
        self._lock = threading.Lock()
        #: How a front end sends the redraws of one change together (the app: Panel's hold of
        #: the session's document, so that a click reaches the browser as one message, not one
        #: per part redrawn); a context manager factory, nothing by default.
        self.batch: Callable[[], AbstractContextManager[Any]] = nullcontext
        self.wvm_computations = 0  # WV/WCCV matrices computed (multi-channel view)
        self.wv_computations = 0  # how many WVs this session computed (for tests/diagnostics)
        self._inference: dict[int, Inference] = {}  # per fit (id of the GMWMResult)
        self._inference_pending: set[int] = set()  # ids of fits whose inference is running
        #: How a front end runs work off its event loop (:data:`Offload`; the app: its job
        #: runner); None runs it at once (tests, notebooks).
        self.offload: Offload | None = None
        #: How a front end computes a WV off its event loop with its progress shown
        #: (:data:`WVJob`; the app: its job runner's page load); None computes it at once.
        self.wv_job: WVJob | None = None
        self._reverting = False  # a refused choice (compensation, weights) is being put back
        self._publishing = False  # the state's own update is being made
        self._shown: dict[str, Any] = {n: getattr(self, n) for n in DATA_CHOICES}
        self.param.watch(self._compensate_changed, "compensate")
        self.param.watch(self._weights_changed, "weights")
        self.param.watch(self._data_changed, list(DATA_CHOICES))

    # ---------------------------------------------------------------------------------
    # helpers
    # ---------------------------------------------------------------------------------
    def wv_matrix(
        self, lg: ImuLog, channels: Sequence[str], fs: float
    ) -> tuple[eg.wv.WVMatrix, str]:
        """:func:`gmwm_app.data.wv_matrix_of` (of the temperature-compensated signals that
        the choice :attr:`compensate` compensates), cached in the session's WV cache while
        ``lg`` is the session's log (worker-thread safe; the last :data:`N_WV_MATRICES` kept).
        """
        comp = str(self.compensate)
        with self._lock:
            cache = self._wv_cache if self._log is lg else None
            hit = cache.matrix(channels, fs, comp) if cache is not None else None
        if hit is not None:
            return hit
        out = wv_matrix_of(lg, channels, fs, compensate=comp)
        with self._lock:
            self.wvm_computations += 1
            if cache is not None and self._log is lg:
                cache.store_matrix(channels, fs, out, comp)
        return out

    def cached_wvs(self) -> dict[WVKey, eg.WaveletVariance]:
        """A copy of the session's WVs, ``(channel, fs, robust, compensated) ->
        WaveletVariance``."""
        with self._lock:
            return dict(self._wv_cache.wvs)

    @property
    def log(self) -> ImuLog | None:
        """The loaded ``ImuLog`` (None before the first load)."""
        return self._log

    def _loaded_log(self) -> ImuLog:
        """The loaded log, for an action that needs data (ValueError before the first load)."""
        if self._log is None:
            raise ValueError("load data first")
        return self._log

    def _data_fs(self) -> float:
        """The sampling frequency of the data (ValueError before the first load)."""
        if self.fs is None:
            raise ValueError("load data first: no sampling frequency yet")
        return float(self.fs)

    def _publish(self, **changes: Any) -> None:
        """Set parameters in one ``param.update``: each watcher of them runs once, with the
        final values.

        An error message equal to the one shown is triggered again (an unchanged value wakes
        no watcher): a repeated failure is reported as often as it happens.
        """
        again = bool(changes.get("error")) and changes["error"] == self.error
        names = changes.get("channels")
        choice = self.param.channel
        with self.batch():
            if names is not None:
                self.offer_channels(names)
            was, self._publishing = self._publishing, True
            before = self._shown
            if not changes.keys().isdisjoint(("wv", *DATA_CHOICES)):  # (read by the watchers)
                self._shown = {n: changes.get(n, getattr(self, n)) for n in DATA_CHOICES}
            try:
                self.param.update(**changes)
            except BaseException:
                self._shown = before
                raise
            finally:
                self._publishing = was
                if names is not None:
                    choice.objects = list(names) or [""]
            if again:
                self.param.trigger("error")

    @property
    def shown(self) -> dict[str, Any]:
        """The data choices (:data:`DATA_CHOICES`) of the WV shown: equal to the parameters
        except while a choice set alone has its WV computed (a choice that differs from them
        is a request, :meth:`_data_changed`)."""
        return dict(self._shown)

    def offer_channels(self, names: Sequence[str]) -> None:
        """Add ``names`` to the choices of :attr:`channel` (the old ones stay until the
        channels change): while the value changes, old and new are valid, so a widget of the
        choice never falls back on a first option in between. Called before the watchers of
        the change run (:meth:`from_query` batches them: then before its batch)."""
        choice = self.param.channel
        union = list(dict.fromkeys([*names, *choice.objects]))
        if union != list(choice.objects):
            choice.objects = union

    def report_error(self, message: str) -> bool:
        """Show ``message`` as the error of the page (state otherwise unchanged) and log it;
        returns False."""
        log.warning("reported to the page: %s", message)
        self._publish(error=message)
        return False

    _fail = report_error

    def show_notice(self, notice: str, *, clear_error: bool = False) -> None:
        """Show ``notice`` (information, not an error; empty: none); ``clear_error`` also
        removes the error shown (e.g. a session restored in full)."""
        self._publish(notice=notice, **({"error": ""} if clear_error else {}))

    def _guard(self, action: str, fn: Callable[[], bool]) -> bool:
        """Run ``fn``; an error the action expects (bad input, an unreadable file: an engine
        error, :class:`engine.errors.GmwmError`, or another ``ValueError`` or ``OSError``:
        :data:`gmwm_app.boundary.EXPECTED`) becomes a message in :attr:`error` and False.

        Anything else (a ``KeyError``, ``TypeError``, ``IndexError`` ...) is a bug and is
        raised: the app's error boundary (:mod:`gmwm_app.boundary`) logs it with its traceback
        and shows it in the session as unexpected.
        """
        try:
            return fn()
        except EXPECTED as e:
            return self._fail(f"{action}: {message_of(e)}")

    # ---------------------------------------------------------------------------------
    # reading (thread-safe: no parameter changes)
    # ---------------------------------------------------------------------------------
    @staticmethod
    def read(source: str, **kw: Any) -> LoadedData:
        """:func:`gmwm_app.data.read_source` with the session's demo log (worker-thread safe)."""
        return read_source(source, demo=demo_path(), **kw)

    precompute = staticmethod(precompute)

    def read_and_warm(self, source: str, **kw: Any) -> LoadedData:
        """:meth:`read` data and compute the WV the session will show (worker-thread safe).

        A read error keeps ``(source, kw)`` as its ``gmwm_read`` attribute (to read it again,
        e.g. its longest clean segment).
        """
        try:
            loaded = self.read(source, **kw)
        except ValueError as e:
            e.gmwm_read = (source, kw)  # type: ignore[attr-defined]
            raise
        self.precompute(loaded, self.channel, None, self.robust, self.compensate)
        return loaded

    def without_warmup(self, load: dict[str, Any] | None = None) -> LoadedData:
        """The data shown without the warm-up the log check found (:attr:`warmup_start`
        samples dropped, :func:`engine.io.drop_warmup`), with the WV the session will show
        computed (worker-thread safe, no state change; :meth:`install` makes it the session's).

        ``load``: the options the data shown were read with; the result's ``load`` adds the
        samples dropped (in all), so that a saved session reads the same samples again.

        Raises
        ------
        ValueError
            No data, or no warm-up found in the channel shown.
        """
        with self._lock:
            lg = self._log
        start = self.warmup_start
        if lg is None or lg.is_summary or start <= 0:
            raise ValueError("the log check found no warm-up to drop in the channel shown")
        out = LoadedData(drop_warmup_of(lg, start), self.source, self.filename, self.path)
        out.load = {**(load or {})}
        out.load["drop_warmup"] = int(out.load.get("drop_warmup", 0)) + start
        self.precompute(out, self.channel, None, self.robust, self.compensate)
        return out

    def warm(
        self,
        channel: str | None = None,
        fs: float | None = None,
        robust: bool | None = None,
        progress: Callable[[int, int], object] | None = None,
    ) -> None:
        """Compute a WV of the current log into the cache (worker-thread safe, no state change):
        that of the compensated signal when the choice :attr:`compensate` compensates the
        channel, and then the raw one too (:func:`gmwm_app.data.precompute`).

        :meth:`select_channel`, :meth:`set_fs` and :meth:`set_robust` then find it cached,
        and the channel's log check (:func:`gmwm_app.data.log_check_line`) done.
        ``progress(j, J)`` is called as each level is done (a robust WV of a long log takes
        seconds).

        Raises
        ------
        ValueError
            The WV cannot be computed (e.g. a channel of NaN); the job running this reports
            it on the page (``Jobs.load``'s failure hook).
        """
        with self._lock:  # the log and its cache, together (a new log brings a new cache)
            lg, cache = self._log, self._wv_cache
        if lg is None:
            return
        ch = channel or self.channel
        f = float(fs or self.fs or lg.fs)
        rob = self.robust if robust is None else bool(robust)
        log_check_line(lg, ch)  # cached: the switch on the loop finds it done
        comp = is_compensated(lg, ch, self.compensate)
        for c in (comp, False) if comp else (False,):
            with self._lock:
                if cache.find(ch, f, rob, c) is not None:
                    continue
            wv = compute_wv(lg, ch, f, rob, progress, compensate=c)
            with self._lock:
                cache.store(ch, f, rob, c, wv)
                self.wv_computations += 1

    # ---------------------------------------------------------------------------------
    # WV cache
    # ---------------------------------------------------------------------------------
    def get_wv(
        self, channel: str, fs: float, robust: bool, compensate: str | bool | None = None
    ) -> eg.WaveletVariance:
        """The WV of a channel: from the cache, or computed once and cached; that of its
        temperature-compensated signal when the choice ``compensate`` (:attr:`compensate` by
        default; True: ``auto``, False: ``off``) compensates the channel
        (:func:`gmwm_app.data.is_compensated`).

        Raises
        ------
        ValueError
            Channel unknown, series unusable (NaN, too short), or a robust WV asked of a
            summary file.
        """
        lg = self._loaded_log()
        want = self.compensate if compensate is None else compensation_mode(compensate)
        comp = is_compensated(lg, channel, want)
        with self._lock:
            wv = self._wv_cache.find(channel, fs, robust, comp)
        if wv is not None:
            return wv
        wv = compute_wv(lg, channel, fs, robust, compensate=comp)
        with self._lock:
            self._wv_cache.store(channel, fs, robust, comp, wv)
            self.wv_computations += 1
        return wv

    # ---------------------------------------------------------------------------------
    # data actions
    # ---------------------------------------------------------------------------------
    def load_demo(self) -> bool:
        """Load the bundled demo log (keeps the model; refits it on the new WV)."""
        return self._guard("Could not load the demo", lambda: self.install(self.read("demo")))

    def load_path(self, path: str | os.PathLike[str], segments: str | None = None) -> bool:
        """Load a log from a path on the server (``segments``: a flight's still parts,
        ``"auto"`` or ``"START:STOP,..."``; its WV pools them)."""
        return self._guard(
            f"Could not load {path}",
            lambda: self.install(self.read("path", path=path, segments=segments)),
        )

    def load_upload(
        self, data: bytes | str | None, filename: str, segments: str | None = None
    ) -> bool:
        """Load an uploaded file (its bytes and its name; the suffix picks the format;
        ``segments`` as :meth:`load_path`)."""
        return self._guard(
            f"Could not load the uploaded file {filename}",
            lambda: self.install(
                self.read("upload", data=data, filename=filename, segments=segments)
            ),
        )

    def install(
        self,
        loaded: LoadedData,
        *,
        channel: str | None = None,
        fs: float | None = None,
        robust: bool | None = None,
        compensate: str | bool | None = None,
    ) -> bool:
        """Make a read log the session's data; select a channel, compute (or reuse) its WV
        (with the choice ``compensate``, :attr:`compensate` by default: of the
        temperature-compensated signal when it compensates the channel, and the raw one
        beside).

        The channel is ``channel`` if given, else the current one if the new log has it, else
        the first. The model is kept and refitted (an empty model becomes the form of a teaching
        scenario's true model); if it does not fit the new data it is cleared (with a
        message). Nothing changes if the new data cannot be used.
        """

        def run() -> bool:
            lg = loaded.log
            names = channel_names(lg)
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
            f = f_file if fs is None else check_fs(fs)
            rob = self.robust if robust is None else bool(robust)
            if lg.is_summary and rob and not summary_has_robust(lg, ch):
                msgs.append(
                    f"{loaded.name} holds a classical WV summary only; "
                    "the robust WV needs the raw log"
                )
                rob = False
            want = self.compensate if compensate is None else compensation_mode(compensate)
            comp = is_compensated(lg, ch, want)
            cache = WVCache(loaded.wv_cache)
            computed = 0
            wvs = []  # the WV shown, then the raw one beside a compensated one
            for c in (comp, False) if comp else (False,):
                got = wv_from_cache(cache.wvs, ch, f, rob, c)
                if got is None:
                    failed = loaded.wv_errors.get((ch, f, rob, c))
                    if failed is not None:  # precompute tried (and logged it): not again
                        raise ValueError(failed)
                    got = compute_wv(lg, ch, f, rob, compensate=c)
                    computed += 1
                cache.store(ch, f, rob, c, got)
                wvs.append(got)
            wv = wvs[0]
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
            fs_src = "user" if fs is not None and f != f_file else fs_source(lg)
            self._publish(
                loads=self.loads + 1,
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
                compensate=want,
                **self._data_info(lg, ch, wv, want, wvs[1] if comp else None),
                **self._model_update(new_model, result),
                error="; ".join(msgs),
                notice="; ".join(lg.meta.get("notes", []) or []),
            )
            return not msgs

        return self._guard(f"Could not use {loaded.name}", run)

    def _data_info(
        self,
        lg: ImuLog,
        ch: str,
        wv: eg.WaveletVariance,
        compensate: str,
        wv_raw: eg.WaveletVariance | None,
    ) -> dict[str, Any]:
        n = int(wv.n if lg.is_summary else np.size(lg.channels[ch]))
        info = {"n": n, "duration_s": n / float(wv.fs), "unit": unit_of(lg, ch)}
        tname = None if lg.is_summary else find_temperature(lg, "auto", channel=ch)
        return {
            **info,
            "log_check": log_check_line(lg, ch),
            "warmup_start": warmup_start(lg, ch),
            "temperature": temperature_line(lg, ch, compensate),
            "temperature_channel": tname or "",
            "compensation_unavailable": temperature_unusable(lg, ch),
            "wv_raw": wv_raw,
        }

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
            if self.is_summary and rob and not summary_has_robust(self._log, channel):
                rob = False
                msgs.append("this summary file has no robust WV; showing the classical one")
            wv = self.get_wv(channel, self._data_fs(), rob)
            return self._switch_wv(wv, channel=channel, robust=rob, msgs=msgs)

        return self._guard(f"Could not show channel {channel}", run)

    def set_fs(self, fs: float) -> bool:
        """Use another sampling frequency (Hz); the WV is re-labelled, not recomputed."""

        def run() -> bool:
            f = check_fs(fs)
            if self._log is None:
                raise ValueError("load a log first")
            wv = self.get_wv(self.channel, f, self.robust)
            return self._switch_wv(
                wv, fs=f, fs_source="user" if f != float(self._log.fs) else fs_source(self._log)
            )

        return self._guard("Could not set the sampling frequency", run)

    def set_robust(self, robust: bool) -> bool:
        """Switch between the classical and the robust (biweight) WV."""

        def run() -> bool:
            if self._log is None:
                self._publish(robust=bool(robust))
                return True
            if self.is_summary and robust and not summary_has_robust(self._log, self.channel):
                raise ValueError(
                    "this file holds a classical WV summary only; the robust WV needs the raw log"
                )
            wv = self.get_wv(self.channel, self._data_fs(), bool(robust))
            return self._switch_wv(wv, robust=bool(robust))

        return self._guard("Could not switch the robust WV", run)

    def _data_changed(self, *events: Any) -> None:
        """A data choice (:data:`DATA_CHOICES`) set alone, by its widget: show it. fs
        re-labels the WV at once; a channel or the robust WV is computed as a job
        (:attr:`wv_job`), then shown. A choice the state refuses (a bad fs, a WV that cannot be
        computed) is reported in one line and the previous values are put back (and so
        their widgets)."""
        # the state's own update (also one whose watchers run later, batched), or a put-back
        old = {n: v for n, v in self._shown.items() if getattr(self, n) != v}
        if self._publishing or self._reverting or not old:
            return
        ch, rob = self.channel, self.robust
        if "fs" in old or self._log is None:  # fs, or no log: at once (no WV to compute)
            self._shown_or_restored(old, lambda: self._show_choices(old, ch, rob))
            return
        kind = "robust" if rob else "classical"
        what = (
            f"the wavelet variance of {ch}" if "channel" in old else f"the {kind} wavelet variance"
        )
        message = f"Computing {what}"

        def work(report: Callable[[int, int], object]) -> None:
            self.warm(ch, robust=rob, progress=report)

        def apply(_out: Any) -> None:
            if (self.channel, self.robust) == (ch, rob):  # (not superseded by another choice)
                self._shown_or_restored(old, lambda: self._show_choices(old, ch, rob))

        def fail(err: BaseException) -> None:
            self._restore(old)
            if not isinstance(err, (ValueError, KeyError, OSError, TypeError, IndexError)):
                raise err  # a bug: the app's error boundary
            self._fail(f"Could not show {what}: {message_of(err)}")

        if self.wv_job is not None:
            self.wv_job(message, work, apply, fail)
            return
        try:
            work(lambda j, n: None)
        except (ValueError, KeyError, OSError, TypeError, IndexError) as e:
            fail(e)
            return
        apply(None)

    def _show_choices(self, old: dict[str, Any], channel: str, robust: bool) -> bool:
        """Show the choices set (``old``: their previous values): fs first, then the channel
        or the robust WV (computed here unless cached)."""
        if "fs" in old and not self.set_fs(cast(float, self.fs)):  # (None: refused there)
            return False
        if "channel" in old:
            return self.select_channel(channel)
        return "robust" not in old or self.set_robust(robust)

    def _shown_or_restored(self, old: dict[str, Any], show: Callable[[], bool]) -> None:
        """Run ``show``; if it refuses (or fails), put the ``old`` choices back."""
        shown = False
        try:
            shown = show()
        finally:
            if not shown:
                self._restore(old)

    def _restore(self, old: dict[str, Any]) -> None:
        """Put the choices ``old`` back (no action: the state's own put-back)."""
        self._reverting = True
        try:
            with self.batch():
                self.param.update(**old)
        finally:
            self._reverting = False

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
        lg = self._loaded_log()
        raw = None
        if is_compensated(lg, ch, self.compensate):  # the raw signal's WV, drawn beside it
            rob = bool(changes.get("robust", self.robust))
            raw = self.get_wv(ch, changes.get("fs", self._data_fs()), rob, False)
        self._publish(
            wv=wv,
            **changes,
            **self._data_info(lg, ch, wv, self.compensate, raw),
            **self._model_update(model, result),
            error="; ".join(msgs),
        )
        return not msgs

    def _compensate_changed(self, event: Any) -> None:
        """The compensation choice changed (by its widget, a URL, a restored session): show
        the WV of the compensated or of the raw signal and refit on it, and say the choice in
        the info line (nothing else to do when the WV shown is already that one, e.g. an
        install that set both, or ``auto`` and ``always`` on a channel whose test rejects)."""
        if self._log is None or self.wv is None or not self.channel or self._reverting:
            return

        def run() -> bool:
            wv = self.get_wv(self.channel, self._data_fs(), self.robust)
            if wv is self.wv:  # the same WV: the line still says which choice is in force
                lg = self._loaded_log()
                self._publish(temperature=temperature_line(lg, self.channel, self.compensate))
                return True
            return self._switch_wv(wv)

        before = self.wv
        if not self._guard("Could not switch the temperature compensation", run):
            if self.wv is before:  # nothing switched: the switch (and its widget) go back
                self._restore({"compensate": event.old})

    # ---------------------------------------------------------------------------------
    # model actions
    # ---------------------------------------------------------------------------------
    def _fit_or_none(
        self,
        wv: eg.WaveletVariance,
        model: eg.Model,
        start: eg.Model | None = None,
        weights: str | None = None,
    ) -> eg.GMWMResult | str | None:
        """Fit ``model`` (structure only, so a spec always gives the same fit) or say why not.

        ``weights``: the GMWM weights (the session's by default).
        """
        if len(model) == 0:
            return None
        m = start if start is not None else model.cleared()
        try:
            return eg.fit_gmwm(wv, m, weights=weights or self.weights)
        except ValueError as e:  # eg.GmwmError (bad model, unidentifiable, short) or numpy's
            return message_of(e)

    def _model_update(self, model: eg.Model, result: eg.GMWMResult | None) -> dict[str, Any]:
        shown = result.model if result is not None else model
        values = {k: v for k, v in shown.values().items() if v is not None}
        return {"model": shown, "result": result, "whatif_values": values}

    def set_weights(self, weights: str) -> bool:
        """Switch the GMWM weights (one of :data:`WEIGHTS`) and refit: the choice and its fit
        in one update."""

        def run() -> bool:
            if weights not in WEIGHTS:
                raise ValueError(f"unknown weights {weights!r}: use {', '.join(WEIGHTS)}")
            if self.wv is None or not len(self.model):
                self._publish(weights=weights)
                return True
            return self._apply_model(self.model, weights=weights)  # the choice and its fit

        return self._guard("Could not switch the weights", run)

    def _weights_changed(self, event: Any) -> None:
        """The weights changed alone (by their widget, a restored session): refit with them
        (nothing to do when the fit shown already has them, e.g. :meth:`set_weights`); a
        refit that fails puts the previous weights back."""
        res = self.result
        if self._reverting or res is None or res.weights == self.weights or self.wv is None:
            return
        if not self._guard("Could not switch the weights", lambda: self._apply_model(self.model)):
            if self.result is res:  # nothing refitted: the choice (and its widget) go back
                self._restore({"weights": event.old})

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

    def _apply_model(
        self, m: eg.Model, start: eg.Model | None = None, weights: str | None = None
    ) -> bool:
        """Fit ``m`` (with ``weights``, the session's by default) and show it: one update."""
        if len(m):
            if self.wv is None:
                raise ValueError("load data before building a model")
            m.validate(self.wv.n_levels)
        fit = self._fit_or_none(self.wv, m, start, weights) if self.wv is not None else None
        if isinstance(fit, str):
            return self._fail(f"Cannot fit {m.spec()}: {fit}")
        chosen = {"weights": weights} if weights is not None else {}
        self._publish(**self._model_update(m, fit), **chosen, error="")
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
                raise eg.ModelError(  # bad input: a message, not a bug's traceback
                    f"there is no process number {index + 1} (the model has {len(procs)})"
                )
            del procs[index]
            return self._apply_model(eg.Model(tuple(procs)))

        return self._guard("Could not remove the process", run)

    def clear_model(self) -> bool:
        """Remove every process: only the empirical WV is shown."""
        return self.set_model("")

    # ---------------------------------------------------------------------------------
    # what-if (the rest: gmwm_app.whatif)
    # ---------------------------------------------------------------------------------
    def slider_specs(self) -> list[SliderSpec]:
        """One slider per parameter, in the scale its process declares for it
        (:attr:`engine.models.model.Param.slider`, :meth:`SliderSpec.around`)."""
        if not len(self.model) or self.wv is None:
            return []
        vals = {**self._default_values(), **self.whatif_values}
        guesses = eg.fit.starting_values(self.model, self.wv)
        out = []
        for lab, p in zip(self.model.labels, self.model.processes, strict=True):
            for name, spec in p.params().items():
                full = f"{lab}.{name}"
                v = vals.get(full)
                if v is None or not SliderSpec.shows(spec.slider, v):
                    v = guesses[full]
                unit = eg.units.param_unit(p.code, name, self.unit)
                out.append(SliderSpec.around(full, lab, name, unit, spec, v))
        return out

    # ---------------------------------------------------------------------------------
    # what the views draw
    # ---------------------------------------------------------------------------------
    def display_model(self) -> eg.Model | None:
        """The model whose curves are drawn: the what-if one, the fit, or None.

        The what-if values are checked as they are set (:meth:`set_whatif_value`): should
        they still not make a model, the error is raised (a redraw reports it), not hidden
        behind the fit's curves.
        """
        if not len(self.model) or self.wv is None:
            return None
        if self.whatif:
            return self.whatif_model()
        return self.result.model if self.result is not None else None

    def display_objective(self) -> float | None:
        """GMWM objective of the drawn model (the fit's, or the what-if values')."""
        m = self.display_model()
        if m is None or self.wv is None:
            return None
        if not self.whatif and self.result is not None:
            return float(self.result.objective)
        eff = self.weights == "efficient"  # the fit's V^-1 (ci weights without a fit)
        w = self.result.omega if eff and self.result is not None else None
        return eg.fit.gmwm_objective(
            self.wv, m, ("ci" if eff else self.weights) if w is None else w
        )

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


def state_param(doc: str = "The session state.") -> AppState:
    """The ``state`` parameter of a view: the session's :class:`AppState`, given to the view's
    constructor and never replaced (``constant``). Typed as the state itself, not ``AppState |
    None`` (param's type for a selector without a default): no view exists without one."""
    selector = param.ClassSelector(class_=AppState, constant=True, instantiate=False, doc=doc)
    return cast(AppState, selector)
