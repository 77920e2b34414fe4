"""Within the WVIC's tie band the selection prefers a random walk to a drift that mimics it and
the fewer parameters to an over-fitted first row (engine.inference.selection.tie_choice).

The logs are the simulated logs of tests/benchmarks/selection_mc.py (same settings, seeds and
candidate families) on which the previous selection, the first row made actionable, was wrong;
the expected structure is the true one and the expected values are the truth's.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import engine as eg
from engine.inference import rank_models
from engine.inference.selection import GM_RW, tie_choice

FS = 100.0
ROOT = Path(__file__).resolve().parents[2]


def _selection_mc():
    """tests/benchmarks/selection_mc.py: the settings, candidate families and scores."""
    spec = importlib.util.spec_from_file_location(
        "selection_mc", ROOT / "tests" / "benchmarks" / "selection_mc.py"
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules["selection_mc"] = mod
    spec.loader.exec_module(mod)
    return mod


def _log(truth: str, n: int, seed: int, index: int) -> eg.WaveletVariance:
    """The ``index``-th log of a setting of selection_mc.py (its seed: 11 + setting index)."""
    model = eg.parse_model(truth)
    rng = np.random.default_rng(seed)
    for _ in range(index + 1):
        x = model.simulate(n, fs=FS, rng=rng)
    return eg.wavelet_variance(x, fs=FS)


def _structure(model: eg.Model) -> list[str]:
    return sorted(q.code for q in model.processes if q.linear_coef() > 0)


def _in_true_band(truth: eg.Model, wv: eg.WaveletVariance, implied: np.ndarray) -> bool:
    """The implied WV within the true WV's 95 % band (eta3 chi-square) at every scale."""
    nu = truth.wv(wv.tau_samples, wv.fs)
    eta = np.maximum(wv.n_coef / wv.tau_samples, 1.0)
    lo, hi = (nu * stats.chi2.ppf(q, eta) / eta for q in (0.025, 0.975))
    return bool(np.all((lo <= implied) & (implied <= hi)))


def test_a_random_walk_read_as_a_drift_is_selected_as_the_random_walk():
    # GM+WN+RW at 2^16 (selection_mc.py "GM+WN+RW", seed 12, third log): the first row is
    # GM+WN+DR (the RW read as a drift); GM+WN+RW is 0.003 behind it, well within one SE
    spec = "GM(beta=2, sigma2_gm=1)+WN(sigma2=1)+RW(gamma2=1e-4)"
    truth = eg.parse_model(spec)
    wv = _log(spec, 2**16, 12, 2)
    sel = rank_models(wv, max_model="GM+WN+RW+DR")
    assert sel.candidates[0].model == "GM+WN+DR"
    best = sel.best
    assert _structure(best.result.model) == _structure(truth)  # before: GM+WN+DR
    assert sel.first_actionable is None  # the first row was actionable: the tie rule chose
    assert best.is_actionable and best.derived_from == "GM+WN+DR"
    assert "a RW for its drift DR" in best.derivation[-1]
    assert sel.table().splitlines()[1].startswith("selected: GM+WN+RW (the rank-1 GM+WN+DR")
    # what a filter takes away: K within 25 % of the truth's, the WV within the true band
    k = math.sqrt(best.result.params["RW.gamma2"] * FS)
    assert k == pytest.approx(math.sqrt(1e-4 * FS), rel=0.25)
    assert _in_true_band(truth, wv, best.result.implied)


def test_an_over_fitted_first_row_gives_way_to_its_tied_sub_model():
    # QN+WN+RW at 2^16 (selection_mc.py "QN+WN+RW", seed 13, third log): the first row is
    # QN+WN+RW+DR, whose drift takes the long scales beyond the true band
    spec = "QN(q2=1)+WN(sigma2=1)+RW(gamma2=1e-4)"
    truth = eg.parse_model(spec)
    wv = _log(spec, 2**16, 13, 2)
    sel = rank_models(wv, max_model="GM+WN+QN+RW+DR")
    top = sel.candidates[0]
    assert top.model == "QN+WN+RW+DR" and not _in_true_band(truth, wv, top.result.implied)
    best = sel.best
    assert best.model == "QN+WN+RW"  # before: the first row
    assert "fewer parameters" in best.derivation[-1]
    assert _in_true_band(truth, wv, best.result.implied)
    assert best.result.params["RW.gamma2"] == pytest.approx(1e-4, rel=0.3)


def test_a_first_row_the_others_do_not_tie_with_is_kept():
    # WN+RW, 2^15: GM+WN+RW, a drift and a quantisation are far behind; the first row stays
    spec = "WN(sigma2=1)+RW(gamma2=1e-4)"
    sel = rank_models(_log(spec, 2**15, 5, 0), ["WN", "WN+RW", "WN+DR", "QN+WN+RW"])
    assert sel.candidates[0].model == "WN+RW"
    assert sel.selected is None and sel.best is sel.candidates[0]
    assert sel.table().splitlines()[1].startswith("selected: WN+RW (rank 1;")


def test_a_random_walk_beside_a_slow_gm_is_added_only_when_asked():
    # slow GM+WN+RW at 2^17 (selection_mc.py "slow-GM+WN+RW", seed 11, twelfth log): the
    # selection is GM+WN, the random walk missed; GM+WN+RW ties with it. Adding a RW beside a
    # GM slower than a fraction of the log (gm_rw) is off by default: on the ADIS-like setting
    # of docs/selection.md it takes the WV out of the true band (93 -> 87 of 100 at 1/64)
    spec = "GM(beta=0.01, sigma2_gm=1e-2)+WN(sigma2=1)+RW(gamma2=1e-6)"
    truth = eg.parse_model(spec)
    wv = _log(spec, 2**17, 11, 11)
    sel = rank_models(wv, max_model="GM+WN+RW+DR")
    assert sel.best.model == "GM+WN" and GM_RW == math.inf
    start = sel.first_actionable or sel.candidates[0]
    best = tie_choice(sel.candidates, start, sel.v, gm_rw=1 / 64)
    assert _structure(best.result.model) == _structure(truth)
    assert "a RW beside its GM of" in best.derivation[-1]
    # the GM is the truth's (100 s, 0.076 of the log), fitted at 0.02-0.03 of the log
    assert "(0.024 of the log)" in best.derivation[-1]
    k = math.sqrt(best.result.params["RW.gamma2"] * FS)
    assert k == pytest.approx(math.sqrt(1e-6 * FS), rel=0.25)
    assert _in_true_band(truth, wv, best.result.implied)


@pytest.mark.slow
def test_a_random_walk_is_no_longer_read_as_a_drift_on_fresh_logs():
    """30 fresh logs of selection_mc.py's GM+WN+RW setting (2^16 samples; seed 2027, not one of
    the logs the rules were chosen on), every sub-model of GM+WN+RW+DR, scored on the same logs
    for the previous selection (``first_actionable``) and the selection. On the 100 logs of
    docs/selection.md the previous selection read the RW as a drift in 16 % of the logs and the
    tie rules in 1 %: with 30 logs, 2 or fewer at 1 % has probability 0.997; and the true
    structure must gain (82 % against 95 % there: an expected gain of 3.9 logs, sd 2). About 35 s
    of CPU."""
    mc = _selection_mc()
    truth, n = mc.SETTINGS["GM+WN+RW"]
    rankings = mc.ranked_logs("GM+WN+RW", 30, mc.FAMILY["GM+WN+RW"], 2027, None)
    before = mc.score(truth, n, [s.first_actionable or s.candidates[0] for s in rankings], rankings)
    now = mc.score(truth, n, [s.best for s in rankings], rankings)
    assert now["RWDR"] <= 2, (before["RWDR"], now["RWDR"])
    assert now["true"] >= before["true"] + 1, (before["true"], now["true"])
    assert now["band"] >= before["band"] - 1  # the WV a filter uses is not lost
