"""Multivariate GMWM (MGMWM): latent models shared across channels.

* :mod:`.spec`: :class:`MultiModel` (one univariate model per channel plus
  :class:`SharedProcess` objects), implied WV/WCCV moments and simulation;
* :mod:`._cone`: the exact inner solve (least squares over non-negative orthants and PSD
  cones);
* :mod:`.problem`: the stacked moments, the profiled objective and its non-linear search;
* :mod:`.fit`: :func:`fit_mgmwm` and :func:`moment_covariance`;
* :mod:`.result`: :class:`MGMWMResult`, :class:`SharedEstimate`;
* :mod:`.dependence`: :func:`dependence_test` (parametric bootstrap), :class:`DependenceTest`.

The replicate fit (one univariate model, several recordings) is :mod:`engine.fit.replicates`.
"""

from __future__ import annotations

from .dependence import DependenceTest, dependence_test
from .fit import fit_mgmwm, moment_covariance
from .result import MGMWMResult, SharedEstimate
from .spec import SHAREABLE, MultiModel, SharedProcess

__all__ = [
    "SHAREABLE",
    "SharedProcess",
    "MultiModel",
    "MGMWMResult",
    "SharedEstimate",
    "fit_mgmwm",
    "moment_covariance",
    "DependenceTest",
    "dependence_test",
]
