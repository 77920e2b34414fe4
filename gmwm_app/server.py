"""Serving the app: one Bokeh application whose pages are built off the server loop.

:func:`create_application` is what ``gmwm-app`` serves; :class:`PagePool` keeps pages built
ahead of demand (``gmwm-app --prebuild N``); :func:`limit_blas_threads` keeps OpenBLAS's
threads from fighting the loop for the cores. The Panel internals this needs are
in :mod:`gmwm_app._panel_compat`; the page itself is :func:`gmwm_app.app.create_app`.
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
import os
import sys
import threading
import weakref
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import Any, NamedTuple

import numpy as np
import panel as pn
from bokeh.document import Document
from bokeh.document.events import SessionCallbackAdded, SessionCallbackRemoved

import engine as eg
from engine.wv import set_blas_threads
from gmwm_app import _panel_compat as compat
from gmwm_app import hdf5_guard
from gmwm_app._panel_compat import building_off_loop
from gmwm_app.app import GMWMApp, app_of, create_app, live_apps, set_listed

__all__ = [
    "create_application",
    "create_app_factory",
    "limit_blas_threads",
    "limit_blas_once",
    "favour_loop_latency",
    "build_document",
    "serialize_ahead",
    "PULLS",
    "PagePool",
    "served_apps",
    "RequestShape",
    "request_shape",
    "default_prebuild",
    "PAGE_MB",
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
    nine pages took the same 5.4-5.7 s to open (tests/app/test_server_load.py).
    """
    previous = sys.getswitchinterval()
    sys.setswitchinterval(interval_s)
    return previous


def limit_blas_threads(n: int = 1) -> bool:
    """Limit the BLAS (OpenBLAS) thread pool of this process to ``n`` threads.

    In a server, the event loop thread is busy while a worker computes a WV; OpenBLAS's own
    threads then fight them for the cores at every small ``np.dot``, which made a 1e6-sample
    WV 30x slower (1 s instead of 30 ms) on a 2-core machine. The engine's matrices are small,
    so one BLAS thread loses nothing (:func:`engine.wv.set_blas_threads`). Returns True
    when a limit was set.
    """
    return set_blas_threads(n)


_BLAS_LIMITED = False


def limit_blas_once() -> None:
    """:func:`limit_blas_threads` to one thread, the first time it is called."""
    global _BLAS_LIMITED
    if not _BLAS_LIMITED:
        _BLAS_LIMITED = True
        limit_blas_threads(1)


def warm_engine() -> None:
    """Run, once per process and before any page is served, what a page's first fit runs on
    the server loop for the first time: the lazy imports of the fit and of its IEEE table
    (``scipy.optimize``, ``scipy.stats``: about a second). ``import engine`` stays light for
    the CLI; on a server that one-time cost would block the loop while the first pages open
    (tests/app/test_server_load.py: loop probe 0.4-0.6 s before the IEEE rows, 1.2-1.8 s after them
    without this)."""
    x = np.random.default_rng(0).normal(size=4096)
    eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0, unit="deg/s"), "GM+WN+RW").ieee  # noqa: B018


def create_app_factory(
    path: str | None = None,
) -> Callable[[], pn.template.BootstrapTemplate]:
    """A function that builds a fresh page per session (for ``pn.serve``), preloading ``path``
    (and warming the engine's lazy imports first: :func:`warm_engine`)."""
    warm_engine()

    def factory() -> pn.template.BootstrapTemplate:
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
            return (
                Document.to_json(doc, deferred=True)
                if deferred
                else Document.to_json(doc, deferred=False)
            )
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


#: Server memory of one page built ahead (MB; bench_load.py: 4.3-4.7 MB per session).
PAGE_MB = 5.0
#: Pages kept ready by default (a class), and the share of the available memory they may take.
DEFAULT_PREBUILD = 32
PREBUILD_MEMORY_SHARE = 0.1


def default_prebuild(available_mb: float | None = None) -> int:
    """Pages a server process keeps ready by default: :data:`DEFAULT_PREBUILD`, fewer when
    they would take more than :data:`PREBUILD_MEMORY_SHARE` of the available memory.

    Parameters
    ----------
    available_mb : float, optional
        The memory available (MB); by default ``MemAvailable`` of ``/proc/meminfo`` (when it
        cannot be read: :data:`DEFAULT_PREBUILD`).
    """
    if available_mb is None:
        try:
            with open("/proc/meminfo", encoding="ascii") as f:
                kb = next(int(ln.split()[1]) for ln in f if ln.startswith("MemAvailable:"))
            available_mb = kb / 1024
        except (OSError, StopIteration, ValueError, IndexError):
            return DEFAULT_PREBUILD
    return max(0, min(DEFAULT_PREBUILD, int(available_mb * PREBUILD_MEMORY_SHARE / PAGE_MB)))


class RequestShape(NamedTuple):
    """What a page's build reads from its request: a page built for one shape is the page
    Panel would build for any request of that shape.

    The shape is the path only, not the host name or the protocol: the one part of a page
    that reads them is Panel's ``Location`` (``href``, ``hostname``, ``protocol``, ``port``),
    whose browser side sets all four from ``window.location`` when it is created; the app
    reads none of them (it writes ``search`` only, which the browser applies to its own
    location; the server-side copies of the four keep the placeholder's). A class whose browsers
    use another name than the expected one (an IP address for a host name) gets the pages
    built ahead all the same (with the host in the shape, the pool was released and rebuilt
    for it: 30 pages at once went from p95 1.18 s to 21.4 s).
    """

    path: str
    app_path: str


def request_shape(request: Any, app_url: str = "/") -> RequestShape | None:
    """The shape of a session's request (Bokeh's request proxy), or None when a page built
    ahead cannot answer it: a query (``?source=path...``: the page loads other data), no
    request, or not a ``GET``. A session created by its websocket (``APP/ws``) has the shape
    of its page (``APP``)."""
    if request is None or getattr(request, "method", "GET") != "GET":
        return None
    if request.arguments:  # (for a websocket: the page request's, from the session token)
        return None
    app_path = getattr(request, "app_path", None) or app_url
    path = str(request.path)
    if path == app_url.rstrip("/") + "/ws":
        # a session created by its websocket: with --num-procs, the page's HTML came from
        # another process (Bokeh creates the session again where the websocket lands); the
        # page is the one of the application's path
        path = app_url
    return RequestShape(path, app_path)


def served_apps() -> list[GMWMApp]:
    """The app objects of the sessions being served now (:func:`gmwm_app.app.live_apps`
    whose document still has its session).

    A session's app leaves ``live_apps()`` only when it is garbage-collected: the page and
    its app refer to each other (the template holds the app's watchers, the app its
    template), so that takes a full collection of the cyclic garbage collector, which Panel
    schedules 5 s after a session ends and which may come much later (Panel runs none while
    sessions keep ending; a long-lived server's gen-2 collections are rare). Its document
    drops its session context at once when Bokeh discards the session (Panel's
    ``_destroy_document``): a page request whose websocket never came, or a tab closed
    while its data loaded, is then no session opening or loading any more.
    """
    return [app for app in live_apps() if app.served]


def _lowest_priority() -> None:
    """Run this thread at the lowest CPU priority (Linux: nice is per thread)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
    except (AttributeError, OSError):  # not Linux, or not allowed
        pass


class PagePool:
    """Page documents built ahead of demand, for the server's default start.

    Opening a page costs about 0.8 s of server CPU (its Bokeh document, ~340 models); a
    process serves at most one core of it, so a class opening the app at once waited for the
    sum. While the server is idle, a thread keeps up to ``size`` pages built (each a fresh
    session state and document, built exactly as a session's page is built, under a
    placeholder session context with a request of the expected shape:
    :func:`gmwm_app._panel_compat.placeholder_session`); a session whose request has that
    shape and no query gets one (:meth:`take`: the session context, request, id, hooks and
    Panel's document initialisation are the session's own, bound then), others build their
    page on demand.

    Refilling never competes with the sessions: :meth:`step` (called periodically on the
    server loop) starts one page build in a low-priority thread only when no page is being
    built on demand, no session is opening (handed over or built, its first data not yet
    shown) and no session is loading data; otherwise it counts a pause
    (``stats["paused"]``). A session whose request has another shape (another path of the
    application) makes the pool serve that shape from then on: the pages built for the old
    one are released. The host name is not part of the shape (:class:`RequestShape`).

    Parameters
    ----------
    size : int
        Pages kept ready (0: none).
    build : callable
        ``build(doc)`` builds a page into ``doc`` in the calling thread and returns its
        :class:`~gmwm_app.app.GMWMApp` (the server's off-loop page build).
    server_context : bokeh.server.contexts.BokehServerContext
        The server's context (for the placeholder session contexts).
    shape : RequestShape, optional
        The request shape expected (e.g. ``/``, ``/``); without it the pool starts with the
        first session of the default start.
    host : str
        The ``Host`` of the placeholder request the pages are built under (``HOST:PORT``; any
        name serves every host: see :class:`RequestShape`).
    app_url : str
        The application's URL path.
    on_demand : callable, optional
        The number of pages being built on demand now.
    on_full : callable, optional
        ``on_full(size)`` when the pool becomes full (called in the build thread).
    sessions : callable
        The app objects of the sessions (:func:`served_apps`), each with its ``busy``
        (loading data) and ``ready`` (first data shown) flags.
    """

    #: Consecutive failed builds after which the pool stops building.
    MAX_FAILURES = 3

    def __init__(
        self,
        size: int,
        build: Callable[[Any], GMWMApp],
        server_context: Any,
        *,
        shape: RequestShape | None = None,
        host: str = "localhost",
        app_url: str = "/",
        on_demand: Callable[[], int] = lambda: 0,
        on_full: Callable[[int], None] | None = None,
        sessions: Callable[[], Iterable[Any]] = served_apps,
    ) -> None:
        self.size = max(0, int(size))
        self.shape = shape
        self.host = host
        self.app_url = app_url
        self._build_page = build
        self._server_context = server_context
        self._on_demand = on_demand
        self._sessions = sessions
        self._on_full = on_full
        self._ready: deque[tuple[Any, Any, GMWMApp]] = deque()
        self._building: Future | None = None
        self._failures = 0
        self._stepper: Any = None
        self._lock = threading.Lock()
        self.stats = {"built": 0, "handed": 0, "paused": 0, "released": 0, "failed": 0}
        self._executor = ThreadPoolExecutor(
            max_workers=1, thread_name_prefix="gmwm-prebuild", initializer=_lowest_priority
        )

    def __len__(self) -> int:
        return len(self._ready)

    @property
    def building(self) -> bool:
        """Whether a page is being built for the pool now."""
        return self._building is not None and not self._building.done()

    def busy(self) -> bool:
        """Whether the sessions need the server now: a page built on demand, a session
        opening (its first data not yet shown) or loading data."""
        if self._on_demand() > 0:
            return True
        try:
            apps = list(self._sessions())
        except RuntimeError:  # the registry changed meanwhile (a page built): look next step
            return True
        return any(app.busy or not app.ready for app in apps)

    def _tick(self) -> None:
        """:meth:`step`, as the periodic callback of :meth:`start_stepping`."""
        self.step()

    def step(self) -> bool:
        """Start building one page if the pool is short and the server idle (on the loop);
        whether a build started."""
        if self.size == 0 or self.shape is None or len(self._ready) >= self.size:
            return False
        if self.building or self._failures >= self.MAX_FAILURES:
            return False
        if self.busy():
            self.stats["paused"] += 1
            return False
        self._building = self._executor.submit(
            contextvars.Context().run, self._build_one, self.shape
        )
        return True

    def _build_one(self, shape: RequestShape) -> None:
        from bokeh.document import Document

        doc = Document()
        context = compat.placeholder_session(
            doc, self._server_context, protocol="http", host=self.host, **shape._asdict()
        )
        try:
            app = self._build_page(doc)
        except Exception:
            self._failures += 1
            self.stats["failed"] += 1
            log.exception("building a page ahead failed")
            compat.discard_document(doc, context)
            return
        self._failures = 0
        set_listed(app, False)  # not a session's yet
        kept = False
        with self._lock:
            if shape == self.shape:
                self._ready.append((doc, context, app))
                self.stats["built"] += 1
                full = len(self._ready) >= self.size
                kept = True
        if not kept:  # the pool moved to another shape meanwhile
            self._release(doc, context)
        elif full and self._on_full is not None:
            self._on_full(self.size)

    def take(self, request: Any) -> Any:
        """A page document built ahead for a new session's ``request``, or None (build it on
        demand). On the loop, as the session is created; the document's placeholder session
        context is dropped (the caller gives it the session's)."""
        shape = request_shape(request, self.app_url)
        if shape is None or self.size == 0:
            return None
        entry = None
        with self._lock:
            old = []
            if shape != self.shape:
                old = list(self._ready)
                self._ready.clear()
                self.shape = shape
            elif self._ready:
                entry = self._ready.popleft()
        for doc, context, _app in old:
            self._release(doc, context)
        if entry is None:
            return None
        doc, _context, app = entry
        set_listed(app, True)  # a session's from now on (the newest)
        self.stats["handed"] += 1
        return doc

    def _release(self, doc: Any, context: Any) -> None:
        self.stats["released"] += 1
        try:
            compat.discard_document(doc, context)
        except Exception:
            log.exception("releasing a page built ahead failed")

    def start_stepping(self, period_ms: float) -> None:
        """Call :meth:`step` every ``period_ms`` on the current (the server's) event loop."""
        from tornado.ioloop import PeriodicCallback

        self._stepper = PeriodicCallback(self._tick, period_ms)
        self._stepper.start()

    def close(self) -> None:
        """Stop building and release the pages built ahead."""
        self.size = 0
        if self._stepper is not None:
            self._stepper.stop()
        self._executor.shutdown(wait=True, cancel_futures=True)  # a build ends within ~1 s
        with self._lock:
            old = list(self._ready)
            self._ready.clear()
        for doc, context, _app in old:
            self._release(doc, context)


#: How often the pools look whether they can build a page (ms, on the server loop).
POOL_STEP_MS = 250

#: The page pools of this process (one per application served with ``prebuild``).
POOLS: list[PagePool] = []


def create_application(
    path: str | None = None,
    *,
    prebuild: int = 0,
    host: str | None = None,
    on_full: Callable[[int], None] | None = None,
) -> Any:
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
    prebuild : int
        Pages kept built ahead of demand in each server process (:class:`PagePool`; 0: none).
    host : str, optional
        The host (``HOST:PORT``) the browsers are expected to ask for: the placeholder
        request the pages are built under (``localhost`` by default). Browsers that ask for
        another name get the same pages (:class:`RequestShape`); the pool starts at once.
    on_full : callable, optional
        ``on_full(prebuild)`` each time the pool becomes full.

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
    title = "GMWM: stochastic calibration of inertial sensors"
    # one page built (and dropped) before serving: the first-time costs of a page (lazy
    # imports, templates, the first fit's IEEE table) are paid here, not on the loop while the
    # first students' pages open (tests/app/test_server_load.py: loop probe 1.2-1.8 -> 0.4-0.6 s)
    set_listed(app_of(factory()), False)

    class OffLoopHandler(FunctionHandler):
        on_demand = 0  # pages being built on demand now

        def on_server_loaded(self, server_context: Any) -> None:
            # the HDF5 watchdog's helper process, started now so that the first file does not
            # wait; in every server process (--num-procs forks before this), never before a
            # fork (a thread of the parent could hold the guard's lock in the child)
            threading.Thread(target=hdf5_guard.start_helper, daemon=True, name="gmwm-guard").start()
            super().on_server_loaded(server_context)
            if prebuild > 0 and compat.pool_supported():
                self._start_pool(server_context)

        def _start_pool(self, server_context: Any) -> None:
            app_context = server_context.application_context
            app = app_context.application
            url = app_context.url or "/"
            pool = PagePool(
                prebuild,
                partial(self._build_ahead, app=app),
                server_context,
                shape=RequestShape(url, url),
                host=host or "localhost",
                app_url=url,
                on_demand=lambda: self.on_demand,
                on_full=on_full,
            )
            compat.hand_over_sessions(app_context, pool.take)
            pool.start_stepping(POOL_STEP_MS)  # on this (the server's) loop
            POOLS.append(pool)

        async def on_session_created(self, session_context: Any) -> None:
            await super().on_session_created(session_context)
            if not compat.supported():  # another Panel: built on the loop (modify_document)
                return
            doc = session_context._document
            if doc in _PREBUILT:  # a page built ahead (PagePool), handed over
                return
            app = session_context.server_context.application_context.application
            loop = asyncio.get_running_loop()
            OffLoopHandler.on_demand += 1
            try:
                # in a context of its own: whatever the build leaves in context variables
                # (Panel's current document) must not stay with the pool's thread
                await loop.run_in_executor(
                    _build_pool(), contextvars.Context().run, self._build, doc, app
                )
            except Exception:  # built again on the loop by modify_document
                log.exception("building the page off the loop failed; building it on the loop")
            finally:
                OffLoopHandler.on_demand -= 1

        def _build(self, doc: Any, app: Any, func: Callable[[Any], Any] | None = None) -> None:
            build_document(func or self._func, doc)
            # the stylesheet patch Panel's page handler would do on the loop, done here
            try:
                compat.patch_css_off_loop(doc, app)
            except Exception:  # the handler patches them on the loop, as usual
                log.exception("patching the page's stylesheets off the loop failed")
            serialize_ahead(doc)  # the browser's pull of the document, answered off the loop
            _PREBUILT.add(doc)

        def _build_ahead(self, doc: Any, app: Any) -> GMWMApp:
            """The page of a session to come, built as :meth:`_build` builds a session's."""
            pages: list[Any] = []

            def page() -> Any:
                pages.append(factory())
                return pages[-1]

            self._build(doc, app, partial(compat.eval_panel, page, title))
            return app_of(pages[0])

        def modify_document(self, doc: Any) -> None:
            if doc in _PREBUILT:
                _PREBUILT.discard(doc)
                return
            super().modify_document(doc)

    handler = OffLoopHandler(partial(compat.eval_panel, factory, title))
    return Application(handler, admin=False)
