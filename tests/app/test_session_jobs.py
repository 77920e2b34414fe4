"""The session job runner (``gmwm_app.jobs``) and the Panel-internals module's version guard."""

from __future__ import annotations

import asyncio
import inspect
import logging
from concurrent.futures import Future
from typing import Any

import panel as pn
import pytest

from gmwm_app import _panel_compat as compat
from gmwm_app import boundary
from gmwm_app.jobs import Jobs, LoopTurns


def test_a_job_applies_its_result_then_runs_done() -> None:
    jobs = Jobs(doc=None)
    seen: list[Any] = []
    jobs.run(lambda: 6 * 7, seen.append, None, lambda: seen.append("done"))
    assert seen == [42, "done"] and not jobs.served


def test_a_failure_goes_to_fail_never_to_apply() -> None:
    jobs = Jobs(doc=None)
    seen: list[Any] = []
    jobs.run(lambda: 1 / 0, seen.append, lambda e: seen.append(type(e).__name__))
    assert seen == ["ZeroDivisionError"]


def test_a_newer_job_of_the_same_key_supersedes_a_running_one() -> None:
    jobs = Jobs(doc=None)
    seen: list[Any] = []

    def slow() -> str:
        jobs.run(lambda: "new", seen.append, key="k")  # starts (and ends) meanwhile
        return "old"

    jobs.run(slow, seen.append, key="k", inline=True)
    assert seen == ["new"]
    # another key is not affected
    jobs.run(lambda: "other", seen.append, key="j")
    assert seen == ["new", "other"]


def test_cancel_drops_the_result_but_done_still_runs() -> None:
    jobs = Jobs(doc=None)
    seen: list[Any] = []

    def work() -> str:
        jobs.cancel("k")
        return "dropped"

    jobs.run(work, seen.append, seen.append, lambda: seen.append("done"), key="k")
    assert seen == ["done"]


def test_a_page_load_turns_the_indicator_on_and_off_and_installs() -> None:
    jobs = Jobs(doc=None)
    seen: list[Any] = []
    jobs.busy = lambda on, msg: seen.append(("busy", on, msg))
    jobs.install = lambda x: seen.append(("install", x))
    jobs.settled = lambda: seen.append("settled")
    jobs.failed = lambda msg, e: seen.append(("failed", msg, str(e)))
    jobs.load("Reading", lambda: 3)
    assert seen == [("busy", True, "Reading"), ("install", 3), ("busy", False, ""), "settled"]
    seen.clear()
    jobs.load("Reading x", lambda: int("x"))
    assert seen[1][0] == "failed" and seen[1][1] == "Reading x" and seen[2][1] is False


class _ServedDoc:
    """What :class:`Jobs` uses of a served Bokeh document, on an asyncio loop: a next-tick
    callback runs in a later iteration of the loop, as on Bokeh's server."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.session_context = object()

    def on_session_destroyed(self, fn: Any) -> None:
        pass

    def add_next_tick_callback(self, fn: Any) -> None:
        if inspect.iscoroutinefunction(fn):
            self.loop.create_task(fn())
        else:
            self.loop.call_soon(fn)


def _served_results(n_sessions: int, cancel: int | None = None) -> list[tuple[str, Any, int]]:
    """``n_sessions`` served sessions whose page loads came back together (each a finished
    future, as the data read while the page loaded): what ran on the loop, as (what, value,
    the loop iteration it ran in), with session ``cancel``'s job cancelled while it waits."""
    loop = asyncio.new_event_loop()
    iteration = [0]
    seen: list[tuple[str, Any, int]] = []

    def tick() -> None:  # runs once per iteration of the loop (call_soon: the next one)
        iteration[0] += 1
        loop.call_soon(tick)

    tasks: list[asyncio.Task] = []

    def start() -> None:
        for i in range(n_sessions):
            jobs = Jobs(doc=_ServedDoc(loop))
            assert jobs.served
            read: Future = Future()
            read.set_result(i)
            before = asyncio.all_tasks(loop)
            jobs.run(
                read,
                lambda out: seen.append(("apply", out, iteration[0])),
                done=lambda i=i: seen.append(("done", i, iteration[0])),
            )
            tasks.extend(asyncio.all_tasks(loop) - before)  # the session's job

    async def main() -> None:
        nonlocal cancel
        loop.call_soon(tick)
        loop.call_soon(start)
        for _ in range(200):
            await asyncio.sleep(0)
            if cancel is not None and LoopTurns.of(loop).waiting >= 2:
                tasks[cancel].cancel()  # the last one: it waits for its turn
                cancel = None
            if sum(w == "done" for w, *_ in seen) == n_sessions:
                return
        raise AssertionError(f"not every job ended: {seen}")

    try:
        loop.run_until_complete(main())
    finally:
        loop.close()
    return seen


def test_served_results_are_applied_one_per_loop_iteration_in_order() -> None:
    """Nine pages whose data came back together: their results are applied in the order they
    came, each in an iteration of the server loop of its own (so that the loop reads the
    requests that arrived between two of them), never back to back in one iteration."""
    seen = _served_results(9)
    applied = [(v, it) for w, v, it in seen if w == "apply"]
    assert [v for v, _ in applied] == list(range(9))  # first come, first served
    its = [it for _, it in applied]
    assert all(b > a for a, b in zip(its, its[1:], strict=False)), its  # one per iteration
    assert [v for w, v, _ in seen if w == "done"] == list(range(9))


def test_a_session_closed_while_waiting_its_turn_still_runs_done() -> None:
    seen = _served_results(4, cancel=3)
    assert sorted(v for w, v, _ in seen if w == "done") == [0, 1, 2, 3]
    assert [v for w, v, _ in seen if w == "apply"] == [0, 1, 2]


def test_panel_internals_were_checked_for_the_installed_panel() -> None:
    """Fails on a Panel upgrade: re-check gmwm_app/_panel_compat.py, then add the version."""
    assert pn.__version__ in compat.PANEL_VERSIONS, (
        f"Panel {pn.__version__}: re-check the internals used by gmwm_app/_panel_compat.py "
        f"(written for {compat.PANEL_VERSIONS})"
    )
    assert compat.supported() and compat.light_text_updates()
    from panel.pane.markup import HTMLBasePane

    assert getattr(HTMLBasePane._update, "_gmwm_light", False)
    from panel.io.state import state as pn_state

    assert hasattr(pn_state, "_thread_id_") and hasattr(pn_state, "_launching")


def test_the_off_loop_stylesheet_patch_matches_panels_own() -> None:
    """A root patched off the loop is skipped by the page handler only for the same dist_url,
    and Panel's own patch leaves it as it was (the skip changes nothing)."""
    from panel.io import server as pn_server
    from panel.io.resources import patch_model_css

    assert compat.skip_repeated_css_patch()
    assert pn_server.patch_model_css is not patch_model_css  # the handler's name is wrapped
    page = pn.Column(pn.widgets.Button(label="a"), pn.pane.Markdown("x"))
    doc = page.server_doc()
    root = doc.roots[0]

    def urls() -> list[str]:
        from bokeh.models import ImportedStyleSheet

        return sorted(s.url for s in root.select({"type": ImportedStyleSheet}))

    patch_model_css(root, dist_url="static/extensions/panel/")
    compat._CSS_DONE[root] = "static/extensions/panel/"
    before = urls()
    assert before and all("static/extensions/panel/" in u for u in before if "bundled" in u)
    pn_server.patch_model_css(root, dist_url="static/extensions/panel/")  # skipped
    assert urls() == before
    patch_model_css(root, dist_url="static/extensions/panel/")  # Panel's own: no change
    assert urls() == before


def test_a_server_process_favours_the_loops_latency() -> None:
    """create_application sets the 0.5 ms GIL switch interval (the load test measures its
    effect: the loop answers within 0.2 s during a burst of page builds, not 1.1-1.4 s)."""
    import sys

    from gmwm_app import server

    before = sys.getswitchinterval()
    try:
        server.create_application()
        assert sys.getswitchinterval() == server.SWITCH_INTERVAL_S == 0.0005
    finally:
        sys.setswitchinterval(before)


def test_progress_reports_reach_the_indicator_while_the_load_is_the_latest() -> None:
    jobs = Jobs(doc=None)
    seen: list[Any] = []
    jobs.busy = lambda on, msg: seen.append((on, msg))

    def work(report: Any) -> int:
        for j in range(1, 4):
            report(j, 3)
        return 3

    jobs.load("Computing", work, lambda out: seen.append(("applied", out)), progress=True)
    assert seen == [
        (True, "Computing"),
        (True, "Computing: level 1 of 3"),
        (True, "Computing: level 2 of 3"),
        (True, "Computing: level 3 of 3"),
        ("applied", 3),
        (False, ""),
    ]
    # a superseded load's reports are dropped
    seen.clear()
    stale = jobs.progress_reporter("Old", "page-load", ticket=-1)
    stale(5, 9)
    assert seen == []


def test_the_robust_toggle_shows_the_wv_levels_as_they_compute(app_demo: Any) -> None:
    """The app (no browser, no server): switching to the robust WV computes it in a page load
    whose status text follows the levels, 1 to J, then clears."""
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    assert app.state.wv is not None and not app.state.robust
    texts: list[str] = []
    busy = app.jobs.busy
    app.jobs.busy = lambda on, msg="": (busy(on, msg), texts.append(app.status.object))
    app.robust_check.value = True
    assert app.state.robust and app.state.wv.robust, app.state.error
    n = app.state.wv.n_levels
    levels = [t for t in texts if "level" in t]
    want = [
        f"⏳ Computing the robust wavelet variance: level {j} of {n} ..." for j in range(1, n + 1)
    ]
    assert levels == want
    assert texts[0] == "⏳ Computing the robust wavelet variance ..." and texts[-1] == ""
    assert app.status.object == "" and not app.busy


def test_live_apps_lists_sessions_oldest_first_and_forgets_closed_ones(app_demo: Any) -> None:
    """``live_apps()[-1]`` is the newest session (tests pick theirs that way); a discarded
    app leaves the registry."""
    import gc

    from gmwm_app.app import create_app, live_apps

    apps = [create_app().gmwm_app for _ in range(4)]
    listed = [a for a in live_apps() if any(a is b for b in apps)]
    assert [id(a) for a in listed] == [id(a) for a in apps]
    assert live_apps()[-1] is apps[-1]
    gone = id(apps[1])
    del apps[1], listed
    gc.collect()
    assert gone not in {id(a) for a in live_apps()}
    assert [id(a) for a in live_apps() if any(a is b for b in apps)] == [id(a) for a in apps]


def test_a_failing_page_update_reaches_the_page_and_the_log(
    caplog: pytest.LogCaptureFixture,
) -> None:
    class ServedDoc:  # a document of a served session whose next tick comes at once
        session_context = object()

        def add_next_tick_callback(self, fn: Any) -> None:
            fn()

        def on_session_destroyed(self, *callbacks: Any) -> None:  # Jobs registers its end
            pass

    doc = ServedDoc()
    jobs = Jobs(doc)
    shown: list[str] = []
    # the session's page, as the app attaches it to the error boundary (gmwm_app.boundary)
    boundary.install()
    boundary.attach(doc, shown.append)

    def broken() -> None:
        raise RuntimeError("a figure could not be drawn")

    with caplog.at_level(logging.ERROR, logger="gmwm_app.boundary"):
        jobs.locked(broken)  # no exception leaves the loop
    assert shown == [
        "Could not update the page: unexpected RuntimeError: a figure could not be drawn"
    ]
    assert "could not be drawn" in caplog.text and "RuntimeError" in caplog.text
    assert any(r.exc_info for r in caplog.records)  # with its traceback
