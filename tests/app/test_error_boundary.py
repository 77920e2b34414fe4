"""The app's one error boundary (``gmwm_app.boundary``): Panel's exception handler and the jobs'
failure hook log every failure and show it in the session it happened in, which keeps working;
no other session sees it.

Browser-free: a failure reaches the boundary the way Panel hands it over on a server
(``pn.state.execute`` runs a callback and gives its exception to ``pn.config.exception_handler``,
with the session's document current), and a served session's jobs run on a document whose next
tick comes at once.
"""

from __future__ import annotations

import asyncio
import gc
import inspect
import logging
import weakref
from typing import Any

import panel as pn
import pytest
from bokeh.document import Document
from panel.io.state import set_curdoc

import engine as eg
from gmwm_app import boundary
from gmwm_app import report_download as report_mod
from gmwm_app.app import create_app
from gmwm_app.jobs import Jobs
from gmwm_app.state import AppState


class _ServedDoc:
    """What :class:`Jobs` uses of a served session's document, on an asyncio loop: a next-tick
    callback runs in a later iteration of the loop, as on Bokeh's server."""

    session_context = object()

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop

    def add_next_tick_callback(self, fn: Any) -> None:
        if inspect.iscoroutinefunction(fn):
            self.loop.create_task(fn())
        else:
            self.loop.call_soon(fn)

    def on_session_destroyed(self, *callbacks: Any) -> None:
        pass


def _on_the_loop(loop: asyncio.AbstractEventLoop, start: Any, until: Any) -> None:
    """Call ``start()`` on ``loop`` and run it until ``until()`` (at most 500 iterations)."""

    async def main() -> None:
        start()
        for _ in range(500):
            await asyncio.sleep(0.001)
            if until():
                return
        raise AssertionError("the jobs did not end")

    loop.run_until_complete(main())


def _session(app_demo: Any) -> tuple[Any, Document]:
    """A session's app built with its own (unserved) document current, as the server builds
    it; returns (GMWMApp, document)."""
    doc = Document()
    with set_curdoc(doc):
        app = create_app().gmwm_app
    assert app.jobs.doc is doc and app.state.error == ""
    return app, doc


def _as_panel_runs_it(doc: Any, callback: Any) -> None:
    """Run ``callback`` as Panel runs a session's callback: its exception goes to
    ``pn.config.exception_handler`` with the session's document current."""
    with set_curdoc(doc):
        pn.state.execute(callback, schedule=False)


def test_the_boundary_is_panels_exception_handler(app_demo: Any) -> None:
    _session(app_demo)
    assert pn.config.exception_handler is boundary.handle


def test_a_message_is_the_error_alone_when_the_user_caused_it_else_unexpected() -> None:
    assert boundary.describe("Reading a.csv", eg.errors.LoadError("a.csv: column 3 is empty")) == (
        "Reading a.csv: a.csv: column 3 is empty"
    )
    assert boundary.describe("Reading a.csv", OSError("no such file")) == (
        "Reading a.csv: no such file"
    )
    assert boundary.describe("Drawing", KeyError("gyro_q")) == (
        "Drawing: unexpected KeyError: gyro_q"
    )


def test_an_unexpected_failure_in_a_watcher_is_shown_in_its_session_only(
    app_demo: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    a, doc_a = _session(app_demo)
    b, _doc_b = _session(app_demo)

    def broken(self: AppState, fs: Any) -> bool:
        raise RuntimeError("fs watcher exploded")

    monkeypatch.setattr(AppState, "set_fs", broken)
    fs = a.state.fs
    with caplog.at_level(logging.ERROR, logger="gmwm_app.boundary"):
        # the browser changed the fs field: the widget's watcher raises
        _as_panel_runs_it(doc_a, lambda: a.fs_input.param.update(value=2 * fs))
    assert a.state.error == (
        "Could not update the page: unexpected RuntimeError: fs watcher exploded"
    )
    assert a.alert.visible and "fs watcher exploded" in a.alert.object
    rec = [r for r in caplog.records if "fs watcher exploded" in r.getMessage()]
    assert rec and rec[0].exc_info is not None  # the traceback is in the log
    assert b.state.error == "" and not b.alert.visible  # the other session saw nothing
    # the session keeps working: its next action succeeds and clears the message
    monkeypatch.undo()
    _as_panel_runs_it(doc_a, lambda: a.state.set_model("WN+RW"))
    assert a.state.result is not None and a.state.error == ""


def test_an_unexpected_failure_of_an_action_reaches_the_boundary(
    app_demo: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    a, doc = _session(app_demo)

    def broken(*_a: Any, **_kw: Any) -> None:
        raise RuntimeError("solver exploded")

    monkeypatch.setattr(AppState, "_fit_or_none", broken)
    with pytest.raises(RuntimeError):  # a bug is not an error the action expects
        a.state.set_model("WN+RW")
    with caplog.at_level(logging.ERROR):
        _as_panel_runs_it(doc, lambda: a.state.set_model("WN+RW"))
    assert a.state.error == "Could not update the page: unexpected RuntimeError: solver exploded"
    assert any(r.exc_info for r in caplog.records if "solver exploded" in r.getMessage())
    monkeypatch.undo()
    assert a.state.set_model("WN+RW") and a.state.error == ""


@pytest.mark.parametrize("bug", [KeyError("gyro_q"), TypeError("bad operand"), IndexError("3")])
def test_a_key_type_or_index_error_of_an_action_is_a_bug_not_a_bad_input(
    app_demo: Any,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    bug: Exception,
) -> None:
    # an action's guard takes what a user causes (an engine error, ValueError, OSError) and
    # lets the rest reach the boundary: logged with its traceback, shown as unexpected
    a, doc = _session(app_demo)

    def broken(*_a: Any, **_kw: Any) -> None:
        raise bug

    monkeypatch.setattr(AppState, "_fit_or_none", broken)
    with pytest.raises(type(bug)):
        a.state.set_model("WN+RW")
    with caplog.at_level(logging.ERROR):
        _as_panel_runs_it(doc, lambda: a.state.set_model("WN+RW"))
    name = type(bug).__name__
    assert a.state.error.startswith(f"Could not update the page: unexpected {name}: ")
    assert any(r.exc_info for r in caplog.records if name in r.getMessage())
    # bad input still is a message of the action, with no traceback
    monkeypatch.undo()
    assert a.state.set_model("WN+RW") and a.state.error == ""
    assert not a.state.set_model("XX+WN") and a.state.error.startswith("Could not set the model")
    assert not a.state.remove_process(7) and "no process number 8" in a.state.error
    assert not a.state.set_whatif_value("WN.sigma2", None)  # type: ignore[arg-type]
    assert "must be a finite number, got None" in a.state.error


def test_a_failed_job_without_its_own_fail_is_shown_in_its_session_only(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.new_event_loop()
    shown: dict[str, list[str]] = {"a": [], "b": []}
    doc_a, doc_b = _ServedDoc(loop), _ServedDoc(loop)
    boundary.install()
    boundary.attach(doc_a, shown["a"].append)
    boundary.attach(doc_b, shown["b"].append)
    jobs_a, jobs_b = Jobs(doc_a), Jobs(doc_b)
    assert jobs_a.served

    def broken() -> None:
        raise RuntimeError("the worker broke")

    applied: list[Any] = []
    ended: list[str] = []
    with caplog.at_level(logging.ERROR, logger="gmwm_app.boundary"):
        _on_the_loop(
            loop,
            lambda: jobs_a.run(broken, applied.append, done=lambda: ended.append("a")),
            lambda: ended,
        )
    assert shown == {
        "a": ["A computation failed: unexpected RuntimeError: the worker broke"],
        "b": [],
    }
    assert applied == []
    assert any(r.exc_info for r in caplog.records if "the worker broke" in r.getMessage())

    # the session keeps working, and so does the other one
    def more() -> None:
        jobs_a.run(lambda: 42, applied.append, done=lambda: ended.append("a"))
        jobs_b.run(lambda: 7, applied.append, done=lambda: ended.append("b"))

    _on_the_loop(loop, more, lambda: len(ended) == 3)
    loop.close()
    assert sorted(applied) == [7, 42] and len(shown["a"]) == 1 and shown["b"] == []


def test_a_failure_applying_a_jobs_result_is_shown_in_its_session(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.new_event_loop()
    shown: list[str] = []
    doc = _ServedDoc(loop)
    boundary.install()
    boundary.attach(doc, shown.append)
    jobs = Jobs(doc)
    done: list[str] = []

    def apply(_out: Any) -> None:
        raise RuntimeError("a figure could not be drawn")

    def start() -> None:  # nothing leaves the loop
        jobs.run(lambda: 1, apply, done=lambda: done.append("done"))
        jobs.locked(lambda: apply(None))

    with caplog.at_level(logging.ERROR, logger="gmwm_app.boundary"):
        _on_the_loop(loop, start, lambda: len(shown) == 2)
    loop.close()
    what = "Could not update the page: unexpected RuntimeError: a figure could not be drawn"
    assert shown == [what, what]
    assert done == ["done"]  # done runs all the same
    assert all(r.exc_info for r in caplog.records if "could not be drawn" in r.getMessage())


def test_an_unexpected_failure_in_the_report_download_is_shown(
    app_demo: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    a, doc = _session(app_demo)
    assert a.state.set_model("WN+RW")
    button = a.report_download

    def broken(_state: Any) -> str:
        raise RuntimeError("the report's figure broke")

    monkeypatch.setattr(report_mod, "session_report", broken)
    _as_panel_runs_it(doc, button.callback)  # what Panel runs on the button's click
    assert a.state.error == (
        "Could not update the page: unexpected RuntimeError: the report's figure broke"
    )
    monkeypatch.undo()
    a.state.show_notice("", clear_error=True)
    page = button.callback().getvalue()  # the session keeps working: the report is made
    assert page.startswith("<!DOCTYPE html>") and a.state.error == ""
    # an expected failure (no fit) is the reason, in the page and in the file
    a.state.set_model("")
    text = button.callback().getvalue()
    assert a.state.error.startswith("Download report: fit a model first") and "fit a model" in text


def test_typing_abc_in_the_datasheet_check_shows_a_message_and_keeps_working(app: Any) -> None:
    view = app.open_view("Datasheet check")
    view.set_values({"arw": "0.4", "bi": "12", "rrw": "", "q": ""})
    assert view.result is not None and view.message.alert_type == "info"  # "no GMWM fit"
    view.inputs[0].value = "abc"  # typed in the ARW field
    assert view.message.visible and view.message.alert_type == "warning"
    assert view.message.object == "ARW: 'abc' is not a number"
    assert view.result is None and list(view.wv_src.data["ds"]) == []  # not the previous check
    assert app.state.error == ""
    view.inputs[0].value = "0.5"
    assert view.result is not None and view.message.alert_type == "info"
    assert "ARW 0.5 deg/sqrt(h)" in view.status.object


def test_the_boundary_keeps_no_ended_session_alive() -> None:
    # a session's page refers to its document (the state's hold, the jobs): the boundary holds
    # the page's show method weakly, so an ended session's document and page can go
    class Page:
        def __init__(self, doc: Document) -> None:
            self.doc = doc
            self.shown: list[str] = []

        def show(self, message: str) -> None:
            self.shown.append(message)

    doc = Document()
    page = Page(doc)
    boundary.attach(doc, page.show)
    with set_curdoc(doc):
        boundary.report(ValueError("bad value"), "Setting fs")
    assert page.shown == ["Setting fs: bad value"]
    gone = weakref.ref(doc)
    del doc, page
    gc.collect()
    assert gone() is None
