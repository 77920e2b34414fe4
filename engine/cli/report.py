"""``gmwm report`` (:func:`add_parser`, :func:`run`): a calibration report of one IMU log::

    gmwm report INPUT -o report.html [--model SPEC | --max-model SPEC] [--channels a,b,...]
                [--datasheet VALUES | --datasheet-file FILE] [--format kalibr] [--static]
                [--fs HZ] [--levels J] [--weights ci|identity|efficient] [--confidence 0.95]
                [--segment ...] [--scale ...] [--units ...] [--topic T] [--json]
                [--drop-warmup] [--temperature auto|none|COLUMN]

One self-contained HTML file (:func:`engine.report`): the log, per channel the Allan deviation,
the WV with the fit, its decomposition and residuals, the PSD, the parameters and datasheet
quantities with intervals, the J-test and every warning, the datasheet check, the export file,
and how it was made; with a temperature channel, its sensitivity and both WVs (raw and
compensated). ``--static`` draws PNG figures (matplotlib) instead of interactive ones.
"""

from __future__ import annotations

import argparse
import shlex
from typing import Any

from .common import (
    CHANNELS_HELP,
    INPUT_HELP,
    add_check_options,
    add_confidence_option,
    add_log_options,
    add_weights_option,
    add_wv_options,
    check_output,
    input_paths,
    log_kwargs,
    say,
    usage_error,
)

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``report`` sub-command to the ``gmwm`` sub-parsers."""
    from ..inference.selection import DEFAULT_SELECT

    rp = sub.add_parser("report")
    rp.add_argument("input", help=INPUT_HELP)
    rp.add_argument("-o", "--output", required=True, help="output file: the HTML report (.html)")
    what = rp.add_mutually_exclusive_group()
    what.add_argument("--model", help="model of every channel, e.g. 'GM+WN+RW'")
    what.add_argument(
        "--max-model",
        metavar="SPEC",
        help=f"per channel, the WVIC-best sub-model of this model (default {DEFAULT_SELECT})",
    )
    rp.add_argument("--channels", help=CHANNELS_HELP)
    src = rp.add_mutually_exclusive_group()
    src.add_argument(
        "--datasheet",
        help="KEY=VALUE UNIT items separated by commas, as gmwm check takes them "
        "('arw=0.3 deg/sqrt(h), bi=5 deg/h'): the datasheet values to check",
    )
    src.add_argument(
        "--datasheet-file", help="Kalibr imu.yaml, gmwm JSON report or datasheet CSV to check"
    )
    rp.add_argument(
        "--format",
        default="kalibr",
        help="export format whose file the report includes (default kalibr; 'none': none)",
    )
    rp.add_argument("--static", action="store_true", help="PNG figures instead of interactive")
    rp.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object: per channel its model and IEEE quantities (key 'ieee')",
    )
    add_wv_options(rp)
    add_weights_option(rp)
    add_confidence_option(rp, "the parameter intervals")
    add_log_options(rp, stream=False)
    add_check_options(rp)  # --drop-warmup --temperature
    return rp


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm report``; returns one line saying what was written."""
    # before any import or fit:
    check_output(args.output, "-o", suffixes=(".html", ".htm"), inputs=input_paths(args))
    from .._files import write_atomic
    from ..formats import FORMATS
    from ..reporting import gather_report, render_html
    from .progress import Stages

    fmt = None if args.format.lower() == "none" else args.format
    if fmt is not None and fmt not in FORMATS:
        raise usage_error(f"--format {fmt!r}: use one of {', '.join(FORMATS)} or none")
    channels = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
    units = {"fits": "channel", "intervals": "step", "figures": "figure", "writing": "step"}
    with Stages("gmwm report", units) as bars:  # on a terminal only
        rep = gather_report(
            args.input,
            model=args.model,
            select=args.max_model,
            channels=channels,
            fs=args.fs,
            levels=args.levels,
            weights=args.weights,
            level=args.confidence,
            datasheet=args.datasheet_file or args.datasheet,
            export_format=fmt,
            load_options=log_kwargs(args),
            command_line=shlex.join(["gmwm", *args.argv]),
            drop_warmup=args.drop_warmup,
            temperature=args.temperature,
            progress=bars,
        )
        bars.close()
        check = rep.log.get("qualification") or {}
        if check.get("findings") or check.get("dropped"):  # one line, as gmwm fit says it
            say(args, check["summary"])
        for c in rep.channels.values():  # one line per compensated channel, as gmwm fit says it
            if c.temperature is not None:
                say(args, c.temperature.line())
        page = render_html(rep, static=args.static, progress=bars)
        write_atomic(args.output, page)  # never a truncated page; a full disk names the file
    kind = "static" if args.static else "interactive"
    if args.json:
        return {
            "output": str(args.output),
            "qualification": check or None,
            "channels": {
                ch: (
                    {
                        "model": c.fit.model.spec(values=True),
                        "ieee": c.fit.ieee.to_dict(),
                        "temperature": c.temperature.to_dict() if c.temperature else None,
                    }
                    if c.fit is not None
                    else {"error": c.error}
                )
                for ch, c in rep.channels.items()
            },
        }
    return f"wrote {args.output} ({kind}, {len(page.encode('utf-8')) / 1e6:.2f} MB)"
