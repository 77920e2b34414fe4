"""A process added as one engine class reaches the app: its button, fit, sliders, colour.

MA1 (``engine/models/ma1.py``) is that process: nothing in ``gmwm_app`` names it.
"""

from __future__ import annotations

import math

import pytest

import engine as eg
from engine.models import Param
from gmwm_app.state import PROCESS_CODES, PROCESS_NAMES, AppState
from gmwm_app.views import component_color
from gmwm_app.whatif import SliderSpec


def test_the_app_adds_fits_and_slides_an_ma1(app_state: AppState) -> None:
    s = app_state
    assert "MA1" in PROCESS_CODES and PROCESS_NAMES["MA1"] == "MA(1)"
    assert s.set_model("RW"), s.error
    assert s.add_process("MA1"), s.error
    assert s.model.spec() == "RW+MA1"
    # the app's fit is the engine's fit of the same WV
    direct = eg.fit_gmwm(s.wv, "RW+MA1")
    assert s.result.objective == pytest.approx(direct.objective, rel=1e-9)
    assert s.result.params == pytest.approx(direct.params, rel=1e-6)
    specs = {sp.name: sp for sp in s.slider_specs()}
    assert set(specs) == {"RW.gamma2", "MA1.theta", "MA1.sigma2"}
    th = specs["MA1.theta"]
    # a coefficient of either sign: a linear slider over its bounds, as MA1 declares
    assert th.transform == "linear" and th.unit == "1 (per sample)"
    assert (th.lo, th.hi) == pytest.approx((-0.998, 0.998))
    assert th.value_of(th.x) == pytest.approx(s.result.params["MA1.theta"])
    assert specs["MA1.sigma2"].transform == "log10" and specs["MA1.sigma2"].hi - specs[
        "MA1.sigma2"
    ].lo == pytest.approx(6.0)
    assert s.set_whatif(True)
    assert s.set_whatif_value("MA1.theta", -0.5), s.error
    assert s.display_model().values()["MA1.theta"] == -0.5
    assert not s.set_whatif_value("MA1.theta", 1.5) and "theta" in s.error
    assert component_color("MA1") == eg.models.PROCESS_TYPES["MA1"].color


def test_the_app_refuses_ma1_beside_white_noise_and_keeps_the_session(
    app_state: AppState,
) -> None:
    s = app_state
    assert s.set_model("WN+RW"), s.error
    before = s.result.objective
    assert not s.add_process("MA1")
    assert "mixes MA1 and WN" in s.error
    assert s.model.spec() == "WN+RW" and s.result.objective == before
    assert s.add_process("GM"), s.error  # still usable
    assert math.isfinite(s.result.objective)


def test_linear_slider_spans_the_bounds_less_a_thousandth_each_end() -> None:
    spec = Param("atanh", bounds=(-1.0, 1.0), slider="linear")
    sp = SliderSpec.around("X.t", "X", "t", "1", spec, -0.25)
    assert (sp.lo, sp.hi, sp.x) == pytest.approx((-0.998, 0.998, -0.25))
    assert sp.value_of(0.3) == 0.3 and SliderSpec.position_of("linear", -0.7) == -0.7
    assert SliderSpec.shows("linear", 0.0) and not SliderSpec.shows("log10", 0.0)
    # a log slider: 3 decades either side of the value, as before
    sp = SliderSpec.around("X.v", "X", "v", "1", Param(), 0.5)
    assert (sp.lo, sp.hi) == pytest.approx((math.log10(0.5) - 3, math.log10(0.5) + 3))
