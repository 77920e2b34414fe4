"""Screenshot of the app for README and docs (``gmwm-app`` on the bundled demo log).

Starts ``gmwm-app`` on a free local port (no browser of its own), opens the page with a model in
its link (the app keeps its state in the URL query) in headless Chromium, waits until BokehJS
has drawn the Fit tab's figures and the fit, saves the top of the page as a PNG and stops the
server.

Run from the repository root::

    python tests/benchmarks/shot_app.py [--out docs/figures/app_demo.png]
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from _browser import chromium, wait_for_canvases  # noqa: E402


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs/figures/app_demo.png"))
    ap.add_argument("--width", type=int, default=1400)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--query", default="?channel=gyro_x&model=2*GM%2BWN%2BRW", help="the link's")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for the page")
    args = ap.parse_args()

    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "gmwm_app", "--port", str(port), "--no-show"]
    server = subprocess.Popen(cmd, cwd=ROOT, env=env, start_new_session=True)
    url = f"http://localhost:{port}/"
    try:
        deadline = time.monotonic() + args.timeout
        while True:
            try:
                urllib.request.urlopen(url, timeout=30).read()
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    sys.exit(f"shot_app: gmwm-app did not serve {url}")
                time.sleep(1)
        with chromium() as b:
            page = b.new_page(viewport={"width": args.width, "height": args.height})
            page.goto(url + args.query, wait_until="load", timeout=int(args.timeout * 1000))
            wait_for_canvases(page, 2, int(args.timeout * 1000))
            page.get_by_text("sigma2_gm").first.wait_for(timeout=int(args.timeout * 1000))
            page.wait_for_timeout(3000)  # BokehJS paints the fit's curves after the table
            page.screenshot(path=args.out)
    finally:
        os.killpg(server.pid, signal.SIGINT)
        server.wait(timeout=60)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
