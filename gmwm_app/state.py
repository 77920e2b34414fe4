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

import json
import logging
import math
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import param

import engine as eg
from gmwm_app.data import (
    LoadedData,
    channel_names,
    check_fs,
    compute_wv,
    fs_source,
    message_of,
    precompute,
    read_source,
    store_wv,
    summary_has_robust,
    unit_of,
    wv_from_cache,
    wv_matrix_of,
)
from gmwm_app.query import QueryMixin
from gmwm_app.whatif import SliderSpec, WhatIfMixin

__all__ = [
    "AppState",
    "PROCESS_CODES",
    "demo_path",
    "format_value",
]

log = logging.getLogger(__name__)

#: WV/WCCV matrices kept in a session's WV cache (multi-channel view).
N_WV_MATRICES = 4

#: Process codes in the order of the add buttons: the engine's processes, in its order.
PROCESS_CODES: tuple[str, ...] = tuple(eg.PROCESS_TYPES)

#: Readable names of the processes (for the process list): each process's own.
PROCESS_NAMES: dict[str, str] = {c: cls.display_name for c, cls in eg.PROCESS_TYPES.items()}

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


@dataclass
class Inference:
    """95% asymptotic intervals (``ParamInterval`` list) and J-test of one fit."""

    result: Any
    intervals: list[Any]
    j_test: Any = None  # engine.inference.JTest, None when it cannot be computed
    j_error: str = ""


# ---------------------------------------------------------------------------------------------
# the state
# ---------------------------------------------------------------------------------------------
class AppState(QueryMixin, WhatIfMixin, param.Parameterized):
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
    weights = param.String(
        default="ci",
        doc="GMWM weighting: 'ci' (the R default), 'identity' or 'efficient' (two-step, "
        "Omega = V^-1 with V from the first fit's model).",
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
    # messages
    error = param.String(default="", doc="Last error, in words (empty when fine).")
    notice = param.String(default="", doc="Information (not an error), e.g. a URL fallback.")
    revision = param.Integer(default=0, doc="Increases after every change the views draw.")

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        self._log: Any = None
        self._wv_cache: dict[tuple[str, float, bool], eg.WaveletVariance] = {}
        self._lock = threading.Lock()
        self.wvm_computations = 0  # WV/WCCV matrices computed (multi-channel view)
        self.wv_computations = 0  # how many WVs this session computed (for tests/diagnostics)
        self.loads = 0  # data installs: a reload of the (shared) demo log is a new load
        self._inference: dict[int, Inference] = {}  # per fit (id of the GMWMResult)

    # ---------------------------------------------------------------------------------
    # helpers
    # ---------------------------------------------------------------------------------
    def wv_matrix(self, lg: Any, channels: Sequence[str], fs: float) -> tuple[eg.WVMatrix, str]:
        """:func:`gmwm_app.data.wv_matrix_of`, cached in the session's WV cache while ``lg``
        is the session's log (worker-thread safe; the last :data:`N_WV_MATRICES` kept).
        """
        key = ("wv-matrix", tuple(channels), float(fs))
        with self._lock:
            cache = self._wv_cache if self._log is lg else None
            hit = cache.get(key) if cache is not None else None
        if hit is not None:
            return hit
        out = wv_matrix_of(lg, channels, fs)
        with self._lock:
            self.wvm_computations += 1
            if cache is not None and self._log is lg:
                cache[key] = out
                old = [k for k in cache if k[0] == "wv-matrix" and isinstance(k[1], tuple)]
                for k in old[:-N_WV_MATRICES]:
                    cache.pop(k)
        return out

    def cached_wvs(self) -> dict[tuple[str, float, bool], eg.WaveletVariance]:
        """A copy of the session's WV cache, ``(channel, fs, robust) -> WaveletVariance``."""
        with self._lock:
            return dict(self._wv_cache)

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
            return self._fail(f"{action}: {message_of(e)}")
        except Exception as e:  # the UI must keep working
            log.exception("unexpected error while %s", action)
            return self._fail(f"{action}: unexpected {type(e).__name__}: {e}")

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
        self.precompute(loaded, self.channel, None, self.robust)
        return loaded

    def warm(
        self,
        channel: str | None = None,
        fs: float | None = None,
        robust: bool | None = None,
        progress: Callable[[int, int], object] | None = None,
    ) -> None:
        """Compute a WV of the current log into the cache (worker-thread safe, no state change).

        :meth:`select_channel`, :meth:`set_fs` and :meth:`set_robust` then find it cached.
        ``progress(j, J)`` is called as each level is done (a robust WV of a long log takes
        seconds).
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
                if wv_from_cache(cache, ch, f, rob) is not None:
                    return
            wv = compute_wv(lg, ch, f, rob, progress)
            with self._lock:
                store_wv(cache, ch, f, rob, wv)
                self.wv_computations += 1
        except Exception:  # reported by the state change that follows
            pass

    # ---------------------------------------------------------------------------------
    # WV cache
    # ---------------------------------------------------------------------------------
    def get_wv(self, channel: str, fs: float, robust: bool) -> eg.WaveletVariance:
        """The WV of a channel: from the cache, or computed once and cached.

        Raises
        ------
        ValueError
            Channel unknown, series unusable (NaN, too short), or a robust WV asked of a
            summary file.
        """
        with self._lock:
            wv = wv_from_cache(self._wv_cache, channel, fs, robust)
            if wv is not None:
                self._wv_cache[(channel, fs, robust)] = wv
                return wv
        wv = compute_wv(self._log, channel, fs, robust)
        with self._lock:
            store_wv(self._wv_cache, channel, fs, robust, wv)
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
            cache = dict(loaded.wv_cache)
            wv = wv_from_cache(cache, ch, f, rob)
            computed = 0
            if wv is None:
                wv = compute_wv(lg, ch, f, rob)
                computed = 1
            store_wv(cache, ch, f, rob, wv)
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
                self.loads += 1
                self._wv_cache = cache
                self.wv_computations += computed + loaded.computations
            fs_src = "user" if fs is not None and f != f_file else fs_source(lg)
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
        return {"n": n, "duration_s": n / float(wv.fs), "unit": unit_of(lg, ch)}

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
            wv = self.get_wv(channel, float(self.fs), rob)
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
                self.param.update(robust=bool(robust))
                return True
            if self.is_summary and robust and not summary_has_robust(self._log, self.channel):
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
        m = start if start is not None else model.cleared()
        try:
            return eg.fit_gmwm(wv, m, weights=self.weights)
        except (eg.ModelError, eg.FitError, ValueError) as e:
            return message_of(e)

    def _model_update(self, model: eg.Model, result: eg.GMWMResult | None) -> dict[str, Any]:
        shown = result.model if result is not None else model
        values = {k: v for k, v in shown.values().items() if v is not None}
        return {"model": shown, "result": result, "whatif_values": values}

    def set_weights(self, weights: str) -> bool:
        """Switch the GMWM weights (``"ci"``, ``"identity"`` or ``"efficient"``) and refit."""

        def run() -> bool:
            if weights not in ("ci", "identity", "efficient"):
                raise ValueError(f"unknown weights {weights!r}: use ci, identity or efficient")
            old = self.weights
            self.param.update(weights=weights)
            if self.wv is None or not len(self.model) or self._apply_model(self.model):
                return True
            self.param.update(weights=old)
            return False

        return self._guard("Could not switch the weights", run)

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
    # what-if (the rest: gmwm_app.whatif)
    # ---------------------------------------------------------------------------------
    def slider_specs(self) -> list[SliderSpec]:
        """One log-scaled slider per parameter, 3 decades either side of its current value."""
        if not len(self.model) or self.wv is None:
            return []
        vals = {**self._default_values(), **self.whatif_values}
        guesses = eg.starting_values(self.model, self.wv)
        out = []
        for lab, p in zip(self.model.labels, self.model.processes, strict=True):
            for name in p.param_names:
                full = f"{lab}.{name}"
                v = vals.get(full)
                # an AR coefficient near 1 is read on 1 - phi; variances and rates on a log
                transform = "log10(1-x)" if name == "phi" else "log10"
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
        eff = self.weights == "efficient"  # the fit's V^-1 (ci weights without a fit)
        w = self.result.omega if eff and self.result is not None else None
        return eg.gmwm_objective(self.wv, m, ("ci" if eff else self.weights) if w is None else w)

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
            raise ValueError(message_of(e)) from None
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
            raise ValueError(f"no intervals for {result.model.spec()}: {message_of(e)}") from None
        try:
            return Inference(result, intervals, j_test(result), "")
        except (eg.FitError, ValueError, np.linalg.LinAlgError) as e:
            return Inference(result, intervals, None, message_of(e))

    def install_inference(self, inf: Inference) -> bool:
        """Cache intervals and J-test of a fit (at most 32 fits kept) and redraw."""
        if len(self._inference) >= 32:
            self._inference.pop(next(iter(self._inference)))
        self._inference[id(inf.result)] = inf
        self.param.update(inferred=inf, revision=self.revision + 1)
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
    # export (the URL round trip: gmwm_app.query)
    # ---------------------------------------------------------------------------------
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
            out["datasheet"] = eg.datasheet(
                self.result.model, float(self.fs), self.unit, n_levels=self.result.wv.n_levels
            )
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
