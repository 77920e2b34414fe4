"""`gmwm fit` says what the warm-up wander check found (the channel's triad judged together) and
--drop-warmup starts the fit after it."""

from __future__ import annotations

import json

from loadlogs import write_wander_triad

from engine.cli import main

FS = 100.0
N = 200_000


def test_fit_reports_the_wander_and_drop_warmup_cuts_it(tmp_path, capsys):
    # three axes whose RW innovation variance is 8 times larger in the first 300 s of 2000 s
    path = tmp_path / "wander.h5"
    write_wander_triad(path, N, FS)
    args = ["fit", str(path), "--channel", "gyro_y", "--model", "WN+RW", "--json"]
    assert main(args) == 0
    out, err = capsys.readouterr()
    q = json.loads(out)["qualification"]
    start = q["suggested_start"]
    (w,) = [f for f in q["findings"] if f["kind"] == "wander"]
    assert w["channel"] == "gyro_y" and w["values"]["start"] == start
    assert 15_000 <= start <= 60_000, start  # the planted end is sample 30,000
    assert "wander (gyro_y): start at sample" in err and "--drop-warmup" in err
    assert main([*args, "--drop-warmup"]) == 0
    out2, err2 = capsys.readouterr()
    assert json.loads(out2)["qualification"]["dropped"] == start
    assert f"first {start:,} samples dropped" in err2
