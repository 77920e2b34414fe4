"""The slope-method Monte Carlo (the GMWM paper, Fig. 1-2) from the command line.

Run: ``python tests/benchmarks/bench_study.py [--reps R] [--seed S] [--n 2.5e6,6.3e6]
[--workers 2] [--methods GMWM,GMWM-efficient,ARMAV,AVSM,AVSM-auto] [--out DIR]``.

Prints the per-replicate cost of each step on one replicate of each sensor at the longest
length (simulation, WV, each estimator), then runs the study with a progress bar on stderr
and prints the bias / SD / RMSE table, the markdown table for docs/benchmarks.md and the wall time;
with ``--out`` it writes study.json, study.md, study.txt, boxplot.png and rmse.png there.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from engine.fit import fit_gmwm
from engine.fit.estimate import from_gmwm
from engine.fit.gmwfm import fit_armav
from engine.teaching import METHODS, avsm, avsm_auto, run_slope_study, table1_model, typical_regions
from engine.wv import wavelet_variance
from engine.wv.allan import AllanVariance


def step_costs(n: int, fs: float = 250.0) -> None:
    """Time each step of one replicate per sensor."""
    print(f"one replicate at T = {n:.3g} samples (s):")
    print(
        f"  {'sensor':<7} {'simulate':>9} {'WV':>9} {'GMWM':>9} {'ARMAV':>9} {'AVSM':>9} "
        f"{'AVSM-auto':>9}"
    )
    for sensor in ("gyro", "accel"):
        truth = table1_model(sensor, fs)
        t = [time.perf_counter()]
        x = truth.simulate(n, fs=fs, rng=np.random.default_rng(0))
        t.append(time.perf_counter())
        wv = wavelet_variance(x, fs=fs)
        t.append(time.perf_counter())
        from_gmwm(fit_gmwm(wv, truth.cleared()))
        t.append(time.perf_counter())
        fit_armav(wv, truth.cleared()).as_estimate()
        t.append(time.perf_counter())
        av = AllanVariance.from_wv(wv)
        avsm(av, typical_regions(sensor, n, fs))
        t.append(time.perf_counter())
        avsm_auto(av)
        t.append(time.perf_counter())
        d = np.diff(t)
        print(f"  {sensor:<7} " + " ".join(f"{v:>9.4f}" for v in d))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--n", default="2.5e6,6.3e6", help="log lengths, comma-separated")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--methods",
        default="GMWM,GMWM-efficient,ARMAV,AVSM",
        help=f"comma-separated among {','.join(METHODS)}",
    )
    ap.add_argument("--out", default=None, help="output directory")
    ap.add_argument("--no-steps", action="store_true", help="skip the per-step timing")
    args = ap.parse_args()
    ns = [float(v) for v in args.n.split(",") if v.strip()]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if not args.no_steps:
        step_costs(int(max(ns)))
    t0 = time.perf_counter()
    res = run_slope_study(
        args.reps, seed=args.seed, n_values=ns, methods=methods, workers=args.workers, progress=True
    )
    wall = time.perf_counter() - t0
    print()
    print(res.table())
    print()
    print(res.markdown())
    if args.out:
        paths = res.save(args.out)
        print("\nwrote " + ", ".join(paths.values()))
    print(
        f"\nwall time {wall:.1f} s for {args.reps} replicates x {len(ns)} lengths x 2 sensors "
        f"on {args.workers} worker(s)"
    )


if __name__ == "__main__":
    main()
