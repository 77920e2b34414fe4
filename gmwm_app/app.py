"""The GMWM browser app: one :func:`create_app` per browser session.

Layout: a sidebar with the data (demo, upload, server path, channel, fs, robust WV), the model
builder (one add button per process, a remove button per process, a text spec), the what-if
sliders and the exports; the main area with messages, the WV plot, the residual strip, the
fit summary and the parameter and datasheet tables.

Responsiveness: reading a file and computing a WV run in a worker thread (the event loop,
and so every other session, stays free) with a loading indicator; a fit takes milliseconds and
runs inline; every redraw replaces ColumnDataSource data in place (``views.WVFigures``).

Serve with ``gmwm-app`` / ``python -m gmwm_app``, or ``panel serve gmwm_app/app.py``.
"""

from __future__ import annotations

import asyncio
import io
import logging
import sys
import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

if __package__ in (None, ""):  # run as a script by `panel serve gmwm_app/app.py`
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pandas as pd  # noqa: E402
import panel as pn  # noqa: E402
from bokeh.models import CustomJSTickFormatter  # noqa: E402

from gmwm_app.state import (  # noqa: E402
    PROCESS_CODES,
    PROCESS_NAMES,
    AppState,
    SliderSpec,
    format_value,
)
from gmwm_app.views import (  # noqa: E402
    WVFigures,
    component_color,
    datasheet_rows,
    fit_summary,
    parameter_rows,
)

__all__ = ["GMWMApp", "create_app", "create_app_factory", "live_apps"]

log = logging.getLogger(__name__)

pn.extension("tabulator", "filedropper", notifications=False)

_APPS: weakref.WeakSet[GMWMApp] = weakref.WeakSet()

_PROCESS_HELP = {
    "WN": "white noise: WV falls as 1/τ (angle/velocity random walk)",
    "QN": "quantization noise: WV falls as 1/τ²",
    "RW": "random walk: WV rises as τ (rate random walk)",
    "DR": "drift (rate ramp): WV rises as τ²",
    "AR1": "first-order autoregression (per sample phi, sigma2)",
    "GM": "Gauss-Markov: a bump at its correlation time 1/beta (bias instability)",
}

_CSS = """
.gmwm-proc-label { font-size: 13px; line-height: 28px; white-space: nowrap; }
.gmwm-swatch { display: inline-block; width: 14px; height: 4px; margin: 0 6px 3px 0; }
"""


def live_apps() -> list[GMWMApp]:
    """The app objects of the sessions alive in this process (for tests and diagnostics)."""
    return list(_APPS)


class GMWMApp:
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

    def __init__(self, state: AppState | None = None, *, default_source: str = "demo",
                 default_path: str = "") -> None:
        self.state = state or AppState()
        self.default_source = default_source
        self.default_path = default_path
        self.views = WVFigures()
        self._syncing = False
        self._ready = False
        self._job = 0
        self._last_query: dict[str, str] | None = None
        self._proc_key: tuple | None = None
        self._slider_key: Any = None
        self.last_refresh_s = 0.0
        self._build_widgets()
        self._build_layout()
        self.state.param.watch(self._on_state, "revision")
        self.refresh()
        _APPS.add(self)

    # -------------------------------------------------------------------------------------
    # widgets and layout
    # -------------------------------------------------------------------------------------
    def _build_widgets(self) -> None:
        s = self.state
        self.demo_button = pn.widgets.Button(name="Load the demo log", button_type="default",
                                             sizing_mode="stretch_width")
        self.demo_button.on_click(self._on_demo)
        self.upload = pn.widgets.FileDropper(
            multiple=False, max_file_size="2000MB", chunk_size=8_000_000, layout="compact",
            sizing_mode="stretch_width", height=90, name="upload",
        )
        self.upload.param.watch(self._on_upload, "value")
        self.path_input = pn.widgets.TextInput(
            name="Log file on the server", placeholder="/path/to/log.h5 (press Enter)",
            sizing_mode="stretch_width")
        self.path_input.param.watch(self._on_path, "enter_pressed")
        self.path_button = pn.widgets.Button(name="Load path", button_type="default",
                                             sizing_mode="stretch_width")
        self.path_button.on_click(self._on_path)
        self.channel_select = pn.widgets.Select(name="Channel", options=[],
                                                sizing_mode="stretch_width")
        self.channel_select.param.watch(self._on_channel, "value")
        self.fs_input = pn.widgets.FloatInput(name="Sampling frequency fs [Hz]", value=None,
                                              start=0.0, sizing_mode="stretch_width",
                                              format="0[.]########")
        self.fs_input.param.watch(self._on_fs, "value")
        self.data_info = pn.pane.Markdown("", sizing_mode="stretch_width",
                                          styles={"font-size": "13px"}, margin=(0, 10))
        self.robust_check = pn.widgets.Checkbox(
            name="Robust WV (Tukey biweight, 60% efficiency), beside the classical one",
            value=s.robust)
        self.robust_check.param.watch(self._on_robust, "value")

        self.add_buttons = {}
        for code in PROCESS_CODES:
            b = pn.widgets.Button(name=f"+ {code}", button_type="primary", button_style="outline",
                                  description=f"Add {_PROCESS_HELP[code]}", width=82,
                                  margin=(3, 3))
            b.on_click(lambda _e, c=code: self._add(c))
            self.add_buttons[code] = b
        self.spec_input = pn.widgets.TextInput(
            name="Model (type a spec, press Enter)", placeholder="e.g. WN+RW+2*GM",
            sizing_mode="stretch_width")
        self.spec_input.param.watch(self._on_spec, "enter_pressed")
        self.process_list = pn.Column(sizing_mode="stretch_width", margin=0)
        self.clear_button = pn.widgets.Button(name="Remove all", button_type="light",
                                              width=100, margin=(3, 3))
        self.clear_button.on_click(lambda _e: self.state.clear_model())

        self.whatif_toggle = pn.widgets.Switch(name="What if", value=False, margin=(8, 10))
        self.whatif_toggle.param.watch(self._on_whatif, "value")
        self.sliders = pn.Column(sizing_mode="stretch_width", margin=0, visible=False)
        self.reset_button = pn.widgets.Button(name="Back to the fit", button_type="light",
                                              width=130, margin=(3, 3))
        self.reset_button.on_click(lambda _e: self._reset_whatif())
        self.fit_button = pn.widgets.Button(name="Fit from here", button_type="primary",
                                            width=130, margin=(3, 3),
                                            description="Refit using the slider values as a "
                                                        "starting point")
        self.fit_button.on_click(lambda _e: self._fit_from_whatif())
        self.whatif_buttons = pn.Row(self.reset_button, self.fit_button, visible=False)

        self.download = pn.widgets.FileDownload(
            callback=self._export_json, filename="gmwm_fit.json", label="Download fit (JSON)",
            button_type="primary", sizing_mode="stretch_width", embed=False)
        self.plot_format = pn.widgets.RadioButtonGroup(
            name="Plot export format", options=["PNG", "SVG"], value="PNG",
            button_type="default", margin=(3, 10))
        self.plot_format.param.watch(self._on_plot_format, "value")

        # main area
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False,
                                   sizing_mode="stretch_width", margin=(5, 10))
        self.notice = pn.pane.Alert("", alert_type="info", visible=False,
                                    sizing_mode="stretch_width", margin=(5, 10))
        self.warning = pn.pane.Alert("", alert_type="warning", visible=False,
                                     sizing_mode="stretch_width", margin=(5, 10))
        self.status = pn.pane.Markdown("", sizing_mode="stretch_width", margin=(0, 10),
                                       styles={"color": "#555", "font-size": "13px"})
        self.plot_pane = pn.pane.Bokeh(self.views.figure, sizing_mode="stretch_width",
                                       height=500, margin=(5, 10))
        self.resid_pane = pn.pane.Bokeh(self.views.residual, sizing_mode="stretch_width",
                                        height=190, margin=(0, 10))
        self.summary = pn.pane.Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        common = dict(show_index=False, disabled=True, sizing_mode="stretch_width",
                      layout="fit_data_stretch", selectable=False, theme="simple",
                      margin=(5, 10), min_height=60)
        self.param_table = pn.widgets.Tabulator(
            pd.DataFrame(columns=["process", "parameter", "value", "unit"]),
            name="parameters", **common)
        self.datasheet_table = pn.widgets.Tabulator(
            pd.DataFrame(columns=["process", "quantity", "value", "unit"]),
            name="datasheet", **common)

    def _build_layout(self) -> None:
        h = pn.pane.Markdown
        sidebar = [
            h("### Data", margin=(0, 10)),
            self.demo_button,
            h("Upload a log (CSV/TSV/text, NPY/NPZ, HDF5, WV summary HDF5):",
              margin=(0, 10), styles={"font-size": "13px"}),
            self.upload,
            self.path_input, self.path_button,
            self.channel_select, self.fs_input, self.data_info, self.robust_check,
            pn.layout.Divider(),
            h("### Model", margin=(0, 10)),
            pn.FlexBox(*self.add_buttons.values(), margin=(0, 5)),
            self.spec_input,
            self.process_list,
            self.clear_button,
            pn.layout.Divider(),
            pn.Row(h("### What if", margin=(0, 10)), self.whatif_toggle),
            h("Move each parameter on a log scale; the curves follow as you drag.",
              margin=(0, 10), styles={"font-size": "12px", "color": "#555"}),
            self.sliders, self.whatif_buttons,
            pn.layout.Divider(),
            h("### Export", margin=(0, 10)),
            self.download,
            h("Plot image: the save tool of the plot toolbar, as", margin=(0, 10),
              styles={"font-size": "12px", "color": "#555"}),
            self.plot_format,
        ]
        tables = pn.Row(
            pn.Column(h("#### Parameters", margin=(0, 10)), self.param_table,
                      sizing_mode="stretch_width"),
            pn.Column(h("#### Datasheet values", margin=(0, 10)), self.datasheet_table,
                      sizing_mode="stretch_width"),
            sizing_mode="stretch_width",
        )
        main = [pn.Column(self.alert, self.notice, self.warning, self.status, self.plot_pane,
                          self.resid_pane, self.summary, tables, sizing_mode="stretch_width")]
        self.template = pn.template.FastListTemplate(
            title="GMWM: stochastic calibration of inertial sensors",
            sidebar=sidebar, main=main, sidebar_width=350, theme_toggle=False,
            accent="#1F5FAD", main_layout=None, raw_css=[_CSS],
        )

    def view(self) -> pn.template.FastListTemplate:
        """The page of this session."""
        return self.template

    # -------------------------------------------------------------------------------------
    # refresh (state -> widgets and views)
    # -------------------------------------------------------------------------------------
    def _on_state(self, _event: Any = None) -> None:
        self.refresh()

    def refresh(self) -> None:
        """Bring every view and widget in line with the state (in place, one batch)."""
        t0 = time.perf_counter()
        s = self.state
        self._syncing = True
        try:
            with pn.io.hold():
                self.views.update(s)
                self._refresh_tables()
                self._refresh_data_widgets()
                self._refresh_process_list()
                self._refresh_sliders()
                self._refresh_messages()
                self.download.filename = s.export_filename()
        finally:
            self._syncing = False
        self._sync_url()
        self.last_refresh_s = time.perf_counter() - t0

    def _refresh_tables(self) -> None:
        s = self.state
        self.param_table.value = pd.DataFrame(
            parameter_rows(s), columns=["process", "parameter", "value", "unit"])
        self.datasheet_table.value = pd.DataFrame(
            datasheet_rows(s), columns=["process", "quantity", "value", "unit"])
        self.summary.object = fit_summary(s)

    def _refresh_data_widgets(self) -> None:
        s = self.state
        if list(self.channel_select.options) != list(s.channels):
            self.channel_select.options = list(s.channels)
        if s.channel and self.channel_select.value != s.channel:
            self.channel_select.value = s.channel
        if s.fs is not None and self.fs_input.value != s.fs:
            self.fs_input.value = s.fs
        if self.robust_check.value != s.robust:
            self.robust_check.value = s.robust
        if self.whatif_toggle.value != s.whatif:
            self.whatif_toggle.value = s.whatif
        spec = s.model.spec()
        if self.spec_input.value != spec:
            self.spec_input.value = spec
        if s.wv is None:
            self.data_info.object = "No data loaded."
        else:
            u = s.unit or "unknown unit (set it in the file)"
            kind = "WV summary file (no raw samples)" if s.is_summary else "raw log"
            self.data_info.object = (
                f"**{s.filename}** ({kind}, source: {s.source})  \n"
                f"N = {s.n:,} samples, duration {format_value(s.duration_s)} s "
                f"({s.duration_s / 3600:.2f} h)  \n"
                f"fs = {s.fs:g} Hz ({s.fs_source}), unit: {u}, {len(s.wv)} WV levels")

    def _refresh_process_list(self) -> None:
        s = self.state
        key = tuple(s.model.labels)
        if key == self._proc_key:
            return
        self._proc_key = key
        rows = []
        for i, (lab, p) in enumerate(zip(s.model.labels, s.model.processes, strict=True)):
            color = component_color(lab)
            label = pn.pane.HTML(
                f'<span class="gmwm-proc-label"><span class="gmwm-swatch" '
                f'style="background:{color}"></span><b>{lab}</b> {PROCESS_NAMES[p.code]}</span>',
                sizing_mode="stretch_width", margin=(0, 10))
            btn = pn.widgets.Button(name="✕", button_type="light", width=34, height=28,
                                    margin=(0, 5), description=f"Remove {lab}",
                                    css_classes=["gmwm-remove"])
            btn.on_click(lambda _e, i=i: self._remove(i))
            rows.append(pn.Row(label, btn, sizing_mode="stretch_width", margin=0))
        if not rows:
            rows = [pn.pane.Markdown("*Empty model: only the empirical WV is shown.*",
                                     margin=(0, 10), styles={"font-size": "13px"})]
        self.process_list.objects = rows

    def _refresh_sliders(self) -> None:
        s = self.state
        on = bool(s.whatif and len(s.model))
        self.sliders.visible = on
        self.whatif_buttons.visible = on
        if not on:
            self._slider_key = None
            return
        key = (s.model.spec(values=True), id(s.result), s.channel)
        if key == self._slider_key:
            return
        self._slider_key = key
        widgets = []
        for spec in s.slider_specs():
            if spec.transform == "log10(1-x)":
                code = "return (1 - Math.pow(10, tick)).toPrecision(6)"
            else:
                code = "return Math.pow(10, tick).toExponential(3)"
            w = pn.widgets.FloatSlider(
                name=f"{spec.name} [{spec.unit}]", start=spec.lo, end=spec.hi,
                value=min(max(spec.x, spec.lo), spec.hi), step=(spec.hi - spec.lo) / 600,
                format=CustomJSTickFormatter(code=code), sizing_mode="stretch_width",
                margin=(2, 10), bar_color=component_color(spec.label))
            w.param.watch(lambda e, sp=spec: self._on_slider(sp, e.new), "value")
            widgets.append(w)
        self.sliders.objects = widgets

    def _refresh_messages(self) -> None:
        s = self.state
        self.alert.object = s.error
        self.alert.visible = bool(s.error)
        self.notice.object = s.notice
        self.notice.visible = bool(s.notice)
        warn = s.warnings() if not s.whatif else []
        self.warning.object = "**Fit warning**: " + "; ".join(warn) if warn else ""
        self.warning.visible = bool(warn)

    def _sync_url(self) -> None:
        if not self._ready:
            return
        loc = pn.state.location
        if loc is None:
            return
        q = self.state.to_query()
        if q != self._last_query:
            self._last_query = q
            loc.search = "?" + urlencode(q, safe="*/")

    # -------------------------------------------------------------------------------------
    # heavy work off the event loop
    # -------------------------------------------------------------------------------------
    def _busy(self, on: bool, message: str = "") -> None:
        self.plot_pane.loading = on
        self.status.object = f"⏳ {message}" if on else ""
        for w in (self.demo_button, self.path_button, self.upload, self.channel_select):
            w.disabled = on

    async def _offload(self, message: str, work: Callable[[], Any],
                       apply: Callable[[Any], Any]) -> None:
        """Run ``work`` in a worker thread (loading indicator on), then ``apply`` its result.

        A later job supersedes an earlier one (its result is dropped).
        """
        self._job += 1
        job = self._job
        self._busy(True, message)
        try:
            loop = asyncio.get_running_loop()
            try:
                out = await loop.run_in_executor(None, work)
            except Exception as e:  # reported in the page
                if job == self._job:
                    self.state._fail(f"{message}: {e}")
                return
            if job == self._job:
                apply(out)
        finally:
            if job == self._job:
                self._busy(False)

    async def start(self) -> None:
        """Load the data named by the URL (or the default) when the page opens."""
        loc = pn.state.location
        query = dict(loc.query_params) if loc is not None else {}

        def work() -> Any:
            return self.state.prepare_query(query, self.default_source, self.default_path)

        def apply(prepared: Any) -> None:
            self.state.from_query(query, prepared=prepared, default_source=self.default_source,
                                  default_path=self.default_path)

        await self._offload("Loading the data and computing its wavelet variance", work, apply)
        self._ready = True
        self._sync_url()

    def start_sync(self) -> None:
        """Synchronous :meth:`start` (no server: tests, notebooks)."""
        self.state.from_query({}, default_source=self.default_source,
                              default_path=self.default_path)
        self._ready = True

    # -------------------------------------------------------------------------------------
    # callbacks
    # -------------------------------------------------------------------------------------
    async def _on_demo(self, _event: Any = None) -> None:
        s = self.state
        await self._offload("Loading the demo log",
                            lambda: self._read_and_warm("demo"), s.install)

    def _read_and_warm(self, source: str, **kw: Any) -> Any:
        loaded = self.state.read(source, **kw)
        self.state.precompute(loaded, self.state.channel, None, self.state.robust)
        return loaded

    async def _on_upload(self, event: Any) -> None:
        files = event.new or {}
        if not files:
            return
        name, data = next(iter(files.items()))
        await self._offload(f"Reading {name}",
                            lambda: self._read_and_warm("upload", data=data, filename=name),
                            self.state.install)

    async def _on_path(self, _event: Any = None) -> None:
        path = (self.path_input.value_input or self.path_input.value or "").strip()
        if not path:
            self.state._fail("Type the path of a log file on the server first")
            return
        await self._offload(f"Reading {path}",
                            lambda: self._read_and_warm("path", path=path), self.state.install)

    async def _on_channel(self, event: Any) -> None:
        if self._syncing or not event.new or event.new == self.state.channel:
            return
        ch = event.new
        await self._offload(f"Computing the wavelet variance of {ch}",
                            lambda: self.state.warm(ch),
                            lambda _out: self.state.select_channel(ch))

    async def _on_robust(self, event: Any) -> None:
        if self._syncing or bool(event.new) == self.state.robust:
            return
        rob = bool(event.new)
        what = "robust" if rob else "classical"
        await self._offload(f"Computing the {what} wavelet variance",
                            lambda: self.state.warm(robust=rob),
                            lambda _out: self._after_robust(rob))

    def _after_robust(self, rob: bool) -> None:
        if not self.state.set_robust(rob):
            self.refresh()  # put the checkbox back

    def _on_fs(self, event: Any) -> None:
        if self._syncing or event.new is None or event.new == self.state.fs:
            return
        if not self.state.set_fs(event.new):
            self.refresh()

    def _add(self, code: str) -> None:
        self.state.add_process(code)

    def _remove(self, index: int) -> None:
        self.state.remove_process(index)

    def _on_spec(self, _event: Any = None) -> None:
        spec = self.spec_input.value_input if self.spec_input.value_input is not None \
            else self.spec_input.value
        if not self.state.set_model(spec or ""):
            self.refresh()

    def _on_whatif(self, event: Any) -> None:
        if self._syncing:
            return
        self.state.set_whatif(bool(event.new))

    def _on_slider(self, spec: SliderSpec, x: float) -> None:
        if self._syncing:
            return
        self.state.set_whatif_value(spec.name, spec.value_of(x))

    def _reset_whatif(self) -> None:
        self._slider_key = None
        self.state.reset_whatif()

    def _fit_from_whatif(self) -> None:
        if self.state.fit_from_whatif():
            self.state.set_whatif(False)

    def _on_plot_format(self, event: Any) -> None:
        backend = "svg" if event.new == "SVG" else "canvas"
        self.views.figure.output_backend = backend
        self.views.residual.output_backend = backend

    def _export_json(self) -> io.StringIO:
        return io.StringIO(self.state.export_json())


def create_app(*, source: str = "demo", path: str = "", load: bool = True) -> pn.viewable.Viewable:
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
    panel.template.FastListTemplate
        The page; its ``gmwm_app`` attribute is the :class:`GMWMApp`.
    """
    app = GMWMApp(default_source=source, default_path=path)
    page = app.view()
    page.gmwm_app = app  # type: ignore[attr-defined]
    if load:
        if pn.state.curdoc is not None and pn.state.curdoc.session_context is not None:
            pn.state.onload(app.start)
        else:
            app.start_sync()
    return page


def create_app_factory(path: str | None = None) -> Callable[[], pn.viewable.Viewable]:
    """A function that builds a fresh page per session (for ``pn.serve``), preloading ``path``."""
    def factory() -> pn.viewable.Viewable:
        if path:
            return create_app(source="path", path=str(path))
        return create_app()

    return factory


if __name__.startswith("bokeh"):  # `panel serve gmwm_app/app.py`
    create_app().servable(title="GMWM")
