"""Fleet calibration (``engine.batch``, ``gmwm batch``): a fleet of simulated units whose true
white-noise and random-walk levels differ from unit to unit; the summary's spread across
units against the truth's spread; a bad file reported per file while the rest completes."""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest

import engine as eg
from engine.batch import expand_paths, fleet_summary
from engine.cli import main
from engine.io import save_log

FS = 100.0
N = 2**15
#: per unit: WN sigma2 (deg/s)^2 and RW gamma2 (deg/s)^2, 26 % and 40 % spread across units
SIGMA2 = 1e-3 * np.array([0.7, 0.85, 1.0, 1.15, 1.3, 1.45])
GAMMA2 = 1e-7 * np.array([0.5, 1.5, 1.0, 2.0, 0.8, 1.2])


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    for k, (s2, g2) in enumerate(zip(SIGMA2, GAMMA2, strict=True)):
        m = eg.parse_model(f"WN(sigma2={s2})+RW(gamma2={g2})")
        chans = {
            c: m.simulate(N, fs=FS, rng=10 * k + i) for i, c in enumerate(("gyro_x", "gyro_y"))
        }
        save_log(d / f"unit{k}.h5", chans, FS, units=dict.fromkeys(chans, "deg/s"))
    (d / "broken.csv").write_text("time,gyro_x\n0,1\n0.01,oops\n")
    return d


@pytest.fixture(scope="module")
def batch(fleet):
    return eg.fit_batch(
        [str(fleet / "unit*.h5"), str(fleet / "broken.csv")], model="WN+RW", workers=1
    )


def test_the_fleet_spread_matches_the_truths_spread(batch):
    assert len(batch.fitted) == 6 and [lf.source.rsplit("/", 1)[1] for lf in batch.failed] == [
        "broken.csv"
    ]
    rows = {(r.channel, r.kind, r.quantity, r.unit): r for r in batch.rows}
    for ch in ("gyro_x", "gyro_y"):
        wn = rows[(ch, "parameter", "WN.sigma2", "(deg/s)^2")]
        assert wn.n_units == 6
        # sigma2 is estimated within ~1 % per unit (2^15 samples): the fleet's mean, SD, min,
        # max and CV are the truth's within a few %
        assert wn.mean == pytest.approx(SIGMA2.mean(), rel=0.02)
        assert wn.sd == pytest.approx(SIGMA2.std(ddof=1), rel=0.08)
        assert wn.min == pytest.approx(SIGMA2.min(), rel=0.04)
        assert wn.max == pytest.approx(SIGMA2.max(), rel=0.04)
        assert wn.cv == pytest.approx(SIGMA2.std(ddof=1) / SIGMA2.mean(), rel=0.1)
        # the datasheet quantity in its unit: N = sqrt(sigma2 / fs) deg/s/sqrt(Hz)
        n_wn = rows[(ch, "datasheet", "white noise density", "deg/s/sqrt(Hz)")]
        assert n_wn.mean == pytest.approx(np.sqrt(SIGMA2 / FS).mean(), rel=0.02)
        # the random walk is estimated less well (few long scales): the spread is seen
        rw = rows[(ch, "parameter", "RW.gamma2", "(deg/s)^2")]
        assert rw.mean == pytest.approx(GAMMA2.mean(), rel=0.35)
        assert rw.sd > 0.3 * GAMMA2.std(ddof=1)
    # the per-unit values behind the summary: unit k's fit is near unit k's truth
    for k, lf in enumerate(batch.fitted):
        assert lf.fits["gyro_x"].params["WN.sigma2"] == pytest.approx(SIGMA2[k], rel=0.05)
        assert lf.fs == FS and lf.n == N


def test_each_log_has_its_report_and_a_bad_log_its_error(batch, fleet, tmp_path):
    bad = batch.failed[0]
    assert "LoadError" in bad.error and "line 3, column 2 of 2" in bad.error and not bad.fits
    assert "oops" not in bad.error  # the file's content is never quoted
    files = batch.save(tmp_path / "out")
    assert sorted(p.rsplit("/", 1)[1] for p in files["reports"].values()) == [
        f"unit{k}.json" for k in range(6)
    ]
    rep = json.loads((tmp_path / "out" / "unit2.json").read_text())
    assert rep["schema"] == "gmwm-report/1" and set(rep["channels"]) == {"gyro_x", "gyro_y"}
    direct = eg.fit_gmwm(
        eg.wavelet_variance(eg.load_log(fleet / "unit2.h5")["gyro_y"], fs=FS), "WN+RW"
    )
    got = {
        f"{p['label']}.{p['name']}": p["value"] for p in rep["channels"]["gyro_y"]["fit"]["params"]
    }
    assert got == pytest.approx(direct.params, rel=1e-12)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert (summary["n_logs"], summary["n_fitted"], summary["n_failed"]) == (7, 6, 1)
    assert [lg["ok"] for lg in summary["logs"]] == [True] * 6 + [False]
    table = list(csv.DictReader(io.StringIO((tmp_path / "out" / "summary.csv").read_text())))
    assert len(table) == len(batch.rows)
    wn = next(r for r in table if r["channel"] == "gyro_x" and r["quantity"] == "WN.sigma2")
    assert float(wn["mean"]) == pytest.approx(SIGMA2.mean(), rel=0.02) and wn["n_units"] == "6"


def test_the_local_pool_gives_the_same_fleet(batch, fleet):
    from engine._blas import blas_threads, set_blas_threads

    before = blas_threads()
    set_blas_threads(1)  # the workers' BLAS: identical to the last bit (see test_parallel)
    try:
        one = eg.fit_batch([str(fleet / "unit*.h5")], model="WN+RW", workers=1)
        two = eg.fit_batch([str(fleet / "unit*.h5")], model="WN+RW", workers=2)
    finally:
        if before is not None:
            set_blas_threads(before)
    assert [lf.report for lf in two.logs] == [lf.report for lf in one.logs]
    assert two.rows == one.rows and len(two.rows) == len(fleet_summary(batch.fitted))


def test_paths_globs_and_same_named_logs(fleet, tmp_path):
    got = expand_paths([str(fleet / "unit[01].h5"), str(fleet / "nothing*.h5"), "x.csv"])
    assert [p.rsplit("/", 1)[-1] for p, _ in got] == [
        "unit0.h5",
        "unit1.h5",
        "nothing*.h5",
        "x.csv",
    ]
    assert [bool(e) for _, e in got] == [False, False, True, False]
    # two logs named alike in two folders get two reports
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for sub in ("a", "b"):
        (tmp_path / sub / "imu.h5").write_bytes((fleet / "unit0.h5").read_bytes())
    res = eg.fit_batch(
        [str(tmp_path / "a" / "imu.h5"), str(tmp_path / "b" / "imu.h5")],
        model="WN",
        channels=["gyro_x"],
        workers=1,
    )
    files = res.save(tmp_path / "out")
    assert sorted(p.rsplit("/", 1)[1] for p in files["reports"].values()) == [
        "imu.json",
        "imu_2.json",
    ]
    assert res.rows[0].sd == 0.0 and res.rows[0].cv == 0.0  # the same log twice
    with pytest.raises(eg.ModelError, match="model"):
        eg.fit_batch(["x.h5"], model="WN", select="WN+RW")
    with pytest.raises(eg.ModelError):
        eg.fit_batch(["x.h5"], model="WN+XYZ")


def test_select_picks_a_sub_model_per_channel(fleet):
    res = eg.fit_batch([str(fleet / "unit[12].h5")], select="WN+RW+DR", workers=1)
    allowed = {m.spec() for m in eg.inference.submodels("WN+RW+DR")}
    for lf in res.fitted:
        for r in lf.fits.values():
            assert r.model.cleared().spec() in allowed and "WN" in r.model.spec()


def test_cli_batch_writes_reports_and_summary_and_exits_by_the_rules(fleet, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["batch", str(fleet / "unit*.h5"), str(fleet / "broken.csv"), "--model", "WN+RW"]
    assert main([*argv, "-o", str(out), "--workers", "1", "--json"]) == 0
    cap = capsys.readouterr()
    d = json.loads(cap.out)
    assert (d["n_fitted"], d["n_failed"]) == (6, 1) and d["files"]["summary_csv"].endswith(".csv")
    assert "broken.csv: LoadError" in cap.err
    assert "7/7" not in cap.err  # the progress bar is drawn on a terminal only (not captured)
    assert (out / "unit5.json").exists() and (out / "summary.csv").exists()
    # the table: units on every row
    assert main([*argv, "-o", str(out), "--workers", "1", "--quiet"]) == 0
    cap = capsys.readouterr()
    line = next(ln for ln in cap.out.splitlines() if "angle random walk" in ln)
    assert line.split()[0] == "gyro_x" and "deg/sqrt(h)" in line and "%" in line
    assert "1 failed" in cap.out and "gmwm batch:" not in cap.err
    # nothing fitted: exit 2, one line per file and the summary still written
    rc = main(["batch", str(fleet / "broken.csv"), "--model", "WN", "-o", str(tmp_path / "o2")])
    cap = capsys.readouterr()
    assert rc == 2 and "no log could be fitted" in cap.err
    assert json.loads((tmp_path / "o2" / "summary.json").read_text())["n_fitted"] == 0
    # usage: a model or a selection, not both
    assert main(["batch", "x.h5", "-o", str(tmp_path), "--model", "WN", "--select", "WN"]) == 2
    assert "not allowed with" in capsys.readouterr().err


def test_cli_scheduler_local_runs_on_a_dask_local_cluster(fleet, tmp_path, capsys):
    pytest.importorskip("distributed")
    argv = ["batch", str(fleet / "unit[0-2].h5"), "--model", "WN+RW", "--quiet", "--json"]
    assert main([*argv, "-o", str(tmp_path / "a"), "--scheduler", "local"]) == 0
    on_dask = json.loads(capsys.readouterr().out)
    assert on_dask["settings"]["executor"] == "ClientExecutor"
    assert on_dask["settings"]["workers"] == 2
    assert main([*argv, "-o", str(tmp_path / "b"), "--workers", "1"]) == 0
    local = json.loads(capsys.readouterr().out)
    # the same fits (to the last bits: this process's BLAS may have two threads, the workers'
    # one; tests/engine/test_parallel.py checks bit equality with one thread)
    assert [(r["channel"], r["quantity"]) for r in on_dask["summary"]] == [
        (r["channel"], r["quantity"]) for r in local["summary"]
    ]
    for a, b in zip(on_dask["summary"], local["summary"], strict=True):
        for k in ("mean", "min", "max", "sd"):
            assert math.isclose(a[k], b[k], rel_tol=1e-12), (a, b)


@pytest.mark.slow  # six real logs fitted: 6 s of CPU
def test_cli_batch_surfaces_the_sub_sample_warning_on_the_adis_fleet(real_data, tmp_path, capsys):
    # the six ADIS16405 units fitted with GM+WN+RW: the GM lands below one sample (the gyros'
    # filter correlates neighbouring samples; WN takes nothing), which every front end must
    # say: a `gmwm batch: warning:` line per unit, and the JSON's "warnings" list
    logs = [str(real_data / f"adis16405_imu{k}.h5") for k in range(1, 7)]
    argv = ["batch", *logs, "--model", "GM+WN+RW", "--channels", "gyro_x", "--workers", "1"]
    assert main([*argv, "-o", str(tmp_path / "j"), "--quiet", "--json"]) == 0
    cap = capsys.readouterr()
    d = json.loads(cap.out)
    assert len(d["warnings"]) == 6
    for path, w, status in zip(logs, d["warnings"], d["logs"], strict=True):
        assert w.startswith(f"{path} [gyro_x]: GM: correlation time ")
        assert "shorter than one sample" in w and "WN-equivalent sigma2" in w
        assert status["warnings"]["gyro_x"] == [w.split(" [gyro_x]: ", 1)[1]]
        assert f"gmwm batch: warning: {w}" in cap.err.splitlines()
    # each log's own JSON report carries its fit's warning too
    rep = json.loads((tmp_path / "j" / "adis16405_imu1.json").read_text())
    assert "shorter than one sample" in json.dumps(rep)
    # the text table: the same warning lines on stderr, one per unit
    assert main([*argv, "-o", str(tmp_path / "t"), "--quiet"]) == 0
    cap = capsys.readouterr()
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("gmwm batch: warning: ")]
    assert len(lines) == 6 and all("[gyro_x]: GM: correlation time" in ln for ln in lines)
    assert "fleet of 6 log(s): 6 fitted" in cap.out


def test_a_loaded_log_or_its_path_give_the_same_fits_and_refuse_loader_options(tmp_path) -> None:
    """fit_log and gather_report take a path or a loaded log alike (engine.io.log_of): the same
    fits either way; with a loaded log the loader's options are refused, naming the caller."""
    from engine.batch import fit_log
    from engine.reporting import gather_report

    x = eg.parse_model("WN(1e-4) + RW(1e-9)").simulate(2**12, rng=np.random.default_rng(5))
    path = tmp_path / "unit.h5"
    save_log(path, {"gyro_x": x}, fs=100.0, units={"gyro_x": "rad/s"})
    log = eg.load_log(path)
    by_path = fit_log(path, model="WN+RW")
    by_log = fit_log(log, model="WN+RW")
    assert by_path.source == by_log.source == str(path)
    assert by_path.fits["gyro_x"].params == by_log.fits["gyro_x"].params
    rep = gather_report(log, model="WN+RW", export_format=None)
    assert rep.channels["gyro_x"].fit.params == by_path.fits["gyro_x"].params
    for call, name in ((fit_log, "fit_log"), (gather_report, "gather_report")):
        for bad in ({"fs": 50.0}, {"load_options": {"scale": 2.0}}):
            with pytest.raises(TypeError, match=rf"^{name}\(\): fs and load_options apply to a"):
                call(log, model="WN+RW", **bad)
