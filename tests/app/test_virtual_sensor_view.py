"""The "virtual sensor" view of the Multi-channel tab (gmwm_app/virtual_view.py), browser-free.

The numbers shown must be the engine's (``engine.virtual_sensor`` of the tab's fit); on a
simulated array of two negatively correlated, unequal gyros the view's weights are the
closed form of the model's WV matrix and beat the plain average; the export is the
single-channel export of the virtual sensor's model; bad input is a message. One Chromium
test reads the served view: the weights shown, a new criterion, a bad one, the download.
"""

from __future__ import annotations

import json
import logging
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import engine as eg
from engine.multivariate import MultiModel
from gmwm_app.virtual_view import EXPORT_FORMATS, VirtualView, parse_target

TITLE = "Multi-channel"
FS = 100.0


def open_view(app: Any) -> Any:
    v = app.open_view(TITLE)
    app.tabs.active = list(app.tabs._names).index(TITLE)
    return v


@pytest.fixture
def array_log(tmp_path: Path) -> Path:
    truth = MultiModel(
        ["imu_a", "imu_b"],
        "GM+WN",
        shared=["GM", "WN"],
        cov={
            "WN": np.diag([1e-3, 1e-3]),
            "GM": np.array([[1.0, -0.6], [-0.6, 4.0]]) * 1e-3,
        },
        nl={"GM": 2.0},
    )
    x = truth.simulate(1 << 14, fs=FS, rng=3)
    p = tmp_path / "array.h5"
    eg.io.save_log(
        p, {"imu_a": x[:, 0], "imu_b": x[:, 1]}, fs=FS, units={"imu_a": "deg/s", "imu_b": "deg/s"}
    )
    return p


def test_view_shows_the_engine_virtual_sensor_of_the_fit(app: Any, array_log: Path) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "GM+WN"
    assert app.state.load_path(array_log), app.state.error
    v.set_shared("GM", ["imu_a", "imu_b"])
    v.set_shared("WN", ["imu_a", "imu_b"])
    assert v.error == "" and v.result is not None
    vv: VirtualView = v.virtual
    vs = vv.sensor
    assert vs is not None and vv.error == ""
    direct = eg.virtual_sensor(v.result)
    np.testing.assert_allclose(vs.weights, direct.weights, rtol=1e-12)
    np.testing.assert_allclose(vs.ci_low, direct.ci_low, rtol=1e-12)
    assert np.all(np.isnan(vs.conf_low))  # not computed live
    # the table: each channel, the average and the virtual sensor
    rows = vv.weight_source.data
    assert rows["channel"] == ["imu_a", "imu_b", "plain average", "virtual sensor"]
    np.testing.assert_allclose(rows["weight"][:2], vs.weights, rtol=1e-12)
    assert rows["weight"][2:] == [0.5, 1.0] and set(rows["unit"]) == {"deg/s"}
    j = int(vs.target_levels[0])
    assert rows["adev"][3] == pytest.approx(math.sqrt(2 * vs.empirical[j]))
    # negatively correlated, unequal sensors: the optimum beats the average in the model
    assert vs.gain_vs_average < 0.85 and "x the plain average" in vv.info.object
    # the gain shown is the one out of sample, with the shrinkage of the weights
    assert f"**{vs.gain_vs_average:.3f} x the plain average's**" in vv.info.object
    assert "Out of sample" in vv.info.object and f"lambda = {vs.shrinkage:.3f}" in vv.info.object
    np.testing.assert_allclose(rows["weight_fitted"][:2], vs.fitted_weights, rtol=1e-12)
    # the figure: every sensor, the average, the virtual sensor's WV and interval
    d = vv.virtual_source.data
    np.testing.assert_allclose(d["implied"], vs.implied, rtol=1e-12)
    np.testing.assert_allclose(d["empirical"], vs.empirical, rtol=1e-12)
    assert len(vv.sensor_source.data["ys"]) == 2
    np.testing.assert_allclose(vv.average_source.data["wv"], vs.average_empirical)
    assert vv.figure.yaxis.axis_label == "WV [(deg/s)²]"


@pytest.mark.slow  # multivariate fits: 16 s of CPU
def test_scale_band_and_export(app: Any, array_log: Path) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "GM+WN"
    assert app.state.load_path(array_log), app.state.error
    v.set_shared("GM", ["imu_a", "imu_b"])
    vv = v.virtual
    vv.target_input.value = "0.64"
    vs = vv.sensor
    j = int(vs.target_levels[0])
    assert vs.tau_s[j] == pytest.approx(0.64) and vv.error == ""
    n = v.result.implied[j]
    w1 = (n[1, 1] - n[0, 1]) / (n[0, 0] + n[1, 1] - 2 * n[0, 1])
    np.testing.assert_allclose(vs.fitted_weights, [w1, 1 - w1], rtol=1e-10)
    tags = list(vv.weight_table.tags)
    vv.target_input.value = "0.1:2"
    # same rows, new weights: the table model changes so that BokehJS redraws its cells
    assert vv.weight_table.tags != tags
    assert vv.sensor.target.startswith("band levels 4..7 (0.16 to 1.28 s)")
    vv.relative.value = False
    assert vv.sensor.relative is False
    # export: the same text as the engine's single-channel export of as_fit()
    assert vv.name_input.value == "imu_a"
    vv.name_input.value = "gyro_x"
    vv.format_select.value = "json"
    assert vv.download.filename.endswith(".json")
    text = vv.export_file().read()
    ref = eg.export(None, {"gyro_x": vv.sensor.as_fit()}, "json", units={"gyro_x": "deg/s"},
                    source="virtual sensor of imu_a, imu_b")  # fmt: skip
    assert json.loads(text) == json.loads(ref)
    vv.format_select.value = "kalibr"
    assert "gyroscope_noise_density" in vv.export_file().read()
    assert "px4" not in EXPORT_FORMATS and "datasheet" in EXPORT_FORMATS
    # bad criteria are messages; the view recovers
    for text, words in (("abc", "not a number"), ("1e6", "outside"), ("5:1", "not a number")):
        vv.target_input.value = text
        assert words in vv.error and vv.alert.visible and vv.sensor is None
        assert "could not export" in vv.export_file().read()
    vv.target_input.value = ""
    assert vv.error == "" and vv.sensor is not None


@pytest.mark.slow  # multivariate fits: 9 s of CPU
def test_no_fit_clears_the_view(app: Any) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "WN+FOO"
    assert v.result is None and v.virtual.sensor is None
    assert v.virtual.weight_source.data["channel"] == []
    v.controls.spec_input.value = "WN+RW"
    assert v.virtual.sensor is not None and len(v.virtual.sensor.channels) == 3


def test_parse_target() -> None:
    assert parse_target("") == {} and parse_target(" 10 ") == {"scale": 10.0}
    assert parse_target("1:100") == {"band": (1.0, 100.0)}
    for bad in ("-1", "0", "x", "3:1", "1:inf"):
        with pytest.raises(ValueError, match="seconds"):
            parse_target(bad)


# -------------------------------------------------------------------------------------------
# a real browser
# -------------------------------------------------------------------------------------------
#: Pixel sizes of the canvases of the Bokeh plot named ``name`` and how many pixels of its
#: primary layer are drawn (not transparent, not white): the figure is on the page and painted.
CANVAS_JS = """name => {
  for (const doc of Bokeh.documents) {
    const model = doc.get_model_by_name(name);
    if (model == null) continue;
    const view = Bokeh.index.find_one(model);
    if (view == null) return null;
    const canvases = [...view.canvas_view.shadow_el.querySelectorAll("canvas")];
    const c = view.canvas_view.primary.canvas;
    const px = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    let drawn = 0;
    for (let i = 0; i < px.length; i += 4)
      if (px[i + 3] > 0 && (px[i] < 250 || px[i + 1] < 250 || px[i + 2] < 250)) drawn++;
    return {sizes: canvases.map(e => [e.width, e.height]), drawn: drawn};
  }
  return null;
}"""


def numbers(text: str) -> list[float]:
    """Every number written in an export, in order."""
    return [float(t) for t in re.findall(r"[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?", text)]


@pytest.mark.browser
@pytest.mark.browser_tour
def test_browser_view_shows_the_weights_recomputes_and_exports(
    app_demo_file: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from _browser import launch, require_chromium
    from conftest import served_app
    from test_in_browser import TIMEOUT_MS, Tab

    from gmwm_app.app import live_apps

    require_chromium()
    from playwright.sync_api import sync_playwright

    before = live_apps()  # sessions of earlier tests in this process are not ours
    with served_app(app_demo_file) as (port, _thread), sync_playwright() as pw:
        browser = launch(pw)
        try:
            # Tab: console and page errors collected in t.errors; opened once the data loads
            t = Tab(browser.new_page(viewport={"width": 1400, "height": 1100}))
            page, wait_for = t.open(f"http://127.0.0.1:{port}/").page, t.wait_for

            def table() -> dict[str, list[str]]:
                """The weights table as shown: channel -> its cells."""
                rows = {}
                for row in page.locator(".gmwm-vweights .slick-row").all():
                    cells = row.locator(".slick-cell").all_inner_texts()
                    rows[cells[0]] = cells[1:]
                return rows

            def shows(vs: eg.multivariate.VirtualSensor) -> bool:
                """The table shows the weights of ``vs`` as the view formats them (0.0000): the
                weights used, the fitted model's optimum, the data's own."""
                rows = table()
                return all(
                    rows.get(c, [""])[:3] == [f"{w:.4f}", f"{wf:.4f}", f"{wd:.4f}"]
                    for c, w, wf, wd in zip(
                        vs.channels,
                        vs.weights,
                        vs.fitted_weights,
                        vs.empirical_weights,
                        strict=True,
                    )
                )

            # the tab fits the default model of the first 3 channels (a shared RW): the view
            # shows the virtual sensor of that fit
            page.locator(".bk-tab", has_text=TITLE).first.click()
            wait_for(
                lambda: any(TITLE in a.lazy_views for a in live_apps() if a not in before),
                "the session to open the tab",
            )
            app = next(a for a in live_apps() if a not in before and TITLE in a.lazy_views)
            v = app.lazy_views[TITLE]
            assert v.wait(20) and v.error == "" and v.result is not None
            fit = v.result
            chans = list(fit.channels)
            assert len(chans) == 3 and fit.shared
            ref = eg.virtual_sensor(fit, relative=True, confidence=False)
            wait_for(lambda: shows(ref), "the weights of the fit's virtual sensor")
            assert v.virtual.error == "" and v.virtual.result is fit
            rows = table()
            assert list(rows) == [*chans, "plain average", "virtual sensor"]
            assert rows["plain average"][:2] == ["0.3333"] * 2
            assert rows["virtual sensor"][:2] == ["1.0000"] * 2
            unit = ref.unit
            assert unit and {r[4] for r in rows.values()} == {unit}
            shown = [float(rows[c][0]) for c in chans]
            assert math.fsum(ref.weights) == pytest.approx(1.0, abs=1e-12)
            assert abs(math.fsum(shown) - 1.0) <= 0.5e-4 * len(chans)  # rounded to 4 decimals
            assert page.get_by_text("x the plain average's").count() == 1
            # the WV figure: its canvases, painted
            fig = page.evaluate(CANVAS_JS, "virtual_wv")
            assert fig is not None and fig["sizes"], fig
            assert all(w > 100 and h > 100 for w, h in fig["sizes"]) and fig["drawn"] > 1000, fig

            box = page.locator(".gmwm-vtarget input")

            def criterion(text: str) -> None:
                box.fill(text)
                box.press("Enter")

            # one scale: recomputed in the worker, the page shows the new weights
            criterion("10")
            ref10 = eg.virtual_sensor(fit, relative=True, confidence=False, scale=10.0)
            # (the weights used may both be the plain average: the fitted optimum follows)
            assert [f"{w:.4f}" for w in ref10.fitted_weights] != [
                f"{w:.4f}" for w in ref.fitted_weights
            ]
            wait_for(lambda: shows(ref10), "the weights at 10 s")
            assert page.get_by_text(f"Criterion: {ref10.target}").count() == 1
            # a bad criterion: a message, an empty table, no traceback
            criterion("abc")
            alert = page.get_by_text("is not a number of seconds (10) or a band S1:S2")
            alert.first.wait_for(timeout=TIMEOUT_MS)
            wait_for(lambda: not table(), "the table to empty")
            assert v.virtual.sensor is None and "'abc'" in v.virtual.error
            assert page.get_by_text("Traceback").count() == 0
            # and no failure in the server's log: the field's callback clears the figures'
            # sources under the document lock (without it: "_pending_writes should be
            # non-None", logged by the error boundary)
            assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
            # a band: the message goes, the band's weights are shown
            criterion("1:10")
            band = eg.virtual_sensor(fit, relative=True, confidence=False, band=(1.0, 10.0))
            wait_for(lambda: shows(band), "the weights over 1 to 10 s")
            wait_for(lambda: alert.count() == 0 or not alert.first.is_visible(), "no message")
            # the download: the engine's export of the band's virtual sensor (one channel)
            name = chans[0]  # the export's channel name follows the fit's first channel
            kw = {
                "units": {name: unit},
                "source": f"virtual sensor of {', '.join(chans)}",
                "allow_partial": True,
            }
            with page.expect_download(timeout=TIMEOUT_MS) as dl:
                page.get_by_role("button", name="Download model").click()
            assert dl.value.suggested_filename == "virtual_imu.yaml"
            text = Path(dl.value.path()).read_text()
            want = eg.export(None, {name: band.as_fit()}, "kalibr", **kw)
            assert "gyroscope_noise_density" in text
            np.testing.assert_allclose(numbers(text), numbers(want), rtol=1e-12)
            # not the export of the default criterion's sensor: the file follows the criterion
            other = eg.export(None, {name: ref.as_fit()}, "kalibr", **kw)
            assert len(numbers(text)) > 5 and numbers(text) != numbers(other)
            page.get_by_label("Export format", exact=True).select_option("json")
            wait_for(lambda: v.virtual.download.filename == "virtual.json", "the json format")
            with page.expect_download(timeout=TIMEOUT_MS) as dl:
                page.get_by_role("button", name="Download model").click()
            assert dl.value.suggested_filename == "virtual.json"
            got = json.loads(Path(dl.value.path()).read_text())
            want = json.loads(eg.export(None, {name: band.as_fit()}, "json", **kw))
            assert got.keys() == want.keys()
            got_n, want_n = numbers(json.dumps(got)), numbers(json.dumps(want))
            assert len(got_n) == len(want_n) > 10
            np.testing.assert_allclose(got_n, want_n, rtol=1e-12)
            assert not [e for e in t.errors if "favicon" not in e], t.errors
        finally:
            browser.close()
