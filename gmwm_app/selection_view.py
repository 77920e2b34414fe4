"""The "Model selection" tab of the app and the goodness-of-fit badge of the Fit tab.

:class:`SelectionView` ranks candidate models by WVIC (``engine.inference.rank_models``) in a
worker thread, with a progress bar fed by the ranking's ``progress`` callback and a cooperative
Cancel (the callback raises :class:`_Cancelled`); shows the ranked table (a sortable Bokeh
DataTable: clicking a row loads that model into the builder and refits); and compares two
candidates: their decompositions over the same empirical WV (two small figures built once,
updated in place) and their parameters with 95% asymptotic intervals.

Every figure and table is built once; updates replace ColumnDataSource data in place.
"""

from __future__ import annotations

import html
import math
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import panel as pn
import param
from bokeh.models import ColumnDataSource
from bokeh.models.widgets import NumberFormatter, ScientificFormatter, StringFormatter, TableColumn

from engine.inference.jtest import LEVELS_RULE

from .jobs import ProgressThrottle, job_controls
from .state import Inference, format_value
from .tab_view import TabView
from .views import (
    TOTAL_COLOR,
    component_color,
    data_table,
    empirical_curve,
    interval_band,
    log_figure,
    model_grid,
    redraw_table,
    unit_squared,
    wv_data,
)

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs
    from .state import AppState

__all__ = ["SelectionView", "DEFAULT_MAX_MODEL", "jtest_badge", "ranking_data"]

DEFAULT_MAX_MODEL = "3*GM+WN+QN+RW+DR"
#: Component renderers per comparison figure.
N_COMPARE_COMPONENTS = 8

RANK_COLUMNS = (
    "rank",
    "model",
    "n_params",
    "objective",
    "optimism",
    "criterion",
    "j_p_value",
    "note",
)


class _Cancelled(Exception):
    """Raised by the progress callback when the user cancels a ranking."""


def _message(e: BaseException) -> str:
    return str(e) or type(e).__name__


# -----------------------------------------------------------------------------------------
# pure helpers (tested without a browser)
# -----------------------------------------------------------------------------------------
def ranking_data(sel: Any) -> dict[str, Any]:
    """The ranked table's columns from a ``SelectionResult`` (empty columns for None).

    ``note`` says why a candidate was not fitted, or that an AR1/GM of it is faster than one
    sample (white noise in disguise: ranked as its WN twin, or kept when the fold is rejected),
    or that it is a WN twin added to rank such a candidate (``Candidate.note``).
    """
    cands = list(sel.candidates) if sel is not None else []

    def num(attr: str) -> np.ndarray:
        return np.array([float(getattr(c, attr)) for c in cands], dtype=float)

    return {
        "rank": np.arange(1, len(cands) + 1),
        "model": [c.model for c in cands],
        "n_params": np.array([c.n_params for c in cands], dtype=int),
        "objective": num("objective"),
        "optimism": num("optimism"),
        "criterion": num("criterion"),
        "j_p_value": num("j_p_value"),
        # no J-test p-value where the test is not calibrated: the note says so and why
        "note": [
            "; ".join(x for x in (c.note, f"J-test p {sel.j_note}" if sel.j_note else "") if x)
            if sel is not None and not c.error
            else c.note
            for c in cands
        ],
    }


def jtest_badge(inf: Inference | None, pending: bool = False) -> str:
    """HTML badge of the J-test: green p >= 0.05, amber 0.01-0.05, red < 0.01."""
    style = (
        "display:inline-block;padding:2px 10px;border-radius:10px;font-size:13px;"
        "color:white;background:{}"
    )
    if inf is None:
        if not pending:
            return ""
        return f'<span style="{style.format("#888")}">J-test: computing ...</span>'
    jt = inf.j_test
    if jt is None:
        return f'<span style="{style.format("#888")}">J-test n/a: {html.escape(inf.j_error)}</span>'
    if not jt.calibrated:
        return (
            f'<span class="gmwm-jtest" style="{style.format("#888")}" '
            f'title="{html.escape(jt.note)}">J-test: not calibrated, T = '
            f"{format_value(jt.statistic)} [1], df = {jt.df}</span>"
        )
    p = jt.p_value
    color = "#2E7D32" if p >= 0.05 else "#E69F00" if p >= 0.01 else "#C62828"
    verdict = "fits" if p >= 0.05 else "doubtful fit" if p >= 0.01 else "rejected"
    return (
        f'<span class="gmwm-jtest" style="{style.format(color)}" title="Goodness of fit: '
        "efficient J-test (the model refitted with V^-1 on the levels with "
        f'{LEVELS_RULE}, whatever the weights of the fit) against chi-square(levels - p)">'
        f"J-test: p = {format_value(p, 3)} ({verdict}), T = {format_value(jt.statistic)} "
        f"[1], df = {jt.df}</span>"
    )


class _DecompFigure:
    """A small log-log plot: the empirical WV, one candidate's components and total."""

    def __init__(self, name: str, x_range: Any = None, y_range: Any = None) -> None:
        kw = {} if x_range is None else {"x_range": x_range, "y_range": y_range}
        p = log_figure(name, "", 300, "scale τ [s]", **kw)
        p.title.text_font_size = "13px"
        self.emp = ColumnDataSource(wv_data(None))
        interval_band(p, self.emp)
        empirical_curve(p, self.emp, "variance", 1.5, 5)
        self.comps = [
            ColumnDataSource({"tau_s": [], "wv": []}) for _ in range(N_COMPARE_COMPONENTS)
        ]
        self.comp_renderers = [
            p.line("tau_s", "wv", source=s, line_width=2, line_dash="dashed", visible=False)
            for s in self.comps
        ]
        self.total = ColumnDataSource({"tau_s": [], "wv": []})
        p.line(
            "tau_s", "wv", source=self.total, line_color=TOTAL_COLOR, line_width=2.5, line_alpha=0.9
        )
        self.figure = p

    def update(self, wv: Any, model: Any, title: str, unit: str) -> None:
        self.emp.data = wv_data(wv)
        self.figure.title.text = title
        label = f"wavelet variance ν² [{unit_squared(unit)}]"
        if self.figure.yaxis[0].axis_label != label:
            self.figure.yaxis.axis_label = label
        comps: list[tuple[str, np.ndarray]] = []
        if wv is not None and model is not None:
            tau = model_grid(wv)
            tau_s = tau / wv.fs
            comps = list(model.components(tau, wv.fs).items())
            total = np.sum(np.array([y for _, y in comps]), axis=0)
            self.total.data = {"tau_s": tau_s, "wv": np.where(total > 0, total, np.nan)}
        else:
            self.total.data = {"tau_s": [], "wv": []}
        for i, (src, r) in enumerate(zip(self.comps, self.comp_renderers, strict=True)):
            if i < len(comps):
                lab, y = comps[i]
                y = np.asarray(y, float)
                src.data = {"tau_s": tau_s, "wv": np.where(y > 0, y, np.nan)}
                r.glyph.line_color = component_color(lab)
                r.visible = True
            elif r.visible:
                src.data = {"tau_s": [], "wv": []}
                r.visible = False


# -----------------------------------------------------------------------------------------
# the tab
# -----------------------------------------------------------------------------------------
class SelectionView(TabView):
    """Widgets, figures and callbacks of the "Model selection" tab of one session.

    Parameters
    ----------
    state : AppState
        The session state.
    jobs : Jobs
        The session's job runner (worker threads, document lock).
    """

    slug = "selection"

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(state, jobs, **params)
        self.running = False
        self._cancel = jobs.abandon_on_close(threading.Event())  # stops when the session ends
        self._shown_selection: Any = None
        self._compare_key: Any = None
        self._throttle = ProgressThrottle()  # at most ~10 updates a second

        self.max_input = pn.widgets.TextInput(
            label="Maximal model (every sub-model), or candidates separated by commas",
            value=DEFAULT_MAX_MODEL,
            sizing_mode="stretch_width",
            css_classes=["gmwm-max-model"],
        )
        self.rank_button, self.cancel_button, self.progress = job_controls(
            "Rank", lambda: self.start_ranking(), lambda: self.cancel(), width=100, cancel_width=100
        )
        self.status = pn.pane.Markdown(
            "Rank the candidate models of the selected channel by "
            "WVIC = objective + optimism (smallest first).",
            sizing_mode="stretch_width",
            margin=(0, 10),
            styles={"color": "#555", "font-size": "13px"},
        )

        self.source = ColumnDataSource(ranking_data(None), name="ranking_rows")
        sci = ScientificFormatter(precision=4)
        fmt = {
            "rank": NumberFormatter(format="0"),
            "n_params": NumberFormatter(format="0"),
            "objective": sci,
            "optimism": sci,
            "criterion": sci,
            "j_p_value": ScientificFormatter(precision=3),
        }
        titles = {
            "rank": "rank",
            "model": "model",
            "n_params": "p",
            "objective": "objective [1]",
            "optimism": "optimism [1]",
            "criterion": "WVIC [1]",
            "j_p_value": "J-test p (efficient)",
            "note": "note",
        }
        widths = {"rank": 45, "model": 170, "n_params": 35, "j_p_value": 120, "note": 330}
        cols = [
            TableColumn(
                field=c,
                title=titles[c],
                width=widths.get(c, 95),
                formatter=fmt.get(c, StringFormatter()),
            )
            for c in RANK_COLUMNS
        ]
        self.table = data_table(
            self.source, cols, "ranking", "gmwm-ranking", 330, sortable=True, selectable=True
        )
        self.source.selected.on_change("indices", self._on_row)

        self.compare_a = pn.widgets.Select(label="Compare A", options=[], width=230)
        self.compare_b = pn.widgets.Select(label="with B", options=[], width=230)
        for w in (self.compare_a, self.compare_b):
            # the comparison redraws figure sources: under the document lock (TabView._locked)
            w.param.watch(lambda _e: self._locked(self.refresh_compare), "value")
        self.fig_a = _DecompFigure("compare_a")
        self.fig_b = _DecompFigure(
            "compare_b", self.fig_a.figure.x_range, self.fig_a.figure.y_range
        )
        self.compare_source = ColumnDataSource(
            {c: [] for c in ("candidate", "parameter", "value", "low", "high", "unit")},
            name="compare_rows",
        )
        ccols = [
            TableColumn(field=c, title=t, width=w, sortable=False)
            for c, t, w in (
                ("candidate", "candidate", 140),
                ("parameter", "parameter", 110),
                ("value", "value", 85),
                ("low", "low (95%)", 85),
                ("high", "high (95%)", 85),
                ("unit", "unit", 85),
            )
        ]
        self.compare_table = data_table(
            self.compare_source, ccols, "compare_params", "gmwm-compare", 240, reorderable=True
        )

        h = pn.pane.Markdown
        self.panel = pn.Column(
            pn.Row(
                self.max_input, self.rank_button, self.cancel_button, sizing_mode="stretch_width"
            ),
            self.progress,
            self.status,
            self.message,
            pn.pane.Bokeh(self.table, sizing_mode="stretch_width", margin=(5, 10)),
            h(
                "Click a row to load that model into the builder (Fit tab) and refit. Click a "
                "column title to sort. J-test p: the efficient J-test of each candidate (refitted "
                "with Omega = V^-1, V from the largest candidate, on the levels with "
                f"{LEVELS_RULE}, V of the WV's own estimator with a drift's "
                "share), calibrated whatever "
                "the weights, or empty with the reason in the note. A candidate whose AR1/GM is "
                "faster than one sample is white noise in disguise: it is ranked as its WN twin "
                "(note).",
                margin=(0, 10),
                styles={"font-size": "12px", "color": "#555"},
            ),
            pn.layout.Divider(),
            h("#### Compare two candidates", margin=(0, 10)),
            pn.Row(self.compare_a, self.compare_b),
            pn.Row(
                pn.pane.Bokeh(self.fig_a.figure, sizing_mode="stretch_width"),
                pn.pane.Bokeh(self.fig_b.figure, sizing_mode="stretch_width"),
                sizing_mode="stretch_width",
            ),
            pn.pane.Bokeh(self.compare_table, sizing_mode="stretch_width", margin=(5, 10)),
            sizing_mode="stretch_width",
        )
        self.refresh()  # built on first opening: show the session's ranking at once

    @param.depends("state.selection", "state.inferred", "state.unit", watch=True)
    def _on_state(self) -> None:
        """A new ranking, new intervals (of a compared candidate) or another unit."""
        super()._on_state()

    # ------------------------------------------------------------------------------------
    # ranking (off the event loop, with progress and cancel)
    # ------------------------------------------------------------------------------------
    def _set_running(self, on: bool) -> None:
        self.running = on
        self.rank_button.disabled = on
        self.cancel_button.disabled = not on
        self.progress.visible = on
        if on:
            self.progress.value = 0

    def _progress(self, done: int, total: int, observer: Callable[[int, int], None] | None) -> None:
        """Progress callback of ``rank_models`` (worker thread): bar update, cancel point."""
        value = self._throttle.step(done, total, observer, self._cancel, _Cancelled)
        if value is not None:
            self.jobs.locked(lambda: self.progress.param.update(value=value))
            what = (
                f"Fitted every candidate and its J-test; computing the WVIC ({total} fits)"
                if done == total
                else f"Fit {done} of {total} (the candidates, then their J-test refits)"
            )
            self.jobs.locked(lambda: setattr(self.status, "object", f"⏳ {what} ..."))

    def start_ranking(
        self, spec: str | None = None, *, observer: Callable[[int, int], None] | None = None
    ) -> None:
        """Rank the models of ``spec`` (default: the text input) in a worker thread.

        ``observer(done, total)`` is called with every progress step (tests).
        """
        if self.running:
            return
        spec = (
            self.max_input.value_input
            if spec is None and self.max_input.value_input
            else (spec if spec is not None else self.max_input.value or "")
        )
        state = self.state
        try:  # refused at once, not after waiting for a worker behind other rankings
            state.ranking_candidates(spec)
        except ValueError as e:
            self.status.object = f"**Ranking failed:** {_message(e)}"
            state.report_error(f"Could not rank the models: {_message(e)}")
            return
        self._cancel.clear()
        self._set_running(True)
        self.status.object = f"⏳ Ranking the sub-models of {spec} ..."

        def work() -> Any:
            return state.compute_ranking(spec, progress=lambda d, t: self._progress(d, t, observer))

        def apply(out: Any) -> None:
            if self._cancel.is_set():  # cancelled after the last candidate: drop it
                fail(_Cancelled())
            elif state.install_ranking(out):
                sel = out[1]
                self.status.object = (
                    f"Ranked {len(sel.candidates)} candidates in "
                    f"{sel.elapsed_s:.2f} s ({sel.optimism} optimism, "
                    f"weights {sel.weights}) on {state.channel}; "
                    f"best: **{sel.best.model}**"
                    + (
                        f" (the rank-1 {sel.best.derived_from} with "
                        f"{'; '.join(sel.best.derivation)})."
                        if sel.best.derived_from
                        else "."
                    )
                )

        def fail(e: BaseException) -> None:
            if isinstance(e, _Cancelled):
                self.status.object = "Ranking cancelled; the previous table is kept."
            else:
                self._job_failed(e)
                self.status.object = f"**Ranking failed:** {_message(e)}"
                state.report_error(f"Could not rank the models: {_message(e)}")

        self.jobs.run(
            work,
            self._guarded(apply),
            self._guarded(fail),
            lambda: self._set_running(False),
            key="ranking",
            long=True,
        )

    def cancel(self) -> None:
        """Ask the running ranking to stop (at its next candidate)."""
        if self.running:
            self._cancel.set()
            self.status.object = "Cancelling ..."

    # ------------------------------------------------------------------------------------
    # state -> widgets
    # ------------------------------------------------------------------------------------
    def _draw(self, force: bool) -> None:
        """Bring the table and the comparison in line with the state (in place)."""
        sel = self.state.selection
        if sel is not self._shown_selection or force:
            self._shown_selection = sel
            self.source.selected.indices = []  # its echo in _on_row is a no-op
            same = sel is not None and len(sel.candidates) == len(self.source.data["model"])
            self.source.data = ranking_data(sel)
            if same:
                redraw_table(self.table)
            names = self._names()
            # one update per picker; refresh_compare waits until both list the new ranking
            self.compare_a.param.update(options=names, value=names[0] if names else None)
            self.compare_b.param.update(
                options=names, value=names[1] if len(names) > 1 else (names[0] if names else None)
            )
        self.refresh_compare()

    def _names(self) -> list[str]:
        """The candidates of the ranking that were fitted (the pickers' options)."""
        sel = self.state.selection
        return [c.model for c in sel.candidates if c.result is not None] if sel else []

    def _candidate(self, model: str | None) -> Any:
        sel = self.state.selection
        if sel is None or not model:
            return None
        for i, c in enumerate(sel.candidates, 1):
            if c.model == model and c.result is not None:
                return i, c
        return None

    def refresh_compare(self) -> None:
        """Draw the two picked candidates (idempotent: nothing when nothing changed)."""
        names = self._names()
        if list(self.compare_a.options) != names or list(self.compare_b.options) != names:
            return  # a picker of the previous ranking: _draw is updating them
        s = self.state
        picks = [self._candidate(self.compare_a.value), self._candidate(self.compare_b.value)]
        infs = [s.inference(p[1].result) if p else None for p in picks]
        key = (
            id(s.selection),
            tuple(id(p[1]) if p else None for p in picks),
            tuple(i is not None for i in infs),
            s.unit,
        )
        if key == self._compare_key:
            return
        self._compare_key = key
        sel_wv = (
            picks[0][1].result.wv if picks[0] else (picks[1][1].result.wv if picks[1] else None)
        )
        rows: dict[str, list[str]] = {c: [] for c in self.compare_source.data}
        missing = []
        for tag, fig, pick, inf in zip("AB", (self.fig_a, self.fig_b), picks, infs, strict=True):
            if pick is None:
                fig.update(sel_wv, None, f"{tag}: pick a candidate", s.unit)
                continue
            rank, c = pick
            jp = "n/a" if not math.isfinite(c.j_p_value) else format_value(c.j_p_value, 3)
            if s.selection is not None and s.selection.j_note and math.isfinite(c.j_stat):
                jp = "n/c"
            fig.update(
                c.result.wv,
                c.result.model,
                f"{tag}: {c.model} (rank {rank}, WVIC {format_value(c.criterion)}, J-test p {jp})",
                s.unit,
            )
            if inf is None:
                missing.append(c.result)
            ci = {i.name: i for i in inf.intervals} if inf is not None else {}
            for r in c.result.param_records:
                i = ci.get(r.full_name)
                rows["candidate"].append(f"{tag}: {c.model}")
                rows["parameter"].append(r.full_name)
                rows["value"].append(format_value(r.value))
                rows["low"].append(format_value(i.low) if i else "…")
                rows["high"].append(format_value(i.high) if i else "…")
                rows["unit"].append(r.unit.replace("^2", "²"))
        same = len(rows["parameter"]) == len(self.compare_source.data["parameter"])
        self.compare_source.data = rows
        if same:
            redraw_table(self.compare_table)
        for res in missing:  # after the rows: without a server this refreshes at once
            self.state.ensure_inference(res)  # the state's, shared with the Fit tab

    def _on_row(self, _attr: str, _old: Any, new: list[int]) -> None:
        """A click on a ranked row: load that model into the builder and refit."""
        if not new:  # also the echo of clearing the selection in _draw
            return
        models = self.source.data["model"]
        if not 0 <= new[0] < len(models):
            return
        self._safely(self.load_row, new[0])

    def load_row(self, index: int) -> bool:
        """Load the candidate in row ``index`` (data order = rank - 1) into the builder."""
        model = self.source.data["model"][index]
        ok = self.state.set_model(model)
        self.status.object = (
            f"Loaded **{model}** into the builder (Fit tab) and refitted."
            if ok
            else f"**Could not load {model}:** {self.state.error}"
        )
        return ok
