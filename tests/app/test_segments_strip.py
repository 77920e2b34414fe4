"""The Fit tab's time strip of a flight analysed on its still segments
(gmwm_app/segments_view.py): shown with the segments the WV pools, hidden for a still log."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from flightlogs import make

from engine.io.segments import still_segments

FS = 250.0


def test_a_flight_loaded_on_its_still_segments_shows_them_in_time(app: Any, tmp_path: Path) -> None:
    pytest.importorskip("pyulog")
    assert not app.segments.box.visible  # the demo log is still: no strip
    fl = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=7)
    ulg = make.write_ulog(tmp_path / "flight.ulg", fl)
    s = app.state
    assert s.load_path(str(ulg), segments="auto"), s.error
    assert app.segments.box.visible
    log = s.log
    want = [(a / FS, b / FS) for a, b in still_segments(log)]
    np.testing.assert_allclose(app.segments.spans.data["left"], [a for a, _ in want])
    np.testing.assert_allclose(app.segments.spans.data["right"], [b for _, b in want])
    # the strip covers the whole flight (motion included), the shading only the still parts
    t = np.asarray(app.segments.envelope.data["t"])
    assert t[0] < want[0][1] and t[-1] > want[-1][0] and t[-1] <= log.n / FS
    moving = np.asarray(app.segments.envelope.data["high"]) - app.segments.envelope.data["low"]
    inside = (t > want[0][1]) & (t < want[-1][0])  # between the segments: the motion
    assert moving[inside].max() > 3 * np.median(moving)
    # the channel switch redraws it; a still log hides it again
    other = [c for c in s.channels if c != s.channel][0]
    assert s.select_channel(other), s.error
    assert app.segments.box.visible
    assert s.load_demo(), s.error
    assert not app.segments.box.visible
