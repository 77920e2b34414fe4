"""The export formats as records (``engine.formats.catalog``): each carries its consumer
model and capabilities, and names its writer, which is imported only when a file is written.

* reading the formats (``FORMATS``, ``FORMAT_CONSUMERS``, ``gmwm export --help``) imports no
  writer module;
* each record's writer and reader resolve to the functions that write and read it;
* the consumer index and the CLI's help are read from the records.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import engine.formats as fm
from engine.cli import build_parser
from engine.formats import vio
from engine.formats.catalog import CONSUMER_PARAMS, FORMAT_CONSUMERS, FORMATS, VALUE_KINDS

REPO = Path(__file__).resolve().parents[2]
#: The modules that hold writers (and what they import: projection, bound, tails, reports).
WRITER_MODULES = (
    "engine.formats.registry",
    "engine.formats.vio",
    "engine.formats.autopilot",
    "engine.formats.sim",
    "engine.formats.ins",
    "engine.formats.kalibr",
    "engine.formats.projection",
    "engine.formats.report",
    "engine.reporting",
)


def _loaded_after(code: str) -> list[str]:
    probe = f"{code}\nimport sys\nprint(' '.join(m for m in sys.modules if m.startswith('engine')))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO
    ).stdout
    loaded = set(out.split())
    return [m for m in WRITER_MODULES if m in loaded]


def test_reading_the_formats_imports_no_writer():
    code = (
        "from engine.formats import FORMATS, FORMAT_CONSUMERS\n"
        "assert [f.name for f in FORMATS.values() if f.needs_filter_rate] == ['px4', 'ardupilot']\n"
        "assert FORMAT_CONSUMERS['gazebo'] == 'WN+GM'"
    )
    assert _loaded_after(code) == []
    help_code = (
        "from engine.cli import main\n"
        "try:\n    main(['export', '--help'])\nexcept SystemExit:\n    pass"
    )
    assert _loaded_after(help_code) == []


def test_writing_imports_the_writer():
    code = (
        "import numpy as np, engine as eg\n"
        "m = eg.parse_model('WN(1e-6) + RW(1e-12)')\n"
        "wv = eg.wavelet_variance(m.simulate(2**12, rng=1), fs=100.0, unit='rad/s')\n"
        "fit = eg.fit_gmwm(wv, 'WN+RW')\n"
        "eg.export(None, {'gyro_x': fit}, 'ros-imu')"
    )
    loaded = _loaded_after(code)
    assert "engine.formats.ins" in loaded and "engine.formats.registry" in loaded
    assert "engine.formats.vio" not in loaded  # the other writers stay unread


def test_each_record_names_its_writer_and_reader():
    assert fm.FORMATS is FORMATS  # one registry, reached from the package too
    for f in FORMATS.values():
        assert callable(f.writer), f.name
        assert f.suffix.startswith(".")
        assert f.values is None or f.values in VALUE_KINDS
        assert f.is_filter == (f.consumer is not None) == (f.values is not None)
    assert FORMATS["openvins"].writer is vio.openvins_yaml
    assert FORMATS["kalibr"].reader is fm.read_kalibr
    assert [k for k, f in FORMATS.items() if f.reader is not None] == ["kalibr"]


def test_consumer_index_is_read_from_the_records():
    want = {k: f.consumer for k, f in FORMATS.items() if f.consumer is not None}
    assert FORMAT_CONSUMERS == want
    assert set(want.values()) <= set(CONSUMER_PARAMS)
    # the projection reads the same index, without the writers being imported first
    code = (
        "from engine.formats.projection import consumer_of\n"
        "assert consumer_of('px4') == 'WN+RW' and consumer_of('kf-gins') == 'WN+GM'\n"
        "assert consumer_of('ros-imu') == 'WN'"
    )
    assert "engine.formats.registry" not in _loaded_after(code)


def test_export_help_reads_the_records():
    sub = next(a for a in build_parser(["export"])._actions if a.dest == "command")
    assert isinstance(sub.choices, dict)
    ex = sub.choices["export"]
    fmt = next(a for a in ex._actions if a.dest == "format")
    assert list(fmt.choices) == list(FORMATS)
    assert all(f"{f.name}: {f.description}" in fmt.help for f in FORMATS.values())
    rate = next(a for a in ex._actions if a.dest == "filter_rate")
    needs = [k for k, f in FORMATS.items() if f.needs_filter_rate]
    assert rate.help.startswith("/".join(needs) + ":") and needs == ["px4", "ardupilot"]


def test_export_help_lists_the_options_each_record_names():
    # gmwm export --help's epilog: per format, the flags of the options its writer reads
    import re

    from engine.cli.common import ARGUMENT_FLAGS
    from engine.formats.catalog import FILTER_OPTIONS

    sub = next(a for a in build_parser(["export"])._actions if a.dest == "command")
    assert isinstance(sub.choices, dict)
    text = " ".join(sub.choices["export"].format_help().split())
    text = text[text.index("options by format") :]
    flags = {k: ARGUMENT_FLAGS[k] for k in FILTER_OPTIONS if k != "fleet"}
    assert f"the filter formats: {' '.join(flags.values())}" in text
    for f in FORMATS.values():
        m = re.search(rf"(?<![\w-]){re.escape(f.name)}: ([^:]*?)(?= [\w-]+: | an option)", text)
        assert m, f.name
        said = m.group(1)
        own = [ARGUMENT_FLAGS[o] for o in f.options if o not in FILTER_OPTIONS]
        if f.is_filter:
            assert set(f.options) >= set(FILTER_OPTIONS), f.name
            assert said.startswith("the filter options"), (f.name, said)
        else:
            own = [ARGUMENT_FLAGS[o] for o in f.options]
        assert re.findall(r"--[\w-]+", said.split(";")[0].replace("the filter options", "")) == (
            own
        ), (f.name, said)
        assert ("--filter-rate required" in said) == f.needs_filter_rate, f.name
        assert ("a fleet file with gmwm batch --export" in said) == f.fleet_file, f.name
        # the sensors a file needs: the record's partial / needs_both_sensors
        assert ("needs a gyroscope and an accelerometer" in said) == f.needs_both_sensors
        assert ("one sensor is enough (a partial file)" in said) == f.partial, f.name
    assert "px4: the filter options and --vehicle-id; --filter-rate required" in text
    assert "csv: none" in text


def test_the_partial_help_names_the_formats_from_their_records():
    sub = next(a for a in build_parser(["export"])._actions if a.dest == "command")
    assert isinstance(sub.choices, dict)
    partial = next(a for a in sub.choices["export"]._actions if a.dest == "partial")
    # kalibr takes --partial; matlab and ros-imu write a one-sensor file without it
    assert [k for k, f in FORMATS.items() if f.partial] == ["matlab", "ros-imu"]
    assert partial.help == (
        "kalibr: allow a file with only gyroscope or only accelerometer values "
        "(matlab, ros-imu write one without it; the other filter formats need both)"
    )
    both = {k for k, f in FORMATS.items() if f.needs_both_sensors}
    assert both == {k for k, f in FORMATS.items() if f.is_filter} - {"kalibr", "matlab", "ros-imu"}
