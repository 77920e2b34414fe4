"""Multivariate: WCCV and the WV/WCCV matrix, multivariate models, MGMWM, replicates.

Formulas (direct convolution), Monte Carlo (intervals, implied WCCV, recovery of known
covariances), optimality (grid of starts, KKT conditions of the PSD-constrained problem),
real data (six ADIS16405 replicates) and errors.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from engine.cli import main as cli_main
from engine.fit import FitError
from engine.models import ModelError
from engine.multivariate import MultiModel, dependence
from engine.multivariate._cone import ConeLSQ
from engine.multivariate.problem import MProblem

RW_BASIS = staticmethod(lambda tau: (tau**2 + 2.0) / (12.0 * tau))


def direct_wccv(x: np.ndarray, y: np.ndarray, levels: int) -> np.ndarray:
    """Brute force: convolve both series with the level-j Haar filter, mean of products."""
    x = np.asarray(x, float) - np.mean(x)
    y = np.asarray(y, float) - np.mean(y)
    out = []
    for j in range(1, levels + 1):
        m = 2 ** (j - 1)
        h = np.concatenate([np.full(m, 1.0), np.full(m, -1.0)]) / 2**j
        out.append(np.mean(np.convolve(x, h, "valid") * np.convolve(y, h, "valid")))
    return np.array(out)


def rw_cov(sd, corr) -> np.ndarray:
    return np.asarray(corr, float) * np.outer(sd, sd)


def shared_rw(channels, sd: float, rho: float) -> MultiModel:
    """WN(sigma2=1) on every channel and a shared RW: standard deviation ``sd`` on each
    channel, correlation ``rho`` between the two."""
    corr = [[1, rho], [rho, 1]]
    return MultiModel(
        channels, "WN(sigma2=1)+RW", shared=["RW"], cov={"RW": rw_cov([sd, sd], corr)}
    )


# -------------------------------------------------------------------------------------------
# WCCV and the WV/WCCV matrix
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [4, 5, 64, 1024, 1025, 5000])
def test_wccv_equals_direct_convolution(n):
    rng = np.random.default_rng(n)
    x = rng.standard_normal(n).cumsum() * 0.1 + rng.standard_normal(n)
    y = 0.5 * x + rng.standard_normal(n) + 3.0
    c = eg.wavelet_cross_covariance(x, y)
    assert c.n_levels == int(np.floor(np.log2(n - 1)))
    np.testing.assert_allclose(c.covariance, direct_wccv(x, y, c.n_levels), rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(c.n_coef, n - 2**c.levels + 1)


def test_wccv_of_a_series_with_itself_is_its_wv():
    x = np.random.default_rng(1).standard_normal(30_000).cumsum() * 0.01 + 5.0
    wv = eg.wavelet_variance(x)
    c = eg.wavelet_cross_covariance(x, x)
    np.testing.assert_allclose(c.covariance, wv.variance, rtol=1e-12, atol=0)
    np.testing.assert_allclose(c.correlation, 1.0, rtol=1e-12)
    # the matrix: diagonal = the WV with the same eta3 intervals, bit for bit up to order
    y = np.random.default_rng(2).standard_normal(x.size)
    m = eg.wv.wv_matrix({"a": x, "b": y, "c": x})
    for name, series in (("a", x), ("b", y)):
        ref = eg.wavelet_variance(series)
        got = m.wv(name)
        np.testing.assert_allclose(got.variance, ref.variance, rtol=1e-12)
        np.testing.assert_allclose(got.ci_low, ref.ci_low, rtol=1e-12)
        np.testing.assert_allclose(got.ci_high, ref.ci_high, rtol=1e-12)
    np.testing.assert_allclose(m.values[:, 0, 2], m.values[:, 0, 0], rtol=1e-12)


def test_wccv_units_are_spelled_like_the_wv_units():
    """One spelling of a squared unit; the WCCV of two channels in g is g^2, like
    their WV (the pair used to build "(g)^2" by hand)."""
    rng = np.random.default_rng(4)
    xy = rng.standard_normal((4096, 2))
    m = eg.wv.wv_matrix(xy, channels=["a", "b"], units=["g", "g"])
    assert m.pair("a", "b").unit == "g^2" == m.wv("a").unit + "^2"
    m2 = eg.wv.wv_matrix(xy, channels=["a", "b"], units=["deg/s", "deg/s"])
    assert m2.pair("a", "b").unit == "(deg/s)^2"
    m3 = eg.wv.wv_matrix(xy, channels=["a", "b"], units=["g", "m/s^2"])
    assert m3.pair("a", "b").unit == "g*m/s^2"


def test_wv_matrix_is_symmetric_bilinear_and_consistent_with_pairs():
    rng = np.random.default_rng(3)
    x, z = rng.standard_normal((2, 4096))
    y = x + rng.standard_normal(4096)
    m = eg.wv.wv_matrix(np.column_stack([x, y, z]), channels=["x", "y", "z"], fs=10.0)
    assert m.channels == ("x", "y", "z") and m.k == 3 and m.fs == 10.0
    np.testing.assert_array_equal(m.values, np.transpose(m.values, (0, 2, 1)))
    pair = eg.wavelet_cross_covariance(x, y, fs=10.0)
    np.testing.assert_allclose(m.pair("x", "y").covariance, pair.covariance, rtol=1e-12)
    np.testing.assert_allclose(m.pair("y", "x").ci_low, pair.ci_low, rtol=1e-10)
    lin = eg.wavelet_cross_covariance(2 * x - 3 * z, y).covariance
    np.testing.assert_allclose(
        lin, 2 * m.values[:, 0, 1] - 3 * m.values[:, 2, 1], rtol=1e-9, atol=1e-15
    )
    sub = m.select(["z", "x"])
    np.testing.assert_array_equal(sub.values[:, 1, 0], m.values[:, 0, 2])
    assert m.truncate(4).n_levels == 4
    json.dumps(m.to_dict(), allow_nan=False)
    assert "r x/y" in m.table()


def test_wccv_of_independent_channels_is_zero_within_its_interval():
    """Coverage of the interval over replicates near nominal; estimates centred on 0."""
    rng = np.random.default_rng(11)
    n, reps = 2**13, 150
    hits, vals, ses = [], [], []
    for _ in range(reps):
        e = rng.standard_normal((n, 2))
        x = rng.standard_normal((n, 2)) + np.cumsum(e * 0.03, axis=0)  # WN + RW, independent
        m = eg.wv.wv_matrix(x)
        lw = np.array([c == "lag-window" for c in m.ci_method])
        hits.append(((m.ci_low[:, 0, 1] <= 0) & (0 <= m.ci_high[:, 0, 1]))[lw])
        vals.append(m.values[lw, 0, 1])
        ses.append(m.std_error[lw, 0, 1])
    hits, vals, ses = np.array(hits), np.array(vals), np.array(ses)
    assert hits.shape[1] >= 6
    cover = hits.mean(axis=0)
    assert np.all(cover > 0.88), cover
    assert 0.925 < cover.mean() < 0.975, cover
    # the standard error estimates the spread of the estimates (within 15 %)
    ratio = vals.std(axis=0) / ses.mean(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    # centred: |mean| below 4 Monte Carlo standard errors at every level
    assert np.all(np.abs(vals.mean(axis=0)) < 4 * vals.std(axis=0) / np.sqrt(reps))


def test_gaussian_edf_intervals_at_the_top_levels_are_wide_enough():
    m = eg.wv.wv_matrix(np.random.default_rng(4).standard_normal((3000, 2)))
    top = [i for i, c in enumerate(m.ci_method) if c == "gaussian-edf"]
    assert top and top[-1] == m.n_levels - 1 and m.bandwidth[top[0]] == 0
    assert np.all(m.ci_high[top, 0, 1] - m.ci_low[top, 0, 1] > 0)
    assert np.all(m.df[top] >= 1)


# -------------------------------------------------------------------------------------------
# multivariate models: implied WCCV and simulation
# -------------------------------------------------------------------------------------------
def shared_truth() -> MultiModel:
    """Two channels sharing WN, RW and a GM (common beta), each with its own QN."""
    return MultiModel(
        ["a", "b"],
        {"a": "GM(beta=2.0)+QN(q2=0.02)+WN+RW", "b": "GM(beta=2.0)+QN(q2=0.05)+WN+RW"},
        shared=["WN", "RW", "GM"],
        cov={
            "WN": [[1.0, 0.4], [0.4, 2.0]],
            "RW": rw_cov([0.02, 0.03], [[1, -0.6], [-0.6, 1]]),
            "GM": [[0.5, 0.3], [0.3, 0.4]],
        },
    )


def test_implied_wv_and_wccv_of_shared_processes_against_monte_carlo():
    mm = shared_truth()
    assert mm.is_set and mm.shared_process("GM").nl == 2.0
    fs, n, reps = 10.0, 2**12, 200
    levels = 9
    sims = []
    for r in range(reps):
        x = mm.simulate(n, fs=fs, rng=r)
        sims.append(eg.wv.wv_matrix(x, channels=["a", "b"], fs=fs, levels=levels, ci=False).values)
    sims = np.array(sims)
    tau = 2.0 ** np.arange(1, levels + 1)
    implied = mm.implied(tau, fs)
    mean, se = sims.mean(axis=0), sims.std(axis=0) / np.sqrt(reps)
    z = (mean - implied) / se
    assert np.all(np.abs(z) < 4.5), z
    # marginal models: the diagonal is the univariate WV of the channel's marginal model
    for p, c in enumerate(mm.channels):
        np.testing.assert_allclose(implied[:, p, p], mm.channel_model(c).wv(tau, fs), rtol=1e-12)
    # components add up; an off-diagonal comes from shared processes only
    comps = mm.components(tau, fs)
    assert set(comps) == {"WN", "RW", "GM", "a:QN", "b:QN"}
    np.testing.assert_allclose(sum(comps.values()), implied, rtol=1e-12)
    assert np.all(comps["a:QN"][:, 0, 1] == 0)


def test_simulated_shared_processes_have_the_given_covariances():
    cov = np.array([[2.0, -0.8, 0.3], [-0.8, 1.0, 0.2], [0.3, 0.2, 0.5]])
    g = np.random.default_rng(0)
    for code, spec in (("WN", "WN"), ("RW", "RW"), ("GM", "GM(beta=5.0)"), ("AR1", "AR1(0.7)")):
        mm = MultiModel(["x", "y", "z"], spec, shared=[code], cov={code: cov})
        x = mm.simulate(200_000, fs=10.0, rng=g)
        if code == "RW":
            x = np.diff(x, axis=0)
        emp = np.cov(x, rowvar=False)
        target = cov / (1 - 0.7**2) if code == "AR1" else cov
        np.testing.assert_allclose(emp, target, atol=0.05 * np.max(np.abs(target)))


# -------------------------------------------------------------------------------------------
# MGMWM
# -------------------------------------------------------------------------------------------
SD = np.array([1.0, 1.4, 1.2]) * 1e-2
CORR = np.array([[1.0, 0.6, 0.3], [0.6, 1.0, 0.5], [0.3, 0.5, 1.0]])


def three_gyros() -> MultiModel:
    return MultiModel(
        ["g1", "g2", "g3"],
        {"g1": "WN(sigma2=1.0)+RW", "g2": "WN(sigma2=1.5)+RW", "g3": "WN(sigma2=2.0)+RW"},
        shared=["RW"],
        cov={"RW": rw_cov(SD, CORR)},
    )


def test_mgmwm_recovers_a_known_rw_covariance_matrix():
    """The paper's section V setting: Monte Carlo mean within 4 standard errors of the truth,
    and every replicate within 40 % (covariances) / 2 % (WN variances)."""
    truth = three_gyros()
    cov = rw_cov(SD, CORR)
    est, wn = [], []
    for r in range(12):
        x = truth.simulate(2**17, rng=100 + r)
        res = eg.fit_mgmwm(x, truth.cleared())
        assert res.method == "closed-form" and res.converged
        est.append(res.covariance("RW"))
        wn.append([res.params[f"{c}.WN.sigma2"] for c in truth.channels])
    est, wn = np.array(est), np.array(wn)
    z = (est.mean(axis=0) - cov) / (est.std(axis=0) / np.sqrt(len(est)))
    assert np.all(np.abs(z) < 4), z
    assert np.all(np.abs(est - cov) < 0.4 * np.abs(cov) + 5e-6)
    assert np.all(np.abs(wn / [1.0, 1.5, 2.0] - 1) < 0.02)
    rho = res.correlation("RW")
    assert np.allclose(np.diagonal(rho), 1.0) and np.all(np.abs(rho - CORR) < 0.3)


def test_mgmwm_with_a_shared_gm_recovers_beta_and_covariance():
    truth = MultiModel(
        ["a", "b"],
        {
            "a": "GM(beta=0.05, sigma2_gm=2e-3)+WN(sigma2=1e-2)",
            "b": "GM+GM(beta=2, sigma2_gm=5e-3)+WN(sigma2=2e-2)",
        },
        shared={"GM_1": None},
        cov={"GM_1": [[2e-3, 1.5e-3], [1.5e-3, 3e-3]]},
        nl={"GM_1": 0.05},
    )
    x = truth.simulate(200_000, fs=10.0, rng=3)
    res = eg.fit_mgmwm(x, truth.cleared(), fs=10.0)
    assert res.converged and not res.at_bound
    gm = res.shared["GM_1"]
    assert gm.nl_name == "beta" and abs(gm.nl / 0.05 - 1) < 0.3
    np.testing.assert_allclose(gm.cov, [[2e-3, 1.5e-3], [1.5e-3, 3e-3]], rtol=0.3)
    assert abs(res.params["b.GM_2.beta"] / 2 - 1) < 0.2
    # the marginal models carry the shared values (what the app's diagonal panels draw)
    ma = res.channel_models["a"]
    assert ma.processes[0].beta == pytest.approx(gm.nl) and ma.processes[
        0
    ].sigma2_gm == pytest.approx(gm.cov[0, 0])
    np.testing.assert_allclose(res.implied, res.model.implied(res.wvm.tau_samples, 10.0))
    text = res.summary()
    assert "shared GM_1" in text and "correlation" in text
    json.dumps(res.to_dict(), allow_nan=False)
    # deterministic
    again = eg.fit_mgmwm(res.wvm, truth.cleared())
    assert again.objective == res.objective and again.params == res.params


def test_mgmwm_reaches_the_minimum_over_the_shared_beta():
    """The profiled objective over a fine grid of the shared beta (the channel's own GM
    re-optimised by the fit itself at each value) is never below the fit's objective."""
    truth = MultiModel(
        ["a", "b"],
        "GM(beta=0.5, sigma2_gm=1e-2)+WN(sigma2=1e-1)+RW(gamma2=1e-7)",
        shared=["GM"],
        cov={"GM": [[1e-2, 4e-3], [4e-3, 1e-2]]},
        nl={"GM": 0.5},
    )
    x = truth.simulate(50_000, fs=5.0, rng=8)
    wvm = eg.wv.wv_matrix(x, channels=["a", "b"], fs=5.0)
    res = eg.fit_mgmwm(wvm, truth.cleared())
    for beta in np.geomspace(0.01, 20, 60):
        fixed = MultiModel(["a", "b"], "GM+WN+RW", shared=["GM"], nl={"GM": float(beta)})
        prob = MProblem(fixed.cleared(), wvm, res.moment_weights)
        u = np.array([prob.u_of(prob.slots[0], float(np.exp(-beta / 5.0)), np.nan)])
        assert prob.profile(u) >= res.objective * (1 - 1e-9)


def kkt(res: eg.multivariate.MGMWMResult, label: str) -> tuple[float, float, float]:
    """(min eigenvalue of the gradient G, <G, Sigma>, scale) for a shared RW with diagonal
    weights: first-order optimality of min f(Sigma) s.t. Sigma PSD is G PSD, G Sigma = 0."""
    w, r = res.moment_weights, res.wvm.values - res.implied
    b = RW_BASIS(res.wvm.tau_samples.astype(float))
    k = res.wvm.k
    g = np.empty((k, k))
    for p in range(k):
        for q in range(k):
            d = -2.0 * np.sum(w[:, p, q] * r[:, p, q] * b)  # df/dSigma_pq (upper triangle)
            g[p, q] = d if p == q else 0.5 * d
    cov = res.covariance(label)
    scale = float(np.max(np.abs(g)))
    return float(np.linalg.eigvalsh(g)[0]), float(np.sum(g * cov)), scale


def test_psd_constraint_active_gives_a_psd_optimum():
    """Near-perfectly correlated drifts: the per-pair solution is not PSD; the constrained
    optimum satisfies the KKT conditions, and beats the projected per-pair solution."""
    truth = MultiModel(
        ["a", "b", "c"],
        "WN(sigma2=1)+RW",
        shared=["RW"],
        cov={"RW": rw_cov([1e-2] * 3, [[1, 0.999, 0.99], [0.999, 1, 0.995], [0.99, 0.995, 1]])},
    )
    wvm = eg.wv.wv_matrix(truth.simulate(20_000, rng=1), channels=["a", "b", "c"])
    res = eg.fit_mgmwm(wvm, truth.cleared())
    assert res.psd_active and "RW.cov (singular)" in res.at_bound
    cov = res.covariance("RW")
    assert np.linalg.eigvalsh(cov)[0] >= -1e-12 * np.max(cov)
    lam_min, inner, scale = kkt(res, "RW")
    assert lam_min >= -1e-6 * scale and abs(inner) <= 1e-6 * scale * np.trace(cov)
    # better than any point of a crude search around it (random PSD perturbations)
    rng = np.random.default_rng(0)
    iu = np.triu_indices(3)
    for _ in range(50):
        a = rng.standard_normal((3, 3)) * 1e-2 * np.sqrt(np.max(cov))
        trial = cov + a @ a.T - np.eye(3) * 1e-2 * np.max(cov) * rng.uniform()
        lam, vec = np.linalg.eigh(trial)
        trial = (vec * np.clip(lam, 0, None)) @ vec.T
        comps = dict(res.components)
        comps["RW"] = RW_BASIS(res.wvm.tau_samples.astype(float))[:, None, None] * trial
        imp = sum(comps.values())
        f = np.sum(
            res.moment_weights[:, iu[0], iu[1]] * (res.wvm.values - imp)[:, iu[0], iu[1]] ** 2
        )
        assert f >= res.objective * (1 - 1e-9)


def boundary_case(name: str) -> tuple[eg.wv.WVMatrix, MultiModel]:
    """Shared processes absent from the data (covariance 0 at the optimum) or perfectly
    correlated (rank 1): the PSD constraint is active at almost every evaluation."""
    rng = np.random.default_rng(0)
    if name == "identical":
        x = rng.standard_normal(4096)
        data, chans, shared = {"a": x, "b": x.copy()}, ["a", "b"], ["RW"]
    else:
        k = 3 if name == "3 channels RW" else 2
        x = rng.standard_normal((4096, k))
        chans = ["u", "w", "z"][:k]
        data = {c: x[:, i] for i, c in enumerate(chans)}
        shared = ["WN", "RW"] if name == "WN and RW" else ["RW"]
    wvm = eg.wv.wv_matrix(data, channels=chans, fs=100.0)
    return wvm, MultiModel(chans, "GM+WN+RW", shared=shared)


def shared_kkt(res: eg.multivariate.MGMWMResult, label: str, basis) -> tuple[float, float, float]:
    """As :func:`kkt`, for any shared linear process with WV shape ``basis(tau)``; the scale
    is the Cauchy-Schwarz bound of the gradient's entries (G may be 0 up to rounding)."""
    w, r = res.moment_weights, res.wvm.values - res.implied
    b = basis(res.wvm.tau_samples.astype(float))
    g = np.array(
        [
            [
                -2.0 * np.sum(w[:, p, q] * r[:, p, q] * b) * (1.0 if p == q else 0.5)
                for q in range(res.wvm.k)
            ]
            for p in range(res.wvm.k)
        ]
    )
    bound = 2.0 * np.sqrt(res.objective * np.max(np.sum(w * b[:, None, None] ** 2, axis=0)))
    return (
        float(np.linalg.eigvalsh(g)[0]),
        float(np.sum(g * res.covariance(label))),
        float(max(np.max(np.abs(g)), bound)),
    )


@pytest.mark.parametrize(
    "name,weights",
    [
        ("report", "ci"),
        ("report", "efficient"),
        ("WN and RW", "ci"),
        ("3 channels RW", "ci"),
        ("identical", "ci"),
    ],
)
def test_boundary_covariances_fit_within_budget_and_reach_the_minimum(name, weights):
    """Regression: two independent N(0, 1) channels with a shared RW took ~120 s (the
    square-factor inner solve crept to the singular minimiser, up to 500 least-squares
    evaluations per profile evaluation). Now a few Newton steps per evaluation, and the
    fit is no worse than the nested independent model, a multi-start search of the
    profile, and satisfies the KKT conditions of the PSD constraint."""
    wvm, mm = boundary_case(name)
    res = eg.fit_mgmwm(wvm, mm, weights=weights)
    assert res.converged
    assert res.n_evaluations <= 4000 and res.n_inner <= 15 * res.n_evaluations, (
        res.n_evaluations,
        res.n_inner,
    )
    if weights == "efficient":
        return
    # nested: the independent model is the shared one with diagonal covariances
    indep = eg.fit_mgmwm(wvm, MultiModel(mm.channels, "GM+WN+RW"))
    assert res.objective <= indep.objective * (1 + 1e-12)
    # first-order optimality of the shared covariances (independent of the solver)
    bases = {"RW": RW_BASIS, "WN": staticmethod(lambda tau: 1.0 / tau)}
    for sp in mm.shared:
        lam_min, inner, scale = shared_kkt(res, sp.label, bases[sp.label])
        cov = res.covariance(sp.label)
        assert lam_min >= -1e-6 * scale
        assert abs(inner) <= 1e-6 * scale * max(np.trace(cov), 1e-300)
    # multi-start reference over the GM correlation times (profile on a grid, then
    # Nelder-Mead from the three best points), on a fresh problem
    from scipy import optimize

    prob = MProblem(mm.cleared(), wvm, res.moment_weights)
    axis = np.linspace(np.log(0.5), np.log(2.0 * prob.tau[-1]), 6)
    grid = [
        np.array(u)
        for u in np.array(np.meshgrid(*[axis] * len(prob.slots))).reshape(len(prob.slots), -1).T
    ]
    starts = sorted(grid, key=prob.profile)[:3]
    ref = min(
        optimize.minimize(
            prob.profile,
            u0,
            method="Nelder-Mead",
            options={"xatol": 1e-8, "fatol": 1e-14, "maxfev": 3000},
        ).fun
        for u0 in starts
    )
    assert res.objective <= ref * (1 + 1e-9), (res.objective, ref)


@pytest.mark.parametrize("seed", range(8))
def test_bounded_least_squares_of_the_full_weighting_meets_its_kkt_conditions(seed):
    """The relaxation with a full weighting matrix (bounds 0 on variances, none on
    cross-covariances) by elimination of the free coefficients + NNLS: the KKT conditions
    hold and the objective equals SciPy's BVLS to rounding."""
    from scipy import optimize

    rng = np.random.default_rng(seed)
    m, n = 40, 7
    a = rng.standard_normal((m, n)) * np.geomspace(1e-3, 1e3, n)  # badly scaled columns
    b = a @ rng.standard_normal(n) + 0.1 * rng.standard_normal(m)
    lower = np.where(rng.uniform(size=n) < 0.5, 0.0, -np.inf)
    lower[0] = 0.0
    cone = ConeLSQ(b, [(i, 0, 0, 0) for i in range(n)], {}, lower, None)
    c = cone._relaxed_full(a, lower)
    assert np.all(c[lower == 0] >= 0)
    grad = a.T @ (a @ c - b) / np.linalg.norm(a, axis=0)  # scale-free gradient
    tol = 1e-9 * np.linalg.norm(b)
    free = np.isinf(lower)
    assert np.all(np.abs(grad[free]) <= tol)
    assert np.all(grad[~free] >= -tol) and np.all(np.abs(grad[~free][c[~free] > 0]) <= tol)
    norms = np.linalg.norm(a, axis=0)
    ref = optimize.lsq_linear(a / norms, b, bounds=(lower, np.inf), method="bvls", tol=1e-14)
    f, f_ref = np.sum((b - a @ c) ** 2), np.sum((b - a @ (ref.x / norms)) ** 2)
    assert f <= f_ref * (1 + 1e-12)
    assert f == pytest.approx(f_ref, rel=1e-12)


def test_psd_inner_solve_fallback_agrees_with_the_certified_path(monkeypatch):
    """Without any certificate the inner solve ends on the interior-point path (and its
    face): the same objective as the certified candidates, to rounding."""
    wvm, mm = boundary_case("3 channels RW")
    res = eg.fit_mgmwm(wvm, mm)
    prob = MProblem(mm.cleared(), wvm, res.moment_weights)
    phis = [float(np.exp(-res.params[f"{c}.GM.beta"] / wvm.fs)) for c in mm.channels]
    u = np.array([prob.u_of(ti, phi, np.nan) for ti, phi in zip(prob.slots, phis, strict=True)])
    f, _, s, coupled = prob.solve(u)
    assert coupled and f == pytest.approx(res.objective, rel=1e-12)
    monkeypatch.setattr(ConeLSQ, "_uncertified", lambda self, *a, **k: {-1})
    slow = MProblem(mm.cleared(), wvm, res.moment_weights)
    f2, _, s2, _ = slow.solve(u)
    assert f2 == pytest.approx(f, rel=1e-10)
    ti = slow.full[0]
    assert np.linalg.eigvalsh(s2[ti])[0] >= -1e-12 * np.max(np.abs(s2[ti]))


def test_without_shared_processes_mgmwm_is_the_univariate_fits():
    x = three_gyros().simulate(2**15, rng=5)
    m = eg.wv.wv_matrix(x, channels=["g1", "g2", "g3"])
    res = eg.fit_mgmwm(m, MultiModel(m.channels, "GM+WN+RW"))
    for c in m.channels:
        uni = eg.fit_gmwm(m.wv(c), "GM+WN+RW")
        for name, v in uni.params.items():
            assert res.params[f"{c}.{name}"] == pytest.approx(v, rel=1e-4, abs=1e-12), name
    # with the RW shared and a PSD solution, the variances are still the univariate ones
    shared = eg.fit_mgmwm(m, MultiModel(m.channels, "WN+RW", shared=["RW"]))
    assert not shared.psd_active
    for p, c in enumerate(m.channels):
        uni = eg.fit_gmwm(m.wv(c), "WN+RW")
        assert shared.covariance("RW")[p, p] == pytest.approx(uni.params["RW.gamma2"], rel=1e-9)


def test_mgmwm_result_has_the_fit_result_interface():
    """One result base: scheme name in ``weights``, the stacked weighting matrix in
    ``omega`` (its diagonal the 1 / (ci width)^2 of every moment), labelled records whose
    unique names are the keys of ``params``, a Summary with an HTML view, to_dict."""
    from engine.fit.result import FitResult, ParamRecord, Summary

    x = three_gyros().simulate(2**13, rng=6)
    m = eg.wv.wv_matrix(x, channels=["g1", "g2", "g3"], levels=9)
    res = eg.fit_mgmwm(m, MultiModel(m.channels, "WN+RW", shared=["RW"]))
    assert isinstance(res, FitResult) and res.weights == "ci"
    assert res.omega.shape == (6 * 9, 6 * 9)
    assert np.count_nonzero(res.omega - np.diag(np.diagonal(res.omega))) == 0
    np.testing.assert_array_equal(res.moment_weights, 1.0 / (m.ci_high - m.ci_low) ** 2)
    recs = res.param_records
    assert all(isinstance(r, ParamRecord) for r in recs)
    assert [r.full_name for r in recs] == list(res.params)
    assert res.params["RW.cov[g1,g2]"] == res.covariance("RW")[0, 1]
    assert res.params["g2.WN.sigma2"] == res.model.models["g2"].processes[0].sigma2
    text = res.summary()
    assert isinstance(text, Summary) and "shared RW (RW) over g1, g2, g3" in text
    assert res._repr_html_().startswith("<pre>") and str(res) == str(text)
    d = json.loads(json.dumps(res.to_dict()))
    assert d["weights"] == "ci" and d["kind"] == "mgmwm" and d["fs"] == 1.0
    assert {p["full_name"]: p["value"] for p in d["params"]} == res.params
    cov_ab = next(p for p in d["params"] if p["full_name"] == "RW.cov[g1,g3]")
    assert cov_ab["channels"] == ["g1", "g3"] and cov_ab["shared"] and cov_ab["label"] == "RW"
    t = eg.multivariate.DependenceTest(0.5, 0.04, 2.0, 1.5, ("RW",), 99)
    assert isinstance(t.summary(), Summary) and str(t) == (
        "test of dependence (RW shared vs independent): D = 0.5, p = 0.04 "
        "(parametric bootstrap, B = 99)"
    )


def test_mgmwm_intervals_without_shared_processes_are_the_univariate_ones():
    """With diagonal weights and independent channels the sandwich separates by channel (the
    model-implied covariance of two channels' WVs is 0): each channel's intervals are those
    of its univariate fit, whatever the model (GM, AR1, RW)."""
    truth = MultiModel(
        ["a", "b", "c"],
        {
            "a": "GM(beta=0.3, sigma2_gm=1e-2)+WN(sigma2=1e-1)+RW(gamma2=1e-6)",
            "b": "WN(sigma2=2)+RW(gamma2=1e-5)",
            "c": "AR1(phi=0.99, sigma2=1e-3)+WN(sigma2=1)",
        },
    )
    x = truth.simulate(2**15, fs=10.0, rng=4)
    res = eg.fit_mgmwm(x, truth.cleared(), fs=10.0)
    table = res.conf_int(0.1)
    assert table.level == 0.9 and table.names == tuple(res.params)
    for p, c in enumerate(res.channels):
        uni = eg.fit_gmwm(res.wvm.wv(p), truth.models[c].cleared()).conf_int(0.1)
        for name in uni.names:
            e, lo, hi = uni.row(name)
            assert table.row(f"{c}.{name}") == pytest.approx((e, lo, hi), rel=1e-10)
            assert lo < e < hi


def test_mgmwm_intervals_of_a_shared_covariance_cover_the_truth():
    """Monte Carlo: 95 % intervals of a shared RW covariance and a WN variance cover the
    truth in about 95 % of 60 replicates (at least 85 %: 4 binomial SE), and entries on a
    boundary get nan bounds."""
    truth = MultiModel(
        ["a", "b"],
        {"a": "WN(sigma2=1)+RW", "b": "WN(sigma2=2)+RW"},
        shared=["RW"],
        cov={"RW": [[1e-4, 6e-5], [6e-5, 2e-4]]},
    )
    values = {"RW.cov[a,b]": 6e-5, "RW.cov[a,a]": 1e-4, "b.WN.sigma2": 2.0}
    hits = dict.fromkeys(values, 0)
    for r in range(60):
        res = eg.fit_mgmwm(truth.simulate(2**14, rng=1000 + r), truth.cleared())
        table = res.conf_int()
        for name, v in values.items():
            _, lo, hi = table.row(name)
            hits[name] += lo <= v <= hi
    assert all(h >= 51 for h in hits.values()), hits
    wvm, mm = boundary_case("identical")  # rank-1 RW covariance: on the cone's boundary
    res = eg.fit_mgmwm(wvm, mm)
    table = res.conf_int()
    assert "RW.cov (singular)" in res.at_bound
    assert np.all(np.isnan(table.lower[[n.startswith("RW.cov") for n in table.names]]))


def test_efficient_weights_and_the_moment_covariance():
    mm = three_gyros()
    x = mm.simulate(2**13, rng=2)
    m = eg.wv.wv_matrix(x, channels=list(mm.channels), levels=8)
    v = eg.multivariate.moment_covariance(mm, m)
    assert v.shape == (6 * 8, 6 * 8) and np.allclose(v, v.T)
    assert np.linalg.eigvalsh(v)[0] > 0
    # the WV block is the univariate model covariance of the channel
    from engine.fit.asymptotic import wv_cov_model

    np.testing.assert_allclose(v[:8, :8], wv_cov_model(mm.channel_model("g1"), m.wv(0)), rtol=1e-9)
    # Monte Carlo check of one WCCV variance and its covariance with a WV
    sims = np.array(
        [
            eg.wv.wv_matrix(mm.simulate(2**13, rng=50 + r), levels=8, ci=False).values
            for r in range(150)
        ]
    )
    emp = np.var(sims[:, 5, 0, 1], ddof=1)
    assert emp / v[8 + 5, 8 + 5] == pytest.approx(1.0, abs=0.3)
    res = eg.fit_mgmwm(m, mm.cleared(), weights="efficient")
    assert res.weights == "efficient" and res.omega.shape == (6 * m.n_levels,) * 2
    assert np.all(np.isfinite(res.covariance("RW")))


def test_dependence_test_detects_shared_drift_and_not_independent_channels():
    kw = dict(B=19, seed=1)
    dep = shared_rw(["a", "b"], 1e-2, 0.8)
    ind = shared_rw(["a", "b"], 1e-2, 0)
    t_dep = eg.multivariate.dependence_test(dep.simulate(2**13, rng=1), dep.cleared(), **kw)
    t_ind = eg.multivariate.dependence_test(ind.simulate(2**13, rng=2), ind.cleared(), **kw)
    assert t_dep.p_value == pytest.approx(1 / 20) and t_dep.statistic > 0
    assert t_ind.p_value > 0.1
    assert t_dep.labels == ("RW",) and t_dep.B == 19
    d = json.loads(json.dumps(t_dep.to_dict()))  # every field but the bootstrap values
    assert list(d) == "statistic p_value objective_independent objective_shared labels B".split()
    assert d["labels"] == ["RW"] and d["B"] == 19 and d["p_value"] == t_dep.p_value
    assert d["statistic"] == t_dep.statistic == d["objective_independent"] - d["objective_shared"]
    # the null model: WN/RW independent per channel, a shared GM keeps its common beta
    h0 = shared_truth().without_dependence(["GM", "RW"])
    assert [s.label for s in h0.shared] == ["WN", "GM"] and h0.shared[1].diagonal
    assert not h0.shared[0].diagonal and h0.spec().endswith("shared: WN, GM (diagonal)")
    with pytest.raises(ModelError, match="QN is not shared"):
        shared_truth().without_dependence(["QN"])


def test_dependence_test_reports_progress_and_can_be_aborted():
    dep = shared_rw(["a", "b"], 1e-2, 0.5)
    x = dep.simulate(2**11, rng=4)
    plain = eg.multivariate.dependence_test(x, dep.cleared(), B=5, seed=3)
    calls = []
    seen = eg.multivariate.dependence_test(
        x, dep.cleared(), B=5, seed=3, progress=lambda done, total: calls.append((done, total))
    )
    assert calls == [(i, 5) for i in range(1, 6)]
    assert seen == plain  # identical results (frozen dataclass equality, bootstrap included)

    class Cancelled(Exception):
        pass

    def cancel(done: int, total: int) -> None:
        calls.append((done, total))
        if done == 2:
            raise Cancelled

    calls.clear()
    with pytest.raises(Cancelled):
        eg.multivariate.dependence_test(x, dep.cleared(), B=5, seed=3, progress=cancel)
    assert calls == [(1, 5), (2, 5)]
    # the app's one-replicate-at-a-time call keeps working, with the same numbers
    wvm = eg.wv.wv_matrix(x, channels=["a", "b"])
    h1 = dep.cleared()
    h0 = h1.without_dependence().cleared()
    fit0 = eg.fit_mgmwm(wvm, h0)
    sd = np.random.SeedSequence(3).spawn(5)[0]
    d = dependence._boot_dependence((fit0.model, h0, h1, wvm.n, wvm.fs, wvm.n_levels, "ci", sd))
    assert d == plain.bootstrap[0]


# -------------------------------------------------------------------------------------------
# replicates
# -------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def adis_wvs(real_data: Path) -> list[eg.WaveletVariance]:
    out = []
    for k in range(1, 7):
        log = eg.load_log(real_data / f"adis16405_imu{k}.h5", channel="gyro_x")
        out.append(eg.wavelet_variance(log["gyro_x"], fs=log.fs, unit="deg/s"))
    return out


def test_replicate_fit_of_the_six_adis_logs_lies_between_the_individual_fits(adis_wvs):
    spec = "2*GM+WN+RW"
    joint = eg.fit.fit_replicates(adis_wvs, spec)
    singles = [eg.fit_gmwm(w, spec) for w in adis_wvs]
    assert joint.converged and len(joint.objectives) == 6
    assert joint.objective == pytest.approx(sum(joint.objectives))
    for name in ("GM_1.beta", "GM_1.sigma2_gm", "GM_2.beta", "GM_2.sigma2_gm", "RW.gamma2"):
        vals = [f.params[name] for f in singles]
        assert min(vals) <= joint.params[name] <= max(vals), (name, joint.params[name], vals)
    assert 30 < 1 / joint.params["GM_1.beta"] < 300  # the slow GM of about 100 s
    # no replicate's own estimate does better on the summed objective
    # omega is block diagonal over the stacked levels: each replicate's diagonal weights
    split = np.cumsum([wv.n_levels for wv in adis_wvs])[:-1]
    ws = np.split(np.diagonal(joint.omega), split)
    assert joint.weights == "ci" and joint.omega.shape == (split[-1] + adis_wvs[-1].n_levels,) * 2
    for f in singles:
        total = sum(
            float(np.sum(w * (wv.variance - f.model.wv(wv.tau_samples, wv.fs)) ** 2))
            for wv, w in zip(adis_wvs, ws, strict=True)
        )
        assert total >= joint.objective * (1 - 1e-9)
    assert "6 recordings" in joint.summary()
    json.dumps(joint.to_dict(), allow_nan=False)


def test_replicates_of_one_series_give_its_fit_and_accept_raw_series():
    x = eg.parse_model("GM(beta=1, sigma2_gm=1e-2)+WN(sigma2=1e-1)").simulate(
        20_000, fs=10.0, rng=4
    )
    wv = eg.wavelet_variance(x, fs=10.0)
    one = eg.fit_gmwm(wv, "GM+WN")
    both = eg.fit.fit_replicates([wv, wv], "GM+WN")
    for name, v in one.params.items():
        assert both.params[name] == pytest.approx(v, rel=1e-4)
    raw = eg.fit.fit_replicates([x, x[:15_000]], "GM+WN", fs=10.0)
    assert [w.n for w in raw.wvs] == [20_000, 15_000] and raw.fs == 10.0


# -------------------------------------------------------------------------------------------
# errors
# -------------------------------------------------------------------------------------------
def test_bad_inputs_give_clear_errors():
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal(1000), rng.standard_normal(999)
    with pytest.raises(ValueError, match=r"different lengths \(1000 and 999"):
        eg.wavelet_cross_covariance(x, y)
    with pytest.raises(ValueError, match="a: 1000, b: 999"):
        eg.wv.wv_matrix({"a": x, "b": y})
    with pytest.raises(ValueError, match="at least 2 channels, got 1"):
        eg.wv.wv_matrix({"a": x, "b": x}, channels=["a"])
    with pytest.raises(KeyError, match="unknown channel 'c'; the channels are a, b"):
        eg.wv.wv_matrix({"a": x, "b": x}, channels=["a", "c"])
    with pytest.raises(ValueError, match="channel 'b'.*NaN"):
        eg.wv.wv_matrix({"a": x, "b": np.where(np.arange(1000) == 5, np.nan, x)})
    with pytest.raises(ModelError, match="at least 2 channels"):
        MultiModel(["a"], "WN+RW")
    with pytest.raises(ModelError, match="not positive definite.*smallest eigenvalue"):
        MultiModel(["a", "b"], "WN+RW", shared=["RW"], cov={"RW": [[1, 2], [2, 1]]})
    with pytest.raises(ModelError, match="variance of b is -1"):
        MultiModel(["a", "b"], "WN+RW", shared=["RW"], cov={"RW": [[1, 0], [0, -1]]})
    with pytest.raises(ModelError, match=r"not symmetric: entry \[a, b\] = 0.5"):
        MultiModel(["a", "b"], "WN+RW", shared=["RW"], cov={"RW": [[1, 0.5], [0.2, 1]]})
    with pytest.raises(ModelError, match="must be 2 x 2"):
        MultiModel(["a", "b"], "WN+RW", shared=["RW"], cov={"RW": np.eye(3)})
    with pytest.raises(ModelError, match="unknown channel 'z'"):
        MultiModel(["a", "b"], "WN+RW", shared={"RW": ["a", "z"]})
    with pytest.raises(ModelError, match="QN cannot be shared"):
        MultiModel(["a", "b"], "WN+QN", shared=["QN"])
    with pytest.raises(ModelError, match="DR cannot be shared"):
        MultiModel(["a", "b"], "WN+DR", shared=["DR"])
    with pytest.raises(ModelError, match="channel b has no process RW"):
        MultiModel(["a", "b"], {"a": "WN+RW", "b": "WN"}, shared=["RW"])
    with pytest.raises(ModelError, match="no model for channel"):
        MultiModel(["a", "b"], {"a": "WN+RW"})
    with pytest.raises(ModelError, match="channel b: the model has 2 WN"):
        MultiModel(["a", "b"], {"a": "WN", "b": "2*WN"})
    with pytest.raises(ModelError, match="one beta for its group"):
        MultiModel(["a", "b"], {"a": "GM(beta=1)", "b": "GM(beta=2)"}, shared=["GM"])
    with pytest.raises(ModelError, match="cannot simulate"):
        MultiModel(["a", "b"], "WN+RW", shared=["RW"]).simulate(10)
    m = eg.wv.wv_matrix({"a": x, "b": rng.standard_normal(1000)})
    with pytest.raises(FitError, match="channel.*c are not in the WV matrix"):
        eg.fit_mgmwm(m, MultiModel(["a", "c"], "WN"))
    with pytest.raises(FitError, match="channel b is constant"):
        eg.fit_mgmwm({"a": x, "b": np.ones(1000)}, MultiModel(["a", "b"], "WN+RW"))
    with pytest.raises(FitError, match="unknown weights"):
        eg.fit_mgmwm(m, MultiModel(["a", "b"], "WN"), weights="optimal")
    with pytest.raises(ModelError, match="must be a MultiModel"):
        eg.fit_mgmwm(m, "WN+RW")
    wv = eg.wavelet_variance(x)
    with pytest.raises(FitError, match="at least 2 recordings"):
        eg.fit.fit_replicates([wv], "WN")
    with pytest.raises(FitError, match="replicate 2 has fs = 2 Hz"):
        eg.fit.fit_replicates([wv, eg.wavelet_variance(x, fs=2.0)], "WN")


# -------------------------------------------------------------------------------------------
# command line
# -------------------------------------------------------------------------------------------
def test_cli_fit_channels_and_replicates(tmp_path, capsys):
    mm = shared_rw(["gx", "gy"], 3e-2, 0.7)
    x = mm.simulate(2**14, rng=1)
    path = tmp_path / "imu.h5"
    eg.io.save_log(
        path, {"gx": x[:, 0], "gy": x[:, 1]}, 100.0, units={"gx": "deg/s", "gy": "deg/s"}
    )
    assert (
        cli_main(
            [
                "fit",
                str(path),
                "--model",
                "WN+RW",
                "--channels",
                "gx,gy",
                "--shared",
                "RW",
                "--json",
            ]
        )
        == 0
    )
    d = json.loads(capsys.readouterr().out)
    assert d["kind"] == "mgmwm" and d["shared"]["RW"]["channels"] == ["gx", "gy"]
    assert 0.4 < d["shared"]["RW"]["corr"][0][1] < 0.95
    paths = []
    for i in range(2):
        p = tmp_path / f"rep{i}.npy"
        np.save(p, x[:, i])
        paths.append(str(p))
    assert cli_main(["fit", *paths, "--model", "WN+RW", "--fs", "100"]) == 0
    assert "replicate fit of WN+RW to 2 recordings" in capsys.readouterr().out
    assert cli_main(["fit", str(path), "--model", "WN+RW", "--channels", "gx,gq"]) == 2
    assert "unknown channel(s) gq" in capsys.readouterr().err
    assert cli_main(["fit", str(path), "--model", "WN+RW", "--shared", "RW"]) == 2
    assert "--shared needs --channels" in capsys.readouterr().err
