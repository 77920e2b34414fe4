"""`gmwm fit` runs the log check (one stderr line, JSON key ``qualification``), drops the warm-up
with --drop-warmup, and fits the temperature relation with --temperature (JSON key
``temperature``)."""

from __future__ import annotations

import html
import json

import numpy as np
import pytest

import engine as eg
from engine.cli import main

FS = 100.0
N = 100_000


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("qualify_cli")
    rng = np.random.default_rng(5)
    t = np.arange(N) / FS
    x = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-10)").simulate(N, fs=FS, rng=rng)
    warm = x + 0.5 * np.exp(-t / 30.0)
    shock = x.copy()
    shock[60_000:60_030] += rng.normal(size=30)
    eg.io.save_log(d / "warm.h5", {"gyro_x": warm}, FS, units={"gyro_x": "deg/s"})
    eg.io.save_log(d / "shock.h5", {"gyro_x": shock}, FS, units={"gyro_x": "deg/s"})
    temp = 25 + 10 * (1 - np.exp(-t / 200)) + 2 * np.sin(2 * np.pi * t / 300)
    y = x + 2e-3 * temp  # 7.2 deg/h per degC
    csv = d / "thermal.csv"
    np.savetxt(
        csv,
        np.column_stack([t, y, temp]),
        delimiter=",",
        header="time,gyro_x,temperature",
        comments="",
        fmt="%.9g",
    )
    return d


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_fit_says_what_the_check_found_in_one_line(files, capsys):
    code, out, err = run(capsys, "fit", str(files / "shock.h5"), "--model", "WN+RW", "--json")
    assert code == 0
    lines = [ln for ln in err.splitlines() if ln.startswith("gmwm fit: log check")]
    assert len(lines) == 1 and "shock (gyro_x)" in lines[0] and "samples 60,000-" in lines[0]
    d = json.loads(out)
    (f,) = [f for f in d["qualification"]["findings"] if f["kind"] == "shock"]
    ((a, b),) = f["ranges"]  # the burst is samples 60,000-60,029; its last steps may be small
    assert a == 60_000 and 60_020 <= b <= 60_030, (a, b)
    assert d["temperature"] is None


def test_drop_warmup_refits_without_the_transient(files, capsys):
    code, out, err = run(capsys, "fit", str(files / "warm.h5"), "--model", "WN+RW", "--json")
    q = json.loads(out)["qualification"]
    start = q["suggested_start"]
    assert code == 0 and start > 0 and "--drop-warmup" in err
    code, out2, err2 = run(
        capsys, "fit", str(files / "warm.h5"), "--model", "WN+RW", "--json", "--drop-warmup"
    )
    d2 = json.loads(out2)
    assert code == 0 and d2["qualification"]["dropped"] == start
    assert f"first {start:,} samples dropped" in err2

    # the transient inflated the RW: without it the RW is the planted 1e-10 (within 3x)
    def rw(d):
        return next(p["value"] for p in d["params"] if p["process"] == "RW")

    rw_before, rw_after = rw(json.loads(out)), rw(d2)
    assert rw_after < rw_before and rw_after < 3e-10, (rw_before, rw_after)


def test_temperature_auto_none_and_a_bad_name(files, capsys):
    csv = str(files / "thermal.csv")
    code, out, err = run(
        capsys, "fit", csv, "--channel", "gyro_x", "--units", "deg/s", "--model", "WN+RW", "--json"
    )
    assert code == 0
    t = json.loads(out)["temperature"]
    assert t["temperature"] == "temperature" and t["sensitivity_unit"] == "deg/h/degC"
    lo, hi = t["sensitivity_interval"]
    assert lo < 7.2 < hi
    assert "temperature sensitivity" in err
    code, out, _ = run(capsys, "fit", csv, "--model", "WN+RW", "--json", "--temperature", "none")
    assert code == 0 and json.loads(out)["temperature"] is None
    code, out, err = run(capsys, "fit", csv, "--model", "WN+RW", "--temperature", "T")
    errors = [ln for ln in err.splitlines() if ln.startswith("gmwm: error:")]
    assert code == 2 and out == "" and "Traceback" not in err and len(errors) == 1
    assert "--temperature T is not a channel" in errors[0]


def test_report_and_batch_run_the_check(files, capsys, tmp_path):
    shock = str(files / "shock.h5")
    html = tmp_path / "r.html"
    code, out, err = run(
        capsys, "report", shock, "-o", str(html), "--model", "WN+RW", "--format", "none", "--json"
    )
    assert code == 0 and "gmwm report: log check" in err and "shock (gyro_x)" in err
    q = json.loads(out)["qualification"]
    assert [f["kind"] for f in q["findings"]] == ["shock"]
    page = html.read_text(encoding="utf-8")
    assert "log check" in page and "burst(s) of steps beyond 8 robust SDs" in page
    code, out, err = run(
        capsys, "batch", shock, "--model", "WN+RW", "-o", str(tmp_path / "b"), "--quiet", "--json"
    )
    assert code == 0
    lines = [ln for ln in err.splitlines() if ln.startswith("gmwm batch:") and "log check" in ln]
    assert len(lines) == 1 and "shock (gyro_x)" in lines[0]
    (status,) = json.loads(out)["logs"]
    assert status["qualification"]["findings"][0]["kind"] == "shock"


def test_report_and_batch_fit_the_temperature_per_log(files, capsys, tmp_path):
    """`gmwm report` and `gmwm batch` (its JSON and its fleet report) take --temperature as
    `gmwm fit` does: one stderr line per compensated channel, the sensitivity in deg/h/degC
    whose interval covers the planted 7.2, the page's temperature paragraph; `--temperature
    none` fits the raw signal and says nothing of it."""
    csv = str(files / "thermal.csv")
    opts = ["--channels", "gyro_x", "--units", "deg/s", "--model", "WN+RW"]
    code, out, err = run(
        capsys, "report", csv, "-o", str(tmp_path / "r.html"), *opts, "--format", "none", "--json"
    )
    assert code == 0
    lines = [ln for ln in err.splitlines() if "temperature sensitivity" in ln]
    assert len(lines) == 1 and lines[0].startswith("gmwm report: gyro_x: ")
    t = json.loads(out)["channels"]["gyro_x"]["temperature"]
    lo, hi = t["sensitivity_interval"]
    assert t["sensitivity_unit"] == "deg/h/degC" and lo < 7.2 < hi
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert page.count('<p class="temperature" data-channel="gyro_x">') == 1

    fleet = tmp_path / "fleet.html"
    code, out, err = run(
        capsys, "batch", csv, *opts, "-o", str(tmp_path / "b"), "--report", str(fleet),
        "--quiet", "--json", "--workers", "1",
    )  # fmt: skip
    assert code == 0
    lines = [ln for ln in err.splitlines() if "temperature sensitivity" in ln]
    assert len(lines) == 1 and lines[0].startswith(f"gmwm batch: {csv}: gyro_x: ")
    d = json.loads(out)
    (status,) = d["logs"]
    bt = status["temperature"]["gyro_x"]
    (row,) = [r for r in d["summary"] if r["process"] == "temperature"]  # the fleet's spread
    assert row["unit"] == "deg/h/degC" and row["n_units"] == 1 and row["mean"] == t["sensitivity"]
    assert "bias temperature sensitivity" in (tmp_path / "b" / "summary.csv").read_text()
    assert bt["sensitivity"] == t["sensitivity"]  # the same fit as the report's
    assert bt["sensitivity_unit"] == "deg/h/degC" and bt["temperature"] == "temperature"
    assert 'class="temperature" data-channel="gyro_x"' in fleet.read_text(encoding="utf-8")

    code, out, err = run(
        capsys, "report", csv, "-o", str(tmp_path / "r2.html"), *opts, "--format", "none",
        "--json", "--temperature", "none",
    )  # fmt: skip
    assert code == 0 and "temperature sensitivity" not in err
    assert json.loads(out)["channels"]["gyro_x"]["temperature"] is None
    code, out, err = run(
        capsys, "batch", csv, *opts, "-o", str(tmp_path / "b2"), "--quiet", "--json",
        "--workers", "1", "--temperature", "T",
    )  # fmt: skip
    errors = [ln for ln in err.splitlines() if "--temperature T is not a channel" in ln]
    assert code == 2 and len(errors) == 1, err


def test_select_runs_the_check_and_the_temperature_fit(files, capsys):
    """`gmwm select` checks the log as `gmwm fit` does (one stderr line, JSON
    ``qualification``) and ranks the candidates on the compensated WV of a log with a
    temperature channel (JSON ``temperature``, the sensitivity's interval covers 7.2)."""
    code, out, err = run(
        capsys, "select", str(files / "shock.h5"), "--models", "WN+RW,WN", "--json"
    )
    assert code == 0
    lines = [ln for ln in err.splitlines() if ln.startswith("gmwm select: log check")]
    assert len(lines) == 1 and "shock (gyro_x)" in lines[0] and "samples 60,000-" in lines[0]
    d = json.loads(out)
    assert [f["kind"] for f in d["qualification"]["findings"]] == ["shock"]
    assert d["temperature"] is None
    csv = str(files / "thermal.csv")
    code, out, err = run(
        capsys, "select", csv, "--channel", "gyro_x", "--units", "deg/s", "--models", "WN+RW,WN",
        "--json", "--temperature", "temperature",  # named: the loud WN hides it from auto
    )  # fmt: skip
    d = json.loads(out)
    lo, hi = d["temperature"]["sensitivity_interval"]
    assert code == 0 and lo < 7.2 < hi and "gmwm select: gyro_x: temperature sensitivity" in err
    wv = d["temperature"]["wv_raw"]["variance"]
    assert d["wv"]["variance"][-1] < wv[-1]  # ranked on the compensated WV, not the raw one


def test_fit_of_several_files_checks_each(files, capsys):
    """`gmwm fit A B --model M` (one model fitted to several recordings) checks every file:
    one stderr line per file with a finding, naming the file; JSON ``qualification`` in the
    order of the inputs."""
    shock, warm = str(files / "shock.h5"), str(files / "warm.h5")
    code, out, err = run(capsys, "fit", shock, warm, "--model", "WN+RW", "--json")
    assert code == 0
    lines = [ln for ln in err.splitlines() if "log check" in ln]
    assert len(lines) == 2
    assert lines[0].startswith(f"gmwm fit: {shock}: log check") and "shock (gyro_x)" in lines[0]
    assert lines[1].startswith(f"gmwm fit: {warm}: log check") and "--drop-warmup" in lines[1]
    d = json.loads(out)
    assert d["inputs"] == [shock, warm]
    kinds = [[f["kind"] for f in q["findings"]] for q in d["qualification"]]
    assert kinds[0] == ["shock"] and "warmup" in kinds[1]
    assert d["temperature"] == [None, None]


def test_a_log_cut_into_segments_is_compensated_under_the_rule_of_any_log(files, capsys, tmp_path):
    """`--segments` with `--temperature auto`: fitted on the segments, each with its own
    offset, and judged by the rule of any log. This log's noise (WN 1e-2 (deg/s)^2) hides the
    planted 7.2 deg/h/degC in 90,000 still samples: the interval holds 0, so one stderr line
    says it is not compensated and names the flag that compensates anyway, as the report
    does; `--temperature temperature` compensates, the interval covering 7.2."""
    csv = str(files / "thermal.csv")
    segs = ["--segments", "0:40000,50000:100000", "--units", "deg/s"]
    code, out, err = run(capsys, "fit", csv, "--model", "WN+RW", "--json", *segs)
    t = json.loads(out)["temperature"]
    lo, hi = t["sensitivity_interval"]
    assert code == 0 and lo < 0 < hi and t["compensated"] is False
    (line,) = [ln for ln in err.splitlines() if "temperature sensitivity" in ln]
    assert "not distinguishable from 0" in line
    assert "not compensated (name it, --temperature temperature, to compensate anyway)" in line
    code, out, err = run(
        capsys, "fit", csv, "--model", "WN+RW", "--json", *segs, "--temperature", "temperature"
    )
    t = json.loads(out)["temperature"]
    lo, hi = t["sensitivity_interval"]
    assert code == 0 and lo < 7.2 < hi and t["compensated"] is True
    assert "temperature sensitivity" in err and "not compensated" not in err
    page = tmp_path / "r.html"
    code, _, _ = run(capsys, "report", csv, "-o", str(page), "--model", "WN+RW", *segs)
    assert code == 0
    text = html.unescape(page.read_text())
    assert "not compensated" in text and "--temperature temperature" in text


def test_the_ardupilot_flight_is_not_compensated_with_auto(capsys, tmp_path):
    """docs/drone-logs.md's walk-through: `gmwm fit 00000001.BIN --segments auto --model WN+RW
    --channel imu0_gyro_x` (`--temperature auto`): one stderr line says the sensitivity is not
    distinguishable from 0 and which flag compensates anyway; the JSON says not compensated,
    and RW.gamma2 is the documented 5.797e-11 (rad/s)^2; the report says it too."""
    pytest.importorskip("pymavlink", reason="pip install 'gmwm-app[ardupilot]'")
    from flightlogs import make

    path = str(
        make.write_dataflash(
            tmp_path / "00000001.BIN", make.simulate_flight(250.0), make.ARDUPILOT_PARAMS
        )
    )
    argv = ["--segments", "auto", "--model", "WN+RW", "--channel", "imu0_gyro_x"]
    code, out, err = run(capsys, "fit", path, *argv, "--json")
    d = json.loads(out)
    assert code == 0 and d["temperature"]["compensated"] is False
    assert d["temperature"]["fit_raw"] is None
    (rw,) = [p["value"] for p in d["params"] if p["label"] == "RW" and p["name"] == "gamma2"]
    assert rw == pytest.approx(5.797e-11, rel=1e-3)  # docs/drone-logs.md
    (line,) = [ln for ln in err.splitlines() if "temperature sensitivity" in ln]
    assert "not distinguishable from 0" in line
    assert "(name it, --temperature imu0_temperature, to compensate anyway)" in line
    page = tmp_path / "r.html"
    code, _, _ = run(capsys, "report", path, "-o", str(page), *argv)
    text = html.unescape(page.read_text())
    assert code == 0 and "not compensated" in text and "--temperature imu0_temperature" in text


def test_channels_fit_runs_the_log_check_and_drops_the_warmup(files, tmp_path, capsys):
    """`gmwm fit --channels` runs the log check that `gmwm fit` runs, on the channels it fits:
    one stderr line naming the shock in gyro_y, the JSON key ``qualification``; with
    --drop-warmup the multivariate fit is that of the log without the warm-up the check
    found (the same numbers as wv_matrix + fit_mgmwm of the cut log). Before, the check was
    skipped: no line, no key, and the warm-up stayed in the fit."""
    from engine.io import drop_warmup, qualify_log
    from engine.multivariate import MultiModel, fit_mgmwm
    from engine.wv import wv_matrix

    log = eg.load_log(files / "warm.h5")
    x = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-10)").simulate(
        N, fs=FS, rng=np.random.default_rng(9)
    )
    y = x.copy()
    y[30_000:30_030] += np.random.default_rng(10).normal(size=30)
    path = tmp_path / "two.h5"
    eg.io.save_log(
        path,
        {"gyro_x": log["gyro_x"], "gyro_y": y},
        FS,
        units={"gyro_x": "deg/s", "gyro_y": "deg/s"},
    )
    argv = ["fit", str(path), "--model", "WN+RW", "--channels", "gyro_x,gyro_y", "--json"]
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("gmwm fit: log check")]
    assert len(lines) == 1 and "shock (gyro_y)" in lines[0] and "--drop-warmup" in lines[0]
    q = json.loads(out)["qualification"]
    assert [f["channel"] for f in q["findings"] if f["kind"] == "shock"] == ["gyro_y"]
    start = q["suggested_start"]
    assert start > 0 and q["dropped"] == 0
    code, out, err = run(capsys, *argv, "--drop-warmup")
    d = json.loads(out)
    assert code == 0 and d["qualification"]["dropped"] == start
    both = eg.load_log(path)
    want_q = qualify_log(both, ["gyro_x", "gyro_y"])
    assert want_q.suggested_start == start
    cut = drop_warmup(both, start)
    chans = ["gyro_x", "gyro_y"]
    want = fit_mgmwm(wv_matrix(cut, channels=chans), MultiModel(chans, "WN+RW"), weights="ci")
    assert [p["value"] for p in d["params"]] == [float(v) for v in want.params.values()]


@pytest.mark.real_data
def test_channels_fit_of_adis_unit4_reports_its_bursts(real_data, capsys):
    """ADIS16405 unit 4, its three accelerometers fitted together: the log check's line and
    JSON give what the single-channel check finds on each of them, the documented bursts at
    samples 11,710-11,900 (accel_y), 404,530-404,640 and 514,580-514,690 (accel_z) among them
    (tests/engine/test_log_qualification.py)."""
    from engine.io import qualify_log

    path = real_data / "adis16405_imu4.h5"
    chans = ["accel_x", "accel_y", "accel_z"]
    argv = ["fit", str(path), "--model", "WN+RW", "--channels", ",".join(chans), "--json"]
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    assert sum(ln.startswith("gmwm fit: log check") for ln in err.splitlines()) == 1
    q = json.loads(out)["qualification"]
    shocks = [
        (f["channel"], [tuple(r) for r in f["ranges"]])
        for f in q["findings"]
        if f["kind"] == "shock"
    ]
    one = [
        (f.channel, list(f.ranges)) for f in qualify_log(eg.load_log(path), chans).of_kind("shock")
    ]
    assert shocks == one
    ranges = [r for _, rs in shocks for r in rs]
    for a, b in ((11_710, 11_900), (404_530, 404_640), (514_580, 514_690)):
        assert any(lo < b and a < hi for lo, hi in ranges), (a, b, shocks)
