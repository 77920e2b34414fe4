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

import os
import tempfile
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
import param
from bokeh.models import ColumnDataSource
from bokeh.models.annotations import Legend, LegendItem
from bokeh.models.widgets import StringFormatter, TableColumn

import engine as eg
from engine.formats.readers import read_check_file
from engine.units import DISPLAY, ExportError, si_factor, squared, times_s

from . import views
from .state import AppState
from .tab_view import TabView

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["CheckView", "FIELDS", "DEFAULTS", "VERDICT_COLORS", "check_fields"]

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


class CheckView(TabView):
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
    """

    slug = "check"

    result = param.ClassSelector(
        class_=eg.inference.DatasheetCheck,
        default=None,
        allow_None=True,
        doc="The check shown (None while there is none).",
    )
    kind = param.String(
        default="",
        doc="The channel's sensor kind, 'gyroscope' or 'accelerometer' ('' when its unit is "
        "neither's): the fields follow it.",
    )
    texts = param.List(default=["", "", "", ""], item_type=str, doc="The fields' values, as typed.")
    file_spec = param.ClassSelector(
        class_=eg.inference.DatasheetSpec,
        default=None,
        allow_None=True,
        doc="The uploaded file's exact values (checked instead of the fields' 4 digits), "
        "until a field is edited.",
    )

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(state, jobs, **params)
        for build in (self._build_widgets, self._build_figures, self._build_table):
            build()
        self._build_layout()
        self.refresh()

    @param.depends("state.wv", "state.result", "state.unit", "texts", "file_spec", watch=True)
    def _on_state(self) -> None:
        """What the check reads changed: the channel's WV, its unit, the Fit tab's fit, the
        datasheet's values (once per update, however many of them it changed; not at all
        for an unchanged value)."""
        super()._on_state()

    # ------------------------------------------------------------------------------------
    # construction (once)
    # ------------------------------------------------------------------------------------
    def _build_widgets(self) -> None:
        self.inputs = [
            pn.widgets.TextInput(label="", value="", width=170, css_classes=[f"gmwm-check-{i}"])
            for i in range(4)
        ]
        for i, w in enumerate(self.inputs):
            w.param.watch(partial(self._on_input, i), "value")
        self.upload = pn.widgets.FileInput(
            accept=".yaml,.yml,.json,.csv", multiple=False, css_classes=["gmwm-check-upload"]
        )
        self.upload.param.watch(self._on_upload, "value")
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

    # ------------------------------------------------------------------------------------
    # actions (also called by tests)
    # ------------------------------------------------------------------------------------
    def set_values(self, values: dict[str, str]) -> None:
        """Set input fields by key (``{"arw": "0.3", "bi": ""}``) and recompute once."""
        keys = [k for k, _s, _u in FIELDS.get(self.kind, [])]
        bad = [key for key in values if key not in keys]
        if bad:
            self._show([f"no field {bad[0]!r} for a {self.kind or 'unknown'} channel"])
            return
        texts = list(self.texts)
        for key, text in values.items():
            texts[keys.index(key)] = str(text)
        self._set_texts(texts)

    def load_file(self, data: bytes, filename: str) -> None:
        """Read datasheet values from an uploaded file into the fields (message on error)."""
        suffix = Path(filename).suffix.lower()
        fd, tmp = tempfile.mkstemp(suffix=suffix or ".yaml", prefix="datasheet_")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            # every filter file gmwm export writes, a consumer's own, or a gmwm report/CSV
            spec = read_check_file(
                tmp, channel=self.state.channel, kind=self.kind or None, fs=self.state.fs
            )
        except ValueError as e:  # eg.GmwmError (ExportError ...) or numpy's
            self._show([str(e).replace(tmp, filename)])
            return
        finally:
            Path(tmp).unlink(missing_ok=True)
        if self.kind and spec.kind != self.kind:
            self._show([f"{filename} is a {spec.kind}'s datasheet; the channel is a {self.kind}"])
            return
        self.message.visible = False
        self._set_texts(self._file_texts(spec), spec)  # its exact values, until a field is edited

    # ------------------------------------------------------------------------------------
    # callbacks (thin)
    # ------------------------------------------------------------------------------------
    def _on_input(self, i: int, event: Any) -> None:
        """A field was edited (idempotent: the echo of :meth:`_set_texts` is a no-op)."""
        if event.new == self.texts[i]:
            return
        texts = list(self.texts)
        texts[i] = event.new
        # the user's values now; the check they trigger redraws Bokeh models (the figures'
        # sources): with the session's document lock, which Panel does not hold while it runs a
        # widget's callback (a bad value's cleared figures raised "_pending_writes should be
        # non-None" instead of a message)
        self._locked(self._set_texts, texts)

    def _on_upload(self, event: Any) -> None:
        if event.new:
            name = self.upload.filename or "datasheet.yaml"
            self._locked(self.load_file, event.new, name)

    # ------------------------------------------------------------------------------------
    # state -> computation -> views
    # ------------------------------------------------------------------------------------
    @staticmethod
    def _file_texts(spec: eg.inference.DatasheetSpec) -> list[str]:
        """A datasheet's values as the fields show them (datasheet units, 4 digits)."""
        out = []
        for _key, sym, _unit in FIELDS[spec.kind]:
            v = spec.values.get(sym)
            if v is None:
                out.append("")
            elif sym == "Q":
                out.append(_fmt(v / si_factor(_SIGNAL[spec.kind])[1]))
            else:
                out.append(_fmt(v * DISPLAY[(spec.kind, sym)].factor))
        return out

    def _set_texts(
        self, texts: list[str], file_spec: eg.inference.DatasheetSpec | None = None
    ) -> None:
        """The datasheet's values (and the file's spec, None for typed values): one update,
        one check."""
        self.param.update(texts=list(texts), file_spec=file_spec)

    @param.depends("texts", watch=True)
    def _show_texts(self) -> None:
        """The fields show the values (their echo in :meth:`_on_input` is a no-op)."""
        for w, text in zip(self.inputs, self.texts, strict=True):
            w.value = text

    def _sync_kind(self) -> None:
        """Fields follow the channel's sensor kind (labels, units, defaults)."""
        try:
            kind = si_factor(self.state.unit or "")[0]
        except ExportError:
            kind = ""
        if kind == self.kind:
            return
        fields = FIELDS.get(kind, [])
        texts = [DEFAULTS[kind][key] for key, _s, _u in fields] if kind else list(self.texts)
        with param.parameterized.discard_events(self):  # (called by the draw that uses them)
            self.param.update(kind=kind, texts=texts)
        if kind:
            for w, text, (key, _s, unit) in zip(self.inputs, self.texts, fields, strict=True):
                # one update, after self.texts: the value's echo in _on_input is a no-op
                w.param.update(label=f"{key.upper()} [{unit}]", value=text, disabled=False)
        else:
            for w in self.inputs:
                w.disabled = True

    def spec(self) -> eg.inference.DatasheetSpec:
        """The datasheet of the fields (raises DatasheetError with a readable message)."""
        items: dict[str, tuple[float, str]] = {}
        for text, (key, _s, unit) in zip(self.texts, FIELDS[self.kind], strict=True):
            text = text.strip()
            if not text:
                continue
            try:
                items[key] = (float(text), unit)
            except ValueError:
                raise eg.errors.DatasheetError(f"{key.upper()}: {text!r} is not a number") from None
        return eg.inference.DatasheetSpec.from_values(items, source="app")

    def _draw(self, force: bool) -> None:
        """Check the datasheet (called when what it reads changed: :meth:`_on_state`)."""
        s = self.state
        self._sync_kind()
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
        except eg.errors.DatasheetError as e:
            self._clear([str(e)])
            return
        fit = s.result if s.result is not None and s.result.wv is s.wv else None
        self._compute(partial(eg.check_datasheet, s.wv, spec, fit=fit), self.draw, "check")

    def _failed(self, err: BaseException) -> None:
        self._clear([f"could not check: {err}"])

    def _clear(self, msgs: list[str]) -> None:
        self.result = None
        for src in (self.wv_src, self.adev_src):
            src.data = {c: [] for c in src.data}
        self.table_src.data = {c: [] for c in self.table_columns}
        self.status.object = ""
        self._show(msgs)

    def draw(self, chk: Any) -> None:
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
        self.show_message(msgs, level="info" if info else "warning")
