"""Model selection judged by what a filter needs. Run from the repository
root:

    nice -n 10 python tests/benchmarks/selection_mc.py [--logs 100] [--max-model FAMILY]
        [--settings slow-GM+WN+RW ...] [--seed 11] [--cache DIR] [--variants]

For each setting, ``--logs`` logs are simulated, every sub-model of the setting's family
(``FAMILY``: the truth and the alternatives it is confused with; ``--max-model`` gives one
family to all) is ranked by :func:`engine.inference.rank_models` (ci weights, asymptotic
optimism: the defaults), and three choices are scored: the first row of the ranking (the WVIC
alone), the first row made actionable (``SelectionResult.first_actionable``: no AR1/GM faster
than one sample, nothing at a bound; the selection before the tie rules) and the selection
``SelectionResult.best`` (with the tie rules of :func:`engine.inference.selection.tie_choice`).
Each log's ranking is saved in ``--cache`` (a pickle per log; a log already there is not
ranked again: delete the cache when the ranking's code changes; ``--cached-only`` scores the
cached logs alone, for a run stopped part way), so that ``--variants`` scores the tie rules
with other bands (``z``) and slow-GM fractions on the same logs at no cost.
Printed per setting and choice:

* ``true``: how often the chosen structure is the true one;
* ``in band``: how often the chosen model's implied WV lies within the true WV's 95 % band
  (Percival's eta3 chi-square interval around the true WV) at every scale;
* ``N err``, ``K err``, ``B err``: median absolute relative error of the white-noise density N
  (``sqrt(sigma2 / fs)``, WN plus the white-noise equivalent of terms faster than one sample),
  the random-walk density K (``sqrt(gamma2 fs)``; ``-`` when the truth has no RW) and the
  bias-instability B (the minimum over tau of the implied Allan deviation, divided by 0.664),
  each against the true model's own value;
* ``K missed``: how often the truth has a RW but the chosen model does not; ``RW->DR``: how
  often the chosen model has a drift and no RW when the truth has a RW and no drift;
  ``over``: how often the chosen model has a term the truth does not have (or more of one).

The binomial standard error of a rate p over L logs is ``sqrt(p (1 - p) / L)`` (5 points at
p = 0.5 and L = 100).
"""

from __future__ import annotations

import argparse
import math
import pickle
import time
from collections import Counter
from pathlib import Path

import numpy as np
from scipy import stats

import engine as eg
from engine.inference import SelectionResult, rank_models
from engine.inference.selection import GM_RW, SLOW_GM, TIE_Z, tie_choice, wvic_se

FS = 100.0

#: (true model at 100 Hz, log length): the four settings of issue 27 item 5 and two more
SETTINGS = {
    # item 5: the random walk missed (GM+WN won 84/100)
    "slow-GM+WN+RW": ("GM(beta=0.01, sigma2_gm=1e-2)+WN(sigma2=1)+RW(gamma2=1e-6)", 2**17),
    # item 5: the random walk read as a drift (GM+WN+DR won 40/100)
    "GM+WN+RW": ("GM(beta=2, sigma2_gm=1)+WN(sigma2=1)+RW(gamma2=1e-4)", 2**16),
    # item 5: over-fitted winners 20/100
    "QN+WN+RW": ("QN(q2=1)+WN(sigma2=1)+RW(gamma2=1e-4)", 2**16),
    # item 5: the white-noise-twin setting (a disguised term on top)
    "2*GM+WN": ("GM(beta=0.2, sigma2_gm=0.5)+GM(beta=10, sigma2_gm=1)+WN(sigma2=1)", 2**16),
    # own: a strong drift with a random walk (item 6's setting, shorter)
    "WN+RW+DR": ("WN(sigma2=1)+RW(gamma2=1e-5)+DR(omega=1e-5)", 2**16),
    # own: a quantised MEMS gyro with bias instability, as the ADIS16405 (one slow GM)
    "GM+QN+WN+RW": ("GM(beta=0.05, sigma2_gm=5e-2)+QN(q2=0.5)+WN(sigma2=1)+RW(gamma2=1e-6)", 2**16),
}

#: the candidates of each setting: every sub-model of a family that holds the truth and the
#: alternatives it is confused with (one GM where the truth has one: a ranking of the 47
#: sub-models of 2*GM+WN+QN+RW+DR costs 4-13 s of CPU, of these 11-31 about 1-3 s)
FAMILY = {
    "slow-GM+WN+RW": "GM+WN+RW+DR",
    "GM+WN+RW": "GM+WN+RW+DR",
    "QN+WN+RW": "GM+WN+QN+RW+DR",
    "2*GM+WN": "2*GM+WN+RW",
    "WN+RW+DR": "GM+WN+QN+RW+DR",
    "GM+QN+WN+RW": "GM+WN+QN+RW+DR",
}

#: pairs of candidates whose WVIC difference's spread over the logs ``--se-check`` compares
#: with :func:`engine.inference.selection.wvic_se` (per setting: (reference, other))
SE_PAIRS = {
    "slow-GM+WN+RW": [("GM+WN+RW", "GM+WN"), ("GM+WN+RW", "WN+RW")],
    "GM+WN+RW": [("GM+WN+RW", "GM+WN+DR"), ("GM+WN+RW", "GM+WN+RW+DR"), ("GM+WN+RW", "GM+WN")],
    "QN+WN+RW": [("QN+WN+RW", "QN+WN+RW+DR"), ("QN+WN+RW", "GM+QN+WN+RW")],
    "2*GM+WN": [("2*GM+WN", "2*GM+WN+RW"), ("2*GM+WN", "GM+WN+RW")],
    "WN+RW+DR": [("WN+RW+DR", "WN+RW"), ("WN+RW+DR", "QN+WN+RW+DR")],
    "GM+QN+WN+RW": [("GM+QN+WN+RW", "GM+QN+WN"), ("GM+QN+WN+RW", "QN+WN+RW")],
}

#: the tie rules' settings scored by ``--variants`` (z, slow-GM fraction); inf: no GM swap
VARIANTS = [(z, g) for z in (0.5, 1.0, 2.0) for g in (1.0, 1 / 16, 1 / 32, 1 / 64, math.inf)]

#: the fractions of the log beyond which a tie that adds a RW beside the selection's slowest
#: AR1/GM is chosen (``gm_rw`` of :func:`tie_choice`), scored by ``--variants`` with the
#: default band and slow-GM swap; inf: never
GM_RW_VARIANTS = [math.inf, 1 / 16, 1 / 32, 1 / 64, 1 / 128, 0.0]


def quantities(model: eg.Model, fs: float, tau: np.ndarray) -> tuple[float, float, float]:
    """(N, K, B) of a model: see the module notes (B from the implied WV at ``tau``)."""
    white, gamma2 = 0.0, 0.0
    for q in model.processes:
        if q.code == "WN":
            white += q.linear_coef()
        elif q.code == "RW":
            gamma2 += q.linear_coef()
        elif q.nonlinear is not None:
            phi = q.nl_value(fs)
            if phi is not None and 0 < phi < 1 and -1 / math.log(phi) < 1.0:
                white += q.white_equivalent(fs)
    adev = np.sqrt(2.0 * model.wv(tau, fs))  # AVAR(tau / 2) = 2 nu2(tau)
    return math.sqrt(white / fs), math.sqrt(gamma2 * fs), float(adev.min()) / 0.664


def true_band(truth: eg.Model, wv: eg.WaveletVariance, alpha: float = 0.05) -> np.ndarray:
    """(2, J) 95 % band of the WV estimate around the true WV (eta3 chi-square)."""
    nu = truth.wv(wv.tau_samples, wv.fs)
    eta = np.maximum(wv.n_coef / wv.tau_samples, 1.0)
    lo = nu * stats.chi2.ppf(alpha / 2, eta) / eta
    hi = nu * stats.chi2.ppf(1 - alpha / 2, eta) / eta
    return np.vstack([lo, hi])


def structure(model: eg.Model) -> Counter[str]:
    """The terms of a model with a positive variance, counted by code."""
    return Counter(q.code for q in model.processes if q.linear_coef() > 0)


def ranked_logs(
    name: str, logs: int, max_model: str, seed: int, cache: Path | None, cached_only: bool = False
) -> list[SelectionResult]:
    """The rankings of ``logs`` simulated logs of a setting (from the cache when there; with
    ``cached_only``, only the cached ones: a run stopped part way is scored as it stands)."""
    truth_spec, n = SETTINGS[name]
    truth = eg.parse_model(truth_spec)
    rng = np.random.default_rng(seed)
    out = []
    for i in range(logs):
        x = truth.simulate(n, fs=FS, rng=rng)  # every log drawn: the i-th log is the same
        path = cache / f"{name}_{max_model}_{seed}_{i:03d}.pkl" if cache else None
        if path is not None and path.exists():
            out.append(pickle.loads(path.read_bytes()))
            continue
        if cached_only:
            continue
        sel = rank_models(eg.wavelet_variance(x, fs=FS), max_model=max_model)
        if path is not None:
            path.write_bytes(pickle.dumps(sel))
        out.append(sel)
    return out


def score(truth_spec: str, n: int, chosen: list[eg.inference.Candidate], rankings: list) -> dict:
    """The columns of the table for one choice per log."""
    truth = eg.parse_model(truth_spec)
    have = structure(truth)
    dense = np.geomspace(2, n / 4, 200)
    n0, k0, b0 = quantities(truth, FS, dense)
    o: dict = {"true": 0, "band": 0, "N": [], "K": [], "B": [], "Kmiss": 0, "RWDR": 0, "over": 0}
    for cand, sel in zip(chosen, rankings, strict=True):
        r = cand.result
        if r is None:
            continue
        band = true_band(truth, sel.candidates[0].result.wv)
        got = structure(r.model)
        o["true"] += got == have
        o["band"] += bool(np.all((band[0] <= r.implied) & (r.implied <= band[1])))
        o["over"] += any(got[k] > have[k] for k in got)
        nn, kk, bb = quantities(r.model, FS, dense)
        o["N"].append(abs(nn / n0 - 1))
        o["B"].append(abs(bb / b0 - 1))
        if have["RW"]:
            o["K"].append(abs(kk / k0 - 1))
            o["Kmiss"] += not got["RW"]
            o["RWDR"] += not have["DR"] and got["DR"] > 0 and not got["RW"]
    return o


def choices(sel: SelectionResult) -> dict[str, eg.inference.Candidate]:
    """The three choices scored for one ranking."""
    first = sel.candidates[0]
    return {
        "WVIC first row": first,
        "actionable first row": sel.first_actionable or first,
        "selection": sel.best,
    }


def true_fit(sel: SelectionResult, truth_spec: str) -> eg.inference.Candidate | None:
    """The candidate with the true structure (a reference, not a choice: its fit on the log,
    actionable or not; None when it is not a candidate)."""
    spec = eg.parse_model(truth_spec).cleared().spec()
    return next((c for c in sel.candidates if c.model == spec and c.result is not None), None)


def se_check(name: str, rankings: list[SelectionResult]) -> list[str]:
    """Rows: the sd over the logs of a pair's WVIC difference against the formula's SE."""
    out = []
    for a, b in SE_PAIRS[name]:
        d, se = [], []
        for sel in rankings:
            by = {c.model: c for c in sel.candidates}
            ca, cb = by.get(a), by.get(b)
            if ca is None or cb is None or ca.result is None or cb.result is None:
                continue
            d.append(cb.criterion - ca.criterion)
            se.append(wvic_se(cb.result, ca.result, cb.optimism, ca.optimism, sel.v))
        if len(d) < 3:
            continue
        sd, rms = float(np.std(d, ddof=1)), float(np.sqrt(np.mean(np.square(se))))
        out.append(
            f"| {name} | {b} - {a} | {len(d)} | {np.mean(d):.4f} | {sd:.4f} | {rms:.4f} "
            f"| {sd / rms:.2f} |"
        )
    return out


def row(name: str, n: int, choice: str, o: dict, logs: int, dt: float) -> str:
    med = {q: (f"{100 * np.median(o[q]):.1f} %" if o[q] else "-") for q in "NKB"}
    rw = "RW" in SETTINGS[name][0]
    return (
        f"| {name} | 2^{int(math.log2(n))} | {choice} | {o['true']}/{logs} | {o['band']}/{logs} "
        f"| {med['N']} | {med['K']} | {med['B']} | {o['Kmiss'] if rw else '-'} "
        f"| {o['RWDR'] if rw else '-'} | {o['over']} | {dt:.0f} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--logs", type=int, default=100)
    ap.add_argument("--max-model", default=None, help="one family for every setting")
    ap.add_argument("--settings", nargs="*", default=list(SETTINGS))
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--cache", type=Path, default=None, help="directory of saved rankings")
    ap.add_argument("--variants", action="store_true", help="score the tie rules' variants")
    ap.add_argument("--cached-only", action="store_true", help="score the cached logs only")
    ap.add_argument("--se-check", action="store_true", help="the tie band's SE against the logs")
    args = ap.parse_args()
    if args.cache is not None:
        args.cache.mkdir(parents=True, exist_ok=True)
    print(
        f"Selection on simulated logs: {'the cached' if args.cached_only else args.logs} logs per "
        f"setting at {FS:g} Hz, every "
        f"sub-model of the family ranked (ci weights, asymptotic optimism); tie rules: band "
        f"{TIE_Z:g} SE, slow GM > {SLOW_GM:.3g} of the log, a RW beside a GM > {GM_RW:.3g} of "
        "the log"
    )
    print(
        "| setting | N | choice | true | in band | N err | K err | B err | K missed | RW->DR "
        "| over | s |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    )
    variants: dict = {}
    checks: list[str] = []
    for name in list(args.settings):
        truth, n = SETTINGS[name]
        family = args.max_model or FAMILY[name]
        t0 = time.perf_counter()
        seed = args.seed + list(SETTINGS).index(name)
        rankings = ranked_logs(name, args.logs, family, seed, args.cache, args.cached_only)
        logs = len(rankings)
        if not logs:  # --cached-only with none of this setting's logs in the cache
            args.settings = [nm for nm in args.settings if nm != name]
            continue
        dt = time.perf_counter() - t0
        for choice in ("WVIC first row", "actionable first row", "selection"):
            chosen = [choices(sel)[choice] for sel in rankings]
            print(row(name, n, choice, score(truth, n, chosen, rankings), logs, dt), flush=True)
        ref = [(c, s) for s in rankings if (c := true_fit(s, truth)) is not None]
        if ref:
            o = score(truth, n, [c for c, _ in ref], [s for _, s in ref])
            print(row(name, n, "true structure's fit", o, len(ref), dt), flush=True)
        if args.se_check:
            checks += se_check(name, rankings)
        if args.variants:
            for z, g in VARIANTS:
                chosen = [
                    tie_choice(
                        sel.candidates, choices(sel)["actionable first row"], sel.v, z=z, slow_gm=g
                    )
                    for sel in rankings
                ]
                variants[(name, z, g)] = score(truth, n, chosen, rankings)
            for g in GM_RW_VARIANTS:
                first = [choices(sel)["actionable first row"] for sel in rankings]
                chosen = [
                    tie_choice(sel.candidates, c, sel.v, gm_rw=g)
                    for sel, c in zip(rankings, first, strict=True)
                ]
                variants[(name, "gm_rw", g)] = score(truth, n, chosen, rankings)
    if args.variants:
        print("\nTie rules' variants (in band / true / K missed / over, per setting):")
        print(f"| z | slow GM | {' | '.join(args.settings)} | in band | K missed | over |")
        print("|---" * (len(args.settings) + 5) + "|")
        for z, g in VARIANTS:
            cells = [variants[(nm, z, g)] for nm in args.settings]
            txt = " | ".join(f"{o['band']}/{o['true']}/{o['Kmiss']}/{o['over']}" for o in cells)
            tot = [sum(o[k] for o in cells) for k in ("band", "Kmiss", "over")]
            print(f"| {z:g} | {g:.3g} | {txt} | {' | '.join(map(str, tot))} |")
        print(
            "\nA RW kept beside a slow GM (gm_rw: a tie that adds a RW to a selection whose "
            "slowest AR1/GM is slower than this fraction of the log; band 1 SE; in band / true / "
            "K missed / over, median K error, per setting):"
        )
        print(f"| gm_rw | {' | '.join(args.settings)} | in band | K missed | over |")
        print("|---" * (len(args.settings) + 4) + "|")
        for g in GM_RW_VARIANTS:
            cells = [variants[(nm, "gm_rw", g)] for nm in args.settings]
            txt = " | ".join(
                f"{o['band']}/{o['true']}/{o['Kmiss']}/{o['over']}"
                + (f", K {100 * np.median(o['K']):.0f} %" if o["K"] else "")
                for o in cells
            )
            tot = [sum(o[k] for o in cells) for k in ("band", "Kmiss", "over")]
            print(f"| {g:.3g} | {txt} | {' | '.join(map(str, tot))} |")

    if args.se_check:
        print("\nThe WVIC difference of a pair over the logs against wvic_se (the tie band's SE):")
        print("| setting | difference | logs | mean | sd over the logs | SE (rms) | sd / SE |")
        print("|---|---|---|---|---|---|---|")
        print("\n".join(checks))


if __name__ == "__main__":
    main()
