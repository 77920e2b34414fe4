"""The "Plan" tab: how long to record, for the session's fitted model.

From the Fit tab's fit (its model, fs and unit) the tab plans a run
(:func:`engine.plan_run`): the precision of every IEEE quantity against the log length, drawn
on log-log axes with the current log's length as a vertical line and each target as a
horizontal one, and a sentence per target: the length it needs, and what the current log
gives. A lecturer types ``K within 10 %`` over a 20-minute log and the class sees why it
cannot give a rate random walk. Guide: ``docs/planning.md``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
import param
from bokeh.models import ColumnDataSource
from bokeh.models.annotations import Legend, LegendItem, Span

import engine as eg
from engine.inference import parse_targets

from . import views
from .state import AppState
from .tab_view import TabView

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["PlanView"]

#: Colours of the quantities' curves.
COLORS = {
    "N": "#1F77B4",
    "B": "#2CA02C",
    "ADEV_min": "#98DF8A",
    "K": "#D62728",
    "Q": "#9467BD",
    "R": "#8C564B",
}
DEFAULT_TARGETS = "K within 20 %, N within 2 %, B within 20 %"
NOTE = (
    "The precision (half-width of the 95 % interval, in % of the value) that an efficient "
    "GMWM fit of the Fit tab's model reaches at each log length, from its asymptotic "
    "covariance (no simulation). The dashed line is this log's length. Targets: e.g. "
    "`K within 10 %, N within 2 %` (N = ARW/VRW, B = bias instability, K = rate random walk)."
)


class PlanView(TabView):
    """Widgets, figure and callbacks of the "Plan" tab of one session.

    Attributes
    ----------
    plan : RunPlan or None
        What is drawn.
    """

    slug = "plan"

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(state, jobs, **params)
        self.plan: eg.inference.RunPlan | None = None
        self.targets = pn.widgets.TextInput(
            label="Targets (95 % intervals)",
            value=DEFAULT_TARGETS,
            width=420,
            css_classes=["gmwm-plan-targets"],
        )
        self.targets.param.watch(lambda _e: self.refresh(force=True), "value")
        self.status = pn.pane.Markdown(
            "", sizing_mode="stretch_width", margin=(0, 10), css_classes=["gmwm-plan-status"]
        )
        self.source = ColumnDataSource({"hours": [], **{k: [] for k in COLORS}}, name="plan_src")
        self.figure = views.log_figure(
            "plan_precision", "Precision against log length", 420, "log length [h]"
        )
        self.figure.yaxis.axis_label = "half-width of the 95 % interval [% of the value]"
        self.figure.xaxis.axis_label = "log length [h]"
        items = []
        for key, color in COLORS.items():
            r = self.figure.line("hours", key, source=self.source, line_color=color, line_width=2)
            items.append(LegendItem(label=key, renderers=[r]))
        self.figure.add_layout(
            Legend(
                items=items, location="top_right", click_policy="hide", background_fill_alpha=0.7
            )
        )
        self.now_line = Span(
            location=1.0, dimension="height", line_dash="dashed", line_color="#444", visible=False
        )
        self.figure.add_layout(self.now_line)
        # one horizontal line per quantity, shown where it has a target
        self.target_lines = {
            key: Span(
                location=1.0,
                dimension="width",
                line_color=color,
                line_dash="dotted",
                line_width=1.5,
                visible=False,
            )
            for key, color in COLORS.items()
        }
        for span in self.target_lines.values():
            self.figure.add_layout(span)
        self.panel[:] = [
            pn.pane.Markdown(NOTE, margin=(0, 10), styles={"font-size": "13px", "color": "#444"}),
            self.targets,
            self.message,
            self.status,
            pn.pane.Bokeh(self.figure, sizing_mode="stretch_width"),
        ]
        self.refresh()

    @param.depends("state.result", "state.n", watch=True)
    def _on_state(self) -> None:
        """The Fit tab's fit, or the log's length, changed."""
        super()._on_state()

    def _draw(self, force: bool) -> None:
        res = self.state.result
        if res is None or not res.model.is_set:
            self.show_message(
                ["Fit a model on the Fit tab first: the plan is made for it."], level="info"
            )
            self.status.object = ""
            return
        try:
            targets = parse_targets(self.targets.value or "")
        except ValueError as e:
            self.show_message([str(e)], level="warning")
            return
        self.show_message([])
        model, fs, unit, n_log = res.model, res.fs, res.wv.unit, int(self.state.n or res.wv.n)
        self.status.object = "Planning ..."

        def work() -> tuple[eg.inference.RunPlan, list[str]]:
            plan = eg.plan_run(model, fs, targets, unit=unit)
            return plan, plan.sentences(n_log)

        self._compute(work, lambda out: self._apply(out, n_log), key="plan")

    def _apply(self, out: tuple[eg.inference.RunPlan, list[str]], n_log: int) -> None:
        plan, sentences = out
        self.plan = plan
        data: dict[str, Any] = {"hours": list(plan.hours)}
        for key in COLORS:
            p = plan.precision.get(key)
            vals = np.full(plan.lengths.size, np.nan) if p is None else 100.0 * np.asarray(p)
            data[key] = [v if math.isfinite(v) and v < 1000.0 else math.nan for v in vals]
        self.source.data = data
        self.now_line.location = n_log / plan.fs / 3600.0
        self.now_line.visible = n_log > 0
        rel = {t.key: t.rel for t in plan.targets}
        for key, span in self.target_lines.items():
            span.visible = key in rel
            span.location = 100.0 * rel.get(key, 0.01)
        self.status.object = "  \n".join(sentences)

    def _failed(self, err: BaseException) -> None:
        self.status.object = ""
        self.show_message([f"Could not plan: {err}"], level="danger")
