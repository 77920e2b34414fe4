"""``gmwm virtual`` (:func:`add_parser`, :func:`run`): the optimal virtual sensor::

    gmwm virtual LOG... --model SPEC [--shared WN,RW,...] [--channel NAME | --channels a,b,..]
                 [--tau S | --band S1:S2] [--absolute] [--weights ci|identity|efficient]
                 [--fs HZ] [--levels J] [--units U] [--confidence 0.95]
                 [--format NAME -o OUT|-] [--name CH] [--json]

k sensors of one axis: several LOG files (one sensor each, channel ``--channel``, cut to the
shortest) or one LOG with ``--channels`` (recorded together). The multivariate model
(``--model`` for every sensor, ``--shared`` processes with a k x k covariance) is fitted by
:func:`engine.fit_mgmwm`, then :func:`engine.virtual_sensor` gives the weights (sum 1) that
minimise the WV at the scale ``--tau`` (seconds) or over ``--band`` (default: every level, each
relative to the plain average's WV; ``--absolute``: the plain sum). ``--format`` exports the
virtual sensor's model as one channel (``--name``, default the sensors' common channel
name), like ``gmwm export``. ``--scale`` (the scale in seconds, before ``--scale`` meant the
counts factor everywhere) and ``--alpha`` are deprecated spellings of ``--tau`` and
``--confidence``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import (
    add_confidence_option,
    add_deprecated_alias,
    add_weights_option,
    add_wv_options,
    alpha_of,
    check_output,
    input_paths,
    positive,
    queue_warning,
    usage_error,
    warn_fs_unknown,
)

__all__ = ["add_parser", "run"]


def _band(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(":")
    try:
        if not sep:
            raise ValueError
        a, b = float(lo), float(hi)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--band takes S1:S2 in seconds, e.g. 1:100, got {text!r}"
        ) from None
    if not (0 < a <= b < float("inf")):
        raise argparse.ArgumentTypeError(f"--band needs 0 < S1 <= S2, got {text!r}")
    return a, b


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``virtual`` sub-command to the ``gmwm`` sub-parsers."""
    from ..formats.catalog import FORMATS

    vp = sub.add_parser("virtual")
    vp.add_argument(
        "inputs",
        nargs="+",
        metavar="LOG",
        help="one log per sensor (with --channel), or one log with --channels",
    )
    vp.add_argument("--model", required=True, help="model of every sensor, e.g. 'GM+WN+RW'")
    vp.add_argument("--shared", help="processes shared by the sensors, e.g. WN,RW,GM")
    add_weights_option(
        vp, "weighting matrix of the MGMWM: ci (default), identity, or efficient (two-step, V^-1)"
    )
    vp.add_argument("--channel", help="several LOGs: the channel of each (default: the first)")
    vp.add_argument("--channels", help="one LOG: its sensors' channels, e.g. gyro_a,gyro_b")
    target = vp.add_mutually_exclusive_group()
    tau = target.add_argument(
        "--tau",
        type=positive(float, "--tau"),
        metavar="S",
        help="minimise the WV at the scale tau = S seconds",
    )
    add_deprecated_alias(target, "--scale", tau, type=positive(float, "--scale"))
    target.add_argument(
        "--band", type=_band, help="minimise the WV over the scales S1:S2 (s); default all"
    )
    vp.add_argument(
        "--absolute",
        action="store_true",
        help="band: sum the WVs plainly (default: each relative to the average's WV)",
    )
    add_wv_options(vp)
    vp.add_argument("--units", help="signal unit overriding the files', e.g. deg/s")
    add_confidence_option(vp, "the virtual sensor's WV interval", "--alpha")
    vp.add_argument(
        "--format",
        choices=list(FORMATS),
        help="export format of the virtual sensor's model (as gmwm export; needs -o)",
    )
    vp.add_argument("-o", "--output", help="--format: output file, or - for stdout (checked first)")
    vp.add_argument("--name", help="--format: the virtual channel's name (e.g. gyro_x)")
    vp.add_argument("--json", action="store_true", help="print one JSON object")
    return vp


def _load(args: argparse.Namespace) -> tuple[dict[str, Any], float, str, list[str], str]:
    """``(series by sensor name, fs, unit, notes, the virtual channel's default name)``."""
    import numpy as np

    from ..io import load_log

    files = list(args.inputs)
    notes: list[str] = []
    if args.channels:
        if len(files) > 1:
            raise usage_error(
                "--channels takes one LOG (sensors recorded together); several LOGs are "
                "one sensor each (use --channel)"
            )
        if args.channel:
            raise usage_error("give --channel (several LOGs) or --channels (one LOG), not both")
        names = [c.strip() for c in args.channels.split(",") if c.strip()]
        log = load_log(files[0], fs=args.fs)
        if log.is_summary:
            raise usage_error(f"{files[0]} is a WV summary file: the sensors' raw series needed")
        if log.fs_source == "default":
            warn_fs_unknown(args, str(files[0]))
        unknown = [c for c in names if c not in log.channels]
        if unknown:
            raise usage_error(
                f"{files[0]}: unknown channel(s) {', '.join(unknown)}; the channels are "
                f"{', '.join(log.channels)}"
            )
        data = {c: log[c] for c in names}
        units = {log.units.get(c, "") for c in names}
        fs, base = log.fs, "virtual"
    else:
        if len(files) < 2:
            raise usage_error(
                "give several LOGs (one sensor each) or one LOG with --channels a,b,..: a "
                "virtual sensor needs at least 2 sensors"
            )
        data, units, rates, chans = {}, set(), set(), set()
        for f in files:
            log = load_log(f, channel=args.channel, fs=args.fs)
            if log.is_summary:
                raise usage_error(f"{f} is a WV summary file: the sensor's raw series needed")
            if log.fs_source == "default":
                warn_fs_unknown(args, str(f))
            ch = log.names[0]
            chans.add(ch)
            name = Path(f).stem
            while name in data:
                name += "'"
            data[name] = log[ch]
            units.add(log.units.get(ch, ""))
            rates.add(float(log.fs))
        if len(rates) > 1:
            raise usage_error(
                "the LOGs have different sampling rates ("
                + ", ".join(f"{r:g}" for r in sorted(rates))
                + " Hz): the sensors must be sampled alike"
            )
        fs = rates.pop()
        base = chans.pop() if len(chans) == 1 else "virtual"
        lengths = {k: v.size for k, v in data.items()}
        n = min(lengths.values())
        if len(set(lengths.values())) > 1:
            notes.append(f"the LOGs are cut to the shortest, {n} samples")
        data = {k: np.asarray(v[:n], float) for k, v in data.items()}
    if args.units:
        unit = args.units
    elif len(units) == 1:
        unit = units.pop()
    else:
        raise usage_error(
            f"the sensors have different units ({', '.join(sorted(units))}); give --units"
        )
    return data, fs, unit, notes, base


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm virtual``; returns the text to print (or a JSON-ready dict)."""
    if args.format and not args.output:
        raise usage_error("--format needs -o OUT (a file, or - for stdout)")
    if args.output and not args.format:
        raise usage_error("-o needs --format NAME (the export format of the virtual sensor)")
    # before the (slow) imports and the fit:
    check_output(args.output, "-o", inputs=input_paths(args))
    from .._jsonutil import json_ready
    from ..multivariate import MultiModel, fit_mgmwm, virtual_sensor
    from ..wv import wv_matrix

    data, fs, unit, notes, base = _load(args)
    names = list(data)
    wvm = wv_matrix(data, channels=names, fs=fs, levels=args.levels, units=[unit] * len(names))
    model = MultiModel(names, args.model, shared=args.shared or ())
    res = fit_mgmwm(wvm, model, weights=args.weights)
    vs = virtual_sensor(
        res,
        scale=args.tau,
        band=args.band,
        relative=not args.absolute,
        alpha=alpha_of(args.confidence),
    )
    for w in vs.warnings:  # the fit's and the virtual model's (e.g. a GM faster than one sample)
        queue_warning(args, w)
    exported = None
    if args.format:
        from ..formats import FORMATS, export

        name = args.name or base
        out = None if args.output == "-" else args.output
        text = export(
            out,
            {name: vs.as_fit()},
            args.format,
            units={name: unit} if unit else None,
            source=", ".join(str(f) for f in args.inputs),
            # one axis: a Kalibr file with only its sensor's keys
            allow_partial=FORMATS[args.format].takes("allow_partial"),
        )
        if out is None:
            return text.rstrip("\n")
        exported = {"output": out, "format": args.format, "channel": name}
    if args.json:
        d = vs.to_dict()
        d["inputs"] = list(args.inputs)
        d["fit"] = {"model": model.spec(), "objective": res.objective, "converged": res.converged}
        if exported:
            d["export"] = exported
        if notes:
            d["notes"] = notes
        return json_ready(d)
    head = [
        f"{', '.join(str(f) for f in args.inputs)}: {len(names)} sensors, N = {wvm.n}, "
        f"fs = {fs:g} Hz",
        f"MGMWM fit of {model.spec()}: objective {res.objective:.4g}"
        + ("" if res.converged else " (not converged)"),
        *notes,
    ]
    tail = (
        [
            f"wrote {exported['format']} export of the virtual sensor ({exported['channel']}) to "
            f"{exported['output']}"
        ]
        if exported
        else []
    )
    return "\n".join([*head, vs.table(), *tail])
