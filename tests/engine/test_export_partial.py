"""A filter file of one sensor (a partial file).

Most filter formats need a gyroscope and an accelerometer and refuse the fits of one sensor;
the message offers ``allow_partial`` (``--partial``) only for a format whose record takes it
(:meth:`engine.formats.Format.takes`): to the others the option does nothing. A format whose
record says it writes a partial file (:attr:`engine.formats.Format.partial`: matlab, ros-imu)
writes the sensor fitted without being asked, and its writer reads that from the record.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import engine as eg
from engine.errors import ExportError
from engine.formats import FORMATS

FS = 100.0
FILTERS = [n for n, f in FORMATS.items() if f.is_filter]


@pytest.fixture(scope="module")
def gyro_only() -> dict[str, eg.fit.GMWMResult]:
    m = eg.parse_model("WN(1e-6) + RW(1e-12)")
    x = m.simulate(2**14, rng=np.random.default_rng(3))
    return {"gyro_x": eg.fit_gmwm(eg.wavelet_variance(x, fs=FS, unit="rad/s"), "WN + RW")}


def _refusal(fits: dict, fmt: str, projection: str) -> str | None:
    """The message of ``fmt``'s refusal of a one-sensor file, or None (written, or refused for
    another reason)."""
    kw = {"filter_rate": FS} if FORMATS[fmt].needs_filter_rate else {}
    try:
        eg.export(None, fits, fmt, ci=None, projection=projection, **kw)
    except ExportError as e:
        return str(e) if "gyroscope and accelerometer" in str(e) else None
    return None


@pytest.mark.parametrize("projection", ["bound", "fit"])
def test_the_partial_hint_is_given_only_where_the_format_takes_it(gyro_only, projection) -> None:
    refused = {}
    for fmt in FILTERS:
        msg = _refusal(gyro_only, fmt, projection)
        if msg is None:
            continue
        refused[fmt] = msg
        assert "only gyroscope (gyro_x)" in msg and "Add the other channels" in msg
        if FORMATS[fmt].takes("allow_partial"):
            assert "allow a partial file (allow_partial=True)" in msg, fmt
        else:
            assert "allow_partial" not in msg, (fmt, msg)
            assert f"the {fmt} format takes no partial file" in msg
    assert {"kalibr", "openvins", "px4", "gazebo"} <= set(refused), projection
    # and where it is offered, taking it writes the file
    assert eg.export(None, gyro_only, "kalibr", ci=None, allow_partial=True, projection=projection)


def _written(fits: dict, fmt: str) -> bool:
    kw = {"filter_rate": FS} if FORMATS[fmt].needs_filter_rate else {}
    try:
        eg.export(None, fits, fmt, ci=None, **kw)
    except ExportError as e:
        assert "gyroscope and accelerometer" in str(e) or "needs T_c" in str(e), (fmt, e)
        return False
    return True


def test_a_one_sensor_file_is_written_exactly_by_the_formats_whose_record_says_partial(
    gyro_only,
) -> None:
    written = {fmt for fmt in FILTERS if _written(gyro_only, fmt)}
    assert written == {n for n, f in FORMATS.items() if f.partial} == {"matlab", "ros-imu"}
    assert not any(FORMATS[n].needs_both_sensors for n in written)


@pytest.mark.parametrize("fmt", ["matlab", "ros-imu"])
def test_the_writer_reads_partial_from_the_record(gyro_only, monkeypatch, fmt) -> None:
    # the record is the owner: declared not partial, the same writer refuses one sensor
    monkeypatch.setitem(FORMATS, fmt, dataclasses.replace(FORMATS[fmt], partial=False))
    with pytest.raises(ExportError, match="needs gyroscope and accelerometer noise"):
        eg.export(None, gyro_only, fmt, ci=None)
    assert FORMATS[fmt].needs_both_sensors
