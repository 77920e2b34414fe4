"""Monte Carlo of the log check (engine.io.qualify): false alarms on clean logs, detections
of planted defects.

False alarms: R clean simulated logs of each model class (2e5 samples at 100 Hz, 33 min);
for every check, the share of logs where it raised a warning, with its Clopper-Pearson 95 %
band. Detections: R logs of the first class with one defect planted; the share where the
right check fired and its first range overlaps the planted samples.

Usage::

    nice python tests/benchmarks/qualify_mc.py [--reps 200] [--seed 1]

Prints Markdown tables (docs/qualify.md holds its output) and the CPU time per log.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import stats

import engine as eg
from engine.io.qualify import KINDS, qualify_signal

FS = 100.0
N = 200_000
CLASSES = {
    "WN+RW+GM (ADIS-like gyro)": "WN(sigma2=1e-2)+RW(gamma2=1e-10)+GM(beta=0.05,sigma2_gm=1e-4)",
    "WN+QN": "WN(sigma2=1.0)+QN(q2=0.1)",
    "AR1(0.99)+WN+RW": "AR1(phi=0.99,sigma2=1e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-8)",
    "WN+RW quantised (step 0.5 SD)": "quantised",
    "Student t3 + RW (heavy tails)": "t3",
}
BASE = CLASSES["WN+RW+GM (ADIS-like gyro)"]


def clean(kind: str, rng: np.random.Generator) -> np.ndarray:
    if kind == "quantised":
        x = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-10)").simulate(N, fs=FS, rng=rng)
        return np.round(x / 0.05) * 0.05
    if kind == "t3":
        return 0.1 * rng.standard_t(3, size=N) + np.cumsum(rng.normal(size=N)) * 1e-5
    return eg.parse_model(kind).simulate(N, fs=FS, rng=rng)


def band(k: int, n: int) -> str:
    lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def plant(defect: str, x: np.ndarray, rng: np.random.Generator) -> tuple[str, tuple[int, int]]:
    t = np.arange(N) / FS
    if defect == "shock: 20 samples at 10 SD":
        a = int(rng.integers(10_000, N - 10_000))
        x[a : a + 20] += rng.normal(size=20) * 1.0
        return "shock", (a, a + 20)
    if defect == "motion: noise x1.5 for 60 s":
        a = int(rng.integers(10_000, N - 20_000))
        x[a : a + 6000] += rng.normal(size=6000) * 0.1 * np.sqrt(1.5**2 - 1)
        return "motion", (a, a + 6000)
    if defect == "clipping at the 99.8 % quantile":
        top = np.quantile(x, 0.998)
        np.minimum(x, top, out=x)
        i = np.flatnonzero(x == top)
        return "saturation", (int(i[0]), int(i[-1]) + 1)
    if defect == "line: 13.3 Hz, amplitude 0.3 SD":
        x += 0.03 * np.sin(2 * np.pi * 13.3 * t + rng.uniform(0, 6.3))
        return "periodic", (0, N)
    if defect == "warm-up: 0.1 deg/s, tau 60 s":
        x += 0.1 * np.exp(-t / 60)
        return "warmup", (0, 6000)
    if defect == "thermal ramp: 0.5 deg/s over the log":
        x += 0.5 * t / t[-1]
        return "trend", (0, N)
    raise ValueError(defect)


DEFECTS = (
    "shock: 20 samples at 10 SD",
    "motion: noise x1.5 for 60 s",
    "clipping at the 99.8 % quantile",
    "line: 13.3 Hz, amplitude 0.3 SD",
    "warm-up: 0.1 deg/s, tau 60 s",
    "thermal ramp: 0.5 deg/s over the log",
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    checks = [k for k in KINDS if k not in ("quantisation", "timing")]
    print(f"False alarms: share of {a.reps} clean logs (2e5 samples) where a check warned, %")
    print("[Clopper-Pearson 95 % band]\n")
    print("| model class | " + " | ".join(checks) + " | any |")
    print("|---|" + "---|" * (len(checks) + 1))
    cpu = []
    for label, kind in CLASSES.items():
        hits = dict.fromkeys([*checks, "any"], 0)
        for _ in range(a.reps):
            x = clean(kind, rng)
            t0 = time.process_time()
            found = {f.kind for f in qualify_signal(x, FS) if f.severity == "warning"}
            cpu.append(time.process_time() - t0)
            for k in found:
                hits[k] += 1
            hits["any"] += bool(found)
        row = " | ".join(band(hits[k], a.reps) for k in [*checks, "any"])
        print(f"| {label} | {row} |", flush=True)
    print(f"\nCPU per log of 2e5 samples: median {1e3 * np.median(cpu):.0f} ms\n")
    print(f"Detections: share of {a.reps} logs ({BASE}) where the right check fired on the")
    print("planted samples, %\n")
    print("| defect | check | fired, % [95 % band] | its range overlaps the planted one, % |")
    print("|---|---|---|---|")
    for defect in DEFECTS:
        fired = hit = 0
        for _ in range(a.reps):
            x = clean(BASE, rng)
            kind, (lo, hi) = plant(defect, x, rng)
            fs = [f for f in qualify_signal(x, FS) if f.kind == kind]
            fired += bool(fs)
            hit += any(ra < hi and lo < rb for f in fs for ra, rb in f.ranges)
        print(f"| {defect} | {kind} | {band(fired, a.reps)} | {band(hit, a.reps)} |", flush=True)


if __name__ == "__main__":
    main()
