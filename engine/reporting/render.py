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

from ..errors import ReportError
from .data import CalibrationReport, Progress
from .figures import (
    FigureSpec,
    channel_figures,
    check_figure,
    fleet_adev_figure,
    spread_figure,
)
from .fleet import MIN_UNITS_Z, OUTLIER_REL, OUTLIER_Z, FleetReport

__all__ = ["ReportError", "render_html", "render_fleet_html", "figure_specs", "fleet_figure_specs"]


def figure_specs(rep: CalibrationReport, prefix: str = "") -> dict[str, FigureSpec]:
    """Every figure of the report by key (``<prefix>gyro_x-adev``, ``<prefix>gyro_x-wv`` ...),
    in page order."""
    out: dict[str, FigureSpec] = {}
    for ch in rep.channels.values():
        specs = channel_figures(ch, prefix)
        chk = check_figure(ch, prefix)
        for s in [*specs, *([chk] if chk is not None else [])]:
            out[s.key] = s
    return out


def fleet_figure_specs(fleet: FleetReport) -> dict[str, FigureSpec]:
    """The fleet's figures by key: per channel the overlaid Allan deviations
    (``fleet-<channel>-adev``) and one spread plot per noise term
    (``fleet-<channel>-<k>``, k the column's index), then every unit's own figures
    (``<anchor>-<channel>-adev`` ...)."""
    from ..units import DISPLAY

    out: dict[str, FigureSpec] = {}
    names = [u.name for u in fleet.units]
    for ch, cols in fleet.columns.items():
        curves = [
            (u.name, u.report.channels[ch])
            for u in fleet.units
            if u.report is not None and ch in u.report.channels
        ]
        unit = next((c.unit for _, c in curves if c.fit is not None), "")
        out[f"fleet-{ch}-adev"] = fleet_adev_figure(f"fleet-{ch}-adev", ch, unit, curves)
        for k, col in enumerate(cols):
            if not _spread_drawn(col):
                continue
            values = []
            for u in fleet.units:
                t = next((t for t in u.terms.get(ch, []) if t.column == col), None)
                if t is None:
                    values.append((math.nan, math.nan, math.nan, False))
                else:
                    values.append((t.value, t.low, t.high, t.outlier))
            limit = None
            for lim in fleet.limits:
                d = DISPLAY.get((lim.kind, lim.symbol))
                # a B limit declared as the ADEV minimum is drawn on the "ADEV min" columns
                sym = "ADEV min" if lim.ieee_key == "ADEV_min" else (d.symbol if d else "")
                if (
                    d is not None
                    and (sym, d.unit) == (col[1].removesuffix(" (data)"), col[2])
                    and _kind_of(fleet, ch) == lim.kind
                ):
                    limit = lim.si * d.factor
            key = f"fleet-{ch}-{k}"
            title = f"{ch}: {col[0]} {col[1]} across the units"
            out[key] = spread_figure(key, title, f"{col[1]} [{col[2]}]", names, values, limit)
    for u in fleet.units:
        if u.report is not None:
            out.update(figure_specs(u.report, f"{u.anchor}-"))
    return out


def _spread_drawn(col: tuple[str, str, str]) -> bool:
    """Whether a fleet column gets a spread plot: every process term; the IEEE quantities
    (the tables' ``IEEE`` columns) are in the tables only, which keeps the six-unit page
    within its size budget (tests/engine/test_fleet_report_in_browser.py: 5.18 MB with a spread plot
    of the IEEE ARW/VRW and an IEEE table in every unit's section, over the 5 MB budget)."""
    return col[0] != "IEEE"


def _kind_of(fleet: FleetReport, channel: str) -> str | None:
    """The sensor kind of a channel (from the first unit that has it fitted)."""
    from ..units import ExportError, si_factor

    for u in fleet.units:
        c = u.report.channels.get(channel) if u.report is not None else None
        if c is not None and c.fit is not None:
            try:
                return si_factor(c.unit, channel)[0]
            except ExportError:
                return None
    return None


# ----------------------------------------------------------------------------- Bokeh
def _bokeh_figures(specs: dict[str, FigureSpec], step: Callable[[], None]) -> dict[str, Any]:
    """A Bokeh figure per spec (``step()`` after each)."""
    from bokeh.models import ColumnDataSource, DataRange1d, HoverTool
    from bokeh.models.renderers import DataRenderer
    from bokeh.plotting import figure

    figs: dict[str, Any] = {}
    for key, s in specs.items():
        kw: dict[str, Any] = {}
        if s.x_range_of in figs:
            kw["x_range"] = figs[s.x_range_of].x_range
        p = figure(
            title=s.title,
            x_axis_type="log" if s.log_x else "linear",
            y_axis_type="log" if s.log_y else "linear",
            x_axis_label=s.x_label,
            y_axis_label=s.y_label,
            height=s.height,
            sizing_mode="stretch_width",
            tools="pan,box_zoom,wheel_zoom,reset,save",
            name=key,
            **kw,
        )
        hover: list[DataRenderer] = []
        for layer in s.layers:
            data = {"x": layer.x, "y": layer.y}
            if layer.y2 is not None:
                data["y2"] = layer.y2
            src = ColumnDataSource(data)
            leg = {"legend_label": layer.label} if layer.label else {}
            if layer.kind == "band":
                p.varea("x", "y", "y2", source=src, color=layer.color, fill_alpha=0.18, **leg)
            elif layer.kind == "errorbar":
                p.segment("x", "y", "x", "y2", source=src, color=layer.color, line_width=2, **leg)
            elif layer.kind == "points":
                hover.append(p.scatter("x", "y", source=src, color=layer.color, size=7, **leg))
            else:
                dash = "dashed" if layer.kind == "dashed" else "solid"
                w = 1.5 if layer.kind == "dashed" else 2.2
                p.line("x", "y", source=src, color=layer.color, line_width=w, line_dash=dash, **leg)
        if s.x_ticks:
            p.xaxis.ticker = [t for t, _ in s.x_ticks]
            p.xaxis.major_label_overrides = {t: n for t, n in s.x_ticks}
            if isinstance(p.x_range, DataRange1d):  # figure()'s default range
                p.x_range.range_padding = 0.1
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
        step()
    return figs


def _interactive(
    specs: dict[str, FigureSpec], step: Callable[[], None]
) -> tuple[dict[str, str], str, str]:
    """(div per figure key, the figures' script, the inline BokehJS) of the figures
    (``step()`` after each figure and after their serialisation)."""
    from bokeh.core.templates import CSS_RESOURCES, JS_RESOURCES
    from bokeh.document import Document
    from bokeh.embed import components
    from bokeh.resources import Resources

    if not specs:
        return {}, "", ""
    figs = _bokeh_figures(specs, step)
    # one document holding every figure, its model graph computed once: components() of
    # figures without a document adds them one root at a time and recomputes the graph after
    # each root (a cost growing with the square of the figures: 24 of a six-channel report,
    # ~150 of a six-unit fleet); given the whole set of a document's roots it uses that document
    doc = Document()
    with doc.models.freeze():
        for fig in figs.values():
            doc.add_root(fig)
    script, divs = components(figs)
    step()
    # BokehJS inline, and no file: Resources' js_files/css_files also list the external files
    # of every model class loaded in this process (Panel's widgets, when the app renders the
    # report), which the report's core figures never use and an offline page cannot fetch
    core = Resources(mode="inline", components=["bokeh"])
    resources = CSS_RESOURCES.render(css_raw=core.css_raw, css_files=[]) + JS_RESOURCES.render(
        js_raw=core.js_raw, js_files=[], hashes=core.hashes
    )
    return dict(divs), script, resources


# ----------------------------------------------------------------------------- matplotlib
def _static(specs: dict[str, FigureSpec], step: Callable[[], None]) -> dict[str, str]:
    """An ``<img>`` data URI (PNG) per figure key, drawn by matplotlib (no pyplot state;
    ``step()`` after each)."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise ReportError(
            "a static report draws its figures with matplotlib, which is not installed: "
            "pip install 'gmwm-app[study]' (or drop static=True)"
        ) from None
    out: dict[str, str] = {}
    for key, s in specs.items():
        fig = Figure(figsize=(9.0, 3.4 if s.height > 200 else 2.0), dpi=90)
        ax = fig.add_subplot()
        bottom = 0.15 if s.height > 200 else 0.27  # fixed margins: a layout engine costs seconds
        fig.subplots_adjust(left=0.09, right=0.7, bottom=bottom, top=1 - bottom * 0.75)
        ax.set_xscale("log" if s.log_x else "linear")
        ax.set_yscale("log" if s.log_y else "linear")
        if s.x_ticks:
            ax.set_xticks([t for t, _ in s.x_ticks], [n for _, n in s.x_ticks], fontsize=6)
        for layer in s.layers:
            lab = layer.label or "_nolegend_"  # matplotlib's label for no legend entry
            if layer.kind in ("band", "errorbar"):
                if layer.y2 is None:
                    raise ValueError(f"figure {key!r}: a {layer.kind} layer needs y2")
                if layer.kind == "band":
                    ax.fill_between(
                        layer.x, layer.y, layer.y2, color=layer.color, alpha=0.18, label=lab
                    )
                else:
                    ax.vlines(layer.x, layer.y, layer.y2, color=layer.color, lw=2, label=lab)
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
        step()
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
        loader=PackageLoader("engine.reporting", "templates"),
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


def _figures(
    specs: dict[str, FigureSpec], static: bool, progress: Progress | None
) -> tuple[dict[str, Any], str, str]:
    """(markup per figure key, the Bokeh script, the inline BokehJS): PNG ``<img>`` tags
    when ``static`` (no script, no BokehJS), else Bokeh divs. ``progress("figures", done,
    total)`` after each figure (and after the interactive figures' serialisation)."""
    from markupsafe import Markup

    total = len(specs) + (0 if static else 1)
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress("figures", done, total)

    if progress is not None:
        progress("figures", 0, total)
    if static:
        images = _static(specs, step)
        figures = {
            k: Markup('<img class="fig" alt="{}" src="{}">').format(specs[k].title, v)
            for k, v in images.items()
        }
        return figures, "", ""
    divs, script, resources = _interactive(specs, step)
    return {k: Markup(v) for k, v in divs.items()}, script, resources


def render_html(
    rep: CalibrationReport,
    *,
    static: bool = False,
    title: str | None = None,
    progress: Progress | None = None,
) -> str:
    """The report as one self-contained HTML page.

    Parameters
    ----------
    rep : CalibrationReport
        From :func:`engine.reporting.gather_report`.
    static : bool
        Figures as PNG images (matplotlib) instead of interactive Bokeh plots.
    title : str, optional
        Page title (default: ``"Calibration report: <file name>"``).
    progress : callable (stage, done, total), optional
        Called as the figures are drawn (stage ``"figures"``) and the page is written
        (``"writing"``).

    Raises
    ------
    ReportError
        ``static=True`` without matplotlib.
    """
    from markupsafe import Markup

    specs = figure_specs(rep)
    figures, script, resources = _figures(specs, static, progress)
    by_channel: dict[str, list[str]] = {ch: [] for ch in rep.channels}
    for key in specs:
        by_channel[key.rsplit("-", 1)[0]].append(key)
    if progress is not None:
        progress("writing", 0, 1)
    page = _environment().get_template("report.html.jinja")
    render: Callable[..., str] = page.render
    html = render(
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
    if progress is not None:
        progress("writing", 1, 1)
    return html


def render_fleet_html(
    fleet: FleetReport,
    *,
    static: bool = False,
    title: str | None = None,
    progress: Progress | None = None,
) -> str:
    """The fleet acceptance report as one self-contained HTML page.

    The acceptance table (a row per unit, its verdict and why), per channel the table of
    every unit's noise terms with their intervals (outliers marked), the overlaid Allan
    deviations and a spread plot per term, then every unit's own section (the calibration
    report's log table, channels and export, with anchors ``#unit-<k>`` and
    ``#unit-<k>-ch-<channel>``).

    Parameters
    ----------
    fleet : FleetReport
        From :func:`engine.reporting.fleet.gather_fleet`.
    static : bool
        Figures as PNG images (matplotlib) instead of interactive Bokeh plots.
    title : str, optional
        Page title (default: ``"Fleet acceptance report: <n> units"``).
    progress : callable (stage, done, total), optional
        As :func:`render_html`'s.

    Raises
    ------
    ReportError
        ``static=True`` without matplotlib.
    """
    from markupsafe import Markup

    specs = fleet_figure_specs(fleet)
    figures, script, resources = _figures(specs, static, progress)
    unit_keys: dict[str, dict[str, list[str]]] = {}
    for u in fleet.units:
        if u.report is None:
            continue
        keys: dict[str, list[str]] = {ch: [] for ch in u.report.channels}
        pre = f"{u.anchor}-"
        for key in specs:
            if key.startswith(pre):
                keys[key[len(pre) :].rsplit("-", 1)[0]].append(key)
        unit_keys[u.anchor] = keys
    cells = {
        ch: {u.anchor: {t.column: t for t in u.terms.get(ch, [])} for u in fleet.units}
        for ch in fleet.columns
    }
    spread = {
        ch: [f"fleet-{ch}-{k}" for k, c in enumerate(cols) if _spread_drawn(c)]
        for ch, cols in fleet.columns.items()
    }
    if progress is not None:
        progress("writing", 0, 1)
    page = _environment().get_template("fleet.html.jinja")
    render: Callable[..., str] = page.render
    html = render(
        title=title or f"Fleet acceptance report: {len(fleet.units)} units",
        fleet=fleet,
        figures=figures,
        unit_keys=unit_keys,
        cells=cells,
        spread=spread,
        static=static,
        outlier_z=OUTLIER_Z,
        outlier_rel=OUTLIER_REL,
        min_units_z=MIN_UNITS_Z,
        bokeh_resources=Markup(resources),
        bokeh_script=Markup(script),
        data_json=Markup(_json_script(fleet.to_dict())),
    )
    if progress is not None:
        progress("writing", 1, 1)
    return html
