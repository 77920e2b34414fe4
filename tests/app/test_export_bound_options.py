"""The export menu's bound options: the data bound (the empirical WV's lower limit,
estimate, upper limit or nothing) and the horizon, the engine's ``data=`` and ``horizon_s=``,
reach the preview and the downloaded file; the widgets are built when the menu's toggle is
first opened, not with the page; a bad horizon is a note, not a traceback. Tested without a
browser on the page's objects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

import engine as eg
from engine.formats import DATA_BOUNDS, project
from gmwm_app.export_bound import DATA_CHOICES


def _fit_two(app) -> tuple:
    s = app.state
    s.set_model("GM+WN+RW")
    gyro = s.result
    s.select_channel("accel_x")
    s.set_model("GM+WN+RW")
    return gyro, s.result


def test_choices_are_the_engines() -> None:
    assert sorted(DATA_CHOICES.values()) == sorted(DATA_BOUNDS)


def test_bound_options_are_built_on_opening_and_reach_preview_and_file(app_demo: Path) -> None:
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    b = sp.bound
    # not built with the page: the menu's toggle only; the engine's defaults meanwhile
    assert not b.toggle.value and not b.built and b.box.objects == []
    assert b.options == {}
    gyro, accel = _fit_two(app)
    units = s.log.units
    sp.format_select.value = "kalibr"
    sp.preview.toggle.value = True
    b.toggle.value = True
    assert b.built and b.data_select.value == "low" and b.horizon_input.value is None
    assert b.options == {"data": "low"}
    # the default: the file is the engine's default export
    d = yaml.safe_load(sp.format_download.callback().getvalue())
    want = project(gyro, "kalibr", channel="gyro_x", unit=units["gyro_x"])
    assert d["gyroscope_noise_density"] == want.value("N")
    # the fitted model only, over a 60 s horizon: preview and file follow, and differ
    b.data_select.value = "none"
    b.horizon_input.value = 60.0
    assert b.options == {"data": "none", "horizon_s": 60.0}
    for ch, fit in (("gyro_x", gyro), ("accel_x", accel)):
        w = project(fit, "kalibr", channel=ch, unit=units[ch], data="none", horizon_s=60.0)
        got = sp.preview.projections[ch]
        assert got.data == "none" and got.horizon_s == 60.0 and got.band[1] <= 60.0
        assert got.value("N") == w.value("N") and got.value("K") == w.value("K")
    text = sp.format_download.callback().getvalue()
    d = yaml.safe_load(text)
    w = project(gyro, "kalibr", channel="gyro_x", unit=units["gyro_x"], data="none", horizon_s=60)
    assert d["gyroscope_noise_density"] == w.value("N")
    assert "horizon 60 s" in text and "empirical WV's lower" not in text
    # the file is the CLI's / API's for the same options
    ref = eg.export(
        None,
        {"gyro_x": gyro, "accel_x": accel},
        "kalibr",
        units=units,
        allow_partial=True,
        data="none",
        horizon_s=60.0,
    )
    assert yaml.safe_load(ref) == d
    # the upper limit bounds more than the lower one: larger (or equal) N and K on every axis
    b.data_select.value = "high"
    hi = {ch: p.value("N") for ch, p in sp.preview.projections.items()}
    b.data_select.value = "low"
    lo = {ch: p.value("N") for ch, p in sp.preview.projections.items()}
    assert all(hi[ch] >= lo[ch] for ch in hi) and any(hi[ch] > lo[ch] for ch in hi)
    # closing the options goes back to the engine's defaults
    b.toggle.value = False
    assert b.options == {} and not b.box.visible
    assert sp.preview.projections["gyro_x"].value("N") == want.value("N")


def test_bad_horizon_is_a_note_and_the_session_goes_on(app_demo: Path) -> None:
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    _fit_two(app)
    sp.bound.toggle.value = True
    sp.bound.horizon_input.value = 0.0
    assert "Not exported" in sp.fits_note.object and "horizon" in sp.fits_note.object
    assert sp.format_download.disabled
    sp.bound.horizon_input.value = 120.0
    assert "Not exported" not in sp.fits_note.object and not sp.format_download.disabled
    s.set_model("WN+RW")  # the session keeps working
    assert s.error == "" and s.result is not None


def test_misfit_line_is_shown_next_to_the_file(app_demo: Path) -> None:
    """A model that misses the data (white noise alone on the demo's gyro_x, whose truth has
    two GM terms and a random walk): the export menu says so beside the download, the line
    the engine writes (engine.formats.misfit)."""
    from engine.formats import misfit
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    s.set_model("WN")
    line = misfit(s.result, "gyro_x")
    wv = s.result.wv
    mw = s.result.model.wv(np.asarray(wv.tau_samples, float), s.result.fs)
    out = np.sum((mw < wv.ci_low) | (mw > wv.ci_high))
    assert out > len(mw) / 3 and line  # the premise, counted here
    assert f"**Warning:** {line}" in sp.fits_note.object
    s.set_model("2*GM+WN+RW")  # the truth's form: no line
    assert misfit(s.result, "gyro_x") == ""
    assert "model and data disagree" not in sp.fits_note.object


def test_the_app_file_covers_heavy_tails_as_gmwm_export_does(app_demo: Path) -> None:
    """A log whose errors are heavier-tailed than a Gaussian's (Student t, 3 degrees of
    freedom, plus a random walk): the app's filter file is ``gmwm export``'s (the data bound
    times the log's tail factors, ``tails=True``), larger than the data bound alone; the
    options' checkbox gives ``--no-tails``'s file, and the preview follows both. Before, the
    app exported without the log, so its file was the data bound alone whatever the tails."""
    from engine.formats import log_tail_factors
    from engine.io import ImuLog
    from gmwm_app.app import create_app
    from gmwm_app.data import LoadedData

    rng = np.random.default_rng(7)
    n, fs = 2**17, 100.0
    rw = np.cumsum(rng.standard_normal(n)) * 1e-3
    chans = {
        "gyro_x": rng.standard_t(3, n) * 0.01 + rw,
        "accel_x": rng.standard_t(3, n) * 0.02 + rw,
    }
    log = ImuLog(channels=chans, fs=fs, units={"gyro_x": "rad/s", "accel_x": "m/s^2"})
    app = create_app().gmwm_app
    s, sp, b = app.state, app.session_panel, app.session_panel.bound
    assert s.install(LoadedData(log, "upload", "tails.h5")), s.error
    gyro, accel = _fit_two(app)
    fits = {"gyro_x": gyro, "accel_x": accel}
    tf = log_tail_factors(log, fits)
    assert tf["gyro_x"].largest()[0] > 1.2  # heavy tails: the factor raises the data bound
    sp.format_select.value = "kalibr"
    sp.preview.toggle.value = True
    b.toggle.value = True
    kw = {"units": log.units, "allow_partial": True, "log": log}
    with_tails = yaml.safe_load(eg.export(None, fits, "kalibr", **kw))
    without = yaml.safe_load(eg.export(None, fits, "kalibr", tails=False, **kw))
    key = "gyroscope_noise_density"
    assert with_tails[key] > without[key] * 1.05
    d = yaml.safe_load(sp.format_download.callback().getvalue())
    assert d == with_tails
    assert sp.preview.projections["gyro_x"].value("N") == with_tails[key]
    b.tails_check.value = False
    assert b.options == {"data": "low", "tails": False}
    assert yaml.safe_load(sp.format_download.callback().getvalue()) == without
    assert sp.preview.projections["gyro_x"].value("N") == without[key]


def test_the_menu_asks_only_the_options_of_the_format(app_demo: Path) -> None:
    # read from the format records (engine.formats.Format.options): a report has no inflate
    # factor, the datasheet no filter rate or projection, every filter format all three
    from gmwm_app.app import create_app

    sp = create_app().gmwm_app.session_panel
    shown = {}
    for fmt in ("datasheet", "json", "openvins", "px4"):
        sp.format_select.value = fmt
        shown[fmt] = (
            sp.inflate_input.visible,
            sp.rate_input.visible,
            sp.projection_select.visible,
            sp.rate_input.placeholder if sp.rate_input.visible else "",
        )
    assert shown == {
        "datasheet": (False, False, False, ""),
        "json": (False, True, True, "the log's rate"),
        "openvins": (True, True, True, "the log's rate"),
        "px4": (True, True, True, "required"),
    }


def test_a_report_downloads_with_the_inflate_of_a_filter_format_left(app_demo: Path) -> None:
    # the inflate factor typed for a filter format is not sent to a report (which refuses it)
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp = app.session_panel
    _fit_two(app)
    sp.format_select.value = "openvins"
    sp.inflate_input.value = 2.0
    sp.format_select.value = "datasheet"
    text = sp.format_download.callback().getvalue()
    assert not text.startswith("# could not export") and "gyro_x" in text
    assert not app.state.error
