"""False alarms and power of the log check's warm-up wander scan (docs/qualify.md).

    nice -n 10 python tests/benchmarks/wander_mc.py --reps 30

False alarms: clean triads (three independent axes) of six model classes at four lengths and
rates; the share of triads where ``engine.io.qualify.wander_test`` gives a scan-adjusted
p-value below ``WANDER_ALPHA`` (1 %), with Clopper-Pearson 95 % bands. Power: WN (SD 0.1) +
RW (gamma2 1e-8 per sample) whose innovation variance is ``r`` times larger in the first
``T`` (a share of the log), 2e5 samples at 100 Hz: the share found, and the median cut over T.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import engine as eg  # noqa: E402
from engine.io.qualify import WANDER_ALPHA, wander_test  # noqa: E402

CLASSES = {
    "WN+RW": "WN(sigma2=1e-2)+RW(gamma2=1e-8)",
    "GM+WN+RW": "GM(beta=0.02,sigma2_gm=1e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-9)",
    "2*GM+WN+RW": "GM(beta=0.5,sigma2_gm=1e-4)+GM(beta=0.005,sigma2_gm=1e-3)"
    "+WN(sigma2=1e-2)+RW(gamma2=1e-9)",
    "WN+RW+DR": "WN(sigma2=1e-2)+RW(gamma2=1e-8)+DR(omega=1e-6)",
    "WN+RW quantised (step 0.5 SD)": "WN(sigma2=1e-2)+RW(gamma2=1e-8)",
    "WN only": "WN(sigma2=1e-2)",
}
LENGTHS = ((2**16, 50.0), (200_000, 100.0), (200_000, 400.0), (1_000_000, 100.0))


def band(k: int, n: int) -> str:
    lo = 0.0 if k == 0 else stats.beta.ppf(0.025, k, n - k + 1)
    hi = 1.0 if k == n else stats.beta.ppf(0.975, k + 1, n - k)
    return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def triad(name: str, n: int, fs: float, rng: np.random.Generator) -> list[np.ndarray]:
    model = eg.parse_model(CLASSES[name])
    xs = [model.simulate(n, fs=fs, rng=rng) for _ in range(3)]
    if "quantised" in name:
        xs = [np.round(x / 0.05) * 0.05 for x in xs]
    return xs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=100)
    args = ap.parse_args()
    t0 = time.process_time()
    rng = np.random.default_rng(1)
    head = " | ".join(f"{n:,} at {fs:g} Hz ({n / fs / 60:.0f} min)" for n, fs in LENGTHS)
    print(f"False alarms, % of {args.reps} clean triads [Clopper-Pearson 95 %]\n")
    print(f"| model class | {head} |")
    print("|---" * (1 + len(LENGTHS)) + "|")
    total = [0, 0]
    for name in CLASSES:
        cells = []
        for n, fs in LENGTHS:
            reps = args.reps if n < 1_000_000 else max(args.reps // 2, 1)
            k = sum(wander_test(triad(name, n, fs, rng), fs)[0] < WANDER_ALPHA for _ in range(reps))
            total[0] += k
            total[1] += reps
            cells.append(band(k, reps))
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    print(f"\nall: {band(*total)} of {total[1]} triads; CPU {time.process_time() - t0:.0f} s\n")
    print("Power: WN + RW with the RW's innovation variance x r in the first T, 2e5 samples")
    print("at 100 Hz (2000 s), triads; found, % [95 %]; median cut / T (quartiles)\n")
    print("| r | T = 5 % (100 s) | T = 10 % (200 s) | T = 20 % (400 s) |")
    print("|---|---|---|---|")
    reps = max(args.reps // 2, 1)
    for r in (2.0, 4.0, 8.0):
        cells = []
        for share in (0.05, 0.10, 0.20):
            found, cuts = 0, []
            for _ in range(reps):
                g = np.full(200_000, 1e-8)
                g[: int(share * 200_000)] *= r
                xs = [
                    rng.normal(scale=0.1, size=g.size) + np.cumsum(rng.normal(size=g.size) * g**0.5)
                    for _ in range(3)
                ]
                p, _, _, start, _ = wander_test(xs, 100.0)
                if p < WANDER_ALPHA:
                    found += 1
                    cuts.append(start / (share * 200_000))
            q = np.percentile(cuts, [25, 50, 75]) if cuts else [np.nan] * 3
            cells.append(f"{band(found, reps)}; {q[1]:.2f} ({q[0]:.2f}-{q[2]:.2f})")
        print(f"| {r:g} | " + " | ".join(cells) + " |", flush=True)
    print(f"\nCPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()
