"""The export menu's bound options: what of the data a filter file bounds besides the
fitted model (``data``: the empirical WV's lower 95 % limit, its estimate, its upper limit or
nothing), over which horizon (the longest time the filter runs unaided) and whether the data
bound covers the data's heavy tails, the engine's ``engine.export(..., data=, horizon_s=,
tails=)`` options.

The widgets are built when the menu's "Bound options" toggle is first opened, not with the
page (a page that never exports pays nothing for them); until then, and whenever the menu is
closed again, :attr:`BoundOptions.options` is the engine's defaults (``{}``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import panel as pn

__all__ = ["DATA_CHOICES", "BoundOptions"]

#: The labels of the data-bound choices (values: the keys of ``engine.formats.DATA_BOUNDS``,
#: tests/app/test_export_bound_options.py checks they are the same).
DATA_CHOICES: dict[str, str] = {
    "The data's lower 95 % limit (default)": "low",
    "The data's estimate": "estimate",
    "The data's upper 95 % limit": "high",
    "The fitted model only": "none",
}

_SMALL = {"font-size": "12px"}


class BoundOptions:
    """The data-bound selector and the horizon input of the export menu, built lazily.

    Parameters
    ----------
    on_change : callable
        Called with no argument when an option changes (the menu recomputes its preview).
    """

    def __init__(self, on_change: Callable[[], None]) -> None:
        self._on_change = on_change
        self.toggle = pn.widgets.Toggle(
            label="Bound options (data, horizon)", value=False, sizing_mode="stretch_width"
        )
        self.box = pn.Column(margin=0, sizing_mode="stretch_width")
        self.data_select: Any = None  # built on first opening
        self.horizon_input: Any = None
        self.tails_check: Any = None
        self.toggle.param.watch(self._on_toggle, "value")

    def panel(self) -> Any:
        """The toggle and the (initially empty) box of the widgets."""
        return pn.Column(self.toggle, self.box, margin=0, sizing_mode="stretch_width")

    @property
    def built(self) -> bool:
        """True once the menu was opened (the widgets exist)."""
        return self.data_select is not None

    def _build(self) -> None:
        self.data_select = pn.widgets.Select(
            label="Bound the data too",
            options=DATA_CHOICES,
            value="low",
            sizing_mode="stretch_width",
        )
        self.horizon_input = pn.widgets.FloatInput(
            label="Horizon (s): longest time unaided",
            value=None,
            start=0.0,
            placeholder="the log length",
            sizing_mode="stretch_width",
        )
        self.tails_check = pn.widgets.Checkbox(
            label="Cover the data's heavy tails (tail factors, default)", value=True
        )
        for w in (self.data_select, self.horizon_input, self.tails_check):
            w.param.watch(lambda _e: self._on_change(), "value")
        self.box.objects = [
            self.data_select,
            self.horizon_input,
            self.tails_check,
            pn.pane.Markdown(
                "The filter file's WV is at least the fitted model's and this of the "
                "empirical WV at every scale from two filter steps to the horizon (a GNSS "
                "outage, a visual dropout: the longest time your filter runs without aiding). "
                "With tail factors, the data bound is raised where the sensor's errors are "
                "heavier-tailed than a Gaussian's (docs: Filter files, Tails).",
                margin=(0, 10),
                styles=_SMALL,
            ),
        ]

    def _on_toggle(self, event: Any) -> None:
        if event.new and not self.built:
            self._build()
        self.box.visible = bool(event.new)
        self._on_change()

    @property
    def options(self) -> dict[str, Any]:
        """The engine keywords (``data``, ``horizon_s``, ``tails``) of the chosen options;
        ``{}`` (the engine's defaults) while the menu is closed.

        Raises
        ------
        ValueError
            A horizon that is not a positive time (the message says what to enter).
        """
        if not (self.toggle.value and self.built):
            return {}
        out: dict[str, Any] = {"data": self.data_select.value}
        if not self.tails_check.value:
            out["tails"] = False
        h = self.horizon_input.value
        if h is not None:
            if not (math.isfinite(float(h)) and float(h) > 0):
                raise ValueError(
                    f"horizon {h!r} s: enter the longest time in seconds that the filter runs "
                    "without aiding (a positive number), or leave it empty for the log length"
                )
            out["horizon_s"] = float(h)
        return out
