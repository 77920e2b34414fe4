"""Why a strong drift can break the J-test, and where :data:`DRIFT_SHARE_MAX` sits: the size of
the test against the drift's share of ``Var(nu_j)``, with V at the truth and V at the estimate.
Run from the repository root (27 s of CPU at the defaults):

    nice -n 10 python tests/benchmarks/jtest_drift_scan.py [--omegas 1e-3,2e-3,3e-3,5e-3,1e-2,3e-2]
        [--log2n 14] [--gamma2 1e-4] [--reps 300] [--seed 51]

For each drift ``omega``, ``--reps`` classical WVs of WN(sigma2=1)+RW(gamma2)+DR(omega) at
100 Hz are tested for the true structure at 5 % in three ways, on the levels of
:func:`engine.inference.jtest.jtest_levels`:

* ``truth V, no fit``: ``r' V^-1 r`` with ``r = nu_hat - nu(truth)`` and V at the truth,
  against chi2(levels);
* ``truth V, refit``: the efficient refit with V at the truth, against chi2(levels - p);
* ``V at the estimate``: what ``j_test`` computes (ci fit, V at it, efficient refit, V at the
  refit, refit), without the calibration rule.

Then the logs of all omegas are pooled and binned by the rule's number (the drift's share over
the rest at the estimate, :func:`engine.inference.jtest.drift_share_ratio`), so each bin's
rejection rate shows what the rule lets through. ``docs/jtest.md`` holds the output.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy import stats

import engine as eg
from engine.fit import wv_cov_model
from engine.inference.jtest import DRIFT_SHARE_MAX, drift_share_ratio, efficient_j, jtest_levels

FS = 100.0
SPEC = "WN(sigma2=1)+RW(gamma2={})+DR(omega={})"


def one_log(truth: eg.Model, n: int, rng: np.random.Generator) -> tuple[float, ...]:
    """p-values of the three statistics and the share ratio at the truth and at the estimate."""
    wv = eg.wavelet_variance(truth.simulate(n, fs=FS, rng=rng), fs=FS)
    k = jtest_levels(wv)
    vt = wv_cov_model(truth, wv)
    r = (wv.variance - truth.wv(wv.tau_samples, FS))[:k]
    p_nofit = stats.chi2.sf(float(r @ np.linalg.solve(vt[:k, :k], r)), k)
    t, df, _, _ = efficient_j(wv, truth, vt)
    p_truth = stats.chi2.sf(t, df)
    fit = eg.fit_gmwm(wv, truth.cleared())
    _, _, _, refit = efficient_j(wv, fit.model, wv_cov_model(fit.model, wv))
    t, df, _, refit = efficient_j(wv, refit.model, wv_cov_model(refit.model, wv))
    return (
        p_nofit,
        p_truth,
        stats.chi2.sf(t, df),
        drift_share_ratio(truth, wv, k)[0],
        drift_share_ratio(refit.model, wv, k)[0],
    )


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson 95 % interval of k / n."""
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(c - h, 0.0), min(c + h, 1.0)


def rate(p: np.ndarray) -> str:
    """Rejections at 5 %: count, percent and Wilson band."""
    k, n = int(np.sum(p < 0.05)), p.size
    if n == 0:
        return "0/0"
    lo, hi = wilson(k, n)
    return f"{k}/{n} ({100 * k / n:.1f} %, [{100 * lo:.1f}, {100 * hi:.1f}])"


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--omegas", default="1e-3,2e-3,3e-3,5e-3,1e-2,3e-2")
    ap.add_argument("--log2n", type=int, default=14)
    ap.add_argument("--gamma2", default="1e-4", help="the random walk's gamma2")
    ap.add_argument("--reps", type=int, default=300)
    ap.add_argument("--seed", type=int, default=51)
    args = ap.parse_args()
    cpu0 = time.process_time()
    rows = []
    print(
        f"WN(1)+RW({args.gamma2})+DR(omega), 2^{args.log2n}, {args.reps} logs each, "
        f"seed {args.seed}"
    )
    print(
        "| omega | share at the truth | share at the estimate, median [10 %, 90 %] "
        "| truth V, no fit | truth V, refit | V at the estimate |"
    )
    print("|---|---|---|---|---|---|")
    for om in args.omegas.split(","):
        truth = eg.parse_model(SPEC.format(args.gamma2, om))
        rng = np.random.default_rng(args.seed)
        a = np.array([one_log(truth, 2**args.log2n, rng) for _ in range(args.reps)])
        rows.append(a)
        q = np.percentile(a[:, 4], [50, 10, 90])
        print(
            f"| {om} | {np.median(a[:, 3]):.3g} | {q[0]:.3g} [{q[1]:.3g}, {q[2]:.3g}] "
            f"| {rate(a[:, 0])} | {rate(a[:, 1])} | {rate(a[:, 2])} |",
            flush=True,
        )
    a = np.concatenate(rows)
    print(
        f"\nAll {len(a)} logs by the share at the estimate (DRIFT_SHARE_MAX = {DRIFT_SHARE_MAX:g})"
    )
    print("| share at the estimate | logs | V at the estimate | truth V, refit |")
    print("|---|---|---|---|")
    edges = [0, 100, 300, 600, 1000, 2000, 4000, 10000, math.inf]
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (a[:, 4] > lo) & (a[:, 4] <= hi)
        if m.any():
            print(f"| ({lo:g}, {hi:g}] | {int(m.sum())} | {rate(a[m, 2])} | {rate(a[m, 1])} |")
    m = a[:, 4] <= DRIFT_SHARE_MAX
    print(
        f"| calibrated by the rule (<= {DRIFT_SHARE_MAX:g}) | {int(m.sum())} | {rate(a[m, 2])} "
        f"| {rate(a[m, 1])} |"
    )
    print(
        f"| not calibrated by the rule | {int((~m).sum())} | {rate(a[~m, 2])} | {rate(a[~m, 1])} |"
    )
    print(f"\n{time.process_time() - cpu0:.0f} s of CPU")


if __name__ == "__main__":
    main()
