"""The pieces of the profiled objective that make model selection cheaper, checked against
independent computations. What selection costs is a benchmark, not a test:
tests/benchmarks/bench_ranking.py prints it (a ratio to a bare NumPy Haar WV timed in the same
run) and docs/performance.md has the before/after table.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize

import engine as eg
from engine.fit._varpro import NNLSProblem, corner_anchors, local, search, sqrt_weight
from engine.fit.gmwm import weight_matrix
from engine.models.processes import ar1_wv, ar1_wv_pos


def test_ar1_series_branch_equals_the_vectorised_formula() -> None:
    # correlation times from 0.01 samples to 1e9: the series (x tau < 2e-3) covers none, some
    # and all of the scales; ar1_wv's array branch evaluates it term by term, independently
    tau = 2.0 ** np.arange(1, 21)
    for tc in (0.01, 0.7, 30.0, 600.0, 3e3, 1e5, 1e7, 1e9):
        phi = math.exp(-1.0 / tc)
        fast = ar1_wv_pos(tau, phi)
        ref = ar1_wv(tau, np.array([phi]))[0]
        np.testing.assert_allclose(fast, ref, rtol=1e-13, atol=0)
    # and the defining limit: a random walk's WV per unit innovation as phi = exp(-x) -> 1
    # (the first correction is -3 x tau / 8 relative: 4e-10 at x = 1e-15, tau = 2^20)
    rw = (tau**2 + 2.0) / (12.0 * tau)
    np.testing.assert_allclose(ar1_wv_pos(tau, math.exp(-1e-15)), rw, rtol=1e-9)


def _problem(model: str, weights: str = "ci") -> NNLSProblem:
    x = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-3)+WN(sigma2=1e-2)+RW(gamma2=1e-8)").simulate(
        2**16, fs=100.0, rng=np.random.default_rng(4)
    )
    wv = eg.wavelet_variance(x, fs=100.0)
    omega = (
        weight_matrix(wv, weights)[0]
        if weights == "ci"
        else np.linalg.inv(np.diag(wv.variance) ** 2 + 1e-3 * np.outer(wv.variance, wv.variance))
    )
    return NNLSProblem.from_wv(eg.parse_model(model), wv, sqrt_weight(omega))


@pytest.mark.parametrize("weights", ["ci", "full"])
def test_profile_is_the_nnls_of_the_weighted_design(weights: str) -> None:
    # the profile (constant columns weighted once, a diagonal A as a vector) against the NNLS of
    # A X formed here from the processes' own basis, for a diagonal and a full weight matrix
    prob = _problem("2*GM+WN+QN+RW+DR", weights)
    u = np.log([400.0, 3.0])
    phis = np.exp(-1.0 / np.exp(u))
    cols = [
        p.basis(prob.tau, prob.fs, phis[list(prob.nl_idx).index(i)] if p.nonlinear else None)
        for i, p in enumerate(prob.model.processes)
    ]
    c = prob.a @ np.column_stack(cols)
    norms = np.linalg.norm(c, axis=0)
    g, rnorm = scipy.optimize.nnls(c / norms, prob.b)
    assert prob.profile(u) == pytest.approx(rnorm**2, rel=1e-10)
    assert prob.solve(tuple(phis))[0] == pytest.approx(rnorm**2, rel=1e-10)


def test_each_point_of_the_profile_is_solved_once() -> None:
    prob = _problem("2*GM+WN")
    u = np.log([400.0, 3.0])
    first = prob.profile(u)
    n = prob.n_eval
    assert prob.profile(u.copy()) == first and prob.n_eval == n
    prob.profile(u + [1e-9, 0.0])
    assert prob.n_eval == n + 1


def test_ar1_rows_equal_the_term_by_term_formula() -> None:
    # several phi at once (the search's hot path: one expm1, B (B - 2) for the powers) against
    # ar1_wv's array branch, which evaluates the closed form and the series term by term; both
    # lose digits to the closed form's cancellation near x tau = 2e-3 (measured 4e-10 against
    # 50-digit arithmetic for either), hence 1e-9
    tau = 2.0 ** np.arange(1, 21)
    tc = np.array([0.01, 0.7, 30.0, 600.0, 999.0, 1001.0, 3e3, 1e5, 1e7, 1e9, 1e10])
    phis = np.exp(-1.0 / tc)
    rows = ar1_wv_pos(tau, phis)
    assert rows.shape == (tc.size, tau.size)
    np.testing.assert_allclose(rows, ar1_wv(tau, phis), rtol=1e-9, atol=0)
    # one row at a time gives the same rows (the series applies to some rows only)
    for k in (0, 3, 6):
        np.testing.assert_array_equal(ar1_wv_pos(tau, phis[k : k + 2]), rows[k : k + 2])


@pytest.mark.parametrize("weights", ["ci", "full"])
def test_profile_along_a_path_is_the_nnls_at_every_point(weights: str) -> None:
    # the profile tries the previous point's positive set first (normal equations + KKT): along
    # a path that crosses active-set changes (a GM's variance going to 0 and back, the QN and
    # DR columns in and out), every value equals SciPy's NNLS of the same design from scratch
    prob = _problem("2*GM+WN+QN+RW+DR", weights)
    rng = np.random.default_rng(2)
    path = np.log([2000.0, 3.0]) + np.cumsum(rng.normal(0.0, 0.15, (300, 2)), axis=0)
    path = np.sort(np.clip(path, prob.lo, prob.hi), axis=1)[:, ::-1]
    warm, supports = 0, set()
    for u in path:
        phis = np.exp(-1.0 / np.exp(u))
        c = prob.a @ prob.design(tuple(phis))
        norms = np.linalg.norm(c, axis=0)
        g, rnorm = scipy.optimize.nnls(c / norms, prob.b)
        supports.add(tuple(g > 0))
        n_before = prob._active
        assert prob.profile(u) == pytest.approx(rnorm**2, rel=1e-10)
        warm += prob._active is n_before
    assert len(supports) >= 3  # the path does cross changes of the positive set
    assert warm > len(path) // 2  # and most points were answered by the previous set


def test_polished_refit_reaches_the_searched_minimum() -> None:
    # the J-test's efficient refit of a fitted candidate (Omega = V^-1, fewer levels) starts
    # from the candidate's values with no grid: it reaches the same minimum as the full search
    # (grid, multi-starts, anchors), and never lies above its
    # start (the anchor argument)
    x = eg.parse_model("GM(beta=0.05, sigma2_gm=1e-4)+GM(beta=5, sigma2_gm=1e-3)+WN(sigma2=1e-2)")
    wv = eg.wavelet_variance(x.simulate(2**16, fs=100.0, rng=np.random.default_rng(7)), fs=100.0)
    first = eg.fit_gmwm(wv, "2*GM+WN")
    k = wv.n_levels - 3
    omega = np.linalg.inv(eg.fit.wv_cov(first)[:k, :k])
    full = eg.fit_gmwm(wv, "2*GM+WN", weights=omega, levels=k)
    polished = eg.fit_gmwm(wv, first.model, weights=omega, levels=k, optima={}, polish=True)
    assert polished.objective == pytest.approx(full.objective, rel=1e-8)
    start = eg.fit.gmwm_objective(wv.truncate(k), first.model, omega)
    assert polished.objective <= start


@pytest.mark.slow
@pytest.mark.parametrize("channel", ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
def test_ranking_j_column_is_the_full_searchs(real_data, channel: str) -> None:
    # the ranking's J-test refits are polished from each fitted candidate (no grid): on every
    # imu1 channel each of the 47 J statistics equals the one of a refit by the full search
    # (grid, multi-starts, its own sub-models), to 1e-6 relative (measured: <= 7e-8)
    from engine.inference.jtest import efficient_j

    log = eg.load_log(real_data / "adis16405_imu1.h5", channel=channel)
    wv = eg.wavelet_variance(log[channel], fs=log.fs)
    ranking = eg.rank_models(wv, max_model="2*GM+WN+QN+RW+DR")
    fitted = [c for c in ranking.candidates if c.result is not None]
    largest = max(fitted, key=lambda c: (c.n_params, -c.objective))
    vmat = eg.fit.wv_cov(largest.result)
    checked = 0
    for c in fitted:
        if not math.isfinite(c.j_stat):
            continue
        full, _, _, _ = efficient_j(wv, c.result.model, vmat)
        assert c.j_stat == pytest.approx(full, rel=1e-6), c.model
        checked += 1
    assert checked >= 40


def test_ar1_columns_on_stacked_scales() -> None:
    # a replicate fit stacks the scale vectors of its recordings (six logs: 2 .. 2^19 six
    # times): the series must go where x tau < 2e-3, not to as many of the first scales of the
    # stacked vector (it went there before: with the slow GM of the six ADIS gyro_x, 6,580
    # samples, to the first 18 scales, 2 .. 2^18 of the first log, off by 10^5 at the
    # coarsest; their replicate fit of 2*GM+WN+RW stopped at 630.28, it reaches 630.09 now)
    tau = np.tile(2.0 ** np.arange(1, 20), 6)
    for tc in (600.0, 6580.0, 1e5, 1e7):
        phi = math.exp(-1.0 / tc)
        ref = ar1_wv(tau, np.array([phi, 0.5]))
        np.testing.assert_allclose(ar1_wv_pos(tau, phi), ref[0], rtol=1e-9, atol=0)
        np.testing.assert_allclose(ar1_wv_pos(tau, np.array([phi, 0.5])), ref, rtol=1e-9, atol=0)


@pytest.mark.parametrize("weights", ["ci", "full"])
@pytest.mark.parametrize("model", ["2*GM+WN+QN+RW+DR", "GM+WN", "2*GM+RW", "GM+QN+WN+RW+DR"])
def test_profile_of_many_points_is_the_nnls_of_each(weights: str, model: str) -> None:
    # the grid's exact profiles at once (every positive set solved, the best feasible one)
    # against SciPy's NNLS of each point's design, at 200 random correlation times from 0.1
    # samples to 9e6
    prob = _problem(model, weights)
    rng = np.random.default_rng(1)
    u = np.sort(rng.uniform(-2.0, 16.0, (200, prob.k)), axis=1)[:, ::-1].copy()
    many = prob.profile_many(u)
    for row, value in zip(u, many, strict=True):
        c = prob.a @ prob.design(tuple(np.exp(-1.0 / np.exp(row))))
        norms = np.linalg.norm(c, axis=0)
        _, rnorm = scipy.optimize.nnls(c / norms, prob.b)
        assert value == pytest.approx(rnorm**2, rel=1e-10)
    assert np.array_equal(prob.profile_many(u), many)  # memoised


@pytest.mark.parametrize("code", ["GM", "AR1", "MA1"])
def test_search_kernel_is_the_basis_at_the_search_values(code: str) -> None:
    # the column kernel a fit problem prepares once (Process.search_kernel) gives the same
    # numbers as the process's basis at its search values, bit for bit, at coordinates below,
    # inside and above the search range (clipped) and where the AR1 series branch applies
    tau = 2.0 ** np.arange(1, 20)
    proc = eg.parse_model(code).processes[0]
    lo, hi = proc.search_range(10**6)
    kernel = proc.search_kernel(tau, 100.0, lo, hi)
    for us in ([lo - 3.0], [0.5], [math.log(30.0), math.log(2.5)], [hi + 1.0, math.log(1e9)]):
        got = kernel(us)
        nls = np.array([proc.search_nl(u, lo, hi) for u in us])
        np.testing.assert_array_equal(got, proc.basis_many(tau, 100.0, nls))
        if code == "GM":  # and the AR1 WV formula of docs/conventions.md, independently
            ref = ar1_wv(tau, nls, 1.0 - nls * nls)
            np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0)


def test_local_search_stops_in_a_known_minimums_basin() -> None:
    # a run whose best point comes within `merge` of a minimum found before, not below it,
    # returns that minimum (with fewer evaluations); a known point above the run's path is
    # not taken
    calls = [0]

    def f(u: np.ndarray) -> float:
        calls[0] += 1
        return float((u[0] - 1.0) ** 2 + 2.0 * (u[1] + 0.5) ** 2 + 1.0)

    f1, u1, ok = local(f, [0.0, 0.0], 0.2, -5.0, 5.0)
    assert ok and f1 == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_allclose(u1, [1.0, -0.5], atol=1e-5)
    calls[0] = 0
    plain = local(f, [0.4, 0.2], 0.2, -5.0, 5.0)
    n_plain = calls[0]
    calls[0] = 0
    merged = local(f, [0.4, 0.2], 0.2, -5.0, 5.0, known=[(f1, u1)], merge=0.05)
    assert merged[0] == f1 and np.array_equal(merged[1], u1) and merged[2]
    assert calls[0] < n_plain / 2
    assert plain[0] == pytest.approx(f1, rel=1e-9)
    high = local(f, [0.4, 0.2], 0.2, -5.0, 5.0, known=[(f1 + 1e-6, u1)], merge=1e-4)
    assert high[0] < f1 + 1e-9 and not np.array_equal(high[1], u1)


class _WithoutSurfaceStop:
    """A problem that hides ``nl_term_dead``: :func:`search` then runs every local search to
    its end, as it did before runs on a sub-model's surface were stopped."""

    def __init__(self, prob: NNLSProblem) -> None:
        self._prob = prob

    def __getattr__(self, name: str) -> object:
        if name == "nl_term_dead":
            raise AttributeError(name)
        return getattr(self._prob, name)


def test_an_anchor_that_is_a_sub_models_minimum_starts_no_search() -> None:
    # GM+WN+RW's optimum on a series without drift is a point of GM+WN+RW+DR where DR's
    # variance stays 0 (the same objective, to rounding): a local minimum of the larger model
    # already, so its search profiles the anchor once and runs no Nelder-Mead; without the
    # sub-model's objective the same search runs from the anchor and finds the same minimum
    prob_s = _problem("GM+WN+RW")
    f_s, u_s, ok = search(prob_s)
    assert ok
    prob = _problem("GM+WN+RW+DR")
    f, h, _ = prob.solve(prob.phis_of(u_s))
    assert h[-1] == 0.0 and f == pytest.approx(f_s, rel=1e-12)
    n = prob.n_eval
    got = search(prob, keep=0, anchors=[tuple(u_s)], anchor_minima=[f_s])
    assert prob.n_eval == n + 1 and got[0] == pytest.approx(f, rel=1e-12)
    assert np.array_equal(got[1], u_s) and got[2]
    plain = _problem("GM+WN+RW+DR")
    ref = search(plain, keep=0, anchors=[tuple(u_s)])
    assert plain.n_eval > 20  # (measured: a Nelder-Mead run that does not move)
    assert got[0] == pytest.approx(ref[0], rel=1e-10)


def test_a_run_on_a_sub_models_surface_stops() -> None:
    # 2*GM+WN+RW on a series with one GM: the grid's starts lead Nelder-Mead to where the
    # second GM's variance is 0 (GM+WN+RW's objective, flat in that GM's correlation time);
    # those runs stop once there, not below the anchor that GM+WN+RW's optimum gives, and the
    # search ends at the same minimum as when every run goes to its end, with a third of the
    # profile evaluations (measured 247 against 843)
    f_s, u_s, _ = search(_problem("GM+WN+RW"))
    fast = _problem("2*GM+WN+RW")
    got = search(fast, anchors=corner_anchors(fast, [tuple(u_s)]))
    full = _problem("2*GM+WN+RW")
    ref = search(_WithoutSurfaceStop(full), anchors=corner_anchors(full, [tuple(u_s)]))
    assert got[0] == pytest.approx(ref[0], rel=1e-10) and got[0] <= f_s
    assert fast.n_eval < full.n_eval / 2


@pytest.mark.real_data
def test_ranking_profile_evaluations(real_data, monkeypatch) -> None:
    # the 47 sub-models of the default ranked on imu1 accel_x (the candidates' fits and their
    # J-test refits): a deterministic count of the profiled objective's evaluations, memo hits
    # and the grid's batches included, as tests/benchmarks/bench_ranking.py counts them
    # (8,281 before the anchors that are minima already and the runs stopped on a
    # sub-model's surface, 4,647 after); the numbers themselves: test_ranking_table.py
    n = [0]
    one, many = NNLSProblem.profile, NNLSProblem.profile_many

    def counted(self, u):  # type: ignore[no-untyped-def]
        n[0] += 1
        return one(self, u)

    def counted_many(self, u):  # type: ignore[no-untyped-def]
        n[0] += len(u)
        return many(self, u)

    monkeypatch.setattr(NNLSProblem, "profile", counted)
    monkeypatch.setattr(NNLSProblem, "profile_many", counted_many)
    wv = eg.load_log(real_data / "adis16405_imu1.h5").wavelet_variance("accel_x")
    ranking = eg.rank_models(wv, max_model="2*GM+WN+QN+RW+DR")
    assert len(ranking.candidates) == 47
    assert n[0] <= 5_500


@pytest.mark.parametrize("weights", ["ci", "full"])
@pytest.mark.parametrize("model", ["2*GM+WN+QN+RW+DR", "GM+WN", "2*GM"])
def test_grid_lower_bounds_are_the_unconstrained_least_squares(weights: str, model: str) -> None:
    # branch and bound's lower bound of each grid candidate (its columns formed once per axis
    # value, a diagonal A as a vector) against the unconstrained weighted least squares of that
    # candidate's design formed here (numpy's lstsq), and its feasibility flag against the
    # signs of that solution, at every candidate of the grid
    prob = _problem(model, weights)
    u = np.asarray(prob.candidates(), dtype=float)
    lower, feasible = prob.lower_bounds(u)
    assert len(u) > 30
    for row, lo, ok in zip(u, lower, feasible, strict=True):
        c = prob.a @ prob.design(tuple(np.exp(-1.0 / np.exp(row))))
        norms = np.linalg.norm(c, axis=0)
        coef, *_ = np.linalg.lstsq(c / norms, prob.b, rcond=None)
        r = prob.b - (c / norms) @ coef
        assert lo == pytest.approx(max(float(r @ r), 0.0), rel=1e-6, abs=1e-12 * prob.bb)
        assert lo <= prob.profile(row) * (1 + 1e-9)
        if ok:
            assert np.all(coef >= -1e-9 * np.max(np.abs(coef)))
