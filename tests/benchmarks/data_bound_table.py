"""Before/after of the data bound on the six ADIS16405 logs.

    python tests/benchmarks/data_bound_table.py

Per unit and channel, the WN+RW fit exported as the filter formats do (``project(fit,
"WN+RW")``): with ``data="none"`` (the fitted model alone: the default before issue 28) and
with the default ``data="low"`` (also the lower end of the empirical 95 % interval). Columns:
N [deg/s/sqrt(Hz) or g/sqrt(Hz)] and K [deg/s^2/sqrt(Hz) or g/s/sqrt(Hz)] in the
logs' units, the number of dyadic scales (of 19, from 2 filter steps = 0.02 s to the longest,
5243 s) where the file's WV is below the empirical lower limit, and the smallest ratio file WV /
lower limit over them.

    python tests/benchmarks/data_bound_table.py --tails

The tail factors (``engine.formats.tails``; what ``gmwm export`` applies by default): per unit
and channel, the largest factor over the band and its scale (s), the factors at 10.24, 20.48
and 40.96 s, and the default export's N and K with the tail factors over those without them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from conftest import real_data_dir  # noqa: E402

import engine as eg  # noqa: E402
from engine.formats.tails import tail_factors  # noqa: E402


def main() -> None:
    print("| unit | channel | data | N | K | scales below the lower limit | min WV / lower limit |")
    print("|---|---|---|---|---|---|---|")
    for i in range(1, 7):
        log = eg.load_log(real_data_dir() / f"adis16405_imu{i}.h5")
        for ch in log.names:
            wv = log.wavelet_variance(ch)
            fit = eg.fit_gmwm(wv, "WN+RW")
            tau = np.asarray(wv.tau_samples, float)
            for data in ("none", "low"):
                p = eg.formats.project(fit, "WN+RW", unit="", ci=None, data=data)
                fw = p.value("N") ** 2 * log.fs / tau + p.value("K") ** 2 / log.fs * (
                    tau**2 + 2
                ) / (12 * tau)
                r = fw / np.asarray(wv.ci_low)
                print(
                    f"| {i} | {ch} | {data} | {p.value('N'):.4g} | {p.value('K'):.4g} "
                    f"| {int(np.sum(r < 1 - 1e-9))} of {tau.size} | {r.min():.2f} |"
                )


def tails() -> None:
    print(
        "| unit | channel | largest factor | at tau s | factor at 10.24 / 20.48 / 40.96 s "
        "| N with / without | K with / without |"
    )
    print("|---|---|---|---|---|---|---|")
    for i in range(1, 7):
        log = eg.load_log(real_data_dir() / f"adis16405_imu{i}.h5")
        for ch in log.names:
            tf = tail_factors(log[ch], fs=log.fs, channel=ch)
            fit = eg.fit_gmwm(log.wavelet_variance(ch), "WN+RW")
            a = eg.formats.project(fit, "WN+RW", unit="", ci=None)
            b = eg.formats.project(fit, "WN+RW", unit="", ci=None, tails=tf)
            f, t = tf.largest()
            mid = " / ".join(f"{v:.2f}" for v in tf.at(np.array([1024.0, 2048.0, 4096.0])))
            print(
                f"| {i} | {ch} | {f:.2f} | {t:.4g} | {mid} "
                f"| {b.value('N') / a.value('N'):.3f} | {b.value('K') / a.value('K'):.3f} |"
            )


if __name__ == "__main__":
    tails() if sys.argv[1:2] == ["--tails"] else main()
