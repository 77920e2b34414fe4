"""GMWM fitting: the univariate fit, its result and the result base every fit shares.

* :mod:`engine.fit.gmwm`: :func:`fit_gmwm`, :class:`GMWMResult`, :func:`weight_matrix`,
  :func:`gmwm_objective`;
* :mod:`engine.fit.result`: :class:`FitResult` (the base of every fit's result),
  :class:`ParamRecord`, :class:`ParamTable`, :class:`Summary`, :class:`FitError`;
* :mod:`engine.fit.start`: :func:`starting_values` (rough values read off a WV);
* :mod:`engine.fit.replicates`: one model fitted to several recordings;
* :mod:`engine.fit.gmwfm`: the wavelet functional moments (ARMAV, GMWFM);
* :mod:`engine.fit.estimate`: the common form of every estimator's answer (GMWM, ARMAV,
  the slope method) and the table that compares them;
* :mod:`engine.fit._varpro`: the one variable-projection search all the fits use.

The replicate, GMWFM and estimate modules are imported on first use (PEP 562), so that
``import engine.fit`` stays fast for the ``gmwm`` command.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes
from .gmwm import GMWMResult, fit_gmwm, gmwm_objective, weight_matrix
from .result import FitError, FitResult, ParamRecord, ParamTable, Summary
from .start import starting_values

_LAZY: dict[str, str] = {
    "fit_replicates": "replicates",
    "ReplicateResult": "replicates",
    "fit_gmwfm": "gmwfm",
    "fit_armav": "gmwfm",
    "GMWFMResult": "gmwfm",
    "MethodEstimate": "estimate",
    "from_gmwm": "estimate",
    "compare_table": "estimate",
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from .estimate import MethodEstimate, compare_table, from_gmwm
    from .gmwfm import GMWFMResult, fit_armav, fit_gmwfm
    from .replicates import ReplicateResult, fit_replicates

__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "fit_gmwm",
    "GMWMResult",
    "starting_values",
    "weight_matrix",
    "gmwm_objective",
    "FitError",
    "FitResult",
    "ParamRecord",
    "ParamTable",
    "Summary",
    "fit_replicates",
    "ReplicateResult",
    "fit_gmwfm",
    "fit_armav",
    "GMWFMResult",
    "MethodEstimate",
    "from_gmwm",
    "compare_table",
]
