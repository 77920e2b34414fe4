"""A class server a hostile student cannot take down or hijack (server side).

The real ``gmwm-app`` in a subprocess on loopback (always stopped), attacked with a real
websocket client speaking Bokeh's protocol:

* a message whose inline ``bytes`` value inflates to :data:`BOMB_MB` MB (gzip + base64) and a
  message that never ends (buffers of 4 MB, :data:`FLOOD_MB` MB in all) are refused: that
  session's websocket is closed by the server with a log line, the server's peak memory
  (``VmHWM``) rises by less than :data:`MAX_RISE_MB` MB, and a new page still opens. Measured
  (this machine): the bomb +36 MB (256 MB inflated: +37 MB), the flood +24 MB (160 MB: +24
  MB); the old server kept both sockets open, +249 MB for the 128 MB bomb (+494 MB for 256
  MB) and +47 MB for a 40 MB flood (+161 MB for 160 MB);
* ``Host`` and ``Origin`` both a foreign name (DNS rebinding) get 403 on the page and on the
  websocket, while loopback names and IP addresses are answered;
* the login cookie (HttpOnly) is not copied into the session token embedded in the page;
* failed logins from one address are throttled (exponential delay), the right password works
  after the delay.

Plus the guards' units: the message bound, the bounded inflate, the host policy, the
throttle's schedule, and the current document after a browser's patch fails validation.
"""

from __future__ import annotations

import asyncio
import base64
import json
import re
import time
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_server_options import _gmwm_app, _login, _request

from gmwm_app import server_guard
from gmwm_app.limits import MAX_MESSAGE_BYTES
from gmwm_app.server_guard import HostPolicy, LoginThrottle, inline_bytes_size

#: Inflated size of the compressed bomb (MB) and the bytes of the never-ending message (MB).
BOMB_MB = 128
FLOOD_MB = 80
#: Largest rise of the server's peak memory an attack may cause (MB): one bounded message
#: (MAX_MESSAGE_BYTES = 16 MB) with its copies, far below the attacks' sizes.
MAX_RISE_MB = 48


# ---------------------------------------------------------------------------------------------
# units
# ---------------------------------------------------------------------------------------------
def _gzip_zeros(n_bytes: int) -> bytes:
    """gzip of ``n_bytes`` zero bytes, made 1 MB at a time (never holding them)."""
    z = zlib.compressobj(9, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    block = bytes(1_000_000)
    parts = [z.compress(block) for _ in range(n_bytes // len(block))]
    parts.append(z.compress(bytes(n_bytes % len(block))))
    return b"".join(parts) + z.flush()


def test_inline_bytes_size_is_bounded() -> None:
    small = base64.b64encode(_gzip_zeros(1000)).decode()
    assert inline_bytes_size(small, 10_000) == 1000
    bomb = base64.b64encode(_gzip_zeros(50_000_000)).decode()
    assert len(bomb) < 100_000  # 50 MB of zeros in under 0.1 MB
    assert inline_bytes_size(bomb, 1_000_000) == 1_000_001  # "more than the limit"
    two = base64.b64encode(_gzip_zeros(10) + _gzip_zeros(10)).decode()
    assert inline_bytes_size(two, 1000) == 1001  # several members: refused too
    assert inline_bytes_size("not base64 of gzip!", 1000) == 0  # Bokeh's own error then


def _fragments(
    content: dict[str, Any], buffers: list[bytes] = (), declared: int | None = None
) -> list[str | bytes]:
    n = len(buffers) if declared is None else declared
    header = {"msgid": "m1", "msgtype": "PATCH-DOC", "num_buffers": n} if n else {}
    if not n:
        header = {"msgid": "m1", "msgtype": "PATCH-DOC"}
    out: list[str | bytes] = [json.dumps(header), "{}", json.dumps(content)]
    for i, b in enumerate(buffers):
        out += [json.dumps({"id": f"b{i}"}), b]
    return out


def _consume_all(frags: list[str | bytes]) -> Any:
    from bokeh.protocol import Protocol
    from bokeh.protocol.receiver import Receiver

    receiver = Receiver(Protocol())

    async def run() -> Any:
        msg = None
        for f in frags:
            msg = await receiver.consume(f)
        return msg

    return asyncio.run(run())


def test_message_bound_counts_every_fragment_and_inflated_value() -> None:
    from bokeh.protocol.exceptions import ProtocolError

    server_guard.bound_messages(200_000)
    try:
        ok = _consume_all(_fragments({"events": []}, [bytes(50_000)] * 3))
        assert ok is not None and len(ok.buffers) == 3
        # each fragment below the bound, together above it: refused before the 5th buffer
        with pytest.raises(ProtocolError, match="message over 0.2 MB"):
            _consume_all(_fragments({"events": []}, [bytes(50_000)] * 5))
        # a never-ending message (declares 1000 buffers): refused as it grows
        with pytest.raises(ProtocolError, match="message over"):
            _consume_all(_fragments({"events": []}, [bytes(50_000)] * 5, declared=1000))
        bomb = base64.b64encode(_gzip_zeros(10_000_000)).decode()
        event = {"kind": "MessageSent", "msg_type": "x", "msg_data": {"type": "bytes"}}
        event["msg_data"]["data"] = bomb
        with pytest.raises(ProtocolError, match="compressed value over"):
            _consume_all(_fragments({"events": [event]}))
        # values within the bound, even several, pass
        event["msg_data"]["data"] = base64.b64encode(_gzip_zeros(60_000)).decode()
        assert _consume_all(_fragments({"events": [event, event]})) is not None
    finally:
        server_guard.bound_messages(MAX_MESSAGE_BYTES)


def test_host_policy() -> None:
    default = HostPolicy((), 5006)
    for host in ("localhost:5006", "127.0.0.1:5006", "[::1]:5006", "192.168.1.20:5006"):
        assert default.refusal(host, None) is None, host
    why = default.refusal("evil.example:5006", "http://evil.example:5006")
    assert why is not None and "--allow-websocket-origin evil.example:5006" in why
    assert default.refusal("localhost:5006", "http://evil.example") is not None
    assert default.refusal("localhost:5006", "http://localhost:5006") is None
    assert default.refusal("", None) is not None
    lab = HostPolicy(("lab-pc:5006",), 5006)
    assert lab.refusal("lab-pc:5006", "http://lab-pc:5006") is None
    assert lab.refusal("lab-pc.evil.example:5006", None) is not None
    assert lab.refusal("lab-pc:5006", "http://other:5006") is not None
    anyone = HostPolicy(("*",), 5006)
    assert anyone.refusal("whatever.example:5006", "http://whatever.example:5006") is None


def test_login_throttle_schedule() -> None:
    now = [1000.0]
    t = LoginThrottle(free=3, base_s=1.0, max_s=60.0, clock=lambda: now[0])
    for _ in range(3):
        assert t.wait_s("10.0.0.7") == 0.0
        t.failed("10.0.0.7")
    assert t.wait_s("10.0.0.7") == pytest.approx(1.0)
    assert t.wait_s("10.0.0.8") == 0.0  # per address
    # 20 wrong passwords in a row: the waits between them add up to at least
    # 1+2+4+8+16+32+60*11 = 723 s (the old server took 0.06 s)
    total = 0.0
    for _ in range(17):
        w = t.wait_s("10.0.0.7")
        total += w
        now[0] += w
        t.failed("10.0.0.7")
    assert total == pytest.approx(1 + 2 + 4 + 8 + 16 + 32 + 60 * 11)
    t.succeeded("10.0.0.7")
    assert t.wait_s("10.0.0.7") == 0.0


def test_a_failing_patch_leaves_the_current_document_as_it_was() -> None:
    """A PATCH-DOC that fails validation (a slider's value set to text, as a student can send
    from the browser's console) raises inside Bokeh's ``patch_curdoc``. Without the guard the
    session's document stayed on the process-wide stack, and once it was collected every
    ``components()`` (the HTML report download of every other session) raised "Patched curdoc
    has been previously destroyed"."""
    import gc

    from bokeh.document import Document
    from bokeh.embed import components
    from bokeh.models import Slider
    from bokeh.plotting import figure
    from bokeh.protocol.messages.patch_doc import patch_doc

    assert server_guard.restore_curdoc_on_error()
    doc = Document()
    slider = Slider(start=0, end=1, value=0)
    doc.add_root(slider)
    event = {"kind": "ModelChanged", "model": {"id": slider.id}, "attr": "value", "new": "abc"}
    bad = patch_doc({"msgid": "m1", "msgtype": "PATCH-DOC"}, {}, {"events": [event]})
    with pytest.raises(ValueError, match="failed to validate"):
        bad.apply_to_document(doc)
    del doc, slider, bad
    gc.collect()  # the closed session's document is gone
    script, divs = components(figure())
    assert "<script" in script and "<div" in divs
    assert server_guard.restore_curdoc_on_error()  # a second install keeps the one wrapper


# ---------------------------------------------------------------------------------------------
# the real server, attacked on loopback
# ---------------------------------------------------------------------------------------------
def _peak_mb(pid: int) -> float:
    """Peak resident memory (VmHWM) of the server process (MB)."""
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        kb = next(int(ln.split()[1]) for ln in f if ln.startswith("VmHWM:"))
    return kb / 1024


def _server_pid(srv: dict) -> int:
    return int(srv["proc"].pid)


def _token(html: bytes) -> str:
    m = re.search(rb'"token":\s*"([^"]+)"', html) or re.search(rb"token\W+([\w.-]{40,})", html)
    assert m is not None, "no session token in the page"
    return m.group(1).decode()


async def _open_ws(port: int, token: str, *, host: str = "localhost", cookie: str = "") -> Any:
    from tornado.httpclient import HTTPRequest
    from tornado.websocket import websocket_connect

    headers = {"Origin": f"http://{host}:{port}", "Host": f"{host}:{port}"}
    if cookie:
        headers["Cookie"] = cookie
    req = HTTPRequest(f"ws://127.0.0.1:{port}/ws", headers=headers, request_timeout=60)
    return await websocket_connect(req, subprotocols=["bokeh", token])


async def _attack(port: int, frags: list[str | bytes], timeout_s: float = 60.0) -> int | None:
    """Open a session, read its ACK, send ``frags``; the close code the server sent (None:
    still open after ``timeout_s``)."""
    page = _request(port, "GET", "/")
    ws = await _open_ws(port, _token(page.body))  # type: ignore[attr-defined]
    await asyncio.wait_for(ws.read_message(), timeout_s)  # the ACK's header
    try:
        for f in frags:
            await ws.write_message(f, binary=isinstance(f, bytes))
    except Exception:  # the server closed the socket while we were sending
        pass
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            msg = await asyncio.wait_for(ws.read_message(), deadline - time.monotonic())
        except (asyncio.TimeoutError, TimeoutError):
            break
        if msg is None:
            return ws.close_code
    ws.close()
    return None


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """One ``gmwm-app --prebuild 0`` for the attacks and the DNS-rebinding checks (a start
    costs about 7 s of CPU). Each test reads only what it causes: the peak memory against its
    own baseline, the log lines printed since it began."""
    with _gmwm_app("--prebuild", "0", cwd=tmp_path_factory.mktemp("served")) as srv:
        yield srv


def test_protocol_attacks_close_the_session_not_the_server(served: dict) -> None:
    srv = served
    begin = len(srv["lines"])
    port, pid = srv["port"], _server_pid(srv)
    assert _request(port, "GET", "/").status == 200
    time.sleep(1.0)
    base = _peak_mb(pid)
    # 1. a compressed value inflating to BOMB_MB MB in a PATCH-DOC event
    bomb = base64.b64encode(_gzip_zeros(BOMB_MB * 1_000_000)).decode()
    event = {"kind": "MessageSent", "msg_type": "x", "msg_data": {"type": "bytes"}}
    event["msg_data"]["data"] = bomb
    code = asyncio.run(_attack(port, _fragments({"events": [event]})))
    assert code == 10001, code  # Bokeh's protocol-error close
    rise_bomb = _peak_mb(pid) - base
    # 2. a message declaring 1000 buffers, sent as 4 MB buffers, never finished
    chunk = bytes(4_000_000)
    flood = _fragments({"events": []}, [chunk] * (FLOOD_MB // 4), declared=1000)
    code = asyncio.run(_attack(port, flood))
    assert code == 10001, code
    rise_flood = _peak_mb(pid) - base
    out = "".join(srv["lines"][begin:])
    assert "compressed value over 16 MB" in out and "message over 16 MB" in out, out[-3000:]
    print(
        f"server peak memory {base:.0f} MB; +{rise_bomb:.0f} MB after the bomb, "
        f"+{rise_flood:.0f} MB after the flood"
    )
    assert rise_bomb < MAX_RISE_MB and rise_flood < MAX_RISE_MB, (rise_bomb, rise_flood)
    # the server still serves pages and sessions
    assert srv["proc"].poll() is None
    assert _request(port, "GET", "/").status == 200


def test_dns_rebinding_is_refused(served: dict) -> None:
    srv = served
    begin = len(srv["lines"])
    port = srv["port"]
    evil = f"rebind.evil.example:{port}"
    for headers in ({"Host": evil}, {"Host": evil, "Origin": f"http://{evil}"}):
        r = _request(port, "GET", "/", headers=headers)
        assert r.status == 403, r.status
        assert b"--allow-websocket-origin" in r.body  # type: ignore[attr-defined]
        assert b"token" not in r.body  # type: ignore[attr-defined]
    for host in (f"localhost:{port}", f"127.0.0.1:{port}"):
        assert _request(port, "GET", "/", headers={"Host": host}).status == 200
    # a token obtained by a good page does not open a websocket from the foreign name
    token = _token(_request(port, "GET", "/").body)  # type: ignore[attr-defined]

    async def ws_from(host: str) -> Any:
        ws = await _open_ws(port, token, host=host)
        ws.close()

    with pytest.raises(Exception, match="403"):
        asyncio.run(ws_from("rebind.evil.example"))
    assert "refused GET /" in "".join(srv["lines"][begin:])


def test_login_cookie_not_in_token_and_logins_throttled(tmp_path: Path) -> None:
    from bokeh.util.token import get_token_payload

    pw = tmp_path / "class-password.txt"
    pw.write_text("lecture-7-passphrase\n")
    pw.chmod(0o600)
    with _gmwm_app("--basic-auth", str(pw), "--prebuild", "0", cwd=tmp_path) as srv:
        port = srv["port"]
        good = _login(port, "lecture-7-passphrase")
        cookies = "; ".join(c.split(";", 1)[0] for c in good.headers.get_all("Set-Cookie") or [])
        user_cookie = next(c for c in cookies.split("; ") if c.startswith("user="))
        page = _request(port, "GET", "/", headers={"Cookie": cookies})
        assert page.status == 200
        html = page.body  # type: ignore[attr-defined]
        payload = get_token_payload(_token(html))
        assert payload.get("cookies", {}) == {}
        assert not {"cookie", "authorization"} & {h.lower() for h in payload.get("headers", {})}
        assert user_cookie.split("=", 1)[1].encode() not in html

        # the session still works (the websocket's own request carries the cookie)
        async def ack() -> Any:
            ws = await _open_ws(port, _token(html), cookie=cookies)
            first = await asyncio.wait_for(ws.read_message(), 60)
            ws.close()
            return first

        assert asyncio.run(ack()) is not None
        # three free failures, then refused without checking the password, then 1 s later
        # the right password works
        for _ in range(3):
            bad = _login(port, "wrong")
            assert "Invalid" in urllib_unquote(bad.getheader("Location", ""))
        blocked = _login(port, "lecture-7-passphrase")
        assert "Too many failed logins" in urllib_unquote(blocked.getheader("Location", ""))
        assert not any("user=" in c for c in blocked.headers.get_all("Set-Cookie") or [])
        time.sleep(1.2)
        again = _login(port, "lecture-7-passphrase")
        assert any("user=" in c for c in again.headers.get_all("Set-Cookie") or [])


def urllib_unquote(s: str) -> str:
    from urllib.parse import unquote_plus

    return unquote_plus(s)


# ---------------------------------------------------------------------------------------------
# what a page learns of the server's files
# ---------------------------------------------------------------------------------------------
@pytest.fixture
def data_folder(tmp_path: Path) -> Iterator[Path]:
    """A configured data folder holding a small CSV log; limits back to default after."""
    from gmwm_app import limits

    d = tmp_path / "class-data"
    d.mkdir()
    x = np.random.default_rng(3).normal(size=4000)
    np.savetxt(d / "run1.csv", x[:, None], header="gyro_x", comments="")
    limits.configure(data_dirs=[d])
    yield d
    limits.configure()


def _session_for(data_path: str) -> str:
    doc = {
        "schema": "gmwm-session/1",
        "data": {"path": data_path, "load": {}, "fingerprint": None},
        "channels": {},
        "app": {"source": "path", "channel": "gyro_x"},
    }
    return json.dumps(doc)


def test_restore_does_not_tell_whether_a_server_path_exists(data_folder: Path) -> None:
    from engine.session import SCHEMA
    from gmwm_app import session_view as sv

    existing, missing = "/etc/hostname", "/etc/no-such-file-gmwm"
    assert Path(existing).exists() and not Path(missing).exists()
    answers = []
    for p in (existing, missing):
        plan = sv.prepare_restore(_session_for(p).replace("gmwm-session/1", SCHEMA))
        assert plan.loaded is None and len(plan.problems) == 1
        answers.append(plan.problems[0].replace(p, "PATH"))
    assert answers[0] == answers[1], answers  # the same words, existing or not
    assert "outside the folders" in answers[0]


def test_downloaded_session_names_the_file_relative_to_its_data_folder(
    data_folder: Path,
) -> None:
    from gmwm_app import session_view as sv
    from gmwm_app.state import AppState

    s = AppState()
    assert s.load_path(data_folder / "run1.csv"), s.error
    assert s.set_model("WN")
    text = sv.session_json(s)
    assert str(data_folder) not in text and str(data_folder.parent) not in text
    doc = json.loads(text)
    assert doc["data"]["path"] == "run1.csv" and doc["data"]["fingerprint"] is not None
    # restored on the same server from that name: the same file, fingerprint matched
    plan = sv.prepare_restore(text, "s.json")
    assert plan.problems == [] and plan.notes == [] and plan.loaded is not None
    other = AppState()
    assert sv.apply_restore(other, plan), other.error
    assert other.model.spec() == "WN" and other.filename == "run1.csv"


@pytest.mark.real_data
def test_downloaded_session_of_a_real_log(real_data: Path) -> None:
    from gmwm_app import limits
    from gmwm_app import session_view as sv
    from gmwm_app.state import AppState

    limits.configure(data_dirs=[real_data])
    try:
        s = AppState()
        assert s.load_path("mtig_cont_imu1.h5"), s.error  # by its name in the data folder
        assert s.set_model("WN+RW")
        text = sv.session_json(s)
        assert str(real_data.resolve()) not in text
        assert json.loads(text)["data"]["path"] == "mtig_cont_imu1.h5"
        plan = sv.prepare_restore(text, "s.json")
        assert plan.problems == [] and plan.notes == []
        other = AppState()
        assert sv.apply_restore(other, plan), other.error
        assert other.model.spec() == "WN+RW" and other.channel == "gyro_x"
        assert other.result is not None and s.result is not None
        assert other.result.objective == pytest.approx(s.result.objective, rel=1e-9)
    finally:
        limits.configure()
