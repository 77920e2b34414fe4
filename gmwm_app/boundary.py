"""The app's one error boundary: every failure of a session is logged and shown in that session.

Panel hands every exception of a callback it runs (a widget's or a button's callback, a watcher
woken by the browser, a download's callback, a periodic or next-tick callback, an async task)
to ``pn.config.exception_handler``; :func:`install` makes that :func:`handle`. The session's
job runner (:class:`gmwm_app.jobs.Jobs`) applies its results through Panel's ``execute``, so a
failure while applying a result reaches the same handler, and a job whose work fails without a
``fail`` of its own is :func:`report`-ed. Each session registers where its failures are shown
(:func:`attach`: its document and the page's error message); the handler finds the session of
the failure by Panel's current document, so a failure is shown in its own session only, and
the session keeps working (nothing is raised into the server loop).

A failure the user caused (an engine error, :class:`engine.errors.GmwmError`, or another
``ValueError`` or ``OSError``: a bad value, an unreadable file) is shown as its one-line
message and logged without a traceback; anything else is a bug: shown as "unexpected", logged
with its traceback.
"""

from __future__ import annotations

import inspect
import logging
import weakref
from collections.abc import Callable
from typing import Any

import panel as pn

from gmwm_app.data import message_of

__all__ = ["EXPECTED", "describe", "report", "watcher", "handle", "attach", "install"]

log = logging.getLogger(__name__)

#: The failures a user causes (a bad value, an unreadable file): shown as their message alone.
#: engine.errors.GmwmError derives from ValueError.
EXPECTED: tuple[type[BaseException], ...] = (ValueError, OSError)

#: What a failure is reported as when no action is named.
DEFAULT_ACTION = "Could not update the page"

#: Each session's document -> how a message is shown in that session (its page's error), held
#: weakly (a bound method as a WeakMethod): the session's state refers to its document, and a
#: strong reference here would keep every ended session alive.
_SESSIONS: weakref.WeakKeyDictionary[Any, Callable[[], Callable[[str], Any] | None]] = (
    weakref.WeakKeyDictionary()
)


def describe(
    action: str, err: BaseException, expected: tuple[type[BaseException], ...] = EXPECTED
) -> str:
    """The one line a user reads: ``"<action>: <message>"``, or ``"<action>: unexpected
    <Type>: <message>"`` for a failure that is not :data:`EXPECTED` (a bug).

    Parameters
    ----------
    action : str
        What failed, in the user's words (``"Reading run.csv"``).
    err : BaseException
        The failure.
    expected : tuple of exception classes
        The failures the user causes (default :data:`EXPECTED`).
    """
    if isinstance(err, expected):
        return f"{action}: {message_of(err)}"
    return f"{action}: unexpected {type(err).__name__}: {message_of(err)}"


def report(
    err: BaseException,
    action: str = DEFAULT_ACTION,
    show: Callable[[str], Any] | None = None,
    *,
    expected: tuple[type[BaseException], ...] = EXPECTED,
) -> str:
    """Log ``err`` and show it (:func:`describe`) in the session; returns the message.

    Parameters
    ----------
    err : BaseException
        The failure.
    action : str
        What failed (the message's start).
    show : callable, optional
        ``show(message)``: where the session shows it (default: the session of Panel's current
        document, registered by :func:`attach`; none: the log only).
    expected : tuple of exception classes
        The failures the user causes, logged without their traceback (default
        :data:`EXPECTED`; none, ``()``, where every failure is a bug: drawing the page).
    """
    message = describe(action, err, expected)
    if isinstance(err, expected):
        log.warning("%s", message)
    else:  # a bug: its traceback in the log
        log.error("%s", message, exc_info=err)
    if show is None:
        doc = pn.state.curdoc
        ref = _SESSIONS.get(doc) if doc is not None else None
        show = ref() if ref is not None else None
    if show is None:
        log.warning("no session to show it to: %s", message)
    else:
        show(message)
    return message


def watcher(
    fn: Callable[..., Any],
    action: str,
    show: Callable[[BaseException], Any],
    *args: Any,
) -> Any:
    """Run a watcher of the session state, ``fn(*args)``; a failure is :func:`report`-ed (a
    bug: with its traceback) and shown by ``show(error)``, and None returned.

    param calls the watchers of one state change one after the other: a view's failure
    raised would keep the others from drawing a change that succeeded, so a view's watcher
    stops its own failure here (``views.redraws``, ``TabView._safely``).
    """
    try:
        return fn(*args)
    except Exception as e:  # a watcher's boundary: the state's other watchers still run
        failure = e  # (``e`` is unbound after the block)
        report(failure, action, lambda _message: show(failure), expected=())
        return None


def handle(err: BaseException) -> None:
    """``pn.config.exception_handler``: :func:`report` a failure of a Panel callback in the
    session of the current document."""
    report(err)


def attach(doc: Any, show: Callable[[str], Any]) -> None:
    """Show the failures of the session of ``doc`` (a Bokeh document) with ``show(message)``.

    Without a document (outside a server, no current document) there is nothing to attach:
    the failures of Panel callbacks are logged only.
    """
    if doc is not None:
        _SESSIONS[doc] = weakref.WeakMethod(show) if inspect.ismethod(show) else (lambda: show)


def install() -> None:
    """Make :func:`handle` Panel's exception handler (once per process; idempotent)."""
    pn.config.exception_handler = handle
