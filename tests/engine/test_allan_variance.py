"""Allan variance, the slope method (AVSM, automatic read-off), GMWFM/ARMAV, the common form."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import engine as eg
from engine.fit.estimate import MethodEstimate, compare_table, from_gmwm
from engine.fit.gmwfm import fit_armav
from engine.teaching import avsm, avsm_auto
from engine.units import BI_FACTOR
from engine.wv.allan import AllanVariance, allan_variance


def textbook_avar(x: np.ndarray, m: int) -> float:
    """Overlapping Allan variance from running means, divisor N - 2m + 1 (every term summed)."""
    x = np.asarray(x, float)
    c = np.concatenate([[0.0], np.cumsum(x)])
    avg = (c[m:] - c[:-m]) / m
    d = avg[m:] - avg[:-m]
    return 0.5 * np.mean(d**2)


def exact_av(model: eg.Model, fs: float, n: int = 2**20) -> AllanVariance:
    """The model-implied octave Allan variance (no noise), as an AllanVariance."""
    ms = 2 ** np.arange(eg.wv.default_levels(n), dtype=np.int64)
    av = 2.0 * model.wv(2 * ms, fs)
    return AllanVariance(
        tau_samples=ms,
        avar=av,
        ci_low=av * 0.9,
        ci_high=av * 1.1,
        n_terms=n - 2 * ms + 1,
        n=n,
        fs=fs,
    )


def rel(est: MethodEstimate, truth: eg.Model) -> np.ndarray:
    tv = truth.values()
    return np.array([est.params[k] / tv[k] for k in tv])


# -------------------------------------------------------------------------------------------
# Allan variance
# -------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def series() -> np.ndarray:
    return (
        eg.parse_model("WN(sigma2=1.0)+RW(gamma2=1e-4)+DR(omega=1e-3)").simulate(
            20001, fs=10.0, rng=1
        )
        + 3.0
    )


@pytest.mark.parametrize("taus", ["octave", "decade", [1, 3, 5, 7, 100, 1234, 9999]])
def test_matches_allantools_oadev(series, taus):
    allantools = pytest.importorskip("allantools", reason="allantools comes with the bench extra")
    av = allan_variance(series, fs=10.0, taus=taus)
    t, dev, _, ns = allantools.oadev(series, rate=10.0, data_type="freq", taus=av.tau_s)
    np.testing.assert_allclose(t, av.tau_s, rtol=1e-12)
    np.testing.assert_allclose(dev, av.adev, rtol=1e-10)
    np.testing.assert_array_equal(ns, av.n_terms)


def test_octave_is_exactly_twice_the_wavelet_variance(series):
    wv = eg.wavelet_variance(series, fs=10.0)
    av = allan_variance(series, fs=10.0)
    np.testing.assert_array_equal(av.tau_samples, wv.tau_samples // 2)
    np.testing.assert_allclose(av.avar, 2 * wv.variance, rtol=1e-10)
    np.testing.assert_allclose(av.ci_low, 2 * wv.ci_low, rtol=1e-10)
    np.testing.assert_allclose(av.ci_high, 2 * wv.ci_high, rtol=1e-10)
    np.testing.assert_array_equal(av.n_terms, wv.n_coef)
    fw = AllanVariance.from_wv(wv)
    np.testing.assert_allclose(fw.avar, av.avar, rtol=1e-10)
    back = av.to_wv()
    np.testing.assert_allclose(back.variance, wv.variance, rtol=1e-10)
    np.testing.assert_allclose(back.ci_high, wv.ci_high, rtol=1e-10)
    assert av.wv_tau_samples.tolist() == wv.tau_samples.tolist()


def test_matches_textbook_formula_at_any_averaging_time(series):
    ms = [1, 2, 3, 5, 8, 13, 21, 100, 377, 1000, 10000]
    av = allan_variance(series, taus=ms)
    ref = [textbook_avar(series, m) for m in ms]
    np.testing.assert_allclose(av.avar, ref, rtol=1e-10)
    assert av.n_terms.tolist() == [series.size - 2 * m + 1 for m in ms]
    np.testing.assert_allclose(av.tau_s, np.array(ms) / 1.0)


def test_offset_costs_no_digits():
    x = np.random.default_rng(2).standard_normal(100_000)
    a = allan_variance(x)
    b = allan_variance(x + 1e9)  # the float64 input itself keeps ~1e-7 of the noise
    np.testing.assert_allclose(b.avar, a.avar, rtol=1e-5)


def test_intervals():
    x = np.random.default_rng(5).standard_normal(4096)
    chi2 = allan_variance(x, alpha=0.1)
    assert np.all(chi2.ci_low < chi2.avar) and np.all(chi2.avar < chi2.ci_high)
    r = allan_variance(x, interval="rel")
    z = 1.959963984540054
    relerr = 1 / np.sqrt(2 * (4096 / r.tau_samples - 1))
    np.testing.assert_allclose(r.adev_high, r.adev * (1 + z * relerr), rtol=1e-12)
    np.testing.assert_allclose(r.adev_low, r.adev * np.maximum(1 - z * relerr, 1e-3), rtol=1e-12)
    assert r.interval == "rel"


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"taus": [0, 2]}, "out of range"),
        ({"taus": [1, 5000]}, "out of range"),
        ({"taus": [1.5]}, "integers"),
        ({"taus": "weekly"}, "octave"),
        ({"interval": "wide"}, "interval"),
        ({"alpha": 1.5}, "alpha"),
        ({"fs": 0.0}, "fs"),
    ],
)
def test_bad_input_messages(kwargs, match):
    with pytest.raises(ValueError, match=match):
        allan_variance(np.arange(8000.0) % 7, **kwargs)


def test_to_dict_and_table_are_ready(series):
    av = allan_variance(series, fs=10.0, unit="deg/s")
    d = json.loads(json.dumps(av.to_dict(), allow_nan=False))
    assert d["adev"][0] == pytest.approx(math.sqrt(d["avar"][0]))
    assert len(d["tau_s"]) == len(av) == eg.wv.default_levels(series.size)
    assert "ADEV [deg/s]" in av.table()


# -------------------------------------------------------------------------------------------
# slope method: the IEEE readings, on exact curves
# -------------------------------------------------------------------------------------------
FS = 100.0


@pytest.mark.parametrize(
    "truth, region, rtol",
    [
        (eg.WN(sigma2=2.5e-3), (0.01, 100.0), 1e-12),
        (eg.QN(q2=3e-4), (0.01, 100.0), 1e-12),
        (eg.DR(omega=4e-7), (0.01, 100.0), 1e-12),
        # exact RW AVAR is gamma2 (m/3 + 1/(6m)): the +1/2 line is exact to 1/(2 m^2)
        (eg.RW(gamma2=1e-8), (0.64, 5000.0), 2e-4),
    ],
)
def test_avsm_reads_the_ieee_coefficients_on_exact_curves(truth, region, rtol):
    model = eg.Model((truth,))
    est = avsm(exact_av(model, FS), {truth.code: region})
    assert est.method == "AVSM"
    assert est.params == pytest.approx(model.values(), rel=rtol)
    # the line's reading is the datasheet coefficient (docs/conventions.md, units)
    ds = {r["symbol"]: r for r in eg.units.datasheet(model, FS)}
    reading = est.details["lines"][truth.code]["reading"]
    key = {"WN": "N", "QN": "Q", "DR": "R", "RW": "K"}[truth.code]
    assert reading["value"] == pytest.approx(ds[key]["value"], rel=rtol)
    # the same symbol and unit spelling as the datasheet (one table: engine.units)
    assert (reading["name"], reading["unit"]) == (key, ds[key]["unit"])
    np.testing.assert_allclose(est.implied, model.wv(est.tau_samples, FS), rtol=rtol * 10)


def test_avsm_bias_instability_floor():
    floor = 4e-6  # AVAR of a flat region
    av = exact_av(eg.parse_model("WN(sigma2=1e-9)"), FS)
    av = AllanVariance(
        tau_samples=av.tau_samples,
        avar=av.avar + floor,
        ci_low=av.ci_low,
        ci_high=av.ci_high,
        n_terms=av.n_terms,
        n=av.n,
        fs=FS,
    )
    est = avsm(av, {"BI": (100.0, 1000.0)})
    assert est.extras["BI.B"] == pytest.approx(math.sqrt(floor) / BI_FACTOR, rel=1e-3)
    assert BI_FACTOR == pytest.approx(0.664, abs=5e-4)
    assert "BI" in est.components and len(est.model) == 0
    assert est.datasheet()[-1]["quantity"] == "bias instability"
    assert est.datasheet()[-1]["symbol"] == "B"


def test_avsm_is_biased_where_the_region_overlaps_another_process():
    # WN + RW crossing at m = sqrt(3 sigma2 / gamma2) = 1732 samples: a WN region that runs up
    # to the crossover reads the sum of both and over-estimates sigma2; GMWM on the same exact
    # curve recovers both.
    truth = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-8)")
    av = exact_av(truth, FS)
    good = avsm(av, {"WN": (0.01, 0.5), "RW": (2000.0, 6000.0)})
    wide = avsm(av, {"WN": (0.01, 41.0), "RW": (20.0, 3000.0)})  # both reach the crossover
    assert rel(good, truth) == pytest.approx([1.0, 1.0], rel=0.01)
    assert rel(wide, truth)[0] > 1.2 and rel(wide, truth)[1] > 1.05
    gm = from_gmwm(eg.fit_gmwm(av.to_wv(), truth.cleared()))
    assert rel(gm, truth) == pytest.approx([1.0, 1.0], rel=1e-6)


def test_avsm_region_errors():
    av = exact_av(eg.parse_model("WN(sigma2=1.0)"), FS, n=4096)
    with pytest.raises(ValueError, match="holds no averaging time"):
        avsm(av, {"WN": (100.0, 200.0)})
    with pytest.raises(ValueError, match="unknown process"):
        avsm(av, {"GM": (0.01, 1.0)})
    with pytest.raises(ValueError, match="at least one region"):
        avsm(av, {})


def test_avsm_auto_reads_at_one_and_three_seconds():
    truth = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-12)")
    est = avsm_auto(exact_av(truth, FS, n=2**26))
    assert est.method == "AVSM-auto"
    assert set(est.params) == {"WN.sigma2", "RW.gamma2"} and "BI.B" in est.extras
    # on an exact curve the points of slope -1/2 and +1/2 are at the two ends
    assert rel(est, truth) == pytest.approx([1.0, 1.0], rel=0.02)
    lines = est.details["lines"]
    assert lines["WN"]["read_tau_s"] == 1.0 and lines["RW"]["read_tau_s"] == 3.0


def test_avsm_auto_reading_the_curve_at_three_seconds_reads_white_noise():
    # the pitfall of reading K off the curve at 3 s: there the white noise still dominates
    truth = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-12)")
    est = avsm_auto(exact_av(truth, FS, n=2**26), read="curve")
    r = rel(est, truth)
    assert r[0] == pytest.approx(1.0, rel=1e-4)
    assert r[1] > 1e3
    with pytest.raises(ValueError, match="read"):
        avsm_auto(exact_av(truth, FS), read="both")


# -------------------------------------------------------------------------------------------
# slope method on pure simulated processes (Monte Carlo tolerances)
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "truth, region_samples, tol",
    [
        (eg.WN(sigma2=4.0), (1, 512), 0.03),
        (eg.QN(q2=1.0), (1, 512), 0.03),
        (eg.RW(gamma2=1e-4), (8, 1024), 0.10),
    ],
)
def test_avsm_recovers_a_pure_process(truth, region_samples, tol):
    reps, n = 16, 2**15
    model = eg.Model((truth,))
    vals = []
    for r in range(reps):
        x = model.simulate(n, fs=FS, rng=np.random.default_rng([21, r]))
        est = avsm(x, {truth.code: (region_samples[0] / FS, region_samples[1] / FS)}, fs=FS)
        vals.append(rel(est, model)[0])
    vals = np.array(vals)
    se = vals.std(ddof=1) / math.sqrt(reps)
    assert abs(vals.mean() - 1.0) < max(3 * se, 0.0) + tol / 3, (vals.mean(), se)
    assert abs(vals.mean() - 1.0) < tol


def test_avsm_recovers_a_pure_drift():
    truth = eg.parse_model("DR(omega=2e-4)")
    x = truth.simulate(50_000, fs=FS)
    est = avsm(x, {"DR": (0.01, 200.0)}, fs=FS)
    assert est.params["DR.omega"] == pytest.approx(2e-4, rel=1e-9)


# -------------------------------------------------------------------------------------------
# GMWFM / ARMAV
# -------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def accel_like() -> tuple[eg.Model, eg.WaveletVariance]:
    truth = eg.parse_model("QN(q2=0.05)+WN(sigma2=1.0)+RW(gamma2=1e-6)+DR(omega=1e-5)")
    return truth, eg.wavelet_variance(truth.simulate(2**17, rng=4))


def test_jensen_the_log_of_an_unbiased_wv_is_biased_low():
    """The mechanism of the ARMAV bias (the GMWM paper, eq. 9): E[log10 nu_hat] < log10 nu."""
    truth = eg.parse_model("WN(sigma2=1.0)")
    reps, n = 300, 1024
    v = np.array(
        [
            eg.wavelet_variance(truth.simulate(n, rng=np.random.default_rng([3, r]))).variance
            for r in range(reps)
        ]
    )
    nu = truth.wv(2.0 ** np.arange(1, v.shape[1] + 1))
    ratio = v[:, -1] / nu[-1]  # the last level: few coefficients (eta3 = 1)
    se = ratio.std(ddof=1) / math.sqrt(reps)
    assert abs(ratio.mean() - 1) < 3.5 * se  # unbiased WV
    lg = np.log10(ratio)
    assert lg.mean() < -0.05 and lg.mean() + 4 * lg.std(ddof=1) / math.sqrt(reps) < 0


def mc(truth: eg.Model, n: int, reps: int, methods: dict, seed: int) -> dict[str, np.ndarray]:
    out: dict[str, list] = {k: [] for k in methods}
    for r in range(reps):
        wv = eg.wavelet_variance(truth.simulate(n, rng=np.random.default_rng([seed, r])))
        for k, fn in methods.items():
            out[k].append(rel(fn(wv), truth))
    return {k: np.array(v) for k, v in out.items()}


@pytest.fixture(scope="module")
def composite_mc() -> dict[str, np.ndarray]:
    """QN hidden under WN (as on the accelerometer of Table I), 4096 samples, 240 replicates."""
    truth = eg.parse_model("QN(q2=0.02)+WN(sigma2=1.0)")
    model = truth.cleared()
    regions = {"QN": (1.0, 2.0), "WN": (4.0, 256.0)}  # the first two points, then the -1/2 part
    return mc(
        truth,
        4096,
        240,
        {
            "GMWM-id": lambda wv: from_gmwm(eg.fit_gmwm(wv, model, weights="identity")),
            "GMWM": lambda wv: from_gmwm(eg.fit_gmwm(wv, model)),
            "ARMAV-id": lambda wv: fit_armav(wv, model, weights="identity").as_estimate(),
            "ARMAV": lambda wv: fit_armav(wv, model).as_estimate(),
            "AVSM": lambda wv: avsm(AllanVariance.from_wv(wv), regions),
        },
        seed=8,
    )


@pytest.mark.slow  # Monte Carlo: 7 s of CPU
def test_armav_is_biased_gmwm_is_not_with_the_same_fixed_weights(composite_mc):
    """The GMWM paper's section III comparison: same non-random Omega, f = x versus log10."""
    g, a = composite_mc["GMWM-id"], composite_mc["ARMAV-id"]
    reps = g.shape[0]
    se_g = g.std(axis=0, ddof=1) / math.sqrt(reps)
    assert np.all(np.abs(g.mean(axis=0) - 1) < 3 * se_g)  # unbiased: QN and WN
    se_a = a.std(axis=0, ddof=1) / math.sqrt(reps)
    assert a.mean(axis=0)[1] < 1 - 3 * se_a[1]  # WN: biased low
    assert a.mean(axis=0)[0] > 1 + 3 * se_a[0]  # QN: biased high


def test_avsm_reads_quantization_off_the_white_noise(composite_mc):
    a = composite_mc["AVSM"]
    # slope -1 forced through points of slope -1/2: Q is read an order of magnitude too high
    assert a[:, 0].mean() > 10 and a[:, 0].min() > 5
    g = composite_mc["GMWM"]
    assert abs(g[:, 0].mean() - 1) < 0.5


def test_gmwm_rmse_beats_the_slope_method_and_the_log_regression(composite_mc):
    def rmse(v):
        return np.sqrt(np.mean((v - 1) ** 2, axis=0))

    g = rmse(composite_mc["GMWM"])
    assert np.all(g < rmse(composite_mc["AVSM"]))
    assert np.all(g < rmse(composite_mc["ARMAV-id"]))
    # the interval-weighted ARMAV has the GMWM's asymptotic weights (F' Omega F is the
    # GMWM's Omega): same RMSE up to its small finite-sample bias
    assert np.all(g < 1.15 * rmse(composite_mc["ARMAV"]))


# -------------------------------------------------------------------------------------------
# the common form
# -------------------------------------------------------------------------------------------
def test_common_form_side_by_side(accel_like):
    truth, wv = accel_like
    g = eg.fit_gmwm(wv, truth.cleared())
    ests = [
        from_gmwm(g),
        fit_armav(wv, truth.cleared()).as_estimate(),
        avsm(wv, {"QN": (1, 2), "WN": (4, 64), "RW": (4096, 16384), "DR": (32768, 1e9)}),
        avsm_auto(wv),
    ]
    for e in ests:
        assert isinstance(e, MethodEstimate)
        np.testing.assert_array_equal(e.tau_samples, wv.tau_samples)
        np.testing.assert_allclose(e.implied, sum(e.components.values()), rtol=1e-12)
        np.testing.assert_allclose(e.implied_at(wv.tau_samples), e.implied, rtol=1e-12)
        np.testing.assert_allclose(e.implied_adev, np.sqrt(2 * e.implied))
        assert set(e.params) <= set(truth.values())
        d = json.loads(json.dumps(e.to_dict(), allow_nan=False))
        assert d["method"] == e.method
        assert e.method in e.summary()
    assert ests[0].params == g.params and ests[0].objective == pytest.approx(g.objective)
    table = compare_table(ests, truth)
    assert "truth" in table and "AVSM-auto" in table and "BI.B" in table
