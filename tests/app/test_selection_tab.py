"""Browser-free tests of the app's model selection: ranking, row click, cancel, intervals.

The app's numbers must be the engine's: the ranked table is ``rank_models`` on the session's
WV, the interval columns are ``param_intervals`` of the fit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from engine.inference import JTest, j_test, param_intervals, rank_models
from gmwm_app.selection_view import jtest_badge, ranking_data
from gmwm_app.state import AppState, Inference, format_value

SMALL = "GM+WN+RW"


def test_ranking_through_the_state_equals_rank_models(app_state: AppState) -> None:
    s = app_state
    assert s.rank(SMALL), s.error
    ref = rank_models(s.wv, max_model=SMALL, weights=s.weights)
    got = s.selection
    assert [c.model for c in got.candidates] == [c.model for c in ref.candidates]
    assert got.table().splitlines()[1:] == ref.table().splitlines()[1:]
    a, b = ranking_data(got), ranking_data(ref)
    assert a["model"] == b["model"] and a["note"] == b["note"]
    for k in ("rank", "n_params", "objective", "optimism", "criterion", "j_p_value"):
        np.testing.assert_allclose(a[k], b[k], rtol=1e-12)
    # candidate lists (comma separated) too
    assert s.rank("WN+RW, GM+WN"), s.error
    assert sorted(c.model for c in s.selection.candidates) == ["GM+WN", "WN+RW"]


def test_bad_spec_is_a_message_and_keeps_the_table(app_state: AppState) -> None:
    s = app_state
    assert s.rank(SMALL)
    before = s.selection
    assert not s.rank("FOO+BAR")
    assert s.error.startswith("Could not rank the models") and "Traceback" not in s.error
    assert s.selection is before
    assert not s.rank("  ")
    assert "maximal model" in s.error


def test_view_table_and_row_click_loads_the_candidate(app: Any) -> None:
    v, s = app.selection, app.state
    v.start_ranking(SMALL)
    assert not v.running and s.error == ""
    ref = rank_models(s.wv, max_model=SMALL, weights=s.weights)
    assert list(v.source.data["model"]) == [c.model for c in ref.candidates]
    np.testing.assert_allclose(
        v.source.data["criterion"], [c.criterion for c in ref.candidates], rtol=1e-12
    )
    assert "Ranked 7 candidates" in v.status.object
    # the comparison: two candidates, their curves and parameters with intervals
    assert v.compare_a.value == ref.candidates[0].model
    assert v.compare_b.value == ref.candidates[1].model
    assert v.fig_a.total.data["wv"].size > 0 and v.fig_b.total.data["wv"].size > 0
    assert sum(r.visible for r in v.fig_a.comp_renderers) == 3
    rows = v.compare_source.data
    assert "…" not in rows["low"] and len(rows["parameter"]) == 4 + 3
    # click the third row
    cand = ref.candidates[2]
    v.source.selected.indices = [2]
    assert s.model.spec() == cand.model
    for k, val in cand.result.params.items():
        assert s.result.params[k] == pytest.approx(val, rel=1e-9)
    assert list(app.tables.param_source.data["process"])[0] == cand.model.split("+")[0]
    assert "Loaded" in v.status.object


def test_cancel_stops_and_keeps_the_previous_table(app: Any) -> None:
    v, s = app.selection, app.state
    v.start_ranking(SMALL)
    before, models = s.selection, list(v.source.data["model"])
    seen: list[tuple[int, int]] = []

    def observer(done: int, total: int) -> None:
        seen.append((done, total))
        if done == 2:
            v.cancel()

    v.start_ranking("3*GM+WN+QN+RW+DR", observer=observer)
    assert seen[-1][0] == 2 and seen[-1][1] > 2  # stopped at the next candidate
    assert s.selection is before and list(v.source.data["model"]) == models
    assert "cancelled" in v.status.object and s.error == ""
    assert not v.running and not v.rank_button.disabled and v.cancel_button.disabled


def test_interval_columns_equal_param_intervals(app: Any) -> None:
    s = app.state
    assert s.set_model("GM+WN+RW")
    data = app.tables.param_source.data
    assert set(data["low"]) == {""}

    def shown() -> list[str]:
        return [c.field for c in app.tables.params.columns]

    assert "low" not in shown()
    app.intervals_check.value = True
    assert s.show_intervals and shown() == ["process", "parameter", "value", "low", "high", "unit"]
    ref = param_intervals(s.result, method="asymptotic", level=0.95)
    data = app.tables.param_source.data
    # the parameters' rows first (the fit's IEEE quantities follow, with their own intervals)
    assert list(data["low"])[: len(ref)] == [format_value(i.low) for i in ref]
    assert list(data["high"])[: len(ref)] == [format_value(i.high) for i in ref]
    ieee = s.result.ieee.quantities.values()
    assert list(data["low"])[len(ref) :] == [format_value(q.datasheet_low) for q in ieee]
    inf = s.inference()
    for a, b in zip(inf.intervals, ref, strict=True):
        assert (a.name, a.low, a.high, a.unit) == (b.name, b.low, b.high, b.unit)
    jt = j_test(s.result)
    assert inf.j_test == jt
    assert app.jtest_pane.visible and f"df = {jt.df}" in app.jtest_pane.object
    # cached per fit: the same fit is not recomputed, a new fit gets its own
    assert s.inference() is inf
    assert s.set_model("WN+RW")
    assert s.inference() is not None and s.inference() is not inf
    assert [r for r in app.tables.param_source.data["low"]] != ["", ""]
    app.intervals_check.value = False
    assert "low" not in shown() and not app.jtest_pane.visible


def test_jtest_badge_colours() -> None:
    def badge(p: float) -> str:
        return jtest_badge(Inference(None, [], JTest(3.0, 5, p, "asymptotic")))

    assert "#2E7D32" in badge(0.2) and "#E69F00" in badge(0.03) and "#C62828" in badge(0.001)
    assert "df = 5" in badge(0.2) and "T = 3" in badge(0.2)
    assert "n/a" in jtest_badge(Inference(None, [], None, "J - p = 0"))
    assert jtest_badge(None) == "" and "computing" in jtest_badge(None, pending=True)


def test_a_drift_too_strong_for_a_p_value_says_n_c_everywhere(app: Any, tmp_path: Any) -> None:
    # WN + RW + a drift whose share of Var(nu_j) is far above DRIFT_SHARE_MAX at the estimate
    # (2^14 samples): the J-test has no calibrated p-value (docs/jtest.md); the ranking's
    # table, the comparison's titles and the Fit badge say "n/c" / "not calibrated" with the
    # engine's reason, never a number
    import engine as eg

    x = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)+DR(omega=3e-2)").simulate(
        2**14, fs=100.0, rng=np.random.default_rng(6)
    )
    path = eg.io.save_log(tmp_path / "drift.h5", {"gyro_x": x}, fs=100.0, units={"gyro_x": "deg/s"})
    v, s = app.selection, app.state
    assert s.load_path(path), s.error
    v.start_ranking("WN+RW+DR")
    assert not v.running and s.error == ""
    sel = s.selection
    assert sel.j_note.startswith("not calibrated: the drift's share")
    assert np.all(np.isnan(v.source.data["j_p_value"]))
    assert all(sel.j_note in note for note in v.source.data["note"])
    assert "J-test p n/c" in v.fig_a.figure.title.text
    jt = j_test(sel.candidates[0].result)
    assert not jt.calibrated and jt.note.startswith("not calibrated: the drift's share")
    badge = jtest_badge(Inference(None, [], jt))
    assert "not calibrated" in badge and "p =" not in badge
