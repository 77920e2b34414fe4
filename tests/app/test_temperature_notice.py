"""The app and a log with a temperature channel: the Fit view says the bias-temperature
sensitivity in one line (AppState.temperature) and fits the compensated signal, as ``gmwm fit
--temperature auto`` does, with the raw signal's WV in grey beside it; the "Temperature
compensation" choice (AppState.compensate: auto, always, off) refits on the raw WV or on the
compensated one whatever the test says, and the Multi-channel tab's WV/WCCV matrix follows it;
nothing changes for a log without a temperature channel."""

from __future__ import annotations

import re

import numpy as np
import pytest

import engine as eg
from gmwm_app.report_download import session_report
from gmwm_app.state import AppState

FS = 100.0
N = 200_000
C = 2e-3  # deg/s per degC = 7.2 deg/h per degC
SPEC = "WN(sigma2=1e-4)+RW(gamma2=1e-10)"
LINE = re.compile(r"temperature sensitivity (\S+) \[(\S+), (\S+)\] deg/h/degC")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("app_temperature")
    t = np.arange(N) / FS
    temp = 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sin(2 * np.pi * t / 600)
    x = eg.parse_model(SPEC).simulate(N, fs=FS, rng=21)
    units = {"gyro_x": "deg/s", "temperature": "degC"}
    eg.io.save_log(
        d / "thermal.csv", {"gyro_x": x + C * temp, "temperature": temp}, FS, units=units
    )
    eg.io.save_log(d / "plain.csv", {"gyro_x": x + C * temp}, FS, units={"gyro_x": "deg/s"})
    y = eg.parse_model(SPEC).simulate(N, fs=FS, rng=22)
    both = {"gyro_x": x + C * temp, "gyro_y": y - C * temp, "temperature": temp}
    units2 = {**units, "gyro_y": "deg/s"}
    eg.io.save_log(d / "thermal2.csv", both, FS, units=units2)
    flat = {"gyro_x": x, "temperature": np.full(N, 25.0)}  # a constant temperature
    eg.io.save_log(d / "flat.csv", flat, FS, units=units)
    return d, x, temp


def _grey(fig) -> int:
    """Points of the grey (raw) WV the plot draws: 0 when hidden or never built."""
    if fig.raw is None or fig.raw_item is None or not fig.raw_item.visible:
        return 0
    return len(fig.raw.data["variance"])


def _rw(s: AppState) -> float:
    return float(s.result.params["RW.gamma2"])


def test_fit_view_says_the_sensitivity_and_fits_the_compensated_signal(logs):
    """The line holds the sensitivity and a 95 % interval covering the planted 7.2
    deg/h/degC; the session's WV is that of the compensated signal: at the short scales it is
    the raw one's, at the long scales where the raw signal's is 2 to 18 times that of the noise
    alone (computed here without the temperature term), it is the noise's within 30 %; the WN+RW
    fit's RW is then the planted 1e-10 within 30 %, and the fit of the log without its
    temperature column inflates it. The downloaded report has the temperature paragraph."""
    d, x, temp = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv"), s.error
    m = LINE.search(s.temperature)
    assert m is not None, s.temperature
    lo, hi = float(m[2]), float(m[3])
    assert lo < 7.2 < hi and "compensated" in s.temperature
    noise = eg.wavelet_variance(x, fs=FS).variance
    raw = eg.wavelet_variance(x + C * temp, fs=FS).variance
    wv = s.wv.variance
    assert wv[0] == pytest.approx(raw[0], rel=1e-3)
    ramp = raw > 2 * noise  # the premise: the ramp dominates the long scales (up to 18x)
    assert ramp.sum() >= 4 and np.max(raw / noise) > 10
    np.testing.assert_allclose(wv[ramp], noise[ramp], rtol=0.3)
    assert s.set_model("WN+RW"), s.error
    assert _rw(s) == pytest.approx(1e-10, rel=0.3)
    page = session_report(s)
    assert '<p class="temperature" data-channel="gyro_x">' in page

    plain = AppState()
    assert plain.load_path(d / "plain.csv"), plain.error
    assert plain.temperature == ""
    np.testing.assert_allclose(plain.wv.variance, raw)
    assert plain.set_model("WN+RW"), plain.error
    assert _rw(plain) > 2 * _rw(s)
    assert 'class="temperature"' not in session_report(plain)


def test_switching_compensation_off_refits_on_the_raw_wv(logs):
    """On: the WV shown is the compensated one and the raw one is beside it (``wv_raw``, the
    plot's grey points); off: the WV shown is the raw signal's, the fit's RW is the inflated
    one (more than twice the compensated fit's, which is the planted 1e-10 within 30 %), no
    grey WV, and the line says the compensation is off; on again: the same cached WV and the
    same fit, nothing recomputed. A link keeps the switch (``temperature=0``)."""
    d, x, temp = logs
    raw = eg.wavelet_variance(x + C * temp, fs=FS).variance
    s = AppState()
    assert s.load_path(d / "thermal.csv") and s.set_model("WN+RW"), s.error
    assert s.compensate == "auto" and s.temperature_channel == "temperature"
    assert s.compensation_unavailable == ""
    on_wv, on_rw = s.wv, _rw(s)
    assert on_rw == pytest.approx(1e-10, rel=0.3)
    np.testing.assert_allclose(s.wv_raw.variance, raw, rtol=1e-9)
    assert "temperature" not in s.to_query()
    computed = s.wv_computations

    s.compensate = "off"  # what the widget made from the parameter does
    assert s.error == ""
    np.testing.assert_allclose(s.wv.variance, raw, rtol=1e-9)
    assert s.wv_raw is None and _rw(s) > 2 * on_rw
    assert "compensation off: the WV and the fit are of the raw signal" in s.temperature
    assert LINE.search(s.temperature)
    assert s.result.wv is s.wv  # the fit is of the raw WV
    assert s.to_query()["temperature"] == "0"
    link = AppState()
    assert link.from_query({**s.to_query(), "path": str(d / "thermal.csv")}), link.error
    assert link.compensate == "off" and link.wv_raw is None
    np.testing.assert_allclose(link.wv.variance, raw, rtol=1e-9)
    assert _rw(link) == pytest.approx(_rw(s), rel=1e-9)

    s.compensate = "auto"
    assert s.wv is on_wv and _rw(s) == pytest.approx(on_rw, rel=1e-12)
    assert s.wv_computations == computed  # both WVs came from the session's cache


def test_the_report_of_an_uncompensated_fit_has_no_temperature_paragraph(logs):
    """The downloaded report says what the session fitted: with the compensation off, the
    fit is of the raw signal, and the report has no temperature paragraph (which would say
    the fit is of the compensated signal)."""
    d, _, _ = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv") and s.set_model("WN+RW"), s.error
    s.compensate = "off"
    assert 'class="temperature"' not in session_report(s)


def test_the_multi_channel_matrix_follows_the_switch(logs):
    """The Multi-channel tab's WV/WCCV matrix (AppState.wv_matrix): its diagonal is each
    channel's compensated WV while the switch is on (the Fit tab's WV of that channel), the
    raw one when it is off; the two are cached apart."""
    d, _, _ = logs
    s = AppState()
    assert s.load_path(d / "thermal2.csv"), s.error
    chans = ["gyro_x", "gyro_y"]
    on, note_on = s.wv_matrix(s.log, chans, FS)
    assert "Temperature-compensated" in note_on and "gyro_y ('temperature')" in note_on
    s.compensate = "off"
    off, note_off = s.wv_matrix(s.log, chans, FS)
    assert note_off == ""
    for i, ch in enumerate(chans):
        comp = s.get_wv(ch, FS, False, True).variance
        raw = s.get_wv(ch, FS, False, False).variance
        np.testing.assert_allclose(on.values[:, i, i], comp, rtol=1e-9)
        np.testing.assert_allclose(off.values[:, i, i], raw, rtol=1e-9)
        assert np.max(raw / comp) > 2  # the premise: the temperature term shows at long scales
    # the cross-WV of the two is that of their noise only when compensated: the opposite
    # temperature terms make the raw one strongly negative at the long scales
    assert off.values[-3, 0, 1] < -abs(on.values[-3, 0, 1])
    assert s.wv_matrix(s.log, chans, FS)[0] is off
    s.compensate = "auto"
    assert s.wv_matrix(s.log, chans, FS)[0] is on
    assert s.wvm_computations == 2


def test_the_switch_shows_with_a_temperature_channel_and_says_why_it_cannot_be_used(logs):
    """The page's choice is the state's parameter (``Select.from_param``: auto, always,
    off): shown with a temperature channel beside the channel; disabled, with the reason, for
    a constant temperature; hidden without one. The grey WV is drawn only while
    compensated."""
    from gmwm_app.app import create_app

    d, _, _ = logs
    app = create_app(load=False).gmwm_app
    s, box, fig = app.state, app.compensate_choice, app.views
    assert s.load_path(d / "thermal.csv"), s.error
    assert box.visible and not box.disabled and box.value == "auto"
    assert list(box.options) == ["auto", "always", "off"]
    assert "'temperature'" in box.name
    assert _grey(fig) == len(s.wv)
    box.value = "off"  # the user chooses off
    assert s.compensate == "off" and s.wv_raw is None and _grey(fig) == 0
    box.value = "auto"
    assert s.wv_raw is not None and _grey(fig) == len(s.wv)

    assert s.load_path(d / "flat.csv"), s.error
    assert box.visible and box.disabled and "constant" in box.name
    assert s.temperature == "" and s.wv_raw is None and _grey(fig) == 0

    assert s.load_path(d / "plain.csv"), s.error
    assert not box.visible and s.temperature_channel == ""


@pytest.mark.real_data
def test_a_real_log_without_temperature_shows_no_switch_and_no_grey_wv(real_data):
    """ADIS16405 unit 1 has no temperature channel: no switch, no grey WV, no line, nothing in
    the link, and its WV is the raw signal's whatever the switch says."""
    from gmwm_app.app import create_app

    app = create_app(load=False).gmwm_app
    s = app.state
    assert s.load_path(real_data / "adis16405_imu1.h5"), s.error
    assert s.temperature_channel == "" and s.temperature == "" and s.wv_raw is None
    assert not app.compensate_choice.visible and app.views.raw is None  # never built
    assert "temperature" not in s.to_query()
    want = s.log.wavelet_variance("gyro_x", fs=s.fs).variance
    np.testing.assert_array_equal(s.wv.variance, want)


def test_a_saved_session_keeps_the_switch(logs):
    """A session saved with the compensation off restores with it off: the same raw WV and
    the same fit (a session file without the key restores with auto, as before; one saved
    with the switch of before, True or False, with auto or off)."""
    import json

    from gmwm_app import session_view as sv

    d, _, _ = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv") and s.set_model("WN+RW"), s.error
    s.compensate = "off"
    text = sv.session_json(s)
    assert json.loads(text)["app"]["compensate"] == "off"
    other = AppState()
    assert sv.apply_restore(other, sv.prepare_restore(text, "s.json")), other.error
    assert other.compensate == "off" and other.wv_raw is None
    np.testing.assert_allclose(other.wv.variance, s.wv.variance, rtol=1e-12)
    assert _rw(other) == pytest.approx(_rw(s), rel=1e-9)
    doc = json.loads(text)
    del doc["app"]["compensate"]
    old = AppState()
    assert sv.apply_restore(old, sv.prepare_restore(json.dumps(doc), "s.json")), old.error
    assert old.compensate == "auto" and old.wv_raw is not None
    for before, mode in ((False, "off"), (True, "auto")):  # the switch of before
        doc["app"]["compensate"] = before
        was = AppState()
        assert sv.apply_restore(was, sv.prepare_restore(json.dumps(doc), "s.json")), was.error
        assert was.compensate == mode and (was.wv_raw is None) == (mode == "off")
    doc["app"]["compensate"] = "sometimes"  # edited by hand: one line naming the file
    with pytest.raises(ValueError) as e:
        sv.prepare_restore(json.dumps(doc), "s.json")
    assert str(e.value) == (
        "s.json: temperature compensation 'sometimes' is not one of auto, always, off (or 0 "
        "for off, 1 for auto); edit 'compensate' in the file or remove it"
    )


def test_a_failed_switch_goes_back_and_says_why(logs, monkeypatch):
    """When the other WV cannot be computed, the page says why in one line, the switch goes
    back (its widget with it) and the session keeps its WV and fit."""
    from gmwm_app import state as state_mod

    d, _, _ = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv") and s.set_model("WN+RW"), s.error
    wv, res = s.wv, s.result
    for key in [k for k in s._wv_cache.wvs if not k[3]]:  # the raw WV must be computed
        del s._wv_cache.wvs[key]  # again, and that fails

    def broken(*a, **kw):
        raise ValueError("channel gyro_x: no memory left for its WV")

    monkeypatch.setattr(state_mod, "compute_wv", broken)
    s.compensate = "off"
    why = "channel gyro_x: no memory left for its WV"
    assert s.error == f"Could not switch the temperature compensation: {why}"
    assert s.compensate == "auto" and s.wv is wv and s.result is res


def test_a_log_cut_into_segments_is_compensated_under_the_rule_of_any_log(logs):
    """A log loaded on its still segments is fitted on them, each with its own offset, and
    judged as any log is (`--temperature auto`, docs/qualify.md): the planted 7.2 deg/h/degC
    is clear in 180,000 still samples, so the WV is the compensated one, the pooled raw WV
    beside it, and the switch is enabled."""
    d, x, temp = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv", segments="0:90000,110000:200000"), s.error
    assert s.temperature_channel == "temperature" and s.compensation_unavailable == ""
    lo, hi = (float(v) for v in LINE.search(s.temperature).groups()[1:])
    assert lo < 7.2 < hi and lo > 0
    np.testing.assert_allclose(
        s.wv_raw.variance, s.log.wavelet_variance("gyro_x", fs=s.fs).variance, rtol=1e-12
    )
    assert s.data_info()["temperature_compensated"] is True


def test_a_sensitivity_not_distinguishable_from_0_is_shown_not_applied(tmp_path):
    """No true sensitivity, a temperature that barely moves (30.1 to 30.6 degC): the line
    says the sensitivity with its interval, that it is not compensated (``auto``, with the
    test's p-value) and how to compensate anyway; the WV and the fit are the raw signal's (no
    grey WV beside them), as `gmwm fit --temperature auto` does not compensate either. The
    choice stays enabled: ``always`` takes it out (the test below)."""
    t = np.arange(N) / FS
    temp = 30.1 + 0.5 * (1 - np.exp(-t / 900)) + np.random.default_rng(8).normal(0, 0.01, N)
    x = eg.parse_model(SPEC).simulate(N, fs=FS, rng=23)
    units = {"gyro_x": "deg/s", "temperature": "degC"}
    y = eg.parse_model(SPEC).simulate(N, fs=FS, rng=25)  # p = 0.69 (seed 24: 0.036)
    units = {**units, "gyro_y": "deg/s"}
    chans = {"gyro_x": x, "gyro_y": y, "temperature": temp}
    eg.io.save_log(tmp_path / "ramp.csv", chans, FS, units=units)
    s = AppState()
    assert s.load_path(tmp_path / "ramp.csv") and s.set_model("WN+RW"), s.error
    assert s.temperature_channel == "temperature" and s.wv_raw is None
    lo, hi = (float(v) for v in LINE.search(s.temperature).groups()[1:])
    assert lo < 0 < hi
    assert "not distinguishable from 0" in s.temperature and "raw signal" in s.temperature
    assert "compensation auto: the WV and the fit are of the raw signal" in s.temperature
    assert "(choose 'always' to compensate anyway)" in s.temperature
    assert s.compensation_unavailable == ""  # (before: disabled; the choice can force it)
    raw = s.log.wavelet_variance("gyro_x", fs=s.fs)
    np.testing.assert_allclose(s.wv.variance, raw.variance, rtol=1e-12)
    assert _rw(s) == pytest.approx(eg.fit_gmwm(raw, "WN+RW").params["RW.gamma2"], rel=1e-9)
    assert s.data_info()["temperature_compensated"] is False
    # the Multi-channel tab's matrix: the raw signals, and its notice claims no compensation
    from gmwm_app.data import temperature_fit_of, wv_matrix_of

    assert not any(temperature_fit_of(s.log, c).applied for c in ("gyro_x", "gyro_y"))
    wvm, notice = wv_matrix_of(s.log, ["gyro_x", "gyro_y"], s.fs, compensate="auto")
    assert "Temperature-compensated" not in notice
    np.testing.assert_allclose(wvm.values[:, 0, 0], raw.variance, rtol=1e-9)


def _ramp(path):
    """gyro_x with no true sensitivity under a temperature that barely moves (30.1 to 30.6
    degC): ``auto`` leaves it raw (p = 0.74 on this seed)."""
    t = np.arange(N) / FS
    temp = 30.1 + 0.5 * (1 - np.exp(-t / 900)) + np.random.default_rng(8).normal(0, 0.01, N)
    x = eg.parse_model(SPEC).simulate(N, fs=FS, rng=23)
    units = {"gyro_x": "deg/s", "temperature": "degC"}
    eg.io.save_log(path, {"gyro_x": x, "temperature": temp}, FS, units=units)
    return path


def test_always_compensates_what_auto_declines(tmp_path):
    """``always`` takes out the relation ``auto`` leaves in, as `gmwm fit --temperature
    COLUMN` does: the WV fitted is that of the engine's named-channel fit (its
    TemperatureFit.wv, bit for bit up to 1e-12), the raw WV is drawn beside it, the line says
    "compensation always" with the p-value; the link carries ``temperature=always`` and
    brings it back; ``off`` and ``auto`` fit the raw WV again, from the session's cache.
    Before, the app could not force it (its switch was disabled)."""
    from engine.inference.temperature import fit_log_temperature

    path = _ramp(tmp_path / "ramp.csv")
    s = AppState()
    assert s.load_path(path) and s.set_model("WN+RW"), s.error
    raw_wv = s.wv
    named = fit_log_temperature(s.log, "gyro_x", "temperature")  # --temperature temperature
    assert named.applied and named.p_value > 0.05  # the premise: auto declines
    assert f"p = {named.p_value:.2g}" in s.temperature  # auto says its test's p-value
    s.compensate = "always"
    assert s.error == "" and s.wv is not raw_wv
    np.testing.assert_allclose(s.wv.variance, named.wv.variance, rtol=1e-12)
    np.testing.assert_allclose(s.wv_raw.variance, raw_wv.variance, rtol=1e-12)
    assert s.result.wv is s.wv
    want = eg.fit_gmwm(named.wv, "WN+RW").params["RW.gamma2"]
    assert _rw(s) == pytest.approx(want, rel=1e-9)
    assert f"compensation always (p = {named.p_value:.2g}" in s.temperature
    assert "temperature-compensated signal" in s.temperature
    assert "not compensated" not in s.temperature
    assert s.data_info()["temperature_compensated"] is True
    assert s.data_info()["temperature_compensation"] == "always"
    q = s.to_query()
    assert q["temperature"] == "always"
    link = AppState()
    assert link.from_query({**q, "path": str(path)}), link.error
    assert link.compensate == "always" and link.wv_raw is not None
    np.testing.assert_allclose(link.wv.variance, s.wv.variance, rtol=1e-12)
    computed = s.wv_computations
    for mode in ("off", "auto"):
        s.compensate = mode
        assert s.wv is raw_wv and s.wv_raw is None, mode
        assert f"compensation {mode}" in s.temperature
    assert s.wv_computations == computed  # both WVs from the session's cache


def test_auto_and_always_agree_where_the_test_rejects(logs):
    """On the planted 7.2 deg/h/degC the test rejects: ``auto`` compensates and its line says
    so with the p-value; ``always`` is the same WV (the same relation, nothing recomputed),
    its line says "always"."""
    d, _, _ = logs
    s = AppState()
    assert s.load_path(d / "thermal.csv") and s.set_model("WN+RW"), s.error
    m = re.search(r"compensation auto \(p = (\S+) < 0.05\)", s.temperature)
    assert m is not None and float(m[1]) < 1e-6, s.temperature
    wv, computed = s.wv, s.wv_computations
    s.compensate = "always"
    assert s.wv is wv and s.wv_computations == computed and s.wv_raw is not None
    assert "compensation always (p = " in s.temperature


def test_links_of_before_and_bad_links(logs):
    """Links made before the choice: ``temperature=0`` is off, ``temperature=1`` auto; a
    link with another value names it and the choices in one line, and the rest applies."""
    d, _, _ = logs
    p = str(d / "thermal.csv")
    for value, mode in (("0", "off"), ("1", "auto"), ("always", "always"), ("auto", "auto")):
        assert AppState().parse_query({"temperature": value})["compensate"] == mode
    s = AppState()
    assert not s.from_query({"source": "path", "path": p, "temperature": "sometimes"})
    assert s.error == (
        "temperature='sometimes' in the link is not one of auto, always, off (or 0 for off)"
    )
    assert s.compensate == "auto" and s.wv_raw is not None


def _heater_log(path) -> None:
    """gyro_x (rad/s): white noise N = 1e-4 rad/s/sqrt(Hz) and a random walk, its bias
    2e-4 rad/s per degC of a temperature that warms up by 10 degC and steps by 4 degC every
    5 min (a heater cycling); 2^17 samples at 100 Hz."""
    n = 2**17
    t = np.arange(n) / FS
    temp = 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sign(np.sin(2 * np.pi * t / 600))
    x = eg.parse_model("WN(1e-6)+RW(1e-12)").simulate(n, rng=np.random.default_rng(1))
    units = {"gyro_x": "rad/s", "temperature": "degC"}
    eg.io.save_log(path, {"gyro_x": x + 2e-4 * (temp - 25), "temperature": temp}, FS, units=units)


def test_filter_export_of_a_compensated_fit_reads_the_compensated_signal(tmp_path):
    """A gyro_x of white noise N = 1e-4 rad/s/sqrt(Hz) (and a random walk) whose bias follows
    a temperature that warms up by 10 degC and steps by 4 degC every 5 min (2e-4 rad/s per
    degC): the session fits the compensated signal, and the Kalibr export's tail factors must
    read that signal too (``gmwm_app.data.fitted_log``), not the raw one, whose steps give
    tail factors of 1.8-3.0 at 5-20 s (a density of 1.65e-4 before). Compensated: the
    planted density within 3 %, from the download and from the several-channel export alike;
    with compensation off, the raw signal's fit and tails (more than 1.3x it)."""
    import yaml

    from gmwm_app.session_view import export_fits, export_text

    path = tmp_path / "heater.csv"
    _heater_log(path)
    s = AppState()
    assert s.load_path(path), s.error
    assert "compensated signal" in s.temperature
    assert s.set_model("WN+RW"), s.error

    def density(text: str) -> float:
        return float(yaml.safe_load(text)["gyroscope_noise_density"])

    assert density(export_text(s, "kalibr")) == pytest.approx(1e-4, rel=0.03)
    both = export_fits(s, {"gyro_x": s.result}, "kalibr")
    assert density(both) == pytest.approx(1e-4, rel=0.03)
    s.compensate = "off"
    assert s.set_model("WN+RW"), s.error
    assert density(export_text(s, "kalibr")) > 1.3e-4


def test_the_export_preview_of_a_compensated_fit_reads_the_compensated_signal(tmp_path, app_demo):
    """The export menu's preview ("Show what the filter will assume") of the same fit: its N
    is the download's, the planted 1e-4 within 3 % (the raw signal's tails made it 1.65e-4)."""
    from gmwm_app.app import create_app

    path = tmp_path / "heater.csv"
    _heater_log(path)
    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    assert s.load_path(path), s.error
    assert s.set_model("WN+RW"), s.error
    sp.format_select.value = "kalibr"
    sp.preview.toggle.value = True
    got = sp.preview.projections["gyro_x"].value("N")
    assert got == pytest.approx(1e-4, rel=0.03)
