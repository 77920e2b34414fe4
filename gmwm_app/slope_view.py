"""The "Slope method" tab: the Allan variance slope method (AVSM) beside GMWM, for teaching.

The tab shows the overlapping Allan deviation of the session's channel (exactly
``sqrt(2 nu2)`` of its cached Haar WV at averaging times ``2^(j-1)`` samples: nothing is
recomputed from the raw data) with its 95% band. The user picks a process (WN slope -1/2,
QN -1, bias-instability floor 0, RW +1/2, DR +1) and drags a region on the plot (Bokeh box
select); the regions are shaded, the fixed-slope lines are drawn over them, and a table puts
the datasheet values the slope method reads (``engine.teaching.avsm``) beside the "automatic"
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

from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
import param
from bokeh.models import BoxSelectTool, ColumnDataSource
from bokeh.models.annotations import BoxAnnotation, Legend, LegendItem
from bokeh.models.widgets import StringFormatter, TableColumn

import engine as eg
from engine.fit.estimate import MethodEstimate, from_gmwm
from engine.teaching import SCENARIOS, SLOPES, get_scenario

from .slope_data import (
    METHODS,
    REGION_COLORS,
    TABLE_COLUMNS,
    SlopeResult,
    comparison_rows,
    comparison_values,
    compute_slope,
    implied_adev_curves,
    regions_text,
    slope_line_data,
    truth_model,
)
from .state import AppState
from .tab_view import TabView
from .views import (
    data_table,
    empirical_curve,
    hidden_alert,
    interval_band,
    log_figure,
    redraw_table,
)

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["SlopeView", "PROCESS_CHOICES"]

TITLE = "Slope method"

#: The processes of the slope method: label of the chooser -> code.
_SLOPE_TEXT = {-1.0: "−1", -0.5: "−½", 0.5: "+½", 1.0: "+1"}
PROCESS_CHOICES: dict[str, str] = {
    (f"{c}  slope {_SLOPE_TEXT[s]}" if c != "BI" else "bias instability  floor"): c
    for c, s in sorted(SLOPES.items(), key=lambda cs: cs[0] != eg.WN.code)  # WN first
}

TRUTH_COLOR = "#2E7D32"


# -----------------------------------------------------------------------------------------
# the tab
# -----------------------------------------------------------------------------------------
class SlopeView(TabView):
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

    slug = "slope"

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(state, jobs, **params)
        self.regions: dict[str, tuple[float, float]] = {}
        self._scenario_seen = ""  # last scenario whose naive regions were offered
        self.result: SlopeResult | None = None
        self._key: Any = None
        self._gmwm_cache: dict[tuple[eg.WaveletVariance, str], MethodEstimate] = {}

        self._build_widgets()
        self._build_figure()
        self._build_table()
        self._build_layout()
        self.refresh()

    @param.depends(
        "state.wv",
        "state.unit",
        "state.source",
        "state.path",
        "state.channel",
        "state.fs",
        watch=True,
    )
    def _on_state(self) -> None:
        """The data the tab draws changed (its WV, unit, channel, fs, or the scenario)."""
        super()._on_state()

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
            value=eg.WN.code,
            color="default",
            variant="outline",
            margin=(22, 10, 5, 10),
            css_classes=["gmwm-slope-process"],
        )
        self.clear_button = pn.widgets.Button(
            label="Clear regions", color="light", width=130, margin=(22, 5, 5, 5)
        )
        # clearing redraws the figure's sources: under the document lock (TabView._locked)
        self.clear_button.on_click(lambda _e: self._locked(self.clear_regions))
        self.explain = hidden_alert("info", css_classes=["gmwm-scenario-why"])
        self.status = pn.pane.Markdown(
            "",
            sizing_mode="stretch_width",
            margin=(0, 10),
            styles={"font-size": "13px", "color": "#555"},
        )

    def _build_figure(self) -> None:
        p = log_figure(
            "slope_adev",
            "Overlapping Allan deviation",
            460,
            "averaging time τ [s]",
            tools="pan,wheel_zoom,reset,save",
        )
        p.yaxis.axis_label = "Allan deviation"
        self.adev_src = ColumnDataSource(
            {"tau_s": [], "adev": [], "lo": [], "hi": []}, name="slope_adev_points"
        )
        band = interval_band(p, self.adev_src, "lo", "hi")
        line, pts = empirical_curve(
            p, self.adev_src, "adev", 1.5, 7, selection_color="#D62728", nonselection_alpha=1.0
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
        self.table = data_table(self.table_src, cols, "slope_table", "gmwm-slope-table", 260)

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
        # idempotent: the menu showing the session's scenario (set by _sync_scenario) is a no-op
        if not event.new or (self.state.source == "scenario" and self.state.path == event.new):
            return
        self.load_scenario(event.new)

    def _on_select(self, _attr: str, _old: Any, new: list[int]) -> None:
        if not new:  # also the echo of clearing the selection below
            return
        tau = np.asarray(self.adev_src.data["tau_s"], float)
        idx = [i for i in new if 0 <= i < tau.size]
        self.adev_src.selected.indices = []  # the shaded region shows it now
        if idx:
            self.set_region(self.process.value, float(tau[idx].min()), float(tau[idx].max()))

    # ------------------------------------------------------------------------------------
    # state -> computation -> views
    # ------------------------------------------------------------------------------------
    def _draw(self, force: bool) -> None:
        """Recompute when the data or the regions changed."""
        s = self.state
        self._sync_scenario()
        # the WV object itself (identity), not its id(): an id can be reused after collection
        key = (s.wv, s.unit, s.source, s.path, s.channel, s.fs, tuple(sorted(self.regions.items())))
        if key == self._key and not force:
            return
        self._key = key
        wv, regions, truth = s.wv, dict(self.regions), truth_model(s)
        self.status.object = "⏳ Reading the slopes and fitting GMWM ..."
        # compute_slope reports bad regions itself, anything else is shown by _failed
        self._compute(
            partial(compute_slope, wv, regions, truth, gmwm=self._gmwm), self.draw, "slope"
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

    def _failed(self, err: BaseException) -> None:
        self.status.object = ""
        self._show_messages([f"could not compute: {type(err).__name__}: {err}"])

    def draw(self, result: SlopeResult) -> None:
        """Draw a result: points, regions, lines, implied curves, table, messages."""
        self.result = result
        av = result.av
        unit = self.state.unit or "u"
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
        rows = comparison_rows(
            comparison_values(result.estimates, result.truth, fs, self.state.unit)
        )
        if rows != self.table_src.data:
            same = len(rows["process"]) == len(self.table_src.data.get("process", []))
            self.table_src.data = rows
            if same:
                redraw_table(self.table)
        self._show_messages(result.messages)
        parts = [regions_text(result)]
        if result.gmwm_spec:
            parts.append(f"GMWM model: **{result.gmwm_spec}**")
        if result.truth is not None:
            parts.append(f"truth: `{result.truth.spec(values=True)}`")
        self.status.object = "  \n".join(p for p in parts if p)

    def _show_messages(self, msgs: list[str]) -> None:
        hint = len(msgs) == 1 and msgs[0].startswith("choose a process")  # guidance, no fault
        self.show_message(msgs, level="info" if hint else "warning")

    def _sync_scenario(self) -> None:
        """The scenario menu and the explanation follow the session's data."""
        s = self.state
        key = s.path if s.source == "scenario" and s.path in SCENARIOS else ""
        if self.scenario_select.value != key:
            self.scenario_select.value = key  # its echo in _on_scenario is a no-op
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
