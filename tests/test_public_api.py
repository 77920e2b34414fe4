"""engine's public surface is built from its subpackages' ``__all__`` (issue 11), stays lazy,
and the structure of engine/ and gmwm_app/ has no import cycle, no private import across
modules and no module over 800 lines (tests/structure_check.py)."""

from __future__ import annotations

import importlib
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import engine as eg

ROOT = Path(__file__).resolve().parents[1]


def test_every_public_name_comes_from_one_subpackage_and_resolves():
    expected: dict[str, set[str]] = defaultdict(set)
    for pkg in eg.SUBPACKAGES:
        for name in importlib.import_module(f"engine.{pkg}").__all__:
            expected[name].add(pkg)
    assert set(eg.__all__) == set(expected)
    for name, pkgs in expected.items():
        objs = [getattr(importlib.import_module(f"engine.{p}"), name) for p in sorted(pkgs)]
        # a name two subpackages export is one object (re-exported), never two meanings
        assert all(o is objs[0] for o in objs), (name, pkgs)
        got = getattr(eg, name)
        assert got is objs[0], name


def test_the_names_users_had_are_still_there():
    # the names engine exported before the redesign (README, app, scripts rely on them)
    before = """AR1 DR GM QN RW WN Process Model ModelError parse_model WaveletVariance
    wavelet_variance default_levels haar_coefficients biweight_constant robust_scale_biweight
    ar1_wv fit_gmwm GMWMResult ParamRecord FitError FitResult ParamTable Summary weight_matrix
    datasheet param_unit ImuLog LoadError load_log save_log AllanVariance allan_variance
    MethodEstimate from_gmwm avsm avsm_auto fit_gmwfm fit_armav compare_table run_slope_study
    ExportError datasheet_table export fit_report kalibr_imu kalibr_models read_kalibr
    write_kalibr Session SessionError load_session save_session wavelet_variance_stream
    TimeReport check_time WaveletCrossCovariance WVMatrix wavelet_cross_covariance wv_matrix
    MultiModel SharedProcess fit_mgmwm MGMWMResult SharedEstimate moment_covariance
    dependence_test DependenceTest fit_replicates ReplicateResult Scenario SCENARIOS
    simulate_scenario fit_efficient param_intervals ParamInterval j_test JTest wv_cov_model
    wv_cov_data wv_cov_bootstrap rank_models submodels SelectionResult Candidate""".split()
    assert not [n for n in before if n not in eg.__all__]


def test_import_engine_stays_light():
    code = (
        "import sys, engine as eg; eg.fit_gmwm; eg.WN; eg.wavelet_variance;"
        "print('scipy' in sys.modules, 'h5py' in sys.modules, 'engine.multivariate' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout.split()
    assert out == ["False", "False", "False"]


def test_structure_has_no_cycle_no_private_import_no_big_module():
    spec = importlib.util.spec_from_file_location(
        "structure_check", ROOT / "tests" / "structure_check.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cycles, private, big = mod.analyse()
    assert (cycles, private, big) == ([], [], [])


def _structure_check():
    spec = importlib.util.spec_from_file_location(
        "structure_check", ROOT / "tests" / "structure_check.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_packages_run_one_way_through_the_layers():
    # every import, inside functions and under TYPE_CHECKING too (issue 20: the old tree had
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
