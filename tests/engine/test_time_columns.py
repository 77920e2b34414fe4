"""Time columns: fs inference, gaps, duplicates, reversals, jitter; load_log's segment choice."""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

import engine as eg
from engine.io import LoadError, as_seconds, check_time, load_log, segment_fs


def csv(path: Path, t: np.ndarray, x: np.ndarray | None = None, col: str = "time") -> Path:
    x = np.sin(np.arange(t.size)) if x is None else x
    path.write_text(
        f"{col},gyro_x [deg/s]\n"
        + "\n".join(f"{a!r},{b!r}" for a, b in zip(t.tolist(), x.tolist(), strict=True))
    )
    return path


# ----------------------------------------------------------------------------- check_time
def test_clean_uniform_stamps() -> None:
    t = 12.5 + np.arange(1000) / 200.0
    rep = check_time(t)
    assert rep.ok and rep.events == () and rep.counts == {}
    assert rep.fs == 200.0 and rep.median_step == pytest.approx(0.005)
    assert rep.segments.tolist() == [[0, 1000]] and rep.longest == (0, 1000)
    assert rep.jitter < 1e-9
    assert "no gap" in rep.summary()
    d = rep.to_dict()
    assert d["ok"] and d["fs"] == 200.0 and d["longest"] == [0, 1000]
    json.dumps(d, allow_nan=False)


def test_gap_where_and_how_long() -> None:
    t = np.arange(2000) / 100.0
    t[700:] += 0.25  # 25 samples missing between samples 699 and 700
    rep = check_time(t, rows=np.arange(2000) + 2)
    assert not rep.ok and rep.counts == {"gap": 1}
    (e,) = rep.events
    assert (e.kind, e.index, e.missing, e.line) == ("gap", 700, 25, 702)
    assert e.time == pytest.approx(6.99) and e.step == pytest.approx(0.26)
    assert "gap of 0.26 s (about 25 missing sample(s)) at line 702 (sample 700" in e.describe()
    assert rep.segments.tolist() == [[0, 700], [700, 2000]]
    assert rep.longest == (700, 2000) and rep.fs == 100.0
    msg = rep.message()
    assert "1 gap(s)" in msg and "samples 700 to 1999" in msg and "line 702" in msg


def test_duplicates_reversals_and_invalid_stamps() -> None:
    t = np.arange(100, dtype=float) * 0.01
    t[10] = t[9]  # duplicate
    t[50], t[51] = t[51], t[50]  # reversal (and a double step before it)
    t[80] = np.nan
    rep = check_time(t)
    kinds = {e.kind for e in rep.events}
    assert kinds == {"duplicate", "backward", "gap", "invalid"}
    assert rep.counts["duplicate"] == 1 and rep.counts["backward"] == 1
    assert rep.counts["invalid"] == 1
    dup = rep.events_of("duplicate")[0]
    assert dup.index == 10
    back = rep.events_of("backward")[0]
    assert back.index == 51 and back.step == pytest.approx(-0.01)
    # the NaN sample belongs to no segment; segments never contain a break
    for a, b in rep.segments:
        assert not a <= 80 < b or b - a == 0
        assert np.all(np.diff(t[a:b]) > 0)
    assert rep.counts["gap"] == 3  # after the duplicate, and around the swapped pair
    assert rep.segments.tolist() == [
        [0, 10],
        [10, 11],
        [11, 50],
        [50, 51],
        [51, 52],
        [52, 80],
        [81, 100],
    ]
    assert rep.longest == (11, 50)
    text = rep.summary()
    assert "duplicate stamp at sample 10" in text and "NaN/Inf stamp at sample 80" in text


def test_jitter_is_reported_not_a_break() -> None:
    rng = np.random.default_rng(1)
    steps = 0.01 * (1 + 0.02 * rng.standard_normal(5000))
    t = np.concatenate([[0.0], np.cumsum(steps)])
    rep = check_time(t)
    assert rep.ok and rep.jitter == pytest.approx(0.02, rel=0.1)
    assert rep.fs == pytest.approx(100.0, rel=1e-3)


def test_integer_nanosecond_stamps_are_exact() -> None:
    t = 1_700_000_000_000_000_000 + np.arange(500, dtype=np.int64) * 2_500_000  # 400 Hz
    assert as_seconds(t, 1e9)[1] == 0.0025
    rep = check_time(t, scale=1e9)
    assert rep.ok and rep.fs == 400.0 and rep.jitter < 1e-12


def test_many_events_are_capped_but_counted() -> None:
    t = np.cumsum(np.tile([0.01, 0.01, 0.01, 0.05], 2500))
    rep = check_time(t, max_events=100)
    assert rep.counts["gap"] == 2499 or rep.counts["gap"] == 2500
    assert len(rep.events) <= 110
    assert rep.to_dict(max_events=20)["events_truncated"] is True
    assert "more gap(s)" in rep.summary()


def test_segment_fs_and_bad_arguments() -> None:
    assert segment_fs(np.arange(10) / 8.0) == 8.0
    assert math.isnan(segment_fs(np.zeros(1)))
    with pytest.raises(ValueError, match="gap_factor"):
        check_time(np.arange(5.0), gap_factor=1.0)
    with pytest.raises(ValueError, match="scale"):
        check_time(np.arange(5.0), scale=0)
    with pytest.raises(ValueError, match="one-dimensional"):
        check_time(np.zeros((2, 2)))
    assert check_time(np.zeros(0)).segments.shape == (0, 2)


# ----------------------------------------------------------------------------- load_log
@pytest.fixture
def gappy(tmp_path: Path) -> Path:
    t = np.arange(600) / 50.0
    t[400:] += 1.0  # 50 missing samples before sample 400
    t = np.insert(t, 100, t[99])  # a duplicated row at sample 100 (line 102)
    return csv(tmp_path / "gappy.csv", t)


def test_default_stops_with_report(gappy: Path) -> None:
    with pytest.raises(LoadError) as exc:
        load_log(gappy)
    msg = str(exc.value)
    for frag in (
        "gappy.csv",
        "time column 'time'",
        "1 gap(s)",
        "1 duplicate stamp(s)",
        "line 403 (sample 401",
        "line 102 (sample 100",
        "segment='longest'",  # the CLI says --segment longest: test_cli_segment_option
        "samples 100 to 400",
        "joined",
    ):
        assert frag in msg, (frag, msg)
    with pytest.raises(LoadError):
        load_log(gappy, segment="stop")


def test_longest_segment(gappy: Path) -> None:
    log = load_log(gappy, segment="longest")
    assert log.n == 301 and log.meta["segment"] == [100, 401]
    assert log.fs == 50.0 and log.fs_source == "time column"
    np.testing.assert_array_equal(log["gyro_x"], np.sin(np.arange(100, 401)))
    assert any("segment='longest'" in n for n in log.meta["notes"])
    rep = log.meta["time_report"]
    assert rep["counts"] == {"gap": 1, "duplicate": 1} and rep["longest"] == [100, 401]


def test_report_keeps_everything_with_a_note(gappy: Path) -> None:
    log = load_log(gappy, segment="report")
    assert log.n == 601 and "segment" not in log.meta and log.fs == 50.0
    assert any("joined across the breaks" in n for n in log.meta["notes"])


def test_explicit_segment(gappy: Path) -> None:
    log = load_log(gappy, segment=(420, 601))
    assert log.n == 181 and log.meta["segment"] == [420, 601] and log.fs == 50.0
    with pytest.raises(LoadError, match="not clean: gap"):
        load_log(gappy, segment=(300, 500))
    with pytest.raises(LoadError, match="outside"):
        load_log(gappy, segment=(0, 602))
    with pytest.raises(LoadError, match="not a choice"):
        load_log(gappy, segment="middle")
    with pytest.raises(LoadError, match="pair"):
        load_log(gappy, segment=(1, 2, 3))


def test_user_fs_keeps_samples_and_reports(gappy: Path) -> None:
    log = load_log(gappy, fs=50)
    assert log.n == 601 and log.fs == 50.0 and log.fs_source == "user"
    assert not log.meta["time_report"]["ok"]
    assert any("joined" in n for n in log.meta["notes"])
    assert load_log(gappy, fs=50, segment="longest").n == 301


def test_short_segment_and_jitter_note(tmp_path: Path) -> None:
    t = np.arange(20) / 10.0
    t[2:] += 5.0
    t[4:] += 5.0
    t[6:] += 5.0  # longest clean segment: 14 samples; make it 3 with more gaps
    t[9:] += 5.0
    t[12:] += 5.0
    t[15:] += 5.0
    t[18:] += 5.0
    with pytest.raises(LoadError, match="only 3 sample"):
        load_log(csv(tmp_path / "short.csv", t), segment="longest")
    rng = np.random.default_rng(0)
    tj = np.cumsum(0.01 * (1 + 0.05 * rng.standard_normal(300)))
    log = load_log(csv(tmp_path / "jit.csv", tj))
    assert log.meta["time_report"]["ok"] and any("jitters" in n for n in log.meta["notes"])


def test_hdf5_and_npy_time_columns(tmp_path: Path) -> None:
    t = np.arange(1000, dtype=np.int64) * 10_000_000 + 1_600_000_000_000_000_000
    t[500:] += 40_000_000
    with h5py.File(tmp_path / "a.h5", "w") as f:
        f["gyro_x"] = np.arange(1000.0)
        f["time_ns"] = t
    with pytest.raises(LoadError, match="gap"):
        load_log(tmp_path / "a.h5")
    log = load_log(tmp_path / "a.h5", segment="longest")
    assert log.n == 500 and log.fs == 100.0 and log["gyro_x"][0] == 0.0
    rec = np.zeros(200, dtype=[("t", "f8"), ("x", "f4")])
    rec["t"] = np.arange(200) / 20.0
    rec["t"][150:] = rec["t"][149]  # stuck clock
    np.save(tmp_path / "r.npy", rec)
    log = load_log(tmp_path / "r.npy", segment="longest")
    assert log.n == 150 and log.fs == 20.0 and log["x"].dtype == np.float32


def test_file_fs_still_checks_the_time_column(tmp_path: Path) -> None:
    t = np.arange(300) / 100.0
    t[200:] += 0.5
    with h5py.File(tmp_path / "b.h5", "w") as f:
        f["x"] = np.random.default_rng(0).normal(size=300)
        f["time"] = t
        f.attrs["fs_hz"] = 100.0
    with pytest.raises(LoadError, match="gap"):
        load_log(tmp_path / "b.h5")
    log = load_log(tmp_path / "b.h5", segment="longest")
    assert log.n == 200 and log.fs == 100.0 and log.fs_source == "file"


def test_cli_segment_option(tmp_path: Path, gappy: Path, capsys) -> None:
    from engine.cli import main

    assert main(["wv", str(gappy), "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--segment longest" in err
    assert main(["wv", str(gappy), "--segment", "longest", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n"] == 301 and d["fs"] == 50.0
    x = eg.load_log(gappy, segment="longest")["gyro_x"]
    np.testing.assert_allclose(d["variance"], eg.wavelet_variance(x).variance, rtol=1e-12)
