"""GMWM fitting: the univariate fit, replicate fits and their results.

Public API: :func:`fit_gmwm`, :class:`GMWMResult`, :class:`ParamRecord`, :func:`weight_matrix`,
:class:`FitError` (``from engine.fit import ...``). The replicate fit lives in
:mod:`engine.fit.replicates` (imported on first use by :mod:`engine`).
"""

from __future__ import annotations

from .gmwm import FitError, GMWMResult, ParamRecord, fit_gmwm, weight_matrix

__all__ = ["fit_gmwm", "GMWMResult", "ParamRecord", "weight_matrix", "FitError"]
