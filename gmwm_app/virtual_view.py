"""The "virtual sensor" view of the Multi-channel tab: the optimal weighted mean of the
channels (``engine.virtual_sensor``), for channels that measure the same quantity (one axis
of several IMUs).

From the tab's MGMWM fit: the weights (sum 1) that minimise the virtual sensor's WV at one
scale, over a band, or over every level (each relative to the plain average's WV), the
weights from the data alone (no model), a figure of the WV of every channel, of their plain
average and of the virtual sensor (empirical points, the implied curve and its 95% interval),
and a download of the virtual sensor's model in any export format (as one channel:
``VirtualSensor.as_fit()``). The computation runs in the session's job runner (key
``"virtual"``: a newer request supersedes an older one), never on the event loop.
"""

from __future__ import annotations

import html
import io
import logging
import math
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
from bokeh.models import ColumnDataSource
from bokeh.models.widgets import NumberFormatter, ScientificFormatter

import engine as eg
from engine.formats import FORMATS, export
from engine.units import param_unit

from .data import message_of
from .multi_figures import make_table
from .session_view import download_button
from .views import (
    TOTAL_COLOR,
    hidden_alert,
    interval_band,
    log_figure,
    redraw_table,
    unit_squared,
)

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["VirtualView", "parse_target", "EXPORT_FORMATS"]

log = logging.getLogger(__name__)

#: Formats offered for the virtual sensor's model (those that need no filter rate).
EXPORT_FORMATS = tuple(k for k, f in FORMATS.items() if not f.needs_filter_rate)
SENSOR_COLOR = "#9e9e9e"
AVERAGE_COLOR = "#1f77b4"
VIRTUAL_COLOR = "#111111"


def parse_target(text: str) -> dict[str, Any]:
    """The criterion typed by the user: ``""`` every level, ``"10"`` one scale (s),
    ``"1:100"`` a band (s). Raises ValueError with a readable message."""
    t = (text or "").strip()
    if not t:
        return {}
    try:
        if ":" in t:
            lo, hi = (float(v) for v in t.split(":", 1))
            if not (0 < lo <= hi and math.isfinite(hi)):
                raise ValueError
            return {"band": (lo, hi)}
        s = float(t)
        if not (s > 0 and math.isfinite(s)):
            raise ValueError
        return {"scale": s}
    except ValueError:
        raise ValueError(
            f"the scale {t!r} is not a number of seconds (10) or a band S1:S2 (1:100)"
        ) from None


class VirtualView:
    """Widgets, figure and table of the virtual-sensor view.

    Parameters
    ----------
    jobs : Jobs
        The session's job runner.
    safely : callable
        ``safely(fn, *args)`` runs ``fn(*args)`` and shows an exception in the tab (logged)
        instead of raising it (:meth:`gmwm_app.tab_view.TabView._safely`).

    Attributes
    ----------
    panel : panel.Column
        The view's layout (appended to the Multi-channel tab).
    sensor : VirtualSensor or None
        What is shown.
    error : str
        The message shown (empty when fine).
    """

    def __init__(self, jobs: Jobs, safely: Callable[..., None]) -> None:
        self.jobs = jobs
        self._safely = safely
        self.result: Any = None
        self.sensor: eg.multivariate.VirtualSensor | None = None
        self.error = ""
        self._auto_name = "virtual"
        self.target_input = pn.widgets.TextInput(
            label="Minimise the WV at (s): empty = every scale, 10 = one scale, 1:100 = a band",
            value="",
            width=420,
            css_classes=["gmwm-vtarget"],
        )
        self.relative = pn.widgets.Checkbox(
            label="each scale relative to the average's WV", value=True, margin=(30, 10, 5, 10)
        )
        for w in (self.target_input, self.relative):
            # a bad target clears the figures' sources at once: under the document lock
            # (Panel runs a widget's callback without it; TabView._locked)
            w.param.watch(lambda _e: self.jobs.locked(partial(self._safely, self.refresh)), "value")
        self.alert = hidden_alert("danger")
        self.info = pn.pane.Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        sci = ScientificFormatter(precision=4)
        self.weight_source, self.weight_table = make_table(
            [
                ("channel", "channel", 120, None),
                ("weight", "w [1]", 80, NumberFormatter(format="0.0000")),
                ("weight_fitted", "w (model) [1]", 95, NumberFormatter(format="0.0000")),
                ("weight_data", "w (data) [1]", 95, NumberFormatter(format="0.0000")),
                ("adev", "Allan dev.", 95, sci),
                ("unit", "unit", 70, None),
            ],
            "virtual_weights",
            "gmwm-vweights",
            240,
        )
        self.sensor_source = ColumnDataSource({"xs": [], "ys": [], "name": []})
        self.average_source = ColumnDataSource({"tau_s": [], "wv": []})
        self.virtual_source = ColumnDataSource(
            {"tau_s": [], "empirical": [], "implied": [], "ci_low": [], "ci_high": []}
        )
        p = log_figure("virtual_wv", "Virtual sensor", 360, "scale tau [s]")
        p.multi_line(
            "xs", "ys", source=self.sensor_source, line_color=SENSOR_COLOR, legend_label="sensors"
        )
        p.line(
            "tau_s",
            "wv",
            source=self.average_source,
            line_color=AVERAGE_COLOR,
            line_dash="dashed",
            line_width=2,
            legend_label="plain average",
        )
        interval_band(p, self.virtual_source, color=TOTAL_COLOR, alpha=0.15)
        p.line(
            "tau_s",
            "implied",
            source=self.virtual_source,
            line_color=TOTAL_COLOR,
            line_width=2,
            legend_label="virtual: implied (95% band)",
        )
        p.scatter(
            "tau_s",
            "empirical",
            source=self.virtual_source,
            size=6,
            color=VIRTUAL_COLOR,
            legend_label="virtual: empirical",
        )
        p.legend.location = "bottom_left"
        p.legend.label_text_font_size = "11px"
        self.figure = p
        self.name_input = pn.widgets.TextInput(
            label="Channel name in the export", value="virtual", width=200
        )
        self.format_select = pn.widgets.Select(
            label="Export format", options=list(EXPORT_FORMATS), value="kalibr", width=160
        )
        self.download = download_button(self.export_file, "virtual_imu.yaml", "Download model")
        self.download.sizing_mode = "fixed"
        self.download.width = 200
        self.format_select.param.watch(self._on_format, "value")
        small = {"font-size": "12px", "color": "#555"}
        self.panel = pn.Column(
            pn.pane.Markdown("#### Virtual sensor: the optimal weighted mean", margin=(0, 10)),
            pn.pane.Markdown(
                "For channels that measure **the same quantity** (one axis of several "
                "sensors): the weights w (sum 1) that minimise the WV of w'x, "
                "w = N^-1 1 / (1' N^-1 1) with N the fitted model's WV/WCCV matrix at the "
                "chosen scale (or summed over the band). Grey: each channel; dashed blue: "
                "their plain average; black dots: the virtual sensor's empirical WV; red: "
                "its implied WV, the band where its empirical WV falls 95% of the time.",
                margin=(0, 10),
                styles=small,
            ),
            self.alert,
            pn.Row(self.target_input, self.relative, sizing_mode="stretch_width"),
            self.info,
            pn.Row(
                pn.pane.Bokeh(self.figure, sizing_mode="stretch_width"),
                pn.pane.Bokeh(self.weight_table, width=520, margin=(5, 10)),
                sizing_mode="stretch_width",
            ),
            pn.Row(self.name_input, self.format_select, self.download),
            sizing_mode="stretch_width",
        )

    # ------------------------------------------------------------------------------------
    def update(self, result: Any) -> None:
        """Show the virtual sensor of a new MGMWM fit (None clears the view)."""
        self.result = result
        if result is not None and self.name_input.value in ("", "virtual", self._auto_name):
            # the export's channel name follows the fit's first channel until the user types one
            self._auto_name = self.name_input.value = result.channels[0]
        self.refresh()

    def refresh(self) -> None:
        """Recompute with the current criterion (in the job runner)."""
        res = self.result
        if res is None:
            self._show(None, "")
            return
        try:
            kw = parse_target(self.target_input.value or "")
        except ValueError as e:
            self._show(None, str(e))
            return
        relative = bool(self.relative.value)

        def work() -> eg.multivariate.VirtualSensor:
            # the sampling band only: the delta-method interval costs as much as the fit
            return eg.virtual_sensor(res, relative=relative, confidence=False, **kw)

        def apply(vs: eg.multivariate.VirtualSensor) -> None:
            if res is self.result:
                self._show(vs, "")

        def fail(e: BaseException) -> None:
            if not isinstance(e, ValueError):  # not a model the weights cannot be found for
                log.error("virtual sensor failed", exc_info=e)
            if res is self.result:
                self._show(None, f"No virtual sensor: {message_of(e)}")

        # served: in a worker; unserved (scripts, tests) at once, since this runs from the
        # fit's own job, whose event loop would only queue a nested one
        self.jobs.run(
            work,
            partial(self._safely, apply),
            partial(self._safely, fail),
            key="virtual",
            inline=not self.jobs.served,
        )

    def _on_format(self, event: Any) -> None:
        self.download.filename = f"virtual{FORMATS[event.new].suffix}"
        if event.new == "kalibr":
            self.download.filename = "virtual_imu.yaml"

    def export_text(self) -> str:
        """The virtual sensor's model in the chosen format (one channel, ``name_input``)."""
        vs = self.sensor
        if vs is None:
            raise ValueError("no virtual sensor yet: fit a model of at least 2 channels")
        name = (self.name_input.value or "").strip() or "virtual"
        return export(
            None,
            {name: vs.as_fit()},
            self.format_select.value,
            units={name: vs.unit} if vs.unit else None,
            source=f"virtual sensor of {', '.join(vs.channels)}",
            allow_partial=FORMATS[self.format_select.value].takes("allow_partial"),
        )

    def export_file(self) -> io.StringIO:
        """The download's content (a comment line with the reason when it cannot be made)."""
        try:
            return io.StringIO(self.export_text())
        except ValueError as e:
            self._message(f"Could not export ({self.format_select.value}): {e}")
            return io.StringIO(f"# could not export: {e}\n")

    def _message(self, text: str) -> None:
        self.error = text
        self.alert.param.update(object=html.escape(text), visible=bool(text))

    def _show(self, vs: eg.multivariate.VirtualSensor | None, error: str) -> None:
        self.sensor = vs
        with pn.io.hold():
            self._message(error)
            if vs is None:
                self.info.object = ""
                self.weight_source.data = {c: [] for c in self.weight_source.data}
                self.sensor_source.data = {"xs": [], "ys": [], "name": []}
                self.average_source.data = {"tau_s": [], "wv": []}
                self.virtual_source.data = {c: [] for c in self.virtual_source.data}
                return
            tau = vs.tau_s
            self.sensor_source.data = {
                "xs": [tau] * len(vs.channels),
                "ys": list(vs.sensors_empirical.T),
                "name": list(vs.channels),
            }
            self.average_source.data = {"tau_s": tau, "wv": vs.average_empirical}
            pos = np.where(vs.empirical > 0, vs.empirical, np.nan)
            self.virtual_source.data = {
                "tau_s": tau,
                "empirical": pos,
                "implied": vs.implied,
                "ci_low": np.maximum(vs.ci_low, 1e-300),
                "ci_high": vs.ci_high,
            }
            self.figure.yaxis.axis_label = f"WV [{unit_squared(vs.unit)}]"
            rows = self.weight_rows(vs)
            same = len(rows["channel"]) == len(self.weight_source.data["channel"])
            self.weight_source.data = rows
            if same:  # BokehJS keeps the old cells of a table whose row count is unchanged
                redraw_table(self.weight_table)
            self.info.object = self.info_text(vs)

    @staticmethod
    def weight_rows(vs: eg.multivariate.VirtualSensor) -> dict[str, list[Any]]:
        """Table rows: each channel, the plain average and the virtual sensor, with their
        weights (used, and the fitted model's optimum before shrinkage) and their Allan
        deviation ``sqrt(2 WV)`` at the criterion's first level."""
        j = int(vs.target_levels[0])
        k = len(vs.channels)
        names = [*vs.channels, "plain average", "virtual sensor"]
        wv = [*vs.sensors_empirical[j], vs.average_empirical[j], vs.empirical[j]]
        return {
            "channel": names,
            "weight": [*vs.weights, 1.0 / k, 1.0],
            "weight_fitted": [*vs.fitted_weights, 1.0 / k, 1.0],
            "weight_data": [*vs.empirical_weights, 1.0 / k, 1.0],
            "adev": [math.sqrt(2 * max(v, 0.0)) for v in wv],
            "unit": [vs.unit or "u"] * (k + 2),
        }

    @staticmethod
    def info_text(vs: eg.multivariate.VirtualSensor) -> str:
        """The criterion, the gains out of sample, the shrinkage or the fallback to the plain
        average (and why), and the virtual model's warnings, in words."""
        rel = " (each scale relative to the average's WV)" if vs.relative else ""
        if vs.fell_back:
            how = f"The weights are **the plain average**: {html.escape(vs.fallback)}. "
        else:
            how = (
                f"The weights are the model's optimum shrunk towards the average (lambda = "
                f"{vs.shrinkage:.3f}: the share of its departure from the average kept). "
            )
        warn = "".join(
            f" Warning: {html.escape(w)}." for w in vs.warnings if w.startswith("virtual.")
        )
        return (
            f"Criterion: {html.escape(vs.target)}{rel}. {how}Out of sample (on new data) the "
            f"virtual sensor's criterion is expected at **{vs.gain_vs_average:.3f} x the plain "
            f"average's** and **{vs.gain_vs_best:.3f} x the best channel's** "
            f"({html.escape(vs.best_sensor)}); the model's optimum in sample: "
            f"{vs.fitted_gain:.3f} x (optimistic). "
            f"Allan deviation column: at {vs.tau_s[int(vs.target_levels[0])]:g} s. "
            f"Model of the virtual sensor ({html.escape(vs.model.spec())}): "
            + ", ".join(
                f"{lab}.{name} = {v:.4g} {param_unit(p.code, name, vs.unit).replace('^2', '²')}"
                for lab, p in zip(vs.model.labels, vs.model.processes, strict=True)
                for name, v in zip(p.param_names, p.values, strict=True)
            )
            + "."
            + warn
        )
