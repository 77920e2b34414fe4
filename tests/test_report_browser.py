"""Real-browser tests of the calibration report: Chromium opens it from ``file://`` with the
network cut off (every request that is not ``file:`` or ``data:`` is aborted and recorded),
no console error, every figure painted.

Without ``/usr/bin/chromium`` these tests skip, except in CI (env ``CI`` set), where they fail.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import CHROMIUM, CHROMIUM_ARGS

import engine as eg
from engine.reporting import gather_report, render_html
from engine.reporting.render import figure_specs

pytestmark = pytest.mark.browser

DATASHEET = "arw=0.3 deg/sqrt(h), bi=6 deg/h, rrw=1 deg/h/sqrt(h)"


def _require_chromium() -> None:
    if not CHROMIUM.exists():
        if os.environ.get("CI"):
            pytest.fail("CI must install chromium (/usr/bin/chromium is missing)")
        pytest.skip("/usr/bin/chromium is not installed")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("CI must install playwright")
        pytest.skip("playwright is not installed")


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Two demo channels with a datasheet, as interactive and static pages."""
    _require_chromium()
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
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


def _open_offline(browser: Any, path: Path) -> tuple[Any, Any, list[str], list[str]]:
    """The page opened from file:// with every other request aborted; returns (context,
    page, console errors, requests attempted outside the file)."""
    ctx = browser.new_context(viewport={"width": 1280, "height": 900}, offline=True)
    outside: list[str] = []

    def route(r: Any) -> None:
        url = r.request.url
        if url.startswith(("file:", "data:")):
            r.continue_()
        else:
            outside.append(url)
            r.abort()

    ctx.route("**/*", route)
    page = ctx.new_page()
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("requestfailed", lambda r: None if r.url in outside else errors.append(r.url))
    page.goto(path.as_uri(), wait_until="load")
    return ctx, page, errors, outside


def _painted(png: bytes) -> float:
    """Share of pixels that are not the background (the most common colour)."""
    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3).astype(np.uint32)
    colour = (a[:, 0] << 16) | (a[:, 1] << 8) | a[:, 2]  # one integer per colour: a 1-D count
    _, counts = np.unique(colour, return_counts=True)
    return 1.0 - counts.max() / colour.size


def test_interactive_report_offline_every_figure_painted(browser, reports):
    ctx, page, errors, outside = _open_offline(browser, reports["interactive"])
    try:
        keys = reports["keys"]
        assert len(keys) == 9  # 4 figures per channel, the gyroscope's datasheet check
        # BokehJS draws every figure into a canvas (in the figures' shadow roots)
        page.wait_for_function(
            """n => {
                const walk = r => [...r.querySelectorAll('*')].reduce(
                    (k, e) => k + (e.tagName === 'CANVAS' && e.width > 0 ? 1 : 0)
                        + (e.shadowRoot ? walk(e.shadowRoot) : 0), 0);
                return walk(document) >= n;
            }""",
            arg=len(keys),
            timeout=30_000,
        )
        for key in keys:
            el = page.locator(f"#fig-{key}")
            box = el.bounding_box()
            assert box is not None and box["height"] > 100, key
            share = _painted(el.screenshot())
            assert share > 0.05, f"figure {key} looks blank ({share:.3f} painted)"
        # the tables are there: parameters of both channels, the check's verdicts
        assert page.locator("table.params").count() == 2
        assert page.locator("table.check tr").count() > 10
    finally:
        ctx.close()
    assert outside == [], f"requests outside the file: {outside}"
    assert errors == [], errors


def test_static_report_offline_every_image_painted(browser, reports):
    ctx, page, errors, outside = _open_offline(browser, reports["static"])
    try:
        keys = reports["keys"]
        for key in keys:
            img = page.locator(f"#fig-{key} img")
            assert img.evaluate("i => i.complete && i.naturalWidth > 300"), key
            share = _painted(img.screenshot())
            assert share > 0.05, f"image {key} looks blank ({share:.3f} painted)"
        assert page.locator("canvas").count() == 0
    finally:
        ctx.close()
    assert outside == [] and errors == [], (outside, errors)
