"""The ``gmwm`` command's entry point: the table of sub-commands (:data:`COMMANDS`), the parser
and the dispatch (:func:`main`).

A sub-command is a :class:`Command` record: its name, its one-line help and the module of
``engine.cli`` that builds its parser and runs it. ``gmwm --help`` reads the table alone, and
``gmwm X ...`` (or ``gmwm X --help``) imports X's module only, so that a command pays for its
own imports: ``gmwm plan`` loads neither the export formats nor the reports
(docs/performance.md, "The gmwm command's start").

Without ``--json`` a readable table with units is printed; with ``--json`` exactly one JSON
object. Bad input exits with status 2 and a one-line message on stderr, never a traceback.
Warnings (queued by the subcommands, or issued by the engine as Python warnings) are printed
after the result as ``gmwm COMMAND: warning: ...``, one line each. An option name has one
meaning in every subcommand (tests/cli/test_cli_options.py holds the table); old spellings
(``--alpha``, ``--level``, ``--out``, ``--select``, ``gmwm virtual --scale``) still work and
print a deprecation warning naming the new option.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import warnings
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any, NoReturn

from ..errors import CliError, GmwmError
from .common import cli_text, queue_warning, terminal_text

__all__ = ["Command", "COMMANDS", "build_parser", "main"]


@dataclass(frozen=True)
class Command:
    """One sub-command of ``gmwm``.

    Attributes
    ----------
    name : str
        What the user types (``gmwm NAME ...``).
    help : str
        The one line ``gmwm --help`` shows.
    module : str
        The module of ``engine.cli`` that builds the parser and runs the command: it has
        ``run(args) -> dict | str`` and the function :attr:`adder`.
    adder : str
        The module's function that adds the parser: ``adder(subparsers) -> parser``.
    """

    name: str
    help: str
    module: str
    adder: str = "add_parser"

    def add_parser(self, sub: Any) -> argparse.ArgumentParser:
        """Import the module and add the sub-command's full parser to ``sub``."""
        parser: argparse.ArgumentParser = getattr(self._module(), self.adder)(_WithHelp(sub))
        return parser

    def run(self, args: argparse.Namespace) -> dict[str, Any] | str:
        """Run the sub-command on the parsed ``args``: a JSON object or a text to print."""
        out: dict[str, Any] | str = self._module().run(args)
        return out

    def _module(self) -> Any:
        return importlib.import_module(f".{self.module}", __package__)


#: Every sub-command, in the order ``gmwm --help`` lists them.
COMMANDS: dict[str, Command] = {
    c.name: c
    for c in (
        Command("wv", "empirical Haar wavelet variance with intervals", "core", "add_wv_parser"),
        Command("fit", "fit a latent model by GMWM", "core", "add_fit_parser"),
        Command("select", "rank candidate models by WVIC", "core", "add_select_parser"),
        Command("simulate", "simulate a model with given values", "core", "add_simulate_parser"),
        Command(
            "study",
            "Monte Carlo studies: slope = AVSM vs ARMAV vs GMWM (the GMWM paper, Fig. 1-2)",
            "core",
            "add_study_parser",
        ),
        Command(
            "export",
            "fit channels and export Kalibr imu.yaml, a JSON report, WV curves (CSV), a "
            "datasheet table, or a filter/simulator format (OpenVINS, Basalt, ORB-SLAM3, VINS, "
            "PX4, ArduPilot, MATLAB, Gazebo, KF-GINS, sensor_msgs/Imu)",
            "export",
        ),
        Command(
            "check",
            "datasheet check: the manufacturer's noise model (ARW/VRW, bias instability, "
            "rate random walk) against the empirical WV and its interval, per scale",
            "check",
        ),
        Command(
            "virtual",
            "optimal virtual sensor: the weighted mean of k redundant sensors (same axis) "
            "with the smallest WV, from a multivariate GMWM fit",
            "virtual",
        ),
        Command(
            "batch",
            "fit every channel of many logs (a fleet of IMUs): one report per log and the "
            "spread of every parameter across the units",
            "batch",
        ),
        Command(
            "report",
            "calibration report of one log: one self-contained HTML file (plots, "
            "parameters with intervals, datasheet check, export numbers)",
            "report",
        ),
        Command("segments", "list the still segments of a flight log", "segments"),
        Command(
            "plan",
            "how long to record: the precision of the IEEE quantities against the log "
            "length, and the length that meets each target",
            "plan",
        ),
    )
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2 (argparse's own convention)
        raise CliError(f"{self.prog}: {message}")


class _WithHelp:
    """The sub-parsers as a module's adder sees them: each sub-command's one-line help comes
    from its :class:`Command` record (declared once, in :data:`COMMANDS`)."""

    def __init__(self, sub: Any) -> None:
        self._sub = sub

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        parser: argparse.ArgumentParser = self._sub.add_parser(
            name, help=COMMANDS[name].help, **kwargs
        )
        return parser


def build_parser(commands: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The ``gmwm`` parser.

    Parameters
    ----------
    commands : collection of str, optional
        The sub-commands whose full parser is built (their modules are imported); the others
        are listed by name and help only. Default: all.
    """
    p = _Parser(prog="gmwm", description="GMWM stochastic calibration of inertial sensors.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for c in COMMANDS.values():
        if commands is None or c.name in commands:
            c.add_parser(sub)
        else:
            sub.add_parser(c.name, help=c.help)
    return p


def _invoked(argv: Sequence[str]) -> list[str]:
    """The sub-command named in ``argv`` (the first word that is not an option), if any."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return [word] if word in COMMANDS else []


def _one_line(e: BaseException | Warning | str) -> str:
    """An engine error or warning as one line, in the command's words (:func:`cli_text`)."""
    return cli_text(" ".join(str(e).split()))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gmwm`` console script; returns the exit status."""
    from .._blas import set_blas_threads

    if argv is None:  # the command itself (not a call from Python): see engine._blas
        set_blas_threads(1)
    given = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser(_invoked(given)).parse_args(given)
        args.argv = given  # as given (gmwm report)
        with warnings.catch_warnings(record=True) as caught:  # the engine's, e.g. PX4 range
            out = COMMANDS[args.command].run(args)
        for w in caught:
            queue_warning(args, _one_line(w.message))
    except GmwmError as e:  # every engine error (engine.errors): one line, exit status 2
        print(terminal_text(f"gmwm: error: {_one_line(e)}"), file=sys.stderr)
        return 2
    except (ValueError, OSError, TypeError) as e:  # data-dependent errors from numpy/h5py
        print(terminal_text(f"gmwm: error: {_one_line(e)}"), file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # pragma: no cover
        print("gmwm: interrupted", file=sys.stderr)
        return 130
    for warning in getattr(args, "warnings", ()):  # e.g. fs unknown, deprecated option
        print(terminal_text(f"gmwm {args.command}: warning: {warning}"), file=sys.stderr)
    text = json.dumps(out, allow_nan=False) if isinstance(out, dict) else out
    try:
        print(terminal_text(text))
        sys.stdout.flush()  # here, not at exit, so that a closed pipe is caught
    except BrokenPipeError:  # `gmwm wv ... | head -3`: the reader left; no traceback
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the exit-time flush writes nowhere
        return 141  # 128 + SIGPIPE, what a shell tool killed by the closed pipe reports
    return 0
