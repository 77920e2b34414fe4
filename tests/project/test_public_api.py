"""engine's API is an explicit list and stays lazy; the structure of engine/ and gmwm_app/ has
no import cycle, no back-edge between layers, no private import across modules
(tests/structure_check.py)."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
import types
from pathlib import Path

import pytest

import engine as eg

ROOT = Path(__file__).resolve().parents[2]


#: The top level (engine/__init__.py's API): what a user calls to calibrate a log. Adding or
#: removing a name is a deliberate act that changes this list.
API = """
    __version__ GmwmError LoadError ModelError FitError ExportError
    Process Model parse_model WN QN RW DR AR1 GM MA1
    WaveletVariance wavelet_variance AllanVariance allan_variance wavelet_cross_covariance
    fit_gmwm fit_efficient GMWMResult param_intervals j_test rank_models check_datasheet plan_run
    MultiModel fit_mgmwm virtual_sensor load_log ImuLog export FORMATS report fleet_report
    fit_batch fit_log to_datasheet avsm run_slope_study demo_path
""".split()

#: The names the top level had until version 0.1, now public in a subpackage (engine.MOVED).
BEFORE = """
    AR1 AllanVariance BI_FACTOR BatchResult CalibrationReport Candidate DR DatasheetCheck
    DatasheetError DatasheetSpec DependenceTest ExportError FORMATS FitError FitResult
    FleetReport GM GMWFMResult GmwmError GMWMResult ImuLog JTest LoadError LogFit MGMWMResult
    MethodEstimate Model ModelError MultiModel PROCESS_TYPES ParamInterval ParamRecord
    ParamTable Process Projection QN RW ReplicateResult ReportError SCENARIOS Scenario
    SelectionResult Session SessionError SharedEstimate SharedProcess Summary TimeReport
    VirtualSensor WN WVMatrix WaveletCrossCovariance WaveletVariance __version__ allan_variance
    ar1_wv avsm avsm_auto biweight_constant check_datasheet check_time compare_table datasheet
    datasheet_table default_levels demo_dir demo_path demo_truth dependence_test export
    fit_armav fit_batch fit_efficient fit_gmwfm fit_gmwm fit_log fit_mgmwm fit_replicates
    fit_report fleet_report from_datasheet from_gmwm gather_fleet gather_report gmwm_objective
    haar_coefficients imu_topics j_test kalibr_imu kalibr_models load_log load_session
    moment_covariance optimal_weights param_intervals param_unit parse_datasheet parse_model
    process_values project rank_models read_datasheet read_imu_bag read_kalibr render_fleet_html
    plan_run RunPlan
    render_html report robust_scale_biweight run_slope_study save_log save_session si_factor
    simulate_scenario starting_values submodels to_datasheet virtual_model virtual_sensor
    virtual_signal wavelet_cross_covariance wavelet_variance wavelet_variance_stream
    weight_matrix write_kalibr wv_cov wv_cov_bootstrap wv_cov_data wv_cov_model wv_matrix
    pooled_wavelet_variance still_segments with_segments
""".split()


def test_the_api_is_the_written_list():
    assert sorted(eg.__all__) == sorted(API) == sorted(eg.API)
    assert len(API) == len(set(API))  # each name once


def test_every_public_name_resolves_to_the_one_module_that_holds_it():
    for name, module in eg.API.items():
        obj = getattr(importlib.import_module(module), name)
        assert getattr(eg, name) is obj, name
        # the module named is where the object is defined (or the package re-exporting it)
        home = getattr(obj, "__module__", None)
        if home is not None and isinstance(obj, type | types.FunctionType):
            assert home == module or home.startswith(module + "."), (name, home, module)


def test_type_checkers_see_every_name_of_the_api_from_its_module():
    # mypy cannot follow the lazy __getattr__ (PEP 562): engine/__init__.py imports each name
    # of API under TYPE_CHECKING, from the module API gives (else eg.X is Any to the app)
    tree = ast.parse((ROOT / "engine" / "__init__.py").read_text(encoding="utf-8"))
    seen: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom) and imp.level == 1, ast.unparse(imp)
                if imp.module is None:  # the subpackages: eg.fit, eg.wv ... typed as modules
                    assert sorted(a.name for a in imp.names) == sorted(eg.SUBMODULES)
                    continue
                for alias in imp.names:
                    assert alias.name not in seen, alias.name
                    seen[alias.name] = f"engine.{imp.module}"
    assert seen == {n: m for n, m in eg.API.items() if n != "__version__"}


def test_engine_export_and_report_are_functions_not_modules():
    assert (
        isinstance(eg.export, types.FunctionType)
        and eg.export.__module__ == "engine.formats.registry"
    )
    assert isinstance(eg.report, types.FunctionType) and eg.report.__module__ == "engine.reporting"
    assert isinstance(eg.fleet_report, types.FunctionType)
    # the subpackages have other names and stay ordinary modules
    import engine.formats
    import engine.reporting

    assert type(engine.formats) is types.ModuleType and type(engine.reporting) is types.ModuleType
    assert eg.export is engine.formats.export


def test_subpackages_are_reachable_but_not_in_the_api():
    assert eg.units.datasheet_rows is importlib.import_module("engine.units").datasheet_rows
    assert not set(eg.SUBMODULES) & set(eg.__all__)
    with pytest.raises(AttributeError, match="no attribute 'parallel_map'"):
        eg.parallel_map  # noqa: B018 - a helper, not in the API


def test_the_names_users_had_are_still_public_in_their_subpackage():
    # every name of the old top level is at the top level or in the __all__ of the subpackage
    # engine.MOVED names; eg.<name> still finds it, with a warning that says where it went
    assert set(BEFORE) == set(API) - {"MA1"} | set(eg.MOVED) and not set(API) & set(eg.MOVED)
    for name, sub in eg.MOVED.items():
        module = importlib.import_module(f"engine.{sub}")
        assert name in module.__all__, (name, sub)
        with pytest.warns(DeprecationWarning, match=rf"engine\.{name} moved to engine\.{sub}\."):
            assert getattr(eg, name) is getattr(module, name) is getattr(getattr(eg, sub), name)


def test_import_engine_stays_light():
    code = (
        "import sys, engine as eg; eg.fit_gmwm; eg.WN; eg.wavelet_variance;"
        "print('scipy' in sys.modules, 'h5py' in sys.modules, 'engine.multivariate' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout.split()
    assert out == ["False", "False", "False"]


def test_structure_has_no_cycle_and_no_private_import():
    spec = importlib.util.spec_from_file_location(
        "structure_check", ROOT / "tests" / "structure_check.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cycles, private = mod.analyse()
    assert (cycles, private) == ([], [])


def _structure_check():
    spec = importlib.util.spec_from_file_location(
        "structure_check", ROOT / "tests" / "structure_check.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_packages_run_one_way_through_the_layers():
    # every import, inside functions and under TYPE_CHECKING too (an older tree had
    # fit.gmwm -> inference.asymptotic and io.session -> fit/inference: 3 findings)
    assert _structure_check().layer_violations() == []


def test_a_back_edge_between_packages_is_a_finding():
    sc = _structure_check()
    graph = {
        "engine.fit.gmwm": {"engine.inference.asymptotic", "engine.wv.classical", "engine._optim"},
        "engine.inference.asymptotic": {"engine.fit.result"},
        "engine.wv.classical": {"engine._blas"},
        "engine._optim": {"engine._limits"},
        "engine.fit.result": set(),
        "engine._blas": set(),
        "engine._limits": set(),
        "engine.formats.kalibr": {"engine.multivariate.fit"},  # same layer: a finding too
        "engine.multivariate.fit": set(),
        "engine.newpkg.mod": set(),
    }
    found = sc.layer_violations(graph)
    assert len(found) == 3, found
    assert found[0].startswith("engine.newpkg: not in LAYERS")
    assert any(f.startswith("engine.fit.gmwm imports engine.inference.asymptotic") for f in found)
    assert any(f.startswith("engine.formats.kalibr imports engine.multivariate.fit") for f in found)
