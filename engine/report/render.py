"""Drawing a :class:`~.data.CalibrationReport`: one self-contained HTML file.

The page is the Jinja2 template ``templates/report.html.jinja`` (autoescaped). Figures are
:class:`~.figures.FigureSpec` drawn either

* interactive: Bokeh figures (pan, zoom, hover, legend click to hide) embedded with
  :func:`bokeh.embed.components` and BokehJS inlined (``Resources(mode="inline")``): the file
  makes no network request and opens from an e-mail attachment;
* static (``static=True``, for archiving): matplotlib PNGs inlined as ``data:`` URIs, no
  JavaScript at all (needs matplotlib: ``pip install 'gmwm-app[study]'``).

Every number of the tables carries its full-precision value in a ``data-value`` attribute,
and the whole report is embedded as JSON (``<script type="application/json"
id="gmwm-report-data">``, :meth:`CalibrationReport.to_dict`) for machines.
"""

from __future__ import annotations

import base64
import io as _io
import json
import math
from collections.abc import Callable
from typing import Any

from .data import CalibrationReport
from .figures import FigureSpec, channel_figures, check_figure

__all__ = ["ReportError", "render_html", "figure_specs"]


class ReportError(ValueError):
    """A report that cannot be made as asked (the message says what to do)."""


def figure_specs(rep: CalibrationReport) -> dict[str, FigureSpec]:
    """Every figure of the report by key (``gyro_x-adev``, ``gyro_x-wv`` ...), in page order."""
    out: dict[str, FigureSpec] = {}
    for ch in rep.channels.values():
        specs = channel_figures(ch)
        chk = check_figure(ch)
        for s in [*specs, *([chk] if chk is not None else [])]:
            out[s.key] = s
    return out


# ----------------------------------------------------------------------------- Bokeh
def _bokeh_figures(specs: dict[str, FigureSpec]) -> dict[str, Any]:
    from bokeh.models import ColumnDataSource, HoverTool
    from bokeh.plotting import figure

    figs: dict[str, Any] = {}
    for key, s in specs.items():
        kw: dict[str, Any] = {}
        if s.x_range_of in figs:
            kw["x_range"] = figs[s.x_range_of].x_range
        p = figure(
            title=s.title,
            x_axis_type="log",
            y_axis_type="log",
            x_axis_label=s.x_label,
            y_axis_label=s.y_label,
            height=s.height,
            sizing_mode="stretch_width",
            tools="pan,box_zoom,wheel_zoom,reset,save",
            name=key,
            **kw,
        )
        hover = []
        for layer in s.layers:
            data = {"x": layer.x, "y": layer.y}
            if layer.y2 is not None:
                data["y2"] = layer.y2
            src = ColumnDataSource(data)
            leg = {"legend_label": layer.label} if layer.label else {}
            if layer.kind == "band":
                p.varea("x", "y", "y2", source=src, color=layer.color, fill_alpha=0.18, **leg)
            elif layer.kind == "points":
                hover.append(p.scatter("x", "y", source=src, color=layer.color, size=7, **leg))
            else:
                dash = "dashed" if layer.kind == "dashed" else "solid"
                w = 1.5 if layer.kind == "dashed" else 2.2
                p.line("x", "y", source=src, color=layer.color, line_width=w, line_dash=dash, **leg)
        if hover:
            p.add_tools(
                HoverTool(
                    renderers=hover,
                    tooltips=[(s.x_label, "@x{0.0000e}"), (s.y_label, "@y{0.0000e}")],
                )
            )
        if p.legend:
            p.legend.click_policy = "hide"
            p.legend.label_text_font_size = "9pt"
            p.add_layout(p.legend[0], "right")  # beside the plot, never over the data
        figs[key] = p
    return figs


def _interactive(specs: dict[str, FigureSpec]) -> tuple[dict[str, str], str, str]:
    """(div per figure key, the figures' script, the inline BokehJS) of the figures."""
    from bokeh.embed import components
    from bokeh.resources import Resources

    if not specs:
        return {}, "", ""
    script, divs = components(_bokeh_figures(specs))
    resources = Resources(mode="inline", components=["bokeh"]).render()
    return dict(divs), script, resources


# ----------------------------------------------------------------------------- matplotlib
def _static(specs: dict[str, FigureSpec]) -> dict[str, str]:
    """An ``<img>`` data URI (PNG) per figure key, drawn by matplotlib (no pyplot state)."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise ReportError(
            "a static report draws its figures with matplotlib, which is not installed: "
            "pip install 'gmwm-app[study]' (or drop --static / static=True)"
        ) from None
    out: dict[str, str] = {}
    for key, s in specs.items():
        fig = Figure(figsize=(9.0, 3.4 if s.height > 200 else 2.0), dpi=90)
        ax = fig.add_subplot()
        bottom = 0.15 if s.height > 200 else 0.27  # fixed margins: a layout engine costs seconds
        fig.subplots_adjust(left=0.09, right=0.7, bottom=bottom, top=1 - bottom * 0.75)
        ax.set_xscale("log")
        ax.set_yscale("log")
        for layer in s.layers:
            lab = layer.label or None
            if layer.kind == "band":
                ax.fill_between(
                    layer.x, layer.y, layer.y2, color=layer.color, alpha=0.18, label=lab
                )
            elif layer.kind == "points":
                ax.plot(layer.x, layer.y, "o", color=layer.color, ms=4, label=lab)
            else:
                ls = "--" if layer.kind == "dashed" else "-"
                ax.plot(layer.x, layer.y, ls, color=layer.color, lw=1.4, label=lab)
        ax.set_title(s.title, fontsize=9)
        ax.set_xlabel(s.x_label, fontsize=8)
        ax.set_ylabel(s.y_label, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
        if any(layer.label for layer in s.layers):
            ax.legend(fontsize=6.5, loc="center left", bbox_to_anchor=(1.01, 0.5))
        buf = _io.BytesIO()
        fig.savefig(buf, format="png", metadata={"Software": None})
        out[key] = "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")
    return out


# ----------------------------------------------------------------------------- page
def _num(v: Any, fmt: str = ".5g") -> str:
    """A number for a table cell; missing or NaN as an em dash."""
    if v is None:
        return "\u2014"
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    return "\u2014" if not math.isfinite(f) else format(f, fmt)


def _full(v: Any) -> str:
    """A number's exact value for a ``data-value`` attribute (``repr``: round-trips)."""
    if v is None:
        return "nan"
    f = float(v)
    return repr(f) if math.isfinite(f) else "nan"


def _environment() -> Any:
    from jinja2 import Environment, PackageLoader, select_autoescape

    env = Environment(
        loader=PackageLoader("engine.report", "templates"),
        autoescape=select_autoescape(["html", "jinja"], default=True),
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["num"] = _num
    env.filters["full"] = _full
    return env


def _json_script(d: dict[str, Any]) -> str:
    """JSON safe inside ``<script>``: ``<``, ``>`` and ``&`` escaped as ``\\u00XX``."""
    text = json.dumps(d, allow_nan=False, separators=(",", ":"))
    for ch in "<>&":
        text = text.replace(ch, f"\\u{ord(ch):04x}")
    return text


def render_html(rep: CalibrationReport, *, static: bool = False, title: str | None = None) -> str:
    """The report as one self-contained HTML page.

    Parameters
    ----------
    rep : CalibrationReport
        From :func:`engine.report.gather_report`.
    static : bool
        Figures as PNG images (matplotlib) instead of interactive Bokeh plots.
    title : str, optional
        Page title (default: ``"Calibration report: <file name>"``).

    Raises
    ------
    ReportError
        ``static=True`` without matplotlib.
    """
    from markupsafe import Markup

    specs = figure_specs(rep)
    script = resources = ""
    if static:
        images = _static(specs)
        figures = {
            k: Markup('<img class="fig" alt="{}" src="{}">').format(specs[k].title, v)
            for k, v in images.items()
        }
    else:
        divs, script, resources = _interactive(specs)
        figures = {k: Markup(v) for k, v in divs.items()}
    by_channel: dict[str, list[str]] = {ch: [] for ch in rep.channels}
    for key in specs:
        by_channel[key.rsplit("-", 1)[0]].append(key)
    page = _environment().get_template("report.html.jinja")
    render: Callable[..., str] = page.render
    return render(
        title=title or f"Calibration report: {rep.log.get('name', '')}",
        rep=rep,
        log=rep.log,
        figures=figures,
        by_channel=by_channel,
        static=static,
        bokeh_resources=Markup(resources),
        bokeh_script=Markup(script),
        data_json=Markup(_json_script(rep.to_dict())),
    )
