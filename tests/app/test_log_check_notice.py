"""The app says what the log check found in the channel shown (AppState.log_check), and
nothing for a clean channel."""

from __future__ import annotations

import numpy as np

import engine as eg
from gmwm_app.state import AppState


def test_log_check_line_follows_the_channel(tmp_path):
    rng = np.random.default_rng(4)
    n, fs = 100_000, 100.0
    clean = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-10)").simulate(n, fs=fs, rng=rng)
    knocked = clean.copy()
    knocked[40_000:40_030] += rng.normal(size=30)
    path = tmp_path / "two.h5"
    eg.save_log(path, {"gx": clean, "gy": knocked}, fs, units={"gx": "deg/s", "gy": "deg/s"})
    s = AppState()
    assert s.load_path(path), s.error
    assert s.channel == "gx" and s.log_check == ""
    assert s.select_channel("gy"), s.error
    assert (
        "shock (gy)" in s.log_check and "first at samples 40,0" in s.log_check
    )  # 40,000-40,029 planted
    assert s.select_channel("gx") and s.log_check == ""
