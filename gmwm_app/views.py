"""Bokeh figures of the app, built once per session and updated in place.

:class:`WVFigures` holds the log-log wavelet-variance plot (empirical WV with its interval,
the classical WV beside a robust one, the model total and one curve per process) and the
residual strip (empirical / model with the interval). :meth:`WVFigures.update` only replaces
the ``data`` of the ColumnDataSources and a few properties (legend labels, colours, axis
labels), so the figures are never rebuilt and a zoom survives a refit. Component curves come
from a fixed pool of renderers; unused ones are hidden.

The table builders (:func:`parameter_rows`, :func:`datasheet_rows`, :func:`fit_summary`) return
plain data for the widgets of ``app.py``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from bokeh.core.properties import value
from bokeh.models import (
    ColumnDataSource,
    DataRange1d,
    DataTable,
    HoverTool,
    Legend,
    LegendItem,
    SaveTool,
    Span,
    TableColumn,
)
from bokeh.plotting import figure

import engine as eg
from engine.units import squared

from .state import PROCESS_NAMES, format_value

if TYPE_CHECKING:  # pragma: no cover
    from .state import AppState

__all__ = [
    "WVFigures",
    "wv_data",
    "FitTables",
    "N_COMPONENTS",
    "component_color",
    "unit_squared",
    "model_grid",
    "parameter_rows",
    "datasheet_rows",
    "fit_summary",
]

#: Size of the pool of component renderers (a model with more processes draws the first ones).
N_COMPONENTS = 12
#: Minimum legend label width (px); the residual strip has a legend as wide, so the two
#: plot frames line up on the shared x axis.
LEGEND_LABEL_WIDTH = 175
#: Points per octave of the smooth model curves.
GRID_PER_OCTAVE = 8

EMPIRICAL_COLOR = "#222222"
BAND_COLOR = "#6C8EBF"
CLASSICAL_COLOR = "#8C8C8C"
TOTAL_COLOR = "#D62728"
_CORRELATED_COLORS = (
    "#FF7F0E",
    "#E377C2",
    "#17BECF",
    "#BCBD22",
    "#7F3C8D",
    "#11A579",
    "#F2B701",
    "#E73F74",
)


def component_color(label: str) -> str:
    """Colour of a process curve, stable per label (``WN`` blue, ``GM_1`` orange, ...)."""
    code, _, idx = label.partition("_")
    cls = eg.PROCESS_TYPES.get(code)
    if cls is not None and cls.color:
        return cls.color  # a kind that appears once has its own colour
    k = int(idx) - 1 if idx.isdigit() else 0
    # a kind that repeats (GM, AR1) takes the palette, each kind from its own offset (AR1 and
    # GM never mix, but keep their colours apart anyway)
    repeating = [c for c, t in eg.PROCESS_TYPES.items() if not t.color]
    if code in repeating:
        k += 4 * repeating.index(code)
    return _CORRELATED_COLORS[k % len(_CORRELATED_COLORS)]


def unit_squared(unit: str) -> str:
    """``(deg/s)²`` for ``deg/s``; ``u²`` when the unit is unknown (:func:`engine.units.squared`,
    printed with ``²``)."""
    return squared(unit).replace("^2", "²")


def model_grid(wv: eg.WaveletVariance, per_octave: int = GRID_PER_OCTAVE) -> np.ndarray:
    """Scales (samples) of the smooth model curves: ``2 .. 2^J``, ``per_octave`` per octave."""
    j = wv.n_levels
    return 2.0 ** np.linspace(1.0, float(j), (j - 1) * per_octave + 1)


def _positive(a: np.ndarray) -> np.ndarray:
    """Non-positive values as NaN (a log axis cannot show them; the line breaks there)."""
    a = np.asarray(a, dtype=float)
    return np.where(a > 0, a, np.nan)


def _empty_wv() -> dict[str, Any]:
    return {
        k: np.zeros(0)
        for k in ("tau_s", "tau_samples", "level", "variance", "ci_low", "ci_high", "n_coef")
    }


def wv_data(wv: eg.WaveletVariance | None) -> dict[str, Any]:
    if wv is None:
        return _empty_wv()
    return {
        "tau_s": np.asarray(wv.tau_s, float),
        "tau_samples": np.asarray(wv.tau_samples),
        "level": np.asarray(wv.levels),
        "variance": np.asarray(wv.variance, float),
        "ci_low": np.asarray(wv.ci_low, float),
        "ci_high": np.asarray(wv.ci_high, float),
        "n_coef": np.asarray(wv.n_coef),
    }


def _curve(tau_s: np.ndarray, y: np.ndarray, label: str) -> dict[str, Any]:
    return {"tau_s": tau_s, "wv": _positive(y), "label": [label] * len(tau_s)}


_EMPTY_CURVE: dict[str, Any] = {"tau_s": np.zeros(0), "wv": np.zeros(0), "label": []}


class WVFigures:
    """The WV plot and the residual strip of one session, updated in place.

    Attributes
    ----------
    figure, residual : bokeh.plotting.figure
        Main log-log plot and the residual strip below it (they share the x range).
    emp, alt, total, resid : ColumnDataSource
        Empirical WV (robust one when robust is on), classical WV (robust mode only), model
        total on a fine grid, residual ratio.
    comps : list of ColumnDataSource
        One per pooled component renderer (``tau_s``, ``wv``, ``label``).
    comp_renderers, comp_items : list
        The pooled line renderers and their legend items.
    """

    def __init__(self, n_components: int = N_COMPONENTS) -> None:
        # names: handles for browser tests and benchmarks (Bokeh's get_model_by_name)
        self.emp = ColumnDataSource(_empty_wv(), name="empirical")
        self.alt = ColumnDataSource(_empty_wv(), name="classical")
        self.total = ColumnDataSource(dict(_EMPTY_CURVE), name="model_total")
        self.comps = [
            ColumnDataSource(dict(_EMPTY_CURVE), name=f"component_{i}") for i in range(n_components)
        ]
        self.resid = ColumnDataSource(
            {
                "tau_s": np.zeros(0),
                "ratio": np.zeros(0),
                "lo": np.zeros(0),
                "hi": np.zeros(0),
                "level": np.zeros(0),
            },
            name="residual",
        )
        self._shown_wv: Any = None
        self._unit: str | None = None

        p = log_figure(
            "wv_plot",
            "Load a log to see its wavelet variance",
            480,
            "scale τ [s]",
            x_range=DataRange1d(range_padding=0.08),
            y_range=DataRange1d(range_padding=0.08),
            min_border_left=80,
        )
        p.yaxis.axis_label = f"wavelet variance ν² [{unit_squared('')}]"
        p.title.text_font_size = "14px"
        p.axis.axis_label_text_font_size = "13px"
        p.axis.major_label_text_font_size = "12px"
        p.xgrid.minor_grid_line_color = "#e6e6e6"
        p.ygrid.minor_grid_line_color = "#eeeeee"
        p.ygrid.minor_grid_line_alpha = 0.6
        p.xgrid.minor_grid_line_alpha = 0.6

        # classical WV drawn beside the robust one (robust mode only)
        alt_band = interval_band(p, self.alt, color=CLASSICAL_COLOR, alpha=0.12)
        alt_line = p.line(
            "tau_s",
            "variance",
            source=self.alt,
            line_color=CLASSICAL_COLOR,
            line_width=1.5,
            line_dash="dashed",
        )
        alt_pts = p.scatter(
            "tau_s",
            "variance",
            source=self.alt,
            marker="square",
            size=6,
            line_color=CLASSICAL_COLOR,
            fill_color="white",
        )
        # empirical WV and its interval
        band = interval_band(p, self.emp)
        emp_line, emp_pts = empirical_curve(p, self.emp, "variance", 1.5, 7)
        # the axes follow the data, not the model curves (a tiny RW at short scales would
        # otherwise squash the plot, and dragging a what-if slider would make it jump)
        p.x_range.renderers = [emp_line, alt_line]
        p.y_range.renderers = [band, emp_line, alt_band]

        # model: one pooled renderer per component, then the total on top
        self.comp_renderers = []
        for src in self.comps:
            r = p.line(
                "tau_s",
                "wv",
                source=src,
                line_width=2.2,
                line_dash="dashed",
                line_alpha=0.95,
                visible=False,
            )
            self.comp_renderers.append(r)
        total = p.line(
            "tau_s", "wv", source=self.total, line_color=TOTAL_COLOR, line_width=3, line_alpha=0.9
        )
        self.total_renderer = total

        self.emp_item = LegendItem(label=value("empirical WV"), renderers=[emp_line, emp_pts])
        self.band_item = LegendItem(label=value("95% interval"), renderers=[band])
        self.alt_item = LegendItem(
            label=value("classical WV"), renderers=[alt_line, alt_pts, alt_band], visible=False
        )
        self.total_item = LegendItem(label=value("model (total)"), renderers=[total], visible=False)
        self.comp_items = [
            LegendItem(label=value(f"component {i + 1}"), renderers=[r], visible=False)
            for i, r in enumerate(self.comp_renderers)
        ]
        self.legend = Legend(
            items=[self.emp_item, self.band_item, self.alt_item, self.total_item, *self.comp_items],
            location="top_left",
            click_policy="hide",
            label_text_font_size="12px",
            spacing=1,
            padding=6,
            border_line_alpha=0.3,
            background_fill_alpha=0.85,
            label_width=LEGEND_LABEL_WIDTH,
        )
        p.add_layout(self.legend, "right")

        self.emp_hover = HoverTool(
            renderers=[emp_pts, alt_pts],
            tooltips=self._emp_tips(""),
            formatters=self._formatters(),
            mode="mouse",
        )
        self.model_hover = HoverTool(
            renderers=[total, *self.comp_renderers],
            tooltips=self._model_tips(""),
            formatters={"@tau_s": "printf", "@wv": "printf"},
            mode="mouse",
            line_policy="nearest",
        )
        p.add_tools(self.emp_hover, self.model_hover)
        self.figure = p
        self.save_tool = p.select_one(SaveTool)

        r = log_figure(
            "residual_plot",
            "Residuals: empirical / model, with the 95% interval",
            180,
            "scale τ [s]",
            tools="pan,wheel_zoom,reset,save",
            y_axis_type="auto",
            x_range=p.x_range,
            y_range=DataRange1d(range_padding=0.6, start=0.0),
            min_border_left=80,
        )
        r.title.text_font_size = "13px"
        r.yaxis.axis_label = "empirical / model [1]"
        rband = interval_band(r, self.resid, "lo", "hi")
        rline, ratio_pts = empirical_curve(r, self.resid, "ratio", 1, 6)
        # linear ratio axis that follows the points (the interval at the longest scales is
        # orders of magnitude wide and would flatten them)
        r.y_range.renderers = [ratio_pts]
        r.add_layout(
            Span(
                location=1.0,
                dimension="width",
                line_color=TOTAL_COLOR,
                line_dash="dashed",
                line_width=1.5,
            )
        )
        r.add_layout(
            Legend(
                items=[
                    LegendItem(label=value("empirical / model"), renderers=[rline, ratio_pts]),
                    LegendItem(label=value("95% interval / model"), renderers=[rband]),
                ],
                location="top_left",
                label_text_font_size="12px",
                spacing=1,
                padding=6,
                border_line_alpha=0.3,
                label_width=LEGEND_LABEL_WIDTH,
            ),
            "right",
        )
        r.add_tools(
            HoverTool(
                renderers=[ratio_pts],
                tooltips=[
                    ("level", "@level"),
                    ("τ", "@tau_s{%.4g} s"),
                    ("empirical / model", "@ratio{%.3f}"),
                    ("95% interval / model", "@lo{%.3f} to @hi{%.3f}"),
                ],
                formatters={
                    "@tau_s": "printf",
                    "@ratio": "printf",
                    "@lo": "printf",
                    "@hi": "printf",
                },
            )
        )
        self.residual = r

    # ------------------------------------------------------------------------------------
    @staticmethod
    def _formatters() -> dict[str, str]:
        return {f"@{k}": "printf" for k in ("tau_s", "variance", "ci_low", "ci_high")}

    @staticmethod
    def _emp_tips(unit: str) -> list[tuple[str, str]]:
        u2 = unit_squared(unit)
        return [
            ("level j", "@level"),
            ("scale τ", "@tau_s{%.4g} s (@tau_samples samples)"),
            ("WV ν²", f"@variance{{%.4g}} {u2}"),
            ("95% interval", f"@ci_low{{%.3g}} to @ci_high{{%.3g}} {u2}"),
            ("coefficients", "@n_coef"),
        ]

    @staticmethod
    def _model_tips(unit: str) -> list[tuple[str, str]]:
        return [
            ("curve", "@label"),
            ("scale τ", "@tau_s{%.4g} s"),
            ("WV ν²", f"@wv{{%.4g}} {unit_squared(unit)}"),
        ]

    # ------------------------------------------------------------------------------------
    def update(self, state: AppState) -> None:
        """Refresh every source from the state (data replaced in place, figures kept)."""
        wv = state.wv
        if state.unit != self._unit:
            self._unit = state.unit
            self.figure.yaxis.axis_label = f"wavelet variance ν² [{unit_squared(state.unit)}]"
            self.emp_hover.tooltips = self._emp_tips(state.unit)
            self.model_hover.tooltips = self._model_tips(state.unit)
        if wv is not self._shown_wv:
            self._shown_wv = wv
            self.emp.data = wv_data(wv)
            robust_pair = wv is not None and wv.robust and wv.classical is not None
            self.alt.data = wv_data(wv.classical if robust_pair else None)
            self.alt_item.visible = bool(robust_pair)
            self.emp_item.label = value(
                "robust WV (biweight)" if wv is not None and wv.robust else "empirical WV"
            )
            if wv is None:
                self.figure.title.text = "Load a log to see its wavelet variance"
            else:
                kind = "robust Haar WV" if wv.robust else "Haar WV"
                self.figure.title.text = (
                    f"{kind} of {state.channel} ({state.filename}), "
                    f"N = {wv.n:,} samples at {wv.fs:g} Hz"
                )
        self._update_model(state)

    def _update_model(self, state: AppState) -> None:
        wv = state.wv
        model = state.display_model()
        if wv is None or model is None:
            self.total.data = dict(_EMPTY_CURVE)
            self.total_item.visible = False
            for src, r, item in zip(self.comps, self.comp_renderers, self.comp_items, strict=True):
                if r.visible:
                    src.data = dict(_EMPTY_CURVE)
                    r.visible = False
                    item.visible = False
            self.resid.data = {k: np.zeros(0) for k in self.resid.data}
            return
        tau = model_grid(wv)
        tau_s = tau / wv.fs
        comps = model.components(tau, wv.fs)
        total = np.sum(np.array(list(comps.values())), axis=0)
        what = "what-if" if state.whatif else "fit"
        self.total.data = _curve(tau_s, total, f"model total ({what})")
        self.total_item.label = value(f"model total ({what})")
        self.total_item.visible = True
        names = dict(zip(model.labels, model.processes, strict=True))
        items = list(comps.items())
        for i, (src, r, item) in enumerate(
            zip(self.comps, self.comp_renderers, self.comp_items, strict=True)
        ):
            if i < len(items):
                lab, y = items[i]
                src.data = _curve(tau_s, y, lab)
                color = component_color(lab)
                if r.glyph.line_color != color:
                    r.glyph.line_color = color
                zero = not np.any(np.asarray(y) > 0)
                item.label = value(
                    f"{lab} {PROCESS_NAMES[names[lab].code]}" + (" (zero)" if zero else "")
                )
                r.visible = True
                item.visible = True
            elif r.visible:
                src.data = dict(_EMPTY_CURVE)
                r.visible = False
                item.visible = False
        implied = model.wv(wv.tau_samples, wv.fs)
        if not state.whatif and state.result is not None:
            implied = state.result.implied
        with np.errstate(divide="ignore", invalid="ignore"):
            ok = implied > 0
            d = np.where(ok, implied, np.nan)
            self.resid.data = {
                "tau_s": np.asarray(wv.tau_s, float),
                "ratio": _positive(wv.variance / d),
                "lo": _positive(wv.ci_low / d),
                "hi": _positive(wv.ci_high / d),
                "level": np.asarray(wv.levels),
            }


# -----------------------------------------------------------------------------------------
# tables
# -----------------------------------------------------------------------------------------
PARAM_COLUMNS = ("process", "parameter", "value", "low", "high", "unit")
DATASHEET_COLUMNS = ("process", "quantity", "value", "unit")


def log_figure(
    name: str,
    title: str,
    height: int,
    x_label: str,
    *,
    tools: str = "pan,wheel_zoom,box_zoom,reset,save",
    y_axis_type: str = "log",
    **kw: Any,
) -> Any:
    """A full-width plot over a log scale axis in the app's style (toolbar above, plain
    axis labels, light grid).

    Parameters
    ----------
    name, title
        The model name (tests find the plot by it) and the title.
    height
        Height in pixels.
    x_label
        The x axis label.
    tools
        Bokeh tools.
    y_axis_type
        ``"log"`` or ``"auto"`` (linear).
    **kw
        More ``figure`` settings (ranges, borders).

    Returns
    -------
    bokeh.plotting.figure
        The plot.
    """
    p = figure(
        x_axis_type="log",
        y_axis_type=y_axis_type,
        height=height,
        sizing_mode="stretch_width",
        tools=tools,
        toolbar_location="above",
        name=name,
        title=title,
        **kw,
    )
    p.xaxis.axis_label = x_label
    p.axis.axis_label_text_font_style = "normal"
    p.grid.grid_line_alpha = 0.35
    return p


def data_table(
    source: ColumnDataSource,
    columns: list[TableColumn],
    name: str,
    css: str,
    height: int,
    **flags: bool,
) -> DataTable:
    """A full-width table in the app's style: no index column, 26 px rows.

    Parameters
    ----------
    source, columns
        The table's data source and its columns.
    name, css
        The model name (tests find the table by it) and its CSS class.
    height
        Height in pixels.
    **flags
        ``sortable``, ``selectable``, ``reorderable``: passed to Bokeh's ``DataTable``, each
        False unless given.

    Returns
    -------
    DataTable
        The table.
    """
    flags = {"sortable": False, "selectable": False, "reorderable": False, **flags}
    # autosize_mode "fit_columns" throws "row is not defined" on data updates in BokehJS 3.9.2
    return DataTable(
        source=source,
        columns=columns,
        index_position=None,
        autosize_mode="force_fit",
        height=height,
        row_height=26,
        sizing_mode="stretch_width",
        name=name,
        css_classes=[css],
        **flags,
    )


def interval_band(
    p: Any,
    source: ColumnDataSource,
    y1: str = "ci_low",
    y2: str = "ci_high",
    color: str = BAND_COLOR,
    alpha: float = 0.25,
) -> Any:
    """Shade an interval between the columns ``y1`` and ``y2`` over ``tau_s``.

    Parameters
    ----------
    p
        The Bokeh figure.
    source
        The data source with ``tau_s``, ``y1`` and ``y2`` columns.
    y1, y2
        Lower and upper bound columns.
    color, alpha
        Fill colour and opacity.

    Returns
    -------
    GlyphRenderer
        The area's renderer.
    """
    return p.varea(x="tau_s", y1=y1, y2=y2, source=source, fill_color=color, fill_alpha=alpha)


def empirical_curve(
    p: Any, source: ColumnDataSource, y: str, line_width: float, size: float, **points_kw: Any
) -> tuple[Any, Any]:
    """Draw an empirical curve over ``tau_s``: a line through its points.

    Parameters
    ----------
    p
        The Bokeh figure.
    source
        The data source with ``tau_s`` and ``y`` columns.
    y
        The value column.
    line_width, size
        Width of the line and size of the points.
    **points_kw
        More settings of the points (e.g. their selection look).

    Returns
    -------
    tuple
        The line's and the points' renderers.
    """
    line = p.line("tau_s", y, source=source, line_color=EMPIRICAL_COLOR, line_width=line_width)
    pts = p.scatter(
        "tau_s",
        y,
        source=source,
        size=size,
        line_color=EMPIRICAL_COLOR,
        fill_color=EMPIRICAL_COLOR,
        **points_kw,
    )
    return line, pts


def _table(
    columns: tuple[str, ...], widths: dict[str, int], name: str, height: int, css: str
) -> tuple[DataTable, ColumnDataSource]:
    src = ColumnDataSource({c: [] for c in columns}, name=f"{name}_rows")
    cols = [TableColumn(field=c, title=c, width=widths.get(c, 80), sortable=False) for c in columns]
    return data_table(src, cols, name, css, height), src


def hidden_alert(alert_type: str, **kw: Any) -> Any:
    """An empty full-width alert, hidden until it has something to say.

    Parameters
    ----------
    alert_type
        ``"danger"``, ``"warning"`` or ``"info"``.
    **kw
        More settings (e.g. ``css_classes``).

    Returns
    -------
    panel.pane.Alert
        The alert.
    """
    import panel as pn

    return pn.pane.Alert(
        "", alert_type=alert_type, visible=False, sizing_mode="stretch_width", margin=(5, 10), **kw
    )


def redraw_table(table: DataTable) -> None:
    """Make BokehJS redraw a DataTable's cells after a data change that keeps the row count.

    BokehJS 3.9.2 redraws a DataTable when its CDSView's indices change; new values in as many
    rows leave the old cells on screen. Any change of the table model re-renders it.
    """
    n = int(table.tags[0]) + 1 if table.tags and isinstance(table.tags[0], int) else 1
    table.tags = [n]


class FitTables:
    """The parameter and datasheet tables (Bokeh DataTables, data replaced in place).

    Attributes
    ----------
    params, datasheet : bokeh.models.DataTable
        Columns ``process, parameter, value, unit`` and ``process, quantity, value, unit``.
    param_source, datasheet_source : ColumnDataSource
        Their data (strings: values formatted with 4 significant digits, units spelled out).
    """

    def __init__(self) -> None:
        self.params, self.param_source = _table(
            PARAM_COLUMNS,
            {"process": 60, "parameter": 90, "value": 90, "low": 90, "high": 90, "unit": 90},
            "parameters",
            300,
            "gmwm-params",
        )
        # the 95% interval columns, shown on request (the column list is swapped: BokehJS
        # 3.9 draws a column made visible later without its cells)
        self._all_columns = list(self.params.columns)
        for col in self._all_columns:
            if col.field in ("low", "high"):
                col.title = f"{col.field} (95%)"
        self._base_columns = [c for c in self._all_columns if c.field not in ("low", "high")]
        self.params.columns = list(self._base_columns)
        self.datasheet, self.datasheet_source = _table(
            DATASHEET_COLUMNS,
            {"process": 60, "quantity": 250, "value": 80, "unit": 110},
            "datasheet",
            300,
            "gmwm-datasheet",
        )

    def update(self, state: AppState) -> None:
        """Refresh both tables from the drawn model (fit or what-if)."""
        for src, rows, cols in (
            (self.param_source, parameter_rows(state), PARAM_COLUMNS),
            (self.datasheet_source, datasheet_rows(state), DATASHEET_COLUMNS),
        ):
            data = {c: [r[c] for r in rows] for c in cols}
            if data != src.data:
                same = len(rows) == len(next(iter(src.data.values()), []))
                src.data = data
                if same:
                    redraw_table(self.params if src is self.param_source else self.datasheet)
        cols_shown = self._all_columns if any(self.param_source.data["low"]) else self._base_columns
        if list(self.params.columns) != cols_shown:
            self.params.columns = list(cols_shown)


def _pretty(unit: str) -> str:
    return unit.replace("^2", "²")


def parameter_rows(state: AppState) -> list[dict[str, str]]:
    """Rows ``{"process", "parameter", "value", "unit"}`` of the drawn model (fit or what-if)."""
    m = state.display_model()
    if m is None:
        return []
    inf = state.inference() if state.show_intervals and not state.whatif else None
    ci = {i.name: i for i in inf.intervals} if inf is not None else {}
    rows = []
    for lab, p in zip(m.labels, m.processes, strict=True):
        for name, v in zip(p.param_names, p.values, strict=True):
            i = ci.get(f"{lab}.{name}")
            rows.append(
                {
                    "process": lab,
                    "parameter": name,
                    "value": format_value(float(v)),
                    "low": format_value(i.low) if i else "",
                    "high": format_value(i.high) if i else "",
                    "unit": _pretty(eg.param_unit(p.code, name, state.unit)),
                }
            )
    return rows


def datasheet_rows(state: AppState) -> list[dict[str, str]]:
    """Rows ``{"process", "quantity", "value", "unit"}``: ARW, rate random walk, 1/beta ..."""
    m = state.display_model()
    if m is None or not state.fs:
        return []
    return [
        {
            "process": r["label"],
            "quantity": r["quantity"],
            "value": format_value(float(r["value"])),
            "unit": _pretty(r["unit"]),
        }
        # the rows of the datasheet download (engine.units), bias-instability floor included
        for r in eg.datasheet(
            m,
            float(state.fs),
            state.unit,
            n_levels=state.wv.n_levels if state.wv is not None else None,
        )
    ]


def fit_summary(state: AppState) -> str:
    """One Markdown line about the fit: model, objective, time, convergence."""
    if state.wv is None:
        return "No data loaded."
    if not len(state.model):
        return "Empty model: only the empirical WV is shown. Add processes with the **+** buttons."
    obj = state.display_objective()
    obj_s = "n/a" if obj is None else format_value(obj)
    if state.whatif:
        return (
            f"**What-if** `{state.model.spec()}`: objective {obj_s} (weighted, "
            "dimensionless); curves follow the sliders, not a fit."
        )
    res = state.result
    if res is None:
        return f"`{state.model.spec()}`: not fitted."
    status = "converged" if res.converged else "**not converged**"
    return (
        f"**Fit** `{res.model.spec()}`: objective {obj_s} (weighted, dimensionless), "
        f"{len(state.wv)} levels, {1e3 * res.elapsed_s:.1f} ms ({res.method}), {status}."
    )
