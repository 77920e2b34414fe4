"""GMWM fitting: the univariate fit, its result and the result base every fit shares.

Public API: :func:`fit_gmwm`, :class:`GMWMResult`, :func:`weight_matrix`, :class:`FitError`,
:class:`FitResult`, :class:`ParamRecord`, :class:`ParamTable`, :class:`Summary`
(``from engine.fit import ...``). The replicate fit is :mod:`engine.fit.replicates` and the
wavelet functional moments (ARMAV, GMWFM) :mod:`engine.fit.gmwfm`, imported on first use by
:mod:`engine`. The variable-projection core is the private :mod:`engine.fit._varpro`.
"""

from __future__ import annotations

from .gmwm import GMWMResult, fit_gmwm, weight_matrix
from .result import FitError, FitResult, ParamRecord, ParamTable, Summary

__all__ = [
    "fit_gmwm",
    "GMWMResult",
    "weight_matrix",
    "FitError",
    "FitResult",
    "ParamRecord",
    "ParamTable",
    "Summary",
]
