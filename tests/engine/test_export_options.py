"""The options of an export (``engine.formats.ExportOptions``): every written file is
byte-identical to the one the code before the typed options wrote (sha256 of 448 exports:
16 formats x the demo fitted WN+RW and 2*GM+WN+RW x 14 option combinations, stored by
``tests/fixtures/make_export_digests.py`` from main at c08fe9f, not by the code under test).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType

import pytest

import engine as eg
from engine.demo import demo_path

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "make_export_digests", FIXTURES / "make_export_digests.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def script() -> ModuleType:
    return _script()


@pytest.fixture(scope="module")
def stored() -> dict:
    return json.loads((FIXTURES / "export_digests.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def demo(script: ModuleType, stored: dict) -> tuple[eg.ImuLog, dict]:
    log = eg.load_log(demo_path())
    fits = {m: script.fits_of(log, m) for m in stored["models"]}
    if script.params_of(fits) != stored["params"]:  # pragma: no cover - another machine's BLAS
        pytest.skip("the demo's fits differ from the stored ones in their last bits here")
    return log, fits


def test_every_format_writes_the_bytes_of_the_code_before(script, stored, demo) -> None:
    log, fits = demo
    got = script.digests(log, fits)
    assert set(got) == set(stored["digests"])
    # gz-sim of a WN+RW fit with projection fit raised a KeyError before; now a one-line error
    fixed = {"gz-sim|WN+RW|fit-inflate": "error"}
    changed = {k: (v, got[k]) for k, v in stored["digests"].items() if fixed.get(k, v) != got[k]}
    assert not changed, f"{len(changed)} of {len(got)} exports changed: {sorted(changed)[:8]}"


def test_gz_sim_of_the_fits_own_terms_without_a_gm_is_one_line(demo) -> None:
    # a WN+RW fit has no Gauss-Markov bias to write (this was a KeyError traceback)
    log, fits = demo
    with pytest.raises(eg.GmwmError, match=r"^the gz-sim export needs T_c on every .*GM term"):
        eg.export(None, fits["WN+RW"], "gz-sim", projection="fit")
