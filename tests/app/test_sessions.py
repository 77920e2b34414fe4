"""App sessions, exports, server limits and time gaps; no browser."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import engine as eg
from gmwm_app import limits
from gmwm_app import session_view as sv
from gmwm_app.state import AppState


@pytest.fixture
def no_limits() -> Iterator[None]:
    """Limits back to the library default after the test."""
    yield
    limits.configure()


def _gap_csv(path: Path, n: int = 5000, cut: int = 3000) -> Path:
    t = np.arange(n) / 100.0
    t[cut:] += 5.0  # a 5 s gap at sample `cut`
    x = np.random.default_rng(1).normal(size=n)
    np.savetxt(path, np.c_[t, x], delimiter=",", header="time,gyro_x", comments="")
    return path


# ---------------------------------------------------------------------------------------------
# session file
# ---------------------------------------------------------------------------------------------
def test_session_round_trip(app_state: AppState, app_demo: Path, tmp_path: Path) -> None:
    s = app_state
    log = tmp_path / "log.h5"
    log.write_bytes(app_demo.read_bytes())
    assert s.load_path(log), s.error
    assert s.select_channel("gyro_y") and s.set_model("GM+WN+RW") and s.set_robust(True)
    assert s.set_fs(50.0)
    text = sv.session_json(s)
    doc = json.loads(text)
    assert doc["schema"] == "gmwm-session/1"
    assert doc["data"]["path"] == str(log.resolve()) and doc["data"]["fingerprint"]
    assert doc["app"]["channel"] == "gyro_y" and doc["app"]["robust"] is True
    assert doc["channels"]["gyro_y"]["model"] == "GM+WN+RW"
    assert sv.session_filename(s) == "gmwm_session_log_gyro_y.json"

    other = AppState()
    assert other.load_demo()
    plan = sv.prepare_restore(text, "s.json")
    assert plan.loaded is not None and not plan.problems
    assert sv.apply_restore(other, plan), other.error
    assert (other.source, other.path, other.channel) == ("path", str(log.resolve()), "gyro_y")
    assert other.robust and other.fs == 50.0 and other.model.spec() == "GM+WN+RW"
    assert other.result.params == pytest.approx(s.result.params, rel=1e-9)
    # the saved fit in the file is the same fit
    saved = plan.session.fits["gyro_y"]
    assert saved.params == pytest.approx(s.result.params, rel=1e-12)


def test_session_round_trip_of_a_teaching_scenario() -> None:
    """A scenario session names its key, not a file: restoring simulates the same log."""
    s = AppState()
    loaded = AppState.read("scenario", path="wn_gm")
    assert s.install(loaded), s.error
    assert s.set_model("GM+WN"), s.error
    text = sv.session_json(s)
    assert json.loads(text)["app"]["scenario"] == "wn_gm"
    other = AppState()
    assert other.load_demo()
    plan = sv.prepare_restore(text, "s.json")
    assert plan.loaded is not None and not plan.problems, plan.problems
    assert sv.apply_restore(other, plan), other.error
    assert (other.source, other.path, other.channel) == ("scenario", "wn_gm", s.channel)
    assert other.model.spec() == "GM+WN"
    assert other.result.params == pytest.approx(s.result.params, rel=1e-9)  # same samples


def test_restore_says_what_is_missing(app_state: AppState, tmp_path: Path) -> None:
    s = app_state
    assert s.set_model("WN+RW")
    from gmwm_app.state import demo_path

    log = tmp_path / "gone.h5"
    log.write_bytes(demo_path().read_bytes())
    assert s.load_path(log)
    text = sv.session_json(s)
    log.unlink()
    other = AppState()
    assert other.load_demo() and other.set_model("WN")
    plan = sv.prepare_restore(text)
    assert plan.loaded is None
    assert not sv.apply_restore(other, plan)
    assert "gone.h5" in other.error and "not on this server" in other.error
    assert other.model.spec() == "WN" and other.source == "demo"  # left as it was

    # an uploaded file cannot be replayed: say so
    assert s.load_upload(demo_path().read_bytes(), "mine.h5")
    plan = sv.prepare_restore(sv.session_json(s))
    assert not sv.apply_restore(other, plan)
    assert "uploaded file mine.h5" in other.error and "upload mine.h5 again" in other.error
    # once the file is uploaded again, the session restores on it
    assert other.load_upload(demo_path().read_bytes(), "mine.h5") and other.set_model("WN")
    assert sv.apply_restore(other, plan), other.error
    assert other.model.spec() == "WN+RW" and other.filename == "mine.h5"


def test_restore_refuses_bad_files(app_state: AppState) -> None:
    for text in ("not json", json.dumps({"schema": "other"}), "[]"):
        with pytest.raises(ValueError, match="session"):
            sv.prepare_restore(text, "bad.json")


def test_restore_respects_data_folders(
    app_state: AppState, tmp_path: Path, no_limits: None
) -> None:
    from gmwm_app.state import demo_path

    log = tmp_path / "outside" / "log.h5"
    log.parent.mkdir()
    log.write_bytes(demo_path().read_bytes())
    assert app_state.load_path(log)
    text = sv.session_json(app_state)
    limits.configure(data_dirs=[tmp_path / "elsewhere"])
    plan = sv.prepare_restore(text)
    assert plan.loaded is None and "outside the folders" in plan.problems[0]


# ---------------------------------------------------------------------------------------------
# exports
# ---------------------------------------------------------------------------------------------
def test_exports_of_the_fit(app_state: AppState) -> None:
    s = app_state
    with pytest.raises(ValueError, match="no fit"):
        sv.export_text(s, "kalibr")
    assert s.set_model("GM+WN+RW")
    # the fit's own terms (the engine's projection="fit", the app's third choice)
    y = sv.export_text(s, "kalibr", projection="fit")
    assert "gyroscope_noise_density:" in y and "gyro_x" in y
    wn = s.result.params["WN.sigma2"]
    import yaml

    doc = yaml.safe_load(y)
    # deg/s -> rad/s, density = sqrt(sigma2 / fs)
    assert doc["gyroscope_noise_density"] == pytest.approx(
        np.sqrt(wn / s.fs) * np.pi / 180, rel=1e-9
    )
    # by default the app writes what the engine's export writes by default from the loaded log
    # (as gmwm export does: the data bound with the log's tail factors): the projected and
    # over-bounded numbers, never below the fit's own white noise density here
    from engine.formats import export

    y_bound = sv.export_text(s, "kalibr")
    fits = {s.channel: s.result}
    ref = export(
        None,
        fits,
        "kalibr",
        units={s.channel: s.unit},
        source=s.filename,
        allow_partial=True,
        log=s.log,
    )
    assert y_bound == ref
    assert yaml.safe_load(y_bound)["gyroscope_noise_density"] >= doc["gyroscope_noise_density"]
    assert "projected" in y_bound.lower() or "bound" in y_bound.lower()
    ds = sv.export_text(s, "datasheet")
    assert "gyro_x" in ds and "correlation time" in ds
    # the on-screen datasheet table shows the download's rows (one table: engine.units)
    from gmwm_app.views import datasheet_rows

    screen = datasheet_rows(s)
    lines = [ln for ln in ds.splitlines()[1:] if ln.strip()]
    assert len(screen) == len(lines) and len(screen) > 8
    for r, ln in zip(screen, lines, strict=True):
        assert ln.split()[1] == r["process"] and f" {r['quantity']} " in ln
        assert ln.endswith("  " + r["unit"].replace("²", "^2")), (ln, r)


# ---------------------------------------------------------------------------------------------
# limits
# ---------------------------------------------------------------------------------------------
def test_paths_limited_to_data_folders(app_demo: Path, tmp_path: Path, no_limits: None) -> None:
    inside = tmp_path / "in"
    inside.mkdir()
    ok = inside / "log.h5"
    ok.write_bytes(app_demo.read_bytes())
    out = tmp_path / "log.h5"
    out.write_bytes(app_demo.read_bytes())
    limits.configure(data_dirs=[inside])
    s = AppState()
    assert s.load_path(ok), s.error
    assert not s.load_path(out)
    assert "outside the folders this server may read" in s.error and "upload" in s.error
    assert str(inside) not in s.error and str(tmp_path) not in s.error.replace(str(out), "")
    assert not s.load_path(inside / ".." / "log.h5")  # no escape with ..
    assert not s.load_path(tmp_path / "nothing.h5")  # outside: refused before existence
    assert "outside the folders" in s.error and "no such file" not in s.error
    assert s.path == str(ok)
    limits.configure(data_dirs=[inside], allowed_files=[out])
    assert s.load_path(out), s.error
    assert s.load_demo()  # the bundled demo is always allowed


def test_upload_limit(app_demo: Path, no_limits: None) -> None:
    data = app_demo.read_bytes()
    limits.configure(max_upload_mb=len(data) / 2e6)
    s = AppState()
    assert not s.load_upload(data, "big.h5")
    assert "more than this server accepts" in s.error and "big.h5" in s.error
    limits.configure(max_upload_mb=len(data) / 1e6 + 1)
    assert s.load_upload(data, "big.h5"), s.error


def test_default_data_dirs() -> None:
    dirs = limits.default_data_dirs()
    assert Path.cwd().resolve() in dirs
    repo = Path(limits.__file__).resolve().parents[1]
    assert (repo / "engine" / "demo").resolve() in dirs  # the bundled demo's folder


def test_cli_limits(tmp_path: Path, no_limits: None) -> None:
    from gmwm_app.__main__ import build_parser, main

    a = build_parser().parse_args(["--max-upload-mb", "5", "--data-dir", "a", "--data-dir", "b"])
    assert a.max_upload_mb == 5.0 and a.data_dir == ["a", "b"]
    assert main(["--data-dir", str(tmp_path / "missing"), "--no-show"]) == 2
    assert main(["--max-upload-mb", "0", "--no-show"]) == 2


# ---------------------------------------------------------------------------------------------
# time gaps and the page (no server)
# ---------------------------------------------------------------------------------------------
def test_gaps_offer_the_longest_segment(app_demo: Path, tmp_path: Path) -> None:
    from gmwm_app.app import create_app

    gap = _gap_csv(tmp_path / "gap.csv")
    page = create_app()
    app = page.gmwm_app
    sp = app.session_panel
    app.path_input.value = str(gap)
    app._on_path()
    s = app.state
    assert "gap" in s.error and s.source == "demo"  # refused, the demo stays
    assert sp.gap_box.visible and "samples 0 to 2999" in sp.gap_report.object
    sp.longest_button.clicks += 1
    assert s.error == "" and s.filename == "gap.csv" and s.n == 3000, s.error
    assert not sp.gap_box.visible and "segment='longest'" in s.notice
    doc = json.loads(sp._session_file().getvalue())
    assert doc["data"]["load"] == {"segment": "longest"}
    # the session restores the same segment
    other = AppState()
    assert sv.apply_restore(other, sv.prepare_restore(json.dumps(doc)))
    assert other.n == 3000 and other.filename == "gap.csv"


def test_page_session_widgets(app_demo: Path) -> None:
    from gmwm_app.app import create_app

    page = create_app()
    app = page.gmwm_app
    sp = app.session_panel
    assert sp.kalibr_download.disabled and "need a fit" in sp.export_note.object
    app.state.set_model("GM+WN+RW")
    assert not sp.kalibr_download.disabled and "**gyro_x** only" in sp.export_note.object
    assert "gyroscope_noise_density" in sp.kalibr_download.callback().getvalue()
    assert "correlation time" in sp.datasheet_download.callback().getvalue()
    assert sp.kalibr_download.filename == "imu_demo_imu_gyro_x.yaml"
    text = sp.session_download.callback().getvalue()
    app.state.set_model("WN")
    app.state.select_channel("gyro_z")
    sp.restore_input.filename = "s.json"
    sp.restore_input.value = text.encode()
    s = app.state
    assert s.channel == "gyro_x" and s.model.spec() == "GM+WN+RW" and s.error == ""
    sp.restore_input.value = b"nonsense"
    assert "not a GMWM session" in s.error or "cannot read session" in s.error


def test_page_export_menu_every_format_from_the_fitted_channels(app_demo: Path) -> None:
    """The sidebar's format menu: the filter formats take the fits of every channel fitted in
    the session; the numbers follow the per-sample parameters (N = sqrt(sigma2 / fs),
    K = sqrt(gamma2 * fs), deg -> rad); inflate and the filter rate reach the file."""
    import math

    import yaml

    from engine.formats import FORMATS
    from gmwm_app.app import create_app

    app = create_app().gmwm_app
    sp, s = app.session_panel, app.state
    assert set(sp.format_select.options.values()) == set(FORMATS)
    assert sp.format_download.disabled and "none yet" in sp.fits_note.object
    s.set_model("WN+RW")
    assert not sp.format_download.disabled and "**gyro_x**" in sp.fits_note.object
    # a gyroscope alone: the VIO file cannot be written; the page says why, no traceback
    sp.format_select.value = "openvins"
    assert sp.format_download.callback().getvalue().startswith("# could not export")
    assert "accelerometer" in s.error
    gyro = s.result
    s.select_channel("accel_x")
    s.set_model("WN+RW")
    accel = s.result
    assert "**gyro_x, accel_x**" in sp.fits_note.object
    sp.inflate_input.value = 2.0
    text = sp.format_download.callback().getvalue()
    assert sp.format_download.filename == "openvins_demo_imu.yaml"
    d = yaml.safe_load(text.split("\n", 1)[1])["imu0"]
    fs = s.fs
    wn = {r: next(p for p in r.model.processes if p.code == "WN") for r in (gyro, accel)}
    rad = math.pi / 180
    # the app writes the engine's default export (it bounds the fit and the
    # empirical WV's lower 95 % limit): the fitted WN+RW's white noise raised where the data
    # need it (K may then go down: the least inflation trades; the engine's bound is tested
    # against formulas elsewhere)
    for r, kind, f in ((gyro, "gyroscope", rad), (accel, "accelerometer", 1.0)):
        p = eg.formats.project(r, "openvins", ci=None)
        assert d[f"{kind}_noise_density"] == pytest.approx(2 * p.value("N"), rel=1e-9)
        assert d[f"{kind}_random_walk"] == pytest.approx(2 * p.value("K"), rel=1e-9)
        assert d[f"{kind}_noise_density"] >= 2 * f * math.sqrt(wn[r].sigma2 / fs) * (1 - 1e-9)
    # PX4 needs the filter rate: the input shows, and the value scales by sqrt(rate)
    sp.format_select.value = "px4"
    assert sp.rate_input.visible and sp.format_download.filename == "px4_demo_imu.params"
    assert sp.format_download.callback().getvalue().startswith("# could not export")
    assert "rate" in s.error
    sp.inflate_input.value = 1.0
    sp.rate_input.value = 250.0
    px4 = sp.format_download.callback().getvalue()
    line = next(ln for ln in px4.splitlines() if "EKF2_GYR_NOISE" in ln and not ln.startswith("#"))
    value = float(line.split("\t")[3])  # QGC format: vehicle, component, name, value, type
    n250 = eg.formats.project(gyro, "px4", fs_filter=250.0, ci=None).value("N")
    assert value == pytest.approx(n250 * math.sqrt(250.0), 1e-9)  # per step at 250 Hz
    # new data forget the fits of the old: only the channel refitted on the new log is left
    s.load_demo()
    assert s.channel == "accel_x" and "fitted in this session: **accel_x**." in sp.fits_note.object
