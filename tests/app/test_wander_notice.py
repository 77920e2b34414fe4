"""The app's log-check line names the warm-up wander of the channel shown, judged on its triad
(the same verdict and start as `gmwm fit`)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from loadlogs import write_wander_triad

import engine as eg
from engine.io.qualify import qualify_log
from gmwm_app.state import AppState


def test_the_channel_shown_gets_its_triads_wander(tmp_path):
    path = tmp_path / "wander.h5"
    write_wander_triad(path)  # RW innovation variance x8 in the first 300 s
    start = qualify_log(eg.load_log(path)).suggested_start
    assert start > 0
    s = AppState()
    assert s.load_path(path), s.error
    assert s.select_channel("gyro_z"), s.error
    assert f"wander (gyro_z): start at sample {start:,}" in s.log_check


def _wander_log(tmp_path):
    """The planted wander's log, its channels and its check's suggested start."""
    path = tmp_path / "wander.h5"
    chans = write_wander_triad(path)
    return path, chans, qualify_log(eg.load_log(path)).suggested_start


def test_the_app_state_drops_the_warm_up_it_reports(tmp_path):
    path, chans, start = _wander_log(tmp_path)
    assert start > 0
    s = AppState()
    assert s.load_path(path), s.error
    assert s.select_channel("gyro_y"), s.error
    assert s.warmup_start == start  # what the offer keeps from
    loaded = s.without_warmup({"segment": "longest"})
    assert loaded.load == {"segment": "longest", "drop_warmup": start}
    assert s.install(loaded), s.error
    # the session's data are the log from the start on: its WV is the engine's of those samples
    assert s.n == 200_000 - start and s.filename == "wander.h5" and s.channel == "gyro_y"
    ref = eg.wavelet_variance(chans["gyro_y"][start:], fs=100.0)
    np.testing.assert_allclose(s.wv.variance, ref.variance, rtol=1e-12)
    assert f"first {start} samples" in s.notice and "dropped as warm-up" in s.notice
    # the cut log is checked again: what is left of the wander is its own finding
    cut = eg.io.drop_warmup(eg.load_log(path), start)
    assert s.warmup_start == qualify_log(cut).suggested_start


def test_a_clean_log_offers_no_warm_up_to_drop(app_state):
    assert app_state.warmup_start == 0  # the demo: no warm-up found
    with pytest.raises(ValueError, match="no warm-up to drop"):
        app_state.without_warmup()


def test_the_pages_button_drops_the_warm_up_and_the_session_file_keeps_it(app_demo, tmp_path):
    from gmwm_app import session_view as sv
    from gmwm_app.app import create_app

    path, _chans, start = _wander_log(tmp_path)
    app = create_app().gmwm_app
    assert not app.drop_warmup_button.visible  # the demo: nothing to offer
    app.path_input.value = str(path)
    app._on_path()
    s = app.state
    assert s.error == "" and s.filename == "wander.h5", s.error
    button = app.drop_warmup_button
    assert button.visible and f"{start:,}" in button.label
    button.clicks += 1  # not served: the job runs at once
    assert s.error == "" and s.n == 200_000 - start, s.error
    doc = json.loads(app.session_panel._session_file().getvalue())
    assert doc["data"]["load"] == {"drop_warmup": start}
    other = AppState()  # a saved session reads the same samples again
    assert sv.apply_restore(other, sv.prepare_restore(json.dumps(doc)))
    assert other.n == 200_000 - start and other.filename == "wander.h5"
