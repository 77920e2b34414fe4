"""The "Datasheet check" tab: browser-free tests of the view.

The drawn numbers must be the formulas' (docs/conventions.md): white noise ``sigma2 = N^2 fs`` with
N = ARW / 60 in (deg/s)/sqrt(Hz), WV ``sigma2 / tau``, the bias-instability floor
``(0.664 B)^2 / 2``, Allan deviation ``sqrt(2 WV)``; the empirical curve is the session's WV and
the GMWM curve the Fit tab's fit.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np
import pytest
import test_in_browser

import engine as eg

BI_FACTOR = math.sqrt(2 * math.log(2) / math.pi)

# the browser fixtures: conftest's served app and chromium, test_in_browser's new page
new_tab = test_in_browser.new_tab


@pytest.fixture
def view(app: Any) -> Any:
    return app.open_view("Datasheet check")


def _hand_wv(tau_samples: np.ndarray, fs: float, arw: float, bi_deg_h: float) -> np.ndarray:
    n = arw / 60.0  # (deg/s)/sqrt(Hz)
    return n * n * fs / tau_samples + (BI_FACTOR * bi_deg_h / 3600.0) ** 2 / 2


def test_draws_the_datasheet_model_over_the_channels_wv(app: Any, view: Any) -> None:
    s = app.state
    assert view.kind == "gyroscope" and s.unit == "deg/s"
    assert [w.label for w in view.inputs] == [
        "ARW [deg/sqrt(h)]",
        "BI [deg/h]",
        "RRW [deg/h/sqrt(h)]",
        "Q [deg]",
    ]
    view.set_values({"arw": "0.4", "bi": "12", "rrw": "", "q": ""})
    d = view.wv_src.data
    tau = np.asarray(s.wv.tau_samples, float)
    np.testing.assert_allclose(d["tau_s"], s.wv.tau_s)
    np.testing.assert_allclose(d["emp"], s.wv.variance)
    np.testing.assert_allclose(d["lo"], s.wv.ci_low)
    np.testing.assert_allclose(d["ds"], _hand_wv(tau, s.fs, 0.4, 12.0), rtol=1e-10)
    a = view.adev_src.data
    np.testing.assert_allclose(a["tau_s"], s.wv.tau_s / 2)
    np.testing.assert_allclose(a["ds"], np.sqrt(2 * _hand_wv(tau, s.fs, 0.4, 12.0)), rtol=1e-10)
    np.testing.assert_allclose(a["emp"], np.sqrt(2 * s.wv.variance))
    # verdicts and their colours follow the interval
    for ds, lo, hi, v, c in zip(d["ds"], d["lo"], d["hi"], d["verdict"], d["color"], strict=True):
        assert v == ("below" if ds < lo else "above" if ds > hi else "inside")
        assert c == {"inside": "#2CA02C", "above": "#FF7F0E", "below": "#D62728"}[v]
    assert view.table_src.data["verdict"] == list(d["verdict"])
    assert "ARW 0.4 deg/sqrt(h)" in view.status.object and "of 17 scales" in view.status.object
    assert view.wv_figure.yaxis[0].axis_label == "wavelet variance [(deg/s)^2]"
    assert view.adev_figure.yaxis[0].axis_label == "Allan deviation [deg/s]"


def test_the_fit_tabs_gmwm_is_drawn_beside(app: Any, view: Any) -> None:
    fig, src = view.wv_figure, view.wv_src
    assert np.all(np.isnan(src.data["fit"]))  # no fit yet: nothing drawn, a hint shown
    assert view.message.visible and "Fit tab" in view.message.object
    tags = list(view.table.tags)
    assert app.state.set_model("GM+WN+RW"), app.state.error
    assert view.table.tags != tags  # same row count: the table is told to redraw its cells
    np.testing.assert_allclose(view.wv_src.data["fit"], app.state.result.implied)
    np.testing.assert_allclose(view.adev_src.data["fit"], np.sqrt(2 * app.state.result.implied))
    lo, hi = view.result.ci_low, view.result.ci_high
    want = [
        "below" if f < a else "above" if f > b else "inside"
        for f, a, b in zip(app.state.result.implied, lo, hi, strict=True)
    ]
    assert view.table_src.data["GMWM"] == want
    assert not view.message.visible
    assert view.wv_figure is fig and view.wv_src is src  # built once, data replaced in place


@pytest.mark.parametrize(
    "values, msg",
    [
        ({"arw": "abc"}, "not a number"),
        ({"arw": "-1"}, "non-negative"),
        ({"arw": "", "bi": "", "rrw": "", "q": ""}, "no value"),
    ],
)
def test_bad_values_give_a_message(view: Any, values: dict, msg: str) -> None:
    view.set_values(values)
    assert view.message.visible and msg in view.message.object
    assert view.result is None and list(view.wv_src.data["ds"]) == []


def test_fields_follow_the_sensor_kind(app: Any, view: Any) -> None:
    assert app.state.select_channel("accel_x"), app.state.error
    assert view.kind == "accelerometer"
    assert [w.label for w in view.inputs][:2] == ["VRW [m/s/sqrt(h)]", "BI [mg]"]
    view.set_values({"vrw": "0.06", "bi": "0.2", "accrw": "", "q": ""})
    tau = np.asarray(app.state.wv.tau_samples, float)
    n = 0.06 / 60  # (m/s^2)/sqrt(Hz)
    floor = (BI_FACTOR * 0.2e-3 * 9.80665) ** 2 / 2
    np.testing.assert_allclose(
        view.wv_src.data["ds"], n * n * app.state.fs / tau + floor, rtol=1e-10
    )
    view.set_values({"arw": "0.3"})
    assert view.message.visible and "no field 'arw'" in view.message.object


def test_upload_kalibr_file_fills_the_fields(app: Any, view: Any) -> None:
    fs = app.state.fs
    n, k = 2e-4, 3e-5  # rad/s/sqrt(Hz), rad/s^2/sqrt(Hz)
    text = f"update_rate: {fs}\ngyroscope_noise_density: {n}\ngyroscope_random_walk: {k}\n"
    view.load_file(text.encode(), "imu.yaml")
    d2r = math.pi / 180
    assert float(view.inputs[0].value) == pytest.approx(n / d2r * 60, rel=1e-3)  # ARW
    assert float(view.inputs[2].value) == pytest.approx(k / d2r * 216000, rel=1e-3)  # RRW
    assert view.inputs[1].value == ""  # no bias instability in a Kalibr file
    tau = np.asarray(app.state.wv.tau_samples, float)
    sigma2, gamma2 = (n / d2r) ** 2 * fs, (k / d2r) ** 2 / fs  # (deg/s)^2, per sample
    want = sigma2 / tau + gamma2 * (tau**2 + 2) / (12 * tau)
    np.testing.assert_allclose(view.wv_src.data["ds"], want, rtol=1e-9)
    view.load_file(b"update_rate: 100.0\ngyroscope_noise_density: abc\n", "bad.yaml")
    assert view.message.visible and "bad.yaml" in view.message.object
    assert "gyroscope_noise_density" in view.message.object
    view.load_file(b"update_rate: 100.0\naccelerometer_noise_density: 1.0e-3\n", "acc.yaml")
    assert view.message.visible and "no gyroscope_* keys" in view.message.object


def test_unknown_unit_says_so(app: Any, view: Any) -> None:
    app.state.unit = ""  # the view depends on the unit itself (no catch-all counter)
    assert view.kind == "" and view.message.visible and "unit" in view.message.object
    assert all(w.disabled for w in view.inputs)


def test_engine_check_is_the_views(app: Any, view: Any) -> None:
    view.set_values({"arw": "0.3", "bi": "10", "rrw": "2", "q": ""})
    chk = eg.check_datasheet(app.state.wv, "arw=0.3 deg/sqrt(h), bi=10 deg/h, rrw=2 deg/h/sqrt(h)")
    np.testing.assert_allclose(view.wv_src.data["ds"], chk.datasheet_wv, rtol=1e-12)
    assert tuple(view.wv_src.data["verdict"]) == chk.verdict


# ---------------------------------------------------------------------------------------------
@pytest.mark.browser
@pytest.mark.browser_tour
def test_browser_typed_value_redraws_the_check(
    server: str, new_tab: Any, caplog: pytest.LogCaptureFixture
) -> None:
    from test_in_browser import TIMEOUT_MS, _app_for

    t = new_tab().open(f"{server}?model=GM%2BWN%2BRW")
    page = t.page
    page.locator(".bk-tab", has_text="Datasheet check").first.click()
    box = page.locator(".gmwm-check-0 input").first
    box.wait_for(timeout=TIMEOUT_MS)
    box.fill("0.9")
    box.press("Enter")
    t.wait_for(
        lambda: _app_for(lambda a: a.served and "Datasheet check" in a.lazy_views) is not None,
        "the tab built in the session",
    )
    view = _app_for(lambda a: a.served and "Datasheet check" in a.lazy_views).lazy_views[
        "Datasheet check"
    ]
    t.wait_for(
        lambda: (
            view.result is not None and "ARW 0.9 deg/sqrt(h)" in view.result.datasheet.describe()
        ),
        "the typed ARW in the session's check",
    )
    # ARW 0.9: the white-noise WV is 9x a 0.3 datasheet's; the page shows the verdicts
    t.wait_for(lambda: "above" in t.table_text(".gmwm-check-table"), "the verdicts")
    assert "inside" in t.table_text(".gmwm-check-table")  # the GMWM column
    assert page.get_by_text("ARW 0.9 deg/sqrt(h)").first.is_visible()
    assert t.errors == [], t.errors
    # a value that is not a number: the message in the page, not the previous check, and no
    # failure in the server's log (it was "_pending_writes should be non-None")
    box.fill("abc")
    box.press("Enter")
    t.wait_for(
        lambda: view.result is None and view.message.object == "ARW: 'abc' is not a number",
        "the message in the session",
    )
    page.get_by_text("ARW: 'abc' is not a number").first.wait_for(timeout=TIMEOUT_MS)
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
    assert t.errors == [], t.errors


def test_the_datasheet_values_are_typed_parameters_checked_once_per_change(
    app: Any, view: Any, datasheet_checks: list[Any]
) -> None:
    checks = datasheet_checks
    s = app.state
    # the values as a parameter: set alone, they are checked (once) and the fields show them
    view.texts = ["0.4", "12", "", ""]
    assert len(checks) == 1 and [w.value for w in view.inputs] == ["0.4", "12", "", ""]
    tau = np.asarray(s.wv.tau_samples, float)
    np.testing.assert_allclose(view.wv_src.data["ds"], _hand_wv(tau, s.fs, 0.4, 12.0), rtol=1e-10)
    view.texts = ["0.4", "12", "", ""]  # the same values: nothing to check
    assert len(checks) == 1
    with pytest.raises(TypeError):  # typed: a list of the fields' texts
        view.texts = [0.4, 12.0, None, None]
    assert view.texts == ["0.4", "12", "", ""] and len(checks) == 1
    # a datasheet set as the file's spec: its exact values are checked, once
    spec = eg.inference.DatasheetSpec.from_values({"arw": (0.25, "deg/sqrt(h)")}, source="test")
    view.file_spec = spec
    assert len(checks) == 2 and checks[-1] is spec and view.result.datasheet is spec
    # a change of the data the tab does not read (a message of the page): no check
    s.report_error("something else")
    assert len(checks) == 2
