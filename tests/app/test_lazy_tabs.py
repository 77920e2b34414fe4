"""The skeleton shared by the lazily built tabs (``gmwm_app.tab_view.TabView``).

Each tab depends on the state parameters it draws (``param.depends("state.<name>")``), not
on a catch-all counter: one ``param.update`` of several of them redraws once, a change of a
parameter it does not draw redraws nothing, a hidden tab waits until shown, and a failure
(of a refresh or of a background job) reaches the tab as a message and the log, never Panel.
The widget callbacks are idempotent: the echo of a widget the tab itself updates is a no-op.
"""

from __future__ import annotations

import logging
from typing import Any

import pytest

from gmwm_app import slope_view
from gmwm_app.check_view import CheckView
from gmwm_app.multi_view import MultiView
from gmwm_app.plan_view import PlanView
from gmwm_app.selection_view import SelectionView
from gmwm_app.slope_view import SlopeView
from gmwm_app.tab_view import TabView

VIEWS = {
    "Model selection": SelectionView,
    "Slope method": SlopeView,
    "Multi-channel": MultiView,
    "Datasheet check": CheckView,
    "Plan": PlanView,
}
TITLES = list(VIEWS)


def _open(app: Any, title: str) -> Any:
    """A shown tab of the session's state, on its own (the Fit page does not drive it)."""
    view = VIEWS[title](app.state, app.jobs, active=True)
    assert isinstance(view, TabView)
    return view


def _count_draws(view: Any, monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    calls: list[bool] = []
    draw = view._draw

    def counted(force: bool) -> None:
        calls.append(force)
        draw(force)

    monkeypatch.setattr(view, "_draw", counted)
    return calls


@pytest.mark.parametrize("title", TITLES)
def test_one_update_of_several_parameters_draws_once(
    app: Any, title: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    view = _open(app, title)
    calls = _count_draws(view, monkeypatch)
    s = app.state
    # a channel switch changes wv, channel, unit, n, duration_s, result ... in one update
    other = [c for c in s.channels if c != s.channel][0]
    assert s.select_channel(other), s.error
    wanted = {  # the parameters each tab draws: a channel switch is one of them, or not
        "Model selection": 0,  # draws the ranking, its intervals and the unit (unchanged)
        "Slope method": 1,
        "Multi-channel": 1,  # a new WV (its own cheap key then sees the same log)
        "Datasheet check": 1,
        "Plan": 0,  # draws the fit and n: no fit yet (None to None), the same n
    }
    assert len(calls) == wanted[title], calls
    # a change the tab does not draw (a message of the page) draws nothing
    calls.clear()
    s.report_error("something else went wrong")
    s.param.update(show_intervals=True, notice="a notice")
    assert calls == []


def test_the_selection_tab_draws_a_new_ranking_and_new_intervals(
    app: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    view = _open(app, "Model selection")
    calls = _count_draws(view, monkeypatch)
    picks: list[tuple[Any, Any]] = []
    update = view.fig_a.update

    def seen(*args: Any) -> None:
        picks.append((view.compare_a.value, view.compare_b.value))
        update(*args)

    monkeypatch.setattr(view.fig_a, "update", seen)
    assert app.state.rank("WN+RW, GM+WN, WN"), app.state.error
    # the ranking, then the intervals of the two compared candidates (computed at once here)
    assert len(calls) == 3, calls
    names = [c.model for c in app.state.selection.candidates]
    final = (names[0], names[1])
    assert (view.compare_a.value, view.compare_b.value) == final
    # never drawn with a picker of the previous ranking (the guard-free update of both)
    assert picks and set(picks) == {final}, picks


@pytest.mark.parametrize(
    "title",
    # the Multi-channel tab's first multivariate fit: 11 s of CPU, the slow tier
    [pytest.param(t, marks=pytest.mark.slow) if t == "Multi-channel" else t for t in TITLES],
)
def test_a_hidden_tab_waits_until_shown(
    app: Any, title: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    view = _open(app, title)
    calls = _count_draws(view, monkeypatch)
    view.active = False  # another tab is shown
    monkeypatch.setattr(view, "_visible", lambda: view.active)  # as on a server
    s = app.state
    assert s.set_fs(s.fs * 2), s.error
    assert s.set_robust(True), s.error
    if title == "Model selection":  # draws neither: a new ranking instead
        assert s.rank("WN+RW, WN"), s.error
    if title == "Plan":  # draws neither: a fit instead
        assert s.set_model("WN+RW"), s.error
    assert calls == [] and view._dirty
    view.active = True
    # drawn when shown (the selection tab draws again when its intervals arrive: at once here)
    assert calls[0] is False and len(calls) == (3 if title == "Model selection" else 1)
    assert not view._dirty
    n = len(calls)
    view.active = False
    view.active = True
    assert len(calls) == n  # nothing changed meanwhile: nothing drawn


@pytest.mark.parametrize(
    "title",
    # the Multi-channel tab's first multivariate fit: 7 s of CPU, the slow tier
    [pytest.param(t, marks=pytest.mark.slow) if t == "Multi-channel" else t for t in TITLES],
)
def test_a_failing_refresh_is_a_message_and_a_log_record(
    app: Any, title: str, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    view = _open(app, title)

    def boom(force: bool) -> None:
        raise RuntimeError("boom in the drawing")

    monkeypatch.setattr(view, "_draw", boom)
    s = app.state
    with caplog.at_level(logging.ERROR, logger="gmwm_app.tab_view"):
        assert s.set_fs(s.fs * 2), s.error  # the tab raises: the session does not
        if title == "Model selection":  # draws a ranking
            assert s.rank("WN+RW, WN"), s.error
        if title == "Plan":  # draws a fit
            assert s.set_model("WN+RW"), s.error
    assert s.error == ""
    assert view.message.visible and "boom in the drawing" in view.message.object
    assert "Traceback" not in view.message.object
    recs = [r for r in caplog.records if "refresh failed" in r.getMessage()]
    assert len(recs) == 1 and recs[0].exc_info is not None
    assert recs[0].exc_info[1].args == ("boom in the drawing",)


def test_a_failing_job_is_a_message_and_a_log_record_with_its_traceback(
    app: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    view = _open(app, "Slope method")

    def broken(*_args: Any, **_kw: Any) -> Any:
        raise RuntimeError("the slope computation broke")

    monkeypatch.setattr(slope_view, "compute_slope", broken)
    with caplog.at_level(logging.ERROR, logger="gmwm_app.tab_view"):
        view.set_region("WN", 0.01, 1.0)
    assert view.message.visible and "the slope computation broke" in view.message.object
    assert not view.computing
    recs = [r for r in caplog.records if "job failed" in r.getMessage()]
    assert len(recs) == 1 and recs[0].exc_info is not None  # the worker's traceback


def test_check_fields_set_or_filled_from_a_file_compute_once(
    app: Any, datasheet_checks: list[Any]
) -> None:
    view = _open(app, "Datasheet check")
    checks = datasheet_checks
    checks.clear()  # from here: the tab's first check (of its default fields) is not counted
    view.set_values({"arw": "0.5", "bi": "7", "rrw": "1", "q": ""})
    assert len(checks) == 1 and [w.value for w in view.inputs] == ["0.5", "7", "1", ""]
    fs = app.state.fs
    view.load_file(f"update_rate: {fs}\ngyroscope_noise_density: 2e-4\n".encode(), "imu.yaml")
    # the file's exact values are checked (not the fields' 4 digits), once
    assert len(checks) == 2 and checks[-1] is view.file_spec is not None
    # typing in a field: the user's values from then on
    view.inputs[1].value = "3"
    assert len(checks) == 3 and view.file_spec is None and view.texts[1] == "3"
    view.inputs[1].value = "3"  # no change: nothing
    assert len(checks) == 3


@pytest.mark.slow  # multivariate fits: 11 s of CPU
def test_multi_channel_echoes_and_repeated_requests_do_not_refit(app: Any) -> None:
    view = _open(app, "Multi-channel")
    fits, result = view.n_fits, view.result
    assert result is not None and view.error == ""
    view.controls.refresh_share_widgets()  # the shared-process widgets shown again
    view.request_fit()  # the settings of the fit shown
    view.refresh(force=True)  # the channels offered again
    assert view.n_fits == fits and view.result is result
    # marking one channel only is no sharing: the same settings, no new fit
    view.set_shared("WN", ["gyro_x"])
    assert view.n_fits == fits
    view.set_shared("WN", ["gyro_x", "gyro_y"])
    assert view.n_fits == fits + 1
    assert tuple(view.result.shared["WN"].channels) == ("gyro_x", "gyro_y")
