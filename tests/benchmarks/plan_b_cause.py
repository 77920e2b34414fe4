"""Why the bias instability B of the ADIS16405 gyro spreads wider than `gmwm plan` says.

Two candidate causes, told apart at B's planned length (``B within 30 %``: 16.4 h at 100 Hz)
for the GM+WN+RW model of ../shared/data/adis16405_imu1.h5 gyro_x (plan_mc.py's model):

1. the delta method's linearisation of B, the minimum of the model's Allan deviation (a
   kinked map of the parameters): the plan's asymptotic normal of the parameters is pushed
   through the exact map (:func:`engine.units.allan_floor` of each drawn model, ``--draws``
   draws) and its spread compared with the delta method's;
2. the GMWM's realised covariance of the parameters at that length: ``--reps`` logs are
   simulated and fitted (efficient GMWM), and the spread of each parameter (unconstrained
   coordinates: logs of the variances and of beta) compared with the plan's; the realised
   covariance pushed through the exact map gives the B spread it implies.

With ``--replay PLAN_MC.json`` (the ``--json`` of ``plan_mc.py --only "gyro_x B within"``) it
instead replays that run's random stream and refits its ``--lowest`` lowest estimates of B,
printing each fitted model and its Allan floor.

Usage::

    nice python tests/benchmarks/plan_b_cause.py [--reps 60] [--draws 1000]
    nice python tests/benchmarks/plan_b_cause.py --replay b.json [--lowest 3]

docs/planning.md quotes its output.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from plan_mc import DATA, Z, adis_model

import engine as eg
from engine.fit.asymptotic import free_params, param_cov
from engine.inference.planning import _planned_fit, plan_precision
from engine.models import TO_UNCONSTRAINED, Model
from engine.units import allan_floor


def unconstrained(m: Model, free: list[tuple[int, str]]) -> np.ndarray:
    return np.array([TO_UNCONSTRAINED[k](float(getattr(m.processes[i], k))) for i, k in free])


def with_u(m: Model, free: list[tuple[int, str]], u: np.ndarray) -> Model:
    procs = list(m.processes)
    for (i, k), x in zip(free, u, strict=True):
        procs[i] = procs[i].with_values(**{k: math.exp(float(x))})
    return Model(tuple(procs))


def sd_log_b(m: Model, free, u0, cov, fs, levels, draws, seed) -> float:
    """The sd of log B over ``draws`` models drawn from N(u0, cov), through the exact map."""
    b0 = allan_floor(m, fs, levels)["adev_min"]
    root = np.linalg.cholesky(cov)
    rng = np.random.default_rng(seed)
    lb = [
        math.log(
            allan_floor(with_u(m, free, u0 + root @ rng.standard_normal(len(u0))), fs, levels)[
                "adev_min"
            ]
            / b0
        )
        for _ in range(draws)
    ]
    return float(np.std(lb))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=60)
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--replay", help="plan_mc.py's --json of the B row: refit its lowest B")
    ap.add_argument("--lowest", type=int, default=3)
    a = ap.parse_args()
    if a.replay:
        replay(a.replay, a.lowest)
        return
    log = eg.load_log(DATA / "adis16405_imu1.h5")
    m, fs, unit = adis_model(log.wavelet_variance("gyro_x")), 100.0, "deg/s"
    n = eg.plan_run(m, fs, "B within 30 %", unit=unit).required["B"]
    assert n is not None
    pf = _planned_fit(m, fs, n, unit, None)
    free = free_params(pf)
    cov = param_cov(pf, pf.vmat, free)
    u0 = unconstrained(m, free)
    levels = pf.wv.n_levels
    q = plan_precision(m, fs, n, unit=unit)["B"]
    print(f"{m.spec(values=True)} at {n} samples ({n / fs / 3600:.3g} h), {levels} levels")
    delta = math.log(q.high / q.value) / Z
    exact = sd_log_b(m, free, u0, cov, fs, levels, a.draws, 0)
    print(f"sd of log B, delta method: {delta:.4f}; exact map of the same normal: {exact:.4f}")
    rng = np.random.default_rng(a.seed)
    us, lb = [], []
    for _ in range(a.reps):
        x = m.simulate(n, fs=fs, rng=rng)
        res = eg.fit_gmwm(eg.wavelet_variance(x, fs=fs, unit=unit), "GM+WN+RW", weights="efficient")
        us.append(unconstrained(res.model, free))
        lb.append(math.log(res.ieee["B"].value))
    u = np.array(us)
    sd_b = float(np.std(lb, ddof=1))
    h = Z * sd_b / math.sqrt(2 * (a.reps - 1))
    print(f"\n{a.reps} logs: realised sd of log B {sd_b:.4f} [{sd_b - h:.4f}, {sd_b + h:.4f}]")
    real = np.cov(u.T)
    print(
        f"  the realised covariance through the exact map: "
        f"{sd_log_b(m, free, u0, real, fs, levels, a.draws // 2, 1):.4f}"
    )
    print("| parameter (log) | planned sd | realised sd [95 % band] | mean shift |")
    print("|---|---|---|---|")
    for k, (i, name) in enumerate(free):
        s = float(np.std(u[:, k], ddof=1))
        hk = Z * s / math.sqrt(2 * (a.reps - 1))
        print(
            f"| {m.labels[i]}.{name} | {math.sqrt(cov[k, k]):.4f} | {s:.4f} "
            f"[{s - hk:.4f}, {s + hk:.4f}] | {np.mean(u[:, k]) - u0[k]:+.4f} |"
        )
    corr = lambda c: c / np.sqrt(np.outer(np.diag(c), np.diag(c)))  # noqa: E731
    print("planned correlations:\n", np.round(corr(cov), 2))
    print("realised correlations:\n", np.round(corr(real), 2))


def replay(path: str, lowest: int) -> None:
    """Refit the logs of plan_mc.py's B row with the lowest estimates (same seed, same order)."""
    row = json.loads(Path(path).read_text())[0]
    lr = np.log(np.asarray(row["estimates"]) / row["truth"])
    idx = sorted(np.argsort(lr)[:lowest].tolist())
    log = eg.load_log(DATA / "adis16405_imu1.h5")
    m, fs, unit, n = adis_model(log.wavelet_variance("gyro_x")), 100.0, "deg/s", row["samples"]
    print("truth:", m.spec(values=True), allan_floor(m, fs, 22))
    rng = np.random.default_rng(1)  # plan_mc.py's default seed
    for k in range(max(idx) + 1):
        x = m.simulate(n, fs=fs, rng=rng)
        if k in idx:
            wv = eg.wavelet_variance(x, fs=fs, unit=unit)
            res = eg.fit_gmwm(wv, "GM+WN+RW", weights="efficient")
            fl = allan_floor(res.model, fs, wv.n_levels)
            print(f"log {k}: log(B_hat / B) = {lr[k]:+.3f}; {res.model.spec(values=True)}; {fl}")


if __name__ == "__main__":
    main()
