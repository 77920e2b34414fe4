"""Load benchmark of the served app: N sessions opened at once (a script; pytest does not
collect it).

    python tests/benchmarks/bench_load.py [--n 10 20 30] [--num-procs 1] [--clicks 8]
        [--prebuild N] [--cold | --cold-and-warm] [--host-name NAME]

It starts ``gmwm-app`` itself (``python -m gmwm_app --address 127.0.0.1 --no-show``, the
demo log) on a free loopback port, once per measurement (a fresh server, so that one burst's
memory does not count in the next), and stops it at the end. The sessions are real Bokeh
websocket sessions, driven by Bokeh's own wire protocol from one asyncio loop in this process
(no browser: thirty Chromium pages would take the two cores from the server being measured).

Page ready, the same for every session: the time from the HTTP request of the page until
(1) the page's HTML has arrived (the server created the session and built its document),
(2) the whole document has arrived over the session's websocket (``PULL-DOC-REPLY``), and,
after the client announced ``document_ready`` (what BokehJS sends once it has rendered the
document, and what starts the session's data load), (3) the session's first data have
arrived: the WV of the demo log in the ``empirical`` data source and the data summary ending
in "WV levels" (the text the browser tests wait for). The document is then the one a browser
would draw, synchronised with the server.

Click-to-redraw: one session opened beforehand with the model WN+RW clicks "+ GM" (a button
event on the wire, as a browser sends it) and then its first process's remove button, in
turn, until the decomposition's first curve (``component_0``) arrives with the expected label;
measured on the idle server (the reference), then while 20 other sessions open at once.

Memory per session: the server's resident memory (its process and children) once the N
sessions are ready, minus that before the burst, divided by N.

Pages built ahead (``gmwm-app --prebuild N``, the app's default unless ``--prebuild`` is
given): by default every burst starts with the pools full ("warm": each server process has
printed that its pages are ready and the server's CPU time stayed flat for a second, before
the reference page and again before the burst); ``--cold`` opens the burst as soon as the
server listens (the pool still empty), and measures the reference page after it.

Bounded: at most 60 sessions, every wait has a time limit (``--timeout`` per burst), and the
server is stopped in every case. Loopback only.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]

MAX_SESSIONS = 60
HOST = "127.0.0.1"
TARGET_P95_S = 5.0
TARGET_CLICK_S = 1.0
#: Pause between two clicks of the clicking session (a person, not a loop).
CLICK_PAUSE_S = 0.3


# ---------------------------------------------------------------------------------------------
# the server
# ---------------------------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def _tree_pids(pid: int) -> list[int]:
    """``pid`` and its descendants (``--num-procs`` forks workers)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children.get(p, []))
    return out


def _rss_mb(pid: int) -> float:
    """Resident memory of ``pid`` and its descendants (MB)."""
    total = 0.0
    for p in _tree_pids(pid):
        try:
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) / 1024
        except OSError:
            pass
    return total


def _cpu_s(pid: int) -> float:
    """CPU time (user + system) of ``pid`` and its descendants (s)."""
    total = 0
    for p in _tree_pids(pid):
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += int(fields[11]) + int(fields[12])  # utime, stime (clock ticks)
    return total / os.sysconf("SC_CLK_TCK")


class Server:
    """``gmwm-app`` on a free loopback port in a subprocess (stopped on exit)."""

    def __init__(self, num_procs: int, timeout: float = 60, prebuild: int | None = None) -> None:
        self.port = _free_port()
        self.num_procs = num_procs
        cmd = [sys.executable, "-m", "gmwm_app", "--address", HOST, "--port", str(self.port)]
        cmd += ["--no-show"]
        if num_procs > 1:
            cmd += ["--num-procs", str(num_procs)]
        if prebuild is not None:
            cmd += ["--prebuild", str(prebuild)]
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
        self.log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            cmd, env=env, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True
        )
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"gmwm-app exited with status {self.proc.returncode}: {cmd}")
            try:
                with socket.create_connection((HOST, self.port), timeout=1):
                    return
            except OSError:
                time.sleep(0.2)
        self.stop()
        raise RuntimeError(f"gmwm-app did not listen on {HOST}:{self.port} in {timeout:.0f} s")

    @property
    def url(self) -> str:
        return self.url_by(HOST)

    def url_by(self, name: str) -> str:
        """The page's URL by the host name ``name`` (the server expects ``HOST``)."""
        return f"http://{name}:{self.port}/"

    def rss_mb(self) -> float:
        return _rss_mb(self.proc.pid)

    def pools_reported(self) -> int:
        """Server processes that printed "pages ready ahead" (their pool was full once)."""
        self.log.seek(0)
        return len(set(re.findall(r"pages ready ahead \(process (\d+)\)", self.log.read())))

    async def wait_pools(self, timeout: float) -> float:
        """Wait until every process reported a full pool and the server's CPU time stays
        flat for a second (no page being built); the seconds waited."""
        t0 = time.perf_counter()
        deadline = t0 + timeout
        while time.perf_counter() < deadline:
            cpu = self.cpu_s()
            await asyncio.sleep(1.0)
            if self.pools_reported() >= self.num_procs and self.cpu_s() - cpu < 0.05:
                return time.perf_counter() - t0
        raise RuntimeError(f"the page pools did not fill in {timeout:.0f} s")

    def cpu_s(self) -> float:
        return _cpu_s(self.proc.pid)

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10)
        self.log.close()

    def __enter__(self) -> Server:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


# ---------------------------------------------------------------------------------------------
# a session over Bokeh's websocket protocol
# ---------------------------------------------------------------------------------------------
def _walk(obj: Any) -> Any:
    """Every serialised Bokeh model (``{"type": "object", "id": ...}``) in a document's JSON."""
    stack = [obj]
    while stack:
        o = stack.pop()
        if isinstance(o, dict):
            if o.get("type") == "object" and "id" in o:
                yield o
            stack.extend(o.values())
        elif isinstance(o, list):
            stack.extend(o)


def _entries(rep: Any) -> dict[str, Any]:
    """A serialised map (``{"type": "map", "entries": [...]}``) or a plain dict, as a dict."""
    if isinstance(rep, dict) and rep.get("type") == "map":
        return {k: v for k, v in rep.get("entries", [])}
    return rep if isinstance(rep, dict) else {}


def _length(rep: Any) -> int:
    """The length of a serialised column (a list or an ndarray)."""
    if isinstance(rep, list):
        return len(rep)
    if isinstance(rep, dict) and rep.get("type") == "ndarray":
        shape = rep.get("shape") or [0]
        return int(shape[0])
    return 0


@dataclass
class Session:
    """One page: its HTTP request, its websocket and the models the benchmark watches."""

    url: str
    cpu: Any = None  # the server's CPU time (s), read at each phase of a page alone
    t0: float = 0.0
    t_html: float = float("nan")
    t_doc: float = float("nan")
    t_ready: float = float("nan")
    ids: dict[str, str] = field(default_factory=dict)
    cpus: list[float] = field(default_factory=list)
    n_models: int = 0
    error: str = ""
    _ws: Any = None
    _receiver: Any = None
    _wv_seen: bool = False
    _info_seen: bool = False
    _events: asyncio.Queue | None = None
    _reader: asyncio.Task | None = None

    @property
    def ready_s(self) -> float:
        return self.t_ready - self.t0

    async def open(self, timeout: float) -> None:
        """Open the page until it is ready (see the module's docstring); errors are kept."""
        try:
            await asyncio.wait_for(self._open(), timeout)
        except Exception as e:  # reported as a failed session, the others go on
            self.error = f"{type(e).__name__}: {e}"

    async def _open(self) -> None:
        from bokeh.protocol import Protocol
        from bokeh.protocol.receiver import Receiver
        from tornado.httpclient import AsyncHTTPClient, HTTPRequest
        from tornado.websocket import websocket_connect

        self._cpu()
        self.t0 = time.perf_counter()
        resp = await AsyncHTTPClient().fetch(self.url, request_timeout=600, connect_timeout=600)
        html = resp.body.decode()
        self.t_html = time.perf_counter()
        self._cpu()
        m = re.search(r'"token":\s*"([^"]+)"', html) or re.search(r"token\W+([\w.-]{40,})", html)
        if m is None:
            raise RuntimeError("no session token in the page's HTML")
        netloc = self.url.split("/")[2]  # the name the page was opened by (--host-name)
        req = HTTPRequest(
            f"ws://{netloc}/ws",
            headers={"Origin": f"http://{netloc}"},
            request_timeout=600,
            connect_timeout=600,
        )
        self._ws = await websocket_connect(
            req, subprotocols=["bokeh", m.group(1)], max_message_size=256 * 1024 * 1024
        )
        self._receiver = Receiver(Protocol())
        ack = await self._next_message()
        if ack.msgtype != "ACK":
            raise RuntimeError(f"expected ACK, got {ack.msgtype}")
        await self._send("PULL-DOC-REQ", {})
        while True:
            msg = await self._next_message()
            if msg.msgtype == "PULL-DOC-REPLY":
                break
        self.t_doc = time.perf_counter()
        self._cpu()
        self._index(msg.content["doc"])
        self._events = asyncio.Queue()
        self._reader = asyncio.ensure_future(self._read_forever())
        await self.send_event("document_ready", [])
        while not (self._wv_seen and self._info_seen):
            await self._events.get()
        self.t_ready = time.perf_counter()
        self._cpu()

    def _cpu(self) -> None:
        if self.cpu is not None:
            self.cpus.append(self.cpu())

    def _index(self, doc: Any) -> None:
        """Ids of the watched models: data sources by name, the "+ GM" and remove buttons."""
        removes = []
        self.n_models = sum(1 for _ in _walk(doc))
        for o in _walk(doc):
            attrs = _entries(o.get("attributes", {}))
            name, label = attrs.get("name"), attrs.get("label")
            if o.get("name") == "ColumnDataSource" and name in ("empirical", "component_0"):
                self.ids[name] = o["id"]
            button = str(o.get("name", "")).endswith("Button")  # Panel's or Bokeh's
            if button and label == "+ GM":
                self.ids["add_gm"] = o["id"]
            if button and "gmwm-remove" in str(attrs.get("css_classes", "")):
                removes.append(o["id"])
        if removes:  # the first process row's remove button (document order)
            self.ids["remove_first"] = min(removes, key=lambda i: int(re.sub(r"\D", "", i) or 0))
        missing = {"empirical", "component_0", "add_gm"} - set(self.ids)
        if missing:
            raise RuntimeError(f"models not found in the document: {sorted(missing)}")

    async def _next_message(self) -> Any:
        while True:
            frag = await self._ws.read_message()
            if frag is None:
                raise RuntimeError("the server closed the websocket")
            msg = await self._receiver.consume(frag)
            if msg is not None:
                return msg

    async def _send(self, msgtype: str, content: dict[str, Any]) -> None:
        header = {"msgid": uuid.uuid4().hex, "msgtype": msgtype}
        for part in (header, {}, content):
            await self._ws.write_message(json.dumps(part))

    async def send_event(self, name: str, entries: list[Any]) -> None:
        """A Bokeh UI event, as BokehJS sends it (a ``MessageSent`` patch)."""
        event = {
            "kind": "MessageSent",
            "msg_type": "bokeh_event",
            "msg_data": {
                "type": "event",
                "name": name,
                "values": {"type": "map", "entries": entries},
            },
        }
        await self._send("PATCH-DOC", {"events": [event]})

    async def click(self, key: str) -> None:
        """Click the button ``self.ids[key]``."""
        await self.send_event("button_click", [["model", {"id": self.ids[key]}]])

    async def _read_forever(self) -> None:
        assert self._events is not None
        try:
            while True:
                msg = await self._next_message()
                if msg.msgtype != "PATCH-DOC":
                    continue
                for ev in msg.content.get("events", []):
                    self._observe(ev)
        except Exception as e:
            await self._events.put(("closed", str(e)))

    def _observe(self, ev: dict[str, Any]) -> None:
        assert self._events is not None
        model = (ev.get("model") or {}).get("id")
        if ev.get("kind") == "ModelChanged" and ev.get("attr") == "text":
            if "WV levels" in str(ev.get("new")):
                self._info_seen = True
                self._events.put_nowait(("info", None))
        data = None
        if ev.get("kind") == "ModelChanged" and ev.get("attr") == "data":
            data = _entries(ev.get("new"))
        elif ev.get("kind") == "ColumnDataChanged":
            data = _entries(ev.get("data") or ev.get("new"))
        if data is None:
            return
        if model == self.ids.get("empirical") and _length(data.get("tau_s")) > 0:
            self._wv_seen = True
            self._events.put_nowait(("wv", None))
        if model == self.ids.get("component_0"):
            labels = data.get("label")
            first = labels[0] if isinstance(labels, list) and labels else None
            self._events.put_nowait(("component_0", first))

    async def timed_click(self, key: str, want: str, timeout: float) -> float:
        """Seconds from a click on ``key`` until ``component_0`` arrives labelled ``want...``."""
        assert self._events is not None
        while not self._events.empty():
            self._events.get_nowait()
        t = time.perf_counter()
        await self.click(key)

        async def wait() -> None:
            while True:
                kind, value = await self._events.get()
                if kind == "closed":
                    raise RuntimeError(f"session closed: {value}")
                if kind == "component_0" and (value is None or str(value).startswith(want)):
                    return

        await asyncio.wait_for(wait(), timeout)
        return time.perf_counter() - t

    async def close(self) -> None:
        if self._reader is not None:
            self._reader.cancel()
        if self._ws is not None:
            self._ws.close()


# ---------------------------------------------------------------------------------------------
# measurements
# ---------------------------------------------------------------------------------------------
def _pct(xs: list[float], q: float) -> float:
    """The ``q`` quantile of ``xs`` (nearest rank: the value at least q of them are below)."""
    s = sorted(xs)
    return s[max(0, min(len(s) - 1, int(-(-q * len(s) // 1)) - 1))]


async def _burst(url: str, n: int, timeout: float) -> list[Session]:
    sessions = [Session(url) for _ in range(n)]
    await asyncio.gather(*(s.open(timeout) for s in sessions))
    return sessions


async def _single(url: str, timeout: float, cpu: Any = None) -> Session:
    s = Session(url, cpu=cpu)
    await s.open(timeout)
    await s.close()
    if s.error:
        raise RuntimeError(f"a single page did not open: {s.error}")
    return s


def _close_all(sessions: list[Session]) -> Any:
    return asyncio.gather(*(s.close() for s in sessions))


async def measure_burst(
    n: int,
    num_procs: int,
    timeout: float,
    prebuild: int | None = None,
    cold: bool = False,
    name: str = HOST,
) -> dict[str, Any]:
    """A fresh server; warm: the pools full, one warm-up page, the reference (one page
    alone), the pools full again, then ``n`` at once; cold: ``n`` at once as soon as the
    server listens, then the reference."""
    pool_s = float("nan")
    with Server(num_procs, prebuild=prebuild) as srv:
        if not cold:
            if prebuild != 0:
                pool_s = await srv.wait_pools(max(timeout, 300))
            await _single(srv.url, timeout)  # warm-up: imports, first document
            ref = await _single(srv.url, timeout, srv.cpu_s)
            await asyncio.sleep(1.0)
            if prebuild != 0:
                await srv.wait_pools(max(timeout, 300))
        rss0, cpu0 = srv.rss_mb(), srv.cpu_s()
        t = time.perf_counter()
        # (the burst by --host-name; the warm-up and the reference by the name expected)
        sessions = await _burst(srv.url_by(name), n, timeout)
        wall = time.perf_counter() - t
        rss1, cpu1 = srv.rss_mb(), srv.cpu_s()
        await _close_all(sessions)
        if cold:
            ref = await _single(srv.url, timeout, srv.cpu_s)
    ok = [s for s in sessions if not s.error]
    ready = [s.ready_s for s in ok]
    return {
        "n": n,
        "ok": len(ok),
        "errors": sorted({s.error for s in sessions if s.error}),
        "ref": ref.ready_s,
        "ref_parts": (ref.t_html - ref.t0, ref.t_doc - ref.t_html, ref.t_ready - ref.t_doc),
        "ref_cpu": [b - a for a, b in zip(ref.cpus, ref.cpus[1:], strict=False)],
        "models": ref.n_models,
        "p50": _pct(ready, 0.5) if ready else float("nan"),
        "p95": _pct(ready, 0.95) if ready else float("nan"),
        "max": max(ready) if ready else float("nan"),
        "html_max": max((s.t_html - s.t0 for s in ok), default=float("nan")),
        "wall": wall,
        "mb_per_session": (rss1 - rss0) / n,
        "cpu_per_session": (cpu1 - cpu0) / n,
        "rss0": rss0,
        "pool_s": pool_s,
    }


async def _clicks(probe: Session, k: int, timeout: float, stop: asyncio.Event | None) -> list:
    """Up to ``k`` add/remove pairs (stops early when ``stop`` is set); their latencies."""
    out = []
    for _ in range(k):
        out.append(await probe.timed_click("add_gm", "GM", timeout))
        await asyncio.sleep(CLICK_PAUSE_S)
        out.append(await probe.timed_click("remove_first", "WN", timeout))
        await asyncio.sleep(CLICK_PAUSE_S)
        if stop is not None and stop.is_set():
            break
    return out


async def measure_clicks(
    n: int, num_procs: int, clicks: int, timeout: float, prebuild: int | None = None
) -> dict[str, Any]:
    """Click-to-redraw of one session, alone and while ``n`` other sessions open at once
    (with the pools full first, unless ``prebuild`` is 0)."""
    with Server(num_procs, prebuild=prebuild) as srv:
        if prebuild != 0:
            await srv.wait_pools(max(timeout, 300))
        await _single(srv.url, timeout)  # warm-up
        probe = Session(srv.url + "?channel=gyro_x&model=WN%2BRW")
        await probe.open(timeout)
        if probe.error or "remove_first" not in probe.ids:
            raise RuntimeError(f"the clicking session did not open: {probe.error or 'no remove'}")
        await asyncio.sleep(0.5)
        idle = await _clicks(probe, clicks, timeout, None)
        stop = asyncio.Event()
        burst = asyncio.ensure_future(_burst(srv.url, n, timeout))
        burst.add_done_callback(lambda _f: stop.set())
        busy: list[float] = []
        while not stop.is_set():  # click for as long as the pages are opening
            busy += await _clicks(probe, 1, timeout, None)
            await asyncio.sleep(CLICK_PAUSE_S)
        sessions = await burst
        await _close_all([*sessions, probe])
    ready = [s.ready_s for s in sessions if not s.error]
    return {
        "n": n,
        "idle_med": statistics.median(idle),
        "busy_med": statistics.median(busy),
        "busy_max": max(busy),
        "busy_count": len(busy),
        "open_max": max(ready) if ready else float("nan"),
        "ok": len(ready),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[10, 20, 30], help="burst sizes")
    ap.add_argument("--num-procs", type=int, default=1, help="server processes (gmwm-app)")
    ap.add_argument("--click-n", type=int, default=20, help="sessions opening during clicks")
    ap.add_argument("--clicks", type=int, default=5, help="add/remove pairs on the idle server")
    ap.add_argument("--timeout", type=float, default=120.0, help="time limit per burst (s)")
    ap.add_argument(
        "--prebuild", type=int, default=None, help="gmwm-app --prebuild (default: the app's)"
    )
    ap.add_argument("--cold", action="store_true", help="burst at once, the pools empty")
    ap.add_argument("--cold-and-warm", action="store_true", help="each burst size cold, then warm")
    ap.add_argument(
        "--host-name",
        default=HOST,
        help=f"the name the burst's sessions open the server by (it serves and expects {HOST}; "
        "e.g. localhost: a class whose browsers use another name than the one expected)",
    )
    ap.add_argument("--no-clicks", action="store_true", help="skip the click measurement")
    args = ap.parse_args(argv)
    if any(not 1 <= n <= MAX_SESSIONS for n in [*args.n, args.click_n]):
        ap.error(f"--n and --click-n must be 1..{MAX_SESSIONS}")
    if args.num_procs < 1:
        ap.error("--num-procs must be at least 1")
    if args.num_procs > 1:
        helptext = subprocess.run(
            [sys.executable, "-m", "gmwm_app", "--help"], capture_output=True, text=True
        ).stdout
        if "--num-procs" not in helptext:
            ap.error("this gmwm-app has no --num-procs option")

    from tornado.httpclient import AsyncHTTPClient

    AsyncHTTPClient.configure(None, max_clients=2 * MAX_SESSIONS)
    load = os.getloadavg()
    print(
        f"bench_load: {os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} "
        f"{load[2]:.2f}, --num-procs {args.num_procs}, --prebuild "
        f"{'default' if args.prebuild is None else args.prebuild}{', cold' if args.cold else ''}"
        f", opened by {args.host_name}"
    )
    print("page ready = HTML + whole document over the websocket + the first data (WV) drawn")
    rows = []
    modes = [True, False] if args.cold_and_warm else [args.cold]
    for n, cold in ((n, cold) for n in args.n for cold in modes):
        r = asyncio.run(
            measure_burst(n, args.num_procs, args.timeout, args.prebuild, cold, args.host_name)
        )
        rows.append(r)
        err = f"  FAILED {r['n'] - r['ok']}: {r['errors']}" if r["errors"] else ""
        print(
            f"N={n:3d} {'cold' if cold else 'warm'}: page ready p50 {r['p50']:.2f} s, p95 "
            f"{r['p95']:.2f} s, max "
            f"{r['max']:.2f} s (x{r['p95'] / r['ref']:.1f} a single page's {r['ref']:.2f} s; "
            f"target p95 < {TARGET_P95_S:g} s); all in {r['wall']:.1f} s; memory "
            f"{r['mb_per_session']:.1f} MB/session (server {r['rss0']:.0f} MB before); server CPU "
            f"{r['cpu_per_session']:.2f} s/session; pools filled in {r['pool_s']:.0f} s{err}",
            flush=True,
        )
        h, d, w = r["ref_parts"]
        cpu = r["ref_cpu"] + [float("nan")] * (3 - len(r["ref_cpu"]))
        print(
            f"       single page: wall HTML {h:.2f} s, document {d:.2f} s, first data {w:.2f} "
            f"s; server CPU {sum(r['ref_cpu']):.2f} s (HTML {cpu[0]:.2f} s, document "
            f"{cpu[1]:.2f} s, first data {cpu[2]:.2f} s); {r['models']} Bokeh models"
        )
    c = None
    if not args.no_clicks:
        c = asyncio.run(
            measure_clicks(args.click_n, args.num_procs, args.clicks, args.timeout, args.prebuild)
        )
        print(
            f"click '+ GM'/remove -> component_0 redrawn: idle median {c['idle_med'] * 1e3:.0f} "
            f"ms; while {c['n']} pages open ({c['ok']} ready, last at {c['open_max']:.1f} s): "
            f"median {c['busy_med'] * 1e3:.0f} ms, max {c['busy_max'] * 1e3:.0f} ms over "
            f"{c['busy_count']} clicks (x{c['busy_max'] / c['idle_med']:.1f} idle; target < "
            f"{TARGET_CLICK_S * 1e3:.0f} ms)"
        )
    load = os.getloadavg()
    print(f"load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    met = all(r["ok"] == r["n"] for r in rows) and all(
        r["p95"] < TARGET_P95_S for r in rows if r["n"] <= 30
    )
    met = met and (c is None or c["busy_max"] < TARGET_CLICK_S)
    print("targets met" if met else "targets NOT met")
    return 0


if __name__ == "__main__":
    sys.exit(main())
