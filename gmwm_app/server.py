"""Serving the app: one Bokeh application whose pages are built off the server loop.

:func:`create_application` is what ``gmwm-app`` serves; :func:`limit_blas_threads` keeps
OpenBLAS's threads from fighting the loop for the cores. The Panel internals this needs are
in :mod:`gmwm_app._panel_compat`; the page itself is :func:`gmwm_app.app.create_app`.
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
import sys
import threading
import weakref
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import Any

import panel as pn
from bokeh.document import Document
from bokeh.document.events import SessionCallbackAdded, SessionCallbackRemoved

from gmwm_app import _panel_compat as compat
from gmwm_app import hdf5_guard
from gmwm_app._panel_compat import building_off_loop
from gmwm_app.app import create_app

__all__ = [
    "create_application",
    "create_app_factory",
    "limit_blas_threads",
    "limit_blas_once",
    "favour_loop_latency",
    "build_document",
    "serialize_ahead",
    "PULLS",
]

log = logging.getLogger(__name__)


#: The GIL switch interval of a server process (s); Python's default is 0.005.
SWITCH_INTERVAL_S = 0.0005


def favour_loop_latency(interval_s: float = SWITCH_INTERVAL_S) -> float:
    """Make the event loop's turn come sooner while worker threads run Python (returns the
    previous interval).

    Page documents are built in a worker thread (about 0.8 s of pure Python each) and the
    session jobs run in others; the server loop needs the GIL for a few moments per request.
    With Python's default switch interval (5 ms) a thread waiting for the GIL waits up to 5 ms
    for each hand-over, and the loop's short steps (accept, read, write, close per request)
    queued behind the page builds: a burst of nine page opens held the loop 1.1-1.4 s on
    this 2-core machine (py-spy: the loop thread's samples were GIL waits in socket calls).
    At 0.5 ms the loop answered within 0.10-0.16 s, idle or with the other core busy, and the
    nine pages took the same 5.4-5.7 s to open (tests/test_app_load.py).
    """
    previous = sys.getswitchinterval()
    sys.setswitchinterval(interval_s)
    return previous


def limit_blas_threads(n: int = 1) -> bool:
    """Limit the BLAS (OpenBLAS) thread pool of this process to ``n`` threads.

    In a server, the event loop thread is busy while a worker computes a WV; OpenBLAS's own
    threads then fight them for the cores at every small ``np.dot``, which made a 1e6-sample
    WV 30x slower (1 s instead of 30 ms) on a 2-core machine. The engine's matrices are small,
    so one BLAS thread loses nothing (:func:`engine._blas.set_blas_threads`). Returns True
    when a limit was set.
    """
    from engine._blas import set_blas_threads

    return set_blas_threads(n)


_BLAS_LIMITED = False


def limit_blas_once() -> None:
    """:func:`limit_blas_threads` to one thread, the first time it is called."""
    global _BLAS_LIMITED
    if not _BLAS_LIMITED:
        _BLAS_LIMITED = True
        limit_blas_threads(1)


def create_app_factory(path: str | None = None) -> Callable[[], pn.viewable.Viewable]:
    """A function that builds a fresh page per session (for ``pn.serve``), preloading ``path``."""

    def factory() -> pn.viewable.Viewable:
        if path:
            return create_app(source="path", path=str(path))
        return create_app()

    return factory


_BUILD_POOL: ThreadPoolExecutor | None = None
_PREBUILT: weakref.WeakSet[Any] = weakref.WeakSet()  # documents built off the loop


def _no_validation() -> None:
    """Stands for ``Document.validate`` on documents already validated off the loop."""


_VALIDATED = threading.Event()


def _validate_first(doc: Any) -> bool:
    """Validate ``doc`` if it is the first page document of the process; whether it was.

    Bokeh validates a document after the handlers ran, on the loop (a walk of every model
    with its checks, 0.1-0.2 s). Every page of the process has the same models (the build
    does not depend on the URL: the data arrive later), so validating the first finds what
    validating each would.
    """
    if _VALIDATED.is_set():
        return False
    doc.validate()
    _VALIDATED.set()
    return True


def build_document(build: Callable[[Any], Any], doc: Any) -> None:
    """Build a session's page into ``doc`` in this (worker) thread, as Panel's ``run_app``
    does for a function handler on the loop; ``build(doc)`` is Panel's build of the page.

    Without Panel's patch of Bokeh's global ``curdoc()`` stack (shared by all threads: a build
    in a thread would leave another session's document in Bokeh's global state); the current
    document is Panel's context variable, which is per thread. The document belongs to this
    thread while it is built (Panel applies model changes directly only on the document's
    thread); Panel's ``initialize_document`` gives it to the loop's after. The document's
    model graph is recomputed once, at the end (frozen during the build: Panel adds roots and
    attaches callbacks one by one, 8-10 walks of the whole document per page otherwise), and
    only the process's first page document is validated (:func:`_validate_first`); Bokeh's
    validation on the loop is skipped for it.

    Raises
    ------
    RuntimeError
        The build produced an empty document (``doc`` is cleared on any failure, so that
        the page can be built again on the loop).
    """
    with building_off_loop(doc), doc.models.freeze():
        try:
            build(doc)  # the page factory and its document (Panel's build)
        except BaseException:
            doc.clear()  # built again on the loop
            raise
    doc.config.update(
        reconnect_session=pn.config.reconnect is True,
        notifications=None,
        notify_connection_status=False,
    )
    if not doc.roots:
        raise RuntimeError("the page factory produced an empty document")
    _validate_first(doc)
    doc.validate = _no_validation


#: How the first pulls of page documents were answered: "ahead" with the JSON serialised in
#: the build thread, "fresh" serialised on the loop (the document changed in between).
PULLS: dict[str, int] = {"ahead": 0, "fresh": 0}


def serialize_ahead(doc: Any) -> None:
    """Serialise ``doc`` now, in the build thread, for its session's first pull.

    The browser pulls the whole document once, over the websocket, and Bokeh serialises it
    then, on the server loop (``Document.to_json``, about 0.1-0.15 s per page here): during a
    burst of page opens, a click of another session waited behind a queue of these. The JSON
    made here answers that first pull, unless the document changed in between (any change
    event: then it is serialised again, on the loop, as Bokeh does); later calls are Bokeh's.
    """
    serialized = Document.to_json(doc)
    changed: list[Any] = []

    def on_change(event: Any) -> None:
        if not isinstance(event, SessionCallbackAdded | SessionCallbackRemoved):
            changed.append(event)  # (session callbacks are not part of the document's JSON)

    def to_json(*, deferred: bool = True) -> Any:
        del doc.to_json  # from now on Bokeh's own
        doc.remove_on_change(on_change)
        if changed or not deferred:
            PULLS["fresh"] += 1
            return Document.to_json(doc, deferred=deferred)
        PULLS["ahead"] += 1
        return serialized

    doc.on_change(on_change)
    doc.to_json = to_json


def _build_pool() -> ThreadPoolExecutor:
    global _BUILD_POOL
    if _BUILD_POOL is None:
        # one thread: builds queue in order (the GIL would not run two at once anyway)
        _BUILD_POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gmwm-page")
    return _BUILD_POOL


def create_application(path: str | None = None) -> Any:
    """The Bokeh application of the app for ``pn.serve``: each page is built off the loop.

    Opening a page builds a Bokeh document of about 430 models, 0.3-1 s of Python.
    Panel builds it in the server's event loop, so a burst of page opens would hold every
    other session for the sum of their builds. Here the build (the page factory and the
    document's models) runs in a worker thread while the session is being created (Bokeh
    awaits ``on_session_created`` before it initialises the document); the loop only waits
    for it, and keeps serving the other sessions, their events and their HTTP requests
    meanwhile. If the threaded build fails, the page is built on the loop as usual.

    Parameters
    ----------
    path : str, optional
        Server path preloaded by every session (``gmwm-app FILE``); the demo log otherwise.

    Returns
    -------
    panel.io.application.Application
        Pass it to ``pn.serve({"/": create_application()})``.
    """
    from panel.io.application import Application
    from panel.io.handlers import FunctionHandler

    limit_blas_once()  # a server process: see limit_blas_threads
    favour_loop_latency()  # the loop's turns between the page builds' Python
    compat.skip_repeated_css_patch()
    factory = create_app_factory(path)

    class OffLoopHandler(FunctionHandler):
        def on_server_loaded(self, server_context: Any) -> None:
            # the HDF5 watchdog's helper process, started now so that the first file does not
            # wait; in every server process (--num-procs forks before this), never before a
            # fork (a thread of the parent could hold the guard's lock in the child)
            threading.Thread(target=hdf5_guard.start_helper, daemon=True, name="gmwm-guard").start()
            super().on_server_loaded(server_context)

        async def on_session_created(self, session_context: Any) -> None:
            await super().on_session_created(session_context)
            if not compat.supported():  # another Panel: built on the loop (modify_document)
                return
            doc = session_context._document
            app = session_context.server_context.application_context.application
            loop = asyncio.get_running_loop()
            try:
                # in a context of its own: whatever the build leaves in context variables
                # (Panel's current document) must not stay with the pool's thread
                await loop.run_in_executor(
                    _build_pool(), contextvars.Context().run, self._build, doc, app
                )
            except Exception:  # built again on the loop by modify_document
                log.exception("building the page off the loop failed; building it on the loop")

        def _build(self, doc: Any, app: Any) -> None:
            build_document(self._func, doc)
            # the stylesheet patch Panel's page handler would do on the loop, done here
            try:
                compat.patch_css_off_loop(doc, app)
            except Exception:  # the handler patches them on the loop, as usual
                log.exception("patching the page's stylesheets off the loop failed")
            serialize_ahead(doc)  # the browser's pull of the document, answered off the loop
            _PREBUILT.add(doc)

        def modify_document(self, doc: Any) -> None:
            if doc in _PREBUILT:
                _PREBUILT.discard(doc)
                return
            super().modify_document(doc)

    title = "GMWM: stochastic calibration of inertial sensors"
    handler = OffLoopHandler(partial(compat.eval_panel, factory, title))
    return Application(handler, admin=False)
