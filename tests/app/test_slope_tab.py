"""The "Slope method" tab: browser-free tests of the view and its helpers, and one browser test.

The tab's numbers must be the engine's and the formulas': the Allan deviation is the overlapping
ADEV of the raw channel (computed here independently with ``engine.wv.allan.allan_variance``), the
slope readings are the IEEE formulas applied to it, the implied curves are the analytic Allan
variance shapes, and on a teaching scenario the GMWM column is near the truth while the slope
method is off the way the scenario says.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import engine as eg
from engine.io import ImuLog
from engine.teaching import SCENARIOS, avsm
from engine.units import BI_FACTOR
from engine.wv.allan import allan_variance
from gmwm_app.data import LoadedData
from gmwm_app.slope_data import (
    SlopeResult,
    comparison_values,
    compute_slope,
    implied_adev_curves,
    slope_line_data,
    truth_model,
)
from gmwm_app.state import AppState, format_value


@pytest.fixture
def view(app: Any) -> Any:
    return app.open_view("Slope method")


def _raw(app: Any) -> np.ndarray:
    return np.asarray(app.state.log.channels[app.state.channel], float)


def _row(view: Any, process: str, quantity: str) -> dict[str, str]:
    d = view.table_src.data
    for i in range(len(d["process"])):
        if d["process"][i] == process and d["quantity"][i] == quantity:
            return {k: d[k][i] for k in d}
    raise AssertionError(f"no row {process} {quantity} in {d['process']} {d['quantity']}")


def _n_from_line(av: Any, lo: float, hi: float) -> float:
    """IEEE reading of N: the -1/2 line fitted by least squares in log-log, valued at 1 s."""
    sel = (av.tau_s >= lo) & (av.tau_s <= hi)
    x, y = np.log10(av.tau_s[sel]), np.log10(av.adev[sel])
    return 10.0 ** float(np.mean(y + 0.5 * x))  # intercept of a slope -1/2 line = log10 N


# ---------------------------------------------------------------------------------------------
def test_allan_deviation_is_the_channels_and_follows_the_channel(app: Any, view: Any) -> None:
    ref = allan_variance(_raw(app), fs=app.state.fs)  # from the raw samples, independently
    d = view.adev_src.data
    np.testing.assert_allclose(d["tau_s"], ref.tau_s, rtol=1e-12)
    np.testing.assert_allclose(d["adev"], ref.adev, rtol=1e-9)
    np.testing.assert_allclose(d["lo"], ref.adev_low, rtol=1e-9)
    np.testing.assert_allclose(d["hi"], ref.adev_high, rtol=1e-9)
    unit = app.state.unit
    assert view.figure.yaxis[0].axis_label == f"Allan deviation [{unit}]"
    other = [c for c in app.state.channels if c != app.state.channel][-1]
    assert app.state.select_channel(other), app.state.error
    ref2 = allan_variance(_raw(app), fs=app.state.fs)
    np.testing.assert_allclose(view.adev_src.data["adev"], ref2.adev, rtol=1e-9)
    assert other in view.figure.title.text


def test_regions_give_the_ieee_readings_and_gmwm_of_the_same_processes(app: Any, view: Any) -> None:
    view.clear_regions()
    assert view.message.visible and "drag" in view.message.object
    view.set_region("WN", 0.01, 1.0)
    view.set_region("BI", 5.0, 0.5)  # given backwards: still the interval 0.5-5 s
    assert view.regions["BI"] == (0.5, 5.0)
    res = view.result
    assert not res.messages, res.messages
    av = allan_variance(_raw(app), fs=app.state.fs)
    n = _n_from_line(av, 0.01, 1.0)
    sel = (av.tau_s >= 0.5) & (av.tau_s <= 5.0)
    b = 10.0 ** float(np.mean(np.log10(av.adev[sel]))) / BI_FACTOR  # floor / 0.664
    # engine AVSM on the raw series agrees with these formulas and with the view
    direct = avsm(av, {"WN": (0.01, 1.0), "BI": (0.5, 5.0)})
    assert direct.params["WN.sigma2"] == pytest.approx(n**2 * app.state.fs, rel=1e-9)
    assert res.estimates["AVSM"].params["WN.sigma2"] == pytest.approx(n**2 * app.state.fs, rel=1e-9)
    assert res.estimates["AVSM"].extras["BI.B"] == pytest.approx(b, rel=1e-9)
    assert _row(view, "WN", "white noise density")["AVSM"] == format_value(n)
    assert _row(view, "BI", "bias instability")["AVSM"] == format_value(b)
    unit = app.state.unit
    assert _row(view, "WN", "white noise density")["unit"] == f"{unit}/sqrt(Hz)"
    # GMWM fitted the same processes, the floor as a GM
    assert res.gmwm_spec == "GM+WN"
    g = eg.fit_gmwm(app.state.wv, "GM+WN")
    assert res.estimates["GMWM"].params["WN.sigma2"] == pytest.approx(
        g.params["WN.sigma2"], rel=1e-6
    )
    assert _row(view, "WN", "white noise density")["GMWM"] == format_value(
        math.sqrt(g.params["WN.sigma2"] / app.state.fs)
    )
    # the slope line passes through its reading point (N at 1 s)
    lines = view.lines_src.data
    i = lines["code"].index("WN")
    assert lines["read_tau"][i] == 1.0 and lines["read_adev"][i] == pytest.approx(n, rel=1e-9)
    assert view.boxes["WN"].visible and view.boxes["WN"].left == 0.01
    assert not view.boxes["RW"].visible


def test_demo_truth_is_shown_when_the_demo_is_the_bundled_one(
    app: Any, view: Any, app_demo: Path
) -> None:
    p = app_demo
    truth_file = p.with_name(f"{p.stem}_truth.json")
    if not truth_file.exists():
        assert truth_model(app.state) is None
        assert not any(view.table_src.data["truth"])
        return
    spec = json.loads(truth_file.read_text())["models"][app.state.channel]
    m = eg.parse_model(spec)
    assert truth_model(app.state).values() == m.values()
    wn = m.values()["WN.sigma2"]
    assert _row(view, "WN", "white noise density")["truth"] == format_value(
        math.sqrt(wn / app.state.fs)
    )


def test_scenario_loads_into_the_session_with_its_regions_and_truth(app: Any, view: Any) -> None:
    sc = SCENARIOS["qn_wn"]
    view.scenario_select.value = "qn_wn"  # as the menu does
    s = app.state
    assert s.source == "scenario" and s.error == "", s.error
    assert s.n == sc.n and s.fs == sc.fs and s.unit == sc.unit
    assert s.model.spec() == "QN+WN" and s.result is not None  # the Fit tab fits it too
    assert view.regions == sc.region_dict
    assert view.explain.visible and sc.why in view.explain.object
    assert s.to_query()["scenario"] == "qn_wn"
    # truth column: the analytic datasheet values
    n_true, q_true = math.sqrt(1e-3 / sc.fs), math.sqrt(4e-4) / sc.fs
    assert _row(view, "WN", "white noise density")["truth"] == format_value(n_true)
    assert _row(view, "QN", "quantization")["truth"] == format_value(q_true)
    est = view.result.estimates
    # GMWM near the truth (its Monte Carlo SD is about 2% on sigma2, 3% on q2: 5 SD bands)
    assert est["GMWM"].params["WN.sigma2"] == pytest.approx(1e-3, rel=0.10)
    assert est["GMWM"].params["QN.q2"] == pytest.approx(4e-4, rel=0.15)
    # the slope method reads white noise as quantization (about 2.2x in q2, see test_teaching)
    assert est["AVSM"].params["QN.q2"] > 1.6 * 4e-4
    assert est["AVSM"].params["WN.sigma2"] > 1.08 * 1e-3
    # the implied truth curve is the analytic ADEV: 3 Q^2 / T^2 + N^2 / T
    c = view.curve_srcs["truth"].data
    t = np.asarray(c["tau_s"])
    np.testing.assert_allclose(c["adev"], np.sqrt(3 * q_true**2 / t**2 + n_true**2 / t), rtol=1e-9)
    # loading other data hides the explanation and resets the menu
    assert s.load_demo(), s.error
    assert not view.explain.visible and view.scenario_select.value == ""


def test_bad_regions_are_messages_and_the_session_keeps_working(app: Any, view: Any) -> None:
    view.clear_regions()
    view.set_region("WN", 1e5, 1e6)  # beyond the log
    assert "holds no averaging time" in view.message.object
    view.set_region("RW", 1.0, 1.5)  # one octave point only
    assert "at least 2 points" in view.message.object
    view.set_region("XX", 1.0, 2.0)
    assert "unknown process" in view.message.object
    assert "AVSM" not in view.result.estimates and not any(view.table_src.data["AVSM"])
    assert app.state.error == ""
    view.set_region("WN", 0.01, 1.0)
    view.set_region("RW", 10.0, 100.0)
    assert not view.message.visible, view.message.object
    assert view.result.estimates["AVSM"].params["WN.sigma2"] > 0
    # a set GMWM cannot identify on a very short log: a message, the AVSM column stays
    x = np.random.default_rng(1).normal(size=40)
    lg = ImuLog(channels={"g": x}, fs=1.0, units={"g": "deg/s"})
    assert app.state.install(LoadedData(lg, "upload", "tiny.csv")), app.state.error
    view.clear_regions()
    for code in ("QN", "WN", "BI", "RW", "DR"):
        view.set_region(code, 1.0, 16.0)
    assert any("GMWM could not fit GM+QN+WN+RW+DR" in m for m in view.result.messages)
    assert "AVSM" in view.result.estimates and "GMWM" not in view.result.estimates
    assert view.message.visible and app.state.error == ""


def test_a_stale_result_does_not_overwrite_a_newer_one(app: Any, view: Any) -> None:
    view.set_region("WN", 0.01, 1.0)
    stale = SlopeResult(None, messages=["stale"])

    def slow() -> SlopeResult:
        view.set_region("WN", 0.02, 1.0)  # a newer computation starts (and ends) meanwhile
        return stale

    view.jobs.run(slow, view.draw, key="slope")
    shown = view.result
    assert shown is not stale and shown.regions["WN"][0] == pytest.approx(0.02)
    assert "stale" not in view.message.object and not view.computing


def test_hidden_tab_waits_and_robust_wv_still_shows_the_allan_deviation(
    app: Any, view: Any
) -> None:
    shown = view.result
    view._visible = lambda: False  # as when another tab is open in the browser
    other = [c for c in app.state.channels if c != app.state.channel][0]
    assert app.state.select_channel(other), app.state.error
    assert view.result is shown and view._dirty  # nothing computed while hidden
    view._visible = lambda: True
    view._on_tab()  # the tab is opened
    assert view.result is not shown and not view._dirty
    ref = allan_variance(_raw(app), fs=app.state.fs)
    np.testing.assert_allclose(view.adev_src.data["adev"], ref.adev, rtol=1e-9)
    # the robust WV is not an Allan variance: the tab keeps the classical one
    assert app.state.set_robust(True), app.state.error
    assert app.state.wv.robust
    np.testing.assert_allclose(view.adev_src.data["adev"], ref.adev, rtol=1e-9)


def test_scenario_url_round_trip_and_unknown_key(app_demo: Path) -> None:
    s = AppState()
    assert s.from_query({"source": "scenario", "scenario": "rw_dr"}), s.error
    sc = SCENARIOS["rw_dr"]
    assert s.n == sc.n and s.path == "rw_dr"
    np.testing.assert_array_equal(s.log.channels[sc.channel], sc.simulate())
    s2 = AppState()
    assert not s2.from_query({"source": "scenario", "scenario": "nope"})
    assert "unknown teaching scenario" in s2.error and s2.source == "demo"


def test_scenario_from_a_link_gets_its_naive_regions_and_model(app_demo: Path) -> None:
    """A scenario opened by URL (no menu click) shows the pitfall at once."""
    from gmwm_app.app import GMWMApp

    app = GMWMApp()
    assert app.state.from_query({"source": "scenario", "scenario": "wn_gm"}), app.state.error
    view = app.open_view("Slope method")
    sc = SCENARIOS["wn_gm"]
    assert view.regions == dict(sc.region_dict)
    assert app.state.model.spec() == sc.model.cleared().spec()
    res = view.result
    assert res is not None and res.estimates.get("AVSM") is not None
    # the naive white-noise line overstates sigma2 (the pitfall the scenario teaches)
    avsm = res.estimates["AVSM"].model.values()
    assert avsm["WN.sigma2"] > 1.2 * sc.model.values()["WN.sigma2"]


def test_pure_helpers_curves_and_table_rows() -> None:
    # WN + DR: AVAR(T) = N^2/T + R^2 T^2/2 exactly (docs/conventions.md), for the truth curve
    fs, s2, om = 50.0, 2e-3, 3e-6
    truth = eg.parse_model(f"WN(sigma2={s2})+DR(omega={om})")
    n = 4096
    tau = 2.0 ** np.arange(1, 12)
    wv = eg.WaveletVariance.from_arrays(truth.wv(tau, fs), n=n, fs=fs, unit="deg/s")
    res = compute_slope(wv, {"WN": (0.02, 1.0), "DR": (5.0, 1e9), "BI": (1.0, 4.0)}, truth)
    assert not res.messages, res.messages
    curves = implied_adev_curves(res)
    t = curves["truth"]["tau_s"]
    nn, rr = math.sqrt(s2 / fs), om * fs
    np.testing.assert_allclose(
        curves["truth"]["adev"], np.sqrt(nn**2 / t + rr**2 * t**2 / 2), rtol=1e-9
    )
    assert t[0] == pytest.approx(1 / fs) and t[-1] == pytest.approx(2**10 / fs)
    # AVSM on the exact WV: the WN line is exact where DR is negligible; the BI floor adds
    # (0.664 B)^2 to the implied AVAR
    e = res.estimates["AVSM"]
    b = e.extras["BI.B"]
    avsm_m = e.model
    m = t * fs
    np.testing.assert_allclose(
        curves["AVSM"]["adev"] ** 2, 2 * avsm_m.wv(2 * m, fs) + (BI_FACTOR * b) ** 2, rtol=1e-9
    )
    vals = comparison_values(res.estimates, truth, fs, "deg/s")
    row = next(r for r in vals if r["quantity"] == "white noise density")
    assert row["truth"] == pytest.approx(nn, rel=1e-12)
    assert row["AVSM"] == pytest.approx(nn, rel=0.02)
    assert [r["process"] for r in vals].index("WN") < [r["process"] for r in vals].index("DR")
    lines = slope_line_data(res)
    assert set(lines["code"]) == {"WN", "DR", "BI"}
    i = lines["code"].index("BI")
    assert math.isnan(lines["read_tau"][i]) and lines["ys"][i][0] == lines["ys"][i][1]
    # no data: a message, no exception
    empty = compute_slope(None, {"WN": (0.1, 1.0)})
    assert empty.av is None and empty.messages


# ---------------------------------------------------------------------------------------------
@pytest.mark.browser
@pytest.mark.browser_tour
def test_browser_scenario_fills_the_table(
    app_demo_file: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from _browser import launch, require_chromium
    from conftest import served_app
    from test_in_browser import TIMEOUT_MS, Tab, _app_for

    require_chromium()
    from playwright.sync_api import sync_playwright

    with served_app(app_demo_file) as (port, _thread), sync_playwright() as p:
        b = launch(p)
        try:
            ctx = b.new_context(viewport={"width": 1400, "height": 1000})
            t = Tab(ctx.new_page()).open(f"http://127.0.0.1:{port}/?model=WN")
            page = t.page
            page.locator(".bk-tab", has_text="Slope method").first.click()
            sel = page.locator(".gmwm-scenario select").first
            sel.wait_for(timeout=TIMEOUT_MS)
            sel.select_option(label=SCENARIOS["wn_gm"].title)
            t.wait_for(
                lambda: _app_for(lambda a: a.served and a.state.source == "scenario") is not None,
                "the scenario in the session",
            )
            app = _app_for(lambda a: a.served and a.state.source == "scenario")
            view = app.lazy_views["Slope method"]
            t.wait_for(
                lambda: view.result is not None and "GMWM" in view.result.estimates,
                "the GMWM column",
            )
            n_avsm = math.sqrt(view.result.estimates["AVSM"].params["WN.sigma2"] / 100.0)
            t.wait_for(
                lambda: format_value(n_avsm) in t.table_text(".gmwm-slope-table"),
                "the AVSM white-noise reading in the page",
            )
            text = t.table_text(".gmwm-slope-table")
            assert format_value(math.sqrt(1e-3 / 100.0)) in text  # the truth's N
            assert page.get_by_text("Why the slope method goes wrong").first.is_visible()
            assert t.errors == [], t.errors
            # "Clear regions": the slope readings go and the page says what to do, with no
            # failure in the server's log (the button's callback runs under the document lock)
            page.get_by_role("button", name="Clear regions").click()
            t.wait_for(
                lambda: (
                    view.regions == {}
                    and view.result is not None
                    and not view.result.regions
                    and "AVSM" not in view.result.estimates
                ),
                "the result without regions",
            )
            page.get_by_text("drag over the points of the plot").first.wait_for(timeout=TIMEOUT_MS)
            assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
            assert t.errors == [], t.errors
        finally:
            b.close()
