"""The server's doors: bounded browser messages, the host names it answers, throttled logins.

Each guard is installed once per server process by ``gmwm-app`` (:func:`install`) and wraps a
public method of Bokeh or Tornado, never a copy of it:

* :func:`bound_messages`: a Bokeh protocol message from a browser is a header, metadata,
  content and any number of binary buffers, each its own websocket message. Tornado's
  ``websocket_max_message_size`` bounds each of those, not their sum, and Bokeh decompresses an
  inline ``bytes`` value (gzip + base64) with no limit when it applies the message. The guard
  wraps :meth:`bokeh.protocol.receiver.Receiver.consume` (the receiver of every websocket
  session): it counts the fragments of the message being assembled and measures, with a
  bounded decompression, every inline compressed value of a completed one. Past
  :data:`gmwm_app.limits.MAX_MESSAGE_BYTES` it raises Bokeh's ``ProtocolError``, which Bokeh
  logs ("Bokeh Server protocol error: ...") and answers by closing that session's websocket;
  the server and the other sessions go on.
* :func:`guard_hosts`: DNS rebinding. A foreign site whose name resolves to this machine makes
  the browser send ``Host`` and ``Origin`` both equal to that name; Tornado consults no
  allow-list when they are equal. Every request (page, websocket, login, static file) whose
  ``Host`` is not an allowed name, or whose ``Origin`` is neither its ``Host`` nor allowed, is
  answered 403 with a line saying what to add.
* :class:`LoginThrottle`: after failed logins from one address, the next attempt from it is
  refused (without checking the password) for a delay that doubles at each failure.
* :func:`restore_curdoc_on_error`: Bokeh runs every document callback, and every PATCH-DOC a
  browser sends, inside ``bokeh.io.doc.patch_curdoc``, which does not restore the process's
  current document when the code inside raises. One bad patch (a slider value set to text from
  the browser's console) left the session's document on the process-wide stack; once that
  session closed, every later ``curdoc()`` outside a callback raised "Patched curdoc has been
  previously destroyed", so every classmate's HTML report download failed until a restart.

Allowed names: loopback names and addresses (``localhost``, ``127.x.y.z``, ``::1``), any IP
address literal (a rebinding site is a *name*: a browser that typed an address sends it), and
the ``--allow-websocket-origin`` entries (Bokeh's host patterns; ``*`` allows any).
"""

from __future__ import annotations

import base64
import binascii
import ipaddress
import logging
import threading
import time
import zlib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any
from urllib.parse import urlsplit

from gmwm_app.limits import MAX_MESSAGE_BYTES

__all__ = [
    "is_loopback",
    "is_ip_literal",
    "bound_messages",
    "inline_bytes_size",
    "HostPolicy",
    "guard_hosts",
    "LoginThrottle",
    "throttle_logins",
    "restore_curdoc_on_error",
    "install",
]

log = logging.getLogger(__name__)


def is_loopback(address: str) -> bool:
    """Whether ``address`` is this machine's loopback interface only (``localhost``,
    ``127.x.y.z``, ``::1``); the empty address and ``0.0.0.0`` mean every interface."""
    a = address.strip().strip("[]").lower()
    if a == "localhost":
        return True
    try:
        return ipaddress.ip_address(a).is_loopback
    except ValueError:  # a host name: it may resolve to a network interface
        return False


def is_ip_literal(name: str) -> bool:
    """Whether ``name`` (no port; IPv6 in brackets or not) is an IP address, not a name."""
    try:
        ipaddress.ip_address(name.strip().strip("[]"))
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------------------------
# bounded protocol messages
# ---------------------------------------------------------------------------------------------
def _inline_compressed(node: Any) -> Iterator[str]:
    """The inline (base64 string) ``bytes`` values of a message's decoded JSON content."""
    stack = [node]
    while stack:
        x = stack.pop()
        if isinstance(x, dict):
            if x.get("type") == "bytes" and isinstance(x.get("data"), str):
                yield x["data"]
            else:
                stack.extend(x.values())
        elif isinstance(x, list):
            stack.extend(x)


def inline_bytes_size(data: str, limit: int) -> int:
    """Decompressed size (bytes) of one inline ``bytes`` value (base64 of gzip), measured
    without ever holding more than ``limit`` + 1 bytes of it; ``limit + 1`` means "more than
    ``limit``" (or several gzip members, which Bokeh would also inflate). A value that is not
    base64 of gzip is 0: Bokeh refuses it with its own error."""
    try:
        raw = base64.b64decode(data)
    except (binascii.Error, ValueError):
        return 0
    inflater = zlib.decompressobj(16 + zlib.MAX_WBITS)
    try:
        out = inflater.decompress(raw, limit + 1)
    except zlib.error:
        return 0
    if len(out) > limit or inflater.unconsumed_tail or inflater.unused_data:
        return limit + 1
    return len(out)


def _refuse(reason: str) -> None:
    from bokeh.protocol.exceptions import ProtocolError

    raise ProtocolError(reason)  # Bokeh logs it and closes this session's websocket


def bound_messages(max_bytes: int = MAX_MESSAGE_BYTES) -> bool:
    """Bound every Bokeh message a browser sends to ``max_bytes`` (all its fragments and
    buffers together, and the decompressed size of its inline ``bytes`` values together).

    Wraps ``Receiver.consume`` (once per process; a second call changes the bound). Returns
    whether the wrapper is in place. Once a message is refused, whatever else arrives on that
    socket while it closes is dropped unread. The close reason the browser gets is short (a
    websocket close reason is at most 123 bytes); the server's log line says the same.
    """
    from bokeh.protocol.receiver import Receiver

    _BOUND["bytes"] = int(max_bytes)
    current = Receiver.consume
    if getattr(current, "_gmwm_bounded", False):
        return True

    async def consume(self: Any, fragment: str | bytes) -> Any:
        if getattr(self, "_gmwm_refused", False):
            return None  # the socket is closing: what still arrives is dropped, unread
        limit = _BOUND["bytes"]
        pending = getattr(self, "_gmwm_pending", 0) + len(fragment)
        if pending > limit:
            self._gmwm_refused = True
            _refuse(f"message over {limit / 1e6:.3g} MB (gmwm-app limit)")
        self._gmwm_pending = pending
        message = await current(self, fragment)
        if message is not None:
            self._gmwm_pending = 0
            inflated = 0
            for data in _inline_compressed(message.content):
                inflated += inline_bytes_size(data, limit - inflated)
                if inflated > limit:
                    self._gmwm_refused = True
                    _refuse(f"compressed value over {limit / 1e6:.3g} MB (gmwm-app limit)")
        return message

    consume._gmwm_bounded = True  # type: ignore[attr-defined]
    Receiver.consume = consume  # type: ignore[method-assign]
    return True


_BOUND = {"bytes": MAX_MESSAGE_BYTES}


# ---------------------------------------------------------------------------------------------
# Host and Origin
# ---------------------------------------------------------------------------------------------
class HostPolicy:
    """Which ``Host`` and ``Origin`` headers the server answers.

    Parameters
    ----------
    origins : sequence of str
        The ``--allow-websocket-origin`` entries (``HOST`` or ``HOST:PORT``; Bokeh's patterns,
        ``*`` for any).
    port : int
        The port served (for entries without one, as Bokeh reads them: port 80).
    """

    def __init__(self, origins: Sequence[str] = (), port: int = 80) -> None:
        from bokeh.server.util import create_hosts_allowlist

        self.origins = tuple(o for o in origins if o)
        self._allow = create_hosts_allowlist(list(self.origins), port) if self.origins else []

    def _listed(self, netloc: str) -> bool:
        from bokeh.server.util import check_allowlist

        return bool(self._allow) and check_allowlist(netloc, self._allow)

    def host_allowed(self, host: str) -> bool:
        """Whether a request's ``Host`` header (``name[:port]``) names this server."""
        host = host.strip().lower()
        if not host:
            return False
        name = urlsplit("//" + host).hostname or ""
        return is_loopback(name) or is_ip_literal(name) or self._listed(host)

    def origin_allowed(self, origin: str | None, host: str) -> bool:
        """Whether a request's ``Origin`` header (None: absent) may reach a server named
        ``host`` (an allowed ``Host``)."""
        if origin is None:
            return True
        netloc = urlsplit(origin.strip().lower()).netloc
        name = urlsplit("//" + netloc).hostname or ""
        return (
            (bool(netloc) and netloc == host.strip().lower())
            or is_loopback(name)
            or (bool(netloc) and self._listed(netloc))
        )

    def refusal(self, host: str, origin: str | None) -> str | None:
        """The one-line reason a request is refused, or None when it is allowed."""
        if not self.host_allowed(host):
            return (
                f"Host {host!r} is not a name of this server: open it by an allowed name, or "
                f"start gmwm-app with --allow-websocket-origin {host or 'HOST:PORT'}"
            )
        if not self.origin_allowed(origin, host):
            return f"Origin {origin!r} may not use this server"
        return None


_POLICY: dict[str, HostPolicy | None] = {"policy": None}


def guard_hosts(policy: HostPolicy) -> bool:
    """Answer 403 to every request of the Bokeh server whose ``Host`` or ``Origin`` the
    ``policy`` refuses (wraps ``BokehTornado.find_handler``, Tornado's public routing hook,
    once per process; a second call changes the policy). Returns True."""
    from bokeh.server.tornado import BokehTornado
    from tornado.web import ErrorHandler

    _POLICY["policy"] = policy
    current = BokehTornado.find_handler
    if getattr(current, "_gmwm_hosts", False):
        return True

    def find_handler(self: Any, request: Any, **kwargs: Any) -> Any:
        pol = _POLICY["policy"]
        if pol is not None:
            why = pol.refusal(request.host or "", request.headers.get("Origin"))
            if why is not None:
                log.warning("refused %s %s: %s", request.method, request.path, why)
                return self.get_handler_delegate(request, _Refused, {"reason": why})
        return current(self, request, **kwargs)

    class _Refused(ErrorHandler):
        def initialize(self, reason: str) -> None:  # type: ignore[override]
            super().initialize(403)
            self._gmwm_reason = reason

        def write_error(self, status_code: int, **kwargs: Any) -> None:
            self.set_header("Content-Type", "text/plain; charset=UTF-8")
            self.finish(f"403 Forbidden: {self._gmwm_reason}\n")

    find_handler._gmwm_hosts = True  # type: ignore[attr-defined]
    BokehTornado.find_handler = find_handler  # type: ignore[method-assign]
    return True


# ---------------------------------------------------------------------------------------------
# login throttling
# ---------------------------------------------------------------------------------------------
class LoginThrottle:
    """Exponential delay per client address after failed logins.

    After ``free`` consecutive failures from one address, each attempt from it is refused
    until ``base_s * 2**(failures - free)`` seconds (at most ``max_s``) have passed since its
    last failure; a success forgets the address. At most ``max_clients`` addresses are kept
    (the oldest are forgotten first).
    """

    def __init__(
        self,
        *,
        free: int = 3,
        base_s: float = 1.0,
        max_s: float = 60.0,
        max_clients: int = 10_000,
        clock: Any = time.monotonic,
    ) -> None:
        self.free, self.base_s, self.max_s = int(free), float(base_s), float(max_s)
        self.max_clients = int(max_clients)
        self._clock = clock
        self._failed: dict[str, tuple[int, float]] = {}
        self._lock = threading.Lock()

    def delay_s(self, n_failures: int) -> float:
        """The wait imposed after ``n_failures`` consecutive failures (s)."""
        if n_failures < self.free:
            return 0.0
        return min(self.max_s, self.base_s * 2.0 ** (n_failures - self.free))

    def wait_s(self, client: str) -> float:
        """How long ``client`` must still wait before its next attempt (s; 0: now)."""
        with self._lock:
            n, last = self._failed.get(client, (0, 0.0))
        return max(0.0, last + self.delay_s(n) - self._clock())

    def failed(self, client: str) -> None:
        """Record a failed login of ``client``."""
        with self._lock:
            n, _ = self._failed.pop(client, (0, 0.0))
            self._failed[client] = (n + 1, self._clock())
            while len(self._failed) > self.max_clients:
                self._failed.pop(next(iter(self._failed)))

    def succeeded(self, client: str) -> None:
        """Record a successful login of ``client`` (its failures are forgotten)."""
        with self._lock:
            self._failed.pop(client, None)


#: The throttle of this process's login page.
THROTTLE = LoginThrottle()


def throttle_logins(throttle: LoginThrottle = THROTTLE) -> bool:
    """Throttle Panel's basic-auth login page with ``throttle`` (once per process); whether it
    applied (:func:`gmwm_app._panel_compat.wrap_basic_login`)."""
    from gmwm_app._panel_compat import wrap_basic_login

    return wrap_basic_login(throttle.wait_s, throttle.failed, throttle.succeeded)


# ---------------------------------------------------------------------------------------------
# The current document after a failing callback
# ---------------------------------------------------------------------------------------------
def restore_curdoc_on_error() -> bool:
    """Make ``bokeh.io.doc.patch_curdoc`` restore the current document however the code it
    wraps ends (once per process).

    Bokeh's ``invoke_with_curdoc`` looks ``patch_curdoc`` up at each call, so wrapping the
    module's function covers every callback and every PATCH-DOC a browser sends. The wrapper
    enters Bokeh's own context manager and, in a ``finally``, resumes it as on success, which
    runs its restoring step; the exception then goes on to Bokeh's handler as before. Returns
    whether the wrapper is in place.
    """
    import bokeh.io.doc as bokeh_doc

    current = bokeh_doc.patch_curdoc
    if getattr(current, "_gmwm_restores", False):
        return True

    @contextmanager
    def patch_curdoc(doc: Any) -> Iterator[None]:
        patched = current(doc)
        patched.__enter__()
        try:
            yield
        finally:
            patched.__exit__(None, None, None)

    patch_curdoc._gmwm_restores = True  # type: ignore[attr-defined]
    bokeh_doc.patch_curdoc = patch_curdoc
    return True


def install(origins: Sequence[str] = (), port: int = 80, *, login: bool = False) -> None:
    """Every guard of a ``gmwm-app`` server process: bounded messages, the host policy of
    ``origins`` and ``port``, the current document restored after a failing callback and,
    with ``login``, the login throttle."""
    bound_messages()
    restore_curdoc_on_error()
    guard_hosts(HostPolicy(origins, port))
    if login:
        throttle_logins()
