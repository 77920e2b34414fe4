"""The ``Examples`` sections of the main public functions run as doctests.

:data:`REQUIRED` lists the functions that must have one, so that an example cannot silently
disappear; every example in the modules that hold them is run (deterministic: seeded
simulations, rounded output).
"""

from __future__ import annotations

import doctest
import importlib
import inspect

import pytest

import engine as eg

#: (module, qualified name) of every function required to carry an ``Examples`` section
REQUIRED = [
    ("engine.io.load", "load_log"),
    ("engine.wv.classical", "wavelet_variance"),
    ("engine.wv.allan", "allan_variance"),
    ("engine.models.model", "parse_model"),
    ("engine.models.model", "Model.simulate"),
    ("engine.fit.gmwm", "fit_gmwm"),
    ("engine.fit.gmwm", "fit_efficient"),
    ("engine.inference.intervals", "param_intervals"),
    ("engine.inference.jtest", "j_test"),
    ("engine.inference.selection", "rank_models"),
    ("engine.inference.datasheet_check", "check_datasheet"),
    ("engine.multivariate.fit", "fit_mgmwm"),
    ("engine.multivariate.virtual", "virtual_sensor"),
    ("engine.formats.registry", "export"),
    ("engine.formats.projection", "project"),
    ("engine.reporting", "report"),
    ("engine.batch", "fit_batch"),
    # every latent process, in the module that defines it (engine.models.PROCESS_TYPES)
    *[(cls.__module__, code) for code, cls in eg.models.PROCESS_TYPES.items()],
]

MODULES = sorted({m for m, _ in REQUIRED})
FLAGS = doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS


def _resolve(module: str, qualname: str) -> object:
    obj: object = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


@pytest.mark.parametrize(("module", "qualname"), REQUIRED, ids=[q for _, q in REQUIRED])
def test_required_examples_present(module: str, qualname: str) -> None:
    doc = inspect.getdoc(_resolve(module, qualname)) or ""
    assert "Examples\n--------" in doc and ">>> " in doc, (
        f"{module}.{qualname} has no numpydoc Examples section with a doctest"
    )


def test_required_are_public() -> None:
    """The top-level names the examples call are the public API's."""
    for name in ("load_log", "wavelet_variance", "allan_variance", "parse_model", "fit_gmwm"):
        assert hasattr(eg, name), name


def test_every_process_type_required() -> None:
    """A new process type needs its own example: the list above names every one, each
    resolved in the module that defines it."""
    listed = {q for m, q in REQUIRED if q in eg.models.PROCESS_TYPES}
    assert listed == set(eg.models.PROCESS_TYPES), sorted(set(eg.models.PROCESS_TYPES) ^ listed)
    for m, q in REQUIRED:
        if q in eg.models.PROCESS_TYPES:
            assert _resolve(m, q) is eg.models.PROCESS_TYPES[q]


def test_required_examples_run_not_skipped() -> None:
    """A required example really runs: at least one of its lines is not ``+SKIP``."""
    for module, qualname in REQUIRED:
        doc = inspect.getdoc(_resolve(module, qualname)) or ""
        runs = [
            line
            for line in doc.splitlines()
            if line.lstrip().startswith(">>> ") and "doctest: +SKIP" not in line
        ]
        assert runs, f"{module}.{qualname}: every example line is skipped"


@pytest.mark.parametrize("module", MODULES)
def test_examples_run(module: str) -> None:
    mod = importlib.import_module(module)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    tests = [t for t in finder.find(mod, module) if t.examples]
    assert tests, f"{module} has no doctest"
    for t in tests:
        runner.run(t)
    res = runner.summarize(verbose=False)
    assert res.failed == 0, f"{res.failed} of {res.attempted} examples failed in {module}"
