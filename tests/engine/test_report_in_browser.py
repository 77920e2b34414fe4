"""Real-browser tests of the calibration report: Chromium opens it from ``file://`` with the
network cut off (every request that is not ``file:`` or ``data:`` is aborted and recorded),
no console error, every figure painted.

Without ``/usr/bin/chromium`` these tests skip, except in CI (env ``CI`` set), where they fail.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from _browser import chromium, open_offline, painted, require_chromium, wait_for_canvases

import engine as eg
from engine.reporting import gather_report, render_html
from engine.reporting.render import figure_specs

pytestmark = pytest.mark.browser

DATASHEET = "arw=0.3 deg/sqrt(h), bi=6 deg/h, rrw=1 deg/h/sqrt(h)"


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Two demo channels with a datasheet, as interactive and static pages."""
    require_chromium()
    rep = gather_report(
        eg.demo_path(), model="GM+WN+RW", channels=["gyro_x", "accel_x"], datasheet=DATASHEET
    )
    d = tmp_path_factory.mktemp("report")
    out = {"keys": list(figure_specs(rep))}
    for kind, static in (("interactive", False), ("static", True)):
        p = d / f"{kind}.html"
        p.write_text(render_html(rep, static=static), encoding="utf-8")
        out[kind] = p
    return out


@pytest.fixture(scope="module")
def browser(reports: dict[str, Any]) -> Iterator[Any]:
    with chromium() as b:
        yield b


def test_interactive_report_offline_every_figure_painted(browser, reports):
    ctx, page, errors, outside = open_offline(browser, reports["interactive"])
    try:
        keys = reports["keys"]
        assert len(keys) == 9  # 4 figures per channel, the gyroscope's datasheet check
        # BokehJS draws every figure into a canvas (in the figures' shadow roots)
        wait_for_canvases(page, len(keys), timeout_ms=30_000)
        for key in keys:
            el = page.locator(f"#fig-{key}")
            box = el.bounding_box()
            assert box is not None and box["height"] > 100, key
            share = painted(el.screenshot())
            assert share > 0.05, f"figure {key} looks blank ({share:.3f} painted)"
        # the tables are there: parameters of both channels, the check's verdicts
        assert page.locator("table.params").count() == 2
        assert page.locator("table.check tr").count() > 10
    finally:
        ctx.close()
    assert outside == [], f"requests outside the file: {outside}"
    assert errors == [], errors


@pytest.mark.browser_tour
def test_static_report_offline_every_image_painted(browser, reports):
    ctx, page, errors, outside = open_offline(browser, reports["static"])
    try:
        keys = reports["keys"]
        for key in keys:
            img = page.locator(f"#fig-{key} img")
            assert img.evaluate("i => i.complete && i.naturalWidth > 300"), key
            share = painted(img.screenshot())
            assert share > 0.05, f"image {key} looks blank ({share:.3f} painted)"
        assert page.locator("canvas").count() == 0
    finally:
        ctx.close()
    assert outside == [] and errors == [], (outside, errors)
