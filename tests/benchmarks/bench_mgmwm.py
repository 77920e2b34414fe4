"""MGMWM simulation study (the multivariate paper, section V) from the command line.

Run: ``python tests/benchmarks/bench_mgmwm.py [--reps 500] [--n 1e6] [--workers 2]
[--seed 1] [--out /tmp/mgmwm_out]`` (on a shared machine, with ``OPENBLAS_NUM_THREADS=1``:
the workers already use one BLAS thread each, this keeps the main process's timing honest).

Three gyroscopes whose errors are a white noise with a diagonal covariance (independent
channels) plus a random walk with a full covariance (correlated drifts), the setting of
Vaccaro & Zaki (2017) reduced to three gyros as in the paper. Per sample (fs = 1):

* WN variances ``sigma2 = (1.0, 1.5, 2.0)``;
* RW innovation standard deviations ``(1.0, 1.4, 1.2) x 1e-2`` with correlations
  ``rho_12 = 0.6``, ``rho_13 = 0.3``, ``rho_23 = 0.5`` (WN and RW cross at about 350 samples,
  so half of the levels are drift-dominated, as in low-cost gyros).

Estimators of the 9 covariance parameters (3 WN variances, 6 RW covariance entries):

* MGMWM: ``fit_mgmwm`` of ``WN+RW`` per channel with the RW shared, ``"ci"`` weights, and
  with ``weights="efficient"`` (two-step, inverse of the model-implied covariance of all
  stacked WV/WCCV moments);
* univariate GMWM of ``WN+RW`` on each channel for the 6 variances (``"ci"`` weights, and the
  two-step efficient fit of ``engine.fit.fit_efficient``), plus the plain sample
  cross-covariance of the differenced signals, ``cov(x_p(t) - x_p(t-1), x_q(t) - x_q(t-1))``,
  for the 3 RW covariances (unbiased here: the WN are independent across channels).

With diagonal ``"ci"`` weights the MGMWM's variance estimates equal the univariate ones
whenever the fitted covariance is positive semi-definite without constraint (the stacked
problem separates by moment pair, see ``engine/multivariate/_cone.py``), so the comparison
that matters for the variances is the efficient column.

Prints the per-parameter bias, SD and MSE, MSE ratios with Monte Carlo standard errors, a
markdown table ready for docs/multichannel.md, and the wall time; ``--out`` keeps study.json (every
estimate) and study.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from engine._parallel import parallel_map
from engine.fit import fit_efficient, fit_gmwm
from engine.multivariate import MultiModel, fit_mgmwm
from engine.wv import wv_matrix

CHANNELS = ("gyro_1", "gyro_2", "gyro_3")
WN_VAR = np.array([1.0, 1.5, 2.0])
RW_SD = np.array([1.0, 1.4, 1.2]) * 1e-2
RW_CORR = np.array([[1.0, 0.6, 0.3], [0.6, 1.0, 0.5], [0.3, 0.5, 1.0]])
RW_COV = RW_CORR * np.outer(RW_SD, RW_SD)
PAIRS = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
KEYS = ("mgmwm", "mgmwm_eff", "baseline", "baseline_eff")


def truth() -> MultiModel:
    """The simulated model (WN independent across channels, RW shared)."""
    return MultiModel(
        CHANNELS,
        {c: f"WN(sigma2={v})+RW" for c, v in zip(CHANNELS, WN_VAR, strict=True)},
        shared=["RW"],
        cov={"RW": RW_COV},
    )


def param_names() -> list[str]:
    out = [f"sigma2_WN[{p + 1}]" for p in range(3)]
    out += [f"Sigma_RW[{p + 1},{q + 1}]" for p, q in PAIRS]
    return out


def true_values() -> np.ndarray:
    return np.concatenate([WN_VAR, [RW_COV[p, q] for p, q in PAIRS]])


def one_replicate(args: tuple) -> dict:
    """Simulate one replicate and estimate with both methods (a worker's job)."""
    n, seed = args
    t0 = time.perf_counter()
    x = truth().simulate(n, rng=np.random.default_rng(seed))
    t1 = time.perf_counter()
    wvm = wv_matrix(x, channels=list(CHANNELS))
    t2 = time.perf_counter()
    mm = MultiModel(CHANNELS, "WN+RW", shared=["RW"])
    res = fit_mgmwm(wvm, mm)
    t3 = time.perf_counter()
    eff = fit_mgmwm(wvm, mm, weights="efficient")
    t4 = time.perf_counter()
    out: dict = {
        "psd_active": bool(res.psd_active),
        "t_sim": t1 - t0,
        "t_wvm": t2 - t1,
        "t_mgmwm": t3 - t2,
        "t_mgmwm_eff": t4 - t3,
    }
    for key, r in (("mgmwm", res), ("mgmwm_eff", eff)):
        cov = r.covariance("RW")
        out[key] = [r.params[f"{c}.WN.sigma2"] for c in CHANNELS] + [cov[p, q] for p, q in PAIRS]
    dx = np.diff(x, axis=0)
    dx -= dx.mean(axis=0)
    sample = dx.T @ dx / (dx.shape[0] - 1)
    cross = [sample[p, q] for p, q in PAIRS[3:]]
    t5 = time.perf_counter()
    for key, fit in (("baseline", fit_gmwm), ("baseline_eff", fit_efficient)):
        uni = [fit(wvm.wv(p), "WN+RW") for p in range(3)]
        out[key] = (
            [u.params["WN.sigma2"] for u in uni] + [u.params["RW.gamma2"] for u in uni] + cross
        )
    out["t_uni"] = time.perf_counter() - t5
    return out


def summarise(rows: list[dict]) -> dict:
    tv = true_values()
    out = {}
    for key in KEYS:
        est = np.array([r[key] for r in rows])
        err = est - tv
        sq = err**2
        out[key] = {
            "bias": err.mean(axis=0),
            "sd": est.std(axis=0, ddof=1),
            "mse": sq.mean(axis=0),
            "mse_se": sq.std(axis=0, ddof=1) / np.sqrt(len(rows)),
        }
    return out


def _ratio(rows: list[dict], num: str, den: str, i: int, n_boot: int = 2000) -> str:
    """MSE ratio num/den with a 95 % paired bootstrap interval over the replicates."""
    tv = true_values()[i]
    a = (np.array([r[num][i] for r in rows]) - tv) ** 2
    b = (np.array([r[den][i] for r in rows]) - tv) ** 2
    ratio = a.mean() / b.mean()
    idx = np.random.default_rng(0).integers(0, len(rows), (n_boot, len(rows)))
    boot = a[idx].mean(axis=1) / b[idx].mean(axis=1)
    lo, hi = np.quantile(boot, [0.025, 0.975])
    return f"{ratio:.3g} [{lo:.2g}, {hi:.2g}]"


def markdown(stats: dict, rows: list[dict], n: int, reps: int) -> str:
    names = param_names()
    tv = true_values()
    m, me, b, be = (stats[k] for k in KEYS)
    lines = [
        f"3 gyros, WN (diagonal covariance) + RW (full covariance), T = {n:.3g} samples, "
        f"{reps} replicates. Relative RMSE (RMSE / true value). Baseline: univariate GMWM "
        "for the variances, the sample cross-covariance of the differenced signals for "
        "the RW covariances. MSE ratio > 1: the MGMWM is better (95 % paired bootstrap "
        "interval over the replicates).",
        "",
        "| parameter | true | MGMWM | MGMWM, efficient | baseline | baseline, efficient "
        "| MSE ratio baseline / MGMWM | MSE ratio, efficient |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for i, name in enumerate(names):
        rel = [np.sqrt(d["mse"][i]) / abs(tv[i]) for d in (m, me, b, be)]
        cells = [f"{v:.3%}" if v < 10 else f"{v:.3g}x" for v in rel]
        same = np.allclose(m["mse"][i], b["mse"][i], rtol=1e-12)
        lines.append(
            f"| {name} | {tv[i]:.3g} | {' | '.join(cells)} | "
            f"{'1 (identical)' if same else _ratio(rows, 'baseline', 'mgmwm', i)} | "
            f"{_ratio(rows, 'baseline_eff', 'mgmwm_eff', i)} |"
        )
    return "\n".join(lines)


def table(stats: dict) -> str:
    names = param_names()
    tv = true_values()
    lines = [
        f"{'parameter':<16} {'true':>10} | "
        + " | ".join(f"{k + ' bias':>17} {'sd':>9} {'rel.RMSE':>9}" for k in KEYS)
    ]
    for i, name in enumerate(names):
        cells = []
        for k in KEYS:
            d = stats[k]
            cells.append(
                f"{d['bias'][i]:>17.3e} {d['sd'][i]:>9.3e} "
                f"{np.sqrt(d['mse'][i]) / abs(tv[i]):>9.3%}"
            )
        lines.append(f"{name:<16} {tv[i]:>10.3e} | " + " | ".join(cells))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=500)
    ap.add_argument("--n", type=float, default=1e6, help="samples per channel")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None, help="output directory")
    args = ap.parse_args()
    n = int(args.n)
    print(f"truth: {truth().spec()}, T = {n:.3g}, {args.reps} replicates, {args.workers} worker(s)")
    print("RW covariance:\n" + np.array2string(RW_COV, precision=4))
    one = one_replicate((n, 0))
    print(
        f"one replicate (s): simulate {one['t_sim']:.3f}, WV/WCCV matrix {one['t_wvm']:.3f}, "
        f"MGMWM fit {one['t_mgmwm']:.4f}, efficient MGMWM {one['t_mgmwm_eff']:.3f}, "
        f"univariate fits (ci + efficient) {one['t_uni']:.3f}"
    )
    seeds = np.random.SeedSequence(args.seed).spawn(args.reps)
    t0 = time.perf_counter()
    rows = []
    chunk = max(2 * args.workers, 50)
    for a in range(0, args.reps, chunk):
        rows += parallel_map(one_replicate, [(n, s) for s in seeds[a : a + chunk]], args.workers)
        print(
            f"\r{len(rows)}/{args.reps} replicates, {time.perf_counter() - t0:.0f} s",
            end="",
            file=sys.stderr,
            flush=True,
        )
    print(file=sys.stderr)
    wall = time.perf_counter() - t0
    stats = summarise(rows)
    print()
    print(table(stats))
    md = markdown(stats, rows, n, len(rows))
    print()
    print(md)
    n_psd = sum(r["psd_active"] for r in rows)
    print(f"\nPSD constraint active in {n_psd} of {len(rows)} MGMWM fits")
    print(
        f"wall time {wall:.1f} s for {len(rows)} replicates on {args.workers} worker(s) "
        f"({wall / len(rows) * args.workers:.2f} s per replicate and worker)"
    )
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "study.md").write_text(md + "\n")
        (out / "study.json").write_text(
            json.dumps(
                {
                    "n": n,
                    "reps": len(rows),
                    "seed": args.seed,
                    "wall_s": wall,
                    "params": param_names(),
                    "true": true_values().tolist(),
                    **{k: [r[k] for r in rows] for k in KEYS},
                    "stats": {k: {s: v.tolist() for s, v in d.items()} for k, d in stats.items()},
                }
            )
        )
        print(f"wrote {out / 'study.md'}, {out / 'study.json'}")


if __name__ == "__main__":
    main()
