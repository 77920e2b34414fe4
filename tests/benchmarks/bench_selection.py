"""Model selection against white noise in disguise. Run from the repository
root:

    python tests/benchmarks/bench_selection.py [--logs 100] [--n 16384] [--max-model 2*GM+WN+RW]

For each true model, ``--logs`` logs are simulated and every sub-model of ``--max-model`` is
ranked by :func:`engine.inference.rank_models` (ci weights, asymptotic optimism, the
defaults). Printed per true model:

* how often the true structure ranks first;
* how often the top-ranked structure has an AR1/GM faster than one sample, by the ranking
  (``sub-sample top``) and by the WVIC alone as before the WN-twin rule (``by WVIC alone``),
  with the most frequent such disguised winner.
"""

from __future__ import annotations

import argparse
import collections
import time

import numpy as np

import engine as eg
from engine.inference import rank_models

#: true models at 100 Hz: a GM with a visible bump, two GMs, white noise and random walk only
MODELS = {
    "GM+WN+RW": "GM(beta=2, sigma2_gm=1)+WN(sigma2=1)+RW(gamma2=1e-4)",
    "2*GM+WN": "GM(beta=0.2, sigma2_gm=0.5)+GM(beta=10, sigma2_gm=1)+WN(sigma2=1)",
    "WN+RW": "WN(sigma2=1)+RW(gamma2=1e-4)",
}
FS = 100.0


def study(truth: str, n: int, logs: int, max_model: str, seed: int) -> dict[str, object]:
    """Ranks of ``logs`` simulated logs of ``truth``."""
    model = eg.parse_model(truth)
    spec = model.cleared().spec()
    rng = np.random.default_rng(seed)
    first = sub_top = old_sub_top = 0
    old_winners: collections.Counter[str] = collections.Counter()
    for _ in range(logs):
        wv = eg.wavelet_variance(model.simulate(n, fs=FS, rng=rng), fs=FS)
        sel = rank_models(wv, max_model=max_model)
        first += sel.best.model == spec
        sub_top += bool(sel.best.sub_sample)
        fitted = [c for c in sel.candidates if c.result is not None and not c.added]
        old = min(fitted, key=lambda c: (c.criterion, c.n_params))  # the WVIC alone
        if old.sub_sample:
            old_sub_top += 1
            old_winners[old.model] += 1
    return {
        "first": first,
        "sub_top": sub_top,
        "old_sub_top": old_sub_top,
        "old_winner": old_winners.most_common(1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--logs", type=int, default=100)
    ap.add_argument("--n", type=lambda s: int(float(s)), default=16384)
    ap.add_argument("--max-model", default="2*GM+WN+RW")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    print(
        f"WVIC selection: {args.logs} logs of N = {args.n} at {FS:g} Hz per true model, "
        f"every sub-model of {args.max_model}"
    )
    print(f"{'true model':<12} {'true first':>10} {'sub-sample top':>15} {'by WVIC alone':>14}  s")
    for k, (name, truth) in enumerate(MODELS.items()):
        t0 = time.perf_counter()
        r = study(truth, args.n, args.logs, args.max_model, args.seed + k)
        win = f" (most often {r['old_winner'][0][0]})" if r["old_winner"] else ""
        print(
            f"{name:<12} {r['first']:>6}/{args.logs:<3} {r['sub_top']:>11}/{args.logs:<3} "
            f"{r['old_sub_top']:>10}/{args.logs:<3} {time.perf_counter() - t0:5.0f}{win}",
            flush=True,
        )


if __name__ == "__main__":
    main()
