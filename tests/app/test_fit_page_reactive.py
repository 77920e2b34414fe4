"""The Fit page follows the state declaratively: each part depends on the state
parameters it draws, redraws once per action, widgets echo no state change, and every
failure reaches the page as a message and the log.

Counts, not timings: a part's redraws are counted by wrapping the object it calls.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import panel as pn
import pytest
from bokeh.document import Document
from panel.io.state import set_curdoc

import engine as eg
from gmwm_app import boundary
from gmwm_app import data as data_mod
from gmwm_app import state as state_mod
from gmwm_app.state import AppState
from gmwm_app.wv_cache import N_WV_MATRICES, WVCache


def _count(monkeypatch: pytest.MonkeyPatch, obj: Any, name: str) -> list[int]:
    """Count the calls of ``obj.name`` (still called)."""
    calls: list[int] = []
    real = getattr(obj, name)

    def counting(*a: Any, **kw: Any) -> Any:
        calls.append(1)
        return real(*a, **kw)

    monkeypatch.setattr(obj, name, counting)
    return calls


def _csv(names: tuple[str, ...], n: int = 4096, seed: int = 0) -> bytes:
    x = np.random.default_rng(seed).standard_normal((n, len(names)))
    rows = [f"{i / 100.0},{','.join(f'{v:.17g}' for v in r)}" for i, r in enumerate(x)]
    return ("time," + ",".join(names) + "\n" + "\n".join(rows) + "\n").encode()


# ---------------------------------------------------------------------------------------------
# what depends on what
# ---------------------------------------------------------------------------------------------
def test_the_fit_page_watches_no_revision(app: Any) -> None:
    s = app.state
    watched = set(s.param.watchers)  # parameter name -> its watchers (this instance)
    assert not hasattr(s.param, "revision")  # no catch-all counter: each view names its parameters
    assert {"wv", "model", "result", "error", "inferred", "show_intervals"} <= watched


def test_each_part_redraws_once_per_action(app: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    s = app.state
    plot = _count(monkeypatch, app.views, "update")
    tables = _count(monkeypatch, app.tables, "update")
    # a model change sets model, result, whatif_values and error in one update
    assert s.set_model("GM+WN"), s.error
    assert (len(plot), len(tables)) == (1, 1)
    # a channel sets ten parameters at once: still one redraw of each
    assert s.select_channel("accel_x"), s.error
    assert (len(plot), len(tables)) == (2, 2)
    # an error alone redraws neither the plot nor the tables (it was a full refresh)
    s.report_error("something")
    assert (len(plot), len(tables)) == (2, 2)
    assert app.alert.visible and app.alert.object == "something"
    # the intervals: the tables (and the J-test badge), never the plot
    assert s.set_show_intervals(True)
    assert len(plot) == 2 and len(tables) >= 3
    assert s.inferred is not None and s.inferred.result is s.result  # computed (no server)
    assert list(app.tables.param_source.data["low"]) and all(app.tables.param_source.data["low"])
    assert app.jtest_pane.visible and "J-test" in app.jtest_pane.object


def test_a_batch_of_parameters_wakes_each_watcher_once(app_state: AppState) -> None:
    """param.update calls a watcher of several parameters once, with every event."""
    s = app_state
    seen: list[tuple[str, ...]] = []
    s.param.watch(lambda *ev: seen.append(tuple(e.name for e in ev)), ["model", "result", "error"])
    assert s.set_model("WN+RW")
    assert len(seen) == 1 and set(seen[0]) == {"model", "result"}  # (error was already "")


def test_a_repeated_error_is_reported_again(app: Any) -> None:
    s = app.state
    reported: list[str] = []
    s.param.watch(lambda e: reported.append(e.new), "error")
    s.report_error("Type the path of a log file on the server first")
    s.report_error("Type the path of a log file on the server first")
    assert reported == ["Type the path of a log file on the server first"] * 2
    app.path_input.value = ""
    app._on_path()  # the same click again: the same message, once more
    assert len(reported) == 3 and app.alert.visible


def test_state_updates_of_widgets_echo_no_action(app: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """A new log with other channels: options and value in one update (no intermediate first
    channel that would start a WV job); the what-if sliders set by the state change nothing."""
    s = app.state
    jobs = _count(monkeypatch, app.jobs, "load")
    loaded = s.read("upload", data=_csv(("p", "q", "r")), filename="pqr.csv")
    assert s.install(loaded, channel="r"), s.error
    assert list(app.channel_select.options) == ["p", "q", "r"]
    assert app.channel_select.value == "r" == s.channel
    assert jobs == []  # no channel job from the state's own update
    # the what-if sliders: set from the state, they set no what-if value
    assert s.set_model("WN+RW"), s.error
    mp = app.model_panel
    mp.whatif_toggle.value = True
    assert s.whatif
    before = dict(s.whatif_values)
    changes: list[Any] = []
    s.param.watch(lambda e: changes.append(e.new), "whatif_values")
    mp._reset_whatif()  # the sliders go back to the fit's positions
    assert s.whatif_values == before
    assert len(changes) <= 1  # the reset itself (equal values: none), not one per slider
    slider = mp.sliders.objects[0]
    x0 = slider.value
    slider.value = x0 + 1.0  # one decade up
    assert s.whatif_values["WN.sigma2"] == pytest.approx(10 * before["WN.sigma2"], rel=1e-9)
    slider.value = x0  # and back: the user's move, not an echo
    assert s.whatif_values["WN.sigma2"] == pytest.approx(before["WN.sigma2"], rel=1e-9)
    assert jobs == []


# ---------------------------------------------------------------------------------------------
# widgets of the state's own parameters: linked both ways, one redraw per change
# ---------------------------------------------------------------------------------------------
def test_the_weights_are_a_choice_of_their_allowed_values(app_state: AppState) -> None:
    s = app_state
    assert list(s.param.weights.objects) == ["ci", "identity", "efficient"]
    with pytest.raises(ValueError, match="weights"):
        s.weights = "optimal"
    assert s.weights == "ci"
    assert not s.set_weights("optimal") and "unknown weights 'optimal'" in s.error
    got = s.parse_query({"weights": "optimal"})
    assert "weights" not in got and got["problems"] == [
        "weights='optimal' in the link is not one of ci, identity, efficient"
    ]


def test_weights_widget_and_state_follow_each_other_with_one_refit(
    app: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gmwm_app import app as app_mod

    s, widget = app.state, app.model_panel.weights_select
    assert s.set_model("WN+RW"), s.error
    plot = _count(monkeypatch, app.views, "update")
    tables = _count(monkeypatch, app.tables, "update")
    summary = _count(monkeypatch, app_mod, "fit_summary")
    fits = _count(monkeypatch, eg, "fit_gmwm")
    # widget -> state: the weights and their fit, each part drawn once
    widget.value = "efficient"
    assert s.weights == "efficient" and s.result.weights == "efficient", s.error
    assert (len(fits), len(plot), len(tables), len(summary)) == (1, 1, 1, 1)
    # state -> widget, the parameter set alone (a restored session): refitted once too
    s.weights = "identity"
    assert widget.value == "identity" and s.result.weights == "identity"
    assert (len(fits), len(plot), len(tables), len(summary)) == (2, 2, 2, 2)
    # the action: the choice and its fit in one update, no second fit
    assert s.set_weights("ci")
    assert widget.value == "ci" and s.result.weights == "ci"
    assert (len(fits), len(plot), len(tables), len(summary)) == (3, 3, 3, 3)
    # a refit that fails puts the choice back, in the state and in the widget
    before = s.result

    def refuse(*_a: Any, **_k: Any) -> Any:
        raise ValueError("no fit today")

    monkeypatch.setattr(eg, "fit_gmwm", refuse)
    widget.value = "efficient"
    assert s.weights == "ci" == widget.value and s.result is before
    assert "no fit today" in s.error


def test_toggles_and_state_follow_each_other(app: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    s = app.state
    assert s.set_model("WN+RW"), s.error
    plot = _count(monkeypatch, app.views, "update")
    tables = _count(monkeypatch, app.tables, "update")
    whatif, intervals = app.model_panel.whatif_toggle, app.intervals_check
    whatif.value = True  # widget -> state: the curves follow the what-if values
    assert s.whatif and app.model_panel.sliders.visible
    assert (len(plot), len(tables)) == (1, 1)
    s.set_whatif(False)  # state -> widget
    assert whatif.value is False and not app.model_panel.sliders.visible
    assert (len(plot), len(tables)) == (2, 2)
    intervals.value = True  # the tables (with the intervals computed at once here), no plot
    assert s.show_intervals and s.inference() is not None and app.jtest_pane.visible
    assert len(plot) == 2
    s.set_show_intervals(False)
    assert intervals.value is False and not app.jtest_pane.visible
    assert len(plot) == 2


def test_the_data_widgets_are_built_from_the_states_parameters(app: Any) -> None:
    """Channel, fs and robust: widgets of the state's parameters (labels and choices declared
    there), the channel's choices those of the loaded log."""
    s = app.state
    assert app.channel_select.name == s.param.channel.label == "Channel"
    assert app.fs_input.name == s.param.fs.label == "Sampling frequency fs [Hz]"
    assert app.robust_check.name == s.param.robust.label
    assert list(s.param.channel.objects) == list(s.channels) == list(app.channel_select.options)
    assert app.fs_input.start == 0.0 and s.param.fs.bounds == (0.0, None)
    with pytest.raises(ValueError, match="not accept 'gyro_q'"):
        s.channel = "gyro_q"  # a channel of no log loaded
    with pytest.raises(ValueError, match="greater than 0"):
        s.fs = -1.0
    # a new log: the choices follow it, and the state's own update starts no WV job
    loaded = s.read("upload", data=_csv(("p", "q", "r")), filename="pqr.csv")
    assert s.install(loaded, channel="q"), s.error
    assert list(s.param.channel.objects) == ["p", "q", "r"] == list(app.channel_select.options)
    assert app.channel_select.value == "q"


def test_a_rendered_channel_widget_keeps_the_links_channel(app: Any) -> None:
    """With its Bokeh model (a served page), a Select whose value is not among its options
    falls back on the first one; the link's data are installed with their watchers batched
    (from_query): the new channels must be offered before, or the session ends on the first."""
    s = app.state
    root = app.channel_select.get_root(Document())
    other = s.read("upload", data=_csv(("p", "q", "r")), filename="pqr.csv")
    assert s.install(other, channel="r"), s.error
    assert (s.channel, app.channel_select.value, root.value) == ("r", "r", "r")
    assert s.from_query({"channel": "gyro_y", "model": "WN"}), s.error
    assert (s.channel, app.channel_select.value, root.value) == ("gyro_y",) * 3
    assert s.wv is not None and s.result is not None and s.result.wv is s.wv
    assert [v for v, _ in root.options] == list(s.channels) == list(s.param.channel.objects)


def test_channel_widget_and_state_follow_each_other_with_one_wv_job(
    app: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = app.state
    assert s.set_model("WN+RW"), s.error
    jobs = _count(monkeypatch, app.jobs, "load")
    plot = _count(monkeypatch, app.views, "update")
    tables = _count(monkeypatch, app.tables, "update")
    wvs = _count(monkeypatch, state_mod, "compute_wv")
    # widget -> state: one WV job (inline without a server), the WV and fit shown once
    app.channel_select.value = "accel_x"
    assert s.channel == "accel_x" and s.wv.n == s.n and s.unit == "m/s^2", s.error
    assert s.result is not None and s.result.wv is s.wv
    assert (len(jobs), len(wvs), len(plot), len(tables)) == (1, 1, 1, 1)
    assert app.status.object == "" and not app.busy  # the job's indicator came and went
    # state -> widget, the parameter set alone: the state starts the job itself
    s.channel = "gyro_y"
    assert app.channel_select.value == "gyro_y" and s.wv is not None
    assert s.result is not None and s.result.wv is s.wv
    assert (len(jobs), len(wvs), len(plot), len(tables)) == (2, 2, 2, 2)
    # back to a channel computed already: a job, no WV computed
    app.channel_select.value = "accel_x"
    assert s.channel == "accel_x" and (len(jobs), len(wvs), len(plot)) == (3, 2, 3)
    # the action itself: no job, the widget follows
    assert s.select_channel("gyro_x"), s.error
    assert app.channel_select.value == "gyro_x" and (len(jobs), len(plot)) == (3, 4)


def test_exports_describe_the_data_shown_while_a_channels_wv_is_computed(app: Any) -> None:
    """On a served page the WV job ends later: meanwhile the channel chosen is not yet the
    data's, and the exports (JSON, file names) describe the WV and fit shown."""
    s = app.state
    assert s.set_model("WN+RW"), s.error
    pending: list[Any] = []
    s.wv_job = lambda message, work, apply, fail: pending.append((message, work, apply))
    wv, res = s.wv, s.result
    app.channel_select.value = "accel_x"  # the job starts, and waits
    assert s.channel == "accel_x" and s.wv is wv and s.result is res
    assert [m for m, _, _ in pending] == ["Computing the wavelet variance of accel_x"]
    data = json.loads(app._export_json().getvalue())["data"]
    assert data["channel"] == "gyro_x" == s.shown["channel"] and data["unit"] == "deg/s"
    assert "_gyro_x_" in app.download.filename and "_gyro_x_" in s.export_filename()
    _, work, apply = pending[0]
    work(lambda j, n: None)  # the worker, then the loop's continuation
    apply(None)
    assert s.wv is not wv and s.result.wv is s.wv and s.shown["channel"] == "accel_x"
    data = json.loads(app._export_json().getvalue())["data"]
    assert data["channel"] == "accel_x" and data["unit"] == "m/s^2"
    assert "_accel_x_" in app.download.filename


def test_robust_widget_and_state_follow_each_other_with_one_wv_job(
    app: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = app.state
    jobs = _count(monkeypatch, app.jobs, "load")
    plot = _count(monkeypatch, app.views, "update")
    app.robust_check.value = True  # widget -> state
    assert s.robust and s.wv.robust, s.error
    assert (len(jobs), len(plot)) == (1, 1)
    s.robust = False  # state -> widget: the classical WV shown again (carried by the robust)
    assert app.robust_check.value is False and not s.wv.robust
    assert (len(jobs), len(plot)) == (2, 2)


def test_fs_widget_relabels_at_once_and_a_refused_fs_is_put_back(
    app: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = app.state
    assert s.set_model("GM+WN"), s.error
    fs0, tau0, beta0 = s.fs, s.wv.tau_s.copy(), s.result.params["GM.beta"]
    jobs = _count(monkeypatch, app.jobs, "load")
    plot = _count(monkeypatch, app.views, "update")
    tables = _count(monkeypatch, app.tables, "update")
    app.fs_input.value = fs0 / 2  # widget -> state: re-labelled, no job, one redraw
    assert s.fs == fs0 / 2 and s.fs_source == "user", s.error
    np.testing.assert_allclose(s.wv.tau_s, 2 * tau0)
    assert s.result.params["GM.beta"] == pytest.approx(beta0 / 2, rel=1e-6)
    assert (len(jobs), len(plot), len(tables)) == (0, 1, 1)
    s.fs = fs0  # state -> widget
    assert app.fs_input.value == fs0 and s.wv.fs == fs0 and s.fs_source == "file"
    assert (len(jobs), len(plot), len(tables)) == (0, 2, 2)
    # refused (above the largest sampling frequency the engine accepts): one line, and the
    # previous value back in the state and in the widget; nothing redrawn
    wv = s.wv
    app.fs_input.value = 2e9
    assert s.error.count("\n") == 0 and "Could not set the sampling frequency" in s.error
    assert "2e+09" in s.error or "2000000000" in s.error
    assert s.fs == fs0 == app.fs_input.value and s.wv is wv
    assert (len(plot), len(tables)) == (2, 2)
    assert app.alert.visible
    # the session keeps working: the next change is shown and clears the message
    app.fs_input.value = 2 * fs0
    assert s.fs == 2 * fs0 and s.wv.fs == 2 * fs0 and s.error == ""


# ---------------------------------------------------------------------------------------------
# the Fit tab's intervals are the state's
# ---------------------------------------------------------------------------------------------
def _interval_numbers(intervals: Any) -> tuple[list[str], np.ndarray]:
    return [i.name for i in intervals], np.array([(i.value, i.low, i.high) for i in intervals])


def _check_fit_tab_intervals(app: Any) -> None:
    """Intervals shown on the Fit tab: computed by the state, no other tab built, and the
    numbers of the engine's asymptotic 95 % intervals of the fit shown."""
    s = app.state
    assert s.set_show_intervals(True)
    assert list(app.lazy_views) == []  # the Model selection tab was not built for them
    inf = s.inference()
    assert inf is not None and inf.result is s.result and s.inferred is inf
    ref = eg.inference.param_intervals(s.result, method="asymptotic", level=0.95)
    (names, got), (ref_names, want) = _interval_numbers(inf.intervals), _interval_numbers(ref)
    assert names == ref_names == list(s.result.params)
    np.testing.assert_array_equal(got, want)  # the same numbers, bit for bit
    shown = app.tables.param_source.data
    n = len(ref)  # the model's rows come first, then the IEEE quantities
    assert list(shown["low"][:n]) == [state_mod.format_value(i.low) for i in ref]
    assert list(shown["high"][:n]) == [state_mod.format_value(i.high) for i in ref]
    assert np.all((want[:, 1] < want[:, 0]) & (want[:, 0] < want[:, 2]))  # estimate inside


def test_the_fit_tabs_intervals_are_owned_by_the_state(app: Any) -> None:
    assert app.state.set_model("GM+WN+RW"), app.state.error
    _check_fit_tab_intervals(app)
    # the Model selection tab, opened later, reads the same cached intervals
    assert app.selection.state.inference() is app.state.inferred


def test_the_fit_tabs_intervals_on_a_real_log(app: Any, real_data: Path) -> None:
    s = app.state
    assert s.load_path(real_data / "adis16405_imu1.h5"), s.error
    assert s.select_channel("gyro_x") and s.set_model("WN+RW"), s.error
    _check_fit_tab_intervals(app)


# ---------------------------------------------------------------------------------------------
# failures reach the page and the log
# ---------------------------------------------------------------------------------------------
def test_a_failed_wv_job_is_shown_and_logged(
    app: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    calls = []

    def broken(
        lg: Any, ch: str, fs: float, robust: bool, progress: Any = None, compensate: bool = True
    ) -> Any:
        calls.append(ch)
        raise ValueError(f"channel {ch}: the series has 3 NaN values")

    monkeypatch.setattr(state_mod, "compute_wv", broken)
    with caplog.at_level(logging.WARNING):
        app.channel_select.value = "accel_x"  # warm in a job (inline without a server)
    s = app.state
    assert "accel_x: the series has 3 NaN values" in s.error
    assert app.alert.visible and "3 NaN values" in app.alert.object
    assert any("3 NaN values" in r.getMessage() for r in caplog.records)
    assert calls == ["accel_x"]  # computed once (warm), not again by select_channel
    assert s.channel == "gyro_x"  # the session keeps its channel
    assert app.channel_select.value == "gyro_x"  # ... and its widget shows it


def test_a_failed_precompute_is_reported_once_and_logged(
    app_demo: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    calls = []

    def broken(
        lg: Any, ch: str, fs: float, robust: bool, progress: Any = None, compensate: bool = True
    ) -> Any:
        calls.append(ch)
        raise ValueError(f"channel {ch}: fewer than 8 samples")

    monkeypatch.setattr(data_mod, "compute_wv", broken)
    monkeypatch.setattr(state_mod, "compute_wv", broken)
    s = AppState()
    with caplog.at_level(logging.WARNING):
        assert not s.from_query({"channel": "accel_y"})
    assert "accel_y: fewer than 8 samples" in s.error and s.wv is None
    assert calls == ["accel_y"]  # the install reports precompute's failure, no second try
    assert any("fewer than 8 samples" in r.getMessage() for r in caplog.records)


def test_a_failed_redraw_is_shown_and_logged_and_the_action_stands(
    app: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def broken(_state: Any) -> None:
        raise RuntimeError("glyph trouble")

    monkeypatch.setattr(app.views, "update", broken)
    with caplog.at_level(logging.ERROR):
        assert app.state.set_model("WN+RW")  # the action succeeded
    s = app.state
    assert s.model.spec() == "WN+RW" and s.result is not None
    assert "Display error in the WV plot: RuntimeError: glyph trouble" in s.error
    assert app.alert.visible and "glyph trouble" in app.alert.object
    rec = [r for r in caplog.records if "drawing the WV plot failed" in r.getMessage()]
    assert rec and rec[0].exc_info is not None  # with its traceback
    # the other parts were drawn
    procs = list(app.tables.param_source.data["process"])
    # the model's parameters, then the fit's IEEE quantities (engine/fit/ieee.py)
    assert procs[:2] == ["WN", "RW"] and set(procs[2:]) == {"IEEE"}


def test_a_failed_session_panel_refresh_is_shown_and_logged(
    app: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def broken(*_a: Any, **_kw: Any) -> None:
        raise KeyError("no such format")

    monkeypatch.setattr(app.session_panel.preview, "update", broken)
    with caplog.at_level(logging.ERROR):
        assert app.state.set_model("WN+RW")
    assert "Display error in the export and session buttons" in app.state.error
    assert any(r.exc_info for r in caplog.records if "export and session" in r.getMessage())


def test_unexpected_errors_are_logged_with_their_traceback(
    app: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    s = app.state

    def broken(*_a: Any, **_kw: Any) -> None:
        raise RuntimeError("solver exploded")

    monkeypatch.setattr(AppState, "_fit_or_none", broken)
    # a bug is raised out of the action to the app's error boundary (gmwm_app.boundary), which
    # Panel calls with the session's document current (tests/app/test_error_boundary.py)
    doc = Document()
    boundary.attach(doc, s.report_error)
    with caplog.at_level(logging.ERROR), set_curdoc(doc):
        pn.state.execute(lambda: s.set_model("WN+RW"), schedule=False)
    assert s.error == "Could not update the page: unexpected RuntimeError: solver exploded"
    assert app.alert.visible and "solver exploded" in app.alert.object
    assert any(r.exc_info and "solver exploded" in r.getMessage() for r in caplog.records)
    # a job's unexpected failure, too
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        app._load_failed("Reading x.csv", MemoryError("no room"))
    assert s.error == "Reading x.csv: unexpected MemoryError: no room"
    assert any(r.exc_info for r in caplog.records)


# ---------------------------------------------------------------------------------------------
# the WV cache
# ---------------------------------------------------------------------------------------------
def test_wv_cache_maps_and_eviction() -> None:
    rng = np.random.default_rng(1)
    x = rng.standard_normal(2**12)
    wv = eg.wavelet_variance(x, fs=100.0)
    rob = eg.wavelet_variance(x, fs=100.0, robust=True)
    c = WVCache()
    assert c.find("a", 100.0, False, False) is None
    c.store("a", 100.0, True, False, rob)  # the robust WV carries the classical one
    assert c.find("a", 100.0, True, False) is rob
    assert c.find("a", 100.0, False, False) is rob.classical
    relabelled = c.find("a", 50.0, False, False)  # another fs: the same WV re-labelled, kept
    assert relabelled is not None and relabelled.fs == 50.0
    np.testing.assert_array_equal(relabelled.variance, rob.classical.variance)
    assert c.wvs[("a", 50.0, False, False)] is relabelled
    # the compensated signal's WV is another WV: never derived from the raw one's
    assert c.find("a", 100.0, False, True) is None
    assert c.find("b", 100.0, False, False) is None
    c.store("b", 100.0, False, False, wv)
    # matrices: their own map, the latest N_WV_MATRICES kept
    for k in range(N_WV_MATRICES + 2):
        c.store_matrix(("a", "b"), float(k + 1), (k, f"note {k}"))  # type: ignore[arg-type]
    assert list(c.matrices) == [
        (("a", "b"), float(k + 1), "off") for k in range(2, N_WV_MATRICES + 2)
    ]
    assert c.matrix(["a", "b"], 1.0) is None and c.matrix(["a", "b"], 3.0) == (2, "note 2")
    assert c.matrix(["a", "b"], 3.0, compensate="auto") is None
    assert set(c.wvs) == {("a", 100.0, True, False), ("a", 100.0, False, False),
                          ("a", 50.0, False, False), ("b", 100.0, False, False)}  # fmt: skip


def test_a_state_change_reaches_the_page_as_one_held_batch(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Every part a click redraws is drawn while the session's document is held, so Bokeh
    sends one message (a button's callback is not held by Panel: 19 messages a click)."""
    from bokeh.document import Document
    from panel.io.state import set_curdoc

    from gmwm_app.app import create_app

    doc = Document()
    with set_curdoc(doc):
        page = create_app(load=False)
        page.server_doc(doc)
        app = page.gmwm_app
        app.start_sync()
        held: list[Any] = []
        for obj, name in ((app.views, "update"), (app.tables, "update")):
            real = getattr(obj, name)

            def seen(*a: Any, _real: Any = real, **kw: Any) -> Any:
                held.append(doc.callbacks.hold_value)
                return _real(*a, **kw)

            monkeypatch.setattr(obj, name, seen)
        assert app.jobs.doc is doc
        assert app.state.add_process("GM"), app.state.error
        assert held == ["combine", "combine"]  # the plot and the tables, inside one hold
        assert doc.callbacks.hold_value is None  # released after the change
        # the loading indicator of a job: its text and widgets together, one message
        held.clear()
        app.status.param.watch(lambda _e: held.append(doc.callbacks.hold_value), "object")
        app._busy(True, "Reading x")
        app._busy(False)
        assert held == ["combine", "combine"] and doc.callbacks.hold_value is None
