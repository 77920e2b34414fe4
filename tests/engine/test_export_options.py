"""The options of an export (``engine.formats.ExportOptions``): every written file is
byte-identical to the one the code before the typed options wrote (sha256 of 448 exports:
16 formats x the demo fitted WN+RW and 2*GM+WN+RW x 14 option combinations, stored by
``tests/fixtures/make_export_digests.py`` from main at c08fe9f, not by the code under test).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import warnings
from pathlib import Path
from types import ModuleType

import pytest

import engine as eg
from engine.demo import demo_path
from engine.formats import FORMATS, ExportOptions
from engine.formats.options import CONTEXT

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


# ------------------------------------------------------------------ the options, checked once
BAD = [
    ("filter_rate", 0.0, "a positive number (Hz)"),
    ("filter_rate", "abc", "a positive number (Hz)"),
    ("horizon_s", -5.0, "a positive number (s)"),
    ("scale_factor_std_ppm", float("nan"), "a positive number (ppm)"),
    ("band", (5.0, 1.0), "two WV scales"),
    ("band", 5.0, "two WV scales"),
    ("confidence", 1.5, "a level in (0, 1)"),
    ("ci", "bootstrap", "'asymptotic' or None"),
    ("vehicle_id", 0, "a MAVLink system id 1..255"),
    ("vehicle_id", True, "a MAVLink system id 1..255"),
    ("data", "mid", "one of low, estimate, high, none"),
    ("projection", "bounded", "one of bound, plain, fit"),
    ("tails", "yes", "True or False"),
    ("inflate", 0.0, None),
]


@pytest.mark.parametrize(("name", "value", "must"), BAD)
def test_a_bad_option_is_one_line_naming_it(demo, name, value, must) -> None:
    # every format, the reports too: the options are checked once, before any writer
    _, fits = demo
    for fmt in ("openvins", "datasheet"):
        with pytest.raises(eg.GmwmError) as e:
            eg.export(None, fits["WN+RW"], fmt, **{name: value})
        msg = str(e.value)
        assert msg.startswith(f"{name} must be ") and "\n" not in msg, msg
        assert must is None or must in msg, msg
        assert repr(value) in msg


def test_an_unknown_option_is_one_line(demo) -> None:
    _, fits = demo
    with pytest.raises(eg.GmwmError, match=r"^unknown export option\(s\) filter_rat: the"):
        eg.export(None, fits["WN+RW"], "kalibr", filter_rat=100.0)


def test_an_option_the_format_does_not_read_is_named_in_one_warning(demo) -> None:
    log, fits = demo
    plain = eg.export(None, fits["WN+RW"], "datasheet", log=log)
    with pytest.warns(UserWarning) as caught:
        text = eg.export(None, fits["WN+RW"], "datasheet", log=log, filter_rate=200.0, vehicle_id=3)
    assert text == plain  # ignored, as before
    said = [str(w.message) for w in caught]
    assert said == ["the datasheet export does not use filter_rate=200.0, vehicle_id=3: ignored"]


def test_defaults_and_the_context_are_never_warned_about(demo, recwarn) -> None:
    log, fits = demo
    eg.export(
        None,
        fits["WN+RW"],
        "csv",
        log=log,
        units={"gyro_x": "deg/s"},
        source="x.h5",
        filter_rate=None,
        inflate=1,
        projection="bound",
        data="low",
        tails=True,
        ci="asymptotic",
        vehicle_id=1,
    )
    assert not [w for w in recwarn if "does not use" in str(w.message)]


def test_an_integer_inflate_writes_what_its_float_writes(demo) -> None:
    _, fits = demo
    a = eg.export(None, fits["WN+RW"], "kalibr", projection="fit", inflate=2)
    assert a == eg.export(None, fits["WN+RW"], "kalibr", projection="fit", inflate=2.0)
    assert "inflate = 2.0:" in a


def test_the_cli_words_the_warning_in_its_flags(tmp_path, capsys) -> None:
    from engine.cli import main

    out = tmp_path / "d.txt"
    argv = ["export", str(demo_path()), "--model", "WN+RW", "--format", "datasheet"]
    assert main([*argv, "-o", str(out), "--horizon", "60", "--no-tails"]) == 0
    err = capsys.readouterr().err
    assert "warning: the datasheet export does not use --horizon 60.0, --no-tails: ignored" in err
    assert err.count("does not use") == 1


# ------------------------------------------------------- each record names what its writer reads
_SEEN: set[str] = set()
_ON = [True]


@dataclasses.dataclass(frozen=True)
class _Recording(ExportOptions):
    """Options that note every field a writer reads (not while they are built or copied)."""

    def __post_init__(self) -> None:
        _ON[0] = False
        try:
            super().__post_init__()
        finally:
            _ON[0] = True

    def __getattribute__(self, name: str):  # type: ignore[no-untyped-def]
        if _ON[0] and not name.startswith("_") and name in _FIELDS:
            _SEEN.add(name)
        return object.__getattribute__(self, name)


_FIELDS = {f.name for f in dataclasses.fields(ExportOptions)}


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_each_writer_reads_the_options_its_record_names(demo, fmt, monkeypatch) -> None:
    log, fits = demo
    f = FORMATS[fmt]
    real_replace = dataclasses.replace

    def quiet_replace(obj, **changes):  # type: ignore[no-untyped-def]
        _ON[0] = False
        try:
            return real_replace(obj, **changes)
        finally:
            _ON[0] = True

    monkeypatch.setattr(dataclasses, "replace", quiet_replace)
    o = _Recording(log=log, source="demo", filter_rate=200.0 if f.needs_filter_rate else None)
    _SEEN.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f.writer(fits["2*GM+WN+RW"], o)
    # the writer reads the tail factors engine.export made of ``tails``
    read = {"tails" if n == "tail_factors" else n for n in _SEEN} - set(CONTEXT)
    assert read == set(f.options), (fmt, sorted(read ^ set(f.options)))


@pytest.mark.slow  # about 30 s of CPU: two models fitted on 6 channels of 1e6 samples, 448 files
def test_every_format_writes_the_bytes_of_the_code_before_on_a_real_log(script, real_data) -> None:
    # the same 448 exports from the real ADIS16405 unit 1 log (stored from main at c08fe9f)
    stored = json.loads((FIXTURES / "export_digests_adis_imu1.json").read_text(encoding="utf-8"))
    log = eg.load_log(real_data / stored["log"])
    fits = {m: script.fits_of(log, m) for m in stored["models"]}
    if script.params_of(fits) != stored["params"]:  # pragma: no cover - another machine's BLAS
        pytest.skip("the fits differ from the stored ones in their last bits here")
    got = script.digests(log, fits)
    fixed = {"gz-sim|WN+RW|fit-inflate": "error"}  # a KeyError before (see the demo's test)
    changed = sorted(k for k, v in stored["digests"].items() if fixed.get(k, v) != got[k])
    assert set(got) == set(stored["digests"]) and not changed, changed[:8]
