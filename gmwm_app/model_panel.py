"""The model builder and the what-if sliders of the sidebar (one per session).

One add button per process, a text spec, the list of the model's processes (rows from a
fixed pool, each with a remove button: an add or a remove creates no new Bokeh model), and
the what-if sliders generated from the parameters (:meth:`AppState.slider_specs`), also
from a pool.

Each part depends on the state parameters it shows (``param.depends(..., watch=True)``); the
weights choice and the what-if switch are the state's own parameters (``from_param``); the
spec and the sliders drive the state only with a value that differs from the state's, so
that the panel's own updates of its widgets are no-ops.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import panel as pn
import param
from bokeh.models import CustomJSTickFormatter

import engine as eg
from gmwm_app.state import PROCESS_CODES, PROCESS_NAMES, AppState, state_param
from gmwm_app.views import component_color, redraws
from gmwm_app.whatif import SliderSpec
from gmwm_app.wv_figures import N_INITIAL_COMPONENTS

__all__ = ["ModelPanel", "N_POOL"]

#: Process rows created up front, as many as the component curves the page starts with
#: (more are added if a model grows beyond: 4 Bokeh models each, a page opens faster with
#: fewer).
N_POOL = N_INITIAL_COMPONENTS


#: The labels of the weights choice of the fit: label -> value of ``AppState.weights``.
_WEIGHTS = {"ci weights": "ci", "identity": "identity", "efficient": "efficient"}

_WEIGHTS_HELP = (
    "ci: Omega = diag(1/(ci_high - ci_low)^2), the R package's default. efficient: two "
    "steps, Omega = V^-1 with V the WV covariance implied by the first fit's model (the "
    "GMWM paper, Corollary 1): smaller errors on the long-tau processes (RW, drift) and the "
    "J-test's chi-square holds."
)


class ModelPanel(pn.viewable.Viewer):
    """Model and what-if widgets of one page, driven by the session state.

    Parameters
    ----------
    state : AppState
        The session state (every change goes through its actions).
    """

    state = state_param()

    def __init__(self, state: AppState) -> None:
        super().__init__(state=state)
        self._proc_key: tuple | None = None
        self._slider_key: Any = None
        self.add_buttons = {}
        for code in PROCESS_CODES:
            b = pn.widgets.Button(
                label=f"+ {code}",
                color="primary",
                variant="outline",
                description=f"Add {eg.models.PROCESS_TYPES[code].help}",
                width=82,
                margin=(3, 3),
            )
            b.on_click(partial(self._add, code))
            self.add_buttons[code] = b
        self.spec_input = pn.widgets.TextInput(
            label="Model (type a spec, press Enter)",
            placeholder="e.g. WN+RW+2*GM",
            sizing_mode="stretch_width",
        )
        self.spec_input.param.watch(self._on_spec, "enter_pressed")
        self.process_list = pn.Column(sizing_mode="stretch_width", margin=0)
        self.empty_model_note = pn.pane.Markdown(
            "*Empty model: only the empirical WV is shown.*",
            margin=(0, 10),
            styles={"font-size": "13px"},
        )
        self.process_list.append(self.empty_model_note)
        self._proc_rows: list[tuple[pn.Row, pn.pane.HTML, pn.widgets.Button]] = []
        for _ in range(N_POOL):
            self._new_process_row()
        self.clear_button = pn.widgets.Button(
            label="Remove all", color="light", width=100, margin=(3, 3)
        )
        self.clear_button.on_click(self._clear)
        # the state's own parameters (a change of the weights refits: AppState._weights_changed)
        self.weights_select = pn.widgets.RadioButtonGroup.from_param(
            state.param.weights,
            options=_WEIGHTS,
            color="default",
            description=_WEIGHTS_HELP,
            css_classes=["gmwm-weights"],
            margin=(3, 10),
        )
        self.whatif_toggle = pn.widgets.Checkbox.from_param(
            state.param.whatif,
            label="What if: move the parameters by hand",
            css_classes=["gmwm-whatif"],
        )
        self.sliders = pn.Column(sizing_mode="stretch_width", margin=0, visible=False)
        self._slider_pool: list[pn.widgets.FloatSlider] = []
        self._slider_specs: list[SliderSpec] = []
        # the position each slider stands for in the state (its spec's, or the last one the
        # user moved it to): a slider event at that position is the panel's own update
        self._slider_x: list[float] = []
        self._log_format = CustomJSTickFormatter(code="return Math.pow(10, tick).toExponential(3)")
        self._phi_format = CustomJSTickFormatter(
            code="return (1 - Math.pow(10, tick)).toPrecision(6)"
        )
        self.reset_button = pn.widgets.Button(
            label="Back to the fit", color="light", width=130, margin=(3, 3)
        )
        self.reset_button.on_click(lambda _e: self._reset_whatif())
        self.fit_button = pn.widgets.Button(
            label="Fit from here",
            color="primary",
            width=130,
            margin=(3, 3),
            description="Refit using the slider values as a starting point",
        )
        self.fit_button.on_click(lambda _e: self._fit_from_whatif())
        self.whatif_buttons = pn.Row(self.reset_button, self.fit_button, visible=False)

    def sidebar(self) -> list[Any]:
        """The sidebar's "Model" and "What if" sections."""
        return [
            pn.pane.Markdown("### Model", margin=(0, 10)),
            pn.FlexBox(*self.add_buttons.values(), margin=(0, 5)),
            self.spec_input,
            self.process_list,
            self.clear_button,
            pn.pane.Markdown("Weights", margin=(0, 10), styles={"font-size": "13px"}),
            self.weights_select,
            pn.layout.Divider(),
            pn.pane.Markdown("### What if", margin=(0, 10)),
            self.whatif_toggle,
            pn.pane.Markdown(
                "Each parameter on a log scale, 3 decades either side; the curves follow as "
                "you drag.",
                margin=(0, 10),
                styles={"font-size": "12px", "color": "#555"},
            ),
            self.sliders,
            self.whatif_buttons,
        ]

    def __panel__(self) -> pn.Column:
        return pn.Column(*self.sidebar(), sizing_mode="stretch_width", margin=0)

    def refresh(self) -> None:
        """Bring every widget in line with the state (no new Bokeh models); also puts back a
        widget whose value the state refused."""
        self._sync_spec()
        self._refresh_process_list()
        self._refresh_sliders()

    @param.depends("state.model", watch=True)
    @redraws("the model spec")
    def _sync_spec(self) -> None:
        self.spec_input.value = self.state.model.spec()

    @param.depends("state.model", watch=True)
    @redraws("the process list")
    def _refresh_process_list(self) -> None:
        """One row per process from a fixed pool (no new Bokeh models on add/remove)."""
        s = self.state
        key = tuple(s.model.labels)
        if key == self._proc_key:
            return
        self._proc_key = key
        procs = list(zip(s.model.labels, s.model.processes, strict=True))
        while len(self._proc_rows) < len(procs):  # grows only past the initial pool
            self._new_process_row()
        for i, (row, label, _btn) in enumerate(self._proc_rows):
            if i < len(procs):
                lab, p = procs[i]
                label.object = (
                    f'<span style="font-size:13px;line-height:28px;white-space:nowrap">'
                    f'<span style="display:inline-block;width:18px;height:4px;'
                    f'margin:0 6px 3px 0;background:{component_color(lab)}"></span>'
                    f"<b>{lab}</b> {PROCESS_NAMES[p.code]}</span>"
                )
                row.visible = True
            else:
                row.visible = False
        self.empty_model_note.visible = not procs

    def _new_process_row(self) -> None:
        i = len(self._proc_rows)
        label = pn.pane.HTML("", sizing_mode="stretch_width", margin=(0, 10))
        btn = pn.widgets.Button(
            label="✕",
            color="light",
            width=34,
            height=28,
            margin=(0, 5),
            css_classes=["gmwm-remove"],
            description="Remove this process",
        )
        btn.on_click(partial(self._remove, i))
        row = pn.Row(label, btn, sizing_mode="stretch_width", margin=0, visible=False)
        self._proc_rows.append((row, label, btn))
        self.process_list.append(row)

    @param.depends(
        "state.whatif",
        "state.model",
        "state.result",
        "state.channel",
        "state.fs",
        "state.unit",
        "state.whatif_values",
        watch=True,
    )
    @redraws("the what-if sliders")
    def _refresh_sliders(self) -> None:
        """What-if sliders from the parameter specs, from a pool of slider widgets."""
        s = self.state
        on = bool(s.whatif and len(s.model))
        self.sliders.visible = on
        self.whatif_buttons.visible = on
        if not on:
            self._slider_key = None
            return
        key = (s.model.spec(values=True), id(s.result), s.channel, s.fs)
        if key == self._slider_key:
            return
        self._slider_key = key
        specs = s.slider_specs()
        while len(self._slider_pool) < len(specs):
            i = len(self._slider_pool)
            w = pn.widgets.FloatSlider(
                label="",
                start=0.0,
                end=1.0,
                value=0.5,
                step=0.01,
                format=self._log_format,
                sizing_mode="stretch_width",
                margin=(2, 10),
                visible=False,
            )
            w.param.watch(partial(self._slider_moved, i), "value")
            self._slider_pool.append(w)
            self._slider_x.append(float(w.value or 0.0))
            self.sliders.append(w)
        self._slider_specs = specs
        for i, w in enumerate(self._slider_pool):
            if i < len(specs):
                sp = specs[i]
                phi = sp.transform == "log10(1-x)"
                x = min(max(sp.x, sp.lo), sp.hi)
                self._slider_x[i] = x  # before the update, whose event is then a no-op
                w.param.update(
                    label=f"{sp.name} [{sp.unit.replace('^2', '²')}]",
                    start=sp.lo,
                    end=sp.hi,
                    value=x,
                    step=(sp.hi - sp.lo) / 600,
                    format=self._phi_format if phi else self._log_format,
                    bar_color=component_color(sp.label),
                    visible=True,
                )
            elif w.visible:
                w.visible = False

    def _add(self, code: str, _event: Any = None) -> None:
        self.state.add_process(code)

    def _remove(self, index: int, _event: Any = None) -> None:
        self.state.remove_process(index)

    def _clear(self, _event: Any = None) -> None:
        self.state.clear_model()

    def _slider_moved(self, slot: int, event: Any) -> None:
        self._on_slider(slot, event.new)

    def _on_spec(self, _event: Any = None) -> None:
        spec = (
            self.spec_input.value_input
            if self.spec_input.value_input is not None
            else self.spec_input.value
        )
        if not self.state.set_model(spec or ""):
            self._sync_spec()  # put the spec back (the state did not change)

    def _on_slider(self, slot: int, x: float) -> None:
        # The state holds the value, the slider a position: the two do not round-trip exactly
        # (log10 and back), and a value the slider cannot show (a zero variance) stands at
        # its guess's position. So "differs from the state" is asked of the position this
        # slider last stood for.
        if slot >= len(self._slider_specs) or x == self._slider_x[slot]:
            return
        self._slider_x[slot] = x
        spec = self._slider_specs[slot]
        self.state.set_whatif_value(spec.name, spec.value_of(x))

    def _reset_whatif(self) -> None:
        self._slider_key = None
        self.state.reset_whatif()

    def _fit_from_whatif(self) -> None:
        if self.state.fit_from_whatif():
            self.state.set_whatif(False)
