"""Browser-free tests of the app: session state, views' data and the page built without a server.

The plotted numbers must be the engine's numbers; the WV is computed once per channel; every
bad input gives a message and leaves the session usable.
"""

from __future__ import annotations

import json
from pathlib import Path
from urllib.parse import parse_qs, urlencode

import h5py
import numpy as np
import pytest

import engine as eg
from gmwm_app import state as state_mod
from gmwm_app.state import AppState, format_value
from gmwm_app.views import (
    datasheet_rows,
    fit_summary,
    model_grid,
    parameter_rows,
)
from gmwm_app.whatif import SliderSpec
from gmwm_app.wv_figures import WVFigures

CHANNELS = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]


def assert_params_equal(a: dict[str, float], b: dict[str, float], rtol: float = 1e-12) -> None:
    assert list(a) == list(b)
    for k in a:
        assert a[k] == pytest.approx(b[k], rel=rtol, abs=1e-300), k


def snapshot(s: AppState) -> tuple:
    return (s.channel, s.fs, s.robust, s.model.spec(values=True), s.result, s.wv, s.filename)


# ---------------------------------------------------------------------------------------------
# loading and channels
# ---------------------------------------------------------------------------------------------
def test_load_demo(app_state: AppState, app_demo: Path) -> None:
    s = app_state
    assert s.error == ""
    assert s.channels == CHANNELS
    assert s.channel == "gyro_x"
    assert s.source == "demo" and s.filename == app_demo.name
    assert s.fs == 100.0 and s.fs_source == "file"
    log = eg.io.load_log(app_demo)
    assert s.n == log["gyro_x"].size
    assert s.duration_s == pytest.approx(s.n / 100.0)
    assert s.unit == "deg/s"
    ref = eg.wavelet_variance(log["gyro_x"], fs=100.0)
    np.testing.assert_array_equal(s.wv.variance, ref.variance)
    np.testing.assert_array_equal(s.wv.ci_low, ref.ci_low)
    assert len(s.model) == 0 and s.result is None  # an empty model: just the empirical WV


def test_channel_switch_keeps_model_and_refits(app_state: AppState, app_demo: Path) -> None:
    s = app_state
    assert s.set_model("WN+RW")
    assert s.select_channel("accel_z"), s.error
    assert s.channel == "accel_z" and s.unit == "m/s^2"
    ref = eg.wavelet_variance(eg.io.load_log(app_demo)["accel_z"], fs=100.0)
    np.testing.assert_array_equal(s.wv.variance, ref.variance)
    assert s.model.spec() == "WN+RW"
    assert_params_equal(s.result.params, eg.fit_gmwm(ref, "WN+RW").params)
    assert not s.select_channel("nope")
    assert "no channel 'nope'" in s.error and s.channel == "accel_z"


def test_add_remove_match_the_engine(app_state: AppState) -> None:
    s = app_state
    for code, spec in [
        ("GM", "GM"),
        ("WN", "GM+WN"),
        ("RW", "GM+WN+RW"),
        ("GM", "2*GM+WN+RW"),
        ("QN", "2*GM+QN+WN+RW"),
    ]:
        assert s.add_process(code), s.error
        assert s.model.spec() == spec
        ref = eg.fit_gmwm(s.wv, spec)
        assert_params_equal(s.result.params, ref.params)
        assert s.result.objective == pytest.approx(ref.objective, rel=1e-12)
        assert s.model.labels == s.result.model.labels
    assert s.remove_process(0)  # GM_1 (most persistent)
    assert s.model.spec() == "GM+QN+WN+RW"
    assert_params_equal(s.result.params, eg.fit_gmwm(s.wv, "GM+QN+WN+RW").params)
    assert s.remove_process(s.model.labels.index("QN"))
    assert s.model.spec() == "GM+WN+RW"
    assert not s.remove_process(7)
    assert "no process number 8" in s.error and s.model.spec() == "GM+WN+RW"
    assert not s.add_process("XX") and "unknown process" in s.error
    assert s.clear_model() and s.result is None and s.display_model() is None


def test_wv_is_computed_once_per_channel(app_demo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[int, bool]] = []
    real = eg.wavelet_variance

    def counting(x, **kw):
        calls.append((np.size(x), kw.get("robust", False)))
        return real(x, **kw)

    import engine.io.log  # where "the WV of a channel of a log" is computed (ImuLog)

    monkeypatch.setattr(engine.io.log, "wavelet_variance", counting)
    s = AppState()
    assert s.load_demo()
    assert len(calls) == 1
    for code in ("GM", "WN", "RW", "GM"):
        assert s.add_process(code)
    assert s.remove_process(1) and s.set_model("WN+RW") and s.clear_model()
    assert s.set_model("GM+WN")
    assert len(calls) == 1  # model changes refit on the cached WV
    assert s.select_channel("accel_x") and len(calls) == 2
    assert s.select_channel("gyro_x") and len(calls) == 2
    assert s.set_fs(200.0) and len(calls) == 2  # re-labelled, not recomputed
    assert s.wv.fs == 200.0 and s.fs_source == "user"
    assert s.set_robust(True) and len(calls) == 3 and calls[-1][1] is True
    assert s.set_robust(False) and len(calls) == 3  # the robust WV carries the classical one
    assert s.set_robust(True) and len(calls) == 3
    assert s.wv_computations == 3


def test_fs_change(app_state: AppState) -> None:
    s = app_state
    tau0 = s.wv.tau_s.copy()
    assert s.set_model("GM+WN")
    beta100 = s.result.params["GM.beta"]
    assert s.set_fs(50.0)
    np.testing.assert_allclose(s.wv.tau_s, 2 * tau0)
    assert s.result.params["GM.beta"] == pytest.approx(beta100 / 2, rel=1e-6)
    assert s.duration_s == pytest.approx(s.n / 50.0)
    for bad in (-1.0, 0.0, float("nan"), "abc"):
        before = snapshot(s)
        assert not s.set_fs(bad)
        assert "positive number of Hz" in s.error
        assert snapshot(s) == before


# ---------------------------------------------------------------------------------------------
# errors: messages, previous state kept, session usable
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name, data, words",
    [
        ("empty.csv", b"", "empty"),
        ("blank.csv", b"\n\n# only a comment\n", "empty"),
        ("text.csv", b"time,gyro\n0,0.1\n0.01,abc\n0.02,0.3\n0.03,0.2\n", "not a number"),
        ("nan.csv", b"gyro\n0.1\nnan\n0.3\n0.2\n0.5\n", "NaN"),
        ("short.csv", b"gyro\n0.1\n0.2\n", "at least 4"),
        ("binary.h5", b"\x00\x01garbage" * 10, "HDF5"),
    ],
)
def test_bad_files_give_messages_and_keep_the_session(
    app_state: AppState, name: str, data: bytes, words: str
) -> None:
    s = app_state
    assert s.set_model("GM+WN")
    before = snapshot(s)
    assert not s.load_upload(data, name)
    assert words.lower() in s.error.lower()
    assert name in s.error and "gmwm_upload_" not in s.error  # the user's file name
    assert snapshot(s) == before
    assert s.add_process("RW"), s.error  # still usable
    assert s.error == "" and s.model.spec() == "GM+WN+RW"


def test_missing_server_path(app_state: AppState, tmp_path: Path) -> None:
    s = app_state
    before = snapshot(s)
    assert not s.load_path(tmp_path / "nope.h5")
    assert "no such file" in s.error and snapshot(s) == before
    assert not s.load_path(tmp_path)
    assert "is a directory, not a log file" in s.error  # the engine's message
    assert not s.load_path("")
    assert "no path" in s.error


def test_missing_demo(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("GMWM_APP_DEMO", str(tmp_path / "gone.h5"))
    s = AppState()
    assert not s.load_demo()
    assert "make_demo.py" in s.error and s.wv is None
    assert not s.add_process("WN") and "load data" in s.error


def test_unidentifiable_models_are_refused(app_state: AppState) -> None:
    s = app_state
    assert s.set_model("GM+WN")
    before = snapshot(s)
    assert not s.add_process("WN")
    assert "2 WN terms" in s.error and "keep one WN" in s.error
    assert snapshot(s) == before
    assert not s.add_process("AR1")
    assert "mixes AR1 and GM" in s.error and snapshot(s) == before
    assert not s.set_model("WN+WN+RW")
    assert snapshot(s) == before
    assert not s.set_model("WN+FOO")
    assert "unknown process" in s.error and snapshot(s) == before
    assert s.add_process("RW") and s.error == ""


def test_too_many_parameters_for_a_short_series(app_demo: Path, tmp_path: Path) -> None:
    x = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-3)").simulate(40, fs=10.0, rng=3)
    csv = "time,gyro [deg/s]\n" + "\n".join(f"{i / 10},{float(v)!r}" for i, v in enumerate(x))
    s = AppState()
    assert s.load_upload(csv.encode(), "short.csv"), s.error
    assert s.n == 40 and s.fs == 10.0 and s.fs_source == "time column"
    assert len(s.wv) == 5
    assert s.set_model("GM+WN+RW")
    before = snapshot(s)
    assert not s.add_process("GM")  # 6 parameters, 5 levels
    assert "6 parameters" in s.error and "5 levels" in s.error
    assert snapshot(s) == before
    assert not s.set_model("3*GM")
    assert snapshot(s) == before
    assert s.remove_process(0) and s.model.spec() == "WN+RW"


def test_new_log_without_the_channel_falls_back(app_state: AppState, tmp_path: Path) -> None:
    s = app_state
    assert s.select_channel("gyro_z") and s.set_model("WN")
    x = np.random.default_rng(1).normal(size=5000)
    np.save(tmp_path / "one.npy", x)
    assert s.load_path(tmp_path / "one.npy"), s.error
    assert s.source == "path" and s.channels == s.log.names and s.channel == s.channels[0]
    assert s.fs == 1.0 and s.fs_source == "default"
    assert "fs = 1 Hz assumed" in s.notice
    assert s.model.spec() == "WN" and s.result is not None


# ---------------------------------------------------------------------------------------------
# summary files, robust WV
# ---------------------------------------------------------------------------------------------
def write_summary(path: Path, wv: eg.WaveletVariance, n: int) -> Path:
    with h5py.File(path, "w") as f:
        f.attrs["kind"] = "wavelet_variance"
        f.attrs["fs_hz"] = wv.fs
        f.attrs["n_samples"] = n
        f.attrs["units"] = json.dumps({"gyro_x": "rad/s"})
        g = f.create_group("wv/gyro_x")
        g["variance"] = wv.variance
        g["ci_low"] = wv.ci_low
        g["ci_high"] = wv.ci_high
    return path


def test_wv_summary_file(app_state: AppState, tmp_path: Path) -> None:
    ref = app_state.wv
    p = write_summary(tmp_path / "summary.h5", ref, ref.n)
    s = AppState()
    assert s.load_path(p), s.error
    assert s.is_summary and s.channels == ["gyro_x"] and s.unit == "rad/s"
    np.testing.assert_allclose(s.wv.variance, ref.variance, rtol=0, atol=0)
    assert s.n == ref.n
    assert s.set_model("GM+WN+RW")
    assert_params_equal(s.result.params, eg.fit_gmwm(s.wv, "GM+WN+RW").params)
    before = snapshot(s)
    assert not s.set_robust(True)
    assert "robust WV needs the raw log" in s.error and snapshot(s) == before


def test_robust_wv_beside_classical(app_state: AppState) -> None:
    s = app_state
    assert s.set_model("WN+RW") and s.set_robust(True)
    assert s.wv.robust and s.wv.classical is not None
    x = s.log["gyro_x"]
    ref = eg.wavelet_variance(x, fs=100.0, robust=True)
    np.testing.assert_allclose(s.wv.variance, ref.variance, rtol=1e-12)
    assert_params_equal(s.result.params, eg.fit_gmwm(ref, "WN+RW").params)
    v = WVFigures()
    v.update(s)
    np.testing.assert_array_equal(v.emp.data["variance"], s.wv.variance)
    np.testing.assert_array_equal(v.alt.data["variance"], s.wv.classical.variance)
    assert v.alt_item.visible and "robust" in v.emp_item.label.value
    assert s.set_robust(False)
    v.update(s)
    assert len(v.alt.data["variance"]) == 0 and not v.alt_item.visible


# ---------------------------------------------------------------------------------------------
# URL round trip and export
# ---------------------------------------------------------------------------------------------
def test_url_round_trip(app_state: AppState) -> None:
    s = app_state
    assert s.select_channel("gyro_y") and s.set_model("WN+RW+2*GM") and s.set_robust(False)
    q = s.to_query()
    assert q == {
        "source": "demo",
        "channel": "gyro_y",
        "fs": "100",
        "robust": "0",
        "model": "2*GM+WN+RW",
    }
    # through a real query string, as the browser sends it (values arrive as lists)
    qs = urlencode(q, safe="*")
    assert "model=2*GM%2BWN%2BRW" in qs
    t = AppState()
    assert t.from_query(parse_qs(qs)), t.error
    assert t.to_query() == q
    assert_params_equal(t.result.params, s.result.params)
    np.testing.assert_array_equal(t.wv.variance, s.wv.variance)


def test_url_with_problems_applies_the_rest(app_demo: Path) -> None:
    s = AppState()
    ok = s.from_query({"channel": "gyro_q", "model": "WN+WN", "robust": "maybe", "fs": "-3"})
    assert not ok
    for words in ("gyro_q", "2 WN terms", "robust='maybe'", "fs='-3'"):
        assert words in s.error
    assert s.channel == "gyro_x" and s.wv is not None and len(s.model) == 0
    assert s.add_process("WN")  # usable
    t = AppState()
    assert not t.from_query({"source": "upload", "model": "WN"})
    assert "upload it again" in t.error and t.model.spec() == "WN"
    u = AppState()
    assert not u.from_query({"source": "path", "path": "/does/not/exist.h5"})
    assert "no such file" in u.error and "showing the demo" in u.error and u.source == "demo"
    w = AppState()
    assert w.from_query({"fs": "50", "robust": "1", "model": ""}), w.error
    assert w.fs == 50.0 and w.robust and w.fs_source == "user"


def test_url_path_source(app_demo: Path) -> None:
    s = AppState()
    assert s.from_query({"source": "path", "path": str(app_demo), "channel": "accel_y"}), s.error
    assert s.to_query()["path"] == str(app_demo)
    assert s.to_query()["source"] == "path" and s.channel == "accel_y"


def test_export_json(app_state: AppState) -> None:
    s = app_state
    assert s.set_model("GM+WN+RW")
    d = json.loads(s.export_json())
    assert d["fit"] == json.loads(json.dumps(s.result.to_dict()))
    assert d["data"]["channel"] == "gyro_x" and d["data"]["fs_hz"] == 100.0
    assert d["data"]["unit"] == "deg/s" and d["data"]["n_samples"] == s.n
    assert {r["quantity"] for r in d["datasheet"]} >= {
        "angle random walk",
        "correlation time",
    }
    assert d["query"]["model"] == "GM+WN+RW"
    assert s.export_filename().endswith("_gyro_x_GM+WN+RW.json")
    assert s.clear_model()
    d = json.loads(s.export_json())
    assert d["fit"] is None and d["wv"]["variance"] == list(s.wv.variance)


# ---------------------------------------------------------------------------------------------
# what-if
# ---------------------------------------------------------------------------------------------
def test_whatif(app_state: AppState) -> None:
    s = app_state
    assert s.set_model("GM+WN")
    fitted = s.result.params
    specs = {sp.name: sp for sp in s.slider_specs()}
    assert set(specs) == {"GM.beta", "GM.sigma2_gm", "WN.sigma2"}
    sp = specs["GM.beta"]
    assert sp.hi - sp.lo == pytest.approx(6.0) and sp.value_of(sp.x) == pytest.approx(
        fitted["GM.beta"]
    )
    assert s.set_whatif(True)
    m = s.display_model()
    assert m.values() == pytest.approx(fitted)
    assert s.display_objective() == pytest.approx(s.result.objective, rel=1e-9)
    assert s.set_whatif_value("WN.sigma2", 10 * fitted["WN.sigma2"])
    assert s.display_model().values()["WN.sigma2"] == pytest.approx(10 * fitted["WN.sigma2"])
    assert s.display_objective() > s.result.objective
    assert s.result.params == fitted  # no refit while dragging
    v = WVFigures()
    v.update(s)
    tau = model_grid(s.wv)
    np.testing.assert_allclose(v.total.data["wv"], s.display_model().wv(tau, s.wv.fs), rtol=1e-12)
    assert not s.set_whatif_value("GM.beta", -1.0) and "beta" in s.error
    assert not s.set_whatif_value("XX.y", 1.0) and "no parameter" in s.error
    assert s.fit_from_whatif()
    assert s.result.objective <= eg.fit_gmwm(s.wv, "GM+WN").objective * (1 + 1e-9)
    assert s.reset_whatif()
    assert s.display_model().values() == pytest.approx(s.result.params)
    assert s.set_whatif(False) and s.display_model() is s.result.model


def test_whatif_before_a_fit_uses_guesses(app_state: AppState) -> None:
    s = app_state
    s.model = eg.parse_model("AR1+WN+DR")  # a structure without values (no fit)
    vals = s.whatif_model().values()
    assert all(v is not None and np.isfinite(v) for v in vals.values())
    assert 0 < vals["AR1.phi"] < 1
    specs = {sp.name: sp for sp in s.slider_specs()}
    assert specs["AR1.phi"].transform == "log10(1-x)" and specs["AR1.phi"].hi <= 0
    assert SliderSpec.position_of("log10(1-x)", 0.99) == pytest.approx(-2.0)


# ---------------------------------------------------------------------------------------------
# views: the plotted data are the engine's numbers
# ---------------------------------------------------------------------------------------------
def test_plotted_data_equal_the_engine(app_state: AppState) -> None:
    s = app_state
    v = WVFigures()
    fig, resid, xr = v.figure, v.residual, v.figure.x_range
    v.update(s)
    np.testing.assert_array_equal(v.emp.data["tau_s"], s.wv.tau_s)
    np.testing.assert_array_equal(v.emp.data["variance"], s.wv.variance)
    np.testing.assert_array_equal(v.emp.data["ci_low"], s.wv.ci_low)
    np.testing.assert_array_equal(v.emp.data["ci_high"], s.wv.ci_high)
    assert len(v.total.data["wv"]) == 0 and not any(r.visible for r in v.comp_renderers)

    assert s.set_model("2*GM+WN+RW")
    v.update(s)
    res = s.result
    tau = model_grid(s.wv)
    np.testing.assert_allclose(v.total.data["tau_s"], tau / 100.0)
    total = res.implied_at(tau)
    got = v.total.data["wv"]
    ok = total > 0
    np.testing.assert_allclose(got[ok], total[ok], rtol=1e-12)
    comps = res.model.components(tau, 100.0)
    shown = [
        (r, it, src)
        for r, it, src in zip(v.comp_renderers, v.comp_items, v.comps, strict=True)
        if r.visible
    ]
    assert len(shown) == 4
    for (_r, item, src), (lab, y) in zip(shown, comps.items(), strict=True):
        assert item.label.value.startswith(lab) and item.visible
        assert src.data["label"][0] == lab
        pos = y > 0
        np.testing.assert_allclose(src.data["wv"][pos], y[pos], rtol=1e-12)
        assert np.all(np.isnan(src.data["wv"][~pos]))  # zero curves break, not -inf
    colors = {r.glyph.line_color for r, _, _ in shown}
    assert len(colors) == 4
    # the model at the WV scales: the engine's implied WV, and the residual ratio
    np.testing.assert_allclose(v.resid.data["ratio"], s.wv.variance / res.implied, rtol=1e-12)
    np.testing.assert_allclose(v.resid.data["lo"], s.wv.ci_low / res.implied, rtol=1e-12)
    np.testing.assert_allclose(v.resid.data["hi"], s.wv.ci_high / res.implied, rtol=1e-12)

    # remove a process: one renderer hidden again; the figures are the same objects
    assert s.remove_process(0)
    v.update(s)
    assert sum(r.visible for r in v.comp_renderers) == 3
    assert v.figure is fig and v.residual is resid and v.figure.x_range is xr
    assert "deg/s" in v.figure.yaxis[0].axis_label
    assert any("(deg/s)²" in t[1] for t in v.emp_hover.tooltips)


def test_tables(app_state: AppState) -> None:
    s = app_state
    assert parameter_rows(s) == [] and datasheet_rows(s) == []
    assert "Empty model" in fit_summary(s)
    assert s.set_model("GM+WN+RW")
    rows = parameter_rows(s)
    assert [(r["process"], r["parameter"]) for r in rows[:4]] == [
        ("GM", "beta"),
        ("GM", "sigma2_gm"),
        ("WN", "sigma2"),
        ("RW", "gamma2"),
    ]
    assert [r["unit"] for r in rows[:4]] == ["1/s", "(deg/s)²", "(deg/s)²", "(deg/s)²"]
    # then the fit's IEEE quantities (engine/fit/ieee.py), in datasheet units
    ieee = {r["parameter"]: r for r in rows[4:]}
    assert all(r["process"] == "IEEE" for r in rows[4:])
    assert list(ieee) == list(s.result.ieee.quantities) and {"N", "B", "K"} <= set(ieee)
    assert ieee["N"]["unit"] == "deg/sqrt(h)"
    assert ieee["N"]["value"] == format_value(s.result.ieee["N"].datasheet_value)
    assert ieee["B"]["unit"].startswith("deg/h (T ")
    ds = datasheet_rows(s)
    q = {r["quantity"]: r["unit"] for r in ds}
    assert q["angle random walk"] == "deg/sqrt(h)" and q["correlation time"] == "s"
    assert "objective" in fit_summary(s) and "converged" in fit_summary(s)


def test_fit_warning_at_bound(tmp_path: Path) -> None:
    # a WV falling faster than white noise at long scales: a random walk added to the model
    # would need a negative variance, so it is estimated at its bound, zero
    tau = 2.0 ** np.arange(1, 15)
    falling = eg.WN(sigma2=1e-3).wv(tau) * np.linspace(1.0, 0.3, tau.size)
    exact = eg.WaveletVariance.from_arrays(falling, n=2**15, fs=100.0)
    s = AppState()
    assert s.load_path(write_summary(tmp_path / "wn.h5", exact, 2**15)), s.error
    assert s.set_model("WN+RW")
    assert s.result.params["RW.gamma2"] == 0.0
    assert s.warnings() and "RW.gamma2" in s.warnings()[0] and "at a bound" in s.warnings()[0]
    v = WVFigures()
    v.update(s)
    rw = [i for i in v.comp_items if i.visible and i.label.value.startswith("RW")]
    assert rw and rw[0].label.value.endswith("(zero)")


# ---------------------------------------------------------------------------------------------
# the page without a server
# ---------------------------------------------------------------------------------------------
def test_page_without_server(app_demo: Path) -> None:
    import panel as pn

    from gmwm_app.app import GMWMApp, create_app

    page = create_app()
    assert isinstance(page, pn.template.BootstrapTemplate)
    app: GMWMApp = page.gmwm_app
    s = app.state
    assert s.channel == "gyro_x" and s.error == ""
    assert list(app.channel_select.options) == CHANNELS
    # one button per registered process (the built-in six and any added class)
    assert {"WN", "QN", "RW", "DR", "AR1", "GM"} <= set(app.model_panel.add_buttons)
    assert set(app.model_panel.add_buttons) == set(eg.models.PROCESS_TYPES)
    assert all(f"+ {code}" == b.label for code, b in app.model_panel.add_buttons.items())
    app.model_panel.add_buttons["GM"].clicks += 1
    app.model_panel.add_buttons["WN"].clicks += 1
    assert s.model.spec() == "GM+WN"
    procs = list(app.tables.param_source.data["process"])
    # the model's parameters, then the fit's IEEE quantities (rows of process "IEEE")
    assert procs[:3] == ["GM", "GM", "WN"] and set(procs[3:]) == {"IEEE"}
    assert app.views.comp_renderers[0].visible and app.views.comp_items[0].label.value.startswith(
        "GM"
    )
    rows = [r for r in app.model_panel.process_list.objects[1:] if r.visible]
    assert len(rows) == 2 and "GM" in rows[0].objects[0].object
    app.model_panel.add_buttons["WN"].clicks += 1  # unidentifiable
    assert app.alert.visible and "2 WN terms" in app.alert.object
    assert s.model.spec() == "GM+WN"
    remove = rows[0].objects[1]
    remove.clicks += 1
    assert s.model.spec() == "WN" and not app.alert.visible
    app.model_panel.spec_input.value_input = "WN+RW"
    app.model_panel.spec_input.param.trigger("enter_pressed")
    assert s.model.spec() == "WN+RW"
    weights = app.model_panel.weights_select  # the Fit tab's weights choice
    assert weights.value == "ci" and s.result.weights == "ci"
    weights.value = "efficient"
    assert s.weights == "efficient" and s.result.weights == "efficient", s.error
    s.set_weights("ci")  # from the state back to the widget
    app.model_panel.refresh()
    assert weights.value == "ci" and s.result.weights == "ci"
    app.model_panel.whatif_toggle.value = True
    sliders = app.model_panel.sliders
    assert s.whatif and sliders.visible and len(sliders.objects) == 2
    slider = app.model_panel.sliders.objects[0]
    slider.value = slider.value + 1.0  # one decade up for WN.sigma2
    assert s.display_model().values()["WN.sigma2"] == pytest.approx(
        10 * s.result.params["WN.sigma2"], rel=1e-9
    )
    data = json.loads(app._export_json().getvalue())
    assert data["fit"]["model"] == "WN+RW" and "whatif" in data
    app.fs_input.value = 50.0
    assert s.fs == 50.0
    assert app.views.save_tool.filename.endswith("_gyro_x_WN_RW")


def test_cli_arguments(tmp_path: Path) -> None:
    from gmwm_app.__main__ import build_parser, main

    a = build_parser().parse_args(["log.h5", "--port", "0", "--no-show", "--address", "0.0.0.0"])
    assert a.file == "log.h5" and a.port == 0 and a.no_show and a.address == "0.0.0.0"
    assert main([str(tmp_path / "missing.h5"), "--no-show"]) == 2
    assert main(["--port", "70000", "--no-show"]) == 2


def test_demo_path_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("GMWM_APP_DEMO", raising=False)
    p = state_mod.demo_path()
    assert p.name == "demo_imu.h5" and p.parent.name == "demo" and p.is_file()
    assert p == Path(eg.__file__).resolve().parent / "demo" / "demo_imu.h5"  # package data


def test_weights_switch_refits_with_efficient_weights(app_state: AppState, app_demo: Path) -> None:
    # the demo's accel_x is QN+WN+RW+DR (engine/demo/demo_imu_truth.json)
    from engine.fit import fit_efficient

    s = app_state
    assert s.select_channel("accel_x") and s.set_model("QN+WN+RW+DR"), s.error
    ref = eg.wavelet_variance(eg.io.load_log(app_demo)["accel_x"], fs=100.0)
    ci = eg.fit_gmwm(ref, "QN+WN+RW+DR")
    assert s.result.weights == "ci" and "weights" not in s.to_query()
    # the J-test is the efficient one whatever the fit's weights (engine.inference.jtest): the
    # ci fit's badge no longer rejects the truth (it did, p < 0.01, with the ci weights' own
    # quadratic form against chi2(J - p)), and it is the same test as on the efficient fit
    jt_ci = s.compute_inference(s.result).j_test
    # (levels: 15 of 17, those of the classical WV with M_j / 2^j >= ETA_MIN = 4; the last two
    # have 2.1, 0.5)
    assert jt_ci.p_value >= 0.05 and jt_ci.levels == ref.n_levels - 2
    assert s.set_weights("efficient"), s.error
    assert s.weights == "efficient" and s.result.weights == "efficient"
    eff = fit_efficient(ref, "QN+WN+RW+DR")
    assert_params_equal(s.result.params, eff.params)
    np.testing.assert_allclose(s.result.omega, eff.omega, rtol=1e-12)
    assert not np.allclose(s.result.omega, ci.omega)  # V^-1 is full, ci weights diagonal
    assert s.result.params["RW.gamma2"] != pytest.approx(ci.params["RW.gamma2"], rel=1e-3)
    assert s.display_objective() == pytest.approx(eff.objective, rel=1e-12)
    jt_eff = s.compute_inference(s.result).j_test
    assert jt_eff.p_value >= 0.05 and jt_eff.df == jt_ci.df  # the same test, V at either fit
    # the link keeps the choice and restores the same fit
    q = s.to_query()
    assert q["weights"] == "efficient"
    t = AppState()
    assert t.from_query(parse_qs(urlencode(q, safe="*"))), t.error
    assert t.weights == "efficient" and t.result.weights == "efficient"
    assert_params_equal(t.result.params, eff.params)
    # back to ci: the ci fit again; an unknown choice is refused and changes nothing
    assert s.set_weights("ci") and s.result.weights == "ci"
    assert_params_equal(s.result.params, ci.params)
    assert not s.set_weights("optimal") and "unknown weights" in s.error and s.weights == "ci"
    bad = AppState()
    assert not bad.from_query({"source": "demo", "weights": "best"})
    assert "weights='best'" in bad.error and bad.weights == "ci"
