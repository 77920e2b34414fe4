"""The page of one browser session: :func:`create_app` builds it around a fresh state.

Layout: a sidebar with the data (demo, upload, server path, channel, fs, robust WV), the model
builder and what-if sliders (:class:`gmwm_app.model_panel.ModelPanel`) and the exports; the
main area with messages, the WV plot, the residual strip, the fit summary and the parameter
and datasheet tables (with 95% intervals and a J-test badge on request), in a "Fit" tab; the
"Model selection", "Slope method" and "Multi-channel" tabs are :class:`panel.viewable.Viewer`
objects built on first opening with the session state and its job runner
(:class:`gmwm_app.jobs.Jobs`), never with this page object.

Responsiveness: reading a file and computing a WV run as jobs in a worker thread (the event
loop, and so every other session, stays free) with a loading indicator; the data a URL names
are read while the browser is still loading the page; a fit takes milliseconds and runs
inline; every redraw replaces ColumnDataSource data in place (``wv_figures.WVFigures``,
``FitTables``). Serving (pages built off the loop, BLAS limits) is :mod:`gmwm_app.server`.

State and page: :class:`GMWMApp` is a :class:`panel.viewable.Viewer` around the session's
:class:`~gmwm_app.state.AppState`; each part of the Fit tab depends on the state parameters
it draws (``param.depends(..., watch=True)`` for the in-place Bokeh updates, parameter
references and ``param.depends`` methods as the text panes' objects), so an action redraws
what it changed, each part once. The widgets of the state's plain parameters (weights,
what-if, intervals, temperature compensation, and the data's channel, fs and robust WV) are
built from them (``Widget.from_param``: Panel links the two both ways, and the state reacts to
a change itself: a refit, or a WV computed as a job, :meth:`AppState._data_changed`). The parts
drawn from the data follow the WV, which the channel, fs and robust choices change.

Serve with ``gmwm-app`` / ``python -m gmwm_app``, or ``panel serve gmwm_app/app.py``.
"""

from __future__ import annotations

import io
import itertools
import logging
import sys
import time
import weakref
from collections.abc import Callable
from concurrent.futures import Future
from functools import partial
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

if __package__ in (None, ""):  # run as a script by `panel serve gmwm_app/app.py`
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import panel as pn  # noqa: E402
import param  # noqa: E402

from gmwm_app import boundary  # noqa: E402
from gmwm_app._panel_compat import light_text_updates  # noqa: E402
from gmwm_app.jobs import Jobs  # noqa: E402
from gmwm_app.model_panel import ModelPanel  # noqa: E402
from gmwm_app.report_download import report_file, report_filename  # noqa: E402
from gmwm_app.segments_view import SegmentsStrip  # noqa: E402
from gmwm_app.selection_view import SelectionView, jtest_badge  # noqa: E402
from gmwm_app.session_view import SessionPanel, download_button  # noqa: E402
from gmwm_app.state import (  # noqa: E402
    AppState,
    format_value,
    state_param,
)
from gmwm_app.upload import BoundedFileDropper  # noqa: E402
from gmwm_app.views import (  # noqa: E402
    FitTables,
    fit_summary,
    hidden_alert,
    redraws,
)
from gmwm_app.wv_figures import WVFigures  # noqa: E402

__all__ = ["GMWMApp", "app_of", "create_app", "live_apps", "set_listed"]

log = logging.getLogger(__name__)

boundary.install()  # the process's Panel exception handler (create_app sets it per session too)

pn.extension("filedropper", notifications=False)


light_text_updates()  # see gmwm_app._panel_compat

# app -> creation serial: a weak registry that still lists the sessions oldest first
_APPS: weakref.WeakKeyDictionary[GMWMApp, int] = weakref.WeakKeyDictionary()
_SERIAL = itertools.count()


# Save the WV plot as an image (PNG or SVG) in the browser; the file name follows the data.
_EXPORT_JS = """
const view = Bokeh.index.find_one(plot);
if (view == null) { return; }
view.export("KIND").to_blob().then((blob) => {
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = (save.filename || "gmwm_wv") + ".KIND";
  link.dispatchEvent(new MouseEvent("click"));
});
"""


def _lazy_view_factories() -> list[tuple[str, Callable[[AppState, Jobs], Any]]]:
    """Tabs built on first opening: (title, view class taking the state and the jobs)."""
    from gmwm_app.check_view import CheckView
    from gmwm_app.multi_view import MultiView
    from gmwm_app.plan_view import PlanView
    from gmwm_app.slope_view import SlopeView

    return [
        ("Model selection", SelectionView),
        ("Slope method", SlopeView),
        ("Multi-channel", MultiView),
        ("Datasheet check", CheckView),
        ("Plan", PlanView),
    ]


def live_apps() -> list[GMWMApp]:
    """The app objects of the sessions alive in this process, oldest first.

    For tests and diagnostics: the last item is the most recently opened session.
    """
    items = list(_APPS.items())
    return [app for app, _ in sorted(items, key=lambda kv: kv[1])]


def set_listed(app: GMWMApp, listed: bool) -> None:
    """List ``app`` in :func:`live_apps` as the newest session (True), or not at all (False).

    A page built ahead of its session (:class:`gmwm_app.server.PagePool`) is not a session's
    until it is handed over: the pool unlists it when it is built and lists it then.
    """
    if listed:
        _APPS[app] = next(_SERIAL)
    else:
        _APPS.pop(app, None)


#: The state parameters the WV plot and the residual strip draw (the channel, fs and the
#: robust choice through the WV: set alone by their widgets, they are drawn with their WV).
_PLOT = (
    "wv",
    "wv_raw",
    "unit",
    "filename",
    "model",
    "result",
    "whatif",
    "whatif_values",
)
#: ... the parameter and datasheet tables and the J-test badge.
_TABLES = (
    "wv",
    "unit",
    "model",
    "result",
    "whatif",
    "whatif_values",
    "show_intervals",
    "inferred",
)
#: ... the data description.
_DATA_INFO = (
    "wv",
    "unit",
    "is_summary",
    "filename",
    "source",
    "n",
    "duration_s",
    "fs_source",
)
#: ... the fit summary line.
_SUMMARY = ("wv", "model", "result", "whatif", "whatif_values")  # (weights: by the refit)
#: ... the file names of the downloads (:meth:`AppState.export_filename`).
_FILENAMES = ("filename", "wv", "model")  # (the channel shown: that of the WV)
#: ... the URL's data and model (:meth:`AppState.to_query`; the plain parameters,
#: :attr:`AppState.URL_SYNCED`, are Panel's: :meth:`GMWMApp.link_url`).
_QUERY = ("source", "path", "channel", "fs", "robust", "compensate", "model")
#: ... the temperature compensation switch (shown with a temperature channel beside the
#: channel, disabled with the reason when it cannot be used).
_COMPENSATION = ("temperature_channel", "compensation_unavailable")
#: ... the "Model selection" tab (its refresh, called while the tab is not its own watcher).
_SELECTION = ("selection", "inferred", "unit")


def _on_state(*names: str) -> Any:
    """``param.depends`` on parameters of the ``state`` sub-object, run on every change."""
    return param.depends(*(f"state.{n}" for n in names), watch=True)


class GMWMApp(pn.viewable.Viewer):
    """Widgets, views and callbacks of one session, around an :class:`AppState`.

    Parameters
    ----------
    state : AppState, optional
        The session state (a new one by default).
    default_source : {"demo", "path"}
        What to load when the URL names no data.
    default_path : str
        Server path loaded when ``default_source == "path"`` (the ``gmwm-app FILE`` argument).
    """

    state = state_param()

    def __init__(
        self, state: AppState | None = None, *, default_source: str = "demo", default_path: str = ""
    ) -> None:
        super().__init__(state=state or AppState())
        self.default_source = default_source
        self.default_path = default_path
        self.views = WVFigures()
        self.ready = False
        self._last_query: dict[str, str] | None = None
        self._url_linked = False  # the URL follows the state (link_url)
        self.last_refresh_s = 0.0  # the last WV plot redraw (s), the bulk of a redraw
        self.busy = False
        self._query: dict[str, Any] = {}
        self._prefetched: Future | None = None
        # the session's job runner (async continuations lose pn.state.curdoc: it keeps it)
        self.jobs = Jobs(pn.state.curdoc)
        # each state change reaches the browser as one message, whichever part it redraws
        # (Panel holds the document in a job's continuation only if asked; a widget's or a
        # button's callback is not held: 19 messages a click before)
        self.state.batch = partial(pn.io.hold, self.jobs.doc)
        if self.served:  # the state's own background work (intervals) runs as the session's job
            self.state.offload = self.jobs.run
        self.state.wv_job = self._wv_job  # ... and its WVs as page loads (indicator, progress)
        self._location = pn.state.location if self.served else None
        self._build_widgets()
        self._build_layout()
        self.jobs.busy = self._busy
        self.jobs.failed = self._load_failed
        self.jobs.settled = self._settled
        self.jobs.install = self.install
        boundary.attach(self.jobs.doc, self.state.report_error)  # this session's failures
        self.refresh()
        _APPS[self] = next(_SERIAL)

    # -------------------------------------------------------------------------------------
    # widgets and layout
    # -------------------------------------------------------------------------------------
    def _build_widgets(self) -> None:
        s = self.state
        self.demo_button = pn.widgets.Button(
            label="Load the demo log", color="default", sizing_mode="stretch_width"
        )
        self.demo_button.on_click(self._on_demo)
        self.upload = BoundedFileDropper(  # limited while it arrives: gmwm_app.upload
            multiple=False, layout="compact", sizing_mode="stretch_width", height=90
        )
        self.upload.param.watch(self._on_upload, "value")
        self.jobs.on_close(self.upload.drop_partial)  # no partial upload outlives its session
        self.upload.param.watch(self._on_upload_refused, "refused")
        self.still_only = pn.widgets.Checkbox(  # engine.io.segments: a flight's still parts
            label="Flight log: analyse its still segments only", value=False
        )
        self.path_input = pn.widgets.TextInput(
            label="Log file on the server",
            placeholder="/path/to/log.h5 (press Enter)",
            sizing_mode="stretch_width",
        )
        self.path_input.param.watch(self._on_path, "enter_pressed")
        self.path_button = pn.widgets.Button(
            label="Load path", color="default", sizing_mode="stretch_width"
        )
        self.path_button.on_click(self._on_path)
        # the data choices: the state's own parameters, which it shows itself when they
        # change (AppState._data_changed: a WV job for the channel and the robust WV)
        self.channel_select = pn.widgets.Select.from_param(
            s.param.channel, sizing_mode="stretch_width"
        )
        self.fs_input = pn.widgets.FloatInput.from_param(
            s.param.fs, sizing_mode="stretch_width", format="0[.]########"
        )
        self.data_info = pn.pane.Markdown(
            "", sizing_mode="stretch_width", styles={"font-size": "13px"}, margin=(0, 10)
        )
        self.robust_check = pn.widgets.Checkbox.from_param(
            s.param.robust, css_classes=["gmwm-robust"]
        )
        # the state's own parameter (auto / always / off): a change refits on the
        # compensated or the raw WV
        self.compensate_choice = pn.widgets.Select.from_param(
            s.param.compensate, css_classes=["gmwm-compensate"], visible=False
        )
        self.data_info.object = self._data_info_text

        self.model_panel = ModelPanel(self.state)
        self.download = download_button(
            self._export_json, "gmwm_fit.json", "Download fit (JSON)", "primary"
        )
        # the calibration report of the session's fit (engine.reporting, not refitted)
        self.report_download = download_button(
            self._export_report, "gmwm_report.html", "Download report (HTML)"
        )
        # plot images are made in the browser by BokehJS (PlotView.export), like the toolbar's
        # save tool, but in either format whatever the plot's output backend
        self.png_button = pn.widgets.Button(
            label="Plot as PNG", color="default", width=150, margin=(3, 5)
        )
        self.svg_button = pn.widgets.Button(
            label="Plot as SVG", color="default", width=150, margin=(3, 5)
        )
        for btn, kind in ((self.png_button, "png"), (self.svg_button, "svg")):
            btn.js_on_click(
                args={"plot": self.views.figure, "save": self.views.save_tool},
                code=_EXPORT_JS.replace("KIND", kind),
            )

        # main area: the messages follow the state
        self.alert = hidden_alert("danger", s.param.error)
        self.notice = hidden_alert("info", s.param.notice)
        self.log_check = hidden_alert("secondary", s.param.log_check)  # engine.io.qualify
        # the check's offer: drop the warm-up it found (engine.io.drop_warmup), as --drop-warmup
        start = param.rx(s.param.warmup_start)
        self.drop_warmup_button = pn.widgets.Button(
            label=start.rx.pipe(lambda n: f"Drop the warm-up: keep from sample {n:,}"),
            visible=start.rx.bool(),
            color="warning",
            margin=(0, 10),
        )
        self.drop_warmup_button.on_click(self._on_drop_warmup)
        self.temperature = hidden_alert("info", s.param.temperature)  # compensated signal
        self.warning = hidden_alert("warning")  # (_show_warnings)
        self.status = pn.pane.Markdown(
            "",
            sizing_mode="stretch_width",
            margin=(0, 10),
            styles={"color": "#555", "font-size": "13px"},
        )
        self.plot_pane = pn.pane.Bokeh(
            self.views.figure, sizing_mode="stretch_width", margin=(5, 10)
        )
        self.resid_pane = pn.pane.Bokeh(
            self.views.residual, sizing_mode="stretch_width", margin=(0, 10)
        )
        self.summary = pn.pane.Markdown(
            self._summary_text, sizing_mode="stretch_width", margin=(0, 10)
        )
        self.tables = FitTables()
        self.param_table = pn.pane.Bokeh(
            self.tables.params, sizing_mode="stretch_width", margin=(5, 10)
        )
        self.datasheet_table = pn.pane.Bokeh(
            self.tables.datasheet, sizing_mode="stretch_width", margin=(5, 10)
        )
        # 95% intervals in the parameter table and the J-test badge (computed off the loop)
        self.intervals_check = pn.widgets.Checkbox.from_param(
            s.param.show_intervals,
            label="Intervals (95%, asymptotic) and goodness of fit",
            css_classes=["gmwm-intervals"],
            margin=(0, 10),
        )
        self.jtest_pane = pn.pane.HTML("", margin=(0, 10), visible=False)
        # session download/restore, Kalibr and datasheet exports, time-gap box
        self.session_panel = SessionPanel(self.state, self.jobs)

    def _build_layout(self) -> None:
        h = pn.pane.Markdown
        sidebar = [
            h("### Data", margin=(0, 10)),
            self.demo_button,
            h(
                "Upload a log (CSV/TSV/text, NPY/NPZ, HDF5, WV summary HDF5, ROS bag, PX4 .ulg, "
                "ArduPilot .bin):",
                margin=(0, 10),
                styles={"font-size": "13px"},
            ),
            self.upload,
            self.still_only,
            self.path_input,
            self.path_button,
            self.channel_select,
            self.fs_input,
            self.data_info,
            self.robust_check,
            self.compensate_choice,
            pn.layout.Divider(),
            *self.model_panel.sidebar(),
            h("### Export", margin=(0, 10)),
            self.download,
            self.report_download,
            pn.Row(self.png_button, self.svg_button, margin=(0, 5)),
            h(
                "The plot toolbar's save tool also saves a PNG; each plot's toolbar zooms "
                "and pans.",
                margin=(0, 10),
                styles={"font-size": "12px", "color": "#555"},
            ),
            *self.session_panel.sidebar(),
        ]
        tables = pn.Row(
            pn.Column(
                h("#### Parameters", margin=(0, 10)),
                self.intervals_check,
                self.jtest_pane,
                self.param_table,
                width=540,
            ),
            pn.Column(
                h("#### Datasheet values", margin=(0, 10)),
                self.datasheet_table,
                sizing_mode="stretch_width",
            ),
            sizing_mode="stretch_width",
        )
        # visibility and loading are set on layouts, not on the Bokeh panes (Panel 1.9.4
        # fails on Layoutable changes of a Bokeh pane: "Bokeh.stylesheets items must be str")
        self.resid_box = pn.Column(self.resid_pane, sizing_mode="stretch_width", margin=0)
        self.segments = SegmentsStrip()  # a flight analysed on its still segments
        self.plot_box = pn.Column(
            self.plot_pane, self.resid_box, self.segments.box, sizing_mode="stretch_width", margin=0
        )
        main: list[Any] = [
            pn.Column(
                self.alert,
                *self.session_panel.main(),
                self.notice,
                self.log_check,
                self.drop_warmup_button,
                self.temperature,
                self.warning,
                self.status,
                self.plot_box,
                self.summary,
                tables,
                sizing_mode="stretch_width",
            )
        ]
        self.tabs = pn.Tabs(("Fit", main[0]), dynamic=False, sizing_mode="stretch_width")
        # the other views are built on first opening of their tab (or first use): a page
        # opens with the Fit tab only, about half the models of a page with every tab built
        self.lazy_views: dict[str, Any] = {}
        self._lazy_factories: dict[str, Callable[..., Any]] = {}
        self._titles = ["Fit"]
        for title, factory in _lazy_view_factories():
            self._lazy_factories[title] = partial(factory, self.state, self.jobs)
            self._titles.append(title)
            self.tabs.append(
                (
                    title,
                    pn.Column(
                        pn.pane.Markdown(f"Opening {title} ...", margin=(10, 10)),
                        sizing_mode="stretch_width",
                        margin=0,
                    ),
                )
            )
        self.tabs.param.watch(self._on_tab, "active")
        main = [self.tabs]
        # BootstrapTemplate: every resource is bundled with Panel (the Fast design pulls a web
        # font from a CDN, which is a console error offline)
        self.template = pn.template.BootstrapTemplate(
            title="GMWM: stochastic calibration of inertial sensors",
            # the sidebar as one root: the template adds each root with a walk of the whole
            # document, so 30 roots made opening a page take twice as long on the server loop
            sidebar=[pn.Column(*sidebar, sizing_mode="stretch_width", margin=0)],
            main=main,
            sidebar_width=360,
            header_background="#1F4E8C",
            # no header spinner: Panel's shows whether *any* session of the process is busy
            # (pn.state.busy), so that each callback of one session sent two changes to every
            # open page (30 open pages: 60 messages per click); the session's own loading
            # indicators and status line show its work
            busy_indicator=None,
        )

    def view(self) -> pn.template.BootstrapTemplate:
        """The page of this session."""
        return self.template

    def open_view(self, title: str) -> Any:
        """The view of the lazily built tab ``title``, built on first call.

        Parameters
        ----------
        title : str
            Tab title, e.g. ``"Slope method"`` or ``"Multi-channel"``.

        Returns
        -------
        panel.viewable.Viewer
            The view (its ``panel`` is shown in the tab; its ``active`` parameter says
            whether the tab is shown).
        """
        if title not in self.lazy_views:
            view = self._lazy_factories[title](active=self._shown(title))
            self.lazy_views[title] = view
            index = self._titles.index(title)
            self.tabs[index] = (title, view.panel)
        return self.lazy_views[title]

    @property
    def selection(self) -> SelectionView:
        """The "Model selection" view (built on first use)."""
        return self.open_view("Model selection")

    def _shown(self, title: str) -> bool:
        """Whether the tab ``title`` is the one shown."""
        return 0 <= self.tabs.active < len(self._titles) and self._titles[self.tabs.active] == title

    def _on_tab(self, event: Any) -> None:
        title = self._titles[event.new]
        if title in self._lazy_factories and title not in self.lazy_views:
            self.open_view(title)  # a failure: Panel's callback -> gmwm_app.boundary
        for name, view in self.lazy_views.items():
            view.active = self._shown(name)

    # -------------------------------------------------------------------------------------
    # state -> page: each part depends on the state parameters it draws
    # -------------------------------------------------------------------------------------
    def __panel__(self) -> pn.template.BootstrapTemplate:  # type: ignore[override]
        # a template, which Panel renders as a page (Panel types __panel__ as a Viewable)
        return self.template

    def refresh(self) -> None:
        """Draw every part of the Fit tab from the state (the page's first draw; afterwards
        each part redraws itself when a parameter it depends on changes)."""
        with self.state.batch():
            self._draw_plot()
            self._draw_segments()
            self._draw_tables()
            self._sync_compensation()
            self._sync_filenames()
            self._show_warnings()
            self.model_panel.refresh()

    @_on_state(*_PLOT)
    @redraws("the WV plot")
    def _draw_plot(self) -> None:
        t0 = time.perf_counter()
        s = self.state
        self.views.update(s)
        self.resid_box.visible = s.display_model() is not None
        self.last_refresh_s = time.perf_counter() - t0

    @_on_state("wv", "filename")
    @redraws("the still segments")
    def _draw_segments(self) -> None:
        self.segments.update(self.state.log, self.state.channel)

    @_on_state(*_TABLES)
    @redraws("the parameter tables")
    def _draw_tables(self) -> None:
        s = self.state
        self.tables.update(s)
        show = bool(s.show_intervals and s.result is not None and not s.whatif)
        if show:  # the state's intervals (computed off the loop, drawn when installed)
            s.ensure_inference(s.result)
        badge = jtest_badge(s.inference(), pending=True) if show else ""
        self.jtest_pane.param.update(object=badge, visible=bool(badge))

    @_on_state(*_SELECTION)
    @redraws("the model selection")
    def _refresh_selection(self) -> None:
        if "Model selection" in self.lazy_views:
            self.selection.refresh()

    @_on_state(*_COMPENSATION)
    @redraws("the temperature compensation switch")
    def _sync_compensation(self) -> None:
        s = self.state
        why = s.compensation_unavailable
        label = f"Temperature compensation ('{s.temperature_channel}')"
        self.compensate_choice.param.update(
            visible=bool(s.temperature_channel),
            disabled=bool(why),
            name=f"{label}: not available, {why}" if why else label,
        )

    @param.depends(*(f"state.{n}" for n in _DATA_INFO))
    @redraws("the data description")
    def _data_info_text(self) -> str:
        s = self.state
        if s.wv is None:
            return "No data loaded."
        u = (s.unit or "unknown unit (set it in the file)").replace("^2", "²")
        kind = "WV summary file (no raw samples)" if s.is_summary else "raw log"
        return (
            f"**{s.filename}** ({kind}, source: {s.source})  \n"
            f"N = {s.n:,} samples, duration {format_value(s.duration_s)} s "
            f"({s.duration_s / 3600:.2f} h)  \n"
            f"fs = {s.fs:g} Hz ({s.fs_source}), unit: {u}, {len(s.wv)} WV levels"
        )

    @param.depends(*(f"state.{n}" for n in _SUMMARY))
    @redraws("the fit summary")
    def _summary_text(self) -> str:
        return fit_summary(self.state)

    @_on_state("result", "whatif")
    @redraws("the fit warnings")
    def _show_warnings(self) -> None:
        s = self.state
        warn = s.warnings() if not s.whatif else []
        text = "**Fit warning**: " + "; ".join(warn) if warn else ""
        self.warning.param.update(object=text, visible=bool(text))

    @_on_state(*_FILENAMES)
    def _sync_filenames(self) -> None:
        name = self.state.export_filename()
        self.download.filename = name
        self.views.save_tool.filename = name[:-5].replace("+", "_")

    def link_url(self, location: Any) -> None:
        """Keep the page's URL (a :class:`panel.io.location.Location`) in step with the state,
        from the first data shown on (:meth:`_settled`).

        The plain parameters (:attr:`AppState.URL_SYNCED`) are synced both ways by Panel
        (``location.sync``): a change of the state writes them, a change of the URL sets them
        (a value the parameter refuses is reported as the link's problem). The data and the
        model are written by :meth:`_sync_url`, and read once, when the page opens
        (:meth:`prefetch`, :meth:`start`).
        """
        self._location = location
        location.sync(self.state, dict(self.state.URL_SYNCED), on_error=self._url_refused)
        self._url_linked = True
        self._sync_url()

    def _url_refused(self, values: dict[str, Any]) -> None:
        """Values of the URL's plain parameters that the state refuses: the link's problems
        (those of the link the page opened with were reported when it was read)."""
        if self._url_linked:
            s = self.state
            problems = s.parse_query({s.URL_SYNCED[k]: v for k, v in values.items()})["problems"]
            s.report_error("; ".join(problems) or f"the link's {', '.join(values)} not used")

    @_on_state(*_QUERY)
    def _sync_url(self) -> None:
        """Write the data and the model into the URL (Panel writes the plain parameters)."""
        if not self.ready or self._location is None or not self._url_linked:
            return
        synced = set(self.state.URL_SYNCED.values())
        q = {k: v for k, v in self.state.to_query().items() if k not in synced}
        if q != self._last_query:
            self._last_query = q
            now = self._location.query_params
            kept = {k: str(now[k]) for k in self.state.URL_SYNCED.values() if k in now}
            self._location.search = "?" + urlencode({**q, **kept}, safe="*/")

    # -------------------------------------------------------------------------------------
    # heavy work off the event loop (gmwm_app.jobs)
    # -------------------------------------------------------------------------------------
    @property
    def served(self) -> bool:
        """True when this page is served (a server loop applies the jobs' results)."""
        return self.jobs.served

    def _busy(self, on: bool, message: str = "") -> None:
        self.busy = on
        with self.state.batch():  # the indicator, the text and 4 widgets: one message
            self.plot_box.loading = on  # (not on the Bokeh pane itself: Panel 1.9 fails there)
            self.status.object = f"⏳ {message} ..." if on else ""
            for w in (self.demo_button, self.path_button, self.upload, self.channel_select):
                w.disabled = on

    def _load_failed(self, message: str, err: BaseException) -> None:
        boundary.report(err, message, self.state.report_error)
        self.session_panel.failed(err)  # time gaps: offer the longest segment
        if self.upload.value:
            self.upload.value = {}  # free a refused upload's bytes (a retry keeps its own)

    def _settled(self) -> None:
        self.ready = True
        if not self._url_linked and self._location is not None:
            self.link_url(self._location)
        self._sync_url()

    def prefetch(self) -> Future:
        """Start reading the data the URL names in a worker thread, while the page loads;
        returns the read's future."""
        query = dict(self._location.query_params) if self._location is not None else {}
        self._query = query
        self._prefetched = self.jobs.submit(
            partial(self.state.prepare_query, query, self.default_source, self.default_path)
        )
        return self._prefetched

    async def start(self) -> None:
        """Show the data named by the URL (or the default) once the page has opened."""
        prefetched = self._prefetched if self._prefetched is not None else self.prefetch()
        query = self._query

        def apply(prepared: Any) -> None:
            with self.state.batch():  # one message to the browser for every part redrawn
                self.state.from_query(
                    query,
                    prepared=prepared,
                    default_source=self.default_source,
                    default_path=self.default_path,
                )

        self.jobs.load("Loading the data and computing its wavelet variance", prefetched, apply)

    def start_sync(self) -> None:
        """Synchronous :meth:`start` (no server: tests, notebooks)."""
        self.state.from_query(
            {}, default_source=self.default_source, default_path=self.default_path
        )
        self.ready = True

    # -------------------------------------------------------------------------------------
    # callbacks (synchronous watchers; heavy work runs as a job)
    # -------------------------------------------------------------------------------------
    def _on_demo(self, _event: Any = None) -> None:
        self.jobs.load("Loading the demo log", partial(self.state.read_and_warm, "demo"))

    def _on_upload(self, event: Any) -> None:
        files = event.new or {}
        if not files:
            return
        name, data = list(files.items())[-1]
        segments = "auto" if self.still_only.value else None
        self.jobs.load(
            f"Reading {name}",
            partial(
                self.state.read_and_warm, "upload", data=data, filename=name, segments=segments
            ),
        )

    def _on_upload_refused(self, event: Any) -> None:
        if event.new:
            self.state.report_error(event.new)
            self.upload.refused = ""  # the same refusal again is reported again

    def _on_path(self, _event: Any = None) -> None:
        path = (self.path_input.value_input or self.path_input.value or "").strip()
        if not path:
            self.state.report_error("Type the path of a log file on the server first")
            return
        segments = "auto" if self.still_only.value else None
        self.jobs.load(
            f"Reading {path}",
            partial(self.state.read_and_warm, "path", path=path, segments=segments),
        )

    def _on_drop_warmup(self, _event: Any = None) -> None:
        n = self.state.warmup_start
        if n <= 0:
            return
        self.jobs.load(
            f"Dropping the first {n:,} samples (warm-up)",
            partial(self.state.without_warmup, self.session_panel.load_options),
        )

    def install(self, loaded: Any) -> None:
        """Make newly read data the session's (and remember how they were read)."""
        with self.state.batch():  # one message to the browser for every part redrawn
            self.session_panel.loaded(loaded)
            self.state.install(loaded)
            if self.upload.value:
                self.upload.value = {}  # free an upload's bytes

    def _wv_job(
        self,
        message: str,
        work: Callable[[Callable[[int, int], object]], Any],
        apply: Callable[[Any], Any],
        fail: Callable[[BaseException], Any],
    ) -> None:
        """The state's WV jobs (:data:`gmwm_app.state.WVJob`): page loads with the loading
        indicator and the levels' progress, applied under the session's hold."""
        self.jobs.load(message, work, partial(self._held, apply), progress=True, fail=fail)

    def _held(self, action: Callable[..., Any], *args: Any) -> Any:
        """Run a job's continuation under the session's hold (:attr:`AppState.batch`): the
        state changes it makes, each held already, reach the browser together."""
        with self.state.batch():
            return action(*args)

    def _export_json(self) -> io.StringIO:
        return io.StringIO(self.state.export_json())

    def _export_report(self) -> io.StringIO:
        self.report_download.filename = report_filename(self.state)
        return report_file(self.state)


def create_app(
    *, source: str = "demo", path: str = "", load: bool = True
) -> pn.template.BootstrapTemplate:
    """Build the page of one browser session (a fresh :class:`AppState`).

    Parameters
    ----------
    source : {"demo", "path"}
        What to load when the URL query names no data.
    path : str
        Server path to load when ``source == "path"`` (``gmwm-app FILE``).
    load : bool
        Load the data when the page opens (in a worker thread, with a loading indicator);
        outside a server the data are loaded at once.

    Returns
    -------
    panel.template.BootstrapTemplate
        The page; its ``gmwm_app`` attribute is the :class:`GMWMApp`.
    """
    boundary.install()  # Panel's exception handler: every failure shown in its session
    app = GMWMApp(default_source=source, default_path=path)
    page = app.view()
    page.gmwm_app = app  # type: ignore[attr-defined]
    if load:
        if pn.state.curdoc is not None and pn.state.curdoc.session_context is not None:
            app.prefetch()  # the file is read while the browser loads the page
            pn.state.onload(app.start)
        else:
            app.start_sync()
    return page


if __name__.startswith("bokeh"):  # `panel serve gmwm_app/app.py`
    create_app().servable(title="GMWM")


def app_of(page: Any) -> GMWMApp:
    """The :class:`GMWMApp` of a page built by :func:`create_app` (its ``gmwm_app``)."""
    app: GMWMApp = page.gmwm_app
    return app
