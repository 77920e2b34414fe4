"""The page's URL follows its state: Panel syncs the plain parameters both ways, the page
writes the data and the model.

A :class:`panel.io.location.Location` stands in for the browser's (a served page links its
own when its first data are shown); no server, no browser.
"""

from __future__ import annotations

from typing import Any
from urllib.parse import parse_qs

import pytest
from panel.io.location import Location


def _query(loc: Location) -> dict[str, str]:
    """The URL's query as the browser has it (one value a key)."""
    return {k: v[-1] for k, v in parse_qs(loc.search.lstrip("?")).items()}


@pytest.fixture
def linked(app: Any) -> tuple[Any, Location]:
    """The demo page with a WN+RW fit, its URL linked as a served page's is."""
    assert app.state.set_model("WN+RW"), app.state.error
    loc = Location(search="?channel=gyro_x&model=WN%2BRW")
    app.link_url(loc)
    return app, loc


def test_the_url_carries_the_data_the_model_and_the_weights(linked: tuple[Any, Location]) -> None:
    app, loc = linked
    s = app.state
    assert _query(loc) == {
        "source": "demo",
        "channel": "gyro_x",
        "fs": f"{s.fs:.12g}",
        "robust": "0",
        "model": "WN+RW",
        "weights": "ci",  # a plain parameter: always in the URL
    }
    # the state's weights reach the URL (Panel's sync); the data and model keys stay
    assert s.set_weights("efficient")
    assert _query(loc)["weights"] == "efficient" and _query(loc)["model"] == "WN+RW"
    # the state's model reaches the URL; the weights stay
    assert s.set_model("GM+WN+RW"), s.error
    q = _query(loc)
    assert q["model"] == "GM+WN+RW" and q["weights"] == "efficient"
    # keys come and go with the state: the model cleared, no model key
    assert s.clear_model()
    assert "model" not in _query(loc) and _query(loc)["weights"] == "efficient"


def test_a_change_of_the_urls_weights_refits(linked: tuple[Any, Location]) -> None:
    app, loc = linked
    s = app.state
    assert s.result.weights == "ci"
    loc.search = loc.search.replace("weights=ci", "weights=identity")  # the browser's URL
    assert s.weights == "identity" and s.result.weights == "identity" and s.error == ""
    assert app.model_panel.weights_select.value == "identity"
    # a value the parameter refuses: the link's problem, in words; the state keeps its own
    before = s.result
    loc.search = loc.search.replace("weights=identity", "weights=optimal")
    assert s.weights == "identity" and s.result is before
    assert s.error == "weights='optimal' in the link is not one of ci, identity, efficient"
