"""The what-if mode of a session: sliders over the model's parameters (no widgets).

:class:`SliderSpec` describes one slider, in the scale its parameter declares;
:class:`WhatIfMixin` holds the what-if actions of :class:`gmwm_app.state.AppState` (it has
the state's parameters); a model not fitted yet starts from
:func:`engine.fit.starting_values` (rough values read off the WV).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import engine as eg
from engine.models import Param

__all__ = ["SliderSpec", "WhatIfMixin"]

if TYPE_CHECKING:  # the state's names this mixin uses (AppState defines them)
    from gmwm_app.state_fields import StateFields
else:
    StateFields = object


@dataclass(frozen=True)
class SliderSpec:
    """A "what if" slider generated from a parameter (no widget: the app builds it).

    The slider moves a position ``x`` over ``[lo, hi]`` in the scale the parameter declares
    (:attr:`engine.models.model.Param.slider`): ``log10(value)`` (variances, rates) or
    ``log10(1 - value)`` (an AR1 ``phi``), 3 decades either side of the current value, or
    the value itself over the parameter's bounds (``linear``: a coefficient of either sign).
    """

    name: str  # unique parameter name, e.g. "GM_1.beta"
    label: str  # process label, e.g. "GM_1"
    param: str  # engine parameter name, e.g. "beta"
    unit: str
    transform: str  # "log10", "log10(1-x)" or "linear"
    lo: float
    hi: float
    x: float  # slider position

    def value_of(self, x: float) -> float:
        """Parameter value at slider position ``x``."""
        if self.transform == "linear":
            return x
        return 1.0 - 10.0**x if self.transform == "log10(1-x)" else 10.0**x

    @staticmethod
    def position_of(transform: str, value: float) -> float:
        """Slider position of a parameter value."""
        if transform == "linear":
            return value
        if transform == "log10(1-x)":
            return math.log10(max(1.0 - value, 1e-15))
        return math.log10(abs(value))

    @staticmethod
    def shows(transform: str, value: float | None) -> bool:
        """Whether a slider in ``transform`` can stand at ``value`` (a log slider cannot at 0,
        a ``log10(1-x)`` one not at 1 or above)."""
        if value is None:
            return False
        if transform == "linear":
            return True
        return value != 0 and not (transform == "log10(1-x)" and value >= 1)

    @classmethod
    def around(
        cls,
        name: str,
        label: str,
        param: str,
        unit: str,
        spec: Param,
        value: float,
    ) -> SliderSpec:
        """The slider of a parameter declared by ``spec`` standing at ``value``: 3 decades
        either side of it on a log scale (``log10(1-x)``: at most ``x = 0``, ``phi >= 0``),
        or the parameter's bounds, less a 1/1000 of their width at each end, when linear."""
        transform = spec.slider
        x = cls.position_of(transform, value)
        if transform == "linear":
            lo, hi = spec.bounds
            pad = (hi - lo) / 1000.0
            lo, hi = lo + pad, hi - pad
            return cls(name, label, param, unit, transform, lo, hi, min(max(x, lo), hi))
        lo, hi = x - 3.0, x + 3.0
        if transform == "log10(1-x)":
            hi = min(hi, 0.0)  # phi >= 0
            lo = min(lo, hi - 3.0)
        return cls(name, label, param, unit, transform, lo, hi, x)


class WhatIfMixin(StateFields):
    """What-if actions of :class:`gmwm_app.state.AppState` (its parameters ``model``,
    ``result``, ``wv``, ``whatif``, ``whatif_values``; its ``_publish``, ``_guard``,
    ``_model_update`` and ``_apply_model``)."""

    param: Any
    model: eg.Model
    wv: Any
    whatif_values: dict[str, float]

    def set_whatif(self, on: bool) -> bool:
        """Turn the what-if mode on (curves follow the sliders) or off (curves show the fit)."""
        vals = dict(self.whatif_values)
        if on:
            vals = {**self._default_values(), **vals}
        self._publish(whatif=bool(on), whatif_values=vals)
        return True

    def set_whatif_value(self, name: str, value: float) -> bool:
        """Set one what-if parameter (unique name like ``GM_1.beta``); curves move, no fit."""

        def run() -> bool:
            if name not in self.model.param_names:
                raise ValueError(f"the model has no parameter {name!r}")
            try:
                v = float(value)  # a slider's number, a field's text, or None (cleared)
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            self.whatif_model({name: v})  # validates the value (e.g. beta > 0)
            self._publish(whatif_values={**self.whatif_values, name: v}, error="")
            return True

        return self._guard("Could not set the what-if value", run)

    def reset_whatif(self) -> bool:
        """What-if values back to the fitted ones."""
        self._publish(
            whatif_values=self._model_update(self.model, self.result)["whatif_values"]
            or self._default_values(),
            error="",
        )
        return True

    def fit_from_whatif(self) -> bool:
        """Refit, using the what-if values as extra starting values."""
        return self._guard(
            "Could not fit",
            lambda: self._apply_model(self.model.cleared(), start=self.whatif_model()),
        )

    def _default_values(self) -> dict[str, float]:
        """Fitted values where known, else rough guesses read off the WV."""
        vals = {k: v for k, v in self.model.values().items() if v is not None}
        if self.wv is None:
            return vals
        for name, v in eg.fit.starting_values(self.model, self.wv).items():
            vals.setdefault(name, v)
        return vals

    def whatif_model(self, override: Mapping[str, float] | None = None) -> eg.Model:
        """The model with the what-if values (guesses where none), every value set."""
        vals = {**self._default_values(), **self.whatif_values, **(override or {})}
        procs = []
        for lab, p in zip(self.model.labels, self.model.processes, strict=True):
            procs.append(p.with_values(**{n: vals[f"{lab}.{n}"] for n in p.param_names}))
        return eg.Model(tuple(procs))
