"""GMWM fitting: the univariate fit, its result and the result base every fit shares.

* :mod:`engine.fit.gmwm`: :func:`fit_gmwm` (weights ``"ci"``, ``"identity"``, ``"efficient"``
  or a matrix; :func:`fit_efficient` is its two-step alias), :class:`GMWMResult`,
  :func:`weight_matrix`, :func:`gmwm_objective`;
* :mod:`engine.fit.covariance`: ``V = Cov(nu_hat)`` three ways (:func:`wv_cov_model`,
  :func:`wv_cov_data`, :func:`wv_cov_bootstrap`; :func:`wv_cov` by name), the efficient
  weights ``V^-1``;
* :mod:`engine.fit.asymptotic`: the model-implied WV covariance in closed form
  (:mod:`engine.fit._closed_form`), the Jacobian and the sandwich covariance of a fit
  (:func:`param_cov`; ``GMWMResult.conf_int``);
* :mod:`engine.fit.ieee`: the IEEE quantities of a fit (:func:`ieee_table`,
  ``GMWMResult.ieee``): N with its disguised share, B and the ADEV minimum, K, Q, R;
* :mod:`engine.fit.result`: :class:`FitResult` (the base of every fit's result),
  :class:`ParamRecord`, :class:`ParamTable`, :class:`Summary`, :class:`FitError`;
* :mod:`engine.fit.start`: :func:`starting_values` (rough values read off a WV);
* :mod:`engine.fit.replicates`: one model fitted to several recordings;
* :mod:`engine.fit.gmwfm`: the wavelet functional moments (ARMAV, GMWFM);
* :mod:`engine.fit.estimate`: the common form of every estimator's answer (GMWM, ARMAV,
  the slope method) and the table that compares them;
* :mod:`engine.fit._varpro`: the one variable-projection search all the fits use.

Every name is imported on first use (PEP 562, :func:`engine._lazy.lazy_attributes`), so that
a module that needs one part of the package loads that part only: the run planner
(``gmwm plan``) uses the asymptotic covariance and the IEEE table, not the fit's search, its
starting values or the bootstrap's process pool (docs/performance.md, "The gmwm command's
start").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes

#: Each module of the package and the public names it defines, in ``__all__`` order.
_LAZY: dict[str, tuple[str, ...]] = {
    "gmwm": ("fit_gmwm", "fit_efficient", "GMWMResult", "weight_matrix", "gmwm_objective"),
    "ieee": ("IeeeTable", "IeeeQuantity", "ieee_table"),
    "covariance": ("wv_cov", "wv_cov_data", "wv_cov_bootstrap", "VOptions", "V_DEFAULTS"),
    "asymptotic": ("wv_cov_model", "param_cov"),
    "start": ("starting_values",),
    "result": ("FitError", "FitResult", "ParamRecord", "ParamTable", "Summary"),
    "replicates": ("fit_replicates", "ReplicateResult"),
    "gmwfm": ("fit_gmwfm", "fit_armav", "GMWFMResult"),
    "estimate": ("MethodEstimate", "from_gmwm", "compare_table"),
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs (the names of _LAZY)
    from .asymptotic import param_cov, wv_cov_model  # noqa: F401
    from .covariance import V_DEFAULTS, VOptions, wv_cov, wv_cov_bootstrap, wv_cov_data  # noqa: F401
    from .estimate import MethodEstimate, compare_table, from_gmwm  # noqa: F401
    from .gmwfm import GMWFMResult, fit_armav, fit_gmwfm  # noqa: F401
    from .gmwm import GMWMResult, fit_efficient, fit_gmwm, gmwm_objective, weight_matrix  # noqa: F401
    from .ieee import IeeeQuantity, IeeeTable, ieee_table  # noqa: F401
    from .replicates import ReplicateResult, fit_replicates  # noqa: F401
    from .result import FitError, FitResult, ParamRecord, ParamTable, Summary  # noqa: F401
    from .start import starting_values  # noqa: F401

__getattr__, __dir__, _ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "fit_gmwm",
    "fit_efficient",
    "GMWMResult",
    "IeeeTable",
    "IeeeQuantity",
    "ieee_table",
    "wv_cov",
    "wv_cov_model",
    "wv_cov_data",
    "wv_cov_bootstrap",
    "param_cov",
    "VOptions",
    "V_DEFAULTS",
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
