"""The "Datasheet check" tab: the manufacturer's noise model against the session's channel.

The user types the datasheet's angle (gyroscope) or velocity (accelerometer) random walk, bias
instability, rate random walk and quantization in datasheet units (the fields follow the
channel's sensor kind, read from its unit), or uploads a Kalibr ``imu.yaml``, a ``gmwm`` JSON
report, a datasheet CSV or a saved datasheet JSON; the tab draws the datasheet model's wavelet
variance and Allan deviation over the empirical ones with their 95 % band, marks each scale
by its verdict (inside, above or below the interval: :func:`engine.inference.check_datasheet`),
draws the Fit tab's current GMWM fit beside it, and lists the scales in a table.

Bias instability is not a GMWM process: it is drawn as its Allan-deviation floor
``(0.664 B)^2`` (a constant WV ``(0.664 B)^2 / 2``), summed with the other terms.

The figures and the table are built once; their ColumnDataSources are replaced in place. The
check runs in the session's job runner (at once outside a server); bad values show a message.
"""

from __future__ import annotations

import logging
import os
import tempfile
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
import param
from bokeh.models import ColumnDataSource, Legend, LegendItem, StringFormatter, TableColumn

import engine as eg
from engine.units import DISPLAY, ExportError, si_factor, squared, times_s

from . import views
from .state import AppState

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["CheckView", "FIELDS", "DEFAULTS", "VERDICT_COLORS", "check_fields"]

log = logging.getLogger(__name__)

#: Colour of a scale by verdict.
VERDICT_COLORS = {"inside": "#2CA02C", "above": "#FF7F0E", "below": "#D62728"}
DATASHEET_COLOR = "#9467BD"
FIT_COLOR = "#1F77B4"
_SIGNAL = {"gyroscope": "deg/s", "accelerometer": "m/s^2"}


def check_fields(kind: str) -> list[tuple[str, str, str]]:
    """The input fields of a sensor kind: ``(key, symbol, unit)`` in datasheet units.

    Units from :data:`engine.units.DISPLAY` (ARW ``deg/sqrt(h)``, VRW ``m/s/sqrt(h)``, RRW
    ``deg/h/sqrt(h)``, ``m/s/h/sqrt(h)``, B ``deg/h`` or ``mg``); quantization in integrated
    units (``deg``, ``m/s``).
    """
    gyro = kind == "gyroscope"
    return [
        ("arw" if gyro else "vrw", "N", DISPLAY[(kind, "N")].unit),
        ("bi", "B", DISPLAY[(kind, "B")].unit),
        ("rrw" if gyro else "accrw", "K", DISPLAY[(kind, "K")].unit),
        ("q", "Q", times_s(_SIGNAL[kind])),
    ]


FIELDS = {k: check_fields(k) for k in _SIGNAL}

#: Typical MEMS datasheet values (the user overwrites them): empty means not given.
DEFAULTS: dict[str, dict[str, str]] = {
    "gyroscope": {"arw": "0.3", "bi": "10", "rrw": "", "q": ""},
    "accelerometer": {"vrw": "0.05", "bi": "0.1", "accrw": "", "q": ""},
}


NOTE = (
    "Type the datasheet's values (empty: not given), or upload a Kalibr `imu.yaml`, a gmwm "
    "JSON report, a datasheet CSV or a datasheet JSON. Bias instability is drawn as its "
    "Allan-deviation floor `(0.664 B)²` (a constant WV `(0.664 B)²/2`); each scale is marked "
    "inside, above or below the empirical 95 % interval."
)
_NOTE_LOOK: dict[str, Any] = {"margin": (0, 10), "styles": {"font-size": "13px", "color": "#444"}}


def _fmt(v: float) -> str:
    return f"{v:.4g}"


class CheckView(pn.viewable.Viewer):
    """Widgets, figures, table and callbacks of the "Datasheet check" tab of one session.

    Parameters
    ----------
    state : AppState
        The session state (its WV, unit and current fit are drawn).
    jobs : Jobs
        The session's job runner.

    Attributes
    ----------
    panel : panel.layout.Column
        The tab's content.
    result : DatasheetCheck or None
        What is shown.
    kind : str
        The channel's sensor kind (``""`` when its unit is unknown).
    """

    active = param.Boolean(default=True, doc="Whether the tab is shown.")

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(**params)
        self.state = state
        self.jobs = jobs
        self.result: Any = None
        self.kind = ""
        self.file_spec: eg.DatasheetSpec | None = None
        self._key: Any = None
        self._dirty = True  # something changed while the tab was hidden
        self._syncing = False
        for build in (self._build_widgets, self._build_figures, self._build_table):
            build()
        self._build_layout()
        self.state.param.watch(self._on_change, "revision")
        self.param.watch(self._on_change, "active")
        self.refresh()

    # ------------------------------------------------------------------------------------
    # construction (once)
    # ------------------------------------------------------------------------------------
    def _build_widgets(self) -> None:
        self.inputs = [
            pn.widgets.TextInput(label="", value="", width=170, css_classes=[f"gmwm-check-{i}"])
            for i in range(4)
        ]
        for w in self.inputs:
            w.param.watch(self._on_input, "value")
        self.upload = pn.widgets.FileInput(
            accept=".yaml,.yml,.json,.csv", multiple=False, css_classes=["gmwm-check-upload"]
        )
        self.upload.param.watch(self._on_upload, "value")
        self.message = views.hidden_alert("warning", css_classes=["gmwm-check-message"])
        self.status = pn.pane.Markdown(
            "", sizing_mode="stretch_width", margin=(0, 10), css_classes=["gmwm-check-status"]
        )

    def _source(self, name: str) -> ColumnDataSource:
        cols = ("tau_s", "emp", "lo", "hi", "ds", "fit", "verdict", "color")
        return ColumnDataSource({c: [] for c in cols}, name=name)

    def _figure(self, name: str, title: str, x_label: str, src: ColumnDataSource) -> Any:
        p = views.log_figure(name, title, 400, x_label)
        band = views.interval_band(p, src, "lo", "hi")
        line, pts = views.empirical_curve(p, src, "emp", 1.5, 5)
        ds_line = p.line("tau_s", "ds", source=src, line_color=DATASHEET_COLOR, line_width=2.5)
        ds_pts = p.scatter(
            "tau_s",
            "ds",
            source=src,
            size=9,
            marker="diamond",
            fill_color="color",
            line_color="white",
        )
        fit_line = p.line(
            "tau_s", "fit", source=src, line_color=FIT_COLOR, line_width=2, line_dash="dashed"
        )
        legend = Legend(
            items=[
                LegendItem(label="empirical (95% band)", renderers=[line, pts, band]),
                LegendItem(label="datasheet model", renderers=[ds_line]),
                LegendItem(label="◆ verdict: inside / above / below", renderers=[ds_pts]),
                LegendItem(label="GMWM fit (Fit tab)", renderers=[fit_line]),
            ],
            location="bottom_left",
            click_policy="hide",
            label_text_font_size="11px",
            background_fill_alpha=0.7,
        )
        p.add_layout(legend)
        return p

    def _build_figures(self) -> None:
        self.wv_src = self._source("check_wv_points")
        self.adev_src = self._source("check_adev_points")
        self.wv_figure = self._figure(
            "check_wv", "Wavelet variance: datasheet vs data", "scale τ [s]", self.wv_src
        )
        self.adev_figure = self._figure(
            "check_adev",
            "Allan deviation: datasheet vs data",
            "averaging time T [s]",
            self.adev_src,
        )

    def _build_table(self) -> None:
        self.table_columns = (
            "tau [s]",
            "WV",
            "95% low",
            "95% high",
            "datasheet",
            "verdict",
            "GMWM",
        )
        self.table_src = ColumnDataSource({c: [] for c in self.table_columns}, name="check_rows")
        cols = [
            TableColumn(field=c, title=c, width=95, sortable=False, formatter=StringFormatter())
            for c in self.table_columns
        ]
        self.table = views.data_table(self.table_src, cols, "check_table", "gmwm-check-table", 300)

    def _build_layout(self) -> None:
        note = pn.pane.Markdown(NOTE, sizing_mode="stretch_width", **_NOTE_LOOK)
        self.panel = pn.Column(
            note,
            pn.Row(*self.inputs, sizing_mode="stretch_width"),
            pn.Row(pn.pane.Markdown("or a file:", margin=(12, 10)), self.upload),
            self.message,
            self.status,
            pn.Row(
                pn.pane.Bokeh(self.wv_figure, sizing_mode="stretch_width"),
                pn.pane.Bokeh(self.adev_figure, sizing_mode="stretch_width"),
                sizing_mode="stretch_width",
            ),
            pn.pane.Markdown("#### Per scale", margin=(0, 10)),
            pn.pane.Bokeh(self.table, sizing_mode="stretch_width", margin=(5, 10)),
            sizing_mode="stretch_width",
        )

    def __panel__(self) -> pn.Column:
        """The tab's content."""
        return self.panel

    # ------------------------------------------------------------------------------------
    # actions (also called by tests)
    # ------------------------------------------------------------------------------------
    def set_values(self, values: dict[str, str]) -> None:
        """Set input fields by key (``{"arw": "0.3", "bi": ""}``) and recompute once."""
        keys = [k for k, _s, _u in FIELDS.get(self.kind, [])]
        self._syncing = True
        try:
            for key, text in values.items():
                if key not in keys:
                    self._show([f"no field {key!r} for a {self.kind or 'unknown'} channel"])
                    return
                self.inputs[keys.index(key)].value = str(text)
        finally:
            self._syncing = False
        self.file_spec = None
        self.refresh(force=True)

    def load_file(self, data: bytes, filename: str) -> None:
        """Read datasheet values from an uploaded file into the fields (message on error)."""
        suffix = Path(filename).suffix.lower()
        fd, tmp = tempfile.mkstemp(suffix=suffix or ".yaml", prefix="datasheet_")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            spec = eg.read_datasheet(tmp, channel=self.state.channel, kind=self.kind or None)
        except (ExportError, ValueError) as e:
            self._show([str(e).replace(tmp, filename)])
            return
        finally:
            Path(tmp).unlink(missing_ok=True)
        if self.kind and spec.kind != self.kind:
            self._show([f"{filename} is a {spec.kind}'s datasheet; the channel is a {self.kind}"])
            return
        self._fill(spec)
        self.file_spec = spec  # the file's exact values, until a field is edited
        self.message.visible = False
        self.refresh(force=True)

    # ------------------------------------------------------------------------------------
    # callbacks (thin)
    # ------------------------------------------------------------------------------------
    def _on_input(self, _event: Any) -> None:
        if not self._syncing:
            self.file_spec = None
            self.refresh(force=True)

    def _on_upload(self, event: Any) -> None:
        if event.new:
            self.load_file(event.new, self.upload.filename or "datasheet.yaml")

    def _on_change(self, event: Any = None) -> None:
        """The session changed, or the tab was shown: refresh (never raising into Panel)."""
        if getattr(event, "name", "") == "active" and not (self.active and self._dirty):
            return
        try:
            self.refresh()
        except Exception as e:  # a display problem must not break the session
            log.exception("datasheet check refresh failed")
            self._show([f"display error: {type(e).__name__}: {e}"])

    # ------------------------------------------------------------------------------------
    # state -> computation -> views
    # ------------------------------------------------------------------------------------
    def _fill(self, spec: eg.DatasheetSpec) -> None:
        """Show a datasheet's values in the fields (datasheet units, 4 digits)."""
        vals = {}
        for key, sym, _unit in FIELDS[spec.kind]:
            v = spec.values.get(sym)
            if v is None:
                vals[key] = ""
            elif sym == "Q":
                vals[key] = _fmt(v / si_factor(_SIGNAL[spec.kind])[1])
            else:
                vals[key] = _fmt(v * DISPLAY[(spec.kind, sym)].factor)
        self._syncing = True
        try:
            for w, (key, _s, _u) in zip(self.inputs, FIELDS[spec.kind], strict=True):
                w.value = vals[key]
        finally:
            self._syncing = False

    def _sync_kind(self) -> None:
        """Fields follow the channel's sensor kind (labels, units, defaults)."""
        try:
            kind = si_factor(self.state.unit or "")[0]
        except ExportError:
            kind = ""
        if kind == self.kind:
            return
        self.kind = kind
        self._syncing = True
        try:
            for w, (key, _s, unit) in zip(self.inputs, FIELDS.get(kind, []), strict=False):
                w.param.update(label=f"{key.upper()} [{unit}]", value=DEFAULTS[kind][key])
            for w in self.inputs:
                w.disabled = not kind
        finally:
            self._syncing = False

    def spec(self) -> eg.DatasheetSpec:
        """The datasheet of the fields (raises DatasheetError with a readable message)."""
        items: dict[str, tuple[float, str]] = {}
        for w, (key, _s, unit) in zip(self.inputs, FIELDS[self.kind], strict=True):
            text = w.value.strip()
            if not text:
                continue
            try:
                items[key] = (float(text), unit)
            except ValueError:
                raise eg.DatasheetError(f"{key.upper()}: {text!r} is not a number") from None
        return eg.DatasheetSpec.from_values(items, source="app")

    def refresh(self, force: bool = False) -> None:
        """Recompute when the data, the fit or the values changed (only while shown)."""
        s = self.state
        self._sync_kind()
        key = (s.wv, s.result, s.unit, self.kind, tuple(w.value for w in self.inputs))
        if key == self._key and not force:
            return
        if not (self.active or not self.jobs.served):  # tests, notebooks: always drawn
            self._dirty = True
            return
        self._dirty = False
        self._key = key
        if s.wv is None:
            self._clear(["load a log first"])
            return
        if not self.kind:
            self._clear(
                [
                    f"the channel's unit {s.unit or '(none)'!r} is not a gyroscope or "
                    "accelerometer unit: the datasheet check needs it (set the unit when "
                    "loading, e.g. deg/s, rad/s, g, m/s^2)"
                ]
            )
            return
        try:
            spec = self.file_spec or self.spec()
        except eg.DatasheetError as e:
            self._clear([str(e)])
            return
        fit = s.result if s.result is not None and s.result.wv is s.wv else None
        self.jobs.run(
            partial(eg.check_datasheet, s.wv, spec, fit=fit),
            self.show,
            self._failed,
            key="check",
            inline=not self.jobs.served,
        )

    def _failed(self, err: BaseException) -> None:
        self._clear([f"could not check: {err}"])

    def _clear(self, msgs: list[str]) -> None:
        self.result = None
        for src in (self.wv_src, self.adev_src):
            src.data = {c: [] for c in src.data}
        self.table_src.data = {c: [] for c in self.table_columns}
        self.status.object = ""
        self._show(msgs)

    def show(self, chk: Any) -> None:
        """Draw a check: both figures, the table, the summary."""
        self.result = chk
        colors = [VERDICT_COLORS[v] for v in chk.verdict]
        nan = np.full(len(chk.verdict), np.nan)
        fit = chk.fit_wv if chk.fit_wv is not None else nan
        self.wv_src.data = {
            "tau_s": chk.tau_s,
            "emp": np.asarray(chk.wv.variance, float),
            "lo": chk.ci_low,
            "hi": chk.ci_high,
            "ds": chk.datasheet_wv,
            "fit": fit,
            "verdict": list(chk.verdict),
            "color": colors,
        }
        self.adev_src.data = {
            "tau_s": chk.allan_tau_s,
            "emp": chk.empirical_adev,
            "lo": np.sqrt(2.0 * chk.ci_low),
            "hi": np.sqrt(2.0 * chk.ci_high),
            "ds": chk.datasheet_adev,
            "fit": np.sqrt(2.0 * fit),
            "verdict": list(chk.verdict),
            "color": colors,
        }
        u = squared(self.state.unit or "u")
        self.wv_figure.yaxis.axis_label = f"wavelet variance [{u}]"
        self.adev_figure.yaxis.axis_label = f"Allan deviation [{self.state.unit or 'u'}]"
        fv = chk.fit_verdict or ("",) * len(chk.verdict)
        same_rows = len(self.table_src.data["verdict"]) == len(chk.verdict)
        self.table_src.data = {
            "tau [s]": [_fmt(t) for t in chk.tau_s],
            "WV": [_fmt(v) for v in chk.wv.variance],
            "95% low": [_fmt(v) for v in chk.ci_low],
            "95% high": [_fmt(v) for v in chk.ci_high],
            "datasheet": [_fmt(v) for v in chk.datasheet_wv],
            "verdict": list(chk.verdict),
            "GMWM": list(fv),
        }
        if same_rows:  # BokehJS keeps the old cells when the row count does not change
            views.redraw_table(self.table)
        self.status.object = (
            f"**{chk.datasheet.describe()}** on {self.state.channel} (WV in {u}).  \n"
            + chk.text_summary().replace("\n  ", "  \n")
        )
        self._show(
            [] if chk.fit_wv is not None else ["no GMWM fit to draw: fit a model in the Fit tab"],
            info=True,
        )

    def _show(self, msgs: list[str], info: bool = False) -> None:
        self.message.param.update(
            object="  \n".join(f"• {m}" for m in msgs),
            visible=bool(msgs),
            alert_type="info" if info else "warning",
        )
