"""Latent-process models: the processes (WN, QN, RW, DR, AR1, GM, MA1) and their sums (``Model``).

``engine.models.model`` holds the :class:`Process` interface, :class:`Model` and the parser
(the spectral side of the interface in ``engine.models.spectrum``);
``engine.models.processes`` the concrete processes and ``engine.models.ma1`` the MA(1), which
register themselves on import (a new process: one module and one import line here).
"""

from __future__ import annotations

from .ma1 import MA1
from .model import (
    FROM_UNCONSTRAINED,
    PROCESS_TYPES,
    TO_UNCONSTRAINED,
    Model,
    ModelError,
    Param,
    Process,
    param,
    parse_model,
)
from .processes import (
    AR1,
    DR,
    GM,
    QN,
    RW,
    TC_MAX_FACTOR,
    TC_MIN,
    WN,
    ar1_wv,
    ar1_wv_pos,
)

__all__ = [
    "Process",
    "Param",
    "param",
    "WN",
    "QN",
    "RW",
    "DR",
    "AR1",
    "GM",
    "MA1",
    "Model",
    "ModelError",
    "parse_model",
    "ar1_wv",
    "ar1_wv_pos",
    "PROCESS_TYPES",
    "TO_UNCONSTRAINED",
    "FROM_UNCONSTRAINED",
    "TC_MIN",
    "TC_MAX_FACTOR",
]
