"""The job runner of one session: work in a worker thread, its result applied on the page.

Every view of a session gets the same :class:`Jobs` (with the session state) instead of the
page object. A job is a callable run in the shared worker pool (:data:`EXECUTOR`; numpy
releases the GIL there, so the server loop and the other sessions stay free); its result is
applied with the session's document lock on the server loop, a failure is handed to the
job's ``fail`` (an in-page message, never a traceback; without one, to the error boundary,
:mod:`gmwm_app.boundary`), a newer job of the same key
supersedes a running one (the stale result is dropped), and :meth:`Jobs.cancel` drops a
running job's result. Outside a server (tests, scripts) a job is waited for.

Fair share: a session occupies at most ``session_jobs`` of the shared worker threads at once
(:attr:`gmwm_app.limits.ServerLimits.session_jobs`), and long work (rankings, dependence
tests) runs in a pool of its own (:data:`LONG_EXECUTOR`), so that long work of many sessions
never holds the threads every session's loads and fits need; its other jobs wait their turn on the
loop (not in a thread), and a job whose turn comes after a newer job of its key superseded
it, or after its session ended, is skipped without running. When the session ends, the
cancel events its views registered (:meth:`Jobs.abandon_on_close`) are set, so that a long
job (a ranking) stops at its next step.

Turns on the loop: the results of jobs are applied one per iteration of the server loop, in
the order they came back (:class:`LoopTurns`). asyncio runs every callback that is ready when
an iteration starts before it polls the sockets again, so nine pages whose data came back
together (a class opening the app at once) would apply theirs back to back, about 0.05 s of
CPU each, while every request to the server waits behind them; taking turns, requests are
read between two of them.
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import Any

from bokeh.document import Document
from panel.io.state import set_curdoc
from panel.io.state import state as pn_state

from gmwm_app.boundary import report
from gmwm_app.limits import current as current_limits

__all__ = [
    "EXECUTOR",
    "LONG_EXECUTOR",
    "Jobs",
    "LoopTurns",
    "ProgressThrottle",
    "lower_priority",
    "job_progress",
    "job_controls",
]

log = logging.getLogger(__name__)


def lower_priority() -> None:
    """Run this worker thread at a lower CPU priority (Linux: nice applies per thread), so
    that on a busy machine the event loop, which serves every session, comes first."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 10)
    except (AttributeError, OSError):  # not Linux, or not allowed: keep the priority
        pass


#: Worker threads for reading files, computing WVs and fits (shared by every session).
EXECUTOR = ThreadPoolExecutor(
    max_workers=4, thread_name_prefix="gmwm-app", initializer=lower_priority
)
#: Worker threads for long computations (rankings, dependence tests), shared by every session:
#: at most this many run at once in a process, the others wait their turn, so that long work
#: never holds the threads of :data:`EXECUTOR` that every session's loads and fits need.
LONG_WORKERS = 2
LONG_EXECUTOR = ThreadPoolExecutor(
    max_workers=LONG_WORKERS, thread_name_prefix="gmwm-app-long", initializer=lower_priority
)


def _ignore(*_args: Any) -> None:
    """A hook that does nothing."""


class ProgressThrottle:
    """Lets a job's progress through at most every ``interval`` seconds, and always at the end.

    Parameters
    ----------
    interval : float
        Shortest time between two updates (s).
    """

    def __init__(self, interval: float = 0.1) -> None:
        self.interval = interval
        self.last = 0.0

    def due(self, done: int, total: int) -> bool:
        """Whether step ``done`` of ``total`` is shown (it is then the last one shown)."""
        now = time.perf_counter()
        if done == total or now - self.last > self.interval:
            self.last = now
            return True
        return False

    def step(
        self,
        done: int,
        total: int,
        observer: Callable[[int, int], None] | None,
        cancel: threading.Event,
        cancelled: type[Exception],
    ) -> int | None:
        """The head of a job's progress callback (worker thread): tell ``observer``, raise
        ``cancelled`` once ``cancel`` is set, and return the bar's value (0-100) when an update
        is due (:meth:`due`), else None."""
        if observer is not None:
            observer(done, total)
        if cancel.is_set():
            raise cancelled
        return int(100 * done / max(total, 1)) if self.due(done, total) else None


class LoopTurns:
    """Turns on one event loop: each caller of :meth:`wait` goes on in an iteration of the
    loop of its own, first come first served.

    A turn is given by a callback that the loop runs once per iteration (``call_soon`` from a
    callback runs in the next one), after it has polled the sockets: between two turns the
    loop reads the requests that arrived. :meth:`of` gives the turns of the running loop.

    Parameters
    ----------
    loop : asyncio.AbstractEventLoop
        The loop whose iterations are shared.
    """

    _of_loop: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, LoopTurns] = (
        weakref.WeakKeyDictionary()
    )

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self._waiting: deque[asyncio.Future[None]] = deque()
        self._giving = False

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop | None = None) -> LoopTurns:
        """The turns of ``loop`` (default: the running loop), made on first use."""
        loop = loop if loop is not None else asyncio.get_running_loop()
        turns = cls._of_loop.get(loop)
        if turns is None:
            turns = cls._of_loop[loop] = cls(loop)
        return turns

    @property
    def waiting(self) -> int:
        """How many callers wait for their turn."""
        return len(self._waiting)

    async def wait(self) -> None:
        """Return in this caller's turn (on the loop's thread)."""
        turn = self.loop.create_future()
        self._waiting.append(turn)
        if not self._giving:
            self._giving = True
            self.loop.call_soon(self._give)
        await turn

    def _give(self) -> None:
        """Give the next turn (a waiter cancelled meanwhile has none), then the next one in
        the next iteration."""
        while self._waiting:
            turn = self._waiting.popleft()
            if not turn.done():
                turn.set_result(None)
                break
        if self._waiting:
            self.loop.call_soon(self._give)
        else:
            self._giving = False


class Jobs:
    """Run work off the loop and apply it on the page, for one session.

    Parameters
    ----------
    doc : bokeh.document.Document, optional
        The session's document (default: Panel's current document). Without a served
        document every job runs at once, in the calling thread.

    Attributes
    ----------
    busy : callable
        ``busy(on, message)``: the page-wide loading indicator (set by the page).
    failed : callable
        ``failed(message, error)``: a page-wide load failed (set by the page).
    settled : callable
        ``settled()``: a page-wide load ended, well or not (set by the page).
    install : callable
        ``install(loaded)``: make newly read data the session's (set by the page).
    """

    def __init__(self, doc: Any = None) -> None:
        self.doc = doc if doc is not None else pn_state.curdoc
        self._latest: dict[str, int] = {}
        self._count = 0
        self._loads = 0
        self.busy: Callable[[bool, str], None] = _ignore
        self.failed: Callable[[str, BaseException], None] = _ignore
        self.settled: Callable[[], None] = _ignore
        self.install: Callable[[Any], None] = _ignore
        self.closed = False  # the session ended: nothing more is started
        self.skipped = 0  # jobs not run (superseded or session ended before their turn)
        self._slots: asyncio.Semaphore | None = None
        self._on_close: list[Callable[[], Any]] = []
        if self.served:
            self._served_doc().on_session_destroyed(self._session_ended)

    def _session_ended(self, session_context: Any) -> None:
        """The session ended (Bokeh's session-destroyed callback, whose signature Bokeh
        checks: one argument named ``session_context``): start nothing more, stop the jobs
        that can stop."""
        self.closed = True
        for fn in self._on_close:
            try:
                fn()
            except Exception:  # Bokeh's session-end callback: the others must still run
                log.exception("a session-end callback failed")

    def on_close(self, fn: Callable[[], Any]) -> None:
        """Call ``fn()`` when the session ends (at once if it has ended)."""
        self._on_close.append(fn)
        if self.closed:
            fn()

    def abandon_on_close(self, event: threading.Event) -> threading.Event:
        """Set ``event`` (a job's cancel event) when the session ends; returns it."""
        self.on_close(event.set)
        return event

    @property
    def served(self) -> bool:
        """True when the session is served (a server loop applies the results)."""
        return self.doc is not None and self.doc.session_context is not None

    def _served_doc(self) -> Document:
        """The session's document (called when :attr:`served`, which implies one)."""
        if self.doc is None:  # pragma: no cover - served implies a document
            raise RuntimeError("the session has no document")
        return self.doc

    # ------------------------------------------------------------------------------------
    # the page: lock, spawn, timers
    # ------------------------------------------------------------------------------------
    def locked(self, fn: Callable[[], Any]) -> None:
        """Run ``fn`` with the session's document lock (next tick of the server loop).

        Async jobs run without the lock (so the session stays responsive); every change of
        the state, and so of Bokeh models, goes through here. Outside a server: at once.
        """
        if not self.served:
            fn()
            return
        # Panel's execute: a failure goes to the error boundary (gmwm_app.boundary), shown in
        # this session, never raised into the loop
        with set_curdoc(self._served_doc()):
            pn_state.execute(fn, schedule=True)

    def spawn(self, coro_fn: Callable[[], Any]) -> None:
        """Start an async job: on the server loop when served, else run it to completion."""
        if self.served:
            with set_curdoc(self.doc):
                pn_state.execute(coro_fn)
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no loop (tests, scripts): run it now
            asyncio.run(coro_fn())
        else:  # a notebook's loop
            loop.create_task(coro_fn())

    def later(self, fn: Callable[[], Any], ms: int) -> None:
        """Run ``fn`` on the loop after ``ms`` milliseconds (at once outside a server)."""
        if not self.served:
            fn()
            return
        self._served_doc().add_timeout_callback(fn, ms)

    def every(self, fn: Callable[[], Any], ms: int) -> Any:
        """Run ``fn`` every ``ms`` milliseconds on the loop; returns a handle (None unserved)."""
        if not self.served:
            return None
        return self._served_doc().add_periodic_callback(fn, ms)

    def stop(self, handle: Any) -> None:
        """Stop a periodic callback of :meth:`every`."""
        if handle is None or not self.served:
            return
        try:
            self._served_doc().remove_periodic_callback(handle)
        except ValueError:  # already removed
            pass

    def submit(self, work: Callable[[], Any]) -> Future:
        """Start ``work`` in the worker pool now; its future (for :meth:`run`)."""
        return EXECUTOR.submit(work)

    # ------------------------------------------------------------------------------------
    # jobs
    # ------------------------------------------------------------------------------------
    def cancel(self, key: str) -> None:
        """Drop the result of the running job of ``key`` (its ``done`` still runs)."""
        self._count += 1
        self._latest[key] = self._count

    def current(self, key: str, ticket: int) -> bool:
        """Whether ``ticket`` (from :meth:`run`) is still the latest job of ``key``."""
        return self._latest.get(key) == ticket

    def run(
        self,
        work: Callable[[], Any] | Future,
        apply: Callable[[Any], Any],
        fail: Callable[[BaseException], Any] | None = None,
        done: Callable[[], Any] | None = None,
        *,
        key: str | None = None,
        inline: bool = False,
        long: bool = False,
    ) -> int:
        """Run ``work`` in a worker, then ``apply(result)`` (or ``fail(error)``) and ``done()``.

        Parameters
        ----------
        work : callable or Future
            The computation (no Bokeh or state changes in it), or a future already running.
        apply, fail, done : callable
            Run with the document lock on the loop; ``fail`` gets the exception (default:
            the error boundary, :func:`gmwm_app.boundary.report`: logged and shown in the
            session); ``done`` runs in every case, after them. A failure of ``apply``,
            ``fail`` or ``done`` on the loop reaches the error boundary too.
        key : str, optional
            Jobs of one key supersede each other: only the latest one's ``apply``/``fail``
            runs.
        inline : bool
            Run ``work`` at once in this thread (quick work). Otherwise it runs in a worker;
            outside a server this call still waits for it and its ``apply`` (no loop to
            hand back to).
        long : bool
            Long work (seconds to minutes: a ranking, a bootstrap): it runs in
            :data:`LONG_EXECUTOR`, whose few threads every session's long work shares, never
            in the threads that loads and fits need.

        Returns
        -------
        int
            The job's ticket (see :meth:`current`).
        """
        self._count += 1
        ticket = self._count
        if key is not None:
            self._latest[key] = ticket
        if inline:
            out: Any = None
            err: BaseException | None = None
            try:
                out = work.result() if isinstance(work, Future) else work()
            except Exception as e:  # the jobs' failure hook: handed to fail (or the boundary)
                err = e
            self._finish(key, ticket, out, err, apply, fail, done)
            return ticket
        pool = LONG_EXECUTOR if long else EXECUTOR
        self.spawn(partial(self._background, key, ticket, work, apply, fail, done, pool))
        return ticket

    async def _background(
        self,
        key: str | None,
        ticket: int,
        work: Callable[[], Any] | Future,
        apply: Callable[[Any], Any],
        fail: Callable[[BaseException], Any] | None,
        done: Callable[[], Any] | None,
        pool: ThreadPoolExecutor = EXECUTOR,
    ) -> None:
        out: Any = None
        err: BaseException | None = None
        try:
            if isinstance(work, Future):
                out = await asyncio.wrap_future(work)
            else:
                if self._slots is None:  # this session's share of the worker threads
                    self._slots = asyncio.Semaphore(current_limits().session_jobs)
                async with self._slots:
                    if self.closed or (key is not None and not self.current(key, ticket)):
                        self.skipped += 1  # superseded, or nobody to show it to
                        if done is not None and not self.closed:
                            self.locked(done)
                        return
                    out = await asyncio.get_running_loop().run_in_executor(pool, work)
        except asyncio.CancelledError:  # the session closed
            if done is not None:
                self.locked(done)
            raise
        except Exception as e:  # a worker thread's top: handed to fail (or the boundary)
            err = e
        try:
            await LoopTurns.of().wait()  # one result per loop iteration (module docstring)
        except asyncio.CancelledError:  # the session closed meanwhile
            if done is not None:
                self.locked(done)
            raise
        self.locked(partial(self._finish, key, ticket, out, err, apply, fail, done))

    def _finish(
        self,
        key: str | None,
        ticket: int,
        out: Any,
        err: BaseException | None,
        apply: Callable[[Any], Any],
        fail: Callable[[BaseException], Any] | None,
        done: Callable[[], Any] | None,
    ) -> None:
        try:
            if key is None or self.current(key, ticket):
                if err is None:
                    apply(out)
                elif fail is not None:
                    fail(err)
                else:  # the jobs' failure hook: logged and shown in the session
                    report(err, "A computation failed")
        finally:
            if done is not None:
                done()

    # ------------------------------------------------------------------------------------
    # page-wide loads (data): loading indicator, failure message, install
    # ------------------------------------------------------------------------------------
    def load(
        self,
        message: str,
        work: Callable[..., Any] | Future,
        apply: Callable[[Any], Any] | None = None,
        *,
        progress: bool = False,
        fail: Callable[[BaseException], Any] | None = None,
    ) -> int:
        """Read data in a worker with the page's loading indicator on, then apply them.

        ``apply`` defaults to the page's :attr:`install`. A later load supersedes an
        earlier one; a failure goes to ``fail`` if given, else to the page's :attr:`failed`
        hook. With ``progress``,
        ``work`` is called as ``work(report)``: the worker calls ``report(j, J)`` as step
        ``j`` of ``J`` ends (e.g. a WV level), and the indicator's text becomes
        ``"<message>: level j of J"`` on the loop, while this load is the latest one.
        """
        self._loads += 1
        self.locked(lambda: self.busy(True, message))
        if progress and not isinstance(work, Future):
            ticket = self._count + 1  # the ticket run() gives this load (just below)
            work = partial(work, self.progress_reporter(message, "page-load", ticket))
        return self.run(
            work,
            apply if apply is not None else self.install,
            fail if fail is not None else (lambda e: self.failed(message, e)),
            self._settle,
            key="page-load",
        )

    def progress_reporter(self, message: str, key: str, ticket: int) -> Callable[[int, int], None]:
        """A thread-safe ``report(j, J)`` that shows ``"<message>: level j of J"`` in the
        loading indicator (through :meth:`locked`) while job ``ticket`` of ``key`` is the latest.
        """

        def show(text: str) -> None:
            if self.current(key, ticket):
                self.busy(True, text)

        def report(j: int, n: int) -> None:
            self.locked(partial(show, f"{message}: level {int(j)} of {int(n)}"))

        return report

    def _settle(self) -> None:
        self._loads -= 1
        if self._loads <= 0:  # the latest load ended (a superseded one keeps it on)
            self._loads = 0
            self.busy(False, "")
            self.settled()


def job_progress() -> Any:
    """The progress bar of a tab's background job (hidden until the job starts).

    Returns
    -------
    panel.indicators.Progress
        A full-width bar, 0 of 100.
    """
    import panel as pn

    return pn.indicators.Progress(
        value=0,
        max=100,
        bar_color="primary",
        height=14,
        visible=False,
        sizing_mode="stretch_width",
        margin=(0, 10),
    )


def job_controls(
    label: str,
    start: Callable[[], Any],
    cancel: Callable[[], Any],
    *,
    width: int,
    cancel_width: int,
    margin: tuple[int, ...] = (22, 5, 5, 5),
    description: str | None = None,
) -> tuple[Any, Any, Any]:
    """The controls of a tab's background job: its start button, a Cancel button (disabled
    until a job runs) and its progress bar (:func:`job_progress`).

    Parameters
    ----------
    label : str
        Text of the start button.
    start, cancel : callable
        Called without arguments when the start or the Cancel button is clicked.
    width, cancel_width : int
        Widths of the two buttons (px).
    margin : tuple of int
        Margin of the start button.
    description : str, optional
        Tooltip of the start button.

    Returns
    -------
    (start_button, cancel_button, progress)
    """
    import panel as pn

    run = pn.widgets.Button(
        label=label, color="primary", width=width, margin=margin, description=description
    )
    run.on_click(lambda _e: start())
    stop = pn.widgets.Button(
        label="Cancel", color="light", width=cancel_width, margin=(22, 5, 5, 5), disabled=True
    )
    stop.on_click(lambda _e: cancel())
    return run, stop, job_progress()
