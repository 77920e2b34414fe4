"""Every use of Panel internals by the app, in one place, for the Panel versions it was
written for (:data:`PANEL_VERSIONS`; ``tests/app/test_state.py`` fails on another version, so
that an upgrade forces a re-check of what is here).

* :func:`light_text_updates`: a text pane's ``object`` change sends its text only (Panel
  re-sends the pane's stylesheets, which makes Bokeh re-walk the whole document).
* :func:`building_off_loop`: marks a document as built by the current (worker) thread, as
  Panel's own ``run_app`` does for the loop's thread (``pn.state._thread_id_`` and
  ``pn.state._launching``).
* :func:`eval_panel`: Panel's function that turns a page factory into a document.
* :func:`patch_css_off_loop` and :func:`skip_repeated_css_patch`: Panel's page handler
  patches the stylesheet links of every root of a page on the server loop while it renders
  the page (``patch_model_css``: a walk of every model, about half of the loop's work per
  page open, 0.1-0.5 s on a busy machine); the off-loop build does it in its thread, and the
  handler skips a root already patched for the same ``dist_url`` (the result is the same).
* :func:`placeholder_session`, :func:`hand_over_sessions` and :func:`discard_document`: page
  documents built ahead of their sessions (:class:`gmwm_app.server.PagePool`). Bokeh creates a
  session's ``Document`` in ``ApplicationContext.create_session_if_needed``, before any hook
  of the application runs; :func:`hand_over_sessions` gives that method a document built
  ahead when there is one for the request (also checked against :data:`BOKEH_VERSIONS`).
* :func:`wrap_basic_login`: the login throttle of :mod:`gmwm_app.server_guard` around Panel's
  basic-auth login page.

On another Panel version :func:`supported` is False: the text patch is not applied and the
server builds its pages on the loop, as Panel does (slower, never wrong).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import weakref
from collections.abc import Callable, Iterator
from functools import partial
from typing import Any

import panel as pn
from panel.io.state import state as pn_state

__all__ = [
    "PANEL_VERSIONS",
    "BOKEH_VERSIONS",
    "supported",
    "pool_supported",
    "light_text_updates",
    "building_off_loop",
    "eval_panel",
    "patch_css_off_loop",
    "skip_repeated_css_patch",
    "placeholder_session",
    "hand_over_sessions",
    "discard_document",
    "wrap_basic_login",
]

#: Panel versions whose internals this module was checked against.
PANEL_VERSIONS = ("1.9.4",)


#: Bokeh versions whose session creation :func:`hand_over_sessions` reproduces.
BOKEH_VERSIONS = ("3.9.2",)


def supported() -> bool:
    """Whether the installed Panel is one this module was written for."""
    return pn.__version__ in PANEL_VERSIONS


def pool_supported() -> bool:
    """Whether page documents can be built ahead (this Panel and this Bokeh)."""
    import bokeh

    return supported() and bokeh.__version__ in BOKEH_VERSIONS


def light_text_updates() -> bool:
    """Make a text pane's ``object`` change send its text only (Panel 1.9: also stylesheets).

    Panel's HTML/Markdown/Alert panes re-send their whole property set on every ``object``
    change, the stylesheets included; the first time, that list differs from the one the page
    was built with (the template's design sheets), and a changed list of Bokeh models makes
    Bokeh recompute the graph of every model of the document: 0.05-0.1 s per pane and
    session on the server loop, with about a thousand models per page. The stylesheets a pane
    was built with are kept (they do not depend on its text). Returns whether it applied.
    """
    from panel.pane.markup import HTMLBasePane

    if not supported():
        return False

    if getattr(HTMLBasePane._update, "_gmwm_light", False):
        return True
    original = HTMLBasePane._update
    if not callable(original) or not hasattr(HTMLBasePane, "_get_properties"):
        return False  # pragma: no cover - another Panel: leave it alone

    def _update(self: Any, ref: str, model: Any) -> None:
        if getattr(self, "enable_streaming", False):
            return original(self, ref, model)
        props = self._get_properties(model.document)
        props.pop("stylesheets", None)
        model.update(**props)

    _update._gmwm_light = True  # type: ignore[attr-defined]
    HTMLBasePane._update = _update  # type: ignore[method-assign]  # the patch itself
    return True


@contextlib.contextmanager
def building_off_loop(doc: Any) -> Iterator[None]:
    """Build ``doc`` in this thread: Panel applies model changes directly on the document's
    own thread, and ``_launching`` marks a document whose page is being built (Panel's
    ``initialize_document`` gives the document to the loop's thread afterwards)."""
    pn_state._thread_id_[doc] = threading.get_ident()
    pn_state._launching.add(doc)
    try:
        yield
    finally:
        pn_state._launching.discard(doc)


def eval_panel(factory: Any, title: str, doc: Any) -> Any:
    """Panel's own build of a page (``panel.io.application._eval_panel``) into ``doc``."""
    from panel.io.application import _eval_panel

    return _eval_panel(factory, None, title, True, False, doc)


#: Roots whose stylesheets were patched off the loop, with the ``dist_url`` used.
_CSS_DONE: weakref.WeakKeyDictionary[Any, str] = weakref.WeakKeyDictionary()


def patch_css_off_loop(doc: Any, application: Any) -> str:
    """Patch the stylesheets of every root of ``doc`` as Panel's page handler will (in the
    build thread); returns the ``dist_url`` used (Panel's ``server`` resources mode)."""
    from panel.io.resources import LOCAL_DIST, patch_model_css
    from panel.io.state import set_curdoc

    application._set_session_prefix(doc)  # what initialize_document does first
    with set_curdoc(doc):
        rel = pn_state.rel_path
    dist_url = f"{rel}/{LOCAL_DIST}" if rel else LOCAL_DIST
    for root in doc.roots:
        patch_model_css(root, dist_url=dist_url)
        _CSS_DONE[root] = dist_url
    return dist_url


def skip_repeated_css_patch() -> bool:
    """Make Panel's page handler skip roots that :func:`patch_css_off_loop` patched for the
    same ``dist_url``; returns whether it applied (False on another Panel version)."""
    from panel.io import server as pn_server

    if not supported():
        return False
    original = pn_server.patch_model_css
    if getattr(original, "_gmwm_skip", False):
        return True

    def patch_model_css(root: Any, dist_url: str) -> None:
        if _CSS_DONE.get(root) == dist_url:
            return  # done in the build thread, with the same result
        original(root, dist_url=dist_url)

    patch_model_css._gmwm_skip = True  # type: ignore[attr-defined]
    pn_server.patch_model_css = patch_model_css
    return True


def placeholder_session(
    doc: Any, server_context: Any, *, protocol: str, host: str, path: str, app_path: str
) -> Any:
    """A session context for a page built ahead of its session: a request of the given shape
    (``GET path`` with the ``Host`` header ``host``, no query, no cookie, no other header).

    What Panel reads from the request while it builds a page (the location's protocol, host,
    path and query; the stylesheets' relative path) is then what the session that receives
    the page will have; its own request (cookies, headers, user) and its session id replace
    this context when the page is handed over (:func:`hand_over_sessions`).
    """
    from bokeh.core.types import ID
    from bokeh.server.contexts import BokehSessionContext, _RequestProxy
    from tornado.httputil import HTTPHeaders, HTTPServerRequest, RequestStartLine

    request = HTTPServerRequest(
        start_line=RequestStartLine("GET", path, "HTTP/1.1"), headers=HTTPHeaders({"Host": host})
    )
    request.protocol = protocol
    request.app_path = app_path  # type: ignore[attr-defined]
    context = BokehSessionContext(ID("gmwm-page-built-ahead"), server_context, doc, logout_url=None)
    context._request = _RequestProxy(request, arguments={}, cookies={}, headers={"Host": host})
    doc._session_context = weakref.ref(context)
    return context


def hand_over_sessions(application_context: Any, take: Any) -> None:
    """Make ``application_context`` create its sessions around a document from ``take``.

    ``take(request)`` gets the new session's request (Bokeh's ``_RequestProxy``) and returns a
    page document built ahead for it, or None (a new, empty ``Document`` then, as Bokeh
    does). The method is Bokeh 3.9's ``ApplicationContext.create_session_if_needed`` with
    that one change: the session context, the request, the token, the application's session
    hooks, ``initialize_document`` and the ``ServerSession`` are the session's own, created
    here as Bokeh creates them.
    """
    from bokeh.document import Document
    from bokeh.protocol.exceptions import ProtocolError
    from bokeh.server.contexts import BokehSessionContext, _RequestProxy
    from bokeh.server.session import ServerSession
    from bokeh.util.token import get_token_payload
    from tornado import gen

    self = application_context
    log = logging.getLogger("bokeh.server.contexts")

    async def create_session_if_needed(
        session_id: Any, request: Any = None, token: str | None = None
    ) -> Any:
        if len(session_id) == 0:
            raise ProtocolError("Session ID must not be empty")

        if session_id not in self._sessions and session_id not in self._pending_sessions:
            future: gen.Future[Any] = gen.Future()
            self._pending_sessions[session_id] = future

            proxy = None
            if request is not None:
                payload = get_token_payload(token) if token else {}
                if (
                    "cookies" in payload
                    and "headers" in payload
                    and "Cookie" not in payload["headers"]
                ):
                    payload["headers"]["Cookie"] = "; ".join(
                        [f"{k}={v}" for k, v in payload["cookies"].items()]
                    )
                proxy = _RequestProxy(
                    request,
                    arguments=payload.get("arguments"),
                    cookies=payload.get("cookies"),
                    headers=payload.get("headers"),
                )
            doc = None
            try:
                doc = take(proxy)
            except Exception:  # never fail a session for the pool: build it as Bokeh does
                log.exception("taking a page built ahead failed")
            if doc is None:
                doc = Document()

            session_context = BokehSessionContext(
                session_id, self.server_context, doc, logout_url=self._logout_url
            )
            session_context._request = proxy
            session_context._token = token
            doc._session_context = weakref.ref(session_context)

            try:
                await self._application.on_session_created(session_context)
            except Exception as e:
                log.error("Failed to run session creation hooks %r", e, exc_info=True)

            self._application.initialize_document(doc)

            session = ServerSession(session_id, doc, io_loop=self._loop, token=token)
            del self._pending_sessions[session_id]
            self._sessions[session_id] = session
            session_context._set_session(session)
            self._session_contexts[session_id] = session_context

            future.set_result(session)

        if session_id in self._pending_sessions:
            session = await self._pending_sessions[session_id]
        else:
            session = self._sessions[session_id]
        return session

    self.create_session_if_needed = create_session_if_needed


def discard_document(doc: Any, context: Any) -> None:
    """Release a page document built ahead that no session will get, as Bokeh and Panel
    release a session's (Bokeh's ``_discard_session``): the document is destroyed (Panel's
    ``_destroy_document``), then its session-destroyed callbacks run with ``context``."""
    from panel.io.application import _on_session_destroyed
    from panel.io.document import _destroy_document

    doc.destroy = partial(_destroy_document, doc)  # as Panel's initialize_document sets it
    try:
        doc.destroy(None)
    finally:
        _on_session_destroyed(context)


def wrap_basic_login(
    wait_s: Callable[[str], float],
    failed: Callable[[str], None],
    succeeded: Callable[[str], None],
) -> bool:
    """Throttle Panel's basic-auth login page (``panel.auth.BasicLoginHandler``).

    Before a login attempt, ``wait_s(client)`` (the client's address) says how long it must
    still wait: while positive, the attempt is refused without checking the password (the
    login page shows how long to wait). After the attempt, ``succeeded(client)`` when Panel
    set the login cookie (its ``set_current_user``), else ``failed(client)``. Returns whether
    it applied (False on another Panel version).
    """
    from panel.auth import BasicLoginHandler
    from tornado.escape import url_escape

    if not supported():
        return False
    post, set_user = BasicLoginHandler.post, BasicLoginHandler.set_current_user
    if getattr(post, "_gmwm_throttled", False):
        return True

    def throttled_post(self: Any) -> Any:
        client = str(self.request.remote_ip)
        wait = wait_s(client)
        if wait > 0:
            msg = f"Too many failed logins from this address: try again in {math.ceil(wait)} s"
            self.redirect(f"{self.request.path}?error={url_escape(msg)}")
            return None
        self._gmwm_logged_in = False
        out = post(self)
        (succeeded if self._gmwm_logged_in else failed)(client)
        return out

    def set_current_user(self: Any, user: Any) -> Any:
        self._gmwm_logged_in = bool(user)
        return set_user(self, user)

    throttled_post._gmwm_throttled = True  # type: ignore[attr-defined]
    BasicLoginHandler.post = throttled_post  # type: ignore[method-assign]  # the patch itself
    BasicLoginHandler.set_current_user = set_current_user  # type: ignore[method-assign]
    return True
