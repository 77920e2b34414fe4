"""The engine's errors: one base class (``engine.errors.GmwmError``, a ValueError) under every
error class, each class defined once and importable where users import it, and the front ends
(the ``gmwm`` command, the app's state) showing any of them as one line."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import engine as eg
from engine import errors
from engine.cli import main

ROOT = Path(__file__).resolve().parents[2]

#: Where users import each error (engine.__all__, the subpackages, docs and tests): the same
#: class as engine.errors'.
IMPORT_PATHS = {
    "LoadError": ("engine", "engine.io", "engine.io.log"),
    "ModelError": ("engine", "engine.models", "engine.models.model"),
    "FitError": ("engine", "engine.fit", "engine.fit.result"),
    "ExportError": ("engine", "engine.units", "engine.formats"),
    "DatasheetError": (
        "engine.errors",
        "engine.inference",
        "engine.inference.datasheet_check",
        "engine.inference.datasheet_keys",
        "engine.inference.datasheet_spec",
    ),
    "SessionError": ("engine.errors", "engine.session"),
    "ReportError": ("engine.errors", "engine.reporting", "engine.reporting.render"),
    "CliError": ("engine.cli.common",),
    "UsageError": ("engine.cli.common",),
}


def test_every_error_class_derives_from_the_one_base():
    assert issubclass(errors.GmwmError, ValueError)  # `except ValueError` callers keep working
    assert eg.GmwmError is errors.GmwmError and "GmwmError" in eg.__all__
    public = [getattr(eg, n) for n in eg.__all__]
    top_errors = [c for c in public if isinstance(c, type) and issubclass(c, Exception)]
    # the errors of the top level are engine.errors' own; every one of those derives from the base
    all_errors = [getattr(errors, n) for n in errors.__all__]
    assert errors.GmwmError in top_errors and set(top_errors) <= set(all_errors)
    for cls in all_errors:
        assert issubclass(cls, errors.GmwmError), cls
        assert cls.__module__ == "engine.errors", cls
    assert issubclass(errors.DatasheetError, errors.ExportError)
    assert issubclass(errors.UsageError, errors.CliError)
    assert sorted(errors.__all__) == sorted([*IMPORT_PATHS, "GmwmError"])


@pytest.mark.parametrize("name", sorted(IMPORT_PATHS))
def test_each_error_is_importable_where_users_import_it(name):
    for module in IMPORT_PATHS[name]:
        assert getattr(importlib.import_module(module), name) is getattr(errors, name), module


def test_no_error_class_is_defined_outside_engine_errors():
    # a public exception class anywhere else in engine/ would be a second home (private
    # control-flow exceptions such as engine.wv.robust's _OutOfRegion are not errors users see)
    found = []
    for path in sorted((ROOT / "engine").rglob("*.py")):
        if path.name == "errors.py" and path.parent.name == "engine":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                bases = [ast.unparse(b) for b in node.bases]
                if any(b.endswith(("Error", "Exception")) for b in bases):
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert found == []


def test_the_app_raises_the_engines_errors():
    # the app's command line refuses with the gmwm command's UsageError, not a second class
    # of the same name outside the common base
    import gmwm_app.__main__ as app_main

    assert app_main.UsageError is errors.UsageError
    found = []
    for path in sorted((ROOT / "gmwm_app").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and node.name.lstrip("_").endswith("Error"):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert found == []


def test_the_cli_prints_an_engine_error_as_one_line_with_status_2(capsys):
    with pytest.raises(errors.GmwmError) as caught:
        eg.parse_model("WN+BOGUS")
    assert type(caught.value) is errors.ModelError
    code = main(["fit", str(eg.demo_path()), "--model", "WN+BOGUS"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err == f"gmwm: error: {caught.value}\n"


def test_the_cli_run_as_a_module_catches_its_own_errors_through_the_base():
    # `python -m engine.cli`: main.py's CliError used to be a second class under __main__; the
    # class now lives in engine.errors, one class however the command is started
    r = subprocess.run(
        [sys.executable, "-m", "engine.cli", "select", str(eg.demo_path())],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == "gmwm: error: give --max-model SPEC or --models 'SPEC1,SPEC2,...'\n"


def test_the_app_state_shows_an_engine_error_as_its_message(app_state, tmp_path):
    s = app_state
    with pytest.raises(errors.GmwmError) as caught:
        eg.parse_model("WN+BOGUS")
    before = s.model
    assert s.set_model("WN+BOGUS") is False
    assert s.error == f"Could not set the model: {caught.value}"
    assert s.model is before  # the session keeps working on what it had

    bad = tmp_path / "bad.csv"
    bad.write_text("gyro_x\n0.1\nabc\n0.3\n")
    with pytest.raises(errors.GmwmError) as loading:
        eg.load_log(bad)
    assert type(loading.value) is errors.LoadError
    assert s.load_path(bad) is False
    assert str(loading.value) in s.error and "\n" not in s.error
    assert s.channel == "gyro_x" and s.wv is not None  # the demo is still shown
