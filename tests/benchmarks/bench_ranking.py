"""CPU time of model selection (every sub-model ranked) per channel of a real log. Run from the
repository root:

    nice -n 10 python tests/benchmarks/bench_ranking.py [--log PATH] [--channels gyro_x,accel_x]
        [--max-model 2*GM+WN+QN+RW+DR] [--save numbers.json] [--compare numbers.json]

For each channel: the CPU time (``time.process_time``, this process) of
:func:`engine.inference.rank_models` over every sub-model of ``--max-model`` (47 for the
default: the fits, the efficient J-test refits, the selection), the profile evaluations of its
searches (points of the profile asked for, one by one or in a batch, memo hits included), and
its ratio to a reference measured in the same run, a bare NumPy Haar WV of the same channel
(one cumulative sum, every level), so that figures taken at different loads of this shared
machine compare. SciPy is imported before the clock starts (its import is paid once
per process, not per channel).

``--save`` writes every candidate's objective, WVIC and J statistic; ``--compare`` prints the
largest relative difference from such a file (the numbers of another version of the code).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import scipy.stats  # noqa: F401  (imported once, before any clock)

import engine as eg
from engine.fit import _varpro
from engine.inference import rank_models

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def bare_wv(x: np.ndarray, levels: int) -> np.ndarray:
    """Haar WV of every level from one cumulative sum of the de-meaned series (the reference)."""
    s = np.concatenate(([0.0], np.cumsum(x - x.mean())))
    out = np.empty(levels)
    for j in range(1, levels + 1):
        m = 2 ** (j - 1)
        w = (s[2 * m :] - 2 * s[m:-m] + s[: -2 * m]) / 2**j
        out[j - 1] = float(w @ w) / w.size
    return out


def cpu(fn, repeat: int = 1) -> tuple[float, object]:
    """Smallest CPU time of ``repeat`` calls, and the last result."""
    best, out = math.inf, None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--log", default=str(DATA / "adis16405_imu1.h5"))
    ap.add_argument("--channels", default="gyro_x,accel_x", help="comma-separated, or 'all'")
    ap.add_argument("--max-model", default="2*GM+WN+QN+RW+DR")
    ap.add_argument("--save", help="write every candidate's numbers to this JSON file")
    ap.add_argument("--compare", help="compare every candidate's numbers with this JSON file")
    args = ap.parse_args()
    log = eg.load_log(args.log)
    names = log.names if args.channels == "all" else args.channels.split(",")
    n_eval = [0]
    profile = _varpro.NNLSProblem.profile

    def counted(self, u):  # type: ignore[no-untyped-def]
        n_eval[0] += 1
        return profile(self, u)

    _varpro.NNLSProblem.profile = counted  # type: ignore[method-assign]
    profile_many = getattr(_varpro.NNLSProblem, "profile_many", None)  # not in older trees

    def counted_many(self, u):  # type: ignore[no-untyped-def]
        n_eval[0] += len(u)
        return profile_many(self, u)

    if profile_many is not None:
        _varpro.NNLSProblem.profile_many = counted_many  # type: ignore[method-assign]
    numbers: dict[str, dict[str, list[float | None]]] = {}
    print(f"rank_models, every sub-model of {args.max_model}, {Path(args.log).name}")
    print(
        f"{'channel':<8} {'cands':>5} {'evals':>7} {'rank CPU s':>10} {'ref CPU s':>9} {'ratio':>6}"
    )
    for ch in names:
        x = np.asarray(log[ch], float)
        wv = log.wavelet_variance(ch)
        t_ref, _ = cpu(lambda x=x, j=wv.n_levels: bare_wv(x, j), repeat=3)
        n_eval[0] = 0
        t_rank, sel = cpu(lambda wv=wv: rank_models(wv, max_model=args.max_model))
        print(
            f"{ch:<8} {len(sel.candidates):>5} {n_eval[0]:>7} {t_rank:>10.2f} {t_ref:>9.3f} "
            f"{t_rank / t_ref:>6.1f}",
            flush=True,
        )
        numbers[ch] = {
            c.model: [
                None if not math.isfinite(v) else float(v)
                for v in (c.objective, c.criterion, c.j_stat)
            ]
            for c in sel.candidates
        }
        numbers[ch]["selected: " + sel.best.model] = [sel.best.objective, None, None]
    if args.save:
        Path(args.save).write_text(json.dumps(numbers, indent=1), encoding="utf-8")
    if args.compare:
        old = json.loads(Path(args.compare).read_text(encoding="utf-8"))
        print(f"{'channel':<8} {'compared':>8} {'max rel diff':>12}  where")
        for ch, rows in numbers.items():
            worst, where, n = 0.0, "", 0
            for spec, vals in rows.items():
                ref = old.get(ch, {}).get(spec)
                if ref is None:
                    where = where or f"{spec} missing"
                    continue
                for a, b in zip(vals, ref, strict=True):
                    if a is None or b is None:
                        continue
                    n += 1
                    d = abs(a - b) / max(abs(b), 1e-300)
                    if d > worst:
                        worst, where = d, spec
            print(f"{ch:<8} {n:>8} {worst:>12.2e}  {where}")


if __name__ == "__main__":
    main()
