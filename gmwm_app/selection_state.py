"""Model selection and inference of a session (no widgets): WVIC ranking, intervals, J-test.

:class:`SelectionMixin` holds these actions of :class:`gmwm_app.state.AppState` (it has the
state's parameters ``wv``, ``weights``, ``result``, ``selection``, ``show_intervals`` and
``inferred``, and its ``_publish``, ``_fail`` and ``_guard``). The ``compute_*`` methods are
worker-thread safe (no parameter change); the ``install_*`` methods put their results in the
state on the event loop. The views are :mod:`gmwm_app.selection_view` (the "Model selection"
tab, the J-test badge) and the Fit tab's parameter table.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

import engine as eg
from gmwm_app.data import message_of
from gmwm_app.limits import check_candidates

__all__ = ["Inference", "SelectionMixin", "N_INFERENCES", "Offload"]

log = logging.getLogger(__name__)

#: How a front end runs work off its event loop: ``offload(work, apply, fail, done)`` runs
#: ``work()`` in a worker, then ``apply(result)`` or ``fail(error)``, then ``done()``, on the
#: loop (the app: :meth:`gmwm_app.jobs.Jobs.run`).
Offload = Callable[
    [Callable[[], Any], Callable[[Any], Any], Callable[[BaseException], Any], Callable[[], Any]],
    Any,
]

if TYPE_CHECKING:  # the state's names this mixin uses (AppState defines them)
    from gmwm_app.state_fields import StateFields
else:
    StateFields = object

#: Fits whose intervals and J-test a session keeps.
N_INFERENCES = 32


@dataclass
class Inference:
    """95% asymptotic intervals (``ParamInterval`` list) and J-test of one fit."""

    result: Any
    intervals: list[Any]
    j_test: Any = None  # engine.inference.JTest, None when it cannot be computed
    j_error: str = ""


class SelectionMixin(StateFields):
    """Ranking and inference actions of :class:`gmwm_app.state.AppState`."""

    param: Any
    wv: eg.WaveletVariance | None
    weights: str
    result: eg.GMWMResult | None
    offload: Offload | None
    _inference: dict[int, Inference]
    _inference_pending: set[int]

    def ranking_candidates(self, spec: str) -> list[str]:
        """The parts of a ranking's text, checked (quick, on the loop: a ranking is refused
        before it waits for a worker): one maximal model (``"3*GM+WN+QN+RW+DR"``) or
        candidates separated by commas (``"WN+RW, GM+WN"``), within the server's cap.

        Raises
        ------
        ValueError
            No data, no text, a model that cannot be read, or more candidates than the cap.
        """
        from engine.inference import submodels

        if self.wv is None:
            raise ValueError("load data before ranking models")
        parts = [p.strip() for p in (spec or "").split(",") if p.strip()]
        if not parts:
            raise ValueError(
                "type a maximal model (e.g. 3*GM+WN+QN+RW+DR) or candidate "
                "models separated by commas"
            )
        try:
            if len(parts) == 1:
                check_candidates(len(submodels(parts[0])), parts[0])
            else:
                check_candidates(len(parts), "the list")
        except eg.ModelError as e:
            raise ValueError(message_of(e)) from None
        return parts

    def compute_ranking(
        self, spec: str, *, progress: Callable[[int, int], None] | None = None
    ) -> tuple[eg.WaveletVariance, Any]:
        """Rank models by WVIC on the current WV: every sub-model of a maximal model
        (``"3*GM+WN+QN+RW+DR"``) or candidates separated by commas (``"WN+RW, GM+WN"``)."""
        from engine.inference import rank_models

        wv = self.wv
        if wv is None:
            raise ValueError("load data before ranking models")
        parts = self.ranking_candidates(spec)
        try:
            if len(parts) == 1:
                sel = rank_models(wv, max_model=parts[0], weights=self.weights, progress=progress)
            else:
                sel = rank_models(wv, parts, weights=self.weights, progress=progress)
        except eg.GmwmError as e:  # any engine error: its one-line message
            raise ValueError(message_of(e)) from None
        return wv, sel

    def install_ranking(self, out: tuple[eg.WaveletVariance, Any]) -> bool:
        """Show a ranking from :meth:`compute_ranking` (refused if the data changed since)."""
        wv, sel = out
        if wv is not self.wv:
            return self._fail("The data changed while ranking: rank again")
        self._publish(selection=sel, error="")
        return True

    def rank(self, spec: str, *, progress: Callable[[int, int], None] | None = None) -> bool:
        """:meth:`compute_ranking` then :meth:`install_ranking` (synchronous)."""
        return self._guard(
            "Could not rank the models",
            lambda: self.install_ranking(self.compute_ranking(spec, progress=progress)),
        )

    def compute_inference(self, result: eg.GMWMResult) -> Inference:
        """95% asymptotic intervals and the J-test of a fit (worker-thread safe)."""
        from engine.inference import j_test, param_intervals

        try:
            intervals = param_intervals(result, method="asymptotic", level=0.95)
        except (eg.GmwmError, np.linalg.LinAlgError) as e:
            raise ValueError(f"no intervals for {result.model.spec()}: {message_of(e)}") from None
        try:
            return Inference(result, intervals, j_test(result), "")
        except (ValueError, np.linalg.LinAlgError) as e:  # eg.GmwmError or numpy's
            return Inference(result, intervals, None, message_of(e))

    def install_inference(self, inf: Inference) -> bool:
        """Cache intervals and J-test of a fit (the latest :data:`N_INFERENCES` fits kept) and
        set :attr:`inferred` (the views showing them depend on it)."""
        if len(self._inference) >= N_INFERENCES:
            self._inference.pop(next(iter(self._inference)))
        self._inference[id(inf.result)] = inf
        self._publish(inferred=inf)
        return True

    def inference(self, result: eg.GMWMResult | None = None) -> Inference | None:
        """The cached intervals and J-test of a fit (the current one by default), or None."""
        res = self.result if result is None else result
        inf = self._inference.get(id(res)) if res is not None else None
        return inf if inf is not None and inf.result is res else None

    def ensure_inference(self, result: eg.GMWMResult | None = None) -> bool:
        """Start computing the intervals and J-test of a fit (the current one by default)
        unless they are cached or being computed; :meth:`install_inference` shows them.

        The state owns them, whichever view asks (the Fit tab's parameter table, the Model
        selection tab's comparison): the work runs through :attr:`offload` when a front end
        set it, else at once. A failure is reported in :attr:`error`.

        Returns
        -------
        bool
            True when they are cached already (or were computed at once).
        """
        res = self.result if result is None else result
        if res is None or self.inference(res) is not None:
            return res is not None
        key = id(res)
        if key in self._inference_pending:
            return False

        def fail(e: BaseException) -> None:
            if isinstance(e, ValueError):  # bad input: the message says it all
                log.warning("intervals: %s", e)
            else:
                log.error("intervals: job failed", exc_info=e)
            self._fail(f"Could not compute the intervals: {message_of(e)}")

        if self.offload is None:  # tests, notebooks: at once
            try:
                return self.install_inference(self.compute_inference(res))
            except ValueError as e:
                fail(e)
                return False
        self._inference_pending.add(key)
        self.offload(
            lambda: self.compute_inference(res),
            self.install_inference,
            fail,
            lambda: self._inference_pending.discard(key),
        )
        return False

    def set_show_intervals(self, on: bool) -> bool:
        """Show (or hide) the interval columns and the goodness-of-fit badge."""
        self._publish(show_intervals=bool(on))
        return True
