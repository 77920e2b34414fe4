"""The "virtual sensor" view of the Multi-channel tab (gmwm_app/virtual_view.py), browser-free.

The numbers shown must be the engine's (``engine.virtual_sensor`` of the tab's fit); on a
simulated array of two negatively correlated, unequal gyros the view's weights are the
closed form of the model's WV matrix and beat the plain average; the export is the
single-channel export of the virtual sensor's model; bad input is a message.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import engine as eg
from engine.multivariate import MultiModel
from gmwm_app.virtual_view import EXPORT_FORMATS, VirtualView, parse_target

TITLE = "Multi-channel"
FS = 100.0


def open_view(app: Any) -> Any:
    v = app.open_view(TITLE)
    app.tabs.active = list(app.tabs._names).index(TITLE)
    return v


@pytest.fixture
def array_log(tmp_path: Path) -> Path:
    truth = MultiModel(
        ["imu_a", "imu_b"],
        "GM+WN",
        shared=["GM", "WN"],
        cov={
            "WN": np.diag([1e-3, 1e-3]),
            "GM": np.array([[1.0, -0.6], [-0.6, 4.0]]) * 1e-3,
        },
        nl={"GM": 2.0},
    )
    x = truth.simulate(1 << 14, fs=FS, rng=3)
    p = tmp_path / "array.h5"
    eg.save_log(
        p, {"imu_a": x[:, 0], "imu_b": x[:, 1]}, fs=FS, units={"imu_a": "deg/s", "imu_b": "deg/s"}
    )
    return p


def test_view_shows_the_engine_virtual_sensor_of_the_fit(app: Any, array_log: Path) -> None:
    v = open_view(app)
    v.spec_input.value = "GM+WN"
    assert app.state.load_path(array_log), app.state.error
    v.set_shared("GM", ["imu_a", "imu_b"])
    v.set_shared("WN", ["imu_a", "imu_b"])
    assert v.error == "" and v.result is not None
    vv: VirtualView = v.virtual
    vs = vv.sensor
    assert vs is not None and vv.error == ""
    direct = eg.virtual_sensor(v.result)
    np.testing.assert_allclose(vs.weights, direct.weights, rtol=1e-12)
    np.testing.assert_allclose(vs.ci_low, direct.ci_low, rtol=1e-12)
    assert np.all(np.isnan(vs.conf_low))  # not computed live
    # the table: each channel, the average and the virtual sensor
    rows = vv.weight_source.data
    assert rows["channel"] == ["imu_a", "imu_b", "plain average", "virtual sensor"]
    np.testing.assert_allclose(rows["weight"][:2], vs.weights, rtol=1e-12)
    assert rows["weight"][2:] == [0.5, 1.0] and set(rows["unit"]) == {"deg/s"}
    j = int(vs.target_levels[0])
    assert rows["adev"][3] == pytest.approx(math.sqrt(2 * vs.empirical[j]))
    # negatively correlated, unequal sensors: the optimum beats the average in the model
    assert vs.gain_vs_average < 0.85 and "x the plain average" in vv.info.object
    # the figure: every sensor, the average, the virtual sensor's WV and interval
    d = vv.virtual_source.data
    np.testing.assert_allclose(d["implied"], vs.implied, rtol=1e-12)
    np.testing.assert_allclose(d["empirical"], vs.empirical, rtol=1e-12)
    assert len(vv.sensor_source.data["ys"]) == 2
    np.testing.assert_allclose(vv.average_source.data["wv"], vs.average_empirical)
    assert vv.figure.yaxis.axis_label == "WV [(deg/s)²]"


def test_scale_band_and_export(app: Any, array_log: Path) -> None:
    v = open_view(app)
    v.spec_input.value = "GM+WN"
    assert app.state.load_path(array_log), app.state.error
    v.set_shared("GM", ["imu_a", "imu_b"])
    vv = v.virtual
    vv.target_input.value = "0.64"
    vs = vv.sensor
    j = int(vs.target_levels[0])
    assert vs.tau_s[j] == pytest.approx(0.64) and vv.error == ""
    n = v.result.implied[j]
    w1 = (n[1, 1] - n[0, 1]) / (n[0, 0] + n[1, 1] - 2 * n[0, 1])
    np.testing.assert_allclose(vs.weights, [w1, 1 - w1], rtol=1e-10)
    vv.target_input.value = "0.1:2"
    assert vv.sensor.target.startswith("band levels 4..7 (0.16 to 1.28 s)")
    vv.relative.value = False
    assert vv.sensor.relative is False
    # export: the same text as the engine's single-channel export of as_fit()
    assert vv.name_input.value == "imu_a"
    vv.name_input.value = "gyro_x"
    vv.format_select.value = "json"
    assert vv.download.filename.endswith(".json")
    text = vv.export_file().read()
    ref = eg.export(None, {"gyro_x": vv.sensor.as_fit()}, "json", units={"gyro_x": "deg/s"},
                    source="virtual sensor of imu_a, imu_b")  # fmt: skip
    assert json.loads(text) == json.loads(ref)
    vv.format_select.value = "kalibr"
    assert "gyroscope_noise_density" in vv.export_file().read()
    assert "px4" not in EXPORT_FORMATS and "datasheet" in EXPORT_FORMATS
    # bad criteria are messages; the view recovers
    for text, words in (("abc", "not a number"), ("1e6", "outside"), ("5:1", "not a number")):
        vv.target_input.value = text
        assert words in vv.error and vv.alert.visible and vv.sensor is None
        assert "could not export" in vv.export_file().read()
    vv.target_input.value = ""
    assert vv.error == "" and vv.sensor is not None


def test_no_fit_clears_the_view(app: Any) -> None:
    v = open_view(app)
    v.spec_input.value = "WN+FOO"
    assert v.result is None and v.virtual.sensor is None
    assert v.virtual.weight_source.data["channel"] == []
    v.spec_input.value = "WN+RW"
    assert v.virtual.sensor is not None and len(v.virtual.sensor.channels) == 3


def test_parse_target() -> None:
    assert parse_target("") == {} and parse_target(" 10 ") == {"scale": 10.0}
    assert parse_target("1:100") == {"band": (1.0, 100.0)}
    for bad in ("-1", "0", "x", "3:1", "1:inf"):
        with pytest.raises(ValueError, match="seconds"):
            parse_target(bad)
