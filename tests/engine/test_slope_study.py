"""The slope-method Monte Carlo: Table I conversions, regions, end-to-end run, CLI."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.teaching import (
    STUDY_FS,
    TABLE_I,
    StudyResult,
    estimate_all,
    run_slope_study,
    table1_model,
    typical_regions,
)
from engine.teaching.table1 import from_datasheet, to_datasheet


# -------------------------------------------------------------------------------------------
# Table I in per-sample parameters
# -------------------------------------------------------------------------------------------
def test_table1_per_sample_values_from_first_principles():
    fs = 250.0
    gyro = table1_model("gyro", fs).values()
    # ARW 0.157 deg/sqrt(h) = 0.157/60 deg/s/sqrt(Hz) = N; sigma2 = N^2 fs
    assert gyro["WN.sigma2"] == pytest.approx((0.157 / 60) ** 2 * 250, rel=1e-12)
    # RRW 1.34 deg/h/sqrt(h) = 1.34/3600/60 deg/s/sqrt(s) = K; gamma2 = K^2 / fs
    assert gyro["RW.gamma2"] == pytest.approx((1.34 / 3600 / 60) ** 2 / 250, rel=1e-12)
    acc = table1_model("accel", fs).values()
    assert acc["QN.q2"] == pytest.approx((1.79e-6 * 250) ** 2, rel=1e-12)  # Q = sqrt(q2)/fs
    assert acc["WN.sigma2"] == pytest.approx((4.70e-2 / 60) ** 2 * 250, rel=1e-12)
    assert acc["RW.gamma2"] == pytest.approx((43.5 / 216000) ** 2 / 250, rel=1e-12)
    assert acc["DR.omega"] == pytest.approx(41.4 / 3600**2 / 250, rel=1e-12)  # R = omega fs


@pytest.mark.parametrize("sensor", ["gyro", "accel"])
def test_table1_allan_shapes_give_back_the_datasheet_values(sensor):
    """The implied AVAR has the IEEE shapes N^2/T, K^2 T/3, 3Q^2/T^2, R^2 T^2/2 (T in s)."""
    fs = STUDY_FS
    model = table1_model(sensor, fs)
    t = np.array([0.004, 1.0, 100.0, 4000.0])  # averaging times (s)
    m = np.round(t * fs)
    comps = model.components(2 * m, fs)  # WV at tau = 2m
    vals = {c: v for c, _, v, _ in TABLE_I[sensor]["params"]}
    if "WN" in vals:
        n = vals["WN"] / 60.0  # u/sqrt(Hz)
        np.testing.assert_allclose(2 * comps["WN"], n**2 / t, rtol=1e-12)
    if "RW" in vals:
        k = vals["RW"] / 216000.0  # u/sqrt(s)
        np.testing.assert_allclose(2 * comps["RW"][1:], k**2 * t[1:] / 3, rtol=1e-5)
    if "QN" in vals:
        np.testing.assert_allclose(2 * comps["QN"], 3 * vals["QN"] ** 2 / t**2, rtol=1e-12)
    if "DR" in vals:
        r = vals["DR"] / 3600.0**2  # u/s
        np.testing.assert_allclose(2 * comps["DR"], r**2 * t**2 / 2, rtol=1e-12)


@pytest.mark.parametrize("sensor", ["gyro", "accel"])
def test_conversions_agree_with_the_engine_datasheet(sensor):
    model = table1_model(sensor)
    rows = {
        (r["quantity"], r["unit"]): r["value"]
        for r in eg.units.datasheet(model, STUDY_FS, TABLE_I[sensor]["unit"])
    }
    key = {
        "WN": "angle random walk" if sensor == "gyro" else "velocity random walk",
        "RW": "rate random walk" if sensor == "gyro" else "acceleration random walk",
        "QN": "quantization",
        "DR": "rate ramp" if sensor == "gyro" else "acceleration ramp",
    }
    for code, _, value, unit in TABLE_I[sensor]["params"]:
        # Table I's value and unit are a row of the one datasheet table
        assert rows[(key[code], unit)] == pytest.approx(value, rel=1e-12)
        per_sample = from_datasheet(code, value, STUDY_FS)
        assert to_datasheet(code, per_sample, STUDY_FS) == pytest.approx(value, rel=1e-12)
    with pytest.raises(ValueError, match="sensor"):
        table1_model("magnetometer")


# -------------------------------------------------------------------------------------------
# the typical user's regions
# -------------------------------------------------------------------------------------------
def test_typical_regions_at_the_paper_lengths():
    g = typical_regions("gyro", 2_500_000)
    assert g["WN"] == (0.004, 10.0)
    assert g["RW"] == pytest.approx((2**18 / 250, 2**20 / 250))  # the last 3 points
    a = typical_regions("accel", 6_300_000)
    assert a["QN"] == (0.004, 0.008)
    assert a["WN"] == (0.015, 1.1)
    assert a["RW"] == pytest.approx((2**13 / 250, 2**16 / 250))  # 33 to 262 s
    assert a["DR"] == pytest.approx((2**20 / 250, 2**21 / 250))  # the last 2 points
    short = typical_regions("accel", 200_000)
    assert short["RW"][1] < short["DR"][0]
    with pytest.raises(ValueError, match="too short"):
        typical_regions("gyro", 40)


def test_estimate_all_returns_every_method():
    x = table1_model("accel").simulate(2**18, fs=STUDY_FS, rng=5)
    ests = estimate_all(
        x, "accel", methods=("GMWM", "ARMAV", "ARMAV-unweighted", "AVSM", "AVSM-auto")
    )
    assert [e.method for e in ests.values()] == list(ests)
    truth = table1_model("accel").values()
    for m in ("GMWM", "ARMAV", "AVSM"):
        assert set(ests[m].params) == set(truth)
    assert ests["GMWM"].params["WN.sigma2"] == pytest.approx(truth["WN.sigma2"], rel=0.02)
    with pytest.raises(ValueError, match="unknown method"):
        estimate_all(x, "accel", methods=("PSD",))


# -------------------------------------------------------------------------------------------
# end to end
# -------------------------------------------------------------------------------------------
#: The small study's setting (the number of replicates, workers and progress vary).
SMALL_STUDY = {"seed": 4, "n_values": (2e5,), "methods": ("GMWM", "ARMAV", "AVSM", "AVSM-auto")}


@pytest.fixture(scope="module")
def small_study() -> StudyResult:
    stream = io.StringIO()
    res = run_slope_study(3, workers=2, progress=stream, **SMALL_STUDY)
    object.__setattr__(res, "_progress_text", stream.getvalue())
    return res


def test_study_runs_end_to_end_and_writes_its_outputs(small_study, tmp_path):
    res = small_study
    assert "3/6 (50 %)" in res._progress_text and "6/6 (100 %)" in res._progress_text
    assert not res.errors
    # 2 gyro + 4 accel parameters x 3 methods, plus AVSM-auto's WN and RW for both sensors
    assert len(res.rows) == 6 * 3 + 4
    for r in res.rows:
        assert r["n_ok"] == 3 and math.isfinite(r["rmse"])
        assert r["rmse"] ** 2 == pytest.approx(r["bias"] ** 2 + r["sd"] ** 2 * 2 / 3, rel=1e-9)
    paths = res.save(tmp_path / "out")
    d = json.loads((tmp_path / "out" / "study.json").read_text())
    assert d["settings"]["reps"] == 3 and d["settings"]["n_values"] == [200000]
    assert len(d["estimates"]["200000"]["accel"]["AVSM"]["QN"]) == 3
    assert d["truth"]["accel"]["DR"]["value"] == 41.4
    again = StudyResult.from_json(paths["json"])
    assert again.rows == res.rows and again.markdown() == res.markdown()
    md = (tmp_path / "out" / "study.md").read_text()
    assert "| Accel | QN Q [m/s] | 1.79e-06 | AVSM |" in md and "**" in md
    assert "RMSE" in (tmp_path / "out" / "study.txt").read_text()
    pytest.importorskip("matplotlib")
    for k in ("boxplot", "rmse"):
        with open(paths[k], "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_study_does_not_depend_on_the_number_of_workers_or_replicates(small_study):
    # replicate r has its own seed: 2 replicates in process equal the first 2 of 3 on 2 workers
    one = run_slope_study(2, workers=1, progress=False, **SMALL_STUDY)
    for n, by_s in small_study.estimates.items():
        for s, by_m in by_s.items():
            for m, by_c in by_m.items():
                for c, v in by_c.items():
                    np.testing.assert_array_equal(v[:2], one.estimates[n][s][m][c])


def test_ranking_logic():
    est = {
        100: {
            "gyro": {
                "GMWM": {"WN": np.array([0.157, 0.157]), "RW": np.array([1.3, 1.4])},
                "AVSM": {"WN": np.array([0.16, 0.15]), "RW": np.array([1.34, 1.34])},
            }
        }
    }
    res = StudyResult(
        estimates=est,
        errors=[],
        wall_time_s=1.0,
        settings={
            "reps": 2,
            "seed": 0,
            "n_values": [100],
            "fs": 250.0,
            "methods": ["GMWM", "AVSM"],
            "sensors": ["gyro"],
            "workers": 1,
        },
    )
    rk = res.ranking()
    assert rk["best"] == {"100/gyro/WN": "GMWM", "100/gyro/RW": "AVSM"}
    assert not rk["gmwm_lowest_everywhere"] and rk["exceptions"][0]["process"] == "RW"
    assert rk["exceptions"][0]["z"] == pytest.approx(2.6, abs=0.01)
    assert not rk["exceptions"][0]["tie"] and "clearly lower" in res.ranking_text()
    # a noisy win is a tie: paired z = 0.37
    est[100]["gyro"]["GMWM"]["RW"] = np.array([1.30, 1.38, 1.34])
    est[100]["gyro"]["AVSM"]["RW"] = np.array([1.33, 1.36, 1.30])
    for m in ("GMWM", "AVSM"):
        est[100]["gyro"][m]["WN"] = np.r_[est[100]["gyro"][m]["WN"], 0.157]
    res = StudyResult(estimates=est, errors=[], wall_time_s=1.0, settings=res.settings)
    rk = res.ranking()
    assert rk["exceptions"][0]["tie"] and rk["gmwm_lowest_or_tied_everywhere"]
    assert "holds within Monte Carlo error" in res.ranking_text()


def test_efficient_weights_beat_ci_weights_on_the_gyro_random_walk():
    # Table I's gyroscope (WN + RW) at 2^20 samples (70 min at 250 Hz), 20 replicates: with the
    # R-default ci weights GMWM puts the RW at 0 in 12 of 20 replicates (the few long-tau levels
    # weigh little); two-step efficient weights (Omega = V^-1 from the first fit's model) in 2
    # and cut the RW's RMSE by 30 % (1.24 -> 0.86 deg/h/sqrt(h)); the WN is unaffected
    res = run_slope_study(
        20,
        seed=7,
        n_values=(2**20,),
        sensors=("gyro",),
        methods=("GMWM", "GMWM-efficient"),
        workers=1,
        progress=False,
    )
    row = {(r["process"], r["method"]): r for r in res.rows}
    ci, eff = row[("RW", "GMWM")], row[("RW", "GMWM-efficient")]
    assert eff["rmse"] < 0.8 * ci["rmse"]
    assert eff["zero_frac"] <= 0.15 < 0.5 <= ci["zero_frac"]
    assert abs(eff["bias"]) < 0.1 * abs(ci["bias"])
    wn_ci, wn_eff = row[("WN", "GMWM")]["rmse"], row[("WN", "GMWM-efficient")]["rmse"]
    assert wn_eff == pytest.approx(wn_ci, rel=0.05)
    assert wn_eff < 1e-3 * 0.157  # both within 0.1 % of sigma = 0.157 deg/sqrt(h)


def test_bad_settings():
    with pytest.raises(ValueError, match="reps"):
        run_slope_study(1)
    with pytest.raises(ValueError, match="unknown method"):
        run_slope_study(2, methods=("GMWM", "PSD"))
    with pytest.raises(ValueError, match="sensor"):
        run_slope_study(2, sensors=("baro",))


def test_cli_study(tmp_path, capsys):
    rc = main(
        [
            "study",
            "slope",
            "--reps",
            "2",
            "--seed",
            "3",
            "--n",
            "1e5",
            "--workers",
            "1",
            "--out",
            str(tmp_path),
            "--json",
        ]
    )
    cap = capsys.readouterr()
    assert rc == 0
    d = json.loads(cap.out)
    assert d["study"] == "slope" and "estimates" not in d
    # the default methods: GMWM with ci weights and with efficient weights, side by side
    assert {r["method"] for r in d["summary"]} == {"GMWM", "GMWM-efficient", "ARMAV", "AVSM"}
    assert (tmp_path / "study.md").exists() and d["files"]["json"].endswith("study.json")
    assert "gmwm study slope" not in cap.err  # the progress bar: on a terminal only
    assert main(["study", "slope", "--reps", "2", "--n", "many"]) == 2
    assert "--n" in capsys.readouterr().err
