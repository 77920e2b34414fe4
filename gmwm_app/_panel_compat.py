"""Every use of Panel internals by the app, in one place, for the Panel versions it was
written for (:data:`PANEL_VERSIONS`; ``tests/test_app_state.py`` fails on another version, so
that an upgrade forces a re-check of what is here).

* :func:`light_text_updates`: a text pane's ``object`` change sends its text only (Panel
  re-sends the pane's stylesheets, which makes Bokeh re-walk the whole document).
* :func:`building_off_loop`: marks a document as built by the current (worker) thread, as
  Panel's own ``run_app`` does for the loop's thread (``pn.state._thread_id_`` and
  ``pn.state._launching``).
* :func:`eval_panel`: Panel's function that turns a page factory into a document.
* :func:`patch_css_off_loop` and :func:`skip_repeated_css_patch`: Panel's page handler
  patches the stylesheet links of every root of a page on the server loop while it renders
  the page (``patch_model_css``: a walk of every model, about half of the loop's work per
  page open, 0.1-0.5 s on a busy machine); the off-loop build does it in its thread, and the
  handler skips a root already patched for the same ``dist_url`` (the result is the same).

On another Panel version :func:`supported` is False: the text patch is not applied and the
server builds its pages on the loop, as Panel does (slower, never wrong).
"""

from __future__ import annotations

import contextlib
import threading
import weakref
from collections.abc import Iterator
from typing import Any

import panel as pn
from panel.io.state import state as pn_state

__all__ = [
    "PANEL_VERSIONS",
    "supported",
    "light_text_updates",
    "building_off_loop",
    "eval_panel",
    "patch_css_off_loop",
    "skip_repeated_css_patch",
]

#: Panel versions whose internals this module was checked against.
PANEL_VERSIONS = ("1.9.4",)


def supported() -> bool:
    """Whether the installed Panel is one this module was written for."""
    return pn.__version__ in PANEL_VERSIONS


def light_text_updates() -> bool:
    """Make a text pane's ``object`` change send its text only (Panel 1.9: also stylesheets).

    Panel's HTML/Markdown/Alert panes re-send their whole property set on every ``object``
    change, the stylesheets included; the first time, that list differs from the one the page
    was built with (the template's design sheets), and a changed list of Bokeh models makes
    Bokeh recompute the graph of every model of the document: 0.05-0.1 s per pane and
    session on the server loop, with about a thousand models per page. The stylesheets a pane
    was built with are kept (they do not depend on its text). Returns whether it applied.
    """
    from panel.pane.markup import HTMLBasePane

    if not supported():
        return False

    if getattr(HTMLBasePane._update, "_gmwm_light", False):
        return True
    original = HTMLBasePane._update
    if not callable(original) or not hasattr(HTMLBasePane, "_get_properties"):
        return False  # pragma: no cover - another Panel: leave it alone

    def _update(self: Any, ref: str, model: Any) -> None:
        if getattr(self, "enable_streaming", False):
            return original(self, ref, model)
        props = self._get_properties(model.document)
        props.pop("stylesheets", None)
        model.update(**props)

    _update._gmwm_light = True  # type: ignore[attr-defined]
    HTMLBasePane._update = _update
    return True


@contextlib.contextmanager
def building_off_loop(doc: Any) -> Iterator[None]:
    """Build ``doc`` in this thread: Panel applies model changes directly on the document's
    own thread, and ``_launching`` marks a document whose page is being built (Panel's
    ``initialize_document`` gives the document to the loop's thread afterwards)."""
    pn_state._thread_id_[doc] = threading.get_ident()
    pn_state._launching.add(doc)
    try:
        yield
    finally:
        pn_state._launching.discard(doc)


def eval_panel(factory: Any, title: str, doc: Any) -> Any:
    """Panel's own build of a page (``panel.io.application._eval_panel``) into ``doc``."""
    from panel.io.application import _eval_panel

    return _eval_panel(factory, None, title, True, False, doc)


#: Roots whose stylesheets were patched off the loop, with the ``dist_url`` used.
_CSS_DONE: weakref.WeakKeyDictionary[Any, str] = weakref.WeakKeyDictionary()


def patch_css_off_loop(doc: Any, application: Any) -> str:
    """Patch the stylesheets of every root of ``doc`` as Panel's page handler will (in the
    build thread); returns the ``dist_url`` used (Panel's ``server`` resources mode)."""
    from panel.io.resources import LOCAL_DIST, patch_model_css
    from panel.io.state import set_curdoc

    application._set_session_prefix(doc)  # what initialize_document does first
    with set_curdoc(doc):
        rel = pn_state.rel_path
    dist_url = f"{rel}/{LOCAL_DIST}" if rel else LOCAL_DIST
    for root in doc.roots:
        patch_model_css(root, dist_url=dist_url)
        _CSS_DONE[root] = dist_url
    return dist_url


def skip_repeated_css_patch() -> bool:
    """Make Panel's page handler skip roots that :func:`patch_css_off_loop` patched for the
    same ``dist_url``; returns whether it applied (False on another Panel version)."""
    from panel.io import server as pn_server

    if not supported():
        return False
    original = pn_server.patch_model_css
    if getattr(original, "_gmwm_skip", False):
        return True

    def patch_model_css(root: Any, dist_url: str) -> None:
        if _CSS_DONE.get(root) == dist_url:
            return  # done in the build thread, with the same result
        original(root, dist_url=dist_url)

    patch_model_css._gmwm_skip = True  # type: ignore[attr-defined]
    pn_server.patch_model_css = patch_model_css
    return True
