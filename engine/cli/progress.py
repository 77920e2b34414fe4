"""The command's progress bars: tqdm on stderr when it is a terminal, nothing otherwise.

The engine reports its progress through callbacks (``progress(done, total)`` of
:func:`engine.batch.fit_batch` and :func:`engine.inference.rank_models`,
``progress(stage, done, total)`` of the reports); a :class:`Bar` is such a callback that
draws one tqdm bar, and :class:`Stages` one bar per stage of a report. Off a terminal (a
pipe, a file, a CI log) or with ``--quiet`` nothing is printed, so the command's output can
be read by a program.
"""

from __future__ import annotations

import sys
from contextlib import AbstractContextManager
from types import TracebackType

from tqdm import tqdm

__all__ = ["Bar", "Stages", "shown"]


def shown(quiet: bool = False) -> bool:
    """Whether bars are drawn: stderr is a terminal and ``--quiet`` was not given."""
    isatty = getattr(sys.stderr, "isatty", None)
    return not quiet and isatty is not None and bool(isatty())


class _ClosedOnExit(AbstractContextManager):
    """A ``with`` block that calls :meth:`close` at its end (an exception goes on)."""

    def close(self) -> None:  # pragma: no cover - every subclass closes its own bar
        raise NotImplementedError

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class Bar(_ClosedOnExit):
    """One tqdm bar on stderr, fed as a ``progress(done, total)`` callback or by :meth:`step`.

    Parameters
    ----------
    desc : str
        What is counted, before the bar (``"gmwm batch: logs"``).
    unit : str
        The unit of the count (``"log"``, ``"candidate"``).
    total : int, optional
        The count when it is known before the first call.
    quiet : bool
        Draw nothing (``--quiet``).
    """

    def __init__(self, desc: str, unit: str, total: int | None = None, quiet: bool = False):
        self._bar = tqdm(
            total=total,
            desc=desc,
            unit=f" {unit}",
            file=sys.stderr,
            disable=not shown(quiet),
            leave=True,
            dynamic_ncols=True,
            mininterval=0.2,
        )
        self._done = 0

    def __call__(self, done: int, total: int) -> None:
        """Say that ``done`` of ``total`` are done (a total may grow between calls)."""
        if self._bar.total != total:
            self._bar.total = total
        self._bar.update(done - self._done)
        self._done = done

    def step(self, k: int = 1) -> None:
        """Count ``k`` more done."""
        self._bar.update(k)
        self._done += k

    def close(self) -> None:
        """End the bar's line (a bar left open is closed at exit)."""
        self._bar.close()


class Stages(_ClosedOnExit):
    """One :class:`Bar` per stage of a report, as its ``progress(stage, done, total)`` callback.

    A stage's bar opens at its first call and closes when the next stage starts (or at
    :meth:`close`): ``gmwm report: fits``, ``... intervals``, ``... figures``.

    Parameters
    ----------
    command : str
        The bars' prefix (``"gmwm report"``).
    units : dict of str to str
        The unit counted in each stage (``{"fits": "channel"}``); ``"step"`` otherwise.
    quiet : bool
        Draw nothing.
    """

    def __init__(self, command: str, units: dict[str, str], quiet: bool = False) -> None:
        self.command, self.units, self.quiet = command, units, quiet
        self._stage = ""
        self._bar: Bar | None = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        """Say that ``done`` of ``total`` steps of ``stage`` are done."""
        if stage != self._stage or self._bar is None:
            self.close()
            self._stage = stage
            unit = self.units.get(stage, "step")
            self._bar = Bar(f"{self.command}: {stage}", unit, total, self.quiet)
        self._bar(done, total)

    def close(self) -> None:
        """Close the open stage's bar."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
