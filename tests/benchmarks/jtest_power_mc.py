"""Power of the J-test under the old and the present levels rule, on the same logs.

    nice -n 10 python tests/benchmarks/jtest_power_mc.py TRUTH TESTED LOG2N ROBUST REPS SEED

Each log (100 Hz, robust WV if ROBUST is 1) of the true model TRUTH is fitted with the wrong
model TESTED (ci weights), V is ``wv_cov_model`` at that fit, and the efficient refit is
compared with chi2(levels - p) on the levels of the old rule (``M_j / 2^j >= 4``) and of the
present one (:func:`engine.inference.jtest.jtest_levels`). Prints the rejection counts at 5 %
every 10 logs. The power table of ``docs/jtest.md`` is this script's output.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy import stats

import engine as eg
from engine.fit import fit_gmwm
from engine.fit.asymptotic import free_params, inverse_cov, wv_cov_model
from engine.inference.jtest import jtest_levels


def main() -> None:
    """Run one setting from the command line."""
    truth_s, tested, log2n, robust, reps, seed = (
        sys.argv[1],
        sys.argv[2],
        int(sys.argv[3]),
        sys.argv[4] == "1",
        int(sys.argv[5]),
        int(sys.argv[6]),
    )
    truth = eg.parse_model(truth_s)
    rng = np.random.default_rng(seed)
    rej: dict[str, list[bool]] = {"old": [], "new": []}
    t0 = time.process_time()
    for i in range(reps):
        wv = eg.wavelet_variance(
            truth.simulate(2**log2n, fs=100.0, rng=rng), fs=100.0, robust=robust
        )
        res = fit_gmwm(wv, tested)
        v = wv_cov_model(res.model, wv)
        eta = wv.n_coef / wv.tau_samples
        for rule, k in (("old", int(np.sum(eta >= 4))), ("new", jtest_levels(wv))):
            f = fit_gmwm(wv, res.model, weights=inverse_cov(v[:k, :k]), levels=k)
            rej[rule].append(stats.chi2.sf(f.objective, k - len(free_params(f))) < 0.05)
        if i % 10 == 9:
            print(
                i + 1,
                {r: int(np.sum(x)) for r, x in rej.items()},
                f"cpu {time.process_time() - t0:.0f}",
                flush=True,
            )
    print(
        "final",
        truth_s,
        "tested",
        tested,
        log2n,
        robust,
        {r: f"{int(np.sum(x))}/{len(x)}" for r, x in rej.items()},
    )


if __name__ == "__main__":
    main()
