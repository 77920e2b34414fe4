"""How many correlation times of a Gauss-Markov term the plan's asymptotic covariance needs.

The consumer MEMS gyro of plan_mc.py (GM of 20 s + WN + RW at 100 Hz) at logs of 5 to 200
correlation times of its GM: ``--reps`` logs each, fitted by the efficient GMWM (GM+WN+RW); the
realised spread of ``log N_hat`` and ``log sigma_gm_hat`` against the plan's
(:func:`engine.inference.planning.plan_precision`), with the 95 % band of a standard
deviation's sampling error. docs/planning.md holds its output (the choice of
``engine.inference.planning.SPAN_GM``).

Usage::

    nice python tests/benchmarks/plan_span_mc.py [--reps 200] [--seed 3]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

import engine as eg
from engine.fit.asymptotic import free_params, param_cov
from engine.inference.planning import _planned_fit, plan_precision

Z = 1.959963984540054
MODEL = "GM(beta=0.05, sigma2_gm=4e-6)+WN(sigma2=2.5e-5)+RW(gamma2=1e-10)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--spans", default="5,10,25,50,100,200")
    a = ap.parse_args()
    m, fs, tc = eg.parse_model(MODEL), 100.0, 20.0
    print(
        "| log length | correlation times of the GM | sd of log N_hat: planned | realised "
        "[95 % band] | ratio | sd of log sigma_gm_hat: planned | realised [95 % band] | ratio "
        "| GM fitted at 0 |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for span in (float(s) for s in a.spans.split(",")):
        n = int(span * tc * fs)
        plan = plan_precision(m, fs, n, unit="rad/s")
        rng = np.random.default_rng(a.seed)
        est: dict[str, list[float]] = {"N": [], "S": []}
        for _ in range(a.reps):
            x = m.simulate(n, fs=fs, rng=rng)
            try:
                res = eg.fit_gmwm(
                    eg.wavelet_variance(x, fs=fs, unit="rad/s"), "GM+WN+RW", weights="efficient"
                )
            except eg.FitError:
                continue
            est["N"].append(res.ieee["N"].value)
            est["S"].append(float(res.model.processes[0].sigma2_gm))
        cells = [f"{n / fs / 60:.3g} min", f"{span:g}"]
        # planned sd of log sigma2_gm: from the plan's parameter covariance
        pf = _planned_fit(m, fs, n, "rad/s", None)
        free = free_params(pf)
        cov = param_cov(pf, pf.vmat, free)
        k = free.index((0, "sigma2_gm"))
        sd_plan = {
            "N": math.log1p(max(plan["N"].high / plan["N"].value - 1, 0)) / Z,
            "S": 0.5 * math.sqrt(cov[k, k]),  # log sigma_gm = log(sigma2_gm) / 2
        }
        for key, truth in (("N", plan["N"].value), ("S", 4e-6)):
            e = np.asarray(est[key])
            e = e[e > 0]  # a GM fitted at zero variance has no log (counted below)
            lr = np.log(e / truth) if key == "N" else 0.5 * np.log(e / truth)
            sd = float(np.std(lr, ddof=1))
            h = Z * sd / math.sqrt(2 * (lr.size - 1))
            cells += [f"{sd_plan[key]:.4f}", f"{sd:.4f} [{sd - h:.4f}, {sd + h:.4f}]"]
            cells.append(f"{sd / sd_plan[key]:.2f}")
        zero = sum(v <= 0 for v in est["S"])
        cells.append(f"{zero}")
        print("| " + " | ".join(cells) + " |", flush=True)
    print(f"\n{a.reps} logs per row (tests/benchmarks/plan_span_mc.py).")


if __name__ == "__main__":
    main()
