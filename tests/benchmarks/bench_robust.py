"""Robust WV benchmark (issue #13 item 2). Run: ``python tests/benchmarks/bench_robust.py [--n N]``.

Prints, for a series of N samples (default 6.3e6, WN + RW + drift), best-of-``--repeat`` times of
the classical WV, the robust WV and their ratio, measured in the same run with the BLAS pool
limited to one thread (as the ``gmwm`` command and the app run), and the time of the previous
robust implementation (scale about zero by a full pass per Brent evaluation, copied below) for
reference.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import engine as eg
from engine._blas import set_blas_threads
from engine.wv import biweight_constant, cumsum_demeaned


def old_robust_scale_biweight(w: np.ndarray, eff: float = 0.6) -> float:
    """The previous robust WV of one level (scale about zero), kept for timing only."""
    from scipy import optimize

    from engine.wv.robust import gaussian_psi2_mean

    c = biweight_constant(eff)
    a_c = gaussian_psi2_mean(c)
    w = np.asarray(w, dtype=np.float64)
    mad = np.median(np.abs(w)) * 1.482602218505602
    if mad <= 0:
        mad = float(np.sqrt(np.mean(w * w)))
    if mad <= 0:
        return 0.0
    w2 = w / mad
    np.square(w2, out=w2)
    c2 = c * c
    r2 = np.empty_like(w2)
    u = np.empty_like(w2)

    def f(log_s2: float) -> float:
        np.multiply(w2, math.exp(-log_s2), out=r2)
        r2i = r2[r2 <= c2]
        ui = u[: r2i.size]
        np.multiply(r2i, -1.0 / c2, out=ui)
        ui += 1.0
        np.square(ui, out=ui)
        np.square(ui, out=ui)
        return float(np.dot(r2i, ui)) / w.size - a_c

    step = 0.5
    f0 = f(0.0)
    if f0 > 0:
        lo, hi = 0.0, step
        while f(hi) > 0:
            lo, hi = hi, hi + step
    else:
        hi, lo, f_prev = 0.0, -step, f0
        while True:
            f_lo = f(lo)
            if f_lo > 0:
                break
            if f_lo < f_prev or lo < -80:
                return float(np.exp(lo + step) * mad * mad)
            hi, lo, f_prev = lo, lo - step, f_lo
    root = optimize.brentq(f, lo, hi, xtol=1e-12)
    return float(np.exp(root) * mad * mad)


def old_robust_wv(x: np.ndarray, levels: int) -> np.ndarray:
    s = cumsum_demeaned(x)
    out = np.empty(levels)
    for j in range(1, levels + 1):
        m = 1 << (j - 1)
        w = (s[2 * m :] - 2.0 * s[m:-m] + s[: s.size - 2 * m]) / (2.0 * m)
        out[j - 1] = old_robust_scale_biweight(w)
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
    levels = eg.default_levels(n)
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
