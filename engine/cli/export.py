"""``gmwm export`` (:func:`add_parser`, :func:`run`)::

    gmwm export INPUT --model SPEC [--model-for CH=SPEC ...] [--channels a,b,...]
                --format NAME (engine.formats.FORMATS) -o OUT|-
                [--ci asymptotic|bootstrap [--confidence 0.95]] [--weights ci|identity|efficient]
                [--fs HZ] [--levels J] [--robust] [--segment ...] [--scale ...] [--units ...]
                [--topic T] [--stream] [--rostopic /imu0] [--partial] [--json]
                [--inflate F] [--filter-rate HZ] [--projection bound|plain|fit]
                [--horizon S] [--bound-band S1:S2] [--bound-confidence C] [--no-intervals]
                [--bound-data low|estimate|high|none] [--no-tails]
                [--vehicle-id ID] [--scale-factor-std PPM] [--consumer NAME ...]

The log options and the streamed WV are shared with the other subcommands
(:mod:`engine.cli.common`). Errors are raised as :class:`~engine.cli.common.UsageError` (or the
engine's ValueError subclasses), which ``gmwm`` prints as one line with exit status 2.
"""

from __future__ import annotations

import argparse
import textwrap
from typing import Any

from ..formats.catalog import FORMATS
from .common import (
    ARGUMENT_FLAGS,
    CHANNELS_HELP,
    INPUT_HELP,
    add_bootstrap_options,
    add_confidence_option,
    add_log_options,
    add_weights_option,
    add_wv_options,
    bootstrap_kwargs,
    check_output,
    confidence,
    input_paths,
    log_kwargs,
    positive,
    stream_wv,
    usage_error,
    warn_fs_unknown,
)

__all__ = ["add_parser", "run", "format_options_help"]


def _small_multipliers(spec: str, opt: str, limit: int = 100) -> str:
    """Refuse ``k*CODE`` with a huge k before the model is built (k copies of a process)."""
    import re

    for k in re.findall(r"(\d+)\s*\*|\*\s*(\d+)", spec):
        v = int(k[0] or k[1])
        if v > limit:
            raise usage_error(
                f"{opt}: the multiplier {v} is too large (a model has at most "
                f"{limit} terms of a kind)"
            )
    return spec


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``export`` sub-command to the ``gmwm`` sub-parsers."""
    ex = sub.add_parser(
        "export", epilog=format_options_help(), formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ex.add_argument("input", help=INPUT_HELP)
    ex.add_argument("--model", required=True, help="model for every channel, e.g. 'GM+WN+RW'")
    ex.add_argument(
        "--model-for",
        action="append",
        default=[],
        metavar="CH=SPEC",
        help="model of one channel (repeatable), e.g. gyro_z=2*GM+WN+RW",
    )
    ex.add_argument("--channels", help=CHANNELS_HELP)
    ex.add_argument(
        "--format",
        default="kalibr",
        choices=list(FORMATS),
        help="export format: "
        + "; ".join(f"{f.name}: {f.description}" for f in FORMATS.values())
        + " (default kalibr)",
    )
    ex.add_argument(
        "-o", "--output", required=True, help="output file, or - for stdout (checked first)"
    )
    add_wv_options(ex, robust=True)
    add_weights_option(ex)
    ex.add_argument("--ci", choices=["asymptotic", "bootstrap"], help="parameter intervals")
    add_confidence_option(ex, "the --ci parameter intervals", "--level")
    add_bootstrap_options(ex, replicates="bootstrap replicates for --ci bootstrap")
    ex.add_argument(
        "--rostopic",
        help="rostopic entry of Kalibr/OpenVINS files (default: the bag's IMU topic when a "
        "bag was loaded, else /imu0)",
    )
    ex.add_argument(
        "--inflate",
        type=positive(float, "--inflate"),
        default=1.0,
        help="filter formats: multiply every noise value by this factor (variances by its "
        "square), written in the file's header (default 1: the fitted values)",
    )
    add_filter_rate_option(ex)
    ex.add_argument(
        "--projection",
        choices=["bound", "plain", "fit"],
        default="bound",
        help="filter formats: bound (default) projects each fit onto the consumer's noise "
        "model and over-bounds its WV from the filter step to the horizon with the least "
        "inflation; plain: the projection rule alone; fit: the fit's own terms, one by one "
        "(the JSON report: its projections, none with fit)",
    )
    ex.add_argument(
        "--consumer",
        action="append",
        metavar="NAME",
        help="JSON report: project each fit onto this consumer noise model (WN+RW, WN+GM, WN) "
        "or filter format's (kalibr, kf-gins ...), with each value's interval and factor; "
        "repeat for several (default: WN+RW)",
    )
    add_horizon_option(ex)
    ex.add_argument(
        "--bound-data",
        choices=["low", "estimate", "high", "none"],
        default="low",
        help="filter formats: the bound also covers the empirical WV at its scales in the "
        "band: low (default) the lower limit of its 95 %% interval, estimate the WV itself, "
        "high its upper limit, none the fitted model alone",
    )
    ex.add_argument(
        "--no-tails",
        action="store_true",
        help="filter formats: the data bound without its tail factors (by default the bound's "
        "variance covers the data's 99.9 %% quantile at each scale, not only its variance: "
        "docs/filters.md, Tails)",
    )
    ex.add_argument(
        "--bound-band",
        metavar="S1:S2",
        help="filter formats: the WV scales S1:S2 (s) the bound covers (default: two filter "
        "steps to the horizon)",
    )
    ex.add_argument(
        "--bound-confidence",
        type=confidence("--bound-confidence"),
        metavar="C",
        help="filter formats: bound the upper limit of the fitted WV's interval at this "
        "confidence level (e.g. 0.95) instead of the WV itself",
    )
    ex.add_argument(
        "--no-intervals",
        action="store_true",
        help="filter formats: skip the 95 %% intervals of the exported values (faster)",
    )
    ex.add_argument(
        "--vehicle-id",
        type=positive(int, "--vehicle-id"),
        default=1,
        help="px4: the MAVLink system id of the .params lines (default 1)",
    )
    ex.add_argument(
        "--scale-factor-std",
        type=positive(float, "--scale-factor-std"),
        help="kf-gins: gsstd/asstd in ppm (not identified by GMWM; default 1000)",
    )
    ex.add_argument(
        "--partial",
        action="store_true",
        help=partial_help(),
    )
    ex.add_argument("--json", action="store_true", help="print one JSON object (what was written)")
    add_log_options(ex)
    return ex


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm export``; returns the text to print (or a JSON-ready dict)."""
    # before the (slow) imports and any fit:
    check_output(args.output, "-o", inputs=input_paths(args))
    from ..fit import fit_gmwm
    from ..formats import export
    from ..formats.projection import misfit
    from ..inference import param_intervals
    from ..io import load_log, pick_channel
    from ..models import parse_model

    band = None
    if args.bound_band:
        try:
            band = tuple(float(v) for v in args.bound_band.replace(",", ":").split(":"))
        except ValueError:
            band = ()
        if len(band) != 2 or not 0 < band[0] <= band[1]:
            raise usage_error(
                f"--bound-band takes S1:S2 in seconds with 0 < S1 <= S2, got {args.bound_band!r}"
            )
    if args.robust and not 0 < args.eff < 0.99:
        raise usage_error(f"--eff must be in (0, 0.99), got {args.eff}")
    model = parse_model(_small_multipliers(args.model, "--model"))
    per: dict[str, Any] = {}
    for item in args.model_for:
        ch, sep, spec = item.partition("=")
        if not sep or not ch.strip():
            raise usage_error(f"--model-for takes CH=SPEC, got {item!r}")
        per[ch.strip()] = parse_model(_small_multipliers(spec, "--model-for"))
    wanted = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
    log = None
    wvs: dict[str, Any] = {}
    if args.stream:
        if not wanted:
            raise usage_error("--stream needs --channels (dataset names or .npy columns)")
        for ch in wanted:
            wv, _ = stream_wv(args, channel=ch)
            wvs[ch] = wv
    else:
        log = load_log(args.input, fs=args.fs, **log_kwargs(args))
        if log.fs_source == "default":
            warn_fs_unknown(args, str(args.input))
        names = (
            [pick_channel(str(args.input), log.names, c) for c in wanted] if wanted else log.names
        )
        for ch in names:
            wvs[ch] = log.wavelet_variance(ch, robust=args.robust, eff=args.eff, levels=args.levels)
    unknown = [c for c in per if c not in wvs]
    if unknown:
        raise usage_error(
            f"--model-for names unknown channel(s) {unknown}; channels: {', '.join(wvs)}"
        )
    fits, intervals = {}, {}
    for ch, wv in wvs.items():
        m = per.get(ch, model)
        fits[ch] = fit_gmwm(wv, m, weights=args.weights)
        if args.ci:
            intervals[ch] = param_intervals(
                fits[ch],
                method=args.ci,
                level=args.confidence,
                **bootstrap_kwargs(args),
            )
    units = (
        args.units
        if isinstance(args.units, dict)
        else (dict.fromkeys(fits, args.units) if args.units else None)
    )
    out = None if args.output == "-" else args.output
    text = export(
        out,
        fits,
        args.format,
        intervals=intervals or None,
        log=log,
        units=units,
        source=str(args.input),
        rostopic=args.rostopic,  # default: the bag's IMU topic, else /imu0 (engine.export)
        allow_partial=args.partial,
        inflate=args.inflate,
        filter_rate=args.filter_rate,
        projection=args.projection,
        horizon_s=args.horizon,
        band=band,
        confidence=args.bound_confidence,
        ci=None if args.no_intervals else "asymptotic",
        vehicle_id=args.vehicle_id,
        scale_factor_std_ppm=args.scale_factor_std,
        consumers=args.consumer,
        data=args.bound_data,
        tails=not args.no_tails,
    )
    disagree = [line for ch, r in fits.items() if (line := misfit(r, ch))]
    if out is None:
        return text.rstrip("\n")
    if args.json:
        return {
            "output": out,
            "format": args.format,
            "channels": list(fits),
            "models": {ch: r.model.spec(values=True) for ch, r in fits.items()},
            "misfit": disagree,
        }
    return "\n".join(
        [
            f"wrote {args.format} export of {len(fits)} channel(s) ({', '.join(fits)}) to {out}",
            *(f"  warning: {line}" for line in disagree),
        ]
    )


def sensors_words(f: Any) -> str:
    """What ``gmwm export --help`` says of the sensors a format's file needs, from its record
    (:attr:`engine.formats.Format.partial`, :attr:`~engine.formats.Format.needs_both_sensors`);
    empty for a report."""
    if f.needs_both_sensors:
        return "; needs a gyroscope and an accelerometer"
    if f.partial:
        return "; one sensor is enough (a partial file)"
    if f.is_filter:  # takes allow_partial
        return "; one sensor with --partial"
    return ""


def partial_help() -> str:
    """The help of ``--partial``: the formats that take it and those that write a partial file
    without it, from the records."""
    takes = [f.name for f in FORMATS.values() if f.is_filter and f.takes("allow_partial")]
    always = [f.name for f in FORMATS.values() if f.is_filter and f.partial]
    return (
        f"{', '.join(takes)}: allow a file with only gyroscope or only accelerometer values "
        f"({', '.join(always)} write one without it; the other filter formats need both)"
    )


def format_options_help() -> str:
    """The epilog of ``gmwm export --help``: the options each format reads, from the format
    records (:attr:`engine.formats.Format.options`), in the command's flags."""
    filt = [f for f in FORMATS.values() if f.is_filter]
    common = [o for o in filt[0].options if all(o in f.options for f in filt)]

    def flags(options: Any) -> str:  # fleet is gmwm batch --export's
        return " ".join(ARGUMENT_FLAGS[o] for o in options if o != "fleet")

    lines = [
        "options by format (besides the log, model and fit options):",
        *textwrap.wrap(
            f"the filter formats: {flags(common)}",
            88,
            initial_indent="  ",
            subsequent_indent="    ",
        ),
    ]
    for f in FORMATS.values():
        own = [o for o in f.options if not (f.is_filter and o in common)]
        said = ("the filter options" + (" and " if own else "")) if f.is_filter else ""
        said += flags(own) if own else ("" if f.is_filter else "none")
        if f.needs_filter_rate:
            said += "; --filter-rate required"
        said += sensors_words(f)
        if f.fleet_file:
            said += "; a fleet file with gmwm batch --export"
        lines += textwrap.wrap(
            f"{f.name}: {said}",
            88,
            initial_indent="  ",
            subsequent_indent="    ",
            break_on_hyphens=False,
        )
    lines.append("an option given that the format does not read is ignored, with a warning")
    return "\n".join(lines)


def add_filter_rate_option(group: Any, when: str = "") -> None:
    """``--filter-rate HZ``: the rate the consumer's filter predicts at (the formats that need
    it are read from their records); ``when`` prefixes the help (``"with --export: "``)."""
    group.add_argument(
        "--filter-rate",
        type=positive(float, "--filter-rate"),
        help=when
        + "/".join(f.name for f in FORMATS.values() if f.needs_filter_rate)
        + ": the rate (Hz) the EKF predicts at (required by those formats)",
    )


def add_horizon_option(group: Any, when: str = "", default: str = "the log length") -> None:
    """``--horizon S``: the longest time the filter runs without aiding, the longest WV scale
    the export's bound covers; ``when`` prefixes the help, ``default`` names the default."""
    group.add_argument(
        "--horizon",
        type=positive(float, "--horizon"),
        help=f"{when}the longest time (s) your filter runs without aiding (a GNSS outage, a "
        f"visual dropout): the longest WV scale the bound covers, and the tail factors apply "
        f"from a quarter of it (advised: 4 aiding intervals; default: {default}, the tail "
        "factors at every scale)",
    )
