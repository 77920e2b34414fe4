"""The app's log-check line names the warm-up wander of the channel shown, judged on its triad
(the same verdict and start as `gmwm fit`)."""

from __future__ import annotations

import numpy as np

import engine as eg
from engine.io.qualify import qualify_log
from gmwm_app.state import AppState


def test_the_channel_shown_gets_its_triads_wander(tmp_path):
    n, fs = 200_000, 100.0
    rng = np.random.default_rng(3)
    g = np.full(n, 1e-8)
    g[: int(300 * fs)] *= 8.0  # RW innovation variance x8 in the first 300 s
    chans = {
        f"gyro_{a}": rng.normal(scale=0.1, size=n) + np.cumsum(rng.normal(size=n) * np.sqrt(g))
        for a in "xyz"
    }
    path = tmp_path / "wander.h5"
    eg.io.save_log(path, chans, fs, units=dict.fromkeys(chans, "deg/s"))
    start = qualify_log(eg.load_log(path)).suggested_start
    assert start > 0
    s = AppState()
    assert s.load_path(path), s.error
    assert s.select_channel("gyro_z"), s.error
    assert f"wander (gyro_z): start at sample {start:,}" in s.log_check
