"""engine._optim's kernels against SciPy's, CPU per call on the fit's own problems. Run from the
repository root:

    nice -n 10 python tests/benchmarks/bench_optim.py [--log PATH] [--repeat 200]

* NNLS: the profile's inner problem of ``2*GM+WN+QN+RW+DR`` on imu1 gyro_x (19 x 6), SciPy's
  :func:`scipy.optimize.nnls` (what ``engine._optim.nnls`` calls) against the former NumPy
  Lawson-Hanson (git history), which is not kept;
* Nelder-Mead: one local search of the profile of ``2*GM`` (the former
  ``engine._optim.nelder_mead``, when this version has it, against
  ``scipy.optimize.minimize(method="Nelder-Mead")`` from the same simplex, same tolerances);
* bounded least squares: a 4-parameter fit of the log WV of ``GM+WN+RW`` (engine._optim's
  projected Levenberg-Marquardt against ``scipy.optimize.least_squares``);
* chi-square quantiles of 19 levels' degrees of freedom (``engine._optim.chi2_isf`` against
  ``scipy.special.chdtri``).

Each line prints both CPU times per call, their ratio and the difference of the results.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
from scipy import optimize, special

import engine as eg
from engine import _optim
from engine.fit._varpro import NNLSProblem, sqrt_weight
from engine.fit.gmwm import weight_matrix

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def per_call(fn, repeat: int) -> float:
    """CPU seconds per call (smallest of 3 rounds of ``repeat`` calls)."""
    best = math.inf
    for _ in range(3):
        t = time.process_time()
        for _ in range(repeat):
            fn()
        best = min(best, (time.process_time() - t) / repeat)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--log", default=str(DATA / "adis16405_imu1.h5"))
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args()
    wv = eg.load_log(args.log).wavelet_variance("gyro_x")
    a = sqrt_weight(weight_matrix(wv, "ci")[0])
    rows = []

    # NNLS: the inner problem at a typical point of the search
    big = NNLSProblem.from_wv(eg.parse_model("2*GM+WN+QN+RW+DR"), wv, a)
    c = a @ big.design(big.phis_of(np.log([200.0, 0.5])))
    cn = c / np.sqrt(np.sum(c * c, axis=0))
    t_sp = per_call(lambda: optimize.nnls(cn, big.b), args.repeat)
    t_own = per_call(lambda: _optim.nnls(cn, big.b), args.repeat)
    rows.append(("nnls 19x6 (engine = SciPy + wrapper)", t_own, t_sp, 0.0))

    # Nelder-Mead on the profile of 2*GM from the same simplex
    prob = NNLSProblem.from_wv(eg.parse_model("2*GM"), wv, a)
    x0 = np.log([200.0, 0.5])
    sim = np.vstack([x0, x0 + [0.1, 0], x0 + [0, 0.1]])
    f0 = prob.profile(x0)

    def own_nm():
        prob._memo.clear()
        return _optim.nelder_mead(prob.profile, sim, xatol=1e-6, fatol=1e-10 * f0, maxfev=800)

    def sp_nm():
        prob._memo.clear()
        return optimize.minimize(
            prob.profile,
            x0,
            method="Nelder-Mead",
            options={"initial_simplex": sim, "xatol": 1e-6, "fatol": 1e-10 * f0, "maxfev": 800},
        )

    reps = max(args.repeat // 50, 2)
    r_sp = sp_nm()
    r_own = own_nm() if hasattr(_optim, "nelder_mead") else r_sp
    rows.append(
        (
            f"nelder-mead, profile of 2*GM ({r_own.nfev} evaluations)",
            per_call(own_nm, reps) if hasattr(_optim, "nelder_mead") else math.nan,
            per_call(sp_nm, reps),
            abs(r_own.fun - r_sp.fun) / r_sp.fun,
        )
    )

    # bounded least squares: log WV of GM+WN+RW, 4 parameters (log tc, log variances)
    tau = wv.tau_samples
    y = np.log(wv.variance)
    m3 = NNLSProblem.from_wv(eg.parse_model("GM+WN+RW"), wv, np.eye(tau.size))

    def resid(z: np.ndarray) -> np.ndarray:
        x = m3.design(m3.phis_of(z[:1]))
        return np.log(x @ np.exp(z[1:])) - y

    z0 = np.array([math.log(100.0), math.log(1e-4), math.log(1e-2), math.log(1e-9)])
    lb, ub = np.array([m3.lo, -60, -60, -60]), np.array([m3.hi, 10, 10, 10])
    lo = _optim.least_squares(resid, z0, lb, ub)
    ls = optimize.least_squares(resid, z0, bounds=(lb, ub), ftol=1e-12, xtol=1e-10)
    rows.append(
        (
            f"least squares 19x4, bounded ({lo.nfev} / {ls.nfev} evaluations)",
            per_call(lambda: _optim.least_squares(resid, z0, lb, ub), reps),
            per_call(
                lambda: optimize.least_squares(resid, z0, bounds=(lb, ub), ftol=1e-12, xtol=1e-10),
                reps,
            ),
            (lo.cost - ls.cost) / ls.cost,
        )
    )

    # chi-square quantiles of the levels' equivalent degrees of freedom
    eta = np.maximum(wv.n_coef / wv.tau_samples, 1.0)
    q_own = _optim.chi2_isf(eta, 0.025)
    q_sp = special.chdtri(eta, 0.025)
    rows.append(
        (
            "chi2 quantiles, 19 levels",
            per_call(lambda: _optim.chi2_isf(eta, 0.025), args.repeat // 10),
            per_call(lambda: special.chdtri(eta, 0.025), args.repeat),
            float(np.max(np.abs(q_own / q_sp - 1))),
        )
    )

    print(f"{'kernel':<58} {'engine us':>10} {'SciPy us':>10} {'ratio':>6} {'rel diff':>9}")
    for name, t_e, t_s, d in rows:
        print(f"{name:<58} {1e6 * t_e:>10.1f} {1e6 * t_s:>10.1f} {t_e / t_s:>6.2f} {d:>9.1e}")


if __name__ == "__main__":
    main()
