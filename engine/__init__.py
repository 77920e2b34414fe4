"""GMWM engine: wavelet variance, latent processes, GMWM fitting, loaders (pure numerics, no UI).

>>> import engine as eg
>>> wv = eg.wavelet_variance(x, fs=100.0)                 # doctest: +SKIP
>>> res = eg.fit_gmwm(wv, eg.WN() + eg.RW() + 2 * eg.GM())  # doctest: +SKIP
>>> print(res.summary())                                  # doctest: +SKIP

The API is what a user calls, written out below (docs/api.md is built from it): :data:`API`
maps each public name to the module that defines it, one place per name. A name is imported on
first use (PEP 562), so that ``import engine`` and the ``gmwm`` command stay light (SciPy, h5py
and the multivariate code cost tenths of a second). ``tests/project/test_public_api.py`` pins
the list: adding a name is a deliberate act. Everything else lives in the subpackages
(``engine.fit``, ``engine.formats`` ...) for those who need it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__ as __version__

#: Every public name and the module that defines it.
API: dict[str, str] = {
    "__version__": "engine._version",
    # errors: one base class (catch it to stop on any engine error), one class per kind
    **dict.fromkeys(
        (
            "GmwmError",
            "LoadError",
            "ModelError",
            "FitError",
            "ExportError",
            "DatasheetError",
            "SessionError",
            "ReportError",
        ),
        "engine.errors",
    ),
    # processes and models
    **dict.fromkeys(("Process", "Model", "parse_model", "PROCESS_TYPES"), "engine.models"),
    **dict.fromkeys(("WN", "QN", "RW", "DR", "AR1", "GM", "ar1_wv"), "engine.models.processes"),
    # wavelet variance, Allan variance, cross-covariance
    **dict.fromkeys(
        (
            "WaveletVariance",
            "wavelet_variance",
            "default_levels",
            "haar_coefficients",
            "biweight_constant",
            "robust_scale_biweight",
        ),
        "engine.wv",
    ),
    "wavelet_variance_stream": "engine.wv.stream",
    "pooled_wavelet_variance": "engine.wv.pooled",
    **dict.fromkeys(("AllanVariance", "allan_variance"), "engine.wv.allan"),
    **dict.fromkeys(
        ("WaveletCrossCovariance", "wavelet_cross_covariance", "WVMatrix", "wv_matrix"),
        "engine.wv.wccv",
    ),
    # fits and their results
    **dict.fromkeys(
        (
            "fit_gmwm",
            "fit_efficient",
            "GMWMResult",
            "weight_matrix",
            "gmwm_objective",
            "FitResult",
            "ParamRecord",
            "ParamTable",
            "Summary",
            "starting_values",
            "wv_cov",
            "wv_cov_model",
            "wv_cov_data",
            "wv_cov_bootstrap",
        ),
        "engine.fit",
    ),
    **dict.fromkeys(("fit_replicates", "ReplicateResult"), "engine.fit.replicates"),
    **dict.fromkeys(("fit_gmwfm", "fit_armav", "GMWFMResult"), "engine.fit.gmwfm"),
    **dict.fromkeys(("MethodEstimate", "from_gmwm", "compare_table"), "engine.fit.estimate"),
    # inference: intervals, J-test, selection, datasheet check
    **dict.fromkeys(
        (
            "param_intervals",
            "ParamInterval",
            "j_test",
            "JTest",
            "rank_models",
            "submodels",
            "SelectionResult",
            "Candidate",
            "check_datasheet",
            "read_datasheet",
            "parse_datasheet",
            "DatasheetSpec",
            "DatasheetCheck",
            "plan_run",
            "RunPlan",
        ),
        "engine.inference",
    ),
    # multivariate GMWM and the virtual sensor
    **dict.fromkeys(
        (
            "MultiModel",
            "SharedProcess",
            "fit_mgmwm",
            "MGMWMResult",
            "SharedEstimate",
            "moment_covariance",
            "dependence_test",
            "DependenceTest",
            "virtual_sensor",
            "VirtualSensor",
            "virtual_model",
            "virtual_signal",
            "optimal_weights",
        ),
        "engine.multivariate",
    ),
    # loading logs, sessions
    **dict.fromkeys(
        (
            "load_log",
            "save_log",
            "ImuLog",
            "check_time",
            "TimeReport",
            "read_imu_bag",
            "imu_topics",
        ),
        "engine.io",
    ),
    "read_kalibr": "engine.io.kalibr",
    **dict.fromkeys(("still_segments", "with_segments"), "engine.io.segments"),
    **dict.fromkeys(("Session", "load_session", "save_session"), "engine.session"),
    # export formats and the projection onto a filter's noise model
    **dict.fromkeys(
        (
            "export",
            "FORMATS",
            "project",
            "Projection",
            "datasheet_table",
            "fit_report",
            "kalibr_imu",
            "kalibr_models",
            "write_kalibr",
        ),
        "engine.formats",
    ),
    # reports
    **dict.fromkeys(
        (
            "report",
            "fleet_report",
            "gather_report",
            "gather_fleet",
            "render_html",
            "render_fleet_html",
            "CalibrationReport",
            "FleetReport",
        ),
        "engine.reporting",
    ),
    # units and datasheet conversions
    **dict.fromkeys(
        (
            "datasheet",
            "param_unit",
            "si_factor",
            "to_datasheet",
            "from_datasheet",
            "process_values",
            "BI_FACTOR",
        ),
        "engine.units",
    ),
    # fleets of logs
    **dict.fromkeys(("fit_batch", "fit_log", "BatchResult", "LogFit"), "engine.batch"),
    # teaching: the slope method against GMWM, the scenarios
    **dict.fromkeys(
        ("run_slope_study", "avsm", "avsm_auto", "simulate_scenario", "Scenario", "SCENARIOS"),
        "engine.teaching",
    ),
    # the demo log shipped with the package
    **dict.fromkeys(("demo_path", "demo_truth", "demo_dir"), "engine.demo"),
}

__all__ = sorted(API)

# The same names for type checkers, which cannot follow __getattr__ (at run time each is
# imported on first use): tests/project/test_public_api.py checks that they match API.
if TYPE_CHECKING:  # pragma: no cover
    from .batch import BatchResult, LogFit, fit_batch, fit_log
    from .demo import demo_dir, demo_path, demo_truth
    from .errors import (
        DatasheetError,
        ExportError,
        FitError,
        GmwmError,
        LoadError,
        ModelError,
        ReportError,
        SessionError,
    )
    from .fit import (
        FitResult,
        GMWMResult,
        ParamRecord,
        ParamTable,
        Summary,
        fit_efficient,
        fit_gmwm,
        gmwm_objective,
        starting_values,
        weight_matrix,
        wv_cov,
        wv_cov_bootstrap,
        wv_cov_data,
        wv_cov_model,
    )
    from .fit.estimate import MethodEstimate, compare_table, from_gmwm
    from .fit.gmwfm import GMWFMResult, fit_armav, fit_gmwfm
    from .fit.replicates import ReplicateResult, fit_replicates
    from .formats import (
        FORMATS,
        Projection,
        datasheet_table,
        export,
        fit_report,
        kalibr_imu,
        kalibr_models,
        project,
        write_kalibr,
    )
    from .inference import (
        Candidate,
        DatasheetCheck,
        DatasheetSpec,
        JTest,
        ParamInterval,
        RunPlan,
        SelectionResult,
        check_datasheet,
        j_test,
        param_intervals,
        parse_datasheet,
        plan_run,
        rank_models,
        read_datasheet,
        submodels,
    )
    from .io import ImuLog, TimeReport, check_time, imu_topics, load_log, read_imu_bag, save_log
    from .io.kalibr import read_kalibr
    from .io.segments import still_segments, with_segments
    from .models import PROCESS_TYPES, Model, Process, parse_model
    from .models.processes import AR1, DR, GM, QN, RW, WN, ar1_wv
    from .multivariate import (
        DependenceTest,
        MGMWMResult,
        MultiModel,
        SharedEstimate,
        SharedProcess,
        VirtualSensor,
        dependence_test,
        fit_mgmwm,
        moment_covariance,
        optimal_weights,
        virtual_model,
        virtual_sensor,
        virtual_signal,
    )
    from .reporting import (
        CalibrationReport,
        FleetReport,
        fleet_report,
        gather_fleet,
        gather_report,
        render_fleet_html,
        render_html,
        report,
    )
    from .session import Session, load_session, save_session
    from .teaching import SCENARIOS, Scenario, avsm, avsm_auto, run_slope_study, simulate_scenario
    from .units import (
        BI_FACTOR,
        datasheet,
        from_datasheet,
        param_unit,
        process_values,
        si_factor,
        to_datasheet,
    )
    from .wv import (
        WaveletVariance,
        biweight_constant,
        default_levels,
        haar_coefficients,
        robust_scale_biweight,
        wavelet_variance,
    )
    from .wv.allan import AllanVariance, allan_variance
    from .wv.pooled import pooled_wavelet_variance
    from .wv.stream import wavelet_variance_stream
    from .wv.wccv import WaveletCrossCovariance, WVMatrix, wavelet_cross_covariance, wv_matrix

#: The subpackages and modules, reachable as attributes (``eg.units.datasheet_rows``).
SUBMODULES: tuple[str, ...] = (
    "errors",
    "models",
    "units",
    "wv",
    "io",
    "demo",
    "fit",
    "inference",
    "multivariate",
    "formats",
    "teaching",
    "batch",
    "session",
    "reporting",
    "cli",
)


def __getattr__(name: str) -> Any:
    if name in SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    module = API.get(name)
    if module is None:
        raise AttributeError(f"module 'engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(API))
