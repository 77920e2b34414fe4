"""The app's "Download report" button (browser-free): its callback makes the calibration
report of the session's fit with the engine (not refitted), the page's numbers are the
session's fit; without a fit the reason is the page's error message and the session keeps
working."""

from __future__ import annotations

import json
import re
from typing import Any

import engine as eg
from engine.reporting import gather_report


def _report_data(page: str) -> dict[str, Any]:
    m = re.search(r'<script type="application/json" id="gmwm-report-data">(.*?)</script>', page)
    assert m is not None
    return json.loads(m.group(1))


def _cells(page: str, channel: str) -> dict[str, float]:
    """``parameter -> data-value`` of the parameter table of ``channel``."""
    table = page.split(f'<table class="params" data-channel="{channel}">', 1)[1]
    table = table.split("</table>", 1)[0]
    return {
        name: float(v)
        for name, v in re.findall(
            r'<tr data-name="([^"]+)"><td>[^<]*</td>\s*<td class="n" data-value="([^"]+)"', table
        )
    }


def test_download_report_is_the_sessions_fit(app: Any) -> None:
    s = app.state
    assert s.select_channel("gyro_y") and s.set_model("GM+WN+RW"), s.error
    res = s.result
    page = app._export_report().read()
    assert app.report_download.filename == f"gmwm_report_{s.filename[:-3]}_gyro_y.html"
    assert s.error == ""
    # the session's fit itself, value for value (nothing refitted): the table's numbers and
    # the embedded JSON equal the engine's fit
    cells = _cells(page, "gyro_y")
    want = {r.full_name: r.value for r in res.param_records}
    assert cells == want and len(want) == 4
    d = _report_data(page)
    assert list(d["channels"]) == ["gyro_y"]
    assert d["channels"]["gyro_y"]["fit"] == json.loads(json.dumps(res.to_dict()))
    assert d["provenance"]["fits_given"] is True
    # and the same as the engine's report of the same log and fit
    rep = gather_report(s.log, fits={"gyro_y": res})
    ch = rep.channels["gyro_y"]
    assert [iv.to_dict() for iv in ch.intervals] == d["channels"]["gyro_y"]["intervals"]
    assert ch.jtest.statistic == d["channels"]["gyro_y"]["j_test"]["statistic"]
    # a fresh fit of the same model by the engine agrees with the session's
    fresh = eg.fit_gmwm(res.wv, eg.parse_model("GM+WN+RW"))
    assert fresh.objective == res.objective


def test_download_report_without_a_fit_is_a_message(app: Any) -> None:
    s = app.state
    assert s.clear_model()
    out = app._export_report().read()
    assert "fit a model first" in s.error and "Traceback" not in s.error
    assert "fit a model first" in out and "gmwm-report-data" not in out
    # the session keeps working: fit, and the report comes
    assert s.set_model("WN+RW"), s.error
    page = app._export_report().read()
    assert _cells(page, s.channel) == {r.full_name: r.value for r in s.result.param_records}


def test_report_made_in_the_app_process_loads_nothing(app_demo) -> None:
    """Panel's widget models (loaded with the app) declare external JS/CSS files that Bokeh's
    Resources lists for every loaded model class: the report must not link them (it opens
    offline, from an e-mail attachment)."""
    import re

    import panel as pn

    import engine as eg
    from engine.reporting import gather_report, render_html

    pn.widgets.FileDropper()  # a Panel model with external files, as the app has
    log = eg.load_log(eg.demo_path())
    fit = eg.fit_gmwm(eg.wavelet_variance(log["gyro_x"], fs=log.fs), "WN+RW")
    page = render_html(gather_report(log, fits={"gyro_x": fit}))
    tags = re.findall(r"<(?:script|link)\b[^>]*>", page)
    assert tags and not [t for t in tags if re.search(r'\b(?:src|href)="(?!data:|#)', t)]
