"""``gmwm check`` (:func:`add_parser`, :func:`run`): a datasheet against a log::

    gmwm check INPUT [--channel NAME] [--fs HZ] [--levels J] [--confidence 0.95]
               --datasheet "arw=0.3 deg/sqrt(h), bi=5 deg/h, rrw=2 deg/h/sqrt(h)"
               | --datasheet-file imu.yaml|report.json|datasheet.csv
               [--model SPEC] [--units U] [--json]

The datasheet model (white noise, random walk, quantization, bias-instability floor) is drawn
at the empirical WV's scales, with a per-scale verdict against the empirical interval
(:func:`engine.inference.check_datasheet`); ``--model`` fits a GMWM model beside it. Bad
input exits with status 2 and a one-line message.
"""

from __future__ import annotations

import argparse
from typing import Any

from . import flight_params
from .common import (
    INPUT_HELP,
    add_confidence_option,
    add_log_options,
    add_wv_options,
    alpha_of,
    load_wv,
)

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``check`` sub-command to the ``gmwm`` sub-parsers."""
    ck = sub.add_parser("check")
    ck.add_argument("input", help=INPUT_HELP)
    ck.add_argument("--channel", help="channel name or index (default: the first)")
    add_wv_options(ck)
    add_confidence_option(ck, "the empirical WV interval the verdicts use", "--level")
    src = ck.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--datasheet",
        help="KEY=VALUE UNIT items separated by commas: arw (deg/sqrt(h)) or vrw "
        "(m/s/sqrt(h)), rrw (deg/h/sqrt(h)) or accrw (m/s/h/sqrt(h)), bi (deg/h or mg), "
        "q (deg or m/s); native units like deg/s/sqrt(Hz) also work",
    )
    src.add_argument(
        "--datasheet-file",
        help="Kalibr imu.yaml, gmwm JSON report or datasheet CSV (gmwm export), or a "
        "datasheet JSON (gmwm check --json)",
    )
    src.add_argument(  # engine/cli/flight_params.py
        "--params",
        metavar="FILE|log",
        help="flight logs: the EKF noise parameters flown (PX4 .params, ArduPilot .param, or "
        "'log': the log's own) against its still segments (--segments, default auto)",
    )
    ck.add_argument(
        "--model", help="also fit this GMWM model (ci weights) beside it, e.g. 'GM+WN+RW'"
    )
    ck.add_argument("--json", action="store_true", help="print one JSON object")
    add_log_options(ck)
    ck.set_defaults(robust=False, eff=0.6)
    return ck


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm check``; returns the table (or a JSON-ready dict)."""
    from .._jsonutil import json_ready
    from ..fit import fit_gmwm
    from ..formats.readers import read_check_file
    from ..inference.datasheet_check import check_datasheet, parse_datasheet
    from ..models import parse_model
    from ..units import ExportError, si_factor

    if getattr(args, "params", None):  # a flight's EKF parameters (engine/cli/flight_params)
        return flight_params.run(args)
    ds = parse_datasheet(args.datasheet, source="--datasheet") if args.datasheet else None
    model = parse_model(args.model) if args.model else None
    wv, name = load_wv(args, alpha_of(args.confidence))
    if ds is None:
        kind = None
        try:
            kind = si_factor(wv.unit, name)[0]
        except ExportError:
            pass  # the check itself says the unit is needed
        ds = read_check_file(args.datasheet_file, channel=name, kind=kind, fs=wv.fs)
    fit = fit_gmwm(wv, model) if model is not None else None
    res = check_datasheet(wv, ds, fit=fit, level=args.confidence)
    if args.json:
        d = res.to_dict()
        d["channel"] = name
        d["input"] = str(args.input)
        return json_ready(d)
    return f"{args.input} [{name}]\n{res.table()}"
