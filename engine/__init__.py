"""GMWM engine: wavelet variance, latent processes, GMWM fitting, loaders (pure numerics, no UI).

>>> import engine as eg
>>> wv = eg.wavelet_variance(x, fs=100.0)                 # doctest: +SKIP
>>> res = eg.fit_gmwm(wv, eg.WN() + eg.RW() + 2 * eg.GM())  # doctest: +SKIP
>>> print(res.summary())                                  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__ as __version__
from .fit import (
    FitError,
    GMWMResult,
    ParamRecord,
    fit_gmwm,
    weight_matrix,
)
from .model import (
    Model,
    ModelError,
    parse_model,
)
from .processes import (
    AR1,
    DR,
    GM,
    QN,
    RW,
    WN,
    Process,
    ar1_wv,
)
from .units import (
    datasheet,
    param_unit,
)
from .wavelet import (
    WaveletVariance,
    biweight_constant,
    default_levels,
    haar_coefficients,
    robust_scale_biweight,
    wavelet_variance,
)

# the rest is imported on first use (PEP 562): `import engine` stays light, so the `gmwm`
# command starts fast (SciPy, h5py and the multivariate code cost ~0.5 s to import)
_LAZY: dict[str, str] = {
    "AllanVariance": "allan",
    "MethodEstimate": "allan",
    "allan_variance": "allan",
    "avsm": "allan",
    "avsm_auto": "allan",
    "compare_table": "allan",
    "fit_armav": "allan",
    "fit_gmwfm": "allan",
    "from_gmwm": "allan",
    "ExportError": "export",
    "datasheet_table": "export",
    "export": "export",
    "fit_report": "export",
    "kalibr_imu": "export",
    "kalibr_models": "export",
    "read_kalibr": "export",
    "write_kalibr": "export",
    "ImuLog": "io",
    "LoadError": "io",
    "load_log": "io",
    "save_log": "io",
    "DependenceTest": "mgmwm",
    "MGMWMResult": "mgmwm",
    "MultiModel": "mgmwm",
    "ReplicateResult": "mgmwm",
    "SharedEstimate": "mgmwm",
    "SharedProcess": "mgmwm",
    "dependence_test": "mgmwm",
    "fit_mgmwm": "mgmwm",
    "fit_replicates": "mgmwm",
    "moment_covariance": "mgmwm",
    "Session": "session",
    "SessionError": "session",
    "load_session": "session",
    "save_session": "session",
    "wavelet_variance_stream": "stream",
    "run_slope_study": "study",
    "TimeReport": "timecheck",
    "Scenario": "teaching",
    "SCENARIOS": "teaching",
    "simulate_scenario": "teaching",
    "check_time": "timecheck",
    "WaveletCrossCovariance": "wccv",
    "WVMatrix": "wccv",
    "wavelet_cross_covariance": "wccv",
    "wv_matrix": "wccv",
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from .allan import (
        AllanVariance,
        MethodEstimate,
        allan_variance,
        avsm,
        avsm_auto,
        compare_table,
        fit_armav,
        fit_gmwfm,
        from_gmwm,
    )
    from .export import (
        ExportError,
        datasheet_table,
        export,
        fit_report,
        kalibr_imu,
        kalibr_models,
        read_kalibr,
        write_kalibr,
    )
    from .io import (
        ImuLog,
        LoadError,
        load_log,
        save_log,
    )
    from .mgmwm import (
        DependenceTest,
        MGMWMResult,
        MultiModel,
        ReplicateResult,
        SharedEstimate,
        SharedProcess,
        dependence_test,
        fit_mgmwm,
        fit_replicates,
        moment_covariance,
    )
    from .session import (
        Session,
        SessionError,
        load_session,
        save_session,
    )
    from .stream import (
        wavelet_variance_stream,
    )
    from .study import (
        run_slope_study,
    )
    from .teaching import SCENARIOS, Scenario, simulate_scenario
    from .timecheck import (
        TimeReport,
        check_time,
    )
    from .wccv import (
        WaveletCrossCovariance,
        WVMatrix,
        wavelet_cross_covariance,
        wv_matrix,
    )


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "AR1",
    "DR",
    "GM",
    "QN",
    "RW",
    "WN",
    "Process",
    "Model",
    "ModelError",
    "parse_model",
    "WaveletVariance",
    "wavelet_variance",
    "default_levels",
    "haar_coefficients",
    "biweight_constant",
    "robust_scale_biweight",
    "ar1_wv",
    "fit_gmwm",
    "GMWMResult",
    "ParamRecord",
    "FitError",
    "weight_matrix",
    "datasheet",
    "param_unit",
    "ImuLog",
    "LoadError",
    "load_log",
    "save_log",
    "AllanVariance",
    "allan_variance",
    "MethodEstimate",
    "from_gmwm",
    "avsm",
    "avsm_auto",
    "fit_gmwfm",
    "fit_armav",
    "compare_table",
    "run_slope_study",
]
__all__ += [  # exports, sessions, long and messy logs (issue 7)
    "ExportError",
    "datasheet_table",
    "export",
    "fit_report",
    "kalibr_imu",
    "kalibr_models",
    "read_kalibr",
    "write_kalibr",
    "Session",
    "SessionError",
    "load_session",
    "save_session",
    "wavelet_variance_stream",
    "TimeReport",
    "check_time",
]
__all__ += [  # multivariate: WCCV, MGMWM, replicates (issue 6)
    "WaveletCrossCovariance",
    "WVMatrix",
    "wavelet_cross_covariance",
    "wv_matrix",
    "MultiModel",
    "SharedProcess",
    "fit_mgmwm",
    "MGMWMResult",
    "SharedEstimate",
    "moment_covariance",
    "dependence_test",
    "DependenceTest",
    "fit_replicates",
    "ReplicateResult",
]
__all__ += ["Scenario", "SCENARIOS", "simulate_scenario"]  # teaching (issue 4)
