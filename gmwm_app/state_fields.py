"""What the mixins of :class:`gmwm_app.state.AppState` use of the state, for the type checker.

``AppState`` is assembled from mixins (:mod:`gmwm_app.query`, :mod:`gmwm_app.whatif`,
:mod:`gmwm_app.selection_state`, :mod:`gmwm_app.fit_export`) whose methods read the state's
parameters and call its methods. :class:`StateFields` declares those names with their types:
each mixin derives from it when type-checked (``if TYPE_CHECKING``), and from ``object`` at run
time, so it adds nothing to the state. mypy checks that ``AppState`` defines each name with a
compatible type.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import engine as eg
from gmwm_app.data import LoadedData

__all__ = ["StateFields"]


class StateFields(Protocol):
    """The parameters and methods of ``AppState`` that its mixins use (declarations only)."""

    param: Any
    # parameters (gmwm_app.state.AppState: their defaults and docs)
    source: str
    path: str
    filename: str
    channels: list[str]
    channel: str
    fs: float | None
    fs_source: str
    n: int
    duration_s: float
    unit: str
    is_summary: bool
    robust: bool
    compensate: str
    wv: eg.WaveletVariance | None
    wv_raw: eg.WaveletVariance | None
    model: eg.Model
    result: eg.GMWMResult | None
    whatif: bool
    weights: str
    error: str
    precompute: Callable[..., None]

    @property
    def shown(self) -> dict[str, Any]: ...

    # methods of AppState
    def _publish(self, **changes: Any) -> None: ...
    def _guard(self, action: str, fn: Callable[[], bool]) -> bool: ...
    def _fail(self, message: str) -> bool: ...
    def _model_update(self, model: eg.Model, result: eg.GMWMResult | None) -> dict[str, Any]: ...
    def _apply_model(
        self, m: eg.Model, start: eg.Model | None = None, weights: str | None = None
    ) -> bool: ...
    def read(self, source: str, **kw: Any) -> LoadedData: ...
    def install(
        self,
        loaded: LoadedData,
        *,
        channel: str | None = None,
        fs: float | None = None,
        robust: bool | None = None,
        compensate: str | bool | None = None,
    ) -> bool: ...
    def set_model(self, model: eg.Model | str) -> bool: ...
    def offer_channels(self, names: Sequence[str]) -> None: ...
    def display_objective(self) -> float | None: ...
    def warnings(self) -> list[str]: ...

    # methods of one mixin that another calls
    def to_query(self) -> dict[str, str]: ...
    def data_info(self) -> dict[str, Any]: ...
    def whatif_model(self, override: Mapping[str, float] | None = None) -> eg.Model: ...
