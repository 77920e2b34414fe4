"""The app's "Multi-channel" tab: the WV/WCCV grid and the live multivariate GMWM fit.

Browser-free tests drive the view's widgets programmatically (outside a server the fit's
worker job runs to completion at once); the numbers shown must be the engine's
(``wavelet_variance``, ``wavelet_cross_covariance``, ``fit_mgmwm``) and, on a simulated log
with a known shared random-walk covariance, close to the truth. One Chromium test opens the
tab of a served app and reads the rendered grid and table.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

import engine as eg
from engine.io import ImuLog
from engine.models import ModelError
from engine.multivariate import MultiModel
from gmwm_app.data import LoadedData
from gmwm_app.multi_figures import covariance_rows, grid_data, model_curve_grid
from gmwm_app.multi_fit import build_model, parse_overrides
from gmwm_app.multi_view import MultiView
from gmwm_app.state import format_value

GYROS = ["gyro_x", "gyro_y", "gyro_z"]
TITLE = "Multi-channel"


def open_view(app: Any, show: bool = True) -> MultiView:
    v = app.open_view(TITLE)
    if show:
        app.tabs.active = list(app.tabs._names).index(TITLE)
    return v


def direct_fit(lg: Any, chans: list[str], spec: str, shared: dict) -> eg.multivariate.MGMWMResult:
    wvm = eg.wv.wv_matrix(lg, channels=chans)
    return eg.fit_mgmwm(wvm, MultiModel(chans, spec, shared=shared))


# -------------------------------------------------------------------------------------------
# the grid
# -------------------------------------------------------------------------------------------
def test_grid_shows_the_engine_wv_and_wccv_and_the_fitted_model(app: Any) -> None:
    v = open_view(app)
    lg = app.state.log
    assert list(v.controls.channel_choice.value) == GYROS  # default: the first 3 channels
    assert v.error == "" and v.result is not None and v.grid.k == 3
    assert sorted(v.grid.cells) == [(0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2)]
    fs = lg.fs
    for p, a in enumerate(GYROS):
        wv = eg.wavelet_variance(lg[a], fs=fs)
        d = v.grid.cells[(p, p)].emp.data
        np.testing.assert_allclose(d["value"], wv.variance, rtol=1e-10)
        np.testing.assert_allclose(d["ci_low"], wv.ci_low, rtol=1e-10)
        np.testing.assert_allclose(d["ci_high"], wv.ci_high, rtol=1e-10)
        np.testing.assert_allclose(d["tau_s"], wv.tau_samples / fs, rtol=1e-12)
        np.testing.assert_allclose(d["y"], wv.variance, rtol=1e-10)  # drawn as is
        for q in range(p):
            c = eg.wavelet_cross_covariance(lg[a], lg[GYROS[q]], fs=fs)
            d = v.grid.cells[(p, q)].emp.data
            np.testing.assert_allclose(d["value"], c.covariance, rtol=1e-9, atol=1e-18)
            np.testing.assert_allclose(d["ci_low"], c.ci_low, rtol=1e-9, atol=1e-18)
            np.testing.assert_allclose(d["ci_high"], c.ci_high, rtol=1e-9, atol=1e-18)
            # drawn: |WCCV| on the log axis, hollow markers where negative
            np.testing.assert_allclose(d["y"], np.abs(c.covariance), rtol=1e-9)
            assert [f == "white" for f in d["fill"]] == list(c.covariance < 0)
            assert np.any(c.covariance < 0)  # independent demo gyros: both signs occur
            straddle = (c.ci_low <= 0) & (c.ci_high >= 0)
            np.testing.assert_allclose(
                d["y_high"], np.maximum(abs(c.ci_low), abs(c.ci_high)), rtol=1e-9
            )
            assert np.all(d["y_low"][straddle] < np.nanmin(np.abs(c.covariance)))
    # model curves: the direct fit's implied WV/WCCV at every dyadic scale (every 8th point)
    ref = direct_fit(lg, GYROS, "GM+WN+RW", {"RW": GYROS})
    for (p, q), cell in v.grid.cells.items():
        t = cell.total.data
        np.testing.assert_allclose(t["tau_s"], model_curve_grid(17) / fs, rtol=1e-12)
        np.testing.assert_allclose(t["value"][::8], ref.implied[:, p, q], rtol=1e-6)
        # per process: own GM, WN, RW on the diagonal plus nothing shared but RW off it
        shown = [r.visible for r in cell.comp_renderers]
        assert sum(shown) == (3 if p == q else 1)
        if p != q:
            np.testing.assert_allclose(
                cell.comps[0].data["wv"][::8], np.abs(ref.components["RW"][:, p, q]), rtol=1e-6
            )
    # one shared x range for every cell
    assert len({id(c.figure.x_range) for c in v.grid.cells.values()}) == 1


@pytest.mark.slow  # six multivariate fits: 12 s of CPU
def test_changing_channels_resizes_the_grid_and_reuses_figures(app: Any) -> None:
    v = open_view(app)
    g3 = v.grid
    v.controls.channel_choice.value = ["gyro_z", "accel_x"]
    assert v.grid.k == 2 and len(v.grid.cells) == 3 and v.error == ""
    assert v.grid_box.objects == [v.grid.pane]
    # order follows the choice: row 0 is gyro_z
    np.testing.assert_allclose(
        v.grid.cells[(0, 0)].emp.data["value"],
        eg.wavelet_variance(app.state.log["gyro_z"]).variance,
        rtol=1e-10,
    )
    assert v.result.channels == ("gyro_z", "accel_x")
    # RW shared by every channel by default, also the new ones; units of the pair
    rows = v.cov_source.data
    assert rows["unit"] == ["(deg/s)²", "deg/s·m/s^2".replace("^2", "²"), "(m/s²)²"]
    v.controls.channel_choice.value = ["accel_x", "accel_y", "accel_z", "gyro_x", "gyro_y"]
    assert v.grid.k == 5 and len(v.grid.cells) == 15
    v.controls.channel_choice.value = GYROS
    assert v.grid is g3  # built once per grid size
    # one channel: a message, no grid; at most 6 channels
    v.controls.channel_choice.value = ["gyro_x"]
    assert "at least 2 channels" in v.error and not v.grid_box.visible
    assert v.controls.channel_choice.max_items == 6


def test_data_changes_follow_cheaply_while_hidden(app: Any, tmp_path: Path) -> None:
    v = open_view(app, show=False)
    v.controls.spec_input.value = "WN"
    fits, wvms = v.n_fits, v.n_wvm
    path = write_log(
        tmp_path / "two.h5",
        {
            "u": np.random.default_rng(1).standard_normal(4096),
            "w": np.random.default_rng(2).standard_normal(4096),
        },
    )
    assert app.state.load_path(path), app.state.error
    assert v.n_fits == fits and v.n_wvm == wvms  # hidden: nothing computed
    app.tabs.active = list(app.tabs._names).index(TITLE)
    assert list(v.controls.channel_choice.options) == ["u", "w"]
    assert list(v.controls.channel_choice.value) == ["u", "w"] and v.grid.k == 2
    assert v.n_fits == fits + 1 and v.n_wvm == wvms + 1
    # a change of the sharing refits on the cached matrix
    v.set_shared("WN", ["u", "w"])
    assert v.n_fits == fits + 2 and v.n_wvm == wvms + 1
    assert v.result.model.spec() == "u,w: WN | shared: WN"
    # independent unit white noise: variance 1 (sd sqrt(2/N) = 2 %), correlation near 0
    # (sd 1/sqrt(N) = 0.016)
    cov, rho = v.cov_source.data["covariance"], v.cov_source.data["correlation"]
    assert cov[0] == pytest.approx(1.0, abs=0.1) and cov[2] == pytest.approx(1.0, abs=0.1)
    assert abs(rho[1]) < 0.07


@pytest.mark.slow  # multivariate fits: 7 s of CPU
def test_robust_setting_gives_a_notice_and_keeps_the_classical_matrix(app: Any) -> None:
    v = open_view(app)
    before, wvms = v.wvm, v.n_wvm
    assert not v.notice.visible
    assert app.state.set_robust(True), app.state.error
    assert v.notice.visible and "classical WV/WCCV" in v.notice.object
    assert v.wvm is before and v.n_wvm == wvms  # the cached (classical) matrix


# -------------------------------------------------------------------------------------------
# tables
# -------------------------------------------------------------------------------------------
def test_tables_equal_fit_mgmwm_run_directly(app: Any) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "WN+RW"
    v.set_shared("WN", ["gyro_x", "gyro_z"])
    lg = app.state.log
    ref = direct_fit(lg, GYROS, "WN+RW", {"WN": ["gyro_x", "gyro_z"], "RW": GYROS})
    assert v.result.model.spec() == ref.model.spec()
    rows = v.cov_source.data
    expect = [("WN", "gyro_x", "gyro_x"), ("WN", "gyro_x", "gyro_z"), ("WN", "gyro_z", "gyro_z")]
    expect += [("RW", a, b) for i, a in enumerate(GYROS) for b in GYROS[i:]]
    assert list(zip(rows["process"], rows["channel_a"], rows["channel_b"], strict=True)) == expect
    for lab, a, b, cov, rho in zip(
        rows["process"],
        rows["channel_a"],
        rows["channel_b"],
        rows["covariance"],
        rows["correlation"],
        strict=True,
    ):
        est = ref.shared[lab]
        i, j = est.channels.index(a), est.channels.index(b)
        assert cov == pytest.approx(est.cov[i, j], rel=1e-9)
        assert rho == pytest.approx(
            est.cov[i, j] / np.sqrt(est.cov[i, i] * est.cov[j, j]), rel=1e-9
        )
    # per-channel parameters: gyro_y's own WN; every shared value in the covariance table
    prm = v.param_source.data
    assert list(zip(prm["channel"], prm["process"], prm["parameter"], strict=True)) == [
        ("gyro_y", "WN", "sigma2")
    ]
    assert prm["value"][0] == pytest.approx(ref.params["gyro_y.WN.sigma2"], rel=1e-9)
    assert prm["unit"] == ["(deg/s)²"]
    assert f"**Objective** {format_value(ref.objective)} [1]" in v.fit_info.object
    # a shared GM: its common beta is a parameter row (WN stays shared by x and z: the
    # marks survive a change of the model)
    v.controls.spec_input.value = "GM+WN"
    v.set_shared("GM", GYROS)
    ref = direct_fit(lg, GYROS, "GM+WN", {"GM": GYROS, "WN": ["gyro_x", "gyro_z"]})
    assert v.result.model.spec() == ref.model.spec()
    prm = v.param_source.data
    k = prm["parameter"].index("beta")
    assert prm["channel"][k] == "shared (gyro_x, gyro_y, gyro_z)"
    assert prm["value"][k] == pytest.approx(ref.params["GM.beta"], rel=1e-6)
    assert v.cov_source.data["covariance"][0] == pytest.approx(ref.shared["GM"].cov[0, 0], rel=1e-6)


def write_log(
    path: Path, channels: dict[str, np.ndarray], fs: float = 100.0, unit: str = "deg/s"
) -> Path:
    with h5py.File(path, "w") as f:
        for name, x in channels.items():
            f.create_dataset(name, data=x).attrs["units"] = unit
        f.attrs["fs_hz"] = fs
    return path


# Truth of the simulated log: white noise independent per channel, a random walk shared by
# the three channels with a full covariance (per sample).
SIM_SD = np.array([1.0e-3, 1.5e-3, 0.8e-3])
SIM_CORR = np.array([[1.0, 0.6, -0.4], [0.6, 1.0, 0.2], [-0.4, 0.2, 1.0]])
SIM_COV = SIM_CORR * np.outer(SIM_SD, SIM_SD)
SIM_WN = np.array([1.0, 2.0, 0.5])
SIM_N = 2**20
# Monte Carlo of this estimator (40 replicates of this simulation, seeds 1000..1039, run
# once with the same code): relative sd of the covariance entries (relative to |truth|) and
# sd of the correlations. Mean/truth was within 0.96..1.06 for every entry (no bias beyond
# the Monte Carlo noise). The test allows 4 sd (a 40-replicate sd is itself uncertain by
# about 11 %).
MC_REL_SD = np.array([[0.082, 0.103, 0.142], [0.103, 0.084, 0.289], [0.142, 0.289, 0.082]])
MC_RHO_SD = np.array([[0.0, 0.040, 0.051], [0.040, 0.0, 0.056], [0.051, 0.056, 0.0]])


def simulate_shared_rw(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    root = np.linalg.cholesky(SIM_COV)
    rw = np.cumsum(rng.standard_normal((SIM_N, 3)) @ root.T, axis=0)
    return rw + rng.standard_normal((SIM_N, 3)) * np.sqrt(SIM_WN)


@pytest.mark.slow  # a recovery on a simulated log: 7 s of CPU
def test_table_recovers_a_known_shared_random_walk_covariance(app: Any, tmp_path: Path) -> None:
    x = simulate_shared_rw(1000)
    names = ["imu_a", "imu_b", "imu_c"]
    path = write_log(tmp_path / "shared_rw.h5", dict(zip(names, x.T, strict=True)))
    v = open_view(app)
    v.controls.spec_input.value = "WN+RW"  # RW shared by every channel (the default)
    assert app.state.load_path(path), app.state.error
    assert list(v.controls.channel_choice.value) == names and v.error == ""
    assert v.result.model.spec() == "imu_a,imu_b,imu_c: WN+RW | shared: RW"
    rows = v.cov_source.data
    for a, b, cov, rho in zip(
        rows["channel_a"], rows["channel_b"], rows["covariance"], rows["correlation"], strict=True
    ):
        i, j = names.index(a), names.index(b)
        assert abs(cov - SIM_COV[i, j]) < 4 * MC_REL_SD[i, j] * abs(SIM_COV[i, j]), (a, b, cov)
        if i != j:
            assert abs(rho - SIM_CORR[i, j]) < 4 * MC_RHO_SD[i, j], (a, b, rho)
    assert set(rows["unit"]) == {"(deg/s)²"}
    # the independent white noise: sigma2 of each channel (precise: about 1 %)
    prm = v.param_source.data
    for c, val in zip(prm["channel"], prm["value"], strict=True):
        assert val == pytest.approx(SIM_WN[names.index(c)], rel=0.05)


# -------------------------------------------------------------------------------------------
# errors and data problems
# -------------------------------------------------------------------------------------------
def test_bad_specs_are_messages_and_the_session_keeps_working(app: Any) -> None:
    v = open_view(app)
    for spec, words in (
        ("WN+FOO", "unknown process 'FOO'"),
        ("2*WN", "only their sum"),
        ("GM+AR1", "mixes AR1 and GM"),
        ("", "model is empty"),
    ):
        v.controls.spec_input.value = spec
        assert v.error.startswith("Could not fit the model") and words in v.error, v.error
        assert v.message.visible and "Traceback" not in v.message.object
        assert v.result is None and v.cov_source.data["covariance"] == []
        # the empirical grid stays
        assert v.grid_box.visible and v.grid.cells[(0, 0)].emp.data["value"].size == 17
        assert all(not r.visible for r in v.grid.cells[(1, 0)].comp_renderers)
    v.controls.override_input.value = "gyro_q: WN"
    v.controls.spec_input.value = "WN+RW"
    assert "gyro_q" in v.error and "not among the chosen channels" in v.error
    v.controls.override_input.value = "gyro_z: GM+WN+RW"
    assert v.error == "" and not v.message.visible
    assert v.result.model.models["gyro_z"].spec() == "GM+WN+RW"
    assert v.result.model.models["gyro_x"].spec() == "WN+RW"
    assert app.state.error == ""  # the Fit tab is untouched


@pytest.mark.slow  # multivariate fits: 5 s of CPU
def test_too_short_and_uneven_logs_are_messages(app: Any) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "WN+RW"
    rng = np.random.default_rng(5)
    short = ImuLog(channels={"a": rng.standard_normal(4), "b": rng.standard_normal(4)}, fs=1.0)
    assert app.state.install(LoadedData(short, "path", "short.h5"))
    assert v.grid.k == 2 and "Could not fit the model" in v.error
    # 1 level: 3 moments (2 WV, 1 WCCV) for 5 parameters (2 WN, 3 of the shared RW)
    assert "5 parameters but there are only 3 moments" in v.error, v.error
    # channels of different lengths: truncated to the shortest, with a notice
    lg = ImuLog(channels={"a": rng.standard_normal(5000), "b": rng.standard_normal(3000)}, fs=10.0)
    assert app.state.install(LoadedData(lg, "path", "uneven.h5"))
    assert v.notice.visible and "truncated to the shortest, 3,000 samples" in v.notice.object
    ref = eg.wv.wv_matrix({"a": lg.channels["a"][:3000], "b": lg.channels["b"]}, fs=10.0)
    np.testing.assert_allclose(v.wvm.values, ref.values, rtol=1e-12)


@pytest.mark.slow  # multivariate fit and a real log: 5 s of CPU
def test_summary_file_is_a_message(app: Any, real_data: Path) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "WN+RW"
    assert app.state.load_path(real_data / "derived" / "navchip_wv_av.h5"), app.state.error
    assert "summaries only" in v.error and "raw" in v.error and not v.grid_box.visible


def test_pure_helpers() -> None:
    assert parse_overrides("# comment\n a : WN+RW \n\n", ["a", "b"]) == {"a": "WN+RW"}
    with pytest.raises(ModelError, match="channel: spec"):
        parse_overrides("a WN", ["a", "b"])
    with pytest.raises(ModelError, match="cannot be shared"):
        build_model(["a", "b"], "QN+WN", shared={"QN": ["a", "b"]})
    mm = build_model(["a", "b", "c"], "WN+RW", shared={"RW": ["c", "a"], "WN": ["b"]})
    assert mm.spec() == "a,b,c: WN+RW | shared: RW[a,c]"  # a group of 1 is not shared
    assert covariance_rows(None)["covariance"] == []
    # grid_data without a fit: the empirical part only; an interval straddling 0
    rng = np.random.default_rng(3)
    wvm = eg.wv.wv_matrix(rng.standard_normal((4096, 2)))
    d = grid_data(wvm)
    assert sorted(d) == [(0, 0), (1, 0), (1, 1)] and d[(1, 0)]["components"] == []
    off = d[(1, 0)]["emp"]
    lo, hi = wvm.ci_low[:, 1, 0], wvm.ci_high[:, 1, 0]
    s = (lo <= 0) & (hi >= 0)
    assert s.any()
    floor = 0.5 * np.min(
        np.concatenate([np.abs(wvm.values[:, 1, 0]), np.abs(lo[~s]), np.abs(hi[~s])])
    )
    np.testing.assert_allclose(off["y_low"][s], floor)
    np.testing.assert_allclose(off["y_low"][~s], np.minimum(abs(lo), abs(hi))[~s])


# -------------------------------------------------------------------------------------------
# coalescing: one fit at a time, the latest settings win, stale results are dropped
# -------------------------------------------------------------------------------------------
@pytest.mark.slow  # multivariate fits: 6 s of CPU
def test_changes_during_a_fit_coalesce_into_one_more_fit(
    app: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    v = open_view(app)
    held: list[Any] = []
    monkeypatch.setattr(app.jobs, "spawn", lambda coro_fn: held.append(coro_fn))
    before = v.n_fits
    v.controls.spec_input.value = "WN+RW"  # starts a fit (held: "running")
    assert v.n_fits == before + 1 and v.busy and v.spinner.visible
    for spec in ("GM+WN", "WN", "GM+WN+RW+QN"):  # three more changes while it runs
        v.controls.spec_input.value = spec
    assert v.n_fits == before + 1 and len(held) == 1
    asyncio.run(held.pop()())  # the first fit ends: its (stale) result is dropped ...
    assert v.n_fits == before + 2 and len(held) == 1  # ... and one new fit starts
    assert v.result.model.spec() != "gyro_x,gyro_y,gyro_z: WN+RW | shared: RW"
    asyncio.run(held.pop()())
    assert not held and not v.busy and not v.spinner.visible
    assert v.result.model.spec() == build_model(GYROS, "GM+WN+RW+QN", shared={"RW": GYROS}).spec()
    ref = direct_fit(app.state.log, GYROS, "GM+WN+RW+QN", {"RW": GYROS})
    assert v.result.objective == pytest.approx(ref.objective, rel=1e-9)


# -------------------------------------------------------------------------------------------
# the test of dependence
# -------------------------------------------------------------------------------------------
@pytest.mark.slow  # bootstrap replicates: 7 s of CPU
def test_dependence_test_equals_the_engine_and_can_be_cancelled(app: Any) -> None:
    v = open_view(app)
    v.controls.spec_input.value = "WN+RW"  # RW shared by the three gyros (the default marks)
    mm = MultiModel(GYROS, "WN+RW", shared=["RW"])
    ref = eg.multivariate.dependence_test(
        eg.wv.wv_matrix(app.state.log, channels=GYROS), mm, B=4, seed=0
    )
    seen: list[int] = []
    assert v.dep.start(4, observer=lambda d, t: seen.append(d))
    assert seen == [0, 1, 2, 3, 4] and not v.dep.running
    t = v.dep.result
    assert t.labels == ("RW",) and t.B == 4
    assert t.statistic == pytest.approx(ref.statistic, rel=1e-9)
    assert t.p_value == ref.p_value
    np.testing.assert_allclose(t.bootstrap, ref.bootstrap, rtol=1e-9)
    # independently of dependence_test: the statistic is the drop of the objective that the
    # shared covariance brings, and the p-value counts the bootstrap differences above it
    wvm = eg.wv.wv_matrix(app.state.log, channels=GYROS)
    q1 = eg.fit_mgmwm(wvm, mm.cleared(), weights="ci").objective
    q0 = eg.fit_mgmwm(wvm, mm.without_dependence().cleared(), weights="ci").objective
    assert t.statistic == pytest.approx(q0 - q1, rel=1e-9, abs=1e-12)
    boot = np.asarray(t.bootstrap)
    assert t.p_value == pytest.approx((1 + np.sum(boot >= t.statistic)) / (1 + boot.size))
    assert f"p = {format_value(ref.p_value, 3)}" in v.dep.text.object

    # cancel after the second replicate: the previous outcome is kept
    def observer(done: int, total: int) -> None:
        if done == 2:
            v.dep.cancel()

    assert v.dep.start(50, observer=observer)
    assert v.dep.result is t and "cancelled" in v.dep.text.object
    assert not v.dep.running and not v.dep.button.disabled and v.dep.cancel_button.disabled
    # nothing shared: nothing to test
    v.set_shared("RW", [])
    assert not v.dep.start(4) and "shares no process" in v.dep.text.object


# -------------------------------------------------------------------------------------------
# a real browser
# -------------------------------------------------------------------------------------------
@pytest.mark.browser
@pytest.mark.browser_tour
def test_browser_tab_renders_the_grid_and_the_table(app_demo_file: Path) -> None:
    from _browser import launch, require_chromium
    from conftest import served_app
    from test_in_browser import TIMEOUT_MS

    from gmwm_app.app import live_apps

    require_chromium()
    from playwright.sync_api import sync_playwright

    # sessions of earlier tests in this process (one of them cleared the shared RW) are not ours
    before = live_apps()
    with served_app(app_demo_file) as (port, _thread), sync_playwright() as pw:
        browser = launch(pw)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1100})
            errors: list[str] = []
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
            page.goto(f"http://127.0.0.1:{port}/")
            page.get_by_text("WV levels").first.wait_for(timeout=TIMEOUT_MS)
            n_canvas = page.locator("canvas").count()
            page.locator(".bk-tab", has_text=TITLE).first.click()
            cells = page.locator(".gmwm-mcov .slick-cell")
            deadline = time.time() + TIMEOUT_MS / 1000
            while time.time() < deadline and cells.count() < 6 * 6:
                page.wait_for_timeout(100)
            text = " ".join(cells.all_inner_texts())
            apps = [
                a for a in live_apps() if TITLE in a.lazy_views and not any(a is b for b in before)
            ]
            assert apps, "no session opened the tab"
            v = apps[-1].lazy_views[TITLE]
            assert v.wait(20) and v.error == "" and v.result is not None
            est = v.result.shared["RW"]
            # the table: RW rows for every pair, the numbers of the fit
            for a in GYROS:
                assert a in text
            assert "RW" in text and "(deg/s)²" in text
            assert (
                f"{est.cov[0, 1]:.4e}" in text or f"{est.cov[0, 1]:.4e}".replace("e-", "e−") in text
            ), text
            assert f"{est.corr[0, 1]:.4f}" in text
            # the grid: a canvas per figure (6 for 3 channels), the objective in words
            assert page.locator("canvas").count() >= n_canvas + 6
            obj = " ".join(page.locator(".gmwm-mobjective p").all_inner_texts())
            assert "Objective" in obj and format_value(v.result.objective) in obj
            # type another model: the served view refits (debounced, in a worker thread)
            fits = v.n_fits
            box = page.locator(".gmwm-mspec input")
            box.fill("WN+RW")
            box.press("Enter")
            want = "gyro_x,gyro_y,gyro_z: WN+RW | shared: RW"
            while time.time() < deadline + 20 and (
                v.result is None or v.result.model.spec() != want or v.busy
            ):
                page.wait_for_timeout(100)
            assert v.result.model.spec() == want and v.n_fits == fits + 1
            ref = v.result.shared["RW"].corr[0, 1]
            end = time.time() + TIMEOUT_MS / 1000
            while time.time() < end and f"{ref:.4f}" not in " ".join(cells.all_inner_texts()):
                page.wait_for_timeout(100)
            assert f"{ref:.4f}" in " ".join(cells.all_inner_texts())
            assert not [e for e in errors if "favicon" not in e], errors
            assert not [e for e in errors if "favicon" not in e], errors
        finally:
            browser.close()
