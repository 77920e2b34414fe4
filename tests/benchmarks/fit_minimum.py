"""Does every GMWM fit reach the global minimum on the real logs? Run from the repository root:

    nice -n 10 python tests/benchmarks/fit_minimum.py [--data ../shared/data] [--grid 160]
        [--max-model "2*GM+WN+QN+RW+DR"] [--files adis16405_imu1.h5 ...]

For every channel of the real static logs (the six ADIS16405 units and the MTi-G by default),
every sub-model of ``--max-model`` is fitted as :func:`engine.inference.rank_models` fits them
(ci weights, one shared table of sub-model optima, smallest first), and two checks are made:

(a) **corners**: a fit with a term at zero is a point of the smaller model without that term, so
    the smaller model's own fit must not be above it (``gmwm_objective`` of the fitted model is
    the objective compared);
(b) **brute force**: the profiled objective (exact non-negative least squares over the
    variances) on a dense grid of ``--grid`` log-spaced correlation times per AR1/GM term,
    from ``TC_MIN`` (0.01 samples) to ``TC_MAX_FACTOR * N``, every combination (correlation
    times decreasing), must not be below the fit's objective.

A relative tolerance of 1e-6 applies to both. Printed: one line per channel (fits, fits with a
term at zero, corner failures, brute-force failures, profile evaluations, seconds), then the
totals. Exit status 1 when a check fails.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

import engine as eg
from engine.fit._varpro import NNLSProblem, best_candidates, grid_candidates, sqrt_weight
from engine.fit.gmwm import gmwm_objective, weight_matrix
from engine.inference.selection import submodels
from engine.models import TC_MAX_FACTOR, TC_MIN

FILES = [f"adis16405_imu{i}.h5" for i in range(1, 7)] + ["mtig_cont_imu1.h5"]
RTOL = 1e-6


def fit_lattice(wv: eg.WaveletVariance, max_model: str) -> dict[str, eg.GMWMResult]:
    """Every sub-model's fit, smallest first with one shared table of optima (as a ranking)."""
    optima: dict = {}
    fits = {}
    for m in sorted(submodels(max_model), key=lambda m: len(m.processes)):
        try:
            m.validate(wv.n_levels)
        except eg.ModelError:
            continue
        fits[m.spec()] = eg.fit_gmwm(wv, m, optima=optima)
    return fits


def corner_failures(wv: eg.WaveletVariance, fits: dict[str, eg.GMWMResult]) -> tuple[int, list]:
    """(fits with a term at zero, [(model, objective, smaller model, its objective)])."""
    n_zero, bad = 0, []
    for spec, r in fits.items():
        keep = tuple(q.cleared() for q in r.model.processes if q.linear_coef() != 0.0)
        if len(keep) == len(r.model.processes) or not keep:
            continue
        sub = eg.Model(keep).spec()
        if sub not in fits:
            continue
        n_zero += 1
        mine = gmwm_objective(wv, r.model)
        theirs = gmwm_objective(wv, fits[sub].model)
        if theirs > mine * (1 + RTOL):
            bad.append((spec, mine, sub, theirs))
    return n_zero, bad


def brute_force(wv: eg.WaveletVariance, model: eg.Model, n_grid: int) -> float:
    """The lowest profiled objective on the dense grid of correlation times."""
    omega, _ = weight_matrix(wv)
    prob = NNLSProblem.from_wv(model, wv, sqrt_weight(omega))
    if prob.k == 0:
        return prob.profile(np.zeros(0))
    axis = np.linspace(math.log(TC_MIN), math.log(TC_MAX_FACTOR * max(wv.n, 2)), n_grid)
    return best_candidates(prob, grid_candidates(axis, prob.k), 1)[0][0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[3] / "shared" / "data"))
    ap.add_argument("--files", nargs="*", default=FILES)
    ap.add_argument("--max-model", default="2*GM+WN+QN+RW+DR")
    ap.add_argument("--grid", type=int, default=160)
    args = ap.parse_args()
    tot = dict(fits=0, zero=0, corner=0, brute=0, evals=0, fit_s=0.0)
    print(
        f"{'log':<22} {'channel':<8} {'fits':>4} {'zero':>4} {'corner':>6} {'brute':>5} "
        f"{'evals':>7} {'fit s':>6}"
    )
    for name in args.files:
        log = eg.load_log(Path(args.data) / name)
        for ch in log.channels:
            wv = eg.wavelet_variance(log[ch], fs=log.fs)
            t0 = time.perf_counter()
            fits = fit_lattice(wv, args.max_model)
            fit_s = time.perf_counter() - t0
            n_zero, bad = corner_failures(wv, fits)
            n_brute = 0
            for spec, r in fits.items():
                if r.model.is_linear:
                    continue
                g = brute_force(wv, eg.parse_model(spec), args.grid)
                if g < r.objective * (1 - RTOL):
                    n_brute += 1
                    print(f"  brute force beats {spec}: grid {g:.6g} < fit {r.objective:.6g}")
            for spec, mine, sub, theirs in bad:
                print(f"  corner: {spec} {mine:.6g} with a term at 0, {sub} fitted {theirs:.6g}")
            evals = sum(r.n_evaluations for r in fits.values())
            print(
                f"{name:<22} {ch:<8} {len(fits):>4} {n_zero:>4} {len(bad):>6} {n_brute:>5} "
                f"{evals:>7} {fit_s:>6.2f}",
                flush=True,
            )
            for k, v in zip(
                ("fits", "zero", "corner", "brute", "evals", "fit_s"),
                (len(fits), n_zero, len(bad), n_brute, evals, fit_s),
                strict=True,
            ):
                tot[k] += v
    print(
        f"total: {tot['fits']} fits, {tot['zero']} with a term at zero, {tot['corner']} corner "
        f"failures, {tot['brute']} brute-force failures, {tot['evals']} profile evaluations, "
        f"{tot['fit_s']:.1f} s of fitting"
    )
    return 1 if tot["corner"] or tot["brute"] else 0


if __name__ == "__main__":
    sys.exit(main())
