"""The "Slope method" tab: the Allan variance slope method (AVSM) beside GMWM, for teaching.

The tab shows the overlapping Allan deviation of the session's channel (exactly
``sqrt(2 nu2)`` of its cached Haar WV at averaging times ``2^(j-1)`` samples: nothing is
recomputed from the raw data) with its 95% band. The user picks a process (WN slope -1/2,
QN -1, bias-instability floor 0, RW +1/2, DR +1) and drags a region on the plot (Bokeh box
select); the regions are shaded, the fixed-slope lines are drawn over them, and a table puts
the datasheet values the slope method reads (``engine.allan.avsm``) beside the "automatic"
read-off of the ROS tools (``avsm_auto``), the GMWM fit of the same processes (the
bias-instability floor has no process of its own in GMWM: a Gauss-Markov term plays its part)
and, on simulated data (teaching scenarios, the demo log), the truth. Each method's
model-implied Allan deviation, ``sqrt(2 x implied WV)``, is drawn over the data.

The built-in teaching scenarios (:mod:`engine.teaching`) are simulated in a worker thread and
loaded into the session (the Fit tab shows them too), with the regions a naive user picks and
a sentence on why the slope method goes wrong there.

Layers: pure functions (:func:`compute_slope`, :func:`comparison_values`,
:func:`comparison_rows`, :func:`implied_adev_curves`, :func:`slope_line_data`,
:func:`check_regions`, :func:`truth_model`) do the work and are tested without a browser;
:class:`SlopeView` builds its figure and table once and replaces ColumnDataSource data in place.
The fit runs off the server's event loop; a result that is no longer the latest is dropped.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
import param
from bokeh.models import (
    BoxAnnotation,
    BoxSelectTool,
    ColumnDataSource,
    DataTable,
    Legend,
    LegendItem,
    StringFormatter,
    TableColumn,
)
from bokeh.plotting import figure

import engine as eg
from engine.allan import AllanVariance, MethodEstimate, avsm, avsm_auto, from_gmwm
from engine.teaching import SCENARIOS, get_scenario, gmwm_spec

from .state import AppState, demo_path, format_value
from .views import BAND_COLOR, EMPIRICAL_COLOR, redraw_table

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = [
    "SlopeView",
    "SlopeResult",
    "PROCESS_CHOICES",
    "TABLE_COLUMNS",
    "METHODS",
    "MIN_POINTS",
    "check_regions",
    "compute_slope",
    "comparison_values",
    "comparison_rows",
    "implied_adev_curves",
    "slope_line_data",
    "truth_model",
]

log = logging.getLogger(__name__)

TITLE = "Slope method"

#: The processes of the slope method: label of the chooser -> code.
PROCESS_CHOICES: dict[str, str] = {
    "WN  slope −½": "WN",
    "QN  slope −1": "QN",
    "bias instability  floor": "BI",
    "RW  slope +½": "RW",
    "DR  slope +1": "DR",
}
CODE_ORDER = ("QN", "WN", "BI", "GM", "AR1", "RW", "DR")
REGION_COLORS = {
    "QN": "#9467BD",
    "WN": "#1F77B4",
    "BI": "#FF7F0E",
    "RW": "#2CA02C",
    "DR": "#8C564B",
}

#: Methods in the table and on the plot: column name -> (MethodEstimate.method, colour, dash).
METHODS: dict[str, tuple[str, str, str]] = {
    "AVSM": ("AVSM", "#D62728", "dashed"),
    "ROS auto": ("AVSM-auto", "#E69F00", "dotted"),
    "GMWM": ("GMWM", "#1F4E8C", "solid"),
}
TRUTH_COLOR = "#2E7D32"
TABLE_COLUMNS = ("process", "quantity", "AVSM", "ROS auto", "GMWM", "truth", "unit")

#: Averaging times a region must hold (one point fixes a line, two show whether it fits).
MIN_POINTS = 2
_GRID_PER_OCTAVE = 8


# -----------------------------------------------------------------------------------------
# pure helpers (tested without a browser)
# -----------------------------------------------------------------------------------------
@dataclass
class SlopeResult:
    """Everything the tab shows for one WV and one set of regions.

    Attributes
    ----------
    av : AllanVariance or None
        The octave Allan variance of the (classical) WV.
    estimates : dict
        ``"AVSM"``, ``"ROS auto"``, ``"GMWM"`` -> :class:`~engine.allan.MethodEstimate`
        (missing when the method could not run; the reason is in ``messages``).
    truth : Model or None
        The true model of simulated data.
    regions : dict
        The regions that were used, ``{code: (tau_lo_s, tau_hi_s)}``.
    gmwm_spec : str
        The model fitted by GMWM (``""`` when no region is set).
    messages : list of str
        What could not be done, in words (bad regions, a fit that failed ...).
    """

    av: AllanVariance | None
    estimates: dict[str, MethodEstimate] = field(default_factory=dict)
    truth: eg.Model | None = None
    regions: dict[str, tuple[float, float]] = field(default_factory=dict)
    gmwm_spec: str = ""
    messages: list[str] = field(default_factory=list)


def check_regions(
    av: AllanVariance, regions: Mapping[str, tuple[float, float]], min_points: int = MIN_POINTS
) -> tuple[dict[str, tuple[float, float]], list[str]]:
    """Split the regions into usable ones and messages about the others.

    Parameters
    ----------
    av : AllanVariance
        The Allan variance the regions are drawn on.
    regions : mapping
        ``{code: (tau_lo_s, tau_hi_s)}``, averaging times in seconds.
    min_points : int
        Averaging times a region must hold.

    Returns
    -------
    good : dict
        The usable regions.
    messages : list of str
        One sentence per unusable region: what is wrong and what to do.
    """
    good: dict[str, tuple[float, float]] = {}
    msgs: list[str] = []
    tau = av.tau_s
    for code, (lo, hi) in regions.items():
        if code not in REGION_COLORS:
            msgs.append(f"unknown process {code!r} (use QN, WN, BI, RW or DR)")
            continue
        if not (math.isfinite(lo) and lo >= 0 and hi >= lo):
            msgs.append(
                f"the {code} region ({lo:g} to {hi:g} s) is not an interval of averaging times"
            )
            continue
        k = int(np.sum((tau >= lo * (1 - 1e-9)) & (tau <= hi * (1 + 1e-9))))
        if k == 0:
            msgs.append(
                f"the {code} region ({lo:.3g} to {hi:.3g} s) holds no averaging time "
                f"of this log (it has {tau[0]:.3g} to {tau[-1]:.3g} s): drag it over "
                "the points"
            )
        elif k < min_points:
            msgs.append(
                f"the {code} region ({lo:.3g} to {hi:.3g} s) holds {k} averaging "
                f"time; drag over at least {min_points} points to see a slope"
            )
        else:
            good[code] = (float(lo), float(hi))
    return good, msgs


def compute_slope(
    wv: eg.WaveletVariance | None,
    regions: Mapping[str, tuple[float, float]],
    truth: eg.Model | None = None,
    *,
    gmwm: Callable[[eg.WaveletVariance, str], MethodEstimate] | None = None,
    min_points: int = MIN_POINTS,
) -> SlopeResult:
    """The slope method, its automatic read-off and GMWM on one WV (pure; worker-thread safe).

    Parameters
    ----------
    wv : WaveletVariance or None
        The session's WV (a robust WV is replaced by its classical one: the Allan variance
        is the classical estimator).
    regions : mapping
        ``{code: (tau_lo_s, tau_hi_s)}`` with codes among QN, WN, BI, RW, DR.
    truth : Model, optional
        The true model (simulated data).
    gmwm : callable, optional
        ``gmwm(wv, spec) -> MethodEstimate`` (a cache); default ``from_gmwm(fit_gmwm(wv, spec))``.
    min_points : int
        Averaging times each region must hold.

    Returns
    -------
    SlopeResult
        Never raises for bad regions or failed fits: they become ``messages``.
    """
    if wv is None:
        return SlopeResult(None, truth=truth, messages=["load a log first"])
    if wv.robust:
        if wv.classical is None:
            return SlopeResult(
                None,
                truth=truth,
                messages=[
                    "this channel has a robust WV only; the Allan variance needs the classical one"
                ],
            )
        wv = wv.classical
    if wv.n_levels < 2:
        return SlopeResult(
            None,
            truth=truth,
            messages=["the log is too short for an Allan deviation plot (fewer than 2 levels)"],
        )
    av = AllanVariance.from_wv(wv)
    out = SlopeResult(av, truth=truth)
    good, msgs = check_regions(av, regions, min_points)
    out.regions = good
    out.messages += msgs
    if good:
        try:
            out.estimates["AVSM"] = avsm(av, good)
        except ValueError as e:
            out.messages.append(f"slope method: {e}")
    elif not regions:
        out.messages.append(
            "choose a process and drag over the points of the plot to set its region"
        )
    try:
        out.estimates["ROS auto"] = avsm_auto(av)
    except ValueError as e:
        out.messages.append(f"automatic read-off: {e}")
    out.gmwm_spec = gmwm_spec(list(good))
    if out.gmwm_spec:
        try:
            fit = gmwm or (lambda w, s: from_gmwm(eg.fit_gmwm(w, s)))
            out.estimates["GMWM"] = fit(wv, out.gmwm_spec)
        except (ValueError, ArithmeticError) as e:  # ModelError / FitError are ValueErrors
            out.messages.append(f"GMWM could not fit {out.gmwm_spec}: {e}")
    return out


def _sort_key(label: str) -> int:
    code = label.split("_")[0]
    return CODE_ORDER.index(code) if code in CODE_ORDER else len(CODE_ORDER)


def comparison_values(
    estimates: Mapping[str, MethodEstimate | None],
    truth: eg.Model | None,
    fs: float,
    unit: str = "",
) -> list[dict[str, Any]]:
    """Datasheet quantities of each method and of the truth, side by side (numbers).

    Parameters
    ----------
    estimates : mapping
        Column name (``"AVSM"``, ``"ROS auto"``, ``"GMWM"``) -> estimate or None.
    truth : Model or None
        The true model (every value set).
    fs : float
        Sampling frequency (Hz), for the datasheet conversions.
    unit : str
        Signal unit.

    Returns
    -------
    list of dict
        ``{"process", "quantity", "unit", <column>: float or None ...}``, one row per
        datasheet quantity (``engine.datasheet``: N, Q, K, R, GM correlation time ...;
        the slope method's bias instability B), in the order QN, WN, BI, GM, RW, DR.
    """
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    sources: list[tuple[str, list[dict[str, Any]]]] = []
    for col in METHODS:
        e = estimates.get(col)
        if e is not None:
            sources.append((col, e.datasheet()))
    if truth is not None and len(truth) and truth.is_set:
        sources.append(("truth", eg.datasheet(truth, fs, unit)))
    for col, ds in sources:
        for r in ds:
            key = (r["label"], r["quantity"])
            row = rows.setdefault(
                key,
                {
                    "process": r["label"],
                    "quantity": r["quantity"],
                    "unit": r["unit"],
                    **{c: None for c in METHODS},
                    "truth": None,
                },
            )
            row[col] = float(r["value"])
    order = sorted(rows, key=lambda k: _sort_key(k[0]))  # stable: datasheet order within
    return [rows[k] for k in order]


def comparison_rows(values: list[dict[str, Any]]) -> dict[str, list[str]]:
    """The table's columns (strings) from :func:`comparison_values`."""

    def fmt(v: Any) -> str:
        return "" if v is None else format_value(float(v))

    out: dict[str, list[str]] = {c: [] for c in TABLE_COLUMNS}
    for r in values:
        out["process"].append(r["process"])
        out["quantity"].append(r["quantity"])
        out["unit"].append(str(r["unit"]).replace("^2", "²"))
        for c in (*METHODS, "truth"):
            out[c].append(fmt(r[c]))
    return out


def _grid(av: AllanVariance) -> np.ndarray:
    """Averaging times (samples) of the smooth curves: the measured span, 8 per octave."""
    lo, hi = math.log2(float(av.tau_samples[0])), math.log2(float(av.tau_samples[-1]))
    k = max(int(round((hi - lo) * _GRID_PER_OCTAVE)) + 1, 2)
    return 2.0 ** np.linspace(lo, hi, k)


def implied_adev_curves(result: SlopeResult) -> dict[str, dict[str, np.ndarray]]:
    """Model-implied Allan deviation of each method (and the truth) over the measured span.

    ``ADEV(m) = sqrt(2 nu2(2m))`` with ``nu2`` the implied Haar WV at scale ``2m`` samples
    (CONVENTIONS); the slope method's bias-instability floor adds ``(0.664 B)^2`` to the AVAR.

    Returns
    -------
    dict
        Column name (``"AVSM"``, ``"ROS auto"``, ``"GMWM"``, ``"truth"``) -> ``{"tau_s",
        "adev"}`` (empty arrays when that method has no estimate).
    """
    empty = {"tau_s": np.zeros(0), "adev": np.zeros(0)}
    names = (*METHODS, "truth")
    if result.av is None:
        return {c: dict(empty) for c in names}
    av = result.av
    m = _grid(av)
    tau_s = m / av.fs
    out: dict[str, dict[str, np.ndarray]] = {}
    for col in METHODS:
        e = result.estimates.get(col)
        if e is None:
            out[col] = dict(empty)
            continue
        nu = np.asarray(e.implied_at(2.0 * m), float)
        out[col] = {"tau_s": tau_s, "adev": _pos_sqrt(2.0 * nu)}
    t = result.truth
    if t is not None and len(t) and t.is_set:
        out["truth"] = {"tau_s": tau_s, "adev": _pos_sqrt(2.0 * t.wv(2.0 * m, av.fs))}
    else:
        out["truth"] = dict(empty)
    return out


def _pos_sqrt(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    return np.where(a > 0, np.sqrt(np.where(a > 0, a, 1.0)), np.nan)


def slope_line_data(result: SlopeResult) -> dict[str, list[Any]]:
    """The slope method's fixed-slope lines (for a ``multi_line``) and where they are read.

    Each line ``log10 ADEV = intercept + slope log10 tau`` is drawn over its region, extended
    to the averaging time where the datasheet value is read (1 s for N, 3 s for K, ...).

    Returns
    -------
    dict
        ``xs``, ``ys`` (lists of 2-point lists), ``color``, ``code``, and ``read_tau``,
        ``read_adev`` (the reading point; NaN for the bias-instability floor).
    """
    out: dict[str, list[Any]] = {
        "xs": [],
        "ys": [],
        "color": [],
        "code": [],
        "read_tau": [],
        "read_adev": [],
    }
    e = result.estimates.get("AVSM")
    if e is None:
        return out
    for code, ln in e.details.get("lines", {}).items():
        lo, hi = float(ln["tau_lo"]), float(ln["tau_hi"])
        rt = ln.get("read_tau_s")
        if rt is not None:
            lo, hi = min(lo, rt), max(hi, rt)
        lo, hi = lo / 1.25, hi * 1.25
        xs = [lo, hi]
        ys = [10.0 ** (ln["intercept"] + ln["slope"] * math.log10(x)) for x in xs]
        out["xs"].append(xs)
        out["ys"].append(ys)
        out["color"].append(REGION_COLORS.get(code, "#555555"))
        out["code"].append(code)
        out["read_tau"].append(float(rt) if rt is not None else math.nan)
        out["read_adev"].append(
            10.0 ** (ln["intercept"] + ln["slope"] * math.log10(rt)) if rt is not None else math.nan
        )
    return out


def _demo_truth_path() -> Any:
    p = demo_path()
    return p.with_name(f"{p.stem}_truth.json")


def truth_model(state: AppState) -> eg.Model | None:
    """The true model of the session's channel when the data are simulated, else None.

    Teaching scenarios carry it in the log's ``meta["truth"]``; the demo log's is in
    ``<demo>_truth.json`` beside it. None when the sampling frequency was changed by the user
    (per-sample values would no longer be the truth) or the channel has no known truth.
    """
    lg = state.log
    if lg is None or not state.channel:
        return None
    if state.fs and lg.fs and abs(float(state.fs) - float(lg.fs)) > 1e-9 * float(lg.fs):
        return None
    spec = (lg.meta or {}).get("truth", {}).get(state.channel)
    if spec is None and state.source == "demo":
        p = _demo_truth_path()
        try:
            with open(p, encoding="utf-8") as f:
                spec = json.load(f).get("models", {}).get(state.channel)
        except (OSError, ValueError):
            spec = None
    if not spec:
        return None
    try:
        m = eg.parse_model(spec)
    except ValueError:
        return None
    return m if m.is_set else None


def _regions_text(result: SlopeResult) -> str:
    if result.av is None or not result.regions:
        return ""
    tau = result.av.tau_s
    parts = []
    for code, (lo, hi) in result.regions.items():
        k = int(np.sum((tau >= lo * (1 - 1e-9)) & (tau <= hi * (1 + 1e-9))))
        parts.append(f"**{code}** {lo:.3g}–{hi:.3g} s ({k} points)")
    return "Regions: " + " · ".join(parts)


# -----------------------------------------------------------------------------------------
# the tab
# -----------------------------------------------------------------------------------------
class SlopeView(pn.viewable.Viewer):
    """Widgets, figure, table and callbacks of the "Slope method" tab of one session.

    Parameters
    ----------
    state : AppState
        The session state.
    jobs : Jobs
        The session's job runner (worker pool, document lock, data loads).

    Attributes
    ----------
    panel : panel.layout.Column
        The tab's content.
    regions : dict
        ``{code: (tau_lo_s, tau_hi_s)}``, the regions the user set (or a scenario's).
    result : SlopeResult or None
        What is shown.
    """

    active = param.Boolean(default=True, doc="Whether the tab is shown.")

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(**params)
        self.jobs = jobs
        self.state: AppState = state
        self.regions: dict[str, tuple[float, float]] = {}
        self._scenario_seen = ""  # last scenario whose naive regions were offered
        self.result: SlopeResult | None = None
        self._ticket = 0
        self._key: Any = None
        self._dirty = True
        self._syncing = False
        self._gmwm_cache: dict[tuple[eg.WaveletVariance, str], MethodEstimate] = {}
        self.computing = False

        self._build_widgets()
        self._build_figure()
        self._build_table()
        self._build_layout()
        self.state.param.watch(self._on_state, "revision")
        self.param.watch(self._on_tab, "active")
        self.refresh()

    # ------------------------------------------------------------------------------------
    # construction (once)
    # ------------------------------------------------------------------------------------
    def _build_widgets(self) -> None:
        opts = {"(your data: choose a teaching scenario to load one)": ""}
        opts.update({sc.title: key for key, sc in SCENARIOS.items()})
        self.scenario_select = pn.widgets.Select(
            label="Teaching scenario",
            options=opts,
            value="",
            width=420,
            css_classes=["gmwm-scenario"],
        )
        self.scenario_select.param.watch(self._on_scenario, "value")
        self.process = pn.widgets.RadioButtonGroup(
            label="Process",
            options=PROCESS_CHOICES,
            value="WN",
            color="default",
            variant="outline",
            margin=(22, 10, 5, 10),
            css_classes=["gmwm-slope-process"],
        )
        self.clear_button = pn.widgets.Button(
            label="Clear regions", color="light", width=130, margin=(22, 5, 5, 5)
        )
        self.clear_button.on_click(lambda _e: self.clear_regions())
        self.explain = pn.pane.Alert(
            "",
            alert_type="info",
            visible=False,
            sizing_mode="stretch_width",
            margin=(5, 10),
            css_classes=["gmwm-scenario-why"],
        )
        self.message = pn.pane.Alert(
            "",
            alert_type="warning",
            visible=False,
            sizing_mode="stretch_width",
            margin=(5, 10),
            css_classes=["gmwm-slope-message"],
        )
        self.status = pn.pane.Markdown(
            "",
            sizing_mode="stretch_width",
            margin=(0, 10),
            styles={"font-size": "13px", "color": "#555"},
        )

    def _build_figure(self) -> None:
        p = figure(
            x_axis_type="log",
            y_axis_type="log",
            height=460,
            sizing_mode="stretch_width",
            tools="pan,wheel_zoom,reset,save",
            toolbar_location="above",
            name="slope_adev",
            title="Overlapping Allan deviation",
        )
        p.xaxis.axis_label = "averaging time τ [s]"
        p.yaxis.axis_label = "Allan deviation"
        p.axis.axis_label_text_font_style = "normal"
        p.grid.grid_line_alpha = 0.35
        self.adev_src = ColumnDataSource(
            {"tau_s": [], "adev": [], "lo": [], "hi": []}, name="slope_adev_points"
        )
        band = p.varea(
            x="tau_s",
            y1="lo",
            y2="hi",
            source=self.adev_src,
            fill_color=BAND_COLOR,
            fill_alpha=0.25,
        )
        line = p.line(
            "tau_s", "adev", source=self.adev_src, line_color=EMPIRICAL_COLOR, line_width=1.5
        )
        pts = p.scatter(
            "tau_s",
            "adev",
            source=self.adev_src,
            size=7,
            color=EMPIRICAL_COLOR,
            selection_color="#D62728",
            nonselection_alpha=1.0,
        )
        self.box_select = BoxSelectTool(dimensions="width", renderers=[pts], persistent=False)
        p.add_tools(self.box_select)
        p.toolbar.active_drag = self.box_select
        self.adev_src.selected.on_change("indices", self._on_select)
        self.boxes = {
            c: BoxAnnotation(
                left=1.0,
                right=1.0,
                fill_color=col,
                fill_alpha=0.12,
                line_color=col,
                line_alpha=0.5,
                visible=False,
            )
            for c, col in REGION_COLORS.items()
        }
        for b in self.boxes.values():
            p.add_layout(b)
        self.lines_src = ColumnDataSource(slope_line_data(SlopeResult(None)), name="slope_lines")
        lines = p.multi_line(
            "xs", "ys", source=self.lines_src, line_color="color", line_width=3, line_alpha=0.85
        )
        reads = p.scatter(
            "read_tau",
            "read_adev",
            source=self.lines_src,
            marker="diamond",
            size=11,
            color="color",
            line_color="white",
        )
        self.curve_srcs: dict[str, ColumnDataSource] = {}
        items = [
            LegendItem(label="Allan deviation (95% band)", renderers=[line, pts, band]),
            LegendItem(label="slope lines (◆ read-off point)", renderers=[lines, reads]),
        ]
        styles = {
            **{c: (col, dash) for c, (_m, col, dash) in METHODS.items()},
            "truth": (TRUTH_COLOR, "dashdot"),
        }
        for col, (color, dash) in styles.items():
            src = ColumnDataSource({"tau_s": [], "adev": []}, name=f"slope_curve_{col}")
            r = p.line(
                "tau_s",
                "adev",
                source=src,
                line_color=color,
                line_dash=dash,
                line_width=2.5 if col == "GMWM" else 2,
            )
            self.curve_srcs[col] = src
            items.append(
                LegendItem(label=f"{col} implied" if col != "truth" else "truth", renderers=[r])
            )
        legend = Legend(
            items=items,
            location="top_right",
            click_policy="hide",
            label_text_font_size="11px",
            background_fill_alpha=0.7,
        )
        p.add_layout(legend, "right")
        self.figure = p

    def _build_table(self) -> None:
        widths = {
            "process": 60,
            "quantity": 230,
            "AVSM": 90,
            "ROS auto": 90,
            "GMWM": 90,
            "truth": 90,
            "unit": 120,
        }
        self.table_src = ColumnDataSource({c: [] for c in TABLE_COLUMNS}, name="slope_rows")
        cols = [
            TableColumn(
                field=c, title=c, width=widths[c], sortable=False, formatter=StringFormatter()
            )
            for c in TABLE_COLUMNS
        ]
        # autosize_mode "fit_columns" fails on data updates in BokehJS 3.9.2 (see views.py)
        self.table = DataTable(
            source=self.table_src,
            columns=cols,
            index_position=None,
            sortable=False,
            reorderable=False,
            selectable=False,
            autosize_mode="force_fit",
            height=260,
            row_height=26,
            sizing_mode="stretch_width",
            name="slope_table",
            css_classes=["gmwm-slope-table"],
        )

    def _build_layout(self) -> None:
        h = pn.pane.Markdown
        note = h(
            "Pick a process, then drag over the points where its slope shows (box select): "
            "the slope method (IEEE Std 952) reads its datasheet value off a line of fixed "
            "slope. **ROS auto** is the automatic read-off of the ROS calibration tools. "
            "**GMWM** fits the same processes to the whole wavelet variance; the "
            "bias-instability floor has no process of its own there, a Gauss-Markov (GM) "
            "term plays its part.",
            sizing_mode="stretch_width",
            margin=(0, 10),
            styles={"font-size": "13px", "color": "#444"},
        )
        self.panel = pn.Column(
            pn.Row(self.scenario_select, sizing_mode="stretch_width"),
            self.explain,
            note,
            pn.Row(self.process, self.clear_button, sizing_mode="stretch_width"),
            self.message,
            self.status,
            pn.pane.Bokeh(self.figure, sizing_mode="stretch_width"),
            h("#### Datasheet values by method", margin=(0, 10)),
            pn.pane.Bokeh(self.table, sizing_mode="stretch_width", margin=(5, 10)),
            sizing_mode="stretch_width",
        )

    # ------------------------------------------------------------------------------------
    # actions (also called by tests)
    # ------------------------------------------------------------------------------------
    def set_region(self, code: str, lo: float, hi: float) -> None:
        """Set the averaging-time region (seconds) of a process and recompute."""
        if code not in REGION_COLORS:
            self._show_messages([f"unknown process {code!r} (use QN, WN, BI, RW or DR)"])
            return
        lo, hi = (float(lo), float(hi)) if lo <= hi else (float(hi), float(lo))
        self.regions[code] = (lo, hi)
        self.refresh(force=True)

    def clear_regions(self) -> None:
        """Remove every region."""
        self.regions = {}
        self.refresh(force=True)

    def load_scenario(self, key: str) -> None:
        """Simulate a teaching scenario (worker thread), load it and set its naive regions."""
        try:
            sc = get_scenario(key)
        except KeyError as e:
            self._show_messages([str(e.args[0])])
            return

        def work() -> Any:
            loaded = AppState.read("scenario", path=key)
            AppState.precompute(loaded, sc.channel)
            return loaded

        def apply(loaded: Any) -> None:
            self.regions = dict(sc.region_dict)
            self._scenario_seen = key
            self._key = None
            self.jobs.install(loaded)
            if self.state.source == "scenario" and self.state.path == key:
                self.state.set_model(sc.model.cleared())  # the Fit tab fits the true form

        self.status.object = f"⏳ Simulating the scenario '{sc.title}' ..."
        self.jobs.load(f"Simulating the scenario '{sc.title}'", work, apply)

    # ------------------------------------------------------------------------------------
    # callbacks (thin)
    # ------------------------------------------------------------------------------------
    def _on_scenario(self, event: Any) -> None:
        if self._syncing or not event.new:
            return
        if self.state.source == "scenario" and self.state.path == event.new:
            return
        self.load_scenario(event.new)

    def _on_select(self, _attr: str, _old: Any, new: list[int]) -> None:
        if self._syncing or not new:
            return
        tau = np.asarray(self.adev_src.data["tau_s"], float)
        idx = [i for i in new if 0 <= i < tau.size]
        self._syncing = True
        try:
            self.adev_src.selected.indices = []  # the shaded region shows it now
        finally:
            self._syncing = False
        if idx:
            self.set_region(self.process.value, float(tau[idx].min()), float(tau[idx].max()))

    def _on_state(self, _event: Any = None) -> None:
        try:
            self.refresh()
        except Exception as e:  # a display problem must not break the session
            log.exception("slope view refresh failed")
            self._show_messages([f"display error: {type(e).__name__}: {e}"])

    def _on_tab(self, _event: Any = None) -> None:
        if self._visible() and self._dirty:
            self._on_state()

    def _visible(self) -> bool:
        return self.active or not self.jobs.served  # tests, notebooks: always up to date

    # ------------------------------------------------------------------------------------
    # state -> computation -> views
    # ------------------------------------------------------------------------------------
    def refresh(self, force: bool = False) -> None:
        """Recompute when the data or the regions changed (only while the tab is shown)."""
        s = self.state
        self._sync_scenario()
        # the WV object itself (identity), not its id(): an id can be reused after collection
        key = (s.wv, s.unit, s.source, s.path, s.channel, s.fs, tuple(sorted(self.regions.items())))
        if key == self._key and not force:
            return
        if not self._visible():
            self._dirty = True
            return
        self._dirty = False
        self._key = key
        wv, regions, truth = s.wv, dict(self.regions), truth_model(s)
        self.computing = True
        self.status.object = "⏳ Reading the slopes and fitting GMWM ..."
        self._ticket += 1
        # outside a server at once (tests, notebooks: no server loop to hand back to);
        # compute_slope reports bad regions itself, anything else is shown by _failed
        self.jobs.run(
            partial(compute_slope, wv, regions, truth, gmwm=self._gmwm),
            self.show,
            self._failed,
            partial(self._computed, self._ticket),
            key="slope",
            inline=not self.jobs.served,
        )

    def _gmwm(self, wv: eg.WaveletVariance, spec: str) -> MethodEstimate:
        """GMWM of ``spec`` on ``wv``, cached (moving a region does not refit)."""
        key = (wv, spec)  # holds the WV: identity, never a reused id
        est = self._gmwm_cache.get(key)
        if est is None:
            est = from_gmwm(eg.fit_gmwm(wv, spec))
            if len(self._gmwm_cache) >= 16:
                self._gmwm_cache.clear()
            self._gmwm_cache[key] = est
        return est

    def _computed(self, ticket: int) -> None:
        if ticket == self._ticket:  # not when a newer one runs
            self.computing = False

    def _failed(self, err: BaseException) -> None:
        log.error("slope computation failed: %s: %s", type(err).__name__, err)
        self.status.object = ""
        self._show_messages([f"could not compute: {type(err).__name__}: {err}"])

    def __panel__(self) -> pn.Column:
        """The tab's content."""
        return self.panel

    def show(self, result: SlopeResult) -> None:
        """Draw a result: points, regions, lines, implied curves, table, messages."""
        self.result = result
        av = result.av
        unit = self.state.unit or "unit"
        if av is None:
            self.adev_src.data = {"tau_s": [], "adev": [], "lo": [], "hi": []}
        else:
            self.adev_src.data = {
                "tau_s": np.asarray(av.tau_s, float),
                "adev": np.asarray(av.adev, float),
                "lo": np.asarray(av.adev_low, float),
                "hi": np.asarray(av.adev_high, float),
            }
        label = f"Allan deviation [{unit}]"
        if self.figure.yaxis[0].axis_label != label:
            self.figure.yaxis.axis_label = label
        self.figure.title.text = (
            f"Overlapping Allan deviation of {self.state.channel}"
            if self.state.channel
            else "Overlapping Allan deviation"
        )
        for code, box in self.boxes.items():
            reg = self.regions.get(code)
            if reg is None:
                box.visible = False
            else:
                box.update(left=max(reg[0], 1e-300), right=max(reg[1], reg[0]), visible=True)
        self.lines_src.data = slope_line_data(result)
        for col, data in implied_adev_curves(result).items():
            self.curve_srcs[col].data = data
        fs = float(av.fs) if av is not None else float(self.state.fs or 1.0)
        data = comparison_rows(
            comparison_values(result.estimates, result.truth, fs, self.state.unit)
        )
        if data != self.table_src.data:
            same = len(data["process"]) == len(self.table_src.data.get("process", []))
            self.table_src.data = data
            if same:
                redraw_table(self.table)
        self._show_messages(result.messages)
        parts = [_regions_text(result)]
        if result.gmwm_spec:
            parts.append(f"GMWM model: **{result.gmwm_spec}**")
        if result.truth is not None:
            parts.append(f"truth: `{result.truth.spec(values=True)}`")
        self.status.object = "  \n".join(p for p in parts if p)

    def _show_messages(self, msgs: list[str]) -> None:
        text = "  \n".join(f"• {m}" for m in msgs)
        hint = len(msgs) == 1 and msgs[0].startswith("choose a process")  # guidance, no fault
        self.message.param.update(
            object=text, visible=bool(msgs), alert_type="info" if hint else "warning"
        )

    def _sync_scenario(self) -> None:
        """The scenario menu and the explanation follow the session's data."""
        s = self.state
        key = s.path if s.source == "scenario" and s.path in SCENARIOS else ""
        if self.scenario_select.value != key:
            self._syncing = True
            try:
                self.scenario_select.value = key
            finally:
                self._syncing = False
        if key and key != self._scenario_seen:
            # a scenario arrived by other means than the menu (a link, a restored session):
            # its naive regions (the state gave it its true model form)
            self._scenario_seen = key
            if not self.regions:
                self.regions = dict(SCENARIOS[key].region_dict)
        if key:
            sc = SCENARIOS[key]
            self.explain.param.update(
                object=f"**{sc.title}** ({sc.n} samples at {sc.fs:g} Hz, "
                f"{sc.duration_s:g} s; truth `{sc.model.spec(values=True)}`).  \n"
                f"Why the slope method goes wrong here: {sc.why}",
                visible=True,
            )
        elif self.explain.visible:
            self.explain.param.update(object="", visible=False)
