"""The app says what the log check found in the channel shown (AppState.log_check), and
nothing for a clean channel."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import engine as eg
import gmwm_app.data as data
from gmwm_app.state import AppState


def _knocked_log(path: Path, n: int, knock_at: int, seed: int) -> Path:
    """A log of two channels at 100 Hz: gx clean, gy the same with a shock of 30 samples
    planted at ``knock_at``."""
    rng = np.random.default_rng(seed)
    clean = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-10)").simulate(n, fs=100.0, rng=rng)
    knocked = clean.copy()
    knocked[knock_at : knock_at + 30] += rng.normal(size=30)
    units = {"gx": "deg/s", "gy": "deg/s"}
    eg.io.save_log(path, {"gx": clean, "gy": knocked}, 100.0, units=units)
    return path


def test_log_check_line_follows_the_channel(tmp_path):
    path = _knocked_log(tmp_path / "two.h5", 100_000, 40_000, seed=4)
    s = AppState()
    assert s.load_path(path), s.error
    assert s.channel == "gx" and s.log_check == ""
    assert s.select_channel("gy"), s.error
    assert (
        "shock (gy)" in s.log_check and "first at samples 40,0" in s.log_check
    )  # 40,000-40,029 planted
    assert s.select_channel("gx") and s.log_check == ""


def test_log_check_runs_in_the_worker_not_on_the_loop(tmp_path, monkeypatch):
    """The check takes a tenth of a second on a long log: the page's read (``prepare_query``)
    and a channel's warm-up (``warm``) run it in the worker, so the install and the channel
    switch that follow on the server loop find it done (a second run would raise here)."""
    path = _knocked_log(tmp_path / "two.h5", 50_000, 20_000, seed=5)
    calls: list[list[str]] = []
    real = data.qualify_log

    def counted(lg, channels, *a, **k):
        calls.append(list(channels))
        return real(lg, channels, *a, **k)

    monkeypatch.setattr(data, "qualify_log", counted)
    s = AppState()
    q = {"source": "path", "path": str(path), "channel": "gx"}
    prepared = s.prepare_query(q, "demo", "")  # the worker's part
    assert calls == [["gx"]]

    def refused(*a, **k):
        raise AssertionError("the log check ran on the loop")

    monkeypatch.setattr(data, "qualify_log", refused)
    assert s.from_query(q, prepared=prepared), s.error  # the loop's part
    assert s.channel == "gx" and s.log_check == ""
    monkeypatch.setattr(data, "qualify_log", counted)
    s.warm("gy")  # the worker's part of a channel switch
    assert calls == [["gx"], ["gy"]]
    monkeypatch.setattr(data, "qualify_log", refused)
    assert s.select_channel("gy"), s.error  # the loop's part
    assert "shock (gy)" in s.log_check
