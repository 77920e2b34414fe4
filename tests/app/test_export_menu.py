"""The export menu reads the format records (``engine.formats.Format``): the partial-file hint
only for a format that takes ``allow_partial``, and what it says of a fleet file from
``Format.fleet_file``. Without a browser, on the page's objects."""

from __future__ import annotations

from typing import Any

import yaml

from engine.formats import FORMATS


def test_a_one_sensor_export_offers_partial_only_where_the_format_takes_it(app: Any) -> None:
    s, sp = app.state, app.session_panel
    assert s.set_model("WN+RW"), s.error  # the gyroscope only
    sp.format_select.value = "openvins"
    text = sp.format_download.callback().getvalue()
    assert text.startswith("# could not export:")
    assert "needs gyroscope and accelerometer noise" in s.error
    assert "partial" in s.error and "allow_partial" not in s.error, s.error
    # Kalibr takes it: the app writes the axes fitted
    sp.format_select.value = "kalibr"
    d = yaml.safe_load(sp.format_download.callback().getvalue())
    assert d["gyroscope_noise_density"] > 0 and "accelerometer_noise_density" not in d


def test_the_menu_says_what_the_record_says_of_a_fleet_file(app: Any) -> None:
    s, sp = app.state, app.session_panel
    assert s.set_model("WN+RW"), s.error
    for name, f in FORMATS.items():
        sp.format_select.value = name
        note = sp.fits_note.object
        if not f.is_filter:
            assert "fleet" not in note, name
        elif f.fleet_file:
            assert f"--export {name} -o DIR" in note, name
        else:
            assert f"No fleet file for {name}" in note and "correlation time per unit" in note


def test_the_two_sensor_note_is_shown_only_for_formats_that_need_both(app: Any) -> None:
    # kalibr (the app asks for the axes fitted), matlab and ros-imu write a one-sensor file
    s, sp = app.state, app.session_panel
    assert s.set_model("WN+RW"), s.error
    for name, f in FORMATS.items():
        sp.format_select.value = name
        said = "needs a gyroscope and an accelerometer" in sp.fits_note.object
        assert said == f.needs_both_sensors, name
        if name in ("kalibr", "matlab", "ros-imu"):  # and the file of the gyroscope is written
            assert not said, name
            text = sp.format_download.callback().getvalue()
            assert "could not export" not in text and "gyro" in text.lower(), (name, s.error)
