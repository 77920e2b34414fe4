"""Every action a person takes in the app, timed in Chromium (a script; pytest does not
collect it).

    python tests/benchmarks/bench_actions.py [--repeat 3]

The server runs in this process (``gmwm_app.server.create_application``, no page built ahead,
the demo log); Chromium (tests/_browser.py's launcher) opens one page and takes, in turn:

* page ready: ``goto`` until the data summary ("WV levels") is shown;
* channel switch: choose another channel until the WV plot's data source changed and two
  animation frames passed;
* typed model: type a model spec in the model box and press Enter, until the decomposition's
  first curve changed (two frames after);
* add / remove a process: "+ GM", then the first process's remove button (the same end);
* a tab's first opening: click the tab until its "Opening ... " placeholder is gone.

Each row gives the wall time (median and max over ``--repeat`` rounds; a tab opens for the
first time once per page, so its rounds are fresh pages) and the server's CPU time for the
action (this process's CPU time: the server and the Playwright client, which is small), with
a same-run reference: the smallest round trip (a button that replaces one line's data).
Target: every action within 0.5 s.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from functools import partial
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "tests" / "benchmarks"))

from _browser import CHROMIUM, launch  # noqa: E402
from bench_app import _JS_SOURCE, _demo, _free_port, _reference_app  # noqa: E402

TARGET_S = 0.5
TABS = ("Model selection", "Slope method", "Multi-channel", "Datasheet check", "Plan")

# resolve on the next change of a named data source, two animation frames after it
_JS_NEXT_CHANGE = """
(name) => {
  const find = FIND;
  const src = find(name);
  window.__gmwm_done = null;
  window.__gmwm_t0 = performance.now();
  let armed = true;
  const done = () => {
    if (!armed) { return; }
    armed = false;
    requestAnimationFrame(() => requestAnimationFrame(() => {
      window.__gmwm_done = performance.now() - window.__gmwm_t0;
    }));
  };
  src.properties.data.change.connect(done);
  src.change.connect(done);
  src.streaming.connect(done);
  src.patching.connect(done);
}
""".replace("FIND", _JS_SOURCE.strip())


class Timer:
    """Wall (browser-side when armed) and this process's CPU time of one action."""

    def __init__(self, page: Any) -> None:
        self.page = page

    def on_source(self, action: Any, source: str) -> tuple[float, float]:
        self.page.evaluate(_JS_NEXT_CHANGE, source)
        c0 = time.process_time()
        action()
        self.page.wait_for_function("() => window.__gmwm_done !== null", timeout=60_000, polling=5)
        cpu = time.process_time() - c0
        return float(self.page.evaluate("() => window.__gmwm_done")) / 1e3, cpu

    def on_gone(self, action: Any, text: str) -> tuple[float, float]:
        t0, c0 = time.perf_counter(), time.process_time()
        action()
        self.page.get_by_text(text).first.wait_for(state="detached", timeout=60_000)
        self.page.wait_for_timeout(0)
        return time.perf_counter() - t0, time.process_time() - c0


def _idle(app: Any, page: Any) -> None:
    deadline = time.time() + 60
    while app.busy and time.time() < deadline:
        page.wait_for_timeout(20)
    page.wait_for_timeout(300)


def _open(browser: Any, url: str) -> tuple[Any, float, float]:
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    t0, c0 = time.perf_counter(), time.process_time()
    page.goto(url)
    page.get_by_text("WV levels").first.wait_for(timeout=120_000)
    return page, time.perf_counter() - t0, time.process_time() - c0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="rounds of each action")
    args = ap.parse_args(argv)
    if not CHROMIUM.exists():
        print(f"{CHROMIUM} is missing: install Debian chromium", file=sys.stderr)
        return 2
    import tempfile

    import panel as pn
    from playwright.sync_api import sync_playwright

    from gmwm_app.app import live_apps
    from gmwm_app.server import create_application

    times: dict[str, list[tuple[float, float]]] = {}

    def add(name: str, wall_cpu: tuple[float, float]) -> None:
        times.setdefault(name, []).append(wall_cpu)

    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="gmwm_bench_") as d:
        os.environ["GMWM_APP_DEMO"] = str(_demo(Path(d)))
        port = _free_port()
        server = pn.serve(
            {"/": create_application(prebuild=0), "/ref": _reference_app},
            port=port,
            address="127.0.0.1",
            show=False,
            threaded=True,
            verbose=False,
            websocket_origin=[f"127.0.0.1:{port}"],
        )
        time.sleep(1.0)
        url = f"http://127.0.0.1:{port}/"
        try:
            with sync_playwright() as p:
                browser = launch(p)
                ref = browser.new_page(viewport={"width": 1400, "height": 1000})
                ref.goto(url + "ref")
                go = ref.get_by_role("button", name="go")
                go.wait_for(timeout=60_000)
                ref.wait_for_timeout(300)
                for _ in range(args.repeat):
                    add(
                        "reference: a button replaces one line's data",
                        Timer(ref).on_source(go.click, "ref"),
                    )
                ref.close()
                _open(browser, url)[0].close()  # warm-up: first-time imports of a page
                for r in range(args.repeat):
                    page, wall, cpu = _open(browser, url + "?channel=gyro_x&model=WN%2BRW")
                    add("page ready (goto -> 'WV levels' shown)", (wall, cpu))
                    app = live_apps()[-1]
                    timer = Timer(page)
                    _idle(app, page)
                    chans = [c for c in app.state.channels if c != app.state.channel]
                    select = page.locator("select").first
                    add(
                        "channel switch -> WV redrawn",
                        timer.on_source(
                            partial(select.select_option, chans[r % len(chans)]), "empirical"
                        ),
                    )
                    _idle(app, page)
                    box = page.get_by_placeholder("e.g. WN+RW+2*GM")
                    box.fill("GM+WN+RW" if r % 2 == 0 else "2*GM+WN")

                    add(
                        "typed model + Enter -> decomposition redrawn",
                        timer.on_source(partial(box.press, "Enter"), "component_0"),
                    )
                    _idle(app, page)
                    gm = page.get_by_role("button", name="+ GM", exact=True)
                    add("add a process (+ GM) -> redrawn", timer.on_source(gm.click, "component_0"))
                    _idle(app, page)
                    rm = page.locator(".gmwm-remove button").first
                    add("remove a process -> redrawn", timer.on_source(rm.click, "component_0"))
                    _idle(app, page)
                    for title in TABS:
                        tab = page.locator(".bk-tab", has_text=title).first
                        try:
                            add(
                                f"first opening of tab '{title}'",
                                timer.on_gone(tab.click, f"Opening {title} ..."),
                            )
                        except Exception as e:  # reported, the other tabs go on
                            print(f"tab {title!r}: {type(e).__name__}", file=sys.stderr)
                        _idle(app, page)
                    page.close()
                browser.close()
        finally:
            server.stop()

    ref_wall = statistics.median(
        w for w, _ in times["reference: a button replaces one line's data"]
    )
    width = max(map(len, times))
    print(
        f"bench_actions: {os.cpu_count()} cores, load average {load0:.1f} at the start, "
        f"{os.getloadavg()[0]:.1f} at the end; {args.repeat} rounds; demo log"
    )
    print(
        f"{'action':<{width}}  {'wall median':>11}  {'wall max':>8}  {'x ref':>6}  "
        f"{'CPU median':>10}"
    )
    worst = 0.0
    for name, xs in times.items():
        walls, cpus = [w for w, _ in xs], [c for _, c in xs]
        if not name.startswith("reference") and not name.startswith("page ready"):
            worst = max(worst, max(walls))
        print(
            f"{name:<{width}}  {statistics.median(walls):>9.3f} s  {max(walls):>6.3f} s  "
            f"{statistics.median(walls) / ref_wall:>6.1f}  {statistics.median(cpus):>8.3f} s"
        )
    print(
        f"slowest action {worst:.2f} s: target {TARGET_S} s "
        f"{'met' if worst <= TARGET_S else 'NOT met'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
