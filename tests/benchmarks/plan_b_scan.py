"""Does the realised spread of B converge to the plan's with the log length, and for which fit?

For a GM+WN+RW model (default: the ADIS16405 gyro_x model of plan_mc.py; ``--model`` another,
``--fit WN+RW`` for a model without a GM) at multiples of the length the asymptotic covariance
alone gives for ``B within 30 %`` (``RunPlan.asymptotic``, about 19 averaging times of the Allan
floor), ``--reps`` logs are simulated (``--rate 10``: at 10 Hz, the same continuous-time noise,
plan_mc.py's ``at_rate``) and each log's WV is fitted up to three ways (``--fits``):

* ``efficient``: the two-step efficient GMWM that users run (``weights="efficient"``: a fit with
  the ``ci`` weights, then ``Omega = V^-1`` with V at the first fit's model);
* ``oracle``: ``Omega = V^-1`` with V at the *true* model, the estimator whose covariance the plan
  computes (``(A' V^-1 A)^-1``);
* ``iterated``: the efficient fit with V recomputed once more at its own estimate.

It prints, per length and fit, the realised sd of ``log B_hat`` (with the 95 % band of a
standard deviation's sampling error) against the plan's, the ratio, and the fits whose Allan
floor is at the edge of the scales (no B: an upper bound). ``--json`` keeps every estimate.

It chose ``engine.inference.planning.SPAN_B`` (40 averaging times of the floor); the table
and the commands are in docs/planning.md.

Usage::

    nice -n 10 python tests/benchmarks/plan_b_scan.py --mults 1,2,4 [--reps 200] [--seed 11]
    nice -n 10 python tests/benchmarks/plan_b_scan.py --rate 10 --fits efficient --mults 1
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from plan_mc import DATA, Z, adis_model, at_rate

import engine as eg
from engine.fit.asymptotic import inverse_cov
from engine.fit.covariance import wv_cov
from engine.inference.planning import _planned_fit, plan_precision

FITS = ("efficient", "oracle", "iterated")


def fits(
    wv: eg.WaveletVariance, spec: str, omega_true: np.ndarray, which: tuple[str, ...]
) -> dict[str, eg.GMWMResult]:
    out = {"efficient": eg.fit_gmwm(wv, spec, weights="efficient")}
    if "oracle" in which:
        out["oracle"] = eg.fit_gmwm(wv, spec, weights=omega_true)
    if "iterated" in which:
        eff = out["efficient"]
        out["iterated"] = eg.fit_gmwm(wv, eff.model, weights=inverse_cov(wv_cov(eff)))
    return out


def band(v: np.ndarray) -> tuple[float, float, float]:
    sd = float(np.std(v, ddof=1))
    h = Z * sd / math.sqrt(2 * (v.size - 1))
    return sd, sd - h, sd + h


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--mults", default="1,2,4")
    ap.add_argument("--model", default="", help="a GM+WN+RW model with values (default ADIS)")
    ap.add_argument("--fs", type=float, default=100.0)
    ap.add_argument("--unit", default="deg/s")
    ap.add_argument("--target", default="B within 30 %")
    ap.add_argument("--fit", default="GM+WN+RW", help="the model fitted to each log")
    ap.add_argument("--rate", type=float, default=0.0, help="simulate at this rate (Hz)")
    ap.add_argument("--fits", default=",".join(FITS), help="the fits to run, of " + ",".join(FITS))
    ap.add_argument("--json")
    a = ap.parse_args()
    if a.model:
        m = eg.parse_model(a.model)
    else:
        m = adis_model(eg.load_log(DATA / "adis16405_imu1.h5").wavelet_variance("gyro_x"))
    fs, unit = a.fs, a.unit
    if a.rate:
        m, fs = at_rate(m, fs, a.rate), a.rate
    which = tuple(a.fits.split(","))
    n1 = eg.plan_run(m, fs, a.target, unit=unit).asymptotic["B"]
    assert n1 is not None
    print(f"{m.spec(values=True)} at {fs:g} Hz; {a.target} planned at {n1} samples")
    out = []
    for mult in (float(s) for s in a.mults.split(",")):
        n = int(round(mult * n1))
        q = plan_precision(m, fs, n, unit=unit)["B"]
        sd_plan = math.log(q.high / q.value) / Z
        pf = _planned_fit(m, fs, n, unit, None)
        rng = np.random.default_rng(a.seed)
        rec: dict[str, list] = {k: [] for k in which}
        t0 = time.process_time()
        for _ in range(a.reps):
            wv = eg.wavelet_variance(m.simulate(n, fs=fs, rng=rng), fs=fs, unit=unit)
            for k, r in fits(wv, a.fit, pf.omega, which).items():
                b = r.ieee["B"]
                rec[k].append(
                    [math.log(b.value / q.value), bool(b.upper_bound)]
                    + [float(v) for v in r.params.values()]
                )
            done = len(rec["efficient"])
            if done % 25 == 0 and done < a.reps:  # progress: the running sd, to stderr
                sd_run = band(np.array([x[0] for x in rec["efficient"]]))[0]
                print(f"  {done} logs: sd {sd_run:.4f}", file=sys.stderr, flush=True)
        cpu = time.process_time() - t0
        row = {
            "mult": mult,
            "samples": n,
            "hours": n / fs / 3600,
            "sd_planned": sd_plan,
            "cpu_s": cpu,
            "fits": rec,
            "names": m.param_names,
        }
        out.append(row)
        for k in which:
            r = np.array([x[0] for x in rec[k]])
            ub = np.array([x[1] for x in rec[k]])
            sd, lo, hi = band(r)
            sd2, lo2, hi2 = band(r[~ub])
            print(
                f"| {mult:g}x | {n / fs / 3600:.3g} h | {k} | {sd_plan:.4f} | "
                f"{sd:.4f} [{lo:.4f}, {hi:.4f}] | {sd / sd_plan:.2f} | {int(ub.sum())} | "
                f"{sd2:.4f} [{lo2:.4f}, {hi2:.4f}] | {float(np.mean(r)):+.3f} |",
                flush=True,
            )
        print(f"  ({a.reps} logs, {cpu:.0f} s CPU)", file=sys.stderr, flush=True)
        if a.json:
            Path(a.json).write_text(json.dumps(out))


if __name__ == "__main__":
    main()
