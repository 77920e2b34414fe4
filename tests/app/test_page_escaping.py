"""No script from data or URLs: every string a page shows from a link, a file or a session
file is text, never HTML.

In Chromium (real browser, the app served in this process): ``<img src=x onerror=...>`` planted
in every URL parameter (``source``, ``path``, ``channel``, ``fs``, ``weights``, ``model``), in a
CSV header (a channel name) and in an uploaded file's name; the page must show its messages
and run nothing (``window.__xss`` stays unset, and no element of the page, shadow roots
included, carries an ``onerror`` attribute; a control test shows that the same markup set as
HTML does run and is seen). Without a browser: a crafted session file's
fields, shown in the page's alert, arrive escaped.
"""

from __future__ import annotations

import json
import urllib.parse
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

TIMEOUT_MS = 20_000

#: The planted markup; it sets window.__xss when its script runs.
PAYLOAD = "<img src=x onerror=window.__xss=1>"

#: Counts the elements with an onerror attribute, in shadow roots too.
_ONERROR = """() => {
    const walk = r => [...r.querySelectorAll('*')].reduce(
        (k, e) => k + (e.hasAttribute('onerror') ? 1 : 0)
            + (e.shadowRoot ? walk(e.shadowRoot) : 0), 0);
    return walk(document);
}"""

#: All the text of the page, shadow roots included.
_TEXT = """() => {
    const walk = r => [...r.childNodes].map(n => n.nodeType === 3 ? n.textContent
        : (n.shadowRoot ? walk(n.shadowRoot) : '') + walk(n)).join(' ');
    return walk(document.body);
}"""


@pytest.fixture
def page(browser: Any) -> Iterator[Any]:
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
    yield ctx.new_page()
    ctx.close()


def _ran_nothing(page: Any) -> None:
    page.wait_for_timeout(1500)  # the messages are shown, an image would have failed
    assert page.evaluate("() => window.__xss") is None, "a planted script ran"
    assert page.evaluate(_ONERROR) == 0, "planted markup became HTML"


def _wait_text(page: Any, text: str) -> str:
    deadline = TIMEOUT_MS / 50
    for _ in range(int(deadline)):
        body = page.evaluate(_TEXT)
        if text in body:
            return body
        page.wait_for_timeout(50)
    raise AssertionError(f"the page never showed {text!r}")


@pytest.mark.browser
@pytest.mark.browser_tour
def test_the_detector_sees_a_planted_script(server: str, page: Any) -> None:
    """Control: the same markup set as HTML in this Chromium runs and is seen."""
    page.goto(server)
    _wait_text(page, "WV levels")
    page.evaluate(f"() => {{ document.body.insertAdjacentHTML('beforeend', {PAYLOAD!r}); }}")
    page.wait_for_timeout(500)
    assert page.evaluate("() => window.__xss") == 1 and page.evaluate(_ONERROR) == 1


@pytest.mark.browser
@pytest.mark.browser_tour
@pytest.mark.parametrize("name", ["source", "path", "channel", "fs", "weights", "model"])
def test_url_parameters_are_text(server: str, page: Any, name: str) -> None:
    query = {"source": "path", "path": PAYLOAD} if name == "path" else {name: PAYLOAD}
    page.goto(server + "?" + urllib.parse.urlencode(query))
    _wait_text(page, "onerror")  # the page names the bad value, as text
    _ran_nothing(page)


@pytest.mark.browser
@pytest.mark.browser_tour
def test_file_name_and_channel_names_are_text(server: str, page: Any, tmp_path: Path) -> None:
    page.goto(server)
    _wait_text(page, "WV levels")
    bad = tmp_path / f"{PAYLOAD}.csv"
    rows = "\n".join(f"{i / 100:.2f},{(-1) ** i * 0.01 * (i % 7)}" for i in range(3000))
    bad.write_text(f"time,{PAYLOAD}\n{rows}\n")
    page.locator("input[type=file]").first.set_input_files(str(bad))
    _wait_text(page, "onerror")
    _ran_nothing(page)


def test_session_file_fields_are_escaped_in_the_page(app: Any) -> None:
    """A crafted session file (its file name and data path): the alert's HTML is escaped."""
    from engine.session import SCHEMA
    from gmwm_app import session_view as sv

    doc = {
        "schema": SCHEMA,
        "data": {"path": f"/nowhere/{PAYLOAD}.csv", "load": {}, "fingerprint": None},
        "channels": {},
        "app": {"source": "upload", "filename": PAYLOAD, "channel": PAYLOAD},
    }
    plan = sv.prepare_restore(json.dumps(doc), f"{PAYLOAD}.json")
    assert not sv.apply_restore(app.state, plan)
    assert PAYLOAD in app.state.error  # the state keeps the words; the page escapes them
    shown = _html_of(app.alert)
    assert "<img" not in shown and "&lt;img" in shown, shown
    plan = sv.prepare_restore(
        json.dumps({**doc, "app": {"source": "path", "channel": PAYLOAD}}), "s.json"
    )
    assert not sv.apply_restore(app.state, plan)
    assert "<img" not in _html_of(app.alert)


def _html_of(pane: Any) -> str:
    """The HTML a pane puts in the page: its Bokeh model's text, which Panel sends escaped
    once for transport (the browser unescapes it, then sets it as HTML)."""
    import html

    model = pane.get_root()
    return html.unescape(str(getattr(model, "text", "") or ""))
