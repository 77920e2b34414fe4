"""Which levels the J-test may use: rejections of the TRUE model at 5 % by levels rule.

    nice -n 10 python tests/benchmarks/jtest_levels_mc.py fit SPEC LOG2N ROBUST REPS SEED
    nice -n 10 python tests/benchmarks/jtest_levels_mc.py truth SPEC LOG2N ROBUST REPS SEED

``fit``: each log's WV (100 Hz, robust if ROBUST is 1) is fitted with ci weights, V is
``wv_cov_model`` at the fit, and the efficient refit on the levels with ``M_j / 2^j >= e`` is
compared with chi2(levels - p), for e = 4 (the old rule), 8 and 16 (for a log of 2^n samples:
the last 2, 3 or 4 levels left out; the engine's rule ``eff M_j / 2^j >= 10`` is e = 8 for a
classical WV and e = 16 for a robust one of eff 0.6). Printed every 20 logs: per e, the
rejection rate, mean T/df, and the rejection rate of ``r' V^-1 r`` at the true parameters and V
(no fit) against chi2(levels).

``truth``: REPS WVs of the true model, then per number of levels k: mean ``r' V^-1 r / k`` (V at
the truth) and its rejection rate at 5 % and 1 % against chi2(k), with the Monte Carlo variance
ratio and skewness of every level (no fit: whether V and the chi-square hold level by level).

The tables of ``docs/jtest.md`` ("Which levels") are this script's output.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy import stats

import engine as eg
from engine.fit import fit_gmwm
from engine.fit.asymptotic import free_params, inverse_cov, wv_cov_model

FS = 100.0
ETAS = (4, 8, 16)


def fit_mode(truth: eg.Model, log2n: int, robust: bool, reps: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rej: dict[int, list[bool]] = {e: [] for e in ETAS}
    tdf: dict[int, list[float]] = {e: [] for e in ETAS}
    rej_t: dict[int, list[bool]] = {e: [] for e in ETAS}
    t0 = time.process_time()
    for i in range(reps):
        wv = eg.wavelet_variance(truth.simulate(2**log2n, fs=FS, rng=rng), fs=FS, robust=robust)
        res = fit_gmwm(wv, truth.cleared())
        v = wv_cov_model(res.model, wv)
        vt = wv_cov_model(truth, wv)
        eta = wv.n_coef / wv.tau_samples
        for e in ETAS:
            k = int(np.count_nonzero(eta >= e))
            f = fit_gmwm(wv, res.model, weights=inverse_cov(v[:k, :k]), levels=k)
            df = k - len(free_params(f))
            rej[e].append(bool(stats.chi2.sf(f.objective, df) < 0.05))
            tdf[e].append(f.objective / df)
            r = (wv.variance - truth.wv(wv.tau_samples, fs=FS))[:k]
            t_true = float(r @ np.linalg.solve(vt[:k, :k], r))
            rej_t[e].append(bool(stats.chi2.sf(t_true, k) < 0.05))
        if i % 20 == 19 or i == reps - 1:
            row = {
                e: f"reject {np.mean(rej[e]):.3f} T/df {np.mean(tdf[e]):.3f} "
                f"truth-V reject {np.mean(rej_t[e]):.3f}"
                for e in ETAS
            }
            print(i + 1, row, f"cpu {time.process_time() - t0:.0f} s", flush=True)


def truth_mode(truth: eg.Model, log2n: int, robust: bool, reps: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    nus = np.array(
        [
            eg.wavelet_variance(
                truth.simulate(2**log2n, fs=FS, rng=rng), fs=FS, robust=robust
            ).variance
            for _ in range(reps)
        ]
    )
    wv = eg.wavelet_variance(truth.simulate(2**log2n, fs=FS, rng=rng), fs=FS, robust=robust)
    v = wv_cov_model(truth, wv)
    nu0 = truth.wv(wv.tau_samples, fs=FS)
    eta = wv.n_coef / wv.tau_samples
    np.set_printoptions(precision=3, suppress=True, linewidth=200)
    print("var ratio", np.diag(np.cov(nus.T)) / np.diag(v))
    print("bias", nus.mean(0) / nu0 - 1)
    print("skew", stats.skew(nus, axis=0))
    for k in range(3, len(eta)):
        r = nus[:, :k] - nu0[:k]
        t = np.einsum("ij,ij->i", r @ np.linalg.inv(v[:k, :k]), r)
        p = stats.chi2.sf(t, k)
        print(
            f"{k} levels, min eta {eta[k - 1]:.0f}: mean T/k {t.mean() / k:.3f}, reject 5 % "
            f"{np.mean(p < 0.05):.3f}, 1 % {np.mean(p < 0.01):.4f}"
        )


def main() -> None:
    mode, spec, log2n, robust, reps, seed = sys.argv[1:7]
    truth = eg.parse_model(spec)
    print(mode, spec, f"2^{log2n}", "robust" if robust == "1" else "classical", reps, "logs")
    run = fit_mode if mode == "fit" else truth_mode
    run(truth, int(log2n), robust == "1", int(reps), int(seed))


if __name__ == "__main__":
    main()
