"""The figures and tables of the "Multi-channel" tab: a k x k grid of WV (diagonal) and
WCCV (off-diagonal) cells, each drawn from data built by :func:`grid_data` and updated in
place, and the rows of the covariance and parameter tables.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import panel as pn
from bokeh.layouts import gridplot
from bokeh.models import ColumnDataSource, DataRange1d, HoverTool
from bokeh.models.annotations import Title
from bokeh.models.widgets import DataTable, StringFormatter, TableColumn
from bokeh.plotting import figure

import engine as eg
from engine.units import squared

from .state import format_value
from .views import (
    BAND_COLOR,
    EMPIRICAL_COLOR,
    TOTAL_COLOR,
    component_color,
    data_table,
    interval_band,
    unit_squared,
)

__all__ = [
    "N_CELL_COMPONENTS",
    "PER_OCTAVE",
    "COV_COLUMNS",
    "PARAM_COLUMNS",
    "model_curve_grid",
    "grid_data",
    "covariance_rows",
    "parameter_rows",
    "CellFigure",
    "GridFigure",
    "make_table",
    "color_label",
]

#: Component renderers per cell at most (a model with more processes draws the first ones).
N_CELL_COMPONENTS = 8
#: ... built with the grid: a diagonal cell, an off-diagonal cell (GM+WN+RW draws 3 and 1);
#: more are added when a fit draws more (a 6-channel grid is 21 cells: 2,676 Bokeh models
#: with 8 per cell, 1,461 with these; docs/performance-app.md)
N_CELL_INITIAL = {True: 3, False: 1}
#: Points per octave of the smooth model curves.
PER_OCTAVE = 8

_HOLLOW = "white"


def _pretty(unit: str) -> str:
    return unit.replace("^2", "²")


# -----------------------------------------------------------------------------------------
# pure helpers (tested without a browser)
# -----------------------------------------------------------------------------------------
def model_curve_grid(n_levels: int, per_octave: int = PER_OCTAVE) -> np.ndarray:
    """Scales (samples) of the smooth model curves: ``2 .. 2^J``, ``per_octave`` per octave.

    Every ``per_octave``-th point is a dyadic scale ``2^j`` (where the empirical values are).
    """
    j = int(n_levels)
    return 2.0 ** np.linspace(1.0, float(j), (j - 1) * per_octave + 1)


def _nan_unless(mask: np.ndarray, a: np.ndarray) -> np.ndarray:
    return np.where(mask, a, np.nan)


def _empirical(wvm: eg.wv.WVMatrix, p: int, q: int) -> dict[str, Any]:
    v = np.asarray(wvm.values[:, p, q], float)
    lo = np.asarray(wvm.ci_low[:, p, q], float)
    hi = np.asarray(wvm.ci_high[:, p, q], float)
    tau_s = np.asarray(wvm.tau_s, float)
    base = {
        "tau_s": tau_s,
        "level": np.asarray(wvm.levels),
        "value": v,
        "ci_low": lo,
        "ci_high": hi,
    }
    if p == q:
        return {
            **base,
            "y": _nan_unless(v > 0, v),
            "y_low": _nan_unless(lo > 0, lo),
            "y_high": _nan_unless(hi > 0, hi),
            "fill": [EMPIRICAL_COLOR] * v.size,
            "sign": ["+" if x >= 0 else "-" for x in v],
        }
    a = np.abs(v)
    straddle = (lo <= 0) & (hi >= 0)
    ends = np.concatenate(
        [a[a > 0], np.abs(lo)[~straddle & (lo != 0)], np.abs(hi)[~straddle & (hi != 0)]]
    )
    floor = 0.5 * float(ends.min()) if ends.size else 1e-300
    y_low = np.where(straddle, floor, np.minimum(np.abs(lo), np.abs(hi)))
    y_high = np.maximum(np.abs(lo), np.abs(hi))
    return {
        **base,
        "y": _nan_unless(a > 0, a),
        "y_low": y_low,
        "y_high": y_high,
        "fill": [EMPIRICAL_COLOR if x >= 0 else _HOLLOW for x in v],
        "sign": ["+" if x >= 0 else "-" for x in v],
    }


def _empty_emp() -> dict[str, Any]:
    return {
        k: np.zeros(0)
        for k in ("tau_s", "level", "value", "ci_low", "ci_high", "y", "y_low", "y_high")
    } | {"fill": [], "sign": []}


def _empty_total() -> dict[str, Any]:
    return {"tau_s": np.zeros(0), "pos": np.zeros(0), "neg": np.zeros(0), "value": np.zeros(0)}


def _empty_comp() -> dict[str, Any]:
    return {"tau_s": np.zeros(0), "wv": np.zeros(0)}


def color_label(key: str) -> str:
    """``gyro_x:WN`` -> ``WN``; a shared key is its label."""
    return key.rpartition(":")[2]


def grid_data(
    wvm: eg.wv.WVMatrix, result: Any = None, per_octave: int = PER_OCTAVE
) -> dict[tuple[int, int], dict[str, Any]]:
    """The data of every cell of the grid (row p, column q, q <= p).

    Parameters
    ----------
    wvm : WVMatrix
        The empirical WV (diagonal) and WCCV (off-diagonal) with intervals.
    result : MGMWMResult, optional
        A fit of ``wvm``'s channels; None draws the empirical values only.
    per_octave : int
        Points per octave of the model curves (on :func:`model_curve_grid`).

    Returns
    -------
    dict
        ``(p, q) -> {"emp", "total", "components"}``. ``emp``: the columns of the empirical
        source: ``value``, ``ci_low``, ``ci_high`` as estimated, ``y``/``y_low``/``y_high``
        as drawn (the WV on the diagonal; ``|WCCV|`` off it, an interval containing 0
        reaching down to half the smallest non-zero magnitude of the cell), ``fill`` (hollow
        for a negative WCCV). ``total``: ``tau_s``, ``value`` (the implied WV/WCCV),
        ``pos``/``neg`` (its magnitude where positive/negative, else NaN). ``components``: a
        list of ``(key, label, negative, {"tau_s", "wv"})`` for every process non-zero in the
        cell (keys as ``MGMWMResult.components``: ``"RW"`` shared, ``"gyro_x:WN"`` own).
    """
    k = wvm.k
    out: dict[tuple[int, int], dict[str, Any]] = {}
    comps: dict[str, np.ndarray] = {}
    if result is not None:
        tau = model_curve_grid(wvm.n_levels, per_octave)
        tau_s = tau / wvm.fs
        comps = result.model.components(tau, wvm.fs)
        total = np.sum(np.array(list(comps.values())), axis=0)
    for p in range(k):
        for q in range(p + 1):
            cell: dict[str, Any] = {
                "emp": _empirical(wvm, p, q),
                "total": _empty_total(),
                "components": [],
            }
            if result is not None:
                t = total[:, p, q]
                cell["total"] = {
                    "tau_s": tau_s,
                    "value": t,
                    "pos": _nan_unless(t > 0, t),
                    "neg": _nan_unless(t < 0, -t),
                }
                for key, arr in comps.items():
                    y = arr[:, p, q]
                    if not np.any(y != 0):
                        continue
                    neg = bool(np.sum(y) < 0)
                    cell["components"].append(
                        (
                            key,
                            color_label(key),
                            neg,
                            {"tau_s": tau_s, "wv": _nan_unless(y != 0, np.abs(y))},
                        )
                    )
            out[(p, q)] = cell
    return out


COV_COLUMNS = ("process", "channel_a", "channel_b", "covariance", "unit", "correlation")
PARAM_COLUMNS = ("channel", "process", "parameter", "value", "unit")


def _channel_unit(wvm: eg.wv.WVMatrix, channel: str) -> str:
    i = wvm.channels.index(channel)
    return wvm.units[i] if i < len(wvm.units) else ""


def covariance_rows(result: Any) -> dict[str, list[Any]]:
    """Rows of the shared-process table: every pair ``a <= b`` of every shared group.

    Columns: ``process`` (label and code, with beta/phi for AR1/GM), ``channel_a``,
    ``channel_b``, ``covariance`` (float, per-sample linear parameter: WN sigma2, RW gamma2,
    AR1 innovation variance, GM stationary variance), ``unit`` (of the pair: ``(deg/s)^2``,
    or ``deg/s·m/s^2`` for channels in different units), ``correlation`` [1] (float; 1 on
    the diagonal pairs, NaN when a variance is 0).
    """
    rows: dict[str, list[Any]] = {c: [] for c in COV_COLUMNS}
    if result is None:
        return rows
    for lab, est in result.shared.items():
        name = lab if lab == est.code else f"{lab} ({est.code})"
        if est.nl is not None:
            name += (
                f", {est.nl_name} = {format_value(est.nl)}{' 1/s' if est.nl_name == 'beta' else ''}"
            )
        rho = est.corr
        g = est.channels
        units = [_channel_unit(result.wvm, c) for c in g]
        for a in range(len(g)):
            for b in range(a, len(g)):
                ua, ub = units[a], units[b]
                unit = squared(ua or "u") if ua == ub else f"{ua or 'u'}·{ub or 'u'}"
                rows["process"].append(name)
                rows["channel_a"].append(g[a])
                rows["channel_b"].append(g[b])
                rows["covariance"].append(float(est.cov[a, b]))
                rows["unit"].append(_pretty(unit))
                rows["correlation"].append(float(rho[a, b]))
    return rows


def parameter_rows(result: Any) -> dict[str, list[Any]]:
    """Rows of the per-channel parameter table (independent processes, plus the common
    beta/phi of shared AR1/GM processes); ``value`` as float."""
    rows: dict[str, list[Any]] = {c: [] for c in PARAM_COLUMNS}
    if result is None:
        return rows
    for r in result.param_records:
        if r.name.startswith("cov["):
            continue
        rows["channel"].append(f"shared ({', '.join(r.channels)})" if r.shared else r.channels[0])
        rows["process"].append(r.label)
        rows["parameter"].append(r.name)
        rows["value"].append(float(r.value))
        rows["unit"].append(_pretty(r.unit))
    return rows


class CellFigure:
    """One small log-log figure of the grid."""

    def __init__(self, diag: bool, x_range: Any, size: int, name: str) -> None:
        p = figure(
            x_axis_type="log",
            y_axis_type="log",
            width=size,
            height=int(0.8 * size),
            x_range=x_range,
            tools="pan,wheel_zoom,box_zoom,reset,save",
            name=name,
            title="",
            min_border_left=5,
            min_border_right=5,
        )
        if isinstance(p.title, Title):  # a figure's title is a Title model
            p.title.text_font_size = "12px"
        p.grid.grid_line_alpha = 0.35
        p.axis.major_label_text_font_size = "10px"
        self.diag = diag
        self.emp = ColumnDataSource(_empty_emp())
        if diag:
            interval_band(p, self.emp, "y_low", "y_high")
            p.line("tau_s", "y", source=self.emp, line_color=EMPIRICAL_COLOR, line_width=1.2)
        else:
            p.segment(
                x0="tau_s",
                y0="y_low",
                x1="tau_s",
                y1="y_high",
                source=self.emp,
                line_color=BAND_COLOR,
                line_width=2,
                line_alpha=0.7,
            )
        dots = p.scatter(
            "tau_s", "y", source=self.emp, size=5, fill_color="fill", line_color=EMPIRICAL_COLOR
        )
        p.add_tools(
            HoverTool(
                renderers=[dots],
                tooltips=[
                    ("level", "@level"),
                    ("τ [s]", "@tau_s{0.[000]e}"),
                    ("estimate", "@value{0.000e}"),
                    ("95% interval", "@ci_low{0.00e} .. @ci_high{0.00e}"),
                ],
            )
        )
        self.figure = p
        self.comps: list[ColumnDataSource] = []
        self.comp_renderers: list[Any] = []
        self.total_renderers: list[Any] = []  # (drawn on top of the components)
        self._grow(N_CELL_INITIAL[diag])
        self.total = ColumnDataSource(_empty_total())
        self.total_renderers = [
            p.line("tau_s", "pos", source=self.total, line_color=TOTAL_COLOR, line_width=2.2)
        ]
        if not diag:
            self.total_renderers.append(
                p.line(
                    "tau_s",
                    "neg",
                    source=self.total,
                    line_color=TOTAL_COLOR,
                    line_width=2.2,
                    line_dash="dotted",
                )
            )

    def _grow(self, n: int) -> None:
        """Hold ``n`` component renderers (at most :data:`N_CELL_COMPONENTS`), the model's
        total drawn on top of them."""
        n = min(n, N_CELL_COMPONENTS)
        if n <= len(self.comps):
            return
        p = self.figure
        for _ in range(len(self.comps), n):
            src = ColumnDataSource(_empty_comp())
            self.comps.append(src)
            self.comp_renderers.append(
                p.line("tau_s", "wv", source=src, line_width=1.6, line_dash="dashed", visible=False)
            )
        totals = self.total_renderers
        if totals:
            p.renderers = [*(r for r in p.renderers if r not in totals), *totals]

    def update(self, data: dict[str, Any] | None, title: str, ylabel: str) -> None:
        if isinstance(self.figure.title, Title):  # a figure's title is a Title model
            self.figure.title.text = title
        if self.figure.yaxis[0].axis_label != ylabel:
            self.figure.yaxis.axis_label = ylabel
        if data is None:
            self.emp.data = _empty_emp()
            self.total.data = _empty_total()
            comps: list[Any] = []
        else:
            self.emp.data = data["emp"]
            self.total.data = data["total"]
            comps = data["components"]
            self._grow(len(comps))
        for i, (src, r) in enumerate(zip(self.comps, self.comp_renderers, strict=True)):
            if i < len(comps):
                _key, lab, neg, d = comps[i]
                src.data = d
                r.glyph.line_color = component_color(lab)
                r.glyph.line_dash = "dotted" if neg else "dashed"
                r.visible = True
            elif r.visible or len(src.data["tau_s"]):
                src.data = _empty_comp()
                r.visible = False


class GridFigure:
    """The k x k grid (lower triangle and diagonal) with one shared x range."""

    def __init__(self, k: int) -> None:
        self.k = k
        size = max(170, min(300, 1000 // k))
        self.x_range = DataRange1d()
        self.cells: dict[tuple[int, int], CellFigure] = {}
        rows = []
        for p in range(k):
            row: list[Any] = []
            for q in range(k):
                if q <= p:
                    c = CellFigure(p == q, self.x_range, size, f"mcell_{p}_{q}")
                    self.cells[(p, q)] = c
                    row.append(c.figure)
                else:
                    row.append(None)
            rows.append(row)
        for q in range(k):
            self.cells[(k - 1, q)].figure.xaxis.axis_label = "scale τ [s]"
        self.layout = gridplot(rows, toolbar_location="right", merge_tools=True)
        self.pane = pn.pane.Bokeh(self.layout, margin=(5, 10))

    def update(self, wvm: eg.wv.WVMatrix | None, data: dict[tuple[int, int], Any] | None) -> None:
        for (p, q), cell in self.cells.items():
            if wvm is None or data is None:
                cell.update(None, "", "")
                continue
            a, b = wvm.channels[p], wvm.channels[q]
            ua = wvm.units[p] if p < len(wvm.units) else ""
            ub = wvm.units[q] if q < len(wvm.units) else ""
            if p == q:
                title, ylab = f"WV {a}", f"ν² [{unit_squared(ua)}]"
            else:
                unit = unit_squared(ua) if ua == ub else f"{ua or 'unit'}·{ub or 'unit'}"
                title, ylab = f"|WCCV| {a} × {b}", f"[{unit}]"
            cell.update(data[(p, q)], title, ylab if q == 0 else "")


def make_table(
    columns: Sequence[tuple[str, str, int, Any]], name: str, css: str, height: int
) -> tuple[ColumnDataSource, DataTable]:
    src = ColumnDataSource({c: [] for c, *_ in columns}, name=f"{name}_rows")
    cols = [
        TableColumn(field=c, title=t, width=w, formatter=f or StringFormatter(), sortable=False)
        for c, t, w, f in columns
    ]
    table = data_table(src, cols, name, css, height, reorderable=True)
    return src, table


# -----------------------------------------------------------------------------------------
# the tab
# -----------------------------------------------------------------------------------------
