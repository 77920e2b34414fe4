"""The export menu's preview: what the filter will assume, before the
download, computed by the engine's ``project`` (the app draws and tabulates it), tested
without a browser on the page's objects."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from bokeh.models import BoxAnnotation, Span

from engine.formats import project
from gmwm_app.export_preview import preview_figure, preview_projections, preview_table


def _fit_two(app) -> tuple:
    s = app.state
    s.set_model("GM+WN+RW")
    gyro = s.result
    s.select_channel("accel_x")
    s.set_model("GM+WN+RW")
    return gyro, s.result


def test_preview_shows_the_engine_projection_before_the_download(app_demo: Path) -> None:
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    pv = sp.preview
    assert not pv.toggle.value and pv.table.object == ""  # nothing computed until asked
    gyro, accel = _fit_two(app)
    sp.format_select.value = "kalibr"
    pv.toggle.value = True
    assert set(pv.projections) == {"gyro_x", "accel_x"}
    # the numbers are the engine's, to the bit, and they are what the file writes
    for ch, fit in (("gyro_x", gyro), ("accel_x", accel)):
        want = project(fit, "kalibr", channel=ch, unit=s.log.units[ch])
        for name in ("N", "K"):
            got = pv.projections[ch].params[name]
            assert got.value == want.value(name)
            if "empirical WV" in got.binds:  # set by the data: no fit interval
                assert math.isnan(got.low) and math.isnan(got.high)
            else:
                assert got.low < got.value < got.high  # every value with its interval
    text = sp.format_download.callback().getvalue()
    d = yaml.safe_load(text)
    assert d["gyroscope_noise_density"] == pv.projections["gyro_x"].value("N")
    assert d["accelerometer_random_walk"] == pv.projections["accel_x"].value("K")
    # the table: each value, its interval, factor and binding scale
    for ch, p in pv.projections.items():
        for q in p.params.values():
            row = next(ln for ln in pv.table.object.splitlines() if f"| {ch} | {q.name} |" in ln)
            iv = "-" if math.isnan(q.low) else f"[{q.low:.4g}, {q.high:.4g}]"
            assert f"{q.value:.4g} {q.unit}" in row and f"| {iv} |" in row
            assert f"| {q.factor:.4g} |" in row and f"{q.binding_tau_s:.3g} s" in row
    # the figure is the shown channel's: fitted and consumer WV over the band, binding lines
    assert pv.plot_box.visible and s.channel == "accel_x"
    fig = pv.plot.object
    assert "accel_x" in fig.title.text
    ys = [r.data_source.data["y"] for r in fig.renderers]
    p = pv.projections["accel_x"]
    assert any(np.array_equal(y, p.consumer_wv) for y in ys)
    assert any(np.array_equal(y, p.fitted_wv) for y in ys)
    box = [a for a in fig.center if isinstance(a, BoxAnnotation)][0]
    assert (box.left, box.right) == p.band
    spans = {a.name: a.location for a in fig.center if isinstance(a, Span)}
    assert spans == {n: p.params[n].binding_tau_s for n in ("N", "K")}
    # a GM consumer: three parameters per channel; a report: nothing projected
    sp.format_select.value = "kf-gins"
    assert set(pv.projections["gyro_x"].params) == {"N", "sigma_b", "T_c"}
    assert "| gyro_x | T_c |" in pv.table.object
    sp.format_select.value = "json"
    assert pv.projections == {} and "not a filter file" in pv.note.object
    pv.toggle.value = False
    assert pv.table.object == "" and not pv.plot_box.visible


def test_preview_error_is_a_note_not_a_traceback(app_demo: Path) -> None:
    """A fit the consumer cannot take (no white part for the sensor_msgs/Imu covariance):
    the note says why and the session keeps working."""
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    s.set_model("RW")
    sp.format_select.value = "ros-imu"
    sp.preview.toggle.value = True
    assert "Cannot project" in sp.preview.note.object and "N > 0" in sp.preview.note.object
    assert sp.preview.projections == {}
    s.set_model("WN+RW")  # the session goes on
    assert sp.preview.projections["gyro_x"].value("N") > 0


def test_preview_functions_on_their_own(app_demo: Path) -> None:
    import engine as eg

    log = eg.load_log(app_demo)
    fits = {"gyro_x": eg.fit_gmwm(eg.wavelet_variance(log["gyro_x"], fs=log.fs), "GM+WN+RW")}
    assert preview_projections(fits, "csv") == {} and preview_table({}) == ""
    projs = preview_projections(fits, "px4", units={"gyro_x": "deg/s"}, filter_rate=250.0)
    p = projs["gyro_x"]
    assert p.fs_filter == 250.0 and p.unit == "rad/s"
    assert "at 250 Hz" in preview_table(projs)
    fig = preview_figure(p)
    assert fig.x_scale.__class__.__name__ == "LogScale"
    assert math.isclose(p.band[0], 2 / 250.0, rel_tol=1e-9) or p.band[0] >= 2 / log.fs
    # the export's checks come first (a channel's unit), then the projection's reason
    with pytest.raises(Exception, match="N > 0"):
        preview_projections(
            {"gyro_x": eg.fit_gmwm(eg.wavelet_variance(log["gyro_x"], fs=log.fs), "RW")},
            "ros-imu",
            units={"gyro_x": "deg/s"},
        )


def test_projection_choice_reaches_the_preview_and_the_file(app_demo: Path) -> None:
    """The menu's "Filter numbers" choice: projected only (the engine's bound=False) in the
    preview and the file; the fit's own terms (projection="fit") project nothing."""
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    pv = sp.preview
    gyro, accel = _fit_two(app)
    sp.format_select.value = "kalibr"
    pv.toggle.value = True
    sp.projection_select.value = "plain"
    want = project(gyro, "kalibr", channel="gyro_x", unit=s.log.units["gyro_x"], bound=False)
    assert pv.projections["gyro_x"].value("N") == want.value("N")
    d = yaml.safe_load(sp.format_download.callback().getvalue())
    assert d["gyroscope_noise_density"] == want.value("N")
    sp.projection_select.value = "fit"
    assert pv.projections == {} and "nothing is projected" in pv.note.object
    d = yaml.safe_load(sp.format_download.callback().getvalue())
    # the fit's own white noise: N = sqrt(sigma2 / fs), deg -> rad
    n_fit = math.sqrt(gyro.params["WN.sigma2"] / s.fs) * math.pi / 180
    assert d["gyroscope_noise_density"] == pytest.approx(n_fit, rel=1e-9)


@pytest.mark.parametrize("projection", ["bound", "plain"])
def test_preview_and_written_file_agree_for_every_format(app_demo: Path, projection, monkeypatch):
    """The preview is the engine's ``projections``, computed as the file's numbers are: for
    every filter format, each channel's projection is the one the writer last computed for it
    (KF-GINS: at the file's one T_c, unbounded the largest with each driving noise kept;
    sensor_msgs/Imu: without the tail factors the others apply), with the loaded log's tail
    factors."""
    import engine as eg
    from engine.formats import FORMATS
    from engine.formats import noise as noise_mod

    log = eg.load_log(app_demo)
    fits = {
        ch: eg.fit_gmwm(eg.wavelet_variance(log[ch], fs=log.fs), "GM+WN+RW")
        for ch in ("gyro_x", "accel_x")
    }
    seen: dict[str, object] = {}
    real = noise_mod.project

    def spy(res, consumer, **kw):  # type: ignore[no-untyped-def]
        p = real(res, consumer, **kw)
        seen[kw["channel"]] = p
        return p

    monkeypatch.setattr(noise_mod, "project", spy)
    checked = []
    for name, f in FORMATS.items():
        if not f.is_filter:
            assert preview_projections(fits, name, units=dict(log.units)) == {}
            continue
        kw = {"filter_rate": 100.0} if f.needs_filter_rate else {}
        kw |= {"log": log, "tails": True, "projection": projection, "units": dict(log.units)}
        pv = preview_projections(fits, name, **kw)
        seen.clear()
        text = eg.export(None, fits, name, **kw)  # the file
        assert set(pv) == set(seen) == set(fits), name
        for ch, p in pv.items():
            w = seen[ch]
            if name == "kf-gins" and projection == "plain":
                # the file rescales each channel's own projection (the spy's) to its one T_c,
                # the largest, keeping the driving noise: the preview shows the file's T_c
                tc = yaml.safe_load(text)["imunoise"]["corrtime"] * 3600.0
                own = max(seen[c].value("T_c") for c in seen)
                assert p.value("T_c") == pytest.approx(tc, rel=1e-12) == own
                r = math.sqrt(tc / w.value("T_c"))
                assert p.value("sigma_b") == pytest.approx(w.value("sigma_b") * r, rel=1e-12)
                assert p.value("N") == w.value("N")
                continue
            assert p.consumer == w.consumer and p.band == w.band, (name, ch)
            np.testing.assert_array_equal(p.consumer_wv, w.consumer_wv)
            for q, wq in zip(p.params.values(), w.params.values(), strict=True):
                assert (q.name, q.value, q.binds) == (wq.name, wq.value, wq.binds), (name, ch)
                np.testing.assert_array_equal([q.low, q.high], [wq.low, wq.high])
        checked.append(name)
    assert len(checked) == sum(f.is_filter for f in FORMATS.values()) >= 11
