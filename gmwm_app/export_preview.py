"""What a filter will assume, shown in the export menu before the download.

For a filter format, every fitted channel is projected onto the format's consumer noise model
by the engine, as the export computes the file's numbers with the same options
(:func:`engine.formats.projections`: the rule, the bound, 95 % intervals, the tail factors,
KF-GINS's one T_c); the app only draws and tabulates the result:

* :func:`preview_projections`: the projections of the session's fits for one format;
* :func:`preview_table`: the exported numbers with their intervals, factors and binding scales
  (Markdown);
* :func:`preview_figure`: one channel's fitted WV, the bound's target, the consumer model's WV
  over the band (shaded) and the binding scales (Bokeh);
* :class:`ExportPreview`: the panes of the export menu, computed on request (a toggle) so that
  a fit does not wait for a projection nobody looks at.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import panel as pn
from bokeh.models.annotations import BoxAnnotation, Span
from bokeh.plotting import figure

from engine.formats import FORMAT_CONSUMERS, Projection, projections
from engine.io import ImuLog

__all__ = ["preview_projections", "preview_table", "preview_figure", "ExportPreview"]


def preview_projections(fits: Mapping[str, Any], fmt: str, **options: Any) -> dict[str, Projection]:
    """The projection of each fit onto ``fmt``'s consumer model, as the export computes it:
    :func:`engine.formats.projections` with the download's options.

    Parameters
    ----------
    fits : mapping of channel to GMWMResult
    fmt : str
        A format of :data:`engine.formats.FORMATS`.
    **options
        The export's options (:class:`engine.formats.ExportOptions`: ``units``,
        ``filter_rate`` [Hz], ``projection``, ``data``, ``horizon_s`` [s], ``log`` and
        ``tails`` for the loaded log's tail factors ...).

    Returns
    -------
    dict of channel to Projection
        Empty for a report, or the fit's own terms (``projection="fit"``).

    Raises
    ------
    ExportError
        A fit the consumer cannot take, or a bad option (the message says why).
    """
    return projections(fits, fmt, **options)


def _g(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else "-"


def preview_table(projs: Mapping[str, Projection]) -> str:
    """Markdown table: per channel and parameter the exported value, its interval, the factor
    over the plain conversion and the binding scale (with the fitted term bound there)."""
    if not projs:
        return ""
    p0 = next(iter(projs.values()))
    rows = [
        f"**{p0.consumer}** at {p0.fs_filter:g} Hz, bound over "
        f"{p0.band[0]:.3g} .. {p0.band[1]:.4g} s "
        f"({'upper limit' if p0.confidence else 'fitted WV'}):",
        "",
        "| channel | | value | 95 % interval | x plain | binding |",
        "|---|---|---|---|---|---|",
    ]
    for ch, p in projs.items():
        for q in p.params.values():
            iv = f"[{_g(q.low)}, {_g(q.high)}]" if math.isfinite(q.low) else "-"
            bind = (
                f"{q.binding_tau_s:.3g} s ({q.binds})"
                if math.isfinite(q.binding_tau_s)
                else q.binds
            )
            rows.append(
                f"| {ch} | {q.name} | {_g(q.value)} {q.unit} | {iv} | {_g(q.factor)} | {bind} |"
            )
    return "\n".join(rows)


def preview_figure(p: Projection, height: int = 260) -> Any:
    """The fitted WV, the bound's target and the consumer model's WV over the band (log-log),
    the band shaded and a vertical line at each binding scale."""
    fig = figure(
        height=height,
        sizing_mode="stretch_width",
        x_axis_type="log",
        y_axis_type="log",
        x_axis_label="scale tau (s)",
        y_axis_label=f"WV ({p.unit})^2",
        title=f"{p.channel}: what the filter assumes ({p.consumer})",
        toolbar_location=None,
    )
    t = np.asarray(p.tau_s)
    fig.line(t, p.fitted_wv, color="#1f77b4", line_width=2, legend_label="fitted model")
    if not np.allclose(p.target_wv, p.fitted_wv):
        fig.line(t, p.target_wv, color="#1f77b4", line_dash="dotted", legend_label="bound target")
    fig.line(t, p.consumer_wv, color="#d62728", line_width=2, legend_label=f"{p.consumer} file")
    fig.add_layout(BoxAnnotation(left=p.band[0], right=p.band[1], fill_alpha=0.06))
    for q in p.params.values():
        if math.isfinite(q.binding_tau_s) and q.name != "T_c":
            fig.add_layout(
                Span(location=q.binding_tau_s, dimension="height", line_dash="dashed", name=q.name)
            )
    fig.legend.location = "bottom_left"
    return fig


class ExportPreview:
    """The export menu's preview: a toggle, a note, the figure of the shown channel and the
    table of every channel's numbers (:meth:`update`)."""

    def __init__(self) -> None:
        self.toggle = pn.widgets.Toggle(
            label="Show what the filter will assume", value=False, sizing_mode="stretch_width"
        )
        self.note = pn.pane.Markdown("", margin=(0, 10), styles={"font-size": "12px"})
        self.table = pn.pane.Markdown("", margin=(0, 10), styles={"font-size": "12px"})
        self.plot = pn.pane.Bokeh(None, sizing_mode="stretch_width")
        self.plot_box = pn.Column(self.plot, visible=False, margin=0)  # hides the figure
        self.projections: dict[str, Projection] = {}
        self._key: tuple[Any, ...] | None = None

    def panel(self) -> Any:
        """The preview's layout."""
        return pn.Column(self.toggle, self.note, self.plot_box, self.table, margin=0)

    def update(
        self,
        fits: Mapping[str, Any],
        fmt: str,
        *,
        channel: str = "",
        units: Mapping[str, str] | None = None,
        filter_rate: float | None = None,
        projection: str = "bound",
        data: str = "low",
        horizon_s: float | None = None,
        log: ImuLog | None = None,
        tails: bool = True,
    ) -> None:
        """Recompute (when shown and changed) and redraw; an error becomes the note.
        ``projection`` is the export's (``"fit"``: the file writes the fit's own terms, and
        nothing is projected); ``data``, ``horizon_s`` and ``tails`` its bound's
        (:func:`project`), with the tail factors of ``log`` (the loaded log), as the download
        computes them."""
        key = (
            tuple((c, id(r)) for c, r in fits.items()),
            fmt,
            filter_rate,
            channel,
            projection,
            data,
            horizon_s,
            id(log),
            tails,
        )
        if not self.toggle.value:
            self.note.object, self.table.object, self.plot_box.visible = "", "", False
            self._key = None
            return
        if key == self._key:
            return
        self._key = key
        self.projections = {}
        self.table.object, self.plot_box.visible = "", False
        if fmt not in FORMAT_CONSUMERS:
            self.note.object = f"{fmt} is a report, not a filter file: nothing is projected."
            return
        if not fits:
            self.note.object = "Fit a channel to see what the filter will assume."
            return
        if projection == "fit":
            self.note.object = (
                f"The {fmt} file writes the fit's own terms one by one: nothing is projected "
                "or bounded."
            )
            return
        try:
            self.projections = preview_projections(
                fits,
                fmt,
                units=units,
                filter_rate=filter_rate,
                projection=projection,
                data=data,
                horizon_s=horizon_s,
                log=log,
                tails=tails,
            )
        except ValueError as e:  # eg.GmwmError (ExportError ...) or numpy's
            self.note.object = f"Cannot project the fits for {fmt}: {e}"
            return
        shown = channel if channel in self.projections else next(iter(self.projections))
        self.note.object = (
            f"The {fmt} file's model is **{self.projections[shown].consumer}**: its WV (red) "
            "is at least the fitted model's over the shaded band; dashed lines mark the "
            "binding scales."
        )
        self.plot.object = preview_figure(self.projections[shown])
        self.plot_box.visible = True
        self.table.object = preview_table(self.projections)
