"""Pages built ahead of demand (``gmwm-app --prebuild N``, :class:`gmwm_app.server.PagePool`).

A served app (127.0.0.1, a background thread of this process) keeps three pages built; real
sessions (an HTTP page request, then Bokeh's websocket protocol: ``bench_load.Session``) get
them. Checked: each session gets its own state and document (no model shared, a click in one
never reaches the other), a page built ahead is the page built on demand (the same models, in
the same order, with the same initial data), its first pull is the JSON made ahead, its first
click redraws, a request with a query is built on demand, one with another host name gets a
page built ahead, the pool refills,
and refilling pauses while a session is busy (counted steps, no timing).
"""

from __future__ import annotations

import asyncio
import importlib.util
import re
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from _browser import chromium, require_chromium
from conftest import served_app

from gmwm_app import server
from gmwm_app.app import live_apps, set_listed

REPO = Path(__file__).resolve().parents[2]
POOL = 3
#: Wait limits (s), not latency bounds: the pool builds at the lowest priority, and at load 30
#: three pages took over 120 s to build
WAIT_S = 600.0


def _bench() -> Any:
    """``tests/benchmarks/bench_load.py`` (its websocket session client)."""
    spec = importlib.util.spec_from_file_location(
        "bench_load", REPO / "tests" / "benchmarks" / "bench_load.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("bench_load", mod)
    spec.loader.exec_module(mod)
    return mod


def _wait(predicate: Any, what: str, timeout: float = WAIT_S) -> None:
    deadline = time.time() + timeout
    while time.time() < deadline:
        if predicate():
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


@pytest.fixture(scope="module")
def pooled(app_demo_file: Path) -> Iterator[dict[str, Any]]:
    """The app served with ``prebuild=POOL``, pages built for localhost:PORT, opened by
    127.0.0.1:PORT; yields its URL and pool."""

    n_pools = len(server.POOLS)
    pool = None
    try:
        with served_app(
            app_demo_file,
            # the pages are built for "localhost" and every test opens them by "127.0.0.1":
            # browsers may use another name than the one expected
            lambda port: server.create_application(prebuild=POOL, host=f"localhost:{port}"),
            # a page request without its websocket (most tests here) counts as a session
            # opening, which pauses the refill until Bokeh discards it
            unused_session_lifetime_milliseconds=8000,
            check_unused_sessions_milliseconds=1000,
        ) as (port, _thread):
            _wait(lambda: len(server.POOLS) > n_pools, "the page pool to start")
            pool = server.POOLS[-1]
            _wait(lambda: len(pool) == POOL and not pool.building, "the pool to fill")
            yield {"url": f"http://127.0.0.1:{port}/", "port": port, "pool": pool}
    finally:  # after the server stopped, as before
        if pool is not None:
            pool.close()


def _get(url: str, host: str | None = None) -> None:
    req = urllib.request.Request(url, headers={"Host": host} if host else {})
    with urllib.request.urlopen(req, timeout=WAIT_S) as resp:
        assert resp.status == 200


_REF = re.compile(r"__ref:(\w+)")  # a model named in a tag (Panel's)
PY_ID_MIN = 10**12
_PY_ID = re.compile(r"-\d{9,}$")  # a template root's name: the area and id() of its object
_COUNTED = re.compile(r"([A-Z][A-Za-z]+)\d{5,}")


def _canonical(rep: Any, ids: dict[str, int]) -> Any:
    """A document's JSON with its model ids replaced by their order of appearance, and the
    counters and ``id()`` in Panel's object and root names (different for every object of the
    process) dropped."""
    if isinstance(rep, dict):
        out = {}
        for k, v in rep.items():
            if k == "id" and isinstance(v, str):
                out[k] = ids.setdefault(v, len(ids))
            else:
                out[k] = _canonical(v, ids)
        return out
    if isinstance(rep, list | tuple):
        return [_canonical(v, ids) for v in rep]
    if isinstance(rep, int) and not isinstance(rep, bool) and rep > PY_ID_MIN:
        return "id()"  # Panel tags some callbacks with the id() of their object
    if isinstance(rep, str):  # Panel's object names: the class and a process-wide counter
        rep = _REF.sub(lambda m: f"__ref:{ids.setdefault(m.group(1), len(ids))}", rep)
        return _PY_ID.sub("-#", _COUNTED.sub(r"\1#", rep))
    return rep


def _first_difference(a: Any, b: Any, where: str = "") -> str:
    """Where two JSON values first differ (for the assertion message)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{where}.{k}")
    elif isinstance(a, list | tuple) and isinstance(b, list | tuple) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_difference(x, y, f"{where}[{i}]")
    return f"{where}: {str(a)[:300]} != {str(b)[:300]}"


def _doc_json(doc: Any) -> Any:
    from bokeh.document import Document

    return _canonical(Document.to_json(doc, deferred=False), {})


@pytest.mark.load  # a served pool filling in a background thread
def test_pool_hands_out_distinct_fresh_states(pooled: dict[str, Any]) -> None:
    pool = pooled["pool"]
    handed = pool.stats["handed"]
    before = set(map(id, live_apps()))
    _get(pooled["url"])
    a = live_apps()[-1]
    _get(pooled["url"])
    b = live_apps()[-1]
    assert pool.stats["handed"] == handed + 2  # both from the pool
    assert id(a) not in before and id(b) not in before and a is not b
    assert a.state is not b.state and a.jobs is not b.jobs
    doc_a, doc_b = a.jobs.doc, b.jobs.doc
    assert doc_a is not doc_b
    # each document is its session's: the session context is the real one, not the pool's
    assert doc_a.session_context.id != doc_b.session_context.id
    assert "gmwm-page-built-ahead" not in (doc_a.session_context.id, doc_b.session_context.id)
    assert doc_a.session_context.request.host == f"127.0.0.1:{pooled['port']}"
    # no Bokeh model is shared between the two pages
    assert not {m.id for m in doc_a.models} & {m.id for m in doc_b.models}
    assert not {id(m) for m in doc_a.models} & {id(m) for m in doc_b.models}


@pytest.mark.load  # a served pool filling in a background thread
def test_pooled_page_equals_on_demand_page(pooled: dict[str, Any]) -> None:
    pool = pooled["pool"]
    # (none being built: a page being built ahead is the newest of live_apps() meanwhile)
    _wait(lambda: len(pool) > 0 and not pool.building, "a page in the pool")
    handed = pool.stats["handed"]
    _get(pooled["url"])
    assert pool.stats["handed"] == handed + 1
    ahead = live_apps()[-1]
    # its document now: Bokeh discards a session without websocket after 8 s here (and
    # destroys its document), which a build on demand at load 15 can take
    doc_ahead = ahead.jobs.doc
    types_ahead = sorted(type(m).__name__ for m in doc_ahead.models)
    a = _doc_json(doc_ahead)
    size, pool.size = pool.size, 0  # the same request, built on demand
    try:
        _get(pooled["url"])
    finally:
        pool.size = size
    assert pool.stats["handed"] == handed + 1
    demand = live_apps()[-1]
    assert demand is not ahead
    doc_demand = demand.jobs.doc
    assert types_ahead == sorted(type(m).__name__ for m in doc_demand.models)
    assert len(types_ahead) > 200
    # the same document, model for model, data included (ids aside), but for the location's
    # host: built under "localhost", requested by "127.0.0.1" (the browser sets its own
    # location on creation: test_pooled_page_in_a_browser)
    b = _doc_json(doc_demand)
    assert _location_host(a) == ("localhost", f"http://localhost:{pooled['port']}/")
    assert _location_host(b) == ("127.0.0.1", pooled["url"])
    _location_host(a, ("127.0.0.1", pooled["url"]))
    assert a == b, _first_difference(a, b)


def _location_host(rep: Any, put: tuple[str, str] | None = None) -> tuple[str, str]:
    """The (hostname, href) of the location root of a document's JSON (``put``: set them)."""
    (loc,) = [r for r in rep["roots"] if r["attributes"].get("name") == "location"]
    attrs = loc["attributes"]
    if put is not None:
        attrs["hostname"], attrs["href"] = put
    return attrs["hostname"], attrs["href"]


@pytest.mark.load  # a served pool filling in a background thread
def test_pooled_page_opens_and_its_first_click_redraws(pooled: dict[str, Any]) -> None:
    bench = _bench()
    pool = pooled["pool"]
    _wait(lambda: len(pool) >= 2, "two pages in the pool")
    handed, ahead = pool.stats["handed"], server.PULLS["ahead"]
    before = live_apps()  # (other tests' apps may still be there, some with a GM)
    mine: list[Any] = []

    async def run() -> tuple[Any, Any, float]:
        one, two = bench.Session(pooled["url"]), bench.Session(pooled["url"])
        await asyncio.gather(one.open(WAIT_S), two.open(WAIT_S))
        assert not one.error and not two.error, (one.error, two.error)
        # the two sessions' apps (ready: their first data shown; a page being built ahead
        # for the pool is listed until its build ends, never ready)
        mine.extend(a for a in live_apps() if a.ready and not any(a is b for b in before))
        seen_by_two = two._events.qsize()
        s = await one.timed_click("add_gm", "GM", WAIT_S)
        await asyncio.sleep(0.5)
        # the click redrew session one only: session two received nothing meanwhile
        assert two._events.qsize() == seen_by_two
        await bench._close_all([one, two])
        return one, two, s

    one, two, click_s = asyncio.run(run())
    assert pool.stats["handed"] == handed + 2
    assert server.PULLS["ahead"] >= ahead + 2  # the first pulls were the JSON made ahead
    assert 0 < click_s < 30
    # the two sessions' apps: the click changed the model of one of them only
    models = [str(a.state.model) for a in mine]
    assert len(models) == 2 and sum("GM" in m for m in models) == 1, models


@pytest.mark.load  # a served pool filling in a background thread
@pytest.mark.browser
@pytest.mark.browser_tour
def test_pooled_page_in_a_browser(pooled: dict[str, Any]) -> None:
    """Chromium draws a page built ahead, its first click redraws, and its URL follows the
    session's state (the location bound at hand-over)."""
    require_chromium()
    pool = pooled["pool"]
    _wait(lambda: len(pool) > 0, "a page in the pool")
    handed = pool.stats["handed"]
    errors: list[str] = []
    with chromium() as browser:
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
        page.goto(pooled["url"])
        assert pool.stats["handed"] == handed + 1  # this page came from the pool
        page.get_by_text("WV levels").first.wait_for(timeout=WAIT_S * 1000)
        page.get_by_role("button", name="+ GM", exact=True).click()

        def table() -> str:
            return " ".join(page.locator(".gmwm-params .slick-cell").all_inner_texts())

        deadline = time.time() + WAIT_S
        while "beta" not in table() and time.time() < deadline:
            page.wait_for_timeout(50)
        assert "beta" in table(), table()
        while "model=GM" not in page.url and time.time() < deadline:
            page.wait_for_timeout(50)
        assert "model=GM" in page.url, page.url
        # built under "localhost", opened by 127.0.0.1: the location is the browser's
        assert page.url.startswith(pooled["url"]), page.url
        assert page.evaluate("window.location.host") == f"127.0.0.1:{pooled['port']}"
    assert errors == []


@pytest.mark.load  # a served pool filling in a background thread
def test_query_builds_on_demand(pooled: dict[str, Any]) -> None:
    pool = pooled["pool"]
    _wait(lambda: len(pool) > 0, "a page in the pool")
    handed = pool.stats["handed"]
    before = live_apps()
    _get(pooled["url"] + "?channel=gyro_y")
    assert pool.stats["handed"] == handed  # built on demand
    # the page built for this request carries its query (a page the pool builds meanwhile,
    # in its background thread, may be listed after it: not live_apps()[-1])
    new = [a for a in live_apps() if not any(a is b for b in before)]
    assert [a._query.get("channel") for a in new if a._query] == ["gyro_y"]


@pytest.mark.load  # a served pool filling in a background thread
def test_other_host_name_gets_the_pages_built_ahead(pooled: dict[str, Any]) -> None:
    """Browsers that use another name for the server (``localhost`` where ``127.0.0.1`` was
    expected, an address for a host name) get the pages built ahead: nothing is released or
    rebuilt (a class with another host name lost the pool, p95 1.18 s -> 21.4 s).
    The session's own request is the one with its host; Chromium's location is its own."""
    pool = pooled["pool"]
    _wait(lambda: len(pool) >= 2, "two pages in the pool")
    handed, released, built = pool.stats["handed"], pool.stats["released"], pool.stats["built"]
    for host in (f"localhost:{pooled['port']}", f"127.0.0.1:{pooled['port']}"):
        _get(pooled["url"], host=host)
        doc = live_apps()[-1].jobs.doc
        assert doc.session_context.request.host == host
    assert pool.stats["handed"] == handed + 2  # both from the pool
    assert pool.stats["released"] == released  # no page thrown away
    assert pool.stats["built"] - built <= 2  # (refills only)
    assert pool.shape == server.RequestShape("/", "/")


@pytest.mark.load  # a served pool filling in a background thread
def test_an_ended_session_not_yet_collected_does_not_pause_the_refill(
    pooled: dict[str, Any],
) -> None:
    """A page request whose websocket never comes: Bokeh discards the session (here after
    8 s), but its app stays in ``live_apps()`` until the garbage collector frees it (held
    here, as a pending collection holds it). The pool refills all the same."""
    pool = pooled["pool"]
    _wait(lambda: len(pool) > 0, "a page in the pool")
    handed = pool.stats["handed"]
    _get(pooled["url"])
    app = live_apps()[-1]
    assert pool.stats["handed"] == handed + 1 and app.served and not app.ready
    assert pool.busy()  # a session opening
    _wait(lambda: not app.served, "Bokeh to discard the unused session", 60)
    assert any(a is app for a in live_apps())  # ended, not collected
    assert not pool.busy()
    _wait(lambda: len(pool) == POOL and not pool.building, "the pool to refill")


# ---------------------------------------------------------------------------------------------
# refilling pauses while the sessions need the server (counted steps)
# ---------------------------------------------------------------------------------------------
class _Session:
    """Stands for a session's app in ``live_apps()``: its busy, ready and served flags."""

    busy = False
    ready = True
    served = True


def test_refill_pauses_while_a_session_is_busy_or_opening() -> None:
    built: list[Any] = []
    on_demand = [0]

    def build(doc: Any) -> Any:
        built.append(doc)
        return _Session()

    session = _Session()
    pool = server.PagePool(
        2,
        build,
        None,
        shape=server.RequestShape("/", "/"),
        on_demand=lambda: on_demand[0],
        sessions=lambda: [session],
    )
    try:
        session.busy = True  # loading data
        assert not any(pool.step() for _ in range(5))
        assert pool.stats["paused"] == 5 and built == []
        session.busy, session.ready = False, False  # opening: first data not shown yet
        assert not any(pool.step() for _ in range(3))
        assert pool.stats["paused"] == 8 and built == []
        session.ready = True
        on_demand[0] = 1  # a page being built on demand
        assert not pool.step() and pool.stats["paused"] == 9 and built == []
        on_demand[0] = 0
        assert pool.step()  # idle: one build starts
        pool._building.result(timeout=60)
        assert len(built) == 1 and len(pool) == 1 and pool.stats["built"] == 1
        session.busy = True
        assert not pool.step() and pool.stats["paused"] == 10 and len(built) == 1
        session.busy = False
        assert pool.step()
        pool._building.result(timeout=60)
        assert len(pool) == 2 and not pool.step()  # full: no build, no pause counted
        assert pool.stats["paused"] == 10 and len(built) == 2
    finally:
        pool.close()
    assert pool.busy() is False and len(pool) == 0  # closed: its pages released


class _Ended(_Session):
    """An app whose session ended and which the garbage collector has not freed yet."""

    served = False
    ready = False


def test_refill_counts_only_the_sessions_being_served() -> None:
    assert server.PagePool.__init__.__kwdefaults__["sessions"] is server.served_apps
    ended, opening = _Ended(), _Session()
    opening.ready = False
    set_listed(ended, True)
    pool = server.PagePool(
        1,
        lambda doc: _Session(),
        None,
        shape=server.RequestShape("/", "/"),
        # these two among the served apps (other tests' sessions may be open meanwhile)
        sessions=lambda: [a for a in server.served_apps() if a in (ended, opening)],
    )
    try:
        assert ended in live_apps() and ended not in server.served_apps()
        assert pool.step()  # the ended session does not pause the refill
        pool._building.result(timeout=60)
        assert len(pool) == 1 and pool.stats["paused"] == 0
        pool.size = 2
        set_listed(opening, True)  # a session being served, opening
        assert opening in server.served_apps()
        assert not pool.step() and pool.stats["paused"] == 1
    finally:
        set_listed(ended, False)
        set_listed(opening, False)
        pool.close()


def test_request_shape_and_default_size() -> None:
    from bokeh.server.contexts import _RequestProxy
    from tornado.httputil import HTTPHeaders, HTTPServerRequest, RequestStartLine

    def proxy(uri: str, host: str = "lab-pc:5006") -> Any:
        line = RequestStartLine("GET", uri, "HTTP/1.1")
        return _RequestProxy(
            HTTPServerRequest(start_line=line, headers=HTTPHeaders({"Host": host}))
        )

    shape = server.request_shape(proxy("/"))
    assert shape == server.RequestShape("/", "/")
    # the host name is not part of the shape (Chromium's Location sets its own on creation)
    assert server.request_shape(proxy("/", host="10.0.0.7:5006")) == shape
    assert server.request_shape(proxy("/?source=path&path=x.h5")) is None
    assert server.request_shape(proxy("/ws")) == shape  # a session created by its websocket
    assert server.request_shape(proxy("/other")) != shape
    assert server.request_shape(None) is None
    assert server.default_prebuild(available_mb=20_000) == server.DEFAULT_PREBUILD == 32
    # at most a tenth of the available memory, about 5 MB a page
    assert server.default_prebuild(available_mb=1000) == 20
    assert server.default_prebuild(available_mb=10) == 0


def test_prebuild_option() -> None:
    from gmwm_app.__main__ import build_parser, expected_host, main

    assert main(["--prebuild", "-1", "--no-show"]) == 2
    p = build_parser()
    assert "--prebuild" in p.format_help()
    args = p.parse_args(["--port", "5006"])
    assert args.prebuild is None
    assert expected_host(args, "localhost") == "localhost:5006"
    args = p.parse_args(["--port", "5006", "--allow-websocket-origin", "lab-pc:5006"])
    assert expected_host(args, "0.0.0.0") == "lab-pc:5006"
    args = p.parse_args(["--port", "5006", "--allow-websocket-origin", "lab-pc"])
    assert expected_host(args, "0.0.0.0") == "lab-pc:5006"
    assert expected_host(p.parse_args(["--port", "0"]), "localhost") is None
    assert expected_host(p.parse_args(["--port", "8000"]), "::1") == "[::1]:8000"
