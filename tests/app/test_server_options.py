"""``gmwm-app`` as a server a class can share: safe defaults, logins, processes, a quiet stop.

Parse and configuration tests of :mod:`gmwm_app.__main__`, then the real command in a
subprocess (``python -m gmwm_app``, loopback only, always stopped): the default listens on the
loopback interface only (a connection to this machine's network address is refused), a
``--basic-auth`` server refuses a page request without the password and admits it with the
password, ``--num-procs 2`` serves pages and a websocket session, and Ctrl+C (SIGINT to the
process group, as a terminal sends it) stops it within seconds with one line and no traceback.
"""

from __future__ import annotations

import http.client
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.parse
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from gmwm_app.__main__ import (
    DEFAULT_ADDRESS,
    MAX_MESSAGE_BYTES,
    UsageError,
    build_parser,
    is_loopback,
    main,
    read_password_file,
    server_options,
)

REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 15.0


def _opts(*argv: str) -> dict:
    return server_options(build_parser().parse_args(list(argv)))


# ---------------------------------------------------------------------------------------------
# parsing and configuration (no server)
# ---------------------------------------------------------------------------------------------
def test_default_address_is_loopback() -> None:
    args = build_parser().parse_args([])
    assert args.address == DEFAULT_ADDRESS == "localhost"
    opts = server_options(args)
    assert opts["address"] == "localhost" and "websocket_origin" not in opts
    assert opts["websocket_max_message_size"] == MAX_MESSAGE_BYTES
    assert "basic_auth" not in opts and "num_procs" not in opts and "cookie_secret" not in opts
    assert "localhost" in build_parser().format_help()


@pytest.mark.parametrize(
    ("address", "loop"),
    [
        ("localhost", True),
        ("LOCALHOST", True),
        ("127.0.0.1", True),
        ("127.0.1.1", True),
        ("::1", True),
        ("[::1]", True),
        ("0.0.0.0", False),
        ("::", False),
        ("", False),
        ("192.168.1.20", False),
        ("lab-pc.example.org", False),
    ],
)
def test_is_loopback(address: str, loop: bool) -> None:
    assert is_loopback(address) is loop


@pytest.mark.parametrize("address", ["0.0.0.0", "::", "192.168.1.20", "lab-pc"])
def test_beyond_loopback_needs_origins(address: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(UsageError, match="add --allow-websocket-origin HOST:5006"):
        _opts("--address", address)
    # the command refuses to start, with one line saying what to add
    assert main(["--address", address, "--no-show"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gmwm-app: error: --address")
    assert "--allow-websocket-origin" in err[0]
    opts = _opts("--address", address, "--allow-websocket-origin", "lab-pc:5006")
    assert opts["address"] == address and opts["websocket_origin"] == ["lab-pc:5006"]


def test_origin_list_and_empty_origin() -> None:
    opts = _opts(
        "--address", "0.0.0.0", "--allow-websocket-origin", "a:1", "--allow-websocket-origin", "b"
    )
    assert opts["websocket_origin"] == ["a:1", "b"]
    with pytest.raises(UsageError, match="empty"):
        _opts("--address", "0.0.0.0", "--allow-websocket-origin", " ")
    # an explicit '*' is the user's choice, never a silent default; a note says what it means
    from gmwm_app.__main__ import _notes

    args = build_parser().parse_args(["--address", "0.0.0.0", "--allow-websocket-origin", "*"])
    notes = _notes(args, server_options(args))
    assert any("any site" in n for n in notes) and any("--basic-auth" in n for n in notes)


def test_password_file_plain_and_json(tmp_path: Path) -> None:
    plain = tmp_path / "pw.txt"
    plain.write_text("  correct horse battery  \nsecond line ignored\n")
    assert read_password_file(plain) == "correct horse battery"
    users = tmp_path / "users.json"
    users.write_text(json.dumps({"anna": "pa55-anna", "ben": "pa55-ben"}))
    assert read_password_file(users) == {"anna": "pa55-anna", "ben": "pa55-ben"}
    opts = _opts("--basic-auth", str(plain))
    assert opts["basic_auth"] == "correct horse battery"
    assert isinstance(opts["cookie_secret"], str) and len(opts["cookie_secret"]) >= 32
    assert _opts("--basic-auth", str(plain))["cookie_secret"] != opts["cookie_secret"]
    given = _opts("--basic-auth", str(plain), "--cookie-secret", "s3cret-for-all-procs")
    assert given["cookie_secret"] == "s3cret-for-all-procs"


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (None, "no such file"),
        ("", "first line .* is empty"),
        ("\n\nlater\n", "first line .* is empty"),
        ('{"anna": ""}', "JSON object"),
        ('{"anna": 3}', "JSON object"),
        ("{not json", "JSON object"),
    ],
)
def test_password_file_refusals(tmp_path: Path, content: str | None, match: str) -> None:
    f = tmp_path / "pw"
    if content is not None:
        f.write_text(content)
    with pytest.raises(UsageError, match=match) as e:
        read_password_file(f)
    assert str(f) in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(UsageError, match="not a regular file"):
        read_password_file(tmp_path)


def test_login_and_process_options(tmp_path: Path) -> None:
    pw = tmp_path / "pw"
    pw.write_text("pw\n")
    with pytest.raises(UsageError, match="two logins"):
        _opts("--basic-auth", str(pw), "--oauth-provider", "github")
    with pytest.raises(UsageError, match="--num-procs"):
        _opts("--num-procs", "-1")
    assert _opts("--num-procs", "4")["num_procs"] == 4
    assert _opts("--num-procs", "0")["num_procs"] == 0  # one per core (Bokeh)
    oauth = _opts(
        "--oauth-provider", "github", "--oauth-key", "id", "--oauth-redirect-uri", "http://h/x"
    )
    assert oauth["oauth_provider"] == "github" and oauth["oauth_key"] == "id"
    assert oauth["oauth_redirect_uri"] == "http://h/x" and oauth["cookie_secret"]


def test_pn_serve_accepts_every_option(tmp_path: Path) -> None:
    """Every keyword server_options produces is one ``pn.serve`` (Panel's get_server) takes."""
    import inspect

    from panel.io.server import get_server

    pw = tmp_path / "pw"
    pw.write_text("pw\n")
    known = set(inspect.signature(get_server).parameters) | {"num_procs"}  # num_procs: **kwargs
    known |= {"websocket_max_message_size"}  # Bokeh Server option, through **kwargs
    token_opts = {"include_cookies", "exclude_headers"}  # BokehTornado's, through **kwargs
    known |= token_opts
    for argv in (
        ["--basic-auth", str(pw), "--num-procs", "2"],
        ["--address", "0.0.0.0", "--allow-websocket-origin", "h:1", "--oauth-provider", "x"],
    ):
        assert set(_opts(*argv)) <= known
    from bokeh.server.server import _ServerOpts

    bokeh_opts = set(_ServerOpts.properties())
    assert {"num_procs", "websocket_max_message_size"} <= bokeh_opts
    from bokeh.server.tornado import BokehTornado

    assert token_opts <= set(inspect.signature(BokehTornado.__init__).parameters)


# ---------------------------------------------------------------------------------------------
# the real command in a subprocess
# ---------------------------------------------------------------------------------------------
def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PYTHONUNBUFFERED"] = "1"
    return env


@contextmanager
def _gmwm_app(*argv: str, cwd: Path) -> Iterator[dict]:
    """``python -m gmwm_app --no-show --port 0 ARGV`` in its own process group; yields
    ``{"proc", "port", "lines"}`` once it prints its address; always stopped (SIGINT to the
    group, SIGKILL after STOP_TIMEOUT_S)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "gmwm_app", "--no-show", "--port", "0", *argv],
        cwd=cwd,
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    lines: list[str] = []
    ready = threading.Event()

    def reader() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if "Launching server at" in line:
                ready.set()
        ready.set()

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    info: dict = {"proc": proc, "lines": lines, "reader": t}
    try:
        assert ready.wait(START_TIMEOUT_S), f"gmwm-app did not start: {''.join(lines)}"
        m = next((re.search(r":(\d+)", ln) for ln in lines if "Launching" in ln), None)
        assert m is not None, f"gmwm-app exited: {''.join(lines)}"
        info["port"] = int(m.group(1))
        yield info
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5)
        t.join(5)


def _request(
    port: int, method: str, path: str, body: str | None = None, headers: dict | None = None
) -> http.client.HTTPResponse:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    conn.request(method, path, body=body, headers=headers or {})
    resp = conn.getresponse()
    resp.body = resp.read()  # type: ignore[attr-defined]
    conn.close()
    return resp


def _network_addresses() -> list[str]:
    """This machine's IPv4 addresses other than loopback (the interfaces, else the host name)."""
    found: set[str] = set()
    try:
        import psutil

        for addrs in psutil.net_if_addrs().values():
            found |= {a.address for a in addrs if a.family == socket.AF_INET}
    except ImportError:
        try:
            found |= {
                ai[4][0] for ai in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)
            }
        except OSError:
            pass
    return sorted(a for a in found if not is_loopback(a))


def _connects(address: str, port: int) -> bool:
    try:
        with socket.create_connection((address, port), timeout=2):
            return True
    except OSError:
        return False


def test_default_server_listens_on_loopback_only(tmp_path: Path) -> None:
    with _gmwm_app(cwd=tmp_path) as srv:
        port = srv["port"]
        assert "http://localhost:" in "".join(srv["lines"])
        assert _connects("127.0.0.1", port)
        page = _request(port, "GET", "/")
        assert page.status == 200 and b"GMWM" in page.body  # type: ignore[attr-defined]
        others = _network_addresses()
        if not others:
            pytest.skip("this machine has no network address besides loopback")
        reached = [a for a in others if _connects(a, port)]
        assert reached == [], f"the default server is reachable from {reached}"


def _login(port: int, password: str) -> http.client.HTTPResponse:
    body = urllib.parse.urlencode({"username": "student", "password": password})
    hdr = {"Content-Type": "application/x-www-form-urlencoded"}
    return _request(port, "POST", "/login", body, hdr)


def test_basic_auth_refuses_without_password(tmp_path: Path) -> None:
    pw = tmp_path / "class-password.txt"
    pw.write_text("lecture-7-passphrase\n")
    pw.chmod(0o600)
    with _gmwm_app("--basic-auth", str(pw), cwd=tmp_path) as srv:
        port = srv["port"]
        anon = _request(port, "GET", "/")
        assert anon.status in (302, 401, 403), anon.status
        if anon.status == 302:
            assert "login" in anon.getheader("Location", "")
        assert b"GMWM" not in anon.body  # type: ignore[attr-defined]
        bad = _login(port, "wrong")
        assert bad.status == 302 and "error=" in bad.getheader("Location", "")
        assert not any("user=" in c for c in bad.headers.get_all("Set-Cookie") or [])
        good = _login(port, "lecture-7-passphrase")
        assert good.status == 302 and "error" not in good.getheader("Location", "")
        cookies = "; ".join(c.split(";", 1)[0] for c in good.headers.get_all("Set-Cookie") or [])
        assert "user=" in cookies
        page = _request(port, "GET", "/", headers={"Cookie": cookies})
        assert page.status == 200 and b"GMWM" in page.body  # type: ignore[attr-defined]


@pytest.mark.load  # three gmwm-app processes at once
def test_num_procs_serves_pages_and_sessions(tmp_path: Path) -> None:
    import panel.models.file_dropper  # noqa: F401 - the page's models, for the client side
    from bokeh.client import pull_session

    with _gmwm_app("--num-procs", "2", cwd=tmp_path) as srv:
        port = srv["port"]
        out = "".join(srv["lines"])
        assert "not opening a browser" not in out  # --no-show given: no note
        for _ in range(2):
            page = _request(port, "GET", "/")
            assert page.status == 200 and b"GMWM" in page.body  # type: ignore[attr-defined]
        # a websocket session (what a browser tab opens), with the page's document
        with pull_session(url=f"http://localhost:{port}/") as session:
            assert len(list(session.document.roots)) >= 1
        # two server processes besides the parent (pgrep: children of the started process)
        kids = subprocess.run(
            ["pgrep", "-P", str(srv["proc"].pid), "-f", "gmwm_app"], capture_output=True, text=True
        ).stdout.split()
        assert len(kids) == 2, kids


def test_ctrl_c_stops_quietly(tmp_path: Path) -> None:
    with _gmwm_app(cwd=tmp_path) as srv:
        proc, port = srv["proc"], srv["port"]
        assert _request(port, "GET", "/").status == 200  # a session: pages, the HDF5 helper
        time.sleep(1.0)  # the helper process is up (started with the server)
        t0 = time.perf_counter()
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl+C in a terminal does
        proc.wait(STOP_TIMEOUT_S)
        elapsed = time.perf_counter() - t0
        srv["reader"].join(5)
    out = "".join(srv["lines"])
    assert proc.returncode == 0, out
    assert "Traceback" not in out and "KeyboardInterrupt" not in out, out
    assert "gmwm-app: stopped" in out.splitlines()[-1]
    assert out.count("gmwm-app: stopped") == 1
    assert elapsed < 10.0
