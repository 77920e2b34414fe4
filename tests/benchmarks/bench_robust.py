"""Robust WV benchmark. Run: ``python tests/benchmarks/bench_robust.py [--n N]``.

Prints, for a series of N samples (default 6.3e6, WN + RW + drift), best-of-``--repeat`` times of
the classical WV, the robust WV and their ratio, measured in the same run with the BLAS pool
limited to one thread (as the ``gmwm`` command and the app run), and the time of the previous
robust implementation for reference: the scale about zero by a full pass per Brent evaluation,
which the engine keeps as :func:`engine.wv.robust_scale_biweight` (the R ``wv`` definition;
with the BLAS pool at one thread its sums are the same ``np.dot`` as before).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import engine as eg
from engine._blas import set_blas_threads
from engine.wv import robust_scale_biweight
from engine.wv._kernel import cumsum_demeaned


def old_robust_wv(x: np.ndarray, levels: int) -> np.ndarray:
    """The previous robust WV of every level (scale about zero), kept for timing only."""
    s = cumsum_demeaned(x)
    out = np.empty(levels)
    for j in range(1, levels + 1):
        m = 1 << (j - 1)
        w = (s[2 * m :] - 2.0 * s[m:-m] + s[: s.size - 2 * m]) / (2.0 * m)
        out[j - 1] = robust_scale_biweight(w)
    return out


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=6_300_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--old", action=argparse.BooleanOptionalAction, default=True)
    args = ap.parse_args()
    set_blas_threads(1)
    rng = np.random.default_rng(0)
    n = args.n
    x = rng.standard_normal(n) + 1e-3 * rng.standard_normal(n).cumsum() + 1e-6 * np.arange(n)
    levels = eg.wv.default_levels(n)
    eg.wavelet_variance(x[:100_000], robust=True)  # warm caches (SciPy import, constants)
    t_cl, t_rb = [], []
    for _ in range(args.repeat):  # interleaved, so both see the same machine load
        t_cl.append(best_of(lambda: eg.wavelet_variance(x), 1))
        t_rb.append(best_of(lambda: eg.wavelet_variance(x, robust=True), 1))
    cl, rb = min(t_cl), min(t_rb)
    print(f"N = {n:,}, J = {levels}, best of {args.repeat}")
    print(f"classical WV : {cl:8.3f} s")
    print(f"robust WV    : {rb:8.3f} s   ratio robust/classical = {rb / cl:6.1f}x (target <= 20x)")
    if args.old:
        t_old = best_of(lambda: old_robust_wv(x, levels), 1)
        print(
            f"old robust WV: {t_old:8.3f} s   ({t_old / cl:6.1f}x classical, {t_old / rb:.1f}x new)"
        )


if __name__ == "__main__":
    main()
