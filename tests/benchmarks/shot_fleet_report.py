"""Screenshot of the fleet acceptance report for docs/reports.md (``gmwm batch --report``).

Makes the fleet report of the six ADIS16405 logs of ``../shared/data`` (channels gyro_x and
accel_x, model GM+WN+RW, limits ARW <= 0.3 deg/sqrt(h) and VRW <= 0.1 m/s/sqrt(h)) plus a
damaged copy of one (its first 5000 bytes: listed with its reason), opens it in headless
Chromium from ``file://`` with every other request aborted, and saves the top of the page
(the acceptance table, the gyroscope's term table and its overlaid Allan deviations) as a PNG.

Run from the repository root::

    python tests/benchmarks/shot_fleet_report.py [--data ../shared/data]
        [--out docs/figures/fleet_report.png]
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

SPEC = ["arw<=0.3 deg/sqrt(h)", "vrw<=0.1 m/s/sqrt(h)"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--out", default=str(ROOT / "docs/figures/fleet_report.png"))
    ap.add_argument("--height", type=int, default=1700, help="pixels of the page to keep")
    args = ap.parse_args()

    data = Path(args.data)
    with tempfile.TemporaryDirectory() as d:
        bad = Path(d) / "adis16405_imu7.h5"
        bad.write_bytes((data / "adis16405_imu1.h5").read_bytes()[:5000])
        files = [str(data / f"adis16405_imu{k}.h5") for k in range(1, 7)] + [str(bad)]
        page_path = Path(d) / "fleet.html"
        eg.fleet_report(
            files,
            page_path,
            model="GM+WN+RW",
            channels=["gyro_x", "accel_x"],
            spec=SPEC,
            command_line="gmwm batch adis16405_imu*.h5 adis16405_imu7.h5 --model GM+WN+RW "
            "--channels gyro_x,accel_x --spec 'arw<=0.3 deg/sqrt(h)' "
            "--spec 'vrw<=0.1 m/s/sqrt(h)' --report fleet.html",
        )
        print(f"fleet report: {os.path.getsize(page_path) / 1e6:.2f} MB")
        screenshot_top(
            page_path,
            args.out,
            width=1300,
            height=args.height,
            ready="#fig-fleet-gyro_x-adev",
            ready_timeout_ms=180_000,
            settle_ms=2500,
        )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
