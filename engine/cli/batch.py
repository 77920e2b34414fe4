"""``gmwm batch`` (:func:`add_parser`, :func:`run`): calibrate a fleet of IMUs::

    gmwm batch LOG_OR_GLOB... --model SPEC | --max-model SPEC (-o DIR | --report FILE.html)
               [--channels a,b,...] [--fs HZ] [--levels J] [--weights ci|identity|efficient]
               [--workers N] [--scheduler local|ADDRESS] [--quiet] [--json]
               [--datasheet VALUES | --datasheet-file FILE] [--spec 'KEY<=VALUE UNIT' ...]
               [--segment ...] [--scale ...] [--units ...] [--topic T]
               [--drop-warmup] [--temperature auto|none|COLUMN]
               [--export FORMAT [--filter-rate HZ] [--horizon S]]

Every channel of every log is fitted (:func:`engine.batch.fit_batch`); DIR receives one JSON
report per log and ``summary.csv``/``summary.json`` (the spread of every parameter and
datasheet quantity across the units). ``--select`` is the deprecated spelling of
``--max-model`` (the name ``gmwm select`` uses). ``--scheduler`` runs the logs on a Dask cluster
(:func:`add_scheduler_option` and :func:`scheduler_executor`, also used by ``gmwm study``).

``--report FILE.html`` writes the fleet acceptance report (:func:`engine.reporting.fleet_report`:
a row per unit, verdicts against ``--spec`` limits and/or ``--datasheet``, outliers, every
unit's own section); the logs are fitted once for both outputs (:func:`add_report_options`,
:func:`run_fleet`).

``--export FORMAT`` (with ``-o DIR``) writes ``DIR/fleet.<suffix>``, one filter file that no
unit is overconfident under (:func:`engine.batch.export_fleet`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .._files import write_atomic
from ..formats.catalog import FORMATS
from .common import (
    CHANNELS_HELP,
    CliError,
    add_check_options,
    add_deprecated_alias,
    add_log_options,
    add_weights_option,
    add_wv_options,
    check_output,
    cli_text,
    input_paths,
    log_kwargs,
    positive,
    queue_warning,
    terminal_text,
    usage_error,
)
from .export import add_filter_rate_option, add_horizon_option

__all__ = [
    "add_parser",
    "run",
    "add_scheduler_option",
    "scheduler_executor",
    "add_report_options",
    "run_fleet",
]

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
    bt = sub.add_parser("batch", epilog=_EXIT)
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
        metavar="DIR",
        help="folder for one JSON report per log, summary.csv and summary.json (created if "
        "missing; checked before any fit); -o, --report or both",
    )
    bt.add_argument("--channels", help=CHANNELS_HELP)
    add_wv_options(bt)
    add_weights_option(bt)
    bt.add_argument(
        "--workers",
        type=positive(int, "--workers"),
        default=2,
        help="local worker processes, or the LocalCluster's with --scheduler local (2)",
    )
    add_scheduler_option(bt)
    bt.add_argument(
        "--quiet",
        action="store_true",
        help="no progress line on stderr (the bar drawn on a terminal)",
    )
    add_check_options(bt)  # --drop-warmup --temperature (per log)
    bt.add_argument("--json", action="store_true", help="print one JSON object (the summary)")
    add_log_options(bt, stream=False)
    add_report_options(bt)
    add_fleet_export_options(bt)
    return bt


def add_fleet_export_options(bt: argparse.ArgumentParser) -> None:
    """``--export FORMAT`` (one filter file for the whole fleet) and its rate and horizon."""
    g = bt.add_argument_group("fleet filter file")
    g.add_argument(
        "--export",
        metavar="FORMAT",
        help="with -o DIR: write DIR/fleet.<suffix>, one filter file for every fitted unit: "
        "per axis the largest N and K of the units' own default exports, so that no unit is "
        f"overconfident ({', '.join(n for n, f in FORMATS.items() if f.fleet_file)}; "
        "docs/filters.md, One file for a fleet)",
    )
    add_filter_rate_option(g, "with --export: ")
    add_horizon_option(g, "with --export: ", default="each log's length")


def _fleet_format(name: str) -> Any:
    """The :class:`engine.formats.Format` of ``--export`` (a filter format), else a usage
    error naming the choices."""
    ok = {n: f for n, f in FORMATS.items() if f.fleet_file}
    if name not in ok:
        raise usage_error(
            f"--export takes a filter format whose bias is a random walk or that has none "
            f"({', '.join(ok)}; a Gauss-Markov bias's T_c differs per unit), got {name!r}"
        )
    return ok[name]


def _write_fleet_file(args: argparse.Namespace, res: Any) -> str:
    """``--export``: the fleet file in ``-o DIR``; returns its path."""
    from ..batch import export_fleet

    fmt = _fleet_format(args.export)
    path = str(Path(args.output) / f"fleet{fmt.suffix}")
    export_fleet(
        path,
        res.logs,
        args.export,
        fs=args.fs,
        load_options=log_kwargs(args),
        filter_rate=args.filter_rate,
        horizon_s=args.horizon,
    )
    return path


def add_report_options(bt: argparse.ArgumentParser) -> None:
    """``--report FILE.html`` (the fleet acceptance report) and what it checks."""
    g = bt.add_argument_group("fleet acceptance report")
    g.add_argument(
        "--report",
        metavar="FILE.html",
        help="write the fleet acceptance report: one self-contained HTML file (a row per "
        "unit, pass/fail, outliers, overlaid Allan deviations, each unit's own section)",
    )
    src = g.add_mutually_exclusive_group()
    src.add_argument(
        "--datasheet",
        help="KEY=VALUE UNIT items separated by commas, as gmwm check takes them "
        "('arw=0.3 deg/sqrt(h), bi=5 deg/h'): with --report, checked on every unit",
    )
    src.add_argument(
        "--datasheet-file",
        help="with --report: Kalibr imu.yaml, gmwm JSON report or datasheet CSV to check",
    )
    g.add_argument(
        "--spec",
        action="append",
        default=[],
        metavar="'KEY<=VALUE UNIT'",
        help="with --report: an acceptance limit, e.g. 'arw<=0.3 deg/sqrt(h)' (keys and units "
        "as --datasheet's; repeat the option for more)",
    )


def _fit_kwargs(
    args: argparse.Namespace, channels: list[str] | None, executor: Executor | None, progress: Any
) -> dict[str, Any]:
    """How every log of the fleet is fitted (``fit_batch``'s and ``gather_fleet``'s keywords),
    from the command's options: one list for the plain batch and the fleet report."""
    return {
        "model": args.model,
        "select": args.max_model,
        "channels": channels,
        "fs": args.fs,
        "levels": args.levels,
        "weights": args.weights,
        "load_options": log_kwargs(args),
        "workers": args.workers,
        "executor": executor,
        "progress": progress,
        **({"drop_warmup": True} if getattr(args, "drop_warmup", False) else {}),
        "temperature": getattr(args, "temperature", None),
    }


def run_fleet(
    args: argparse.Namespace,
    channels: list[str] | None,
    executor: Executor | None,
    progress: Any,
) -> Any:
    """Fit the fleet and write ``--report``; returns the batch's :class:`BatchResult`."""
    import shlex

    from ..inference.datasheet_check import DatasheetError
    from ..reporting import ReportError, gather_fleet, render_fleet_html
    from .progress import Stages

    try:
        fleet = gather_fleet(
            args.inputs,
            datasheet=args.datasheet_file or args.datasheet,
            spec=args.spec,
            level=0.95,
            **_fit_kwargs(args, channels, executor, progress),
            command_line=shlex.join(["gmwm", *getattr(args, "argv", [])]),
            output=args.output,  # each unit's report written as it completes
        )
        progress.close()  # the logs' bar ends; the page's bars follow
        units = {"figures": "figure", "writing": "step"}
        with Stages("gmwm batch: report", units, quiet=args.quiet) as bars:
            page = render_fleet_html(fleet, progress=bars)
    except (DatasheetError, ReportError) as e:
        raise CliError(str(e)) from None
    write_atomic(args.report, page)
    verdicts: dict[str, int] = {}
    for u in fleet.units:
        verdicts[u.verdict] = verdicts.get(u.verdict, 0) + 1
    print(
        f"gmwm: batch: wrote {args.report} ({len(fleet.units)} units, "
        f"{len(page.encode('utf-8')) / 1e6:.2f} MB; verdicts: "
        f"{', '.join(f'{n} {v}' for v, n in verdicts.items())})",
        file=sys.stderr,
    )
    return fleet.batch


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm batch``; returns the fleet table (or the JSON-ready summary)."""
    if args.output is None and args.report is None:
        raise usage_error("give -o DIR (JSON reports and summaries), --report FILE.html, or both")
    if args.report is None and (args.spec or args.datasheet or args.datasheet_file):
        raise usage_error("--spec, --datasheet and --datasheet-file apply to --report FILE.html")
    if getattr(args, "export", None) and args.output is None:
        raise usage_error("--export FORMAT writes the fleet file into -o DIR: give -o DIR")
    if getattr(args, "export", None):  # before any fit
        _fleet_format(args.export)
    if args.output is not None:  # before the (slow) imports and any fit
        check_output(args.output, "-o", kind="dir")
    if args.report is not None:
        check_output(args.report, "--report", suffixes=(".html", ".htm"), inputs=input_paths(args))
    from ..batch import BatchFolder, fit_batch
    from .progress import Bar

    if args.output is not None:  # files it did not write: refused before any fit
        BatchFolder(args.output, "").check_summaries()

    channels = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
    with scheduler_executor(args) as ex, Bar("gmwm batch: logs", "log", quiet=args.quiet) as bar:
        if args.report is not None:
            res = run_fleet(args, channels, ex, bar)
        else:
            res = fit_batch(  # each log's report written as it completes; resumes the folder
                args.inputs, **_fit_kwargs(args, channels, ex, bar), output=args.output
            )
    files = res.save(args.output) if args.output is not None else {}
    if getattr(args, "export", None) and res.fitted:
        files = {**files, "fleet_file": _write_fleet_file(args, res)}
    for lf in res.logs:
        if lf.error:
            print(terminal_text(f"gmwm: batch: {lf.source}: {cli_text(lf.error)}"), file=sys.stderr)
        for ch, err in lf.channel_errors.items():
            print(terminal_text(f"gmwm: batch: {lf.source} [{ch}]: {err}"), file=sys.stderr)
        q = lf.qualification
        if q and (q["findings"] or q["dropped"]):  # what the log check found, one line a log
            print(
                terminal_text(f"gmwm batch: {lf.source}: {cli_text(q['summary'])}"), file=sys.stderr
            )
        for t in lf.temperature_status().values():  # each channel with a temperature fit
            print(terminal_text(f"gmwm batch: {lf.source}: {cli_text(t['line'])}"), file=sys.stderr)
    for w in res.warnings:  # the fits' own (e.g. a GM faster than one sample)
        queue_warning(args, w)
    if not res.fitted:
        see = files.get("summary_json") or args.report
        raise CliError(f"no log could be fitted ({len(res.failed)} failed; see {see})")
    if args.json:
        d = res.to_dict()
        d["files"] = {**files, **({"report": args.report} if args.report else {})}
        return d
    wrote = [f"the fleet report {args.report}"] if args.report else []
    if "fleet_file" in files:
        wrote.append(
            f"the fleet {args.export} file {files['fleet_file']} (every axis at the largest N "
            f"and K of the {len(res.fitted)} fitted unit(s))"
        )
    if files:
        again = sum(lf.resumed for lf in res.logs)
        wrote.append(
            f"{len(files['reports'])} report(s)"
            + (f" ({again} resumed from an earlier run)" if again else "")
            + f", summary.csv and summary.json to {args.output}"
        )
    return f"{res.table()}\n\nwrote {' and '.join(wrote)}"
