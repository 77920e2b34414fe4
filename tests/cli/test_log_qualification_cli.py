"""`gmwm fit` runs the log check (one stderr line, JSON key ``qualification``), drops the warm-up
with --drop-warmup, and fits the temperature relation with --temperature (JSON key
``temperature``)."""

from __future__ import annotations

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
    eg.save_log(d / "warm.h5", {"gyro_x": warm}, FS, units={"gyro_x": "deg/s"})
    eg.save_log(d / "shock.h5", {"gyro_x": shock}, FS, units={"gyro_x": "deg/s"})
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
