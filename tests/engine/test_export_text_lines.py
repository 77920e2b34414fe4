"""User-given text in exports: a file name, channel name or topic with a
newline (or any control character) must not add a line to an export file: no PX4 parameter,
no Kalibr key. Every registered format is written with hostile names and compared with the
same export under clean names: same number of lines, no line starting with the injected text,
and the file parses (PyYAML, json, csv, XML) with exactly the keys of the clean file."""

from __future__ import annotations

import csv
import io
import json
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

import engine as eg
from engine.demo import demo_path
from engine.formats import FORMATS, export
from engine.formats.common import clean_text, yaml_str

# what a hostile name tries to add: a PX4 parameter, an ArduPilot one, YAML keys
INJECTED = ("EKF2_GYR_NOISE 9.9", "EK3_GYRO_P_NSE,99.9", "key:", "key2:", "k3:", "<evil")
SOURCES = (
    "run\nEKF2_GYR_NOISE 9.9\n.h5",
    "run\r\nkey: 1",
    "a\u2028key2: 2\x85k3: 3\x0bEK3_GYRO_P_NSE,99.9\x0c<evil/>\t.csv",
)
TOPIC = "/imu0\nkey: 1"


@pytest.fixture(scope="module")
def clean_fits() -> dict[str, eg.GMWMResult]:
    """The demo's six channels, GM+WN+RW (every format accepts them)."""
    log = eg.load_log(demo_path())
    return {
        c: eg.fit_gmwm(eg.wavelet_variance(log[c], fs=log.fs, unit=log.units[c]), "GM+WN+RW")
        for c in log.names
    }


def _hostile(name: str, i: int) -> str:
    """A channel name with an injection before it (its axis letter stays last)."""
    return f"{SOURCES[i % len(SOURCES)]}\n{name}"


def _export(fits: dict, fmt: str, source: str, rostopic: str) -> str:
    opts = {"filter_rate": 100.0} if fmt in ("px4", "ardupilot") else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # range warnings are tested elsewhere
        return export(None, fits, fmt, source=source, rostopic=rostopic, **opts)


def _keys(obj: object) -> object:
    """The key structure of parsed data (dict keys, recursively; lists by their first item)."""
    if isinstance(obj, dict):
        return {k: _keys(v) for k, v in obj.items()}
    if isinstance(obj, list) and obj:
        return [_keys(obj[0])]
    return None


def _yaml(text: str) -> dict:
    if text.startswith("%YAML:1.0\n"):  # OpenCV's directive, which PyYAML does not read
        text = text.split("\n", 1)[1]
    return yaml.safe_load(text)


def test_clean_text_escapes_every_line_break_and_control() -> None:
    s = "a\nb\rc\td\x00e\x1bf\x7fg\x85h\u2028i\u2029j\\n k"
    assert clean_text(s) == "a\\nb\\rc\\td\\x00e\\x1bf\\x7fg\\x85h\\u2028i\\u2029j\\n k"
    assert clean_text(s).splitlines() == [clean_text(s)]  # one line, whatever splits lines
    assert clean_text(Path("/tmp/x.h5")) == "/tmp/x.h5" and clean_text("µ°/s ±") == "µ°/s ±"
    assert yaml_str("/imu0") == "/imu0" and yaml.safe_load(f"k: {yaml_str(TOPIC)}") == {"k": TOPIC}
    assert yaml.safe_load(f"k: {yaml_str('yes')}") == {"k": "yes"}


#: Formats whose export of the six demo channels costs 13-53 s of CPU per test today (a GM bias
#: bounded per channel): the slow tier until exports take their fraction of a second.
SLOW_EXPORTS = ("gazebo", "gz-sim", "kf-gins")


@pytest.mark.parametrize(
    "fmt", [pytest.param(f, marks=pytest.mark.slow) if f in SLOW_EXPORTS else f for f in FORMATS]
)
def test_hostile_names_add_no_line_and_no_key(clean_fits, fmt: str) -> None:
    ref = _export(clean_fits, fmt, "run.h5", "/imu0")
    names = {c: _hostile(c, i) for i, c in enumerate(clean_fits)}
    fits = {names[c]: r for c, r in clean_fits.items()}
    for source in SOURCES:
        text = _export(fits, fmt, source, TOPIC)
        lines = text.splitlines()  # splits at \r, \x0b, \x85, \u2028 ... too
        assert len(lines) == len(ref.splitlines()), (fmt, source)
        for line in lines:
            body = line.lstrip()
            assert not body.startswith(INJECTED), (fmt, line)
        suffix = FORMATS[fmt].suffix
        if suffix == ".yaml":
            got, want = _yaml(text), _yaml(ref)
            assert _keys(got) == _keys(want), fmt
            topic = got.get("rostopic", got.get("imu0", {}).get("rostopic"))
            if topic is not None:  # Kalibr, OpenVINS: the topic read back exactly as given
                assert topic == TOPIC
        elif suffix == ".json":
            got, want = json.loads(text), json.loads(ref)
            assert set(got) == set(want), fmt
            if "channels" in got:  # the JSON report keeps names as given (safe by encoding)
                assert list(got["channels"]) == list(fits) and got["source"] == source
                assert _keys(got["channels"][names["gyro_x"]]) == _keys(want["channels"]["gyro_x"])
            else:
                assert _keys(got) == _keys(want), fmt
        elif suffix in (".params", ".param", ".m"):  # every line but comments is the same
            comment = "%" if suffix == ".m" else "#"
            data = [ln for ln in lines if not ln.startswith(comment)]
            assert data == [ln for ln in ref.splitlines() if not ln.startswith(comment)]
        elif suffix in (".xml", ".sdf"):  # Gazebo plugin element, gz-sim SDF <imu> element
            got = ET.fromstring(f"<r>{text}</r>")
            want = ET.fromstring(f"<r>{ref}</r>")
            assert [e.tag for e in got.iter()] == [e.tag for e in want.iter()]
        elif suffix == ".csv":
            got_rows = list(csv.reader(io.StringIO(text)))
            want_rows = list(csv.reader(io.StringIO(ref)))
            assert [len(r) for r in got_rows] == [len(r) for r in want_rows]
            chans = {r[0] for r in got_rows[1:]}
            assert chans == {clean_text(n) for n in fits}, fmt  # escaped, one cell each
        else:  # the readable datasheet: a table, checked by its line count above
            assert suffix == ".txt", fmt


def test_source_may_be_a_path(clean_fits, tmp_path) -> None:
    src = tmp_path / "unit 7.h5"
    d = json.loads(export(None, clean_fits, "json", source=src))  # was a TypeError
    assert d["source"] == str(src)
    assert f"source: {src};" in export(None, clean_fits, "kalibr", source=src)
    out = tmp_path / "r.json"
    export(out, clean_fits, "json", source=src)
    assert json.loads(out.read_text())["source"] == str(src)
