"""The "Multi-channel" tab: WV/WCCV grid and the multivariate GMWM (MGMWM) fit, live.

As in the multivariate paper, Fig. 2: a k x k grid of small figures for k = 2..6 chosen
channels, the empirical WV on the diagonal and the wavelet cross-covariance below it, each with
the model-implied total and one curve per latent process; the user types the latent model,
marks which channels share each shareable process, and every change refits off the event loop
(requests coalesced). The settings' widgets are :mod:`gmwm_app.multi_controls`, the figures
and tables :mod:`gmwm_app.multi_figures`, the fit's pure helpers :mod:`gmwm_app.multi_fit`,
the test of dependence :mod:`gmwm_app.multi_dependence` and the virtual sensor
:mod:`gmwm_app.virtual_view`; this module is the tab that ties them to the session. How the
WCCV is drawn and how refits are scheduled: docs/methods.md, "The Multi-channel tab"; the
user's view: docs/app.md.
"""

from __future__ import annotations

import html
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import panel as pn
import param
from bokeh.models.widgets import NumberFormatter, ScientificFormatter

import engine as eg
from engine.models import PROCESS_TYPES
from engine.multivariate import SHAREABLE

from .data import message_of
from .multi_controls import DEFAULT_SHARED, DEFAULT_SPEC, MultiControls
from .multi_dependence import DependenceControls
from .multi_figures import (
    GridFigure,
    color_label,
    covariance_rows,
    grid_data,
    make_table,
    parameter_rows,
)
from .multi_fit import MAX_CHANNELS, MIN_CHANNELS, build_model, fit_text
from .tab_view import TabView
from .views import TOTAL_COLOR, component_color, hidden_alert, redraw_table
from .virtual_view import VirtualView

#: the processes a channel keeps to itself (the classes say which may be shared)
PER_CHANNEL = tuple(code for code in PROCESS_TYPES if code not in SHAREABLE)

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs
    from .state import AppState

__all__ = ["MultiView", "DEFAULT_SPEC", "DEFAULT_SHARED"]

#: Wait (ms) after a change before a fit starts, on a server (a burst costs one fit).
DEBOUNCE_MS = 150


class MultiView(TabView):
    """Grid, tables, fit and callbacks of the "Multi-channel" tab of one session.

    Parameters
    ----------
    state : AppState
        The session state (it holds the loaded log).
    jobs : Jobs
        The session's job runner (worker threads, document lock, timers).

    Attributes
    ----------
    panel : panel.Column
        The tab's layout.
    controls : MultiControls
        Channels, models and shared processes.
    dep : DependenceControls
        The test of dependence of the fit shown.
    wvm : WVMatrix or None
        The WV/WCCV matrix shown.
    result : MGMWMResult or None
        The fit shown (None when the model could not be fitted).
    error : str
        The message shown (empty when fine).
    n_fits : int
        Fits started by this view (for tests and diagnostics).
    """

    slug = "multi"

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(state, jobs, **params)
        self.wvm: eg.wv.WVMatrix | None = None
        self.result: Any = None
        self.error = ""
        self.n_fits = 0
        self._running = False
        self._refit = False  # a change came while a fit ran: fit again when it ends
        self._scheduled = False
        self._started: Any = None  # the settings of the last fit started (or refused)
        self._ticker: Any = None
        self._idle = threading.Event()
        self._idle.set()
        self._data_key: Any = None
        self._grids: dict[int, GridFigure] = {}
        self.grid: GridFigure | None = None
        self.controls = MultiControls(lambda: self._safely(self.request_fit))
        self.dep = DependenceControls(jobs, lambda: (self.result, self.wvm), self._safely)
        self.virtual = VirtualView(jobs, self._safely)  # the optimal virtual sensor of the fit
        self._build_display()
        self._build_layout()
        self.refresh()

    @param.depends("state.wv", "state.compensate", watch=True)
    def _on_state(self) -> None:
        """New data (every load sets a new WV: the log itself is no parameter), another
        sampling frequency or the robust WV (a notice here: each comes with its WV), or the
        temperature compensation switched (the channels' WVs and WCCVs are then of the
        compensated or the raw signals)."""
        super()._on_state()

    def _visible(self) -> bool:
        """Only while the tab is shown, also outside a server: the fit is costly, and the
        tests switch the tab as a user does."""
        return self.active

    # ------------------------------------------------------------------------------------
    # construction (once)
    # ------------------------------------------------------------------------------------
    def _build_display(self) -> None:
        self.notice = hidden_alert("info")
        self.spinner = pn.indicators.LoadingSpinner(
            value=True, size=18, visible=False, margin=(8, 0, 0, 10)
        )
        self.status = pn.pane.Markdown(
            "",
            sizing_mode="stretch_width",
            margin=(0, 10),
            styles={"color": "#555", "font-size": "13px"},
        )
        self.legend = pn.pane.HTML("", sizing_mode="stretch_width", margin=(0, 10))
        self.grid_box = pn.Column(margin=0, sizing_mode="stretch_width")
        self.fit_info = pn.pane.Markdown(
            "", sizing_mode="stretch_width", margin=(0, 10), css_classes=["gmwm-mobjective"]
        )
        sci = ScientificFormatter(precision=4)
        self.cov_source, self.cov_table = make_table(
            [
                ("process", "shared process", 150, None),
                ("channel_a", "channel", 80, None),
                ("channel_b", "with", 80, None),
                ("covariance", "covariance", 95, sci),
                ("unit", "unit", 80, None),
                ("correlation", "correlation [1]", 110, NumberFormatter(format="0.0000")),
            ],
            "mgmwm_cov",
            "gmwm-mcov",
            300,
        )
        self.param_source, self.param_table = make_table(
            [
                ("channel", "channel", 110, None),
                ("process", "process", 60, None),
                ("parameter", "parameter", 75, None),
                ("value", "value", 95, sci),
                ("unit", "unit", 80, None),
            ],
            "mgmwm_params",
            "gmwm-mparams",
            300,
        )

    def _build_layout(self) -> None:
        h = pn.pane.Markdown
        c = self.controls
        small = {"font-size": "12px", "color": "#555"}
        self.caption = h(
            "Diagonal: empirical wavelet variance (dots) with its 95% interval (band). Below "
            "it: the wavelet cross-covariance of two channels, drawn as **|WCCV| on a log "
            "axis, the sign in the marker** (filled: positive, hollow: negative), its 95% "
            "interval as a whisker (one that contains 0 reaches the bottom of the cell). "
            "Red: the fitted model's total; coloured dashed: one process each; dotted: "
            "where a curve is negative. Above the diagonal: the same as below (symmetric), "
            "left empty. The WCCV is classical (no robust WCCV yet).",
            margin=(0, 10),
            styles=small,
        )
        self.panel = pn.Column(
            h(
                "#### Several channels: wavelet cross-covariance and the multivariate GMWM",
                margin=(0, 10),
            ),
            self.message,
            self.notice,
            pn.Row(c.channel_choice, c.spec_input, sizing_mode="stretch_width"),
            c.override_input,
            h(
                "**Shared processes**: pick the channels that share each process (a shared "
                f"{', '.join(SHAREABLE[:-1])} or {SHAREABLE[-1]} has a covariance matrix over "
                f"its channels; {', '.join(PER_CHANNEL)} are per channel only; fewer than 2 "
                "channels = independent).",
                margin=(0, 10),
                styles=small,
            ),
            c.share_box,
            c.share_note,
            pn.Row(self.spinner, self.status, sizing_mode="stretch_width"),
            self.caption,
            self.legend,
            self.grid_box,
            self.fit_info,
            pn.Row(
                pn.Column(
                    h("##### Shared processes: covariance and correlation", margin=(0, 10)),
                    pn.pane.Bokeh(self.cov_table, sizing_mode="stretch_width", margin=(5, 10)),
                    sizing_mode="stretch_width",
                ),
                pn.Column(
                    h("##### Per-channel parameters", margin=(0, 10)),
                    pn.pane.Bokeh(self.param_table, sizing_mode="stretch_width", margin=(5, 10)),
                    sizing_mode="stretch_width",
                ),
                sizing_mode="stretch_width",
            ),
            self.dep.panel,
            self.virtual.panel,
            sizing_mode="stretch_width",
        )

    def set_shared(self, label: str, channels: Sequence[str]) -> None:
        """Mark the channels that share ``label`` (fewer than 2: not shared) and refit."""
        self.controls.set_shared(label, channels)

    # ------------------------------------------------------------------------------------
    # following the session's data
    # ------------------------------------------------------------------------------------
    def _draw(self, force: bool) -> None:
        """Follow a new log (or fs, or robust): channel options, default choice, refit."""
        s = self.state
        key = (id(s.log), s.fs, s.robust)
        if key == self._data_key and not force:
            return  # another kind of change (the Fit tab's channel ...): nothing here
        new_log = self._data_key is None or key[0] != self._data_key[0]
        self._data_key = key
        names = list(s.channels) if s.log is not None else []
        if not self.controls.follow_channels(names, new_log):
            self.controls.refresh_share_widgets()
            self.request_fit()  # new data, same channels (a changed choice refitted already)

    # ------------------------------------------------------------------------------------
    # fitting (worker thread, coalesced, stale results dropped)
    # ------------------------------------------------------------------------------------
    def _settings(self) -> tuple:
        s = self.state
        return (id(s.log), s.fs, s.robust, s.compensate, *self.controls.settings())

    @property
    def n_wvm(self) -> int:
        """WV/WCCV matrices computed by the session (the state's cache misses)."""
        return self.state.wvm_computations

    @property
    def busy(self) -> bool:
        """A fit is running or scheduled."""
        return self._running or self._scheduled

    def wait(self, timeout: float = 30.0) -> bool:
        """Block until no fit is running (tests with a served app); True when idle."""
        return self._idle.wait(timeout)

    def request_fit(self) -> None:
        """Refit with the current settings: now, after a short wait on a server, or after
        the running fit (coalesced). Nothing when the last fit had these settings."""
        if self._running:
            self._refit = True
            return
        if self.jobs.served:
            if self._scheduled:
                return
            self._scheduled = True
            self._idle.clear()

            def fire() -> None:
                self._scheduled = False
                self._safely(self._start)

            self.jobs.later(fire, DEBOUNCE_MS)
            return
        self._start()

    def _refuse(self, message: str) -> None:
        self._show(None, None, message, "")
        self._idle.set()

    def _start(self) -> None:
        s = self.state
        lg, fs = s.log, s.fs
        chans = self.controls.channels
        settings = self._settings()
        if settings == self._started:
            if not self._scheduled:
                self._idle.set()
            return  # the fit shown (or running) has these settings: an echo, nothing to do
        self._started = settings
        if lg is None:
            self._refuse("Load a log first (sidebar).")
            return
        if lg.is_summary:
            self._refuse(
                f"{s.filename} holds wavelet-variance summaries only (no raw "
                "samples): the multi-channel view needs the raw channels of "
                "a log. Load a raw log (CSV/text, NPY/NPZ or HDF5)."
            )
            return
        if len(chans) < MIN_CHANNELS:
            self._refuse(f"Choose at least {MIN_CHANNELS} channels (at most {MAX_CHANNELS}).")
            return
        c = self.controls
        spec, over = c.spec_input.value or "", c.override_input.value or ""
        groups = c.shared_groups
        self._running = True
        self._refit = False
        self._idle.clear()
        self.n_fits += 1
        self._set_busy(True, f"Fitting {', '.join(chans)}")

        def work() -> tuple[Any, Any, str, str]:
            wvm, note = self.state.wv_matrix(lg, chans, float(fs or lg.fs))
            try:
                mm = build_model(chans, spec, over, groups)
                res = eg.fit_mgmwm(wvm, mm)
            except ValueError as e:  # ModelError, FitError: bad spec, unidentifiable, short
                return wvm, None, f"Could not fit the model: {message_of(e)}", note
            return wvm, res, "", note

        def apply(out: tuple[Any, Any, str, str]) -> None:
            if settings != self._settings():
                return  # overtaken by a change: the next fit shows the current settings
            wvm, res, err, note = out
            self._show(wvm, res, err, note)

        def fail(e: BaseException) -> None:
            self._started = None  # the same settings may be tried again
            self._log_job_error(e)
            if settings == self._settings():
                self._message(f"Could not compute the WV/WCCV matrix: {message_of(e)}")

        def done() -> None:
            self._running = False
            self._set_busy(False)
            if self._refit:
                self._refit = False
                self.request_fit()
            elif not self._scheduled:
                self._idle.set()

        self.jobs.run(work, self._guarded(apply), self._guarded(fail), done)

    def _failed(self, err: BaseException) -> None:
        self._message(f"Display error: {type(err).__name__}: {err}")

    # ------------------------------------------------------------------------------------
    # display
    # ------------------------------------------------------------------------------------
    def _set_busy(self, on: bool, message: str = "") -> None:
        """Spinner and progress text; on a server the text counts the seconds of a long fit
        (the figures keep the previous result meanwhile)."""
        self.spinner.visible = on
        self.jobs.stop(self._ticker)
        self._ticker = None
        if not on:
            if self.status.object.startswith("⏳"):
                self.status.object = ""
            return
        t0 = time.perf_counter()
        text = html.escape(message)
        self.status.object = f"⏳ {text} ..."

        def tick() -> None:
            self.status.object = (
                f"⏳ {text} ... {time.perf_counter() - t0:.0f} s (the "
                "grid shows the previous fit until this one ends)"
            )

        self._ticker = self.jobs.every(tick, 1000)

    def _message(self, text: str) -> None:
        self.error = text
        self.show_message([html.escape(text)] if text else [], level="danger")

    def _grid_for(self, k: int) -> GridFigure:
        g = self._grids.get(k)
        if g is None:
            g = self._grids[k] = GridFigure(k)
        if self.grid is not g:
            self.grid = g
            self.grid_box.objects = [g.pane]
        return g

    def _show(self, wvm: eg.wv.WVMatrix | None, result: Any, error: str, note: str) -> None:
        """Draw a matrix and a fit (either may be None) with a message."""
        self.wvm, self.result = wvm, result
        rob = (
            "The robust WV of the sidebar does not apply here: the grid and the fit use the "
            "classical WV/WCCV."
            if self.state.robust and wvm is not None
            else ""
        )
        notes = " ".join(t for t in (note, rob) if t)
        with pn.io.hold():
            self._message(error)
            self.notice.param.update(object=html.escape(notes), visible=bool(notes))
            if wvm is None:
                self.grid_box.visible = False
                self.legend.object = ""
            else:
                g = self._grid_for(wvm.k)
                g.update(wvm, grid_data(wvm, result))
                self.grid_box.visible = True
                self.legend.object = self._legend(result)
            self.fit_info.object = fit_text(result)
            for src, table, rows in (
                (self.cov_source, self.cov_table, covariance_rows(result)),
                (self.param_source, self.param_table, parameter_rows(result)),
            ):
                same = len(next(iter(rows.values()))) == len(next(iter(src.data.values())))
                src.data = rows
                if same:
                    redraw_table(table)
        self.virtual.update(result)

    @staticmethod
    def _legend(result: Any) -> str:
        items = [(TOTAL_COLOR, "model total", "solid")]
        if result is not None:
            seen: dict[str, str] = {}
            shared = {lab: est.channels for lab, est in result.shared.items()}
            for key in result.components:
                lab = color_label(key)
                if lab in seen:
                    continue
                seen[lab] = f"{lab} (shared by {', '.join(shared[lab])})" if lab in shared else lab
            items += [(component_color(lab), text, "dashed") for lab, text in seen.items()]
        out = []
        for color, text, dash in items:
            out.append(
                f'<span style="white-space:nowrap;margin-right:14px;font-size:12px">'
                f'<span style="display:inline-block;width:20px;border-top:3px {dash} '
                f'{color};margin:0 5px 3px 0"></span>{html.escape(text)}</span>'
            )
        return "".join(out)
