"""MA1 against the QN + WN pair it contains, on every channel of the real logs (a script;
pytest does not collect it).

    python tests/benchmarks/ma1_real_logs.py [--data ../shared/data]

An MA1's WV spans every non-negative mix of the WN and QN shapes (``theta <= 0``) and more
(``theta > 0``: white noise whose neighbouring samples are positively correlated), so its fit
is at or below the QN + WN one. For each channel of the six ADIS16405 logs and the MTi-G log
it prints the GMWM objective (``ci`` weights) of MA1+RW and QN+WN+RW, of GM+MA1+RW and
GM+QN+WN+RW, and the fitted ``theta`` of MA1+RW, then one summary row per log (the ranges
over its channels of theta and of the objective ratios). The summary table in
docs/conventions.md ("MA1 on the real logs") is this script's output.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import engine as eg

LOGS = [f"adis16405_imu{i}.h5" for i in range(1, 7)] + ["mtig_cont_imu1.h5"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[3] / "shared/data"))
    args = ap.parse_args(argv)
    rows = []
    print("| log | channel | MA1+RW | QN+WN+RW | GM+MA1+RW | GM+QN+WN+RW | theta (MA1+RW) |")
    print("|---|---|---|---|---|---|---|")
    for name in LOGS:
        log = eg.load_log(Path(args.data) / name)
        for ch in log.channels:
            wv = log.wavelet_variance(ch)
            fits = {
                m: eg.fit_gmwm(wv, m) for m in ("MA1+RW", "QN+WN+RW", "GM+MA1+RW", "GM+QN+WN+RW")
            }
            obj = {m: f.objective for m, f in fits.items()}
            theta = fits["MA1+RW"].params["MA1.theta"]
            rows.append((name, ch, obj, theta))
            print(
                f"| {name.removesuffix('.h5')} | {ch} | {obj['MA1+RW']:.4g} "
                f"| {obj['QN+WN+RW']:.4g} | {obj['GM+MA1+RW']:.4g} | {obj['GM+QN+WN+RW']:.4g} "
                f"| {theta:.3f} |"
            )
    print("\n| log | channels | theta (MA1+RW) | QN+WN+RW / MA1+RW | GM+QN+WN+RW / GM+MA1+RW |")
    print("|---|---|---|---|---|")
    for name in LOGS:
        mine = [(o, t) for n, _, o, t in rows if n == name]
        th = [t for _, t in mine]
        r1 = [o["QN+WN+RW"] / o["MA1+RW"] for o, _ in mine]
        r2 = [o["GM+QN+WN+RW"] / o["GM+MA1+RW"] for o, _ in mine]
        print(
            f"| {name.removesuffix('.h5')} | {len(mine)} | {min(th):.3f} to {max(th):.3f} "
            f"| {min(r1):.3g} to {max(r1):.3g} | {min(r2):.3g} to {max(r2):.3g} |"
        )
    below = sum(
        o["MA1+RW"] <= o["QN+WN+RW"] * (1 + 1e-9)
        and o["GM+MA1+RW"] <= o["GM+QN+WN+RW"] * (1 + 1e-9)
        for _, _, o, _ in rows
    )
    ratio = [o["GM+QN+WN+RW"] / o["GM+MA1+RW"] for _, _, o, _ in rows]
    print(
        f"\n{below} of {len(rows)} channels: both MA1 models at or below their QN+WN twins; "
        f"GM+QN+WN+RW / GM+MA1+RW objective ratio median {statistics.median(ratio):.3g} "
        f"(range {min(ratio):.3g} to {max(ratio):.3g})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
