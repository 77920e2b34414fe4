"""Benchmark of the app's responsiveness (a script; pytest does not collect it).

    python tests/benchmarks/bench_app.py [--clicks 10]

Measures, with the server in this process and Debian chromium driven by Playwright:

(a) add a process (click "+ GM") until the decomposition is redrawn in the browser: the click
    is time-stamped in the page, the end is two animation frames after the component data
    source received the new curve (median over the clicks, adding and removing alternately);
(b) the GMWM fit alone (engine) on the same WV, and the server-side work of one add (fit +
    in-place view update);
(c) load a 1e6-sample channel from a server path until its WV is drawn in the browser;
(d) the add-a-process latency of one tab while another tab computes a robust WV of 1e6
    samples (heavy work runs off the event loop).

Targets: (a) < 250 ms, (b) fit < 30 ms, (c) < 1 s.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from _browser import CHROMIUM, launch  # noqa: E402

import engine as eg  # noqa: E402

# JS helpers: find a data source by name in the page's Bokeh document
_JS_SOURCE = """
(name) => {
  for (const doc of Bokeh.documents) {
    const m = doc.get_model_by_name(name);
    if (m) return m;
  }
  return null;
}
"""
_JS_ARM = """
([name, col, idx, want]) => {
  const find = FIND;
  const src = find(name);
  window.__gmwm_done = null;
  window.__gmwm_t0 = performance.now();
  const check = () => {
    const v = src.data[col];
    const ok = want === null ? (v.length > idx) : (v.length > 0 && String(v[idx]).startsWith(want));
    if (ok && window.__gmwm_done === null) {
      // two animation frames: the plot has been painted with the new data
      requestAnimationFrame(() => requestAnimationFrame(() => {
        window.__gmwm_done = performance.now() - window.__gmwm_t0;
      }));
    }
  };
  src.properties.data.change.connect(check);
  src.change.connect(check);
}
""".replace("FIND", _JS_SOURCE.strip())


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _demo(tmp: Path) -> Path:
    from gmwm_app.state import demo_path

    p = demo_path()
    if p.exists():
        return p
    sys.path.insert(0, str(REPO / "data"))
    import make_demo  # the owner's generator (200,000 samples, six channels)

    return make_demo.make(tmp)


def _big_log(tmp: Path, n: int = 1_000_000) -> Path:
    from engine.io import save_log

    x = eg.parse_model("GM(beta=0.05, sigma2_gm=1e-5)+WN(sigma2=2e-3)+RW(gamma2=1e-11)").simulate(
        n, fs=100.0, rng=7
    )
    return save_log(tmp / "big_1e6.h5", {"gyro_x": x}, 100.0, units={"gyro_x": "deg/s"})


class Page:
    def __init__(self, browser: Any, url: str) -> None:
        self.page = browser.new_page(viewport={"width": 1400, "height": 1000})
        self.page.goto(url)
        self.page.get_by_text("WV levels").first.wait_for(timeout=30_000)
        self.page.wait_for_timeout(500)

    def timed(self, action: Any, source: str, col: str, idx: int, want: str | None) -> float:
        """Milliseconds from ``action()`` to two frames after ``source`` shows ``want``."""
        self.page.evaluate(_JS_ARM, [source, col, idx, want])
        action()
        self.page.wait_for_function("() => window.__gmwm_done !== null", timeout=30_000, polling=5)
        return float(self.page.evaluate("() => window.__gmwm_done"))


def _idle(app: Any, page: Page) -> None:
    """Wait until the session has no job running and the page has settled."""
    deadline = time.time() + 60
    while app.busy and time.time() < deadline:
        page.page.wait_for_timeout(20)
    page.page.wait_for_timeout(200)


def _reference_app() -> Any:
    """Same-run reference: a page whose button replaces one line's data (a minimal round trip)."""
    import panel as pn
    from bokeh.models import ColumnDataSource
    from bokeh.plotting import figure

    src = ColumnDataSource({"x": [1.0, 2.0], "y": [1.0, 2.0], "label": ["a", "a"]}, name="ref")
    fig = figure(height=300, x_axis_type="log", y_axis_type="log")
    fig.line("x", "y", source=src)
    button = pn.widgets.Button(label="go")
    count = [0]

    def go(_event: Any) -> None:
        count[0] += 1
        x = np.geomspace(1, 1e3, 130)
        src.data = {"x": x, "y": x**-0.5 * count[0], "label": [f"k{count[0]}"] * x.size}

    button.on_click(go)
    return pn.Column(button, pn.pane.Bokeh(fig))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clicks", type=int, default=10, help="add/remove pairs for (a)")
    args = ap.parse_args(argv)
    if not CHROMIUM.exists():
        print(f"{CHROMIUM} is missing: install Debian chromium", file=sys.stderr)
        return 2
    import panel as pn
    from playwright.sync_api import sync_playwright

    from gmwm_app.app import live_apps
    from gmwm_app.server import create_application

    rows: list[tuple[str, str, str, str]] = []
    with tempfile.TemporaryDirectory(prefix="gmwm_bench_") as d:
        tmp = Path(d)
        demo = _demo(tmp)
        os.environ["GMWM_APP_DEMO"] = str(demo)
        big = _big_log(tmp)
        port = _free_port()
        server = pn.serve(
            {"/": create_application(), "/ref": _reference_app},
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

                # reference: the smallest click -> new line data -> redraw round trip
                ref = browser.new_page(viewport={"width": 1400, "height": 1000})
                ref.goto(url + "ref")
                ref.get_by_role("button", name="go").wait_for(timeout=30_000)
                ref.wait_for_timeout(500)
                refp = Page.__new__(Page)
                refp.page = ref
                ref_ms = []
                go = ref.get_by_role("button", name="go")
                for i in range(1, 2 * args.clicks + 1):
                    ref_ms.append(refp.timed(go.click, "ref", "label", 0, f"k{i}"))
                ref.close()
                ref_med = statistics.median(ref_ms)
                rows.append(
                    (
                        "reference: click -> one line's data replaced -> redrawn",
                        f"{ref_med:.0f} ms",
                        f"{min(ref_ms):.0f} to {max(ref_ms):.0f} ms",
                        "",
                    )
                )

                # (a) add / remove a GM on the demo log, WN+RW already there
                pg = Page(browser, url + "?channel=gyro_x&model=WN%2BRW")
                app = [a for a in live_apps() if a.state.model.spec() == "WN+RW"][-1]
                add_ms, rem_ms, server_add = [], [], []
                gm = pg.page.get_by_role("button", name="+ GM", exact=True)
                for _ in range(args.clicks):
                    add_ms.append(pg.timed(gm.click, "component_0", "label", 0, "GM"))
                    server_add.append(app.last_refresh_s * 1e3)
                    rm = pg.page.locator(".gmwm-remove button").first
                    rem_ms.append(pg.timed(rm.click, "component_0", "label", 0, "WN"))
                rows.append(
                    (
                        "(a) click + GM -> decomposition redrawn (Chromium)",
                        f"{statistics.median(add_ms):.0f} ms",
                        f"{min(add_ms):.0f} to {max(add_ms):.0f} ms",
                        "< 250 ms",
                    )
                )
                rows.append(
                    (
                        "(a)   ratio to the reference round trip",
                        f"{statistics.median(add_ms) / ref_med:.2f}",
                        "",
                        "",
                    )
                )
                rows.append(
                    (
                        "(a) click remove GM -> redrawn (Chromium)",
                        f"{statistics.median(rem_ms):.0f} ms",
                        f"{min(rem_ms):.0f} to {max(rem_ms):.0f} ms",
                        "",
                    )
                )
                rows.append(
                    (
                        "(a) server side of one add: fit + views + tables",
                        f"{statistics.median(server_add):.1f} ms",
                        "",
                        "",
                    )
                )

                # (b) the fit alone, on the same cached WV
                wv = app.state.wv
                for spec in ("WN+RW", "GM+WN+RW", "2*GM+WN+RW"):
                    ts = []
                    for _ in range(20):
                        t0 = time.perf_counter()
                        eg.fit_gmwm(wv, spec)
                        ts.append((time.perf_counter() - t0) * 1e3)
                    rows.append(
                        (
                            f"(b) fit_gmwm {spec} ({len(wv)} levels)",
                            f"{statistics.median(ts):.1f} ms",
                            f"{min(ts):.1f} to {max(ts):.1f} ms",
                            "< 30 ms",
                        )
                    )

                # (c) a 1e6-sample channel from a server path, until its WV is drawn
                n_levels = eg.wv.default_levels(1_000_000)
                loads = []
                for _ in range(3):
                    pg.page.get_by_placeholder("/path/to/log.h5 (press Enter)").fill(str(big))

                    def load() -> None:
                        pg.page.get_by_role("button", name="Load path", exact=True).click()

                    _idle(app, pg)
                    loads.append(pg.timed(load, "empirical", "tau_s", n_levels - 1, None))
                    _idle(app, pg)
                    pg.page.get_by_role("button", name="Load the demo log", exact=True).click()
                    pg.page.wait_for_timeout(300)
                    _idle(app, pg)
                rows.append(
                    (
                        "(c) load 1e6-sample channel (path) -> WV drawn",
                        f"{statistics.median(loads):.0f} ms",
                        f"{min(loads):.0f} to {max(loads):.0f} ms",
                        "< 1000 ms",
                    )
                )
                t_read, t_wv = [], []
                for _ in range(3):
                    t0 = time.perf_counter()
                    lg = eg.io.load_log(big)
                    t1 = time.perf_counter()
                    eg.wavelet_variance(lg["gyro_x"], fs=lg.fs)
                    t_read.append((t1 - t0) * 1e3)
                    t_wv.append((time.perf_counter() - t1) * 1e3)
                rows.append(
                    (
                        "(c) of which: read HDF5 / compute WV (server)",
                        f"{statistics.median(t_read):.0f} / {statistics.median(t_wv):.0f} ms",
                        "",
                        "",
                    )
                )

                # (d) one tab stays responsive while another computes a robust WV of 1e6
                heavy = Page(browser, url + f"?source=path&path={big}&model=WN")
                heavy_app = [a for a in live_apps() if a.state.source == "path"][-1]
                light = pg
                _idle(app, light)
                heavy.page.locator(".gmwm-robust input").first.click()
                t_wait = time.time() + 5
                while not heavy_app.busy and time.time() < t_wait:
                    light.page.wait_for_timeout(10)
                during: list[float] = []
                server_during: list[float] = []
                while heavy_app.busy and len(during) < 6:
                    during.append(light.timed(gm.click, "component_0", "label", 0, "GM"))
                    server_during.append(app.last_refresh_s * 1e3)
                    rm = light.page.locator(".gmwm-remove button").first
                    during.append(light.timed(rm.click, "component_0", "label", 0, "WN"))
                busy_left = heavy_app.busy
                _idle(heavy_app, heavy)
                if during:
                    rows.append(
                        (
                            "(d) add/remove in one tab while another computes a robust WV (1e6)",
                            f"{statistics.median(during):.0f} ms",
                            f"{min(during):.0f} to {max(during):.0f} ms",
                            "< 250 ms",
                        )
                    )
                if server_during:
                    rows.append(
                        (
                            "(d)   of which server side of one add (fit + views + tables)",
                            f"{statistics.median(server_during):.1f} ms",
                            "",
                            "",
                        )
                    )
                rows.append(
                    (
                        "(d)   clicks measured during the heavy job",
                        f"{len(during)}",
                        "all" if busy_left else "job ended",
                        "",
                    )
                )
                browser.close()
        finally:
            server.stop()

    w = max(len(r[0]) for r in rows)
    print(f"\n{'measure':<{w}}  {'median':>12}  {'range':>20}  {'target':>10}")
    print("-" * (w + 50))
    for r in rows:
        print(f"{r[0]:<{w}}  {r[1]:>12}  {r[2]:>20}  {r[3]:>10}")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"\n{args.clicks} add/remove pairs; demo: {demo.name}; {os.cpu_count()} CPUs, "
        f"load average {load:.1f} at the end"
    )
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main())
