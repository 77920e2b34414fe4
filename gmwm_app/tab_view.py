"""The skeleton of the app's lazily built tabs (Model selection, Slope method, Multi-channel,
Datasheet check).

Panel's ``Parameterized`` + ``Viewer`` + ``param.depends`` pattern: the session's
:class:`~gmwm_app.state.AppState` is a parameter of the view (``state``), and each tab declares
the state parameters it draws on its ``_on_state`` method::

    @param.depends("state.wv", "state.unit", watch=True)
    def _on_state(self) -> None:
        self.refresh()

param calls such a method once per ``state.param.update(...)``, however many of the named
parameters the update changed (one batch), and not at all for the parameters it does not name.

:class:`TabView` holds what every tab shares, and nothing else:

- ``active``, whether the tab is the one shown: a hidden tab only marks itself dirty
  (``_dirty``) and draws when it is shown again (outside a server, in tests and notebooks,
  it is always drawn);
- failures: an exception of a refresh or of a job reaches the tab as a message (its
  ``message`` pane) and the log, never Panel or the server loop;
- background computations (:meth:`TabView._compute`): a job key, so only the latest request's
  result is drawn, and a ticket, so ``computing`` ends with the latest job only.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any, ClassVar

import panel as pn
import param

from .boundary import watcher
from .state import AppState, state_param
from .views import hidden_alert

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["TabView"]

log = logging.getLogger(__name__)


class TabView(pn.viewable.Viewer):
    """Base class of a lazily built tab of one session.

    A subclass builds its widgets and ``panel`` in ``__init__``, draws in :meth:`_draw` and
    declares the state parameters it draws with ``@param.depends("state.<name>", ...,
    watch=True)`` on its override of :meth:`_on_state`.

    Parameters
    ----------
    state : AppState
        The session state.
    jobs : Jobs
        The session's job runner (worker pool, document lock).
    **params
        Parameters of the view (``active``).

    Attributes
    ----------
    panel : panel.layout.Column
        The tab's content.
    message : panel.pane.Alert
        The tab's message (hidden when there is nothing to say).
    computing : bool
        A computation of :meth:`_compute` runs.
    """

    active = param.Boolean(default=True, doc="Whether the tab is shown.")
    state = state_param()

    #: The tab's short name: in the log, and in the CSS class of its message
    #: (``gmwm-<slug>-message``).
    slug: ClassVar[str] = "tab"

    def __init__(self, state: AppState, jobs: Jobs, **params: Any) -> None:
        super().__init__(state=state, **params)
        self.jobs = jobs
        self.computing = False
        self._dirty = True  # the state changed while the tab was hidden
        self._ticket = 0  # the latest computation of _compute
        self.message = hidden_alert("warning", css_classes=[f"gmwm-{self.slug}-message"])
        self.panel = pn.Column(sizing_mode="stretch_width")

    def __panel__(self) -> pn.Column:
        """The tab's content."""
        return self.panel

    # ------------------------------------------------------------------------------------
    # following the state and the tab
    # ------------------------------------------------------------------------------------
    def _on_state(self) -> None:
        """The state parameters the tab draws changed: refresh (never raising into Panel).

        Subclasses override it with ``@param.depends("state.<name>", ..., watch=True)``.
        """
        self._safely(self.refresh)

    @param.depends("active", watch=True)
    def _on_tab(self) -> None:
        """The tab was shown or hidden: draw what changed while it was hidden."""
        if self._dirty and self._visible():
            self._safely(self.refresh)

    def _visible(self) -> bool:
        """Whether the tab draws now: it is shown, or there is no server (tests, notebooks)."""
        return self.active or not self.jobs.served

    def refresh(self, force: bool = False) -> None:
        """Bring the tab in line with the state: now while it is shown, else when shown.

        Parameters
        ----------
        force : bool
            Redraw even when the view's inputs look unchanged.
        """
        if not self._visible():
            self._dirty = True
            return
        self._dirty = False
        self._draw(force)

    def _draw(self, force: bool) -> None:
        """Draw the state (the tab is visible). Subclasses implement it."""
        raise NotImplementedError

    # ------------------------------------------------------------------------------------
    # failures: a message in the tab and the log, never an exception into Panel
    # ------------------------------------------------------------------------------------
    def show_message(self, msgs: Sequence[str], *, level: str = "warning") -> None:
        """Show messages in the tab (none: hide the pane).

        Parameters
        ----------
        msgs : sequence of str
            One message (shown as is) or several (one bullet each); Markdown.
        level : {"warning", "info", "danger"}
            The alert's kind.
        """
        text = msgs[0] if len(msgs) == 1 else "  \n".join(f"• {m}" for m in msgs)
        self.message.param.update(object=text, visible=bool(msgs), alert_type=level)

    def _failed(self, err: BaseException) -> None:
        """Show a failure (already logged) in the tab. Subclasses may say more."""
        self.show_message([f"Display error: {type(err).__name__}: {err}"], level="danger")

    def _safely(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)``; an exception is logged and shown in the tab
        (:func:`gmwm_app.boundary.report`), not raised.

        The tab's refresh is a watcher of the state, and param calls the state's watchers one
        after the other: a tab's failure raised would stop the other parts of the page from
        drawing the change (which succeeded).
        """
        watcher(fn, f"{self.slug} tab: refresh failed", self._failed, *args)

    def _locked(self, fn: Callable[..., Any], *args: Any) -> None:
        """:meth:`_safely` with the session's document lock (:meth:`Jobs.locked`): for a
        widget's callback that changes Bokeh models (figure sources, titles). Panel runs a
        widget's callback without the lock, and Bokeh refuses such a change there ("_pending_
        writes should be non-None", and the failure could not be shown either)."""
        self.jobs.locked(partial(self._safely, fn, *args))

    def _log_job_error(self, err: BaseException) -> None:
        """Log the exception of a background job (a traceback unless a ValueError)."""
        if isinstance(err, ValueError):  # bad input: the message says it all
            log.warning("%s tab: %s: %s", self.slug, type(err).__name__, err)
        else:
            log.error("%s tab: job failed", self.slug, exc_info=err)

    def _job_failed(self, err: BaseException) -> None:
        """A background job raised: log it and show it in the tab."""
        self._log_job_error(err)
        self._failed(err)

    def _guarded(self, fn: Callable[[Any], Any]) -> Callable[[Any], None]:
        """``fn`` for a job's ``apply``/``fail``: an exception in it is shown, not raised."""
        return partial(self._safely, fn)

    # ------------------------------------------------------------------------------------
    # background computations
    # ------------------------------------------------------------------------------------
    def _compute(self, work: Callable[[], Any], apply: Callable[[Any], Any], key: str) -> None:
        """Run ``work`` in the job runner and draw its result with ``apply``.

        Only the latest computation of ``key`` is drawn (an older result is dropped);
        outside a server it runs at once. A failure is logged and shown (:meth:`_failed`).
        """
        self._ticket += 1
        self.computing = True
        self.jobs.run(
            work,
            self._guarded(apply),
            self._guarded(self._job_failed),
            partial(self._computed, self._ticket),
            key=key,
            inline=not self.jobs.served,
        )

    def _computed(self, ticket: int) -> None:
        if ticket == self._ticket:  # not while a newer one runs
            self.computing = False
