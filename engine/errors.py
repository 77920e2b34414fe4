"""The engine's errors: one base class, :class:`GmwmError`, and one subclass per kind of failure.

A caller that stops on any engine error catches :class:`GmwmError` (the ``gmwm`` command and the
app do, and show its message as one line); a caller that handles one kind catches that class.
:class:`GmwmError` is a :class:`ValueError`, so code written against ``except ValueError`` keeps
working. Every error is defined here, below every other module of the engine, and re-exported
where users met it first (``engine.io.LoadError``, ``engine.fit.FitError`` ...), so both import
paths give the same class. How to raise one: docs/developers.md, "Errors".
"""

from __future__ import annotations

__all__ = [
    "GmwmError",
    "LoadError",
    "ModelError",
    "FitError",
    "ExportError",
    "DatasheetError",
    "SessionError",
    "ReportError",
    "CliError",
    "UsageError",
]


class GmwmError(ValueError):
    """Base class of every error the engine raises on purpose: input or settings that cannot be
    used as given. The message is one line that says what was wrong, where (file, column,
    argument) and what to do."""


class LoadError(GmwmError):
    """A log could not be loaded (or saved); the message says which file, where, and the fix."""


class ModelError(GmwmError):
    """A model specification that cannot be parsed or cannot be identified."""


class FitError(GmwmError):
    """The data or the settings do not allow a fit (says what and how to fix it)."""


class ExportError(GmwmError):
    """A fit cannot be converted or exported as asked (unknown unit, missing process ...);
    the message says how to fix it."""


class DatasheetError(ExportError):
    """Datasheet values or a datasheet file that cannot be used; the message says which."""


class SessionError(GmwmError):
    """A session file cannot be read or does not match its data; the message says why."""


class ReportError(GmwmError):
    """A report that cannot be made as asked (the message says what to do)."""


class CliError(GmwmError):
    """A user error of the ``gmwm`` command: printed as one line, exit status 2."""


class UsageError(CliError):
    """A command-line usage error (a flag's value or a combination of flags); ``gmwm`` prints
    it as one line and exits with status 2."""
