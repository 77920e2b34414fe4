"""Teaching scenarios: the slope method's pitfalls are real (analytic and Monte Carlo checks).

For each built-in scenario the naive AVSM regions must give a visibly biased (or erratic)
estimate while GMWM of the same processes is close to the truth. The checks are on the
parameter the scenario is about, over ``R`` simulated logs (not single draws), and on the
noise-free Allan variance of the true model (the bias of the slope method is structural).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import engine as eg
from engine.teaching import SCENARIOS, Scenario, avsm, get_scenario, gmwm_spec, simulate_scenario
from engine.wv.allan import AllanVariance

R = 30  # Monte Carlo replicates per scenario (about 1 s in all)


def _ratios(sc: Scenario) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Estimate / truth per parameter for AVSM (naive regions) and GMWM, over R seeds."""
    truth = sc.model.values()
    a_out: dict[str, list[float]] = {}
    g_out: dict[str, list[float]] = {}
    spec = gmwm_spec([c for c, _, _ in sc.regions])
    for r in range(R):
        wv = eg.wavelet_variance(sc.simulate(10_000 + r), fs=sc.fs, unit=sc.unit)
        a = avsm(wv, sc.region_dict)
        g = eg.fit_gmwm(wv, spec)
        for k, v in a.params.items():
            if k in truth:
                a_out.setdefault(k, []).append(v / truth[k])
        for k, v in g.params.items():
            if k in truth:
                g_out.setdefault(k, []).append(v / truth[k])
    return ({k: np.array(v) for k, v in a_out.items()}, {k: np.array(v) for k, v in g_out.items()})


def _rmse(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - 1.0) ** 2)))


def _se(x: np.ndarray) -> float:
    return float(np.std(x, ddof=1) / math.sqrt(x.size))


@pytest.fixture(scope="module")
def mc() -> dict[str, tuple[dict[str, np.ndarray], dict[str, np.ndarray]]]:
    return {k: _ratios(sc) for k, sc in SCENARIOS.items()}


# ---------------------------------------------------------------------------------------------
def test_scenarios_are_complete_and_consistent() -> None:
    assert {"wn_gm", "qn_wn", "rw_dr", "short_log"} <= set(SCENARIOS)
    for sc in SCENARIOS.values():
        assert sc.model.is_set and len(sc.why) > 40 and sc.title
        codes = [c for c, _, _ in sc.regions]
        assert len(set(codes)) == len(codes)
        # the GMWM model has the scenario's processes (its BI floor is a GM)
        true_codes = sorted(p.code for p in sc.model.processes)
        assert sorted(eg.parse_model(gmwm_spec(codes)).spec().split("+")) == true_codes
        # every region holds at least two octave averaging times of the log (a slope to see)
        m = 2 ** np.arange(math.floor(math.log2(sc.n - 1)))
        tau = m / sc.fs
        for c, lo, hi in sc.regions:
            assert np.sum((tau >= lo) & (tau <= hi)) >= 2, (sc.key, c)
    with pytest.raises(KeyError, match="wn_gm"):
        get_scenario("nope")
    with pytest.raises(ValueError, match="XX"):
        gmwm_spec(["WN", "XX"])
    assert gmwm_spec(["WN", "BI"]) == "GM+WN"
    assert gmwm_spec(("DR", "QN", "WN", "RW")) == "QN+WN+RW+DR"


def test_simulation_is_deterministic_and_carries_the_truth() -> None:
    sc = SCENARIOS["qn_wn"]
    a = simulate_scenario("qn_wn")
    b = simulate_scenario(sc)
    c = simulate_scenario(sc, seed=sc.seed + 1)
    x = a[sc.channel]
    assert x.shape == (sc.n,) and a.fs == sc.fs and a.units[sc.channel] == sc.unit
    np.testing.assert_array_equal(x, b[sc.channel])
    assert not np.array_equal(x, c[sc.channel])
    assert eg.parse_model(a.meta["truth"][sc.channel]).values() == sc.model.values()
    assert a.meta["scenario"] == "qn_wn" and a.meta["description"] == sc.why
    # QN + WN: the sample variance is 2 q2 + sigma2 (docs/conventions.md), within 4 standard errors
    v = 2 * 4e-4 + 1e-3
    assert abs(np.var(x) - v) < 4 * v * math.sqrt(2 / sc.n) * 2


@pytest.mark.parametrize(
    "key,code", [("wn_gm", "WN"), ("qn_wn", "QN"), ("qn_wn", "WN"), ("rw_dr", "RW")]
)
def test_slope_method_is_biased_even_without_noise(key: str, code: str) -> None:
    """On the exact Allan variance of the true model the naive lines are still too high."""
    sc = SCENARIOS[key]
    j = math.floor(math.log2(sc.n - 1))
    tau = 2.0 ** np.arange(1, j + 1)
    nu = sc.model.wv(tau, sc.fs)
    wv = eg.WaveletVariance.from_arrays(nu, n=sc.n, fs=sc.fs, unit=sc.unit)
    est = avsm(AllanVariance.from_wv(wv), sc.region_dict)
    name = {"WN": "WN.sigma2", "QN": "QN.q2", "RW": "RW.gamma2"}[code]
    ratio = est.params[name] / sc.model.values()[name]
    assert ratio > 1.1, (key, code, ratio)
    # while a region where the process alone matters reads it right (the method itself is exact)
    if code == "WN" and key == "wn_gm":
        only = avsm(
            AllanVariance.from_wv(
                eg.WaveletVariance.from_arrays(
                    eg.parse_model("WN(sigma2=1e-3)").wv(tau, sc.fs), n=sc.n, fs=sc.fs
                )
            ),
            {"WN": (0.01, 1.0)},
        )
        assert only.params["WN.sigma2"] == pytest.approx(1e-3, rel=1e-9)


def test_wn_gm_slope_overstates_white_noise(mc) -> None:
    a, g = mc["wn_gm"]
    assert a["WN.sigma2"].mean() > 1.3  # about 1.45
    assert abs(g["WN.sigma2"].mean() - 1) < 0.02 + 3 * _se(g["WN.sigma2"])
    assert _rmse(a["WN.sigma2"]) > 10 * _rmse(g["WN.sigma2"])
    # GMWM also recovers the GM the slope method calls "bias instability"
    assert abs(np.median(g["GM.beta"]) - 1) < 0.15
    assert abs(np.median(g["GM.sigma2_gm"]) - 1) < 0.15


def test_qn_wn_slope_reads_white_noise_as_quantization(mc) -> None:
    a, g = mc["qn_wn"]
    assert a["QN.q2"].mean() > 1.8  # about 2.2
    assert a["WN.sigma2"].mean() > 1.1  # about 1.2
    for k in ("QN.q2", "WN.sigma2"):
        assert abs(g[k].mean() - 1) < 0.03 + 3 * _se(g[k]), k
        assert _rmse(a[k]) > 4 * _rmse(g[k]), k


def test_rw_dr_slope_overstates_the_random_walk(mc) -> None:
    a, g = mc["rw_dr"]
    assert a["RW.gamma2"].mean() > 1.3  # about 1.6
    assert abs(np.median(g["RW.gamma2"]) - 1) < 0.15
    assert _rmse(a["RW.gamma2"]) > 3 * _rmse(g["RW.gamma2"])
    # white noise is read correctly by both (its region is clean)
    assert abs(a["WN.sigma2"].mean() - 1) < 0.02 and abs(g["WN.sigma2"].mean() - 1) < 0.02


def test_short_log_slope_random_walk_is_erratic(mc) -> None:
    a, g = mc["short_log"]
    # the slope reading scatters about twice as much as GMWM, and its median is low
    assert _rmse(a["RW.gamma2"]) > 1.5 * _rmse(g["RW.gamma2"])
    assert np.median(a["RW.gamma2"]) < np.median(g["RW.gamma2"])
    assert abs(g["RW.gamma2"].mean() - 1) < 0.05 + 3 * _se(g["RW.gamma2"])
