"""Screenshot of the calibration report for README and docs (``gmwm report``, ``eg.report``).

Makes the report of the bundled demo log's gyro X (model GM+WN+RW, with a gyroscope
datasheet to check), opens it in headless Chromium from ``file://`` with every other request
aborted, and saves the top of the page (the log and the channel's first figures) as a PNG.

Run from the repository root::

    python tests/benchmarks/shot_report.py [--out docs/figures/report_demo.png]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from _browser import screenshot_top  # noqa: E402

import engine as eg  # noqa: E402

DATASHEET = "arw=0.3 deg/sqrt(h), bi=6 deg/h, rrw=1 deg/h/sqrt(h)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs/figures/report_demo.png"))
    ap.add_argument("--height", type=int, default=1500, help="pixels of the page to keep")
    args = ap.parse_args()

    os.chdir(ROOT)  # the report shows the file as given: engine/demo/demo_imu.h5
    with tempfile.TemporaryDirectory() as d:
        page_path = Path(d) / "report.html"
        eg.report(
            os.path.relpath(eg.demo_path(), ROOT),
            page_path,
            model="GM+WN+RW",
            channels=["gyro_x"],
            datasheet=DATASHEET,
            command_line="gmwm report demo_imu.h5 --channels gyro_x --model GM+WN+RW "
            f"--datasheet '{DATASHEET}' -o report.html",
        )
        screenshot_top(page_path, args.out, width=1150, height=args.height, ready="#fig-gyro_x-psd")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
