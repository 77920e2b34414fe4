"""The "Multi-channel" tab: WV/WCCV grid and the multivariate GMWM (MGMWM) fit, live.

As in the multivariate paper, Fig. 2: a k x k grid of small log-x figures for k = 2..6
chosen channels of the loaded log, the empirical wavelet variance (WV) with its 95% interval
on the diagonal and the wavelet cross-covariance (WCCV) with its interval below it, each
with the model-implied total and one curve per latent process. The user types one latent
model for every channel (optionally another per channel), marks which channels share each
shareable process (WN, RW, AR1, GM; QN and DR are per channel only, the paper's section II),
and every change refits; tables give the covariance and correlation of every shared process,
the per-channel parameters and the objective.

Display of the WCCV: it can be negative, so the cells below the diagonal draw ``|WCCV|`` on
a log y axis with the sign in the markers (filled: positive, hollow: negative); the
interval is a vertical whisker (one that contains 0 reaches the bottom of the cell); model
curves are solid where positive and dotted where negative. The cells above the diagonal
would repeat the ones below (the matrix is symmetric) and are left empty.

Responsiveness: the WV/WCCV matrix is computed once per (log, channels, fs) and cached; the
fit runs in the app's worker pool, off the server event loop. Requests are coalesced: while
a fit runs, further changes only mark the view dirty, and one new fit with the latest
settings starts when it ends (a result overtaken by a change is dropped, never shown); on a
server, a change also waits 150 ms before starting a fit, so a burst of changes costs one
fit. Data changes made while the tab is hidden only mark the view stale; it refits when the
tab is shown again. Figures are built once per grid size; updates replace
ColumnDataSource ``data`` in place.

Test of dependence (``engine.dependence_test``, the multivariate paper, section IV): on
request, in the worker pool, with a progress bar and a Cancel button. The parametric
bootstrap refits 2 B simulated logs (B = 100 on the demo log with a linear model: about half
a minute), so it is never run live; its ``progress`` callback feeds the bar and raises to
cancel.
"""

from __future__ import annotations

import html
import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import panel as pn
import param
from bokeh.models import (
    NumberFormatter,
    ScientificFormatter,
)

import engine as eg
from engine.models import parse_model
from engine.multivariate import SHAREABLE, DependenceTest

from .data import message_of
from .jobs import ProgressThrottle, job_controls
from .multi_figures import (
    GridFigure,
    color_label,
    covariance_rows,
    grid_data,
    make_table,
    parameter_rows,
)
from .multi_fit import (
    MAX_CHANNELS,
    MIN_CHANNELS,
    Cancelled,
    build_model,
    dependence_text,
    fit_text,
    parse_overrides,
    run_dependence_test,
    shareable_labels,
)
from .views import (
    TOTAL_COLOR,
    component_color,
    hidden_alert,
    redraw_table,
)
from .virtual_view import VirtualView

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs
    from .state import AppState

__all__ = [
    "MultiView",
    "DEFAULT_SPEC",
    "DEFAULT_SHARED",
]

log = logging.getLogger(__name__)

#: The per-channel model shown first (the demo gyros: a bias instability, white noise and a
#: rate random walk) and the processes shared by every channel at first.
DEFAULT_SPEC = "GM+WN+RW"
DEFAULT_SHARED = (eg.RW.code,)
#: Shared-process controls created up front (one per shareable label of the model).
N_SHARE_POOL = 6
#: Wait (ms) after a change before a fit starts, on a server (a burst costs one fit).
DEBOUNCE_MS = 150


class MultiView(pn.viewable.Viewer):
    """Widgets, grid, tables and callbacks of the "Multi-channel" tab of one session.

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
    wvm : WVMatrix or None
        The WV/WCCV matrix shown.
    result : MGMWMResult or None
        The fit shown (None when the model could not be fitted).
    error : str
        The message shown (empty when fine).
    n_fits : int
        Fits started by this view (for tests and diagnostics).
    """

    active = param.Boolean(default=True, doc="Whether the tab is shown.")

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(**params)
        self.jobs = jobs
        self.state = state
        self.wvm: eg.WVMatrix | None = None
        self.result: Any = None
        self.error = ""
        self.n_fits = 0
        self._syncing = False
        self._running = False
        self._dirty = False
        self._stale = False
        self._scheduled = False
        self._ticker: Any = None
        self._idle = threading.Event()
        self._idle.set()
        self._data_key: Any = None
        self._shared_groups: dict[str, list[str]] = {lab: [] for lab in DEFAULT_SHARED}
        self._shared_all = set(DEFAULT_SHARED)  # labels shared by every channel (default)
        self._share_labels: list[str] = []
        self._grids: dict[int, GridFigure] = {}
        self.grid: GridFigure | None = None

        self.channel_choice = pn.widgets.MultiChoice(
            label=f"Channels ({MIN_CHANNELS} to {MAX_CHANNELS}, in grid order)",
            options=[],
            value=[],
            max_items=MAX_CHANNELS,
            sizing_mode="stretch_width",
            css_classes=["gmwm-mchannels"],
        )
        self.channel_choice.param.watch(self._on_channels, "value")
        self.spec_input = pn.widgets.TextInput(
            label="Model of every channel (press Enter)",
            value=DEFAULT_SPEC,
            placeholder="e.g. WN+RW or GM+WN+RW",
            width=260,
            css_classes=["gmwm-mspec"],
        )
        self.spec_input.param.watch(self._on_control, "value")
        self.override_input = pn.widgets.TextAreaInput(
            label="Other models for some channels (optional, one 'channel: spec' per line)",
            value="",
            placeholder="gyro_z: 2*GM+WN+RW",
            height=62,
            sizing_mode="stretch_width",
        )
        self.override_input.param.watch(self._on_control, "value")
        self.share_widgets: list[pn.widgets.MultiChoice] = []
        self.share_box = pn.FlexBox(margin=0, sizing_mode="stretch_width")
        for i in range(N_SHARE_POOL):
            self._new_share_widget(i)
        self.share_note = pn.pane.Markdown(
            "", margin=(0, 10), styles={"font-size": "12px", "color": "#555"}
        )

        self.alert = hidden_alert("danger")
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

        self.dep_running = False
        self.dependence: DependenceTest | None = None
        self._dep_cancel = threading.Event()
        self._dep_throttle = ProgressThrottle()  # at most ~10 updates a second
        self.dep_b = pn.widgets.IntInput(
            label="Bootstrap replicates B", value=100, start=10, end=2000, step=10, width=170
        )
        self.dep_button, self.dep_cancel, self.dep_progress = job_controls(
            "Test dependence",
            lambda: self.start_dependence_test(),
            lambda: self.cancel_dependence_test(),
            width=150,
            cancel_width=90,
            margin=(22, 5, 5, 10),
            description="Parametric bootstrap of the objective difference (shared vs independent)",
        )
        self.dep_text = pn.pane.Markdown(
            "", sizing_mode="stretch_width", margin=(0, 10), css_classes=["gmwm-mdependence"]
        )

        self.virtual = VirtualView(jobs)  # the optimal virtual sensor of the fit
        h = pn.pane.Markdown
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
            self.alert,
            self.notice,
            pn.Row(self.channel_choice, self.spec_input, sizing_mode="stretch_width"),
            self.override_input,
            h(
                "**Shared processes**: pick the channels that share each process (a shared "
                "WN, RW, AR1 or GM has a covariance matrix over its channels; QN and DR are "
                "per channel only; fewer than 2 channels = independent).",
                margin=(0, 10),
                styles=small,
            ),
            self.share_box,
            self.share_note,
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
            pn.Row(self.dep_button, self.dep_b, self.dep_cancel, sizing_mode="stretch_width"),
            self.dep_progress,
            self.dep_text,
            self.virtual.panel,
            sizing_mode="stretch_width",
        )
        self.state.param.watch(self._on_state, "revision")
        self.param.watch(self._on_tab, "active")
        self._sync_data(force=True)

    # ------------------------------------------------------------------------------------
    # controls
    # ------------------------------------------------------------------------------------
    def _new_share_widget(self, i: int) -> None:
        w = pn.widgets.MultiChoice(
            label="",
            options=[],
            value=[],
            visible=False,
            width=330,
            margin=(2, 10),
            css_classes=[f"gmwm-mshare-{i}"],
        )
        w.param.watch(lambda e, i=i: self._on_share(i, e.new), "value")
        self.share_widgets.append(w)
        self.share_box.append(w)

    def share_control(self, label: str) -> pn.widgets.MultiChoice:
        """The widget that marks the channels sharing the process ``label``."""
        try:
            return self.share_widgets[self._share_labels.index(label)]
        except ValueError:
            raise KeyError(
                f"no shareable process {label!r} in the model; shareable: "
                f"{', '.join(self._share_labels) or 'none'}"
            ) from None

    @property
    def shared_groups(self) -> dict[str, list[str]]:
        """Label -> channels sharing it (groups of at least 2 channels)."""
        chans = list(self.channel_choice.value)
        out = {}
        for lab in self._share_labels:
            g = chans if lab in self._shared_all else self._shared_groups.get(lab, [])
            g = [c for c in chans if c in g]
            if len(g) >= 2:
                out[lab] = g
        return out

    def _refresh_share_widgets(self) -> None:
        """One MultiChoice per shareable label of the current models (from a pool)."""
        chans = list(self.channel_choice.value)
        models: dict[str, eg.Model] = {}
        try:
            base = parse_model(self.spec_input.value)
            per = parse_overrides(self.override_input.value, chans)
            models = {c: parse_model(per[c]) if c in per else base for c in chans}
        except ValueError:
            models = {}  # the fit reports the problem
        labels = shareable_labels(models)
        self._share_labels = [lab for lab, _ in labels]
        while len(self.share_widgets) < len(labels):
            self._new_share_widget(len(self.share_widgets))
        groups = self.shared_groups
        self._syncing = True
        try:
            for i, w in enumerate(self.share_widgets):
                if i < len(labels):
                    lab, has = labels[i]
                    val = [c for c in groups.get(lab, []) if c in has]
                    w.param.update(
                        label=f"{lab} shared by", options=list(has), value=val, visible=True
                    )
                elif w.visible:
                    w.param.update(options=[], value=[], visible=False)
        finally:
            self._syncing = False
        own = sorted(
            {p.code for m in models.values() for p in m.processes if p.code not in SHAREABLE}
        )
        self.share_note.object = f"{', '.join(own)}: per channel only." if own else ""

    def _on_share(self, i: int, value: list[str]) -> None:
        if self._syncing or i >= len(self._share_labels):
            return
        lab = self._share_labels[i]
        self._shared_all.discard(lab)
        self._shared_groups[lab] = list(value)
        self.request_fit()

    def _on_control(self, _event: Any = None) -> None:
        if self._syncing:
            return
        self._refresh_share_widgets()
        self.request_fit()

    def _on_channels(self, event: Any) -> None:
        if self._syncing:
            return
        self._refresh_share_widgets()
        self.request_fit()

    def set_shared(self, label: str, channels: Sequence[str]) -> None:
        """Mark the channels that share ``label`` (fewer than 2: not shared) and refit."""
        self.share_control(label).value = [
            c for c in self.channel_choice.value if c in set(channels)
        ]

    # ------------------------------------------------------------------------------------
    # following the session's data
    # ------------------------------------------------------------------------------------
    @property
    def visible(self) -> bool:
        """The tab is the one shown."""
        return self.active

    def __panel__(self) -> pn.Column:
        """The tab's content."""
        return self.panel

    def _on_tab(self, _event: Any) -> None:
        if self._stale and self.visible:
            self._sync_data(force=True)

    def _on_state(self, _event: Any = None) -> None:
        s = self.state
        key = (id(s.log), s.fs, s.robust)
        if key == self._data_key:
            return  # another kind of change (model, channel of the Fit tab ...): nothing here
        if not self.visible:
            self._stale = True  # cheap: the grid is brought up to date when shown
            return
        self._sync_data()

    def _sync_data(self, force: bool = False) -> None:
        """Follow a new log (or fs): channel options, default choice, refit."""
        s = self.state
        key = (id(s.log), s.fs, s.robust)
        if key == self._data_key and not force:
            return
        new_log = self._data_key is None or key[0] != self._data_key[0]
        self._data_key = key
        self._stale = False
        lg = s.log
        names = list(s.channels) if lg is not None else []
        self._syncing = True
        try:
            if list(self.channel_choice.options) != names:
                self.channel_choice.options = names
            keep = [c for c in self.channel_choice.value if c in names]
            if new_log and len(keep) < MIN_CHANNELS:
                keep = names[:3]
            if keep != list(self.channel_choice.value):
                self.channel_choice.value = keep
        finally:
            self._syncing = False
        self._refresh_share_widgets()
        self.request_fit()

    # ------------------------------------------------------------------------------------
    # the WV/WCCV matrix (worker thread, cached)
    # ------------------------------------------------------------------------------------
    # ------------------------------------------------------------------------------------
    # fitting (worker thread, coalesced, stale results dropped)
    # ------------------------------------------------------------------------------------
    def _settings(self) -> tuple:
        s = self.state
        groups = self.shared_groups
        return (
            id(s.log),
            s.fs,
            tuple(self.channel_choice.value),
            self.spec_input.value,
            self.override_input.value,
            tuple(sorted((k, tuple(v)) for k, v in groups.items())),
        )

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
        """Refit with the current controls: now, after a short wait on a server, or after
        the running fit (coalesced)."""
        if self._running:
            self._dirty = True
            return
        if self.jobs.served:
            if self._scheduled:
                return
            self._scheduled = True
            self._idle.clear()

            def fire() -> None:
                self._scheduled = False
                self._start()

            self.jobs.later(fire, DEBOUNCE_MS)
            return
        self._start()

    def _start(self) -> None:
        s = self.state
        lg, fs = s.log, s.fs
        chans = list(self.channel_choice.value)
        settings = self._settings()
        if lg is None:
            self._show(None, None, "Load a log first (sidebar).", "")
            self._idle.set()
            return
        if lg.is_summary:
            self._show(
                None,
                None,
                (
                    f"{s.filename} holds wavelet-variance summaries only (no raw "
                    "samples): the multi-channel view needs the raw channels of "
                    "a log. Load a raw log (CSV/text, NPY/NPZ or HDF5)."
                ),
                "",
            )
            self._idle.set()
            return
        if len(chans) < MIN_CHANNELS:
            self._show(
                None, None, f"Choose at least {MIN_CHANNELS} channels (at most {MAX_CHANNELS}).", ""
            )
            self._idle.set()
            return
        spec, over, groups = self.spec_input.value, self.override_input.value, self.shared_groups
        self._running = True
        self._dirty = False
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
            if self._dirty or settings != self._settings():
                return  # overtaken by a change: the next fit shows the current settings
            wvm, res, err, note = out
            self._show(wvm, res, err, note)

        def fail(e: BaseException) -> None:
            if self._dirty or settings != self._settings():
                return
            self._show(None, None, f"Could not compute the WV/WCCV matrix: {message_of(e)}", "")

        def done() -> None:
            self._running = False
            self._set_busy(False)
            if self._dirty:
                self._dirty = False
                self.request_fit()
            elif not self._scheduled:
                self._idle.set()

        self.jobs.run(work, self._guarded(apply), self._guarded(fail), done)

    def _guarded(self, fn: Callable[[Any], Any]) -> Callable[[Any], None]:
        """``fn`` that shows a display problem in the view instead of raising it."""

        def run(arg: Any) -> None:
            if isinstance(arg, BaseException) and not isinstance(
                arg, (ValueError, KeyError, TypeError, Cancelled)
            ):
                log.error("multi-channel job failed: %s: %s", type(arg).__name__, arg)
            try:
                fn(arg)
            except Exception as e:  # a display problem: say so, keep the session
                log.exception("multi-channel display failed")
                self._message(f"Display error: {type(e).__name__}: {e}")

        return run

    # ------------------------------------------------------------------------------------
    # test of dependence (on request, worker thread, progress and cancel)
    # ------------------------------------------------------------------------------------
    def _dep_running(self, on: bool) -> None:
        self.dep_running = on
        self.dep_button.disabled = on
        self.dep_cancel.disabled = not on
        self.dep_progress.param.update(visible=on, value=0)

    def _dep_progress(
        self, done: int, total: int, observer: Callable[[int, int], None] | None
    ) -> None:
        """Progress callback (worker thread): bar, text, cancel point."""
        value = self._dep_throttle.step(done, total, observer, self._dep_cancel, Cancelled)
        if value is not None:
            text = f"⏳ Bootstrap replicate {done} of {total} ..."
            self.jobs.locked(
                lambda: (
                    self.dep_progress.param.update(value=value),
                    setattr(self.dep_text, "object", text),
                )
            )

    def start_dependence_test(
        self,
        B: int | None = None,
        *,
        seed: int = 0,
        observer: Callable[[int, int], None] | None = None,
    ) -> bool:
        """Test the dependence of the shown fit's shared processes in a worker thread.

        ``observer(done, total)`` sees every progress step (tests). Returns False (with a
        message) when there is nothing to test.
        """
        if self.dep_running:
            return False
        res, wvm = self.result, self.wvm
        if res is None or wvm is None:
            self.dep_text.object = "Fit a model first."
            return False
        if not res.model.shared:
            self.dep_text.object = (
                "The model shares no process: mark the channels that "
                "share one first (nothing to test)."
            )
            return False
        b = int(B if B is not None else self.dep_b.value or 100)
        model, spec = res.model, res.model.spec()
        self._dep_cancel.clear()
        self._dep_running(True)
        self.dep_text.object = f"⏳ Fitting the independent model of {html.escape(spec)} ..."

        def work() -> DependenceTest:
            return run_dependence_test(
                wvm, model, B=b, seed=seed, progress=lambda d, t: self._dep_progress(d, t, observer)
            )

        def apply(t: DependenceTest) -> None:
            self.dependence = t
            self.dep_text.object = dependence_text(t, spec)

        def fail(e: BaseException) -> None:
            if isinstance(e, Cancelled):
                self.dep_text.object = "Dependence test cancelled."
            else:
                self.dep_text.object = f"**Dependence test failed:** {html.escape(message_of(e))}"

        self.jobs.run(
            work, self._guarded(apply), self._guarded(fail), lambda: self._dep_running(False)
        )
        return True

    def cancel_dependence_test(self) -> None:
        """Stop the running dependence test at its next replicate."""
        if self.dep_running:
            self._dep_cancel.set()
            self.dep_text.object = "Cancelling ..."

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
        self.alert.param.update(object=html.escape(text), visible=bool(text))

    def _grid_for(self, k: int) -> GridFigure:
        g = self._grids.get(k)
        if g is None:
            g = self._grids[k] = GridFigure(k)
        if self.grid is not g:
            self.grid = g
            self.grid_box.objects = [g.pane]
        return g

    def _show(self, wvm: eg.WVMatrix | None, result: Any, error: str, note: str) -> None:
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
