"""The server loop while nine pages open at once (a script; pytest does not collect it).

    python tests/benchmarks/bench_loop.py [--rounds 2]

In this process: the app served on 127.0.0.1 (``tests/conftest.served_app``, a background
thread), nine pages opened at once over HTTP as ``tests/app/test_server_load.py`` opens them
(eight small logs and a 400,000-sample one, each named in its URL), then started; measured in
CPU time of the loop's thread (``time.thread_time``, which compares across loads of this
shared machine better than wall time):

* each page's first data applied on the loop (``Jobs._finish`` of its page load);
* the loop's CPU between two polls of its sockets: while it runs, no request is read (the
  probe of the load test waits that long at least), with what ran in the longest stretches:
  page-load applies and full (generation 2) garbage collections;
* how many page-load applies ran between two polls (at most one with the loop's turns,
  ``gmwm_app.jobs.LoopTurns``).

Same-run reference: one empty Bokeh ``figure`` built (CPU), as in ``bench_page.py``.
"""

from __future__ import annotations

import argparse
import gc
import selectors
import statistics
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from loadlogs import write_log  # noqa: E402


def _get(url: str) -> None:
    try:
        with urllib.request.urlopen(url, timeout=600) as r:
            r.read()
    except urllib.error.HTTPError:
        pass


class _LoopMeter:
    """The loop thread's CPU between two socket polls, and what ran meanwhile."""

    def __init__(self) -> None:
        self.stretches: list[tuple[float, list[str]]] = []
        self.applies: list[float] = []
        self._ran: list[str] = []
        self._last: dict[int, float] = {}
        self._gc0 = 0.0

    def install(self) -> None:
        from gmwm_app.jobs import Jobs

        meter = self
        select = selectors.EpollSelector.select

        def timed_select(sel: Any, timeout: Any = None) -> Any:
            tid, now = threading.get_ident(), time.thread_time()
            if tid in meter._last:
                meter.stretches.append((now - meter._last[tid], meter._ran))
            meter._ran = []
            try:
                return select(sel, timeout)
            finally:
                meter._last[tid] = time.thread_time()

        finish = Jobs._finish

        def timed_finish(jobs: Any, key: Any, *args: Any) -> Any:
            t = time.thread_time()
            try:
                return finish(jobs, key, *args)
            finally:
                if key == "page-load":
                    dt = time.thread_time() - t
                    meter.applies.append(dt)
                    meter._ran.append(f"apply {dt:.3f}")

        def on_gc(phase: str, info: dict[str, Any]) -> None:
            if info["generation"] != 2:
                return
            if phase == "start":
                self._gc0 = time.thread_time()
            else:  # (it stops every thread, the loop's too)
                self._ran.append(f"a full GC ({time.thread_time() - self._gc0:.3f} s)")

        selectors.EpollSelector.select = timed_select  # type: ignore[method-assign]
        Jobs._finish = timed_finish  # type: ignore[method-assign]
        gc.callbacks.append(on_gc)

    def clear(self) -> None:
        self.stretches.clear()
        self.applies.clear()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=2, help="bursts of nine pages")
    args = ap.parse_args(argv)

    from bokeh.plotting import figure
    from conftest import served_app

    from gmwm_app.app import live_apps
    from gmwm_app.state import demo_path

    figure()
    t = time.thread_time()
    for _ in range(10):
        figure()
    ref = (time.thread_time() - t) / 10
    meter = _LoopMeter()
    meter.install()
    tmp = Path(tempfile.mkdtemp(prefix="bench_loop_"))
    files = [write_log(tmp / f"log_{i}.h5", i) for i in range(8)]
    heavy = write_log(tmp / "heavy.h5", 99, n=400_000)
    queries = [{"source": "path", "path": str(heavy), "model": "WN+RW"}] + [
        {"source": "path", "path": str(f), "channel": "gyro_y", "model": "WN+RW"} for f in files
    ]
    load = open("/proc/loadavg").read().split()[:3]
    print(
        f"bench_loop: load average {' '.join(load)}; reference: an empty Bokeh figure "
        f"{ref * 1000:.1f} ms of CPU"
    )
    with served_app(demo_path(), unused_session_lifetime_milliseconds=10**7) as (port, _th):
        url = f"http://127.0.0.1:{port}/"
        _get(url + "?" + urlencode(queries[1]))  # the process's first page (imports, caches)
        for rnd in range(args.rounds):
            before = live_apps()
            gc.collect()
            meter.clear()
            gets = [
                threading.Thread(target=_get, args=(url + "?" + urlencode(q),)) for q in queries
            ]
            for g in gets:
                g.start()
            for g in gets:
                g.join()
            apps = [a for a in live_apps() if a.served and not any(a is b for b in before)]
            for a in apps:
                a.jobs.doc.add_next_tick_callback(a.start)
            deadline = time.time() + 600
            while not all(a.ready and not a.busy for a in apps) and time.time() < deadline:
                time.sleep(0.02)
            time.sleep(0.3)
            st = sorted(meter.stretches, key=lambda s: -s[0])
            per_poll = max(sum(r.startswith("apply") for r in ran) for _, ran in meter.stretches)
            ap_ = meter.applies
            print(
                f"round {rnd + 1}: {len(apps)} pages; first data applied on the loop: median "
                f"{statistics.median(ap_):.3f} s, max {max(ap_):.3f} s of CPU "
                f"(x{statistics.median(ap_) / ref:.1f} / x{max(ap_) / ref:.1f} the reference); "
                f"at most {per_poll} between two socket polls"
            )
            print(
                f"  loop CPU between two socket polls: max {st[0][0]:.3f} s "
                f"(x{st[0][0] / ref:.1f}); over 0.1 s: {sum(s > 0.1 for s, _ in st)}, over "
                f"0.05 s: {sum(s > 0.05 for s, _ in st)}; the longest three:"
            )
            for s, ran in st[:3]:
                print(f"    {s:.3f} s: {', '.join(ran) or 'other work'}")
            del apps, before
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
