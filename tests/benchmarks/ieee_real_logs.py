"""IEEE quantities of the real static logs (../shared/data): the table of docs/ieee.md.

Per channel of the six ADIS16405 units and the MTi-G gyro: the ARW/VRW of two fitted
structures (2*GM+QN, the structure the default selection picks on these logs today, whose
white noise is carried by a GM faster than one sample; and GM+WN+QN+RW), the Allan deviation
read at exactly T = 1 s from the raw series and the ratio, the IEEE 952 B (model floor /
0.664), the model's Allan-deviation minimum and the data's, each with its T, and K.

Run from the repository root: ``nice -n 10 python tests/benchmarks/ieee_real_logs.py``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import engine as eg

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
FILES = [f"adis16405_imu{k}.h5" for k in range(1, 7)] + ["mtig_cont_imu1.h5"]
MODELS = ("2*GM+QN", "GM+WN+QN+RW")


def main() -> int:
    t0 = time.perf_counter()
    print(
        "| log | channel | N 2*GM+QN | N GM+WN+QN+RW | ADEV(1 s) | ratio | B (IEEE) | "
        "ADEV min model (T) | ADEV min data (T) | K |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in FILES:
        log = eg.load_log(DATA / name)
        for ch in log.names:
            x = log[ch]
            adev1 = float(eg.allan_variance(x, fs=log.fs, taus=[int(log.fs)]).adev[0])
            wv = log.wavelet_variance(ch)
            tabs = [eg.fit_gmwm(wv, m).ieee for m in MODELS]
            n1, n2 = (t["N"] for t in tabs)
            t = tabs[1]
            # ADEV(1 s) in the datasheet unit of N: the same factor as N's (x 60 ...)
            f = n2.datasheet_value / n2.native
            b, am, ad, k = t["B"], t["ADEV_min"], t["ADEV_data"], t.get("K")

            def iv(q: eg.fit.ieee.IeeeQuantity) -> str:
                return f"{q.datasheet_value:.3g} [{q.datasheet_low:.3g}, {q.datasheet_high:.3g}]"

            print(
                f"| {name.removesuffix('.h5')} | {ch} | {n1.datasheet_value:.3f} | {iv(n2)} "
                f"{n2.datasheet_unit} | {adev1 * f:.3f} | {n2.native / adev1:.3f} | "
                f"{iv(b)} {b.datasheet_unit} | {am.datasheet_value:.3g} ({am.tau_s:.3g} s) | "
                f"{iv(ad)} ({ad.tau_s:.3g} s) | "
                f"{(iv(k) + ' ' + k.datasheet_unit) if k else '-'} |"
            )
            sys.stdout.flush()
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
