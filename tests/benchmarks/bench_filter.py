"""Proof in a filter (issue 23, item 4): are exported noise numbers consistent in a Kalman filter?

    python tests/benchmarks/bench_filter.py [--runs 100] [--minutes 20] [--fix 1 10 100]

The sensor errors are simulated from the ``2*GM+WN+RW`` model fitted to the real ADIS16405 log
(``adis16405_imu1.h5``: gyro_x in deg/s, accel_x in g; its sub-sample GM and its slow GM), and a
one-axis filter (``tests/filtersim.py``: integral and bias states, 100 Hz, an absolute fix of the
integral every T_fix seconds) is given only N and K:

* (a) the plain conversion of the ``WN+RW`` fit (the Kalibr export's numbers);
* (b) the full fit projected onto WN + RW and over-bounded by the engine's projection
  (``engine.formats.projection.project``, the numbers the filter formats write);
* (c) the folk 10x inflation of (a);
* (a0) for reference, the full fit's own WN and RW terms (N = 0: the exports before issue 23).

Per case and fix interval: the mean NEES of the integral (1 when consistent), the fractions of
epochs whose run-averaged NEES is below / inside / above the 95 % band chi2_M(0.025, 0.975)/M,
and the fraction of (run, epoch) pairs whose error is inside its 2-sigma bound (95.4 % when
consistent); the inflation factors are N/N_a and K/K_a.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from conftest import real_data_dir  # noqa: E402
from filtersim import filter_cases, run_monte_carlo  # noqa: E402

import engine as eg  # noqa: E402

#: channel -> (fix standard deviation in the integral's unit, that unit)
CHANNELS = {"gyro_x": (0.01, "deg"), "accel_x": (1e-3, "g s")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", type=Path, default=real_data_dir() / "adis16405_imu1.h5")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--fix", type=float, nargs="+", default=[1.0, 10.0, 100.0])
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    if not args.log.is_file():
        sys.exit(f"bench_filter: no log at {args.log}; give --log PATH (see README, Data)")
    log = eg.load_log(args.log)
    fs = float(log.fs)
    t_all = time.perf_counter()
    print(
        f"{args.log.name}, {args.runs} runs of {args.minutes:g} min at {fs:g} Hz; case (b): "
        "engine projection"
    )
    for ch, (fix_sigma, iunit) in CHANNELS.items():
        fc = filter_cases(log[ch], fs, ch)
        unit = log.units.get(ch, "u")
        a = fc.cases["a"]
        print(f"\n{ch} [{unit}]: truth {fc.truth_fit.model.spec()}")
        for key, p in fc.truth_fit.params.items():
            print(f"    {key:14s} {p:.4g}")
        print(f"  fix every T_fix s, sigma {fix_sigma:g} {iunit}; bound: {fc.bound_info}")
        print(
            "\n| case | N | K | N/N_a | K/K_a | T_fix s | mean NEES | below / in / above band"
            " | in 2 sigma |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for key in ("a", "b", "c", "a0"):
            noise = fc.cases[key]
            fn, fk = noise.factors_over(a)
            for t_fix in args.fix:
                r = run_monte_carlo(
                    fc.truth,
                    noise,
                    fs=fs,
                    duration_s=60.0 * args.minutes,
                    t_fix_s=t_fix,
                    fix_sigma=fix_sigma,
                    runs=args.runs,
                    seed=args.seed,
                )
                lo, inside, hi = r.fractions()
                print(
                    f"| {noise.label} | {noise.N:.3g} | {noise.K:.3g} | {fn:.2f} | {fk:.2f} "
                    f"| {t_fix:g} | {r.mean_nees:.3f} "
                    f"| {100 * lo:.0f} / {100 * inside:.0f} / {100 * hi:.0f} % "
                    f"| {100 * r.in_2sigma:.1f} % |"
                )
        print(f"  (band of the {args.runs}-run average: {r.band[0]:.3f} .. {r.band[1]:.3f})")
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
