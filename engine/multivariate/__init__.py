"""Multivariate GMWM (MGMWM): latent models shared across channels.

* :mod:`.spec`: :class:`MultiModel` (one univariate model per channel plus
  :class:`SharedProcess` objects), implied WV/WCCV moments and simulation;
* :mod:`._cone`: the exact inner solve (least squares over non-negative orthants and PSD
  cones);
* :mod:`.problem`: the stacked moments, the profiled objective and its non-linear search;
* :mod:`.fit`: :func:`fit_mgmwm`;
* :mod:`.moments`: :func:`moment_covariance` and the asymptotic intervals of a fit;
* :mod:`.result`: :class:`MGMWMResult` (on :class:`engine.fit.result.FitResult`),
  :class:`SharedEstimate`, :class:`MultiParamRecord`;
* :mod:`.dependence`: :func:`dependence_test` (parametric bootstrap), :class:`DependenceTest`;
* :mod:`.virtual`: :func:`virtual_sensor` (the optimal weighted mean of redundant sensors),
  :class:`VirtualSensor`, :func:`optimal_weights`, :func:`virtual_model`,
  :func:`virtual_signal`.

The replicate fit (one univariate model, several recordings) is :mod:`engine.fit.replicates`.
"""

from __future__ import annotations

from .dependence import DependenceTest, dependence_test
from .fit import fit_mgmwm
from .moments import moment_covariance
from .result import MGMWMResult, MultiParamRecord, SharedEstimate
from .spec import SHAREABLE, MultiModel, SharedProcess
from .virtual import (
    VirtualSensor,
    optimal_weights,
    virtual_model,
    virtual_sensor,
    virtual_signal,
)

__all__ = [
    "SHAREABLE",
    "SharedProcess",
    "MultiModel",
    "MGMWMResult",
    "SharedEstimate",
    "MultiParamRecord",
    "fit_mgmwm",
    "moment_covariance",
    "DependenceTest",
    "dependence_test",
    "VirtualSensor",
    "optimal_weights",
    "virtual_sensor",
    "virtual_model",
    "virtual_signal",
]
