"""The time plot of a flight log analysed on its still segments (Fit tab).

When a log was loaded with "still segments only" (``engine.load_log(..., segments="auto")``,
``docs/drone-logs.md``), the WV pools its still parts: this strip shows the selected channel in
time (its min/max envelope over at most ``engine.reporting.data.TIMELINE_POINTS`` blocks, as
the calibration report draws it) with the segments the WV uses shaded, so that a user sees
what was analysed and what was left out. For a log without segments the strip is hidden.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import panel as pn
from bokeh.models import ColumnDataSource

from engine.io import ImuLog
from engine.reporting.data import timeline

from . import views

__all__ = ["SegmentsStrip"]

SEGMENT_COLOR = "#2CA02C"


class SegmentsStrip:
    """The strip of one session: a Bokeh figure in a box that is shown only for a flight (and
    built on the first one).

    Attributes
    ----------
    box : panel.layout.Column
        What the page shows (hidden without segments).
    envelope, spans : ColumnDataSource
        The channel's envelope (``t``, ``low``, ``high``) and the segments (``left``,
        ``right``), in seconds.
    """

    def __init__(self) -> None:
        self.figure: Any = None  # built on the first flight: a still log's page does without
        self.envelope = ColumnDataSource({"t": [], "low": [], "high": []}, name="segments_env")
        self.spans = ColumnDataSource({"left": [], "right": []}, name="segments_spans")
        self.box = pn.Column(sizing_mode="stretch_width", margin=0, visible=False)

    def _build(self) -> None:
        fig = views.log_figure(
            "segments_time",
            "The log in time; shaded: the still segments the WV pools",
            180,
            "time [s]",
            x_axis_type="linear",
            y_axis_type="auto",
        )
        fig.quad(
            left="left",
            right="right",
            bottom=0,
            top=1,
            source=self.spans,
            fill_color=SEGMENT_COLOR,
            fill_alpha=0.2,
            line_alpha=0,
            legend_label="still segments (analysed)",
        )
        fig.varea(
            x="t",
            y1="low",
            y2="high",
            source=self.envelope,
            fill_color="#444",
            fill_alpha=0.7,
            legend_label="signal (min/max)",
        )
        fig.legend.location = "top_left"
        fig.legend.background_fill_alpha = 0.7
        self.figure = fig
        self.box[:] = [pn.pane.Bokeh(fig, sizing_mode="stretch_width")]

    def update(self, log: ImuLog | None, channel: str) -> None:
        """Draw ``channel`` of ``log`` with its segments; hide the strip without segments."""
        segments = list(getattr(log, "segments", None) or ())
        if log is None or not segments or channel not in getattr(log, "names", ()):
            self.box.visible = False
            return
        if self.figure is None:
            self._build()
        tl = timeline(np.asarray(log[channel]), float(log.fs), segments)
        lo, hi = float(np.min(tl.low)), float(np.max(tl.high))
        pad = 0.05 * (hi - lo) if hi > lo else 1.0
        self.envelope.data = {"t": tl.t, "low": tl.low, "high": tl.high}
        # the shading spans the plot's height: quads from below the envelope to above it
        self.spans.data = {
            "left": [a for a, _ in tl.segments],
            "right": [b for _, b in tl.segments],
        }
        glyph = self.figure.renderers[0].glyph
        glyph.bottom, glyph.top = lo - pad, hi + pad
        self.box.visible = True
