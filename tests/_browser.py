"""The headless Chromium of the browser tests, the screenshot scripts and the app benchmark.

One place for what they all repeated: the Debian ``chromium`` binary and its flags
(:data:`CHROMIUM`, :data:`CHROMIUM_ARGS`), the skip rule (:func:`require_chromium`: without
the binary or Playwright a test skips, except in CI (env ``CI`` set), where it fails), the
launch (:func:`launch` on a running Playwright, :func:`chromium` as a context manager that
also starts and stops Playwright), a page opened from ``file://`` with the network cut off
(:func:`open_offline`), the wait for BokehJS to draw its canvases (:func:`wait_for_canvases`),
the share of painted pixels of a screenshot (:func:`painted`) and the README screenshots of a
page's top (:func:`screenshot_top`).
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

try:  # Playwright is in the test extra; without it the browser tests skip (fail in CI)
    from playwright.sync_api import sync_playwright
except ImportError:  # pragma: no cover - the test extra installs it
    sync_playwright = None

#: The headless Chromium and its flags.
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]

#: Counts the canvases BokehJS has drawn (width > 0), in the figures' shadow roots too.
_CANVASES_AT_LEAST = """n => {
    const walk = r => [...r.querySelectorAll('*')].reduce(
        (k, e) => k + (e.tagName === 'CANVAS' && e.width > 0 ? 1 : 0)
            + (e.shadowRoot ? walk(e.shadowRoot) : 0), 0);
    return walk(document) >= n;
}"""


def require_chromium() -> None:
    """Skip the calling test without ``/usr/bin/chromium`` or Playwright (fail in CI)."""
    if not CHROMIUM.exists():
        if os.environ.get("CI"):
            pytest.fail("CI must install chromium (/usr/bin/chromium is missing)")
        pytest.skip("/usr/bin/chromium is not installed")
    if sync_playwright is None:
        if os.environ.get("CI"):
            pytest.fail("CI must install playwright")
        pytest.skip("playwright is not installed")


def launch(playwright: Any) -> Any:
    """The headless Chromium launched by a running Playwright (the caller closes it)."""
    return playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)


@contextmanager
def chromium() -> Iterator[Any]:
    """Playwright and the headless Chromium for the ``with`` block; both always stopped."""
    if sync_playwright is None:
        raise RuntimeError("playwright is not installed: pip install -e '.[test]'")
    with sync_playwright() as p:
        browser = launch(p)
        try:
            yield browser
        finally:
            browser.close()


def open_offline(
    browser: Any, path: Path, viewport: tuple[int, int] = (1280, 900)
) -> tuple[Any, Any, list[str], list[str]]:
    """The page opened from file:// with every other request aborted; returns (context,
    page, console errors, requests attempted outside the file)."""
    ctx = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]}, offline=True)
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


def wait_for_canvases(page: Any, n: int, timeout_ms: int) -> None:
    """Wait until BokehJS has drawn at least ``n`` canvases (in shadow roots too)."""
    page.wait_for_function(_CANVASES_AT_LEAST, arg=n, timeout=timeout_ms)


def painted(png: bytes) -> float:
    """Share of pixels that are not the background (the most common colour)."""
    a = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3).astype(np.uint32)
    colour = (a[:, 0] << 16) | (a[:, 1] << 8) | a[:, 2]  # one integer per colour: a 1-D count
    _, counts = np.unique(colour, return_counts=True)
    return 1.0 - counts.max() / colour.size


def screenshot_top(
    page_path: Path,
    out: str | os.PathLike[str],
    *,
    width: int,
    height: int,
    ready: str,
    ready_timeout_ms: int = 30_000,
    settle_ms: int = 1500,
) -> None:
    """Save the top ``width`` x ``height`` pixels of a page opened offline from ``file://``
    as a PNG, once the element ``ready`` (a CSS selector) is there and BokehJS has had
    ``settle_ms`` to paint (the screenshot scripts of ``tests/benchmarks``)."""
    with chromium() as b:
        _ctx, page, _errors, _outside = open_offline(b, page_path, (width, height))
        page.locator(ready).wait_for(timeout=ready_timeout_ms)
        page.wait_for_timeout(settle_ms)  # BokehJS paints after load
        page.screenshot(path=str(out), clip={"x": 0, "y": 0, "width": width, "height": height})
