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

import asyncio
import html
import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
from bokeh.layouts import gridplot
from bokeh.models import (
    ColumnDataSource,
    DataRange1d,
    DataTable,
    HoverTool,
    NumberFormatter,
    ScientificFormatter,
    StringFormatter,
    TableColumn,
)
from bokeh.plotting import figure

import engine as eg
from engine.models import ModelError, parse_model
from engine.multivariate import SHAREABLE, DependenceTest, MultiModel
from engine.units import squared

from .state import format_value
from .views import (
    BAND_COLOR,
    EMPIRICAL_COLOR,
    TOTAL_COLOR,
    component_color,
    redraw_table,
    unit_squared,
)

if TYPE_CHECKING:  # pragma: no cover
    from .app import GMWMApp

__all__ = [
    "MultiView",
    "DEFAULT_SPEC",
    "DEFAULT_SHARED",
    "MIN_CHANNELS",
    "MAX_CHANNELS",
    "model_curve_grid",
    "grid_data",
    "covariance_rows",
    "parameter_rows",
    "parse_overrides",
    "shareable_labels",
    "build_model",
    "run_dependence_test",
    "dependence_text",
]

log = logging.getLogger(__name__)

#: The per-channel model shown first (the demo gyros: a bias instability, white noise and a
#: rate random walk) and the processes shared by every channel at first.
DEFAULT_SPEC = "GM+WN+RW"
DEFAULT_SHARED = ("RW",)
MIN_CHANNELS = 2
MAX_CHANNELS = 6
#: Component renderers per cell (a model with more processes draws the first ones).
N_CELL_COMPONENTS = 8
#: Shared-process controls created up front (one per shareable label of the model).
N_SHARE_POOL = 6
#: Points per octave of the smooth model curves.
PER_OCTAVE = 8
#: Wait (ms) after a change before a fit starts, on a server (a burst costs one fit).
DEBOUNCE_MS = 150
#: Cached WV/WCCV matrices per session.
N_CACHE = 4

_HOLLOW = "white"


def _message(e: BaseException) -> str:
    if isinstance(e, KeyError) and e.args:
        return str(e.args[0])
    return str(e) or type(e).__name__


def _pretty(unit: str) -> str:
    return unit.replace("^2", "²")


# -----------------------------------------------------------------------------------------
# pure helpers (tested without a browser)
# -----------------------------------------------------------------------------------------
def parse_overrides(text: str, channels: Sequence[str]) -> dict[str, str]:
    """Per-channel model specs from lines ``channel: spec`` (blank lines and ``#`` ignored).

    Raises
    ------
    ModelError
        A line without ``:``, or a channel that is not among ``channels``.
    """
    out: dict[str, str] = {}
    for raw in (text or "").splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, spec = line.partition(":")
        if not sep or not name.strip() or not spec.strip():
            raise ModelError(
                f"cannot read the per-channel line {raw.strip()!r}: write "
                "'channel: spec', e.g. 'gyro_z: GM+WN+RW'"
            )
        name = name.strip()
        if name not in channels:
            raise ModelError(
                f"the per-channel line names {name!r}, which is not among the "
                f"chosen channels ({', '.join(channels)})"
            )
        out[name] = spec.strip()
    return out


def shareable_labels(models: Mapping[str, eg.Model]) -> list[tuple[str, list[str]]]:
    """Labels of the shareable processes (WN, RW, AR1, GM) in model order, each with the
    channels whose model has it: ``[("GM", [...]), ("WN", [...]), ...]``."""
    order: list[str] = []
    has: dict[str, list[str]] = {}
    for c, m in models.items():
        for lab, p in zip(m.labels, m.processes, strict=True):
            if p.code not in SHAREABLE:
                continue
            if lab not in has:
                order.append(lab)
                has[lab] = []
            has[lab].append(c)
    return [(lab, has[lab]) for lab in order]


def build_model(
    channels: Sequence[str],
    spec: str,
    overrides: str = "",
    shared: Mapping[str, Sequence[str]] | None = None,
) -> MultiModel:
    """The multivariate model of the view's controls.

    Parameters
    ----------
    channels : sequence of str
        The chosen channels (2 to 6), in grid order.
    spec : str
        Latent model of every channel (``"WN+RW"``), parsed by :func:`engine.parse_model`.
    overrides : str
        Optional lines ``channel: spec`` replacing ``spec`` for some channels.
    shared : mapping of str to sequence of str, optional
        Label -> channels that share it; groups of fewer than 2 chosen channels mean "not
        shared" and are ignored.

    Returns
    -------
    MultiModel

    Raises
    ------
    ModelError
        Bad spec, unknown channel, a process that cannot be shared, fewer than 2 channels.
    """
    chans = list(channels)
    if len(chans) < MIN_CHANNELS:
        raise ModelError(
            f"choose at least {MIN_CHANNELS} channels (chosen: {', '.join(chans) or 'none'})"
        )
    if not (spec or "").strip():
        raise ModelError("the model is empty: type a per-channel model, e.g. WN+RW")
    base = parse_model(spec)
    per = parse_overrides(overrides, chans)
    models = {c: parse_model(per[c]) if c in per else base for c in chans}
    groups: dict[str, list[str]] = {}
    for lab, group in (shared or {}).items():
        g = [c for c in chans if c in set(group)]
        if len(g) >= 2:
            groups[lab] = g
    return MultiModel(chans, models, shared=groups)


def model_curve_grid(n_levels: int, per_octave: int = PER_OCTAVE) -> np.ndarray:
    """Scales (samples) of the smooth model curves: ``2 .. 2^J``, ``per_octave`` per octave.

    Every ``per_octave``-th point is a dyadic scale ``2^j`` (where the empirical values are).
    """
    j = int(n_levels)
    return 2.0 ** np.linspace(1.0, float(j), (j - 1) * per_octave + 1)


def _nan_unless(mask: np.ndarray, a: np.ndarray) -> np.ndarray:
    return np.where(mask, a, np.nan)


def _empirical(wvm: eg.WVMatrix, p: int, q: int) -> dict[str, Any]:
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


def _color_label(key: str) -> str:
    """``gyro_x:WN`` -> ``WN``; a shared key is its label."""
    return key.rpartition(":")[2]


def grid_data(
    wvm: eg.WVMatrix, result: Any = None, per_octave: int = PER_OCTAVE
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
                            _color_label(key),
                            neg,
                            {"tau_s": tau_s, "wv": _nan_unless(y != 0, np.abs(y))},
                        )
                    )
            out[(p, q)] = cell
    return out


COV_COLUMNS = ("process", "channel_a", "channel_b", "covariance", "unit", "correlation")
PARAM_COLUMNS = ("channel", "process", "parameter", "value", "unit")


def _channel_unit(wvm: eg.WVMatrix, channel: str) -> str:
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
            name += f", {est.nl_name} = {format_value(est.nl)}{' 1/s' if est.code == 'GM' else ''}"
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


def fit_text(result: Any) -> str:
    """One paragraph: objective, weights, method, time and warnings of a fit."""
    if result is None:
        return ""
    w = result.wvm
    parts = [
        f"**Objective** {format_value(result.objective)} [1] ({result.weights} "
        f"weights) for **{html.escape(result.model.spec())}**: {w.k} channels, "
        f"N = {w.n:,}, fs = {w.fs:g} Hz, {w.n_levels} levels; {result.method}, "
        f"{result.n_evaluations} evaluations, {1e3 * result.elapsed_s:.0f} ms."
    ]
    if result.psd_active:
        parts.append("A covariance is on the edge of positive semi-definiteness.")
    if result.at_bound:
        parts.append(f"At a bound: {html.escape(', '.join(result.at_bound))}.")
    parts += [f"Warning: {html.escape(w)}." for w in result.warnings]
    if not result.converged:
        parts.append(html.escape(result.message))
    return " ".join(parts)


class Cancelled(Exception):
    """Raised by the progress callback when the user cancels the dependence test."""


def run_dependence_test(
    wvm: eg.WVMatrix,
    model: MultiModel,
    *,
    B: int = 100,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> DependenceTest:
    """:func:`engine.dependence_test` of every shared process (``weights="ci"``, one worker).

    ``progress(done, B)`` is called first with ``done = 0`` and then after every replicate;
    it may raise to stop the test.

    Raises
    ------
    ModelError
        The model shares nothing.
    FitError
        Half of the replicates or more failed.
    """
    if B < 1:
        raise ValueError(f"B must be at least 1, got {B}")
    if not model.shared:
        raise ModelError(
            "the model shares no process: mark the channels that share one first (nothing to test)"
        )
    if progress is not None:
        progress(0, B)  # the two observed fits come first
    return eg.dependence_test(
        wvm, model, B=B, seed=seed, workers=1, weights="ci", progress=progress
    )


def dependence_text(t: DependenceTest, spec: str) -> str:
    """The test's outcome in words (Markdown)."""
    verdict = (
        "the channels are dependent (the shared covariances improve the fit more than chance)"
        if t.p_value < 0.05
        else "no evidence of dependence at the 5% level"
    )
    return (
        f"**Dependence test** of {', '.join(t.labels)} in *{html.escape(spec)}*: "
        f"D = Q(independent) - Q(shared) = {format_value(t.statistic)} [1], "
        f"p = {format_value(t.p_value, 3)} from {t.B} parametric-bootstrap replicates: "
        f"{verdict}."
    )


# -----------------------------------------------------------------------------------------
# figures (built once per grid size, updated in place)
# -----------------------------------------------------------------------------------------
class _Cell:
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
        p.title.text_font_size = "12px"
        p.grid.grid_line_alpha = 0.35
        p.axis.major_label_text_font_size = "10px"
        self.diag = diag
        self.emp = ColumnDataSource(_empty_emp())
        if diag:
            p.varea(
                x="tau_s",
                y1="y_low",
                y2="y_high",
                source=self.emp,
                fill_color=BAND_COLOR,
                fill_alpha=0.25,
            )
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
        self.comps = [ColumnDataSource(_empty_comp()) for _ in range(N_CELL_COMPONENTS)]
        self.comp_renderers = [
            p.line("tau_s", "wv", source=s, line_width=1.6, line_dash="dashed", visible=False)
            for s in self.comps
        ]
        self.total = ColumnDataSource(_empty_total())
        p.line("tau_s", "pos", source=self.total, line_color=TOTAL_COLOR, line_width=2.2)
        if not diag:
            p.line(
                "tau_s",
                "neg",
                source=self.total,
                line_color=TOTAL_COLOR,
                line_width=2.2,
                line_dash="dotted",
            )
        self.figure = p

    def update(self, data: dict[str, Any] | None, title: str, ylabel: str) -> None:
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


class _Grid:
    """The k x k grid (lower triangle and diagonal) with one shared x range."""

    def __init__(self, k: int) -> None:
        self.k = k
        size = max(170, min(300, 1000 // k))
        self.x_range = DataRange1d()
        self.cells: dict[tuple[int, int], _Cell] = {}
        rows = []
        for p in range(k):
            row: list[Any] = []
            for q in range(k):
                if q <= p:
                    c = _Cell(p == q, self.x_range, size, f"mcell_{p}_{q}")
                    self.cells[(p, q)] = c
                    row.append(c.figure)
                else:
                    row.append(None)
            rows.append(row)
        for q in range(k):
            self.cells[(k - 1, q)].figure.xaxis.axis_label = "scale τ [s]"
        self.layout = gridplot(rows, toolbar_location="right", merge_tools=True)
        self.pane = pn.pane.Bokeh(self.layout, margin=(5, 10))

    def update(self, wvm: eg.WVMatrix | None, data: dict[tuple[int, int], Any] | None) -> None:
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


def _table(
    columns: Sequence[tuple[str, str, int, Any]], name: str, css: str, height: int
) -> tuple[ColumnDataSource, DataTable]:
    src = ColumnDataSource({c: [] for c, *_ in columns}, name=f"{name}_rows")
    cols = [
        TableColumn(field=c, title=t, width=w, formatter=f or StringFormatter(), sortable=False)
        for c, t, w, f in columns
    ]
    table = DataTable(
        source=src,
        columns=cols,
        index_position=None,
        sortable=False,
        selectable=False,
        autosize_mode="force_fit",
        height=height,
        row_height=26,
        sizing_mode="stretch_width",
        name=name,
        css_classes=[css],
    )
    return src, table


# -----------------------------------------------------------------------------------------
# the tab
# -----------------------------------------------------------------------------------------
class MultiView:
    """Widgets, grid, tables and callbacks of the "Multi-channel" tab of one session.

    Parameters
    ----------
    app : GMWMApp
        The session's app (its ``state`` holds the loaded log).

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

    def __init__(self, app: GMWMApp) -> None:
        self.app = app
        self.state = app.state
        self.wvm: eg.WVMatrix | None = None
        self.result: Any = None
        self.error = ""
        self.n_fits = 0
        self.n_wvm = 0  # WV/WCCV matrices computed (cache misses)
        self._syncing = False
        self._running = False
        self._dirty = False
        self._stale = False
        self._scheduled = False
        self._ticker: Any = None
        self._idle = threading.Event()
        self._idle.set()
        self._cache_lock = threading.Lock()
        self._cache_log: Any = None
        self._cache: dict[tuple, tuple[eg.WVMatrix, str]] = {}
        self._data_key: Any = None
        self._shared_groups: dict[str, list[str]] = {lab: [] for lab in DEFAULT_SHARED}
        self._shared_all = set(DEFAULT_SHARED)  # labels shared by every channel (default)
        self._share_labels: list[str] = []
        self._grids: dict[int, _Grid] = {}
        self.grid: _Grid | None = None

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

        self.alert = pn.pane.Alert(
            "", alert_type="danger", visible=False, sizing_mode="stretch_width", margin=(5, 10)
        )
        self.notice = pn.pane.Alert(
            "", alert_type="info", visible=False, sizing_mode="stretch_width", margin=(5, 10)
        )
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
        self.cov_source, self.cov_table = _table(
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
        self.param_source, self.param_table = _table(
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
        self._dep_last = 0.0
        self.dep_b = pn.widgets.IntInput(
            label="Bootstrap replicates B", value=100, start=10, end=2000, step=10, width=170
        )
        self.dep_button = pn.widgets.Button(
            label="Test dependence",
            color="primary",
            width=150,
            margin=(22, 5, 5, 10),
            description="Parametric bootstrap of the objective difference (shared vs independent)",
        )
        self.dep_button.on_click(lambda _e: self.start_dependence_test())
        self.dep_cancel = pn.widgets.Button(
            label="Cancel", color="light", width=90, margin=(22, 5, 5, 5), disabled=True
        )
        self.dep_cancel.on_click(lambda _e: self.cancel_dependence_test())
        self.dep_progress = pn.indicators.Progress(
            value=0,
            max=100,
            bar_color="primary",
            height=14,
            visible=False,
            sizing_mode="stretch_width",
            margin=(0, 10),
        )
        self.dep_text = pn.pane.Markdown(
            "", sizing_mode="stretch_width", margin=(0, 10), css_classes=["gmwm-mdependence"]
        )

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
            sizing_mode="stretch_width",
        )
        self.state.param.watch(self._on_state, "revision")
        tabs = getattr(app, "tabs", None)
        if tabs is not None:
            tabs.param.watch(self._on_tab, "active")
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
        tabs = getattr(self.app, "tabs", None)
        if tabs is None:
            return True
        try:
            return tabs._names[tabs.active] == "Multi-channel"
        except (IndexError, AttributeError):
            return False

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
    def wv_matrix_for(self, lg: Any, channels: Sequence[str], fs: float) -> tuple[eg.WVMatrix, str]:
        """The WV/WCCV matrix of some channels of a log, and a notice (truncation).

        Computed once per (log, channels, fs) and cached (worker-thread safe).

        Raises
        ------
        ValueError
            No raw data (a WV summary file), too few or unusable channels.
        """
        if lg is None:
            raise ValueError("load a log first")
        if lg.is_summary:
            raise ValueError(
                f"{getattr(lg, 'source', '') or 'this file'} is a wavelet-variance "
                "summary without raw samples: the wavelet cross-covariance needs "
                "the raw channels of a log (CSV, NPY/NPZ or HDF5)"
            )
        chans = tuple(channels)
        key = (chans, float(fs))
        with self._cache_lock:
            if self._cache_log is not lg:
                self._cache_log, self._cache = lg, {}
            hit = self._cache.get(key)
        if hit is not None:
            return hit
        series = {c: np.asarray(lg.channels[c]) for c in chans}
        sizes = {c: int(a.size) for c, a in series.items()}
        n = min(sizes.values())
        note = ""
        if len(set(sizes.values())) > 1:
            desc = ", ".join(f"{c}: {v:,}" for c, v in sizes.items())
            note = (
                f"The channels have different lengths ({desc} samples); all are "
                f"truncated to the shortest, {n:,} samples."
            )
            series = {c: a[:n] for c, a in series.items()}
        units = {c: str((getattr(lg, "units", None) or {}).get(c, "")) for c in chans}
        wvm = eg.wv_matrix(series, channels=list(chans), fs=float(fs), units=units)
        with self._cache_lock:
            if self._cache_log is lg:
                self._cache[key] = (wvm, note)
                while len(self._cache) > N_CACHE:
                    self._cache.pop(next(iter(self._cache)))
            self.n_wvm += 1
        return wvm, note

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
        if self.app._served:
            if self._scheduled:
                return
            self._scheduled = True
            self._idle.clear()
            doc = self.app._doc

            def fire() -> None:
                self._scheduled = False
                self._start()

            doc.add_timeout_callback(fire, DEBOUNCE_MS)
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
            wvm, note = self.wv_matrix_for(lg, chans, float(fs or lg.fs))
            try:
                mm = build_model(chans, spec, over, groups)
                res = eg.fit_mgmwm(wvm, mm)
            except ValueError as e:  # ModelError, FitError: bad spec, unidentifiable, short
                return wvm, None, f"Could not fit the model: {_message(e)}", note
            return wvm, res, "", note

        def apply(out: tuple[Any, Any, str, str]) -> None:
            if self._dirty or settings != self._settings():
                return  # overtaken by a change: the next fit shows the current settings
            wvm, res, err, note = out
            self._show(wvm, res, err, note)

        def fail(e: BaseException) -> None:
            if self._dirty or settings != self._settings():
                return
            self._show(None, None, f"Could not compute the WV/WCCV matrix: {_message(e)}", "")

        def done() -> None:
            self._running = False
            self._set_busy(False)
            if self._dirty:
                self._dirty = False
                self.request_fit()
            elif not self._scheduled:
                self._idle.set()

        self.app._spawn(partial(self._background, work, apply, fail, done))

    async def _background(
        self,
        work: Callable[[], Any],
        apply: Callable[[Any], Any],
        fail: Callable[[BaseException], Any],
        done: Callable[[], Any],
    ) -> None:
        """Run ``work`` in the app's worker pool; the rest under the document lock."""
        from .app import _EXECUTOR

        out: Any = None
        err: BaseException | None = None
        try:
            out = await asyncio.get_running_loop().run_in_executor(_EXECUTOR, work)
        except asyncio.CancelledError:  # the session closed
            self.app._locked(done)
            raise
        except Exception as e:  # reported in the view, never a traceback
            if not isinstance(e, (ValueError, KeyError, TypeError, Cancelled)):
                log.exception("multi-channel fit failed")
            err = e

        def finish() -> None:
            try:
                if err is not None:
                    fail(err)
                else:
                    apply(out)
            except Exception as e:  # a display problem: say so, keep the session
                log.exception("multi-channel display failed")
                self._message(f"Display error: {type(e).__name__}: {e}")
            finally:
                done()

        self.app._locked(finish)

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
        if observer is not None:
            observer(done, total)
        if self._dep_cancel.is_set():
            raise Cancelled
        now = time.perf_counter()
        if done == total or now - self._dep_last > 0.1:  # at most ~10 updates a second
            self._dep_last = now
            value = int(100 * done / max(total, 1))
            text = f"⏳ Bootstrap replicate {done} of {total} ..."
            self.app._locked(
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
                self.dep_text.object = f"**Dependence test failed:** {html.escape(_message(e))}"

        self.app._spawn(
            partial(self._background, work, apply, fail, lambda: self._dep_running(False))
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
        doc = self.app._doc if self.app._served else None
        if self._ticker is not None and doc is not None:
            try:
                doc.remove_periodic_callback(self._ticker)
            except ValueError:  # already removed
                pass
        self._ticker = None
        if not on:
            if self.status.object.startswith("⏳"):
                self.status.object = ""
            return
        t0 = time.perf_counter()
        text = html.escape(message)
        self.status.object = f"⏳ {text} ..."
        if doc is not None:

            def tick() -> None:
                self.status.object = (
                    f"⏳ {text} ... {time.perf_counter() - t0:.0f} s (the "
                    "grid shows the previous fit until this one ends)"
                )

            self._ticker = doc.add_periodic_callback(tick, 1000)

    def _message(self, text: str) -> None:
        self.error = text
        self.alert.param.update(object=html.escape(text), visible=bool(text))

    def _grid_for(self, k: int) -> _Grid:
        g = self._grids.get(k)
        if g is None:
            g = self._grids[k] = _Grid(k)
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

    @staticmethod
    def _legend(result: Any) -> str:
        items = [(TOTAL_COLOR, "model total", "solid")]
        if result is not None:
            seen: dict[str, str] = {}
            shared = {lab: est.channels for lab, est in result.shared.items()}
            for key in result.components:
                lab = _color_label(key)
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
