"""``gmwm plan`` (:func:`add_parser`, :func:`run`): how long to record::

    gmwm plan (--model SPEC_WITH_VALUES | --datasheet TEXT | --fit FIT.json | PILOT --model SPEC)
              [--fs HZ] [--units U] [--target "K within 10 %, N within 2 %"]
              [--hours 0.5,1,2,8] [--confidence 0.95] [--json]

The precision of every IEEE quantity against the log length, from the efficient GMWM's
asymptotic covariance (:func:`engine.inference.planning.plan_run`), and the shortest log that
meets each ``--target``. The model comes with its values: a spec, a datasheet
(``arw=0.2 deg/sqrt(h), rrw=2 deg/h/sqrt(h)``), the JSON of ``gmwm fit --json``, or a short
pilot log that is fitted first (efficient GMWM of ``--model``). Guide: ``docs/planning.md``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..inference.datasheet_spec import parse_datasheet
from ..inference.planning import parse_targets, plan_run
from .common import (
    CliError,
    add_confidence_option,
    add_log_options,
    load_wv,
    positive,
    queue_warning,
)

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``plan`` sub-command to the ``gmwm`` sub-parsers."""
    pp = sub.add_parser("plan")
    pp.add_argument(
        "pilot",
        nargs="?",
        metavar="PILOT",
        help="a short pilot log, fitted with --model first (its fs and unit are used)",
    )
    src = pp.add_mutually_exclusive_group()
    src.add_argument(
        "--model",
        help="the model with values, e.g. 'WN(sigma2=1e-6)+RW(gamma2=1e-12)' (per sample, in "
        "--units at --fs); with PILOT, the model to fit to it, e.g. 'GM+WN+RW'",
    )
    src.add_argument(
        "--datasheet",
        help="KEY=VALUE UNIT items of the sensor's datasheet, e.g. 'arw=0.2 deg/sqrt(h), "
        "rrw=2 deg/h/sqrt(h)' (with --fs and --units)",
    )
    src.add_argument(
        "--fit", metavar="FIT.json", help="a fitted model: the output of 'gmwm fit --json'"
    )
    pp.add_argument("--channel", help="PILOT's channel (default: the first)")
    pp.add_argument("--fs", type=positive(float, "--fs"), help="sampling frequency in Hz")
    pp.add_argument(
        "--target",
        default="",
        help="precision targets at --confidence, e.g. 'K within 10 %%, N within 2 %%, "
        "B within 20 %%' (N = ARW/VRW, B = bias instability (IEEE), ADEV_min, K = RRW, Q, R)",
    )
    pp.add_argument(
        "--hours",
        help="log lengths to tabulate, in hours, separated by commas (default: a "
        "doubling grid from 1 min)",
    )
    pp.add_argument(
        "--max-hours",
        type=positive(float, "--max-hours"),
        default=1000.0,
        help="longest log considered for a target (1000)",
    )
    add_confidence_option(pp, "the planned intervals")
    pp.add_argument("--json", action="store_true", help="print one JSON object")
    add_log_options(pp, stream=False)
    return pp


def _from_fit_json(path: str) -> tuple[str, float | None, str]:
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise CliError(f"--fit {path}: not a readable JSON file ({e.__class__.__name__})") from None
    spec = d.get("model_values") if isinstance(d, dict) else None
    if not isinstance(spec, str):
        raise CliError(f"--fit {path}: no 'model_values' key: give the output of gmwm fit --json")
    wv = d.get("wv") if isinstance(d.get("wv"), dict) else {}
    fs = d.get("fs")
    return spec, (float(fs) if isinstance(fs, (int, float)) else None), str(wv.get("unit") or "")


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm plan``."""
    try:
        targets = parse_targets(args.target)
    except ValueError as e:
        raise CliError(f"--target: {e}") from None
    if isinstance(args.units, dict):
        raise CliError("--units: give one unit for the planned signal, e.g. --units deg/s")
    fs, unit = args.fs, args.units
    if args.pilot:
        if not args.model:
            raise CliError("a PILOT log needs --model, the model to fit to it (e.g. GM+WN+RW)")
        args.input = args.pilot
        from ..fit import fit_gmwm  # this input only (the fit's search and its process pool)

        args.levels, args.robust, args.eff = None, False, 0.6
        wv, name = load_wv(args)
        res = fit_gmwm(wv, args.model, weights="efficient")
        model: Any = res.model
        fs, unit = wv.fs, wv.unit if unit is None else unit
        queue_warning(
            args,
            f"planned from the efficient fit of {args.model} to {args.pilot} [{name}] "
            f"({wv.n} samples): {res.model.spec(values=True)}",
        )
    elif args.fit:
        model, fs_json, unit_json = _from_fit_json(args.fit)
        fs = fs if fs is not None else fs_json
        unit = unit if unit is not None else unit_json
    elif args.datasheet:
        if fs is None or not unit:
            raise CliError("--datasheet needs --fs and --units (e.g. --fs 100 --units deg/s)")
        spec = parse_datasheet(args.datasheet)
        model = spec.model(fs, unit)
        if model is None:
            raise CliError("--datasheet: no arw/vrw, rrw or quantisation item to plan for")
    elif args.model:
        model = args.model
    else:
        raise CliError("give the model: --model SPEC_WITH_VALUES, --datasheet, --fit or PILOT")
    if fs is None:
        raise CliError("give --fs, the sampling frequency in Hz of the log to plan")
    lengths = None
    if args.hours:
        try:
            hours = [float(h) for h in args.hours.split(",") if h.strip()]
        except ValueError:
            raise CliError(f"--hours takes hours separated by commas, got {args.hours!r}") from None
        if not hours or not all(math.isfinite(h) and h > 0 for h in hours):
            raise CliError(f"--hours takes positive hours, got {args.hours!r}")
        lengths = [max(16, int(round(h * 3600 * fs))) for h in hours]
    plan = plan_run(
        model,
        fs,
        targets,
        unit=unit or "",
        level=args.confidence,
        lengths=lengths,
        max_hours=args.max_hours,
    )
    return plan.to_dict() if args.json else plan.table()
