"""The test of dependence of the "Multi-channel" tab (``engine.multivariate.dependence_test``, the
multivariate paper, section IV), on request.

The parametric bootstrap refits 2 B simulated logs (B = 100 on the demo log with a linear
model: about half a minute), so it is never run live: a button starts it in the session's
worker pool, its ``progress`` callback feeds a progress bar and raises to cancel
(:class:`~gmwm_app.multi_fit.Cancelled`), and the outcome is shown in words.
"""

from __future__ import annotations

import html
import logging
import threading
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any

import panel as pn

from engine.multivariate import DependenceTest

from .data import message_of
from .jobs import ProgressThrottle, job_controls
from .multi_fit import Cancelled, dependence_text, run_dependence_test

if TYPE_CHECKING:  # pragma: no cover
    from .jobs import Jobs

__all__ = ["DependenceControls"]

log = logging.getLogger(__name__)


class DependenceControls:
    """Button, replicates, progress, Cancel and outcome of the test of dependence.

    Parameters
    ----------
    jobs : Jobs
        The session's job runner.
    fit : callable
        Returns the fit shown by the tab and its WV/WCCV matrix ``(result, wvm)`` (either
        may be None).
    safely : callable
        ``safely(fn, *args)`` runs ``fn(*args)`` and shows an exception in the tab (logged)
        instead of raising it (:meth:`gmwm_app.tab_view.TabView._safely`).

    Attributes
    ----------
    running : bool
        A test runs.
    result : DependenceTest or None
        The last outcome (kept when a test is cancelled or fails).
    """

    def __init__(
        self,
        jobs: Jobs,
        fit: Callable[[], tuple[Any, Any]],
        safely: Callable[..., None],
    ) -> None:
        self.jobs = jobs
        self._fit = fit
        self._safely = safely
        self.running = False
        self.result: DependenceTest | None = None
        self._cancel = jobs.abandon_on_close(threading.Event())  # stops when the session ends
        self._throttle = ProgressThrottle()  # at most ~10 updates a second
        self.replicates = pn.widgets.IntInput(
            label="Bootstrap replicates B", value=100, start=10, end=2000, step=10, width=170
        )
        self.button, self.cancel_button, self.progress = job_controls(
            "Test dependence",
            lambda: self.start(),
            lambda: self.cancel(),
            width=150,
            cancel_width=90,
            margin=(22, 5, 5, 10),
            description="Parametric bootstrap of the objective difference (shared vs independent)",
        )
        self.text = pn.pane.Markdown(
            "", sizing_mode="stretch_width", margin=(0, 10), css_classes=["gmwm-mdependence"]
        )
        self.panel = pn.Column(
            pn.Row(self.button, self.replicates, self.cancel_button, sizing_mode="stretch_width"),
            self.progress,
            self.text,
            margin=0,
            sizing_mode="stretch_width",
        )

    def _set_running(self, on: bool) -> None:
        self.running = on
        self.button.disabled = on
        self.cancel_button.disabled = not on
        self.progress.param.update(visible=on, value=0)

    def _progress(self, done: int, total: int, observer: Callable[[int, int], None] | None) -> None:
        """Progress callback (worker thread): bar, text, cancel point."""
        value = self._throttle.step(done, total, observer, self._cancel, Cancelled)
        if value is not None:
            text = f"⏳ Bootstrap replicate {done} of {total} ..."

            def show() -> None:
                self.progress.param.update(value=value)
                self.text.object = text

            self.jobs.locked(show)

    def start(
        self,
        B: int | None = None,
        *,
        seed: int = 0,
        observer: Callable[[int, int], None] | None = None,
    ) -> bool:
        """Test the dependence of the shown fit's shared processes in a worker thread.

        Parameters
        ----------
        B : int, optional
            Bootstrap replicates (default: the widget's).
        seed : int
            Seed of the bootstrap.
        observer : callable, optional
            ``observer(done, total)`` sees every progress step (tests).

        Returns
        -------
        bool
            False (with a message) when there is nothing to test or a test runs.
        """
        if self.running:
            return False
        res, wvm = self._fit()
        if res is None or wvm is None:
            self.text.object = "Fit a model first."
            return False
        if not res.model.shared:
            self.text.object = (
                "The model shares no process: mark the channels that "
                "share one first (nothing to test)."
            )
            return False
        b = int(B if B is not None else self.replicates.value or 100)
        model, spec = res.model, res.model.spec()
        self._cancel.clear()
        self._set_running(True)
        self.text.object = f"⏳ Fitting the independent model of {html.escape(spec)} ..."

        def work() -> DependenceTest:
            return run_dependence_test(
                wvm, model, B=b, seed=seed, progress=lambda d, t: self._progress(d, t, observer)
            )

        def apply(t: DependenceTest) -> None:
            self.result = t
            self.text.object = dependence_text(t, spec)

        def fail(e: BaseException) -> None:
            if isinstance(e, Cancelled):
                self.text.object = "Dependence test cancelled."
                return
            if isinstance(e, ValueError):  # e.g. a model the bootstrap cannot refit
                log.warning("dependence test: %s", message_of(e))
            else:
                log.error("dependence test failed", exc_info=e)
            self.text.object = f"**Dependence test failed:** {html.escape(message_of(e))}"

        self.jobs.run(
            work,
            partial(self._safely, apply),
            partial(self._safely, fail),
            lambda: self._set_running(False),
            long=True,
        )
        return True

    def cancel(self) -> None:
        """Stop the running test at its next replicate."""
        if self.running:
            self._cancel.set()
            self.text.object = "Cancelling ..."
