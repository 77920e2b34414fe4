"""GMWM browser app (Panel + Bokeh): load an IMU log, build a latent model live, read the fit.

Layers: :mod:`gmwm_app.state` (session state, no widgets; with :mod:`~gmwm_app.data`,
:mod:`~gmwm_app.query` and :mod:`~gmwm_app.whatif`), :mod:`gmwm_app.views` and
:mod:`~gmwm_app.wv_figures` (Bokeh figures and tables updated in place), the tabs (``*_view``
modules, Viewers of the state and of the session's :mod:`~gmwm_app.jobs`), :mod:`gmwm_app.app`
(``create_app()`` per browser session) and :mod:`gmwm_app.server` (serving). Start it with
``gmwm-app`` or ``python -m gmwm_app``.
"""

from __future__ import annotations

from typing import Any

from .state import AppState, demo_path

__all__ = ["AppState", "demo_path", "create_app"]


def create_app(**kwargs: Any) -> Any:
    """Build the page of one session; see :func:`gmwm_app.app.create_app`.

    Imported lazily: importing Panel is slow and the state layer does not need it.
    """
    from .app import create_app as _create_app

    return _create_app(**kwargs)
