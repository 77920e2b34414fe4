"""Teaching and comparison: the slope method, the Monte Carlo study that ranks it against
GMWM and ARMAV, and the app's teaching scenarios.

* :mod:`engine.teaching.slope`: the Allan variance slope method (AVSM, IEEE Std 952) and the
  ROS tools' automatic read-off, as :class:`~engine.fit.estimate.MethodEstimate`;
* :mod:`engine.teaching.table1`, :mod:`~engine.teaching.study`,
  :mod:`~engine.teaching.study_result`: the GMWM paper's Monte Carlo (Table I, Fig. 1-2);
* :mod:`engine.teaching.scenarios`: four simulated logs where the slope method goes wrong.

The Allan variance itself is :mod:`engine.wv.allan`; the common estimate form and the
comparison table are :mod:`engine.fit.estimate`.
"""

from __future__ import annotations

from .scenarios import SCENARIOS, Scenario, get_scenario, gmwm_spec, simulate_scenario
from .slope import READ_TAU, SLOPES, avsm, avsm_auto
from .study import estimate_all, run_slope_study
from .study_result import StudyResult
from .table1 import (
    METHODS,
    STUDY_FS,
    STUDY_N,
    TABLE_I,
    table1_model,
    typical_regions,
)

__all__ = [
    "SLOPES",
    "READ_TAU",
    "avsm",
    "avsm_auto",
    "TABLE_I",
    "STUDY_FS",
    "STUDY_N",
    "METHODS",
    "table1_model",
    "typical_regions",
    "estimate_all",
    "run_slope_study",
    "StudyResult",
    "Scenario",
    "SCENARIOS",
    "get_scenario",
    "gmwm_spec",
    "simulate_scenario",
]
