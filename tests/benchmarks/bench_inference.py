"""Inference and model-selection benchmarks (issue: inference). Run from the repository root:

    python tests/benchmarks/bench_inference.py [--n 1e6] [--workers 2]

* WVIC ranking of every distinct sub-model of 3*GM+WN+QN+RW+DR (63; R's 127 subsets less the
  duplicates of exchangeable GM terms) on an N-sample channel; target 10 s;
* parametric-bootstrap intervals with B = 100 on N samples; target 30 s;
* for reference in the same run: one fit of the largest model, and the analytic V.
"""

from __future__ import annotations

import argparse
import time

import engine as eg
from engine.fit.asymptotic import wv_cov_model
from engine.inference import param_intervals, rank_models

TRUTH = (
    "GM(beta=0.5, sigma2_gm=4e-4)+GM(beta=0.01, sigma2_gm=1e-4)+WN(sigma2=1e-2)+RW(gamma2=1e-10)"
)


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=float, default=1e6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("-B", type=int, default=100)
    args = ap.parse_args()
    n, fs = int(args.n), 100.0
    x = eg.parse_model(TRUTH).simulate(n, fs=fs, rng=1)
    wv = eg.wavelet_variance(x, fs=fs)
    print(f"series: N = {n:,} samples of {TRUTH} at {fs:g} Hz, {wv.n_levels} levels")
    big, t_fit = timed(lambda: eg.fit_gmwm(wv, "3*GM+WN+QN+RW+DR"))
    _, t_v = timed(lambda: wv_cov_model(big.model, wv))
    sel, t_sel = timed(lambda: rank_models(wv, max_model="3*GM+WN+QN+RW+DR"))
    res = eg.fit_gmwm(wv, "2*GM+WN+RW")
    _, t_asym = timed(lambda: param_intervals(res))
    ivs, t_boot = timed(
        lambda: param_intervals(res, method="bootstrap", B=args.B, workers=args.workers)
    )
    print(f"  one fit of 3*GM+WN+QN+RW+DR         {t_fit * 1e3:8.1f} ms")
    print(f"  analytic V ({wv.n_levels} x {wv.n_levels})               {t_v * 1e3:8.1f} ms")
    print(f"  WVIC ranking of {len(sel.candidates)} sub-models       {t_sel:8.2f} s   target 10 s")
    print(f"  asymptotic intervals                {t_asym * 1e3:8.1f} ms")
    print(
        f"  bootstrap intervals, B = {args.B}, {args.workers} workers {t_boot:8.2f} s   target 30 s"
    )
    print("\nbest five by WVIC:")
    print("\n".join(sel.table().splitlines()[1:7]))
    print("\nbootstrap 95 % intervals of 2*GM+WN+RW:")
    for iv in ivs:
        print(f"  {iv.name:<16} {iv.value:11.4e}  [{iv.low:.4e}, {iv.high:.4e}] {iv.unit}")


if __name__ == "__main__":
    main()
