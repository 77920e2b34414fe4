"""The Fit tab's Bokeh figures, built once per session and updated in place.

:class:`WVFigures` holds the log-log wavelet-variance plot (empirical WV with its interval,
the classical WV beside a robust one, the model total and one curve per process) and the
residual strip (empirical / model with the interval). :meth:`WVFigures.update` only replaces
the ``data`` of the ColumnDataSources and a few properties (legend labels, colours, axis
labels), so the figures are never rebuilt and a zoom survives a refit. Component curves come
from a pool of renderers (:data:`N_INITIAL_COMPONENTS` built with the page, grown up to
:data:`N_COMPONENTS` when a model needs more); unused ones are hidden.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from bokeh.core.properties import value
from bokeh.models import ColumnDataSource, DataRange1d, HoverTool, Line, SaveTool, Scatter
from bokeh.models.annotations import Legend, LegendItem, Span
from bokeh.models.renderers import GlyphRenderer

from engine.reporting.figures import RAW_WV_COLOR, RAW_WV_LABEL

from .state import PROCESS_NAMES
from .views import (
    CLASSICAL_COLOR,
    LEGEND_LABEL_WIDTH,
    TOTAL_COLOR,
    add_renderer,
    component_color,
    empirical_curve,
    interval_band,
    log_figure,
    model_grid,
    unit_squared,
    wv_data,
)

if TYPE_CHECKING:  # pragma: no cover
    from .state import AppState

__all__ = ["WVFigures", "N_COMPONENTS", "N_INITIAL_COMPONENTS"]

#: Size of the pool of component renderers (a model with more processes draws the first ones).
N_COMPONENTS = 12
#: Component renderers built with the page; the pool grows up to :data:`N_COMPONENTS` when a
#: model has more processes (8 models each: a page opens faster with fewer).
N_INITIAL_COMPONENTS = 6


def _positive(a: np.ndarray) -> np.ndarray:
    """Non-positive values as NaN (a log axis cannot show them; the line breaks there)."""
    a = np.asarray(a, dtype=float)
    return np.where(a > 0, a, np.nan)


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
    raw, raw_item : ColumnDataSource, LegendItem or None
        The raw signal's WV beside a temperature-compensated one (``AppState.wv_raw``) and its
        legend entry: built the first time a session shows one (None before; a page opens
        without them, as most logs have no temperature channel).
    comps : list of ColumnDataSource
        One per pooled component renderer (``tau_s``, ``wv``, ``label``).
    comp_renderers, comp_items : list
        The pooled line renderers and their legend items.
    """

    def __init__(self, n_components: int = N_INITIAL_COMPONENTS) -> None:
        # names: handles for browser tests and benchmarks (Bokeh's get_model_by_name)
        self.emp = ColumnDataSource(wv_data(None), name="empirical")
        self.alt = ColumnDataSource(wv_data(None), name="classical")
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
        self._shown_raw: Any = None
        self.raw: ColumnDataSource | None = None
        self.raw_item: LegendItem | None = None
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
        # every glyph without selected/muted looks of its own (add_renderer): this plot has
        # no selection tool and its legend hides curves
        alt_band = interval_band(p, self.alt, color=CLASSICAL_COLOR, alpha=0.12, plain=True)
        alt_line = add_renderer(
            p,
            self.alt,
            Line(
                x="tau_s",
                y="variance",
                line_color=CLASSICAL_COLOR,
                line_width=1.5,
                line_dash="dashed",
            ),
        )
        alt_pts = add_renderer(
            p,
            self.alt,
            Scatter(
                x="tau_s",
                y="variance",
                marker="square",
                size=6,
                line_color=CLASSICAL_COLOR,
                fill_color="white",
            ),
        )
        # empirical WV and its interval
        band = interval_band(p, self.emp, plain=True)
        emp_line, emp_pts = empirical_curve(p, self.emp, "variance", 1.5, 7, plain=True)
        # the axes follow the data, not the model curves (a tiny RW at short scales would
        # otherwise squash the plot, and dragging a what-if slider would make it jump)
        p.x_range.renderers = [emp_line, alt_line]
        p.y_range.renderers = [band, emp_line, alt_band]

        # model: one pooled renderer per component, then the total on top
        self.comp_renderers = [self._component_renderer(p, src) for src in self.comps]
        total = add_renderer(
            p,
            self.total,
            Line(x="tau_s", y="wv", line_color=TOTAL_COLOR, line_width=3, line_alpha=0.9),
        )
        self.total_renderer = total

        self.emp_item = LegendItem(label=value("empirical WV"), renderers=[emp_line, emp_pts])
        self.band_item = LegendItem(label=value("95% interval"), renderers=[band])
        self.alt_item = LegendItem(
            label=value("classical WV"), renderers=[alt_line, alt_pts, alt_band], visible=False
        )
        self.total_item = LegendItem(label=value("model (total)"), renderers=[total], visible=False)
        self.comp_items = [self._component_item(i, r) for i, r in enumerate(self.comp_renderers)]
        self.legend = Legend(
            items=[self.emp_item, self.band_item, self.alt_item, self.total_item, *self.comp_items],
            location="top_left",
            click_policy="hide",
            label_text_font_size="12px",
            spacing=1,
            padding=6,  # type: ignore[arg-type]  # an int is a padding (Bokeh types it as a Property)
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
        rband = interval_band(r, self.resid, "lo", "hi", plain=True)
        rline, ratio_pts = empirical_curve(r, self.resid, "ratio", 1, 6, plain=True)
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
                padding=6,  # type: ignore[arg-type]  # as above
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
    def _formatters() -> dict[str, Any]:
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
            classical = wv.classical if wv is not None and wv.robust else None
            robust_pair = classical is not None
            self.alt.data = wv_data(classical)
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
        if state.wv_raw is not self._shown_raw:
            self._shown_raw = state.wv_raw
            if state.wv_raw is not None or self.raw is not None:
                raw, item = self._raw_glyphs()
                raw.data = wv_data(state.wv_raw)
                item.visible = state.wv_raw is not None
        self._update_model(state)

    def _raw_glyphs(self) -> tuple[ColumnDataSource, LegendItem]:
        """The raw signal's WV beside a temperature-compensated one: points and interval in
        the report's grey (:data:`engine.reporting.figures.RAW_WV_COLOR`), under the empirical
        WV, with their legend entry after the classical WV's; built on first use."""
        if self.raw is not None and self.raw_item is not None:
            return self.raw, self.raw_item
        p = self.figure
        src = ColumnDataSource(wv_data(None), name="raw_wv")
        band = interval_band(p, src, color=RAW_WV_COLOR, alpha=0.12, plain=True)
        pts = add_renderer(
            p,
            src,
            Scatter(
                x="tau_s",
                y="variance",
                size=6,
                line_color=RAW_WV_COLOR,
                fill_color=RAW_WV_COLOR,
            ),
        )
        # drawn first (under the data, the model and its components)
        new = [band, pts]
        p.renderers = [*new, *[r for r in p.renderers if r not in new]]
        p.y_range.renderers = [*p.y_range.renderers, band]
        item = LegendItem(label=value(RAW_WV_LABEL), renderers=[pts, band], visible=False)
        items = [i for i in self.legend.items if isinstance(i, LegendItem)]
        items.insert(items.index(self.alt_item) + 1, item)
        self.legend.items = items
        self.emp_hover.renderers = [*self.emp_hover.renderers, pts]
        self.raw, self.raw_item = src, item
        return src, item

    @staticmethod
    def _component_renderer(p: Any, src: ColumnDataSource) -> GlyphRenderer:
        line = Line(x="tau_s", y="wv", line_width=2.2, line_dash="dashed", line_alpha=0.95)
        return add_renderer(p, src, line, visible=False)

    @staticmethod
    def _component_item(i: int, r: GlyphRenderer) -> LegendItem:
        return LegendItem(label=value(f"component {i + 1}"), renderers=[r], visible=False)

    def _grow_components(self, n: int) -> None:
        """Make the pool of component renderers hold ``n`` (at most :data:`N_COMPONENTS`)."""
        n = min(n, N_COMPONENTS)
        if n <= len(self.comps):
            return
        new_src, new_r, new_items = [], [], []
        for i in range(len(self.comps), n):
            src = ColumnDataSource(dict(_EMPTY_CURVE), name=f"component_{i}")
            r = self._component_renderer(self.figure, src)
            new_src.append(src)
            new_r.append(r)
            new_items.append(self._component_item(i, r))
        self.comps += new_src
        self.comp_renderers += new_r
        self.comp_items += new_items
        # the total stays on top of the components
        rs = [r for r in self.figure.renderers if r is not self.total_renderer]
        self.figure.renderers = [*rs, self.total_renderer]
        self.legend.items = [*self.legend.items, *new_items]
        self.model_hover.renderers = [*self.model_hover.renderers, *new_r]

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
        self._grow_components(len(items))
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
