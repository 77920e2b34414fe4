"""``gmwm batch`` (:func:`add_parser`, :func:`run`): calibrate a fleet of IMUs::

    gmwm batch LOG_OR_GLOB... --model SPEC | --max-model SPEC -o DIR [--channels a,b,...]
               [--fs HZ] [--levels J] [--weights ci|identity|efficient] [--workers N]
               [--scheduler local|ADDRESS] [--quiet] [--json]
               [--segment ...] [--scale ...] [--units ...] [--topic T]

Every channel of every log is fitted (:func:`engine.batch.fit_batch`); DIR receives one JSON
report per log and ``summary.csv``/``summary.json`` (the spread of every parameter and
datasheet quantity across the units). ``--select`` is the deprecated spelling of
``--max-model`` (the name ``gmwm select`` uses). ``--scheduler`` runs the logs on a Dask cluster
(:func:`add_scheduler_option` and :func:`scheduler_executor`, also used by ``gmwm study``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from typing import Any

from .common import (
    CliError,
    add_deprecated_alias,
    add_log_options,
    check_output,
    log_kwargs,
    positive,
    queue_warning,
)

__all__ = ["add_parser", "run", "add_scheduler_option", "scheduler_executor"]

_SELECT_HELP = "per channel, the WVIC-best sub-model of this model, e.g. '2*GM+WN+RW+DR'"
_EXIT = (
    "exit status: 0 when at least one log was fitted (the logs that failed are listed on "
    "stderr and in DIR/summary.json), 2 when none was or the command line is wrong"
)


def add_scheduler_option(sp: argparse.ArgumentParser) -> None:
    """Add ``--scheduler`` (run the tasks on a Dask cluster) to a sub-command."""
    sp.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the tasks on a Dask cluster: 'local' starts a LocalCluster of --workers "
        "processes on this machine; an address (tcp://host:8786) uses a running scheduler, "
        "whose workers must have this package and see the input files at the same paths "
        "(needs pip install 'gmwm-app[dask]'; default: local processes without Dask)",
    )


@contextmanager
def scheduler_executor(args: argparse.Namespace) -> Iterator[Executor | None]:
    """The Dask executor of ``--scheduler`` (None without it: the local process pool)."""
    if not getattr(args, "scheduler", None):
        yield None
        return
    from .._parallel import dask_executor

    try:
        import distributed  # noqa: F401 - the optional extra
    except ImportError:
        raise CliError(
            "--scheduler needs Dask's distributed scheduler: pip install 'gmwm-app[dask]'"
        ) from None
    with dask_executor(args.scheduler, getattr(args, "workers", 2) or 2) as ex:
        yield ex


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``batch`` sub-command to the ``gmwm`` sub-parsers."""
    bt = sub.add_parser(
        "batch",
        help="fit every channel of many logs (a fleet of IMUs): one report per log and the "
        "spread of every parameter across the units",
        epilog=_EXIT,
    )
    bt.add_argument(
        "inputs",
        nargs="+",
        metavar="LOG_OR_GLOB",
        help="log files or glob patterns (quoted: 'lab/unit_*.h5'); a pattern matching "
        "nothing is reported as a failed log",
    )
    what = bt.add_mutually_exclusive_group(required=True)
    what.add_argument("--model", help="model of every channel, e.g. 'GM+WN+RW'")
    mm = what.add_argument("--max-model", metavar="SPEC", help=_SELECT_HELP)
    add_deprecated_alias(what, "--select", mm)
    bt.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="DIR",
        help="folder for one JSON report per log, summary.csv and summary.json (created if "
        "missing; checked before any fit)",
    )
    bt.add_argument("--channels", help="channels separated by commas (default: all)")
    bt.add_argument("--fs", type=positive(float, "--fs"), help="sampling frequency in Hz")
    bt.add_argument("--levels", type=positive(int, "--levels"), help="number of WV levels J")
    bt.add_argument(
        "--weights",
        default="ci",
        choices=["ci", "identity", "efficient"],
        help="weighting matrix: ci (default), identity, or efficient (two-step, V^-1)",
    )
    bt.add_argument(
        "--workers",
        type=positive(int, "--workers"),
        default=2,
        help="local worker processes, or the LocalCluster's with --scheduler local (2)",
    )
    add_scheduler_option(bt)
    bt.add_argument("--quiet", action="store_true", help="no progress line on stderr")
    bt.add_argument("--json", action="store_true", help="print one JSON object (the summary)")
    add_log_options(bt, stream=False)
    return bt


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm batch``; returns the fleet table (or the JSON-ready summary)."""
    check_output(args.output, "-o", kind="dir")  # before the (slow) imports and any fit
    from .._parallel import ProgressLine
    from ..batch import fit_batch

    channels = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
    bar = None if args.quiet else ProgressLine(0, sys.stderr, "gmwm batch", "logs")
    with scheduler_executor(args) as ex:
        res = fit_batch(
            args.inputs,
            model=args.model,
            select=args.max_model,
            channels=channels,
            fs=args.fs,
            levels=args.levels,
            weights=args.weights,
            load_options=log_kwargs(args),
            workers=args.workers,
            executor=ex,
            progress=bar,
        )
    files = res.save(args.output)
    for lf in res.logs:
        if lf.error:
            print(f"gmwm: batch: {lf.source}: {lf.error}", file=sys.stderr)
        for ch, err in lf.channel_errors.items():
            print(f"gmwm: batch: {lf.source} [{ch}]: {err}", file=sys.stderr)
    for w in res.warnings:  # the fits' own (e.g. a GM faster than one sample)
        queue_warning(args, w)
    if not res.fitted:
        raise CliError(
            f"no log could be fitted ({len(res.failed)} failed; see {files['summary_json']})"
        )
    if args.json:
        d = res.to_dict()
        d["files"] = files
        return d
    return (
        f"{res.table()}\n\nwrote {len(files['reports'])} report(s), summary.csv and "
        f"summary.json to {args.output}"
    )
