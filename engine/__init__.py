"""GMWM engine: wavelet variance, latent processes, GMWM fitting, loaders (pure numerics, no UI).

>>> import engine as eg
>>> wv = eg.wavelet_variance(x, fs=100.0)                 # doctest: +SKIP
>>> res = eg.fit_gmwm(wv, eg.WN() + eg.RW() + 2 * eg.GM())  # doctest: +SKIP
>>> print(res.summary())                                  # doctest: +SKIP

The top level is what a user calls to calibrate a log, written out below: :data:`API` maps each
name to the module that defines it, one place per name. Everything else is public in its
subpackage, listed in that subpackage's ``__all__`` and reachable as an attribute
(``eg.fit.fit_gmwfm``, ``eg.wv.wv_matrix``, ``eg.formats.project``); docs/api.md is built from
these lists. A name is imported on first use (PEP 562), so that ``import engine`` and the
``gmwm`` command stay light (SciPy, h5py and the multivariate code cost tenths of a second).
``tests/project/test_public_api.py`` pins the top level: adding a name is a deliberate act.
"""

from __future__ import annotations

import importlib
import warnings
from typing import TYPE_CHECKING, Any

from ._version import __version__ as __version__

#: Every name of the top level and the module that defines it: what a user calls to calibrate a
#: log (load, fit, intervals, selection, export, report, plan). The rest is public in its
#: subpackage (``eg.fit.fit_gmwfm``, ``eg.wv.wv_matrix``, ``eg.formats.project`` ...), each
#: listed in that subpackage's ``__all__``.
API: dict[str, str] = {
    "__version__": "engine._version",
    # errors: one base class (catch it to stop on any engine error), one class per common kind
    **dict.fromkeys(
        ("GmwmError", "LoadError", "ModelError", "FitError", "ExportError"), "engine.errors"
    ),
    # processes and models
    **dict.fromkeys(("Process", "Model", "parse_model", "MA1"), "engine.models"),
    **dict.fromkeys(("WN", "QN", "RW", "DR", "AR1", "GM"), "engine.models.processes"),
    # wavelet variance, Allan variance, cross-covariance
    **dict.fromkeys(("WaveletVariance", "wavelet_variance"), "engine.wv"),
    **dict.fromkeys(("AllanVariance", "allan_variance"), "engine.wv.allan"),
    "wavelet_cross_covariance": "engine.wv.wccv",
    # fits, intervals, tests, selection, datasheet check, run planning
    **dict.fromkeys(("fit_gmwm", "fit_efficient", "GMWMResult"), "engine.fit"),
    **dict.fromkeys(
        ("param_intervals", "j_test", "rank_models", "check_datasheet", "plan_run"),
        "engine.inference",
    ),
    # multivariate GMWM and the virtual sensor
    **dict.fromkeys(("MultiModel", "fit_mgmwm", "virtual_sensor"), "engine.multivariate"),
    # logs, filter files, reports, fleets
    **dict.fromkeys(("load_log", "ImuLog"), "engine.io"),
    **dict.fromkeys(("export", "FORMATS"), "engine.formats"),
    **dict.fromkeys(("report", "fleet_report"), "engine.reporting"),
    **dict.fromkeys(("fit_batch", "fit_log"), "engine.batch"),
    "to_datasheet": "engine.units",
    # teaching: the slope method against GMWM; the demo log shipped with the package
    **dict.fromkeys(("avsm", "run_slope_study"), "engine.teaching"),
    "demo_path": "engine.demo",
}

#: The names the top level had until version 0.1 and the subpackage each is public in now:
#: ``eg.<name>`` still finds them, with a :class:`DeprecationWarning` naming the new place.
MOVED: dict[str, str] = {
    **dict.fromkeys(("BatchResult", "LogFit"), "batch"),
    **dict.fromkeys(("demo_dir", "demo_truth"), "demo"),
    **dict.fromkeys(("DatasheetError", "ReportError", "SessionError"), "errors"),
    **dict.fromkeys(
        (
            "compare_table",
            "fit_armav",
            "fit_gmwfm",
            "fit_replicates",
            "FitResult",
            "from_gmwm",
            "GMWFMResult",
            "gmwm_objective",
            "MethodEstimate",
            "ParamRecord",
            "ParamTable",
            "ReplicateResult",
            "starting_values",
            "Summary",
            "weight_matrix",
            "wv_cov",
            "wv_cov_bootstrap",
            "wv_cov_data",
            "wv_cov_model",
        ),
        "fit",
    ),
    **dict.fromkeys(
        (
            "datasheet_table",
            "fit_report",
            "kalibr_imu",
            "kalibr_models",
            "project",
            "Projection",
            "read_kalibr",
            "write_kalibr",
        ),
        "formats",
    ),
    **dict.fromkeys(
        (
            "Candidate",
            "DatasheetCheck",
            "DatasheetSpec",
            "JTest",
            "ParamInterval",
            "parse_datasheet",
            "read_datasheet",
            "RunPlan",
            "SelectionResult",
            "submodels",
        ),
        "inference",
    ),
    **dict.fromkeys(
        (
            "check_time",
            "imu_topics",
            "read_imu_bag",
            "save_log",
            "still_segments",
            "TimeReport",
            "with_segments",
        ),
        "io",
    ),
    **dict.fromkeys(("ar1_wv", "PROCESS_TYPES"), "models"),
    **dict.fromkeys(
        (
            "dependence_test",
            "DependenceTest",
            "MGMWMResult",
            "moment_covariance",
            "optimal_weights",
            "SharedEstimate",
            "SharedProcess",
            "virtual_model",
            "virtual_signal",
            "VirtualSensor",
        ),
        "multivariate",
    ),
    **dict.fromkeys(
        (
            "CalibrationReport",
            "FleetReport",
            "gather_fleet",
            "gather_report",
            "render_fleet_html",
            "render_html",
        ),
        "reporting",
    ),
    **dict.fromkeys(("load_session", "save_session", "Session"), "session"),
    **dict.fromkeys(("avsm_auto", "Scenario", "SCENARIOS", "simulate_scenario"), "teaching"),
    **dict.fromkeys(
        ("BI_FACTOR", "datasheet", "from_datasheet", "param_unit", "process_values", "si_factor"),
        "units",
    ),
    **dict.fromkeys(
        (
            "biweight_constant",
            "default_levels",
            "haar_coefficients",
            "pooled_wavelet_variance",
            "robust_scale_biweight",
            "wavelet_variance_stream",
            "WaveletCrossCovariance",
            "wv_matrix",
            "WVMatrix",
        ),
        "wv",
    ),
}

__all__ = sorted(API)

# The same names for type checkers, which cannot follow __getattr__ (at run time each is
# imported on first use): tests/project/test_public_api.py checks that they match API.
if TYPE_CHECKING:  # pragma: no cover
    from . import (
        batch,
        cli,
        demo,
        errors,
        fit,
        formats,
        inference,
        io,
        models,
        multivariate,
        reporting,
        session,
        teaching,
        units,
        wv,
    )
    from .batch import fit_batch, fit_log
    from .demo import demo_path
    from .errors import ExportError, FitError, GmwmError, LoadError, ModelError
    from .fit import GMWMResult, fit_efficient, fit_gmwm
    from .formats import FORMATS, export
    from .inference import check_datasheet, j_test, param_intervals, plan_run, rank_models
    from .io import ImuLog, load_log
    from .models import MA1, Model, Process, parse_model
    from .models.processes import AR1, DR, GM, QN, RW, WN
    from .multivariate import MultiModel, fit_mgmwm, virtual_sensor
    from .reporting import fleet_report, report
    from .teaching import avsm, run_slope_study
    from .units import to_datasheet
    from .wv import WaveletVariance, wavelet_variance
    from .wv.allan import AllanVariance, allan_variance
    from .wv.wccv import wavelet_cross_covariance

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
    if module is None and name in MOVED:
        sub = MOVED[name]
        warnings.warn(
            f"engine.{name} moved to engine.{sub}.{name} (the top level keeps the names a user "
            f"calls to calibrate a log: engine.__all__)",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(importlib.import_module(f"{__name__}.{sub}"), name)
    if module is None:
        raise AttributeError(f"module 'engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(API))
