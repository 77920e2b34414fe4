"""From what length does the plan's interval of a drift's rate ramp R hold?

A drift's WV (``omega^2 tau^2 / 16``) overtakes the rest of the model at one scale ``tau_R``
(:func:`drift_scale`). For logs of ``mult * tau_R`` samples, ``--reps``
logs are simulated from the model and each is fitted by the efficient GMWM with the model's
own terms; per length the script prints the plan's 95 % interval of R (relative to R), the
realised 2.5-97.5 % range of ``R_hat / R``, the share of fits that put the drift at 0 (with its
Wilson 95 % band) against the plan's ``drift_at_zero`` (``Phi(-1 / (2 s))``), and the sd of
``log R_hat`` over the other fits against the plan's (with
the 95 % sampling band of a standard deviation).

Models (``--model``): ``wn`` is ``WN(sigma2=1)+DR(omega=1e-6)`` (tau_R = 25,198 samples;
docs/planning.md's drift example), ``adis`` the WN+RW efficient fit of ADIS16405 unit 1
gyro_x (../shared/data) plus the drift docs/qualify.md measures on an uncompensated thermal
ramp (omega = 2.94e-7 deg/s per sample; tau_R about 205,000 samples).

It chose ``engine.inference.planning.DRIFT_AT_ZERO`` (the plan's R holds where at most 1 % of
the fits put the drift at 0, by the plan's own ``drift_at_zero``); the table is in docs/planning.md.

Usage::

    nice -n 10 python tests/benchmarks/plan_drift_scan.py --model wn --mults 1,2,4,8,16
    nice -n 10 python tests/benchmarks/plan_drift_scan.py --model adis --reps 100 --mults 1,2,4,8
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from plan_mc import DATA, Z, wilson

import engine as eg
from engine.inference.planning import drift_at_zero, plan_precision


def drift_scale(model: eg.Model, fs: float) -> float:
    """The scale ``tau_R`` (samples) above which the drift's WV (``omega^2 tau^2 / 16``, the
    fastest growing) exceeds the rest of the model's: ``(16 sigma2 / omega^2)^(1/3)`` for white
    noise ``sigma2`` alone, about ``4 gamma2 / (3 omega^2)`` with a random walk ``gamma2``."""
    omega2 = sum(float(p.omega) ** 2 for p in model.processes if p.code == "DR")
    rest = eg.Model(tuple(p for p in model.processes if p.code != "DR"))
    tau = 2.0 ** np.arange(0.0, 80.0, 1.0 / 16.0)
    gap = np.log(omega2 * tau**2 / 16.0) - np.log(rest.wv(tau, fs))
    i = int(np.flatnonzero(gap < 0)[-1])  # the last grid scale where the rest dominates
    t = gap[i] / (gap[i] - gap[i + 1])  # linear in log tau to the next
    return float(tau[i] * (tau[i + 1] / tau[i]) ** t)


def model_of(name: str) -> tuple[eg.Model, str, float, str]:
    """(model, model fitted, fs, unit)."""
    if name == "wn":
        return eg.parse_model("WN(sigma2=1)+DR(omega=1e-6)"), "WN+DR", 100.0, ""
    wv = eg.load_log(DATA / "adis16405_imu1.h5").wavelet_variance("gyro_x")
    fit = eg.fit_gmwm(wv, "WN+RW", weights="efficient")
    m = eg.Model(fit.model.processes + eg.parse_model("DR(omega=2.94e-7)").processes)
    return m, "WN+RW+DR", wv.fs, wv.unit


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", choices=("wn", "adis"), default="wn")
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--mults", default="1,2,4,8,16")
    a = ap.parse_args()
    m, spec, fs, unit = model_of(a.model)
    tau_r = drift_scale(m, fs)
    print(f"{m.spec(values=True)} at {fs:g} Hz, fitted {spec}; tau_R = {tau_r:.0f} samples")
    print(
        "| length / tau_R | samples | planned 95 % of R_hat / R | realised 2.5-97.5 % | "
        "drift at 0 [Wilson 95 %] | planned at 0 | sd of log R_hat (drift > 0): planned | "
        "realised [95 % band] | ratio |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for mult in (float(s) for s in a.mults.split(",")):
        n = int(round(mult * tau_r))
        table = plan_precision(m, fs, n, unit=unit)
        q = table["R"]
        sd_plan = math.log(q.high / q.value) / Z
        rng = np.random.default_rng(a.seed)
        t0 = time.process_time()
        est = np.array(
            [
                eg.fit_gmwm(
                    eg.wavelet_variance(m.simulate(n, fs=fs, rng=rng), fs=fs, unit=unit),
                    spec,
                    weights="efficient",
                )
                .ieee["R"]
                .value
                / q.value
                for _ in range(a.reps)
            ]
        )
        cpu = time.process_time() - t0
        zero = est <= 0
        k = int(zero.sum())
        wl, wh = wilson(k, a.reps)
        lr = np.log(est[~zero])
        sd = float(np.std(lr, ddof=1)) if lr.size > 2 else math.nan
        h = Z * sd / math.sqrt(2 * (lr.size - 1)) if lr.size > 2 else math.nan
        lo, hi = np.percentile(est, [2.5, 97.5])
        print(
            f"| {mult:g} | {n:,} | [{q.low / q.value:.2f}, {q.high / q.value:.2f}] | "
            f"[{lo:.2f}, {hi:.2f}] | {k} ({100 * k / a.reps:.1f} %) [{100 * wl:.1f}, "
            f"{100 * wh:.1f}] | {100 * drift_at_zero(table):.1f} % | {sd_plan:.3f} | "
            f"{sd:.3f} [{sd - h:.3f}, {sd + h:.3f}] | {sd / sd_plan:.2f} |",
            flush=True,
        )
        print(f"  ({a.reps} logs, {cpu:.0f} s CPU)", flush=True)


if __name__ == "__main__":
    main()
