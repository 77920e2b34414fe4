"""Inference for GMWM: intervals, goodness of fit, model selection, the datasheet check.

* ``V = Cov(nu_hat)`` across levels (in :mod:`engine.fit.covariance`, below the fit, which
  uses it for ``weights="efficient"``), three ways:

  - :func:`wv_cov_data`: from the data, per level (diagonal), Percival & Walden's asymptotic
    estimator ``2 A_j / M_j`` with ``A_j = s_0^2 / 2 + sum_{tau>0} s_tau^2`` (``s`` the
    autocovariances of the level-j coefficients, i.e. the spectral density of the coefficients
    integrated squared), as in the R ``gmwm`` package;
  - :func:`wv_cov_model`: from a fitted model, Gaussian and asymptotic but full:
    ``Cov(nu_j, nu_k) = 2 / max(M_j, M_k) int |H_j(f)|^2 |H_k(f)|^2 S(f)^2 df`` with the Haar
    squared gains ``|H_j(f)|^2 = sin^4(pi f 2^(j-1)) / (4^(j-1) sin^2(pi f))`` and the model's
    spectral density ``S`` (checked against Monte Carlo in the tests);
  - :func:`wv_cov_bootstrap`: parametric bootstrap from a fitted model (simulate, recompute
    the WV, sample covariance).

* Efficient two-step GMWM (``fit_gmwm(..., weights="efficient")``): fit with
  ``weights="ci"``, estimate V from that fit, refit with ``Omega = V^-1`` (the GMWM paper,
  Corollary 1).
* Parameter intervals (:func:`param_intervals`): asymptotic sandwich
  ``(A' W A)^-1 A' W V W A (A' W A)^-1`` (the GMWM paper, Theorem 2 / Lemma 2) in the
  unconstrained space of each parameter (log variances, log beta, atanh phi) mapped back, so
  intervals stay inside the parameter space; or the parametric bootstrap (percentile).
* Goodness of fit (:func:`j_test`): ``T = (nu_hat - nu)' V^-1 (nu_hat - nu)`` against a
  chi-square with ``J - p`` degrees of freedom.
* Model selection (:func:`rank_models`, WVIC) in :mod:`engine.inference.selection`.
* Datasheet check (:func:`check_datasheet`, :func:`read_datasheet`): a manufacturer's noise
  model against the empirical WV, scale by scale (:mod:`engine.inference.datasheet_check`);
  the datasheet's values as a model (:class:`DatasheetSpec`, :func:`parse_datasheet`:
  :mod:`engine.inference.datasheet_spec`).
* Planning a log's length (:func:`plan_run`) in :mod:`engine.inference.planning`.

The names are imported on first use (PEP 562, :func:`engine._lazy.lazy_attributes`): ``gmwm
plan`` loads the planning module, not the selection or the datasheet check.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes

#: Each module of the package and the public names it defines.
_LAZY: dict[str, tuple[str, ...]] = {
    "intervals": ("param_intervals", "ParamInterval"),
    "jtest": ("j_test", "JTest"),
    "selection": ("rank_models", "submodels", "SelectionResult", "Candidate"),
    "datasheet_check": (
        "check_datasheet",
        "read_datasheet",
        "DatasheetCheck",
        "DatasheetError",
        "DATASHEET_KEYS",
    ),
    "datasheet_spec": ("parse_datasheet", "DatasheetSpec"),
    "planning": ("plan_run", "plan_precision", "parse_targets", "PlanTarget", "RunPlan"),
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs (the names of _LAZY)
    from .datasheet_check import (  # noqa: F401
        DATASHEET_KEYS,
        DatasheetCheck,
        DatasheetError,
        check_datasheet,
        read_datasheet,
    )
    from .datasheet_spec import DatasheetSpec, parse_datasheet  # noqa: F401
    from .intervals import ParamInterval, param_intervals  # noqa: F401
    from .jtest import JTest, j_test  # noqa: F401
    from .planning import PlanTarget, RunPlan, parse_targets, plan_precision, plan_run  # noqa: F401
    from .selection import Candidate, SelectionResult, rank_models, submodels  # noqa: F401

__getattr__, __dir__, _lazy_names = lazy_attributes(__name__, _LAZY, globals())

__all__ = list(_lazy_names)  # the names of _LAZY, in its order
