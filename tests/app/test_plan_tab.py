"""The app's "Plan" tab (gmwm_app.plan_view): the run plan of the Fit tab's model, with this
log's length and the targets drawn, and one sentence per target."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

import engine as eg
from engine.inference import plan_precision
from gmwm_app.plan_view import PlanView


def _rel(q: Any) -> float:
    return max(q.high / q.value - 1.0, 1.0 - q.low / q.value)


def test_the_plan_tab_plans_for_the_fit_and_says_what_this_log_gives(app: Any) -> None:
    s = app.state
    view = PlanView(s, app.jobs, active=True)
    assert view.message.visible and "Fit a model" in view.message.object  # no fit yet
    assert s.set_model("GM+WN+RW"), s.error
    assert s.result is not None and s.result.model.is_set
    view.targets.value = "K within 20 %, N within 2 %"
    plan = view.plan
    assert plan is not None and plan.model == s.result.model
    assert plan.fs == s.fs and set(plan.required) == {"K", "N"}
    # the plot: finite precisions of N in %, the demo's 2000 s as the vertical line
    n_pct = np.asarray(view.source.data["N"], float)
    assert np.isfinite(n_pct).any() and np.nanmax(n_pct) < 1000
    assert view.now_line.visible and view.now_line.location == pytest.approx(s.n / s.fs / 3600)
    assert view.target_lines["K"].visible and view.target_lines["K"].location == 20.0
    assert not view.target_lines["Q"].visible
    # one sentence per target, with this log's own precision (the plan at its length)
    text = view.status.object
    assert text.count("needs") == 2
    now = plan_precision(plan.model, plan.fs, s.n, unit=plan.unit)
    assert f"+-{100 * _rel(now['N']):.3g} %" in text


def test_a_bad_target_or_no_fit_is_a_message_not_an_error(app: Any) -> None:
    assert app.state.set_model("WN+RW"), app.state.error
    view = PlanView(app.state, app.jobs, active=True)
    view.targets.value = "K within ten %"
    assert view.message.visible and "not of the form" in view.message.object
    view.targets.value = "K within 20 %"
    assert not view.message.visible
    assert app.state.clear_model()
    assert app.state.result is None
    assert view.message.visible and "Fit a model" in view.message.object


def test_a_twenty_minute_log_gives_no_rate_random_walk_sentence() -> None:
    m = eg.inference.parse_datasheet("arw=0.15 deg/sqrt(h), rrw=2 deg/h/sqrt(h)").model(
        100.0, "deg/s"
    )
    plan = eg.plan_run(m, 100.0, "K within 10 %", unit="deg/s")
    (line,) = plan.sentences(20 * 60 * 100)
    assert "needs 63.8 h of log" in line and "this log (20 min)" in line
    k = plan_precision(m, 100.0, 20 * 60 * 100, unit="deg/s")["K"]
    assert _rel(k) > 9.99 and "no usable value" in line
    assert math.isfinite(k.value)


def test_a_fit_with_a_drift_is_planned_not_a_memory_error(app: Any, tmp_path: Any) -> None:
    """Was: the plan of a model with a drift built arrays of up to 3.6e8 values for the
    plan's 1000 h (the class server's memory, or a MemoryError shown as 'Could not plan').
    Now the drift's share of V is in closed form; the tab answers with finite numbers."""
    s = app.state
    x = eg.parse_model("WN(sigma2=1)+DR(omega=1e-3)").simulate(
        50_000, fs=100.0, rng=np.random.default_rng(3)
    )
    np.save(tmp_path / "drift.npy", x)
    assert s.load_path(tmp_path / "drift.npy"), s.error
    assert s.set_fs(100.0), s.error
    assert s.set_model("WN+DR"), s.error
    assert s.result is not None
    (drift,) = [p for p in s.result.model.processes if p.code == "DR"]
    assert drift.omega > 0  # the drift is fitted
    view = PlanView(s, app.jobs, active=True)
    view.targets.value = "N within 1 %, R within 20 %"
    assert not view.message.visible, view.message.object
    plan = view.plan
    assert plan is not None and plan.required["N"] is not None and plan.required["R"] is not None
    assert plan.achieved["N"] <= 0.01 and plan.achieved["R"] <= 0.20
    assert np.isfinite(view.source.data["N"]).all()
    assert view.status.object.count("needs") == 2
