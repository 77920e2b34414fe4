"""Bokeh figures of the app, built once per session and updated in place.

:class:`~gmwm_app.wv_figures.WVFigures` (the Fit tab's WV plot and residual strip) is in
:mod:`gmwm_app.wv_figures`; here are the plot building blocks the views share (log figures,
interval bands, empirical curves, tables, colours).

The table builders (:func:`parameter_rows`, :func:`datasheet_rows`, :func:`fit_summary`) return
plain data for the widgets of ``app.py``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any, Literal, TypeVar

import numpy as np
from bokeh.models import ColumnDataSource, Line, Scatter, VArea
from bokeh.models.renderers import GlyphRenderer
from bokeh.models.widgets import DataTable, TableColumn
from bokeh.plotting import figure

import engine as eg
from engine.units import squared

from .boundary import watcher
from .state import format_value

if TYPE_CHECKING:  # pragma: no cover
    from .state import AppState

__all__ = [
    "redraws",
    "hidden_alert",
    "wv_data",
    "FitTables",
    "component_color",
    "unit_squared",
    "model_grid",
    "parameter_rows",
    "datasheet_rows",
    "fit_summary",
    "add_renderer",
]

_F = TypeVar("_F", bound=Callable[..., Any])


def redraws(what: str) -> Callable[[_F], _F]:
    """Decorate a view's method (taking no argument) that draws part of the page from the
    state (a watcher).

    A failure while drawing is a bug of the view, not of the state change that woke it: it is
    logged with its traceback and shown on the page as a display error (the error boundary,
    :func:`gmwm_app.boundary.report`, through the state's ``report_error``, on the object's
    ``state``), and never raised into the action that changed the state (which succeeded):
    param calls the state's watchers one after the other, and one raising would stop the
    others from drawing. The method then returns None.

    Parameters
    ----------
    what : str
        What the method draws, for the message (e.g. ``"the WV plot"``).
    """

    def decorate(fn: _F) -> _F:
        @functools.wraps(fn)
        def draw(self: Any) -> Any:  # no other arguments: param.depends reads the signature
            return watcher(
                partial(fn, self),
                f"drawing {what} failed",
                lambda e: self.state.report_error(
                    f"Display error in {what}: {type(e).__name__}: {e}"
                ),
            )

        return draw  # type: ignore[return-value]

    return decorate


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
    cls = eg.models.PROCESS_TYPES.get(code)
    if cls is not None and cls.color:
        return cls.color  # a kind that appears once has its own colour
    k = int(idx) - 1 if idx.isdigit() else 0
    # a kind that repeats (GM, AR1) takes the palette, each kind from its own offset (AR1 and
    # GM never mix, but keep their colours apart anyway)
    repeating = [c for c, t in eg.models.PROCESS_TYPES.items() if not t.color]
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
    y_axis_type: Literal["log", "linear", "auto"] = "log",
    x_axis_type: Literal["log", "linear", "auto"] = "log",
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
    y_axis_type, x_axis_type
        ``"log"`` or ``"auto"``/``"linear"``.
    **kw
        More ``figure`` settings (ranges, borders).

    Returns
    -------
    bokeh.plotting.figure
        The plot.
    """
    p = figure(
        x_axis_type=x_axis_type,
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
    *,
    sortable: bool = False,
    selectable: bool = False,
    reorderable: bool = False,
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
    sortable, selectable, reorderable
        Bokeh's ``DataTable`` settings.

    Returns
    -------
    DataTable
        The table.
    """
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
        sortable=sortable,
        selectable=selectable,
        reorderable=reorderable,
    )


def interval_band(
    p: Any,
    source: ColumnDataSource,
    y1: str = "ci_low",
    y2: str = "ci_high",
    color: str = BAND_COLOR,
    alpha: float = 0.25,
    plain: bool = False,
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
    plain : bool
        The glyph only, without its selected and muted looks (:func:`add_renderer`): for a
        plot without selection tools whose legend hides.

    Returns
    -------
    GlyphRenderer
        The area's renderer.
    """
    if plain:
        glyph = VArea(x="tau_s", y1=y1, y2=y2, fill_color=color, fill_alpha=alpha)
        return add_renderer(p, source, glyph)
    return p.varea(x="tau_s", y1=y1, y2=y2, source=source, fill_color=color, fill_alpha=alpha)


def add_renderer(p: Any, source: ColumnDataSource, glyph: Any, **kw: Any) -> GlyphRenderer:
    """Draw ``glyph`` from ``source`` on the plot ``p``, without looks of its own for selected,
    unselected or muted data (Bokeh's ``"auto"``: BokehJS derives them when it needs them).

    ``figure.line`` and the other glyph methods add two copies of each glyph (the unselected
    and the muted looks) as models of the page: two of every three glyph models of the Fit
    tab's plots, which have no selection tool and whose legends hide curves, never mute them,
    so that the copies were never drawn. Fewer models: a page is built and sent faster.

    Parameters
    ----------
    p : bokeh.plotting.figure
        The plot.
    source : ColumnDataSource
        The data.
    glyph : bokeh.models.Glyph
        The glyph (e.g. ``Line(x="tau_s", y="wv", line_color=...)``).
    **kw
        More renderer settings (``visible``, ``name``).

    Returns
    -------
    GlyphRenderer
        The renderer, added to ``p.renderers``.
    """
    return p.add_glyph(source, glyph, **kw)


def empirical_curve(
    p: Any,
    source: ColumnDataSource,
    y: str,
    line_width: float,
    size: float,
    plain: bool = False,
    **points_kw: Any,
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
    plain : bool
        The glyphs only, without their selected and muted looks (:func:`add_renderer`): for a
        plot without selection tools whose legend hides (no ``points_kw`` then).
    **points_kw
        More settings of the points (e.g. their selection look).

    Returns
    -------
    tuple
        The line's and the points' renderers.
    """
    if plain:
        if points_kw:
            raise TypeError(f"plain points take no more settings, got {sorted(points_kw)}")
        line = Line(x="tau_s", y=y, line_color=EMPIRICAL_COLOR, line_width=line_width)
        pts = Scatter(
            x="tau_s", y=y, size=size, line_color=EMPIRICAL_COLOR, fill_color=EMPIRICAL_COLOR
        )
        return add_renderer(p, source, line), add_renderer(p, source, pts)
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


def hidden_alert(alert_type: str, text: Any = None, **kw: Any) -> Any:
    """A full-width alert, hidden while it has nothing to say.

    Parameters
    ----------
    alert_type
        ``"danger"``, ``"warning"`` or ``"info"``.
    text
        What it says: a parameter (e.g. ``state.param.error``) the alert follows, shown when
        not empty. None: an empty alert its owner sets (``object`` and ``visible``).
    **kw
        More settings (e.g. ``css_classes``).

    Returns
    -------
    panel.pane.Alert
        The alert.
    """
    import panel as pn
    import param

    visible: Any  # False, or the parameter's truth (a reactive expression)
    if text is None:
        text, visible = "", False
    else:
        visible = param.rx(text).rx.bool()
    return pn.pane.Alert(
        text,
        alert_type=alert_type,
        visible=visible,
        sizing_mode="stretch_width",
        margin=(5, 10),
        **kw,
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
    """Rows ``{"process", "parameter", "value", "low", "high", "unit"}`` of the drawn model (fit
    or what-if), then, for a fit, its IEEE quantities (process ``IEEE``: N, B, ADEV_min,
    ADEV_data, K, Q, R in datasheet units)."""
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
                    "value": format_value(float(v)) if v is not None else "",
                    "low": format_value(i.low) if i else "",
                    "high": format_value(i.high) if i else "",
                    "unit": _pretty(eg.units.param_unit(p.code, name, state.unit)),
                }
            )
    res = state.result
    if not state.whatif and res is not None and hasattr(res, "ieee"):
        # the fit's IEEE quantities (engine.fit.ieee): N with its disguised share, B and the
        # ADEV minimum (model, data) at their T, K, Q, R; datasheet units; intervals on request
        for key, q in res.ieee.quantities.items():
            at = f" (T {q.tau_s:.3g} s)" if math.isfinite(q.tau_s) else ""
            rows.append(
                {
                    "process": "IEEE",
                    "parameter": key,
                    "value": format_value(q.datasheet_value),
                    "low": format_value(q.datasheet_low) if inf is not None else "",
                    "high": format_value(q.datasheet_high) if inf is not None else "",
                    "unit": _pretty(q.datasheet_unit) + at,
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
        for r in eg.units.datasheet(
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
