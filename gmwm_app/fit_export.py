"""The JSON export of a session's fit (no widgets): the fit, its datasheet values, the data.

:class:`ExportMixin` holds these methods of :class:`gmwm_app.state.AppState` (it has the
state's parameters and ``to_query``, ``data_info``, ``warnings``, ``whatif_model`` and
``display_objective``). The other exports (session file, Kalibr, the filter formats) are in
:mod:`gmwm_app.session_view`; the HTML report in :mod:`gmwm_app.report_download`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import engine as eg

__all__ = ["ExportMixin"]

if TYPE_CHECKING:  # the state's names this mixin uses (AppState defines them)
    from gmwm_app.state_fields import StateFields
else:
    StateFields = object


class ExportMixin(StateFields):
    """JSON export methods of :class:`gmwm_app.state.AppState`."""

    param: Any

    def export_dict(self) -> dict[str, Any]:
        """JSON-ready export: the fit (``GMWMResult.to_dict()``), datasheet values, data info.

        Without a fit, the empirical WV alone (``"fit": null``).
        """
        out: dict[str, Any] = {
            "app": "gmwm-app",
            "query": self.to_query(),
            "data": self.data_info(),
        }
        if self.result is not None and self.fs is not None:  # a fit implies data and fs
            out["fit"] = self.result.to_dict()
            out["datasheet"] = eg.units.datasheet(
                self.result.model, float(self.fs), self.unit, n_levels=self.result.wv.n_levels
            )
            out["warnings"] = self.warnings()
        else:
            out["fit"] = None
            out["wv"] = None if self.wv is None else self.wv.to_dict()
        if self.whatif and len(self.model):
            m = self.whatif_model()
            out["whatif"] = {
                "model_values": m.spec(values=True),
                "objective": self.display_objective(),
            }
        return out

    def export_json(self) -> str:
        """:meth:`export_dict` as indented JSON text."""
        return json.dumps(self.export_dict(), indent=2, allow_nan=False, default=_json_default)

    def export_filename(self) -> str:
        """A file name for the JSON export, e.g. ``gmwm_demo_imu_gyro_x_2GM+WN+RW.json``."""
        stem = Path(self.filename or "data").stem
        spec = self.model.spec().replace("*", "") or "wv"
        return f"gmwm_{stem}_{self.shown['channel'] or 'none'}_{spec}.json"


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"cannot export {type(o).__name__} to JSON")
