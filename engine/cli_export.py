"""Command-line pieces for messy and long logs and for exports (used by :mod:`engine.cli`).

* :func:`add_log_options` / :func:`log_kwargs`: ``--segment``, ``--scale``, ``--units``,
  ``--topic`` (passed to :func:`engine.io.load_log`) and ``--stream`` for ``gmwm wv``,
  ``fit`` and ``select``;
* :func:`stream_wv`: the WV of ``--stream`` (:func:`engine.wv.stream.wavelet_variance_stream`);
* :func:`add_export_parser` / :func:`cmd_export`: ``gmwm export``::

    gmwm export INPUT --model SPEC [--model-for CH=SPEC ...] [--channels a,b,...]
                --format kalibr|json|csv|datasheet|datasheet-csv -o OUT|-
                [--ci asymptotic|bootstrap] [--weights ci|identity|efficient]
                [--fs HZ] [--levels J] [--robust] [--segment ...] [--scale ...] [--units ...]
                [--topic T] [--stream] [--rostopic /imu0] [--partial] [--json]

Errors are raised as :class:`UsageError` (or the engine's ValueError subclasses), which
``gmwm`` prints as one line with exit status 2.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

__all__ = [
    "add_log_options",
    "log_kwargs",
    "stream_wv",
    "add_export_parser",
    "cmd_export",
    "UsageError",
]


class UsageError(ValueError):
    """A command-line usage error; ``gmwm`` prints it as one line and exits with status 2.

    A ValueError (which ``gmwm`` catches) rather than ``engine.cli.CliError``: under
    ``python -m engine.cli`` the CLI module runs as ``__main__`` and its CliError is another
    class than ``engine.cli.CliError``.
    """


def _cli_error(msg: str) -> Exception:
    return UsageError(msg)


def _float_map(opt: str) -> Any:
    def conv(text: str) -> float | dict[str, float]:
        def num(s: str) -> float:
            try:
                v = float(s)
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"{opt} takes a number or NAME=NUMBER pairs separated by commas, got {text!r}"
                ) from None
            if not math.isfinite(v) or v == 0:
                raise argparse.ArgumentTypeError(f"{opt} must be finite and non-zero, got {s!r}")
            return v

        if "=" not in text:
            return num(text)
        out = {}
        for part in text.split(","):
            k, sep, v = part.partition("=")
            if not sep or not k.strip():
                raise argparse.ArgumentTypeError(f"{opt}: {part!r} is not NAME=NUMBER")
            out[k.strip()] = num(v)
        return out

    return conv


def _str_map(text: str) -> str | dict[str, str]:
    if "=" not in text:
        return text.strip()
    out = {}
    for part in text.split(","):
        k, sep, v = part.partition("=")
        if not sep or not k.strip():
            raise argparse.ArgumentTypeError(f"--units: {part!r} is not NAME=UNIT")
        out[k.strip()] = v.strip()
    return out


def add_log_options(sp: argparse.ArgumentParser, *, stream: bool = True) -> None:
    """Add ``--segment --scale --units --topic`` (and ``--stream``) to a sub-command."""
    sp.add_argument(
        "--segment",
        choices=["stop", "longest", "report"],
        help="time column with gaps/duplicates: stop with a report (default), "
        "analyse the longest clean segment, or keep every sample (report)",
    )
    sp.add_argument(
        "--scale",
        type=_float_map("--scale"),
        help="scale factor for raw counts: 0.05, or gyro_x=0.05,accel_z=0.001",
    )
    sp.add_argument(
        "--units",
        type=_str_map,
        help="signal unit(s) overriding the file: deg/s, or gyro_x=deg/s,accel_x=g",
    )
    sp.add_argument("--topic", help="ROS bag: the sensor_msgs/Imu topic")
    if stream:
        sp.add_argument(
            "--stream",
            action="store_true",
            help="stream a .npy/HDF5 log larger than memory in blocks (classical WV)",
        )


def log_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The :func:`engine.io.load_log` keyword arguments given on the command line."""
    return {
        k: getattr(args, k)
        for k in ("segment", "scale", "units", "topic")
        if getattr(args, k, None) is not None
    }


def stream_wv(
    args: argparse.Namespace, alpha: float = 0.05, channel: str | None = None
) -> tuple[Any, str]:
    """``(WaveletVariance, channel name)`` of ``--stream``."""
    from .wv import open_series, wavelet_variance_stream

    if getattr(args, "robust", False):
        raise _cli_error(
            "--stream computes the classical WV; the robust WV needs the whole "
            "log in memory (drop --robust or --stream)"
        )
    for opt in ("segment", "topic"):
        if getattr(args, opt, None) is not None:
            raise _cli_error(
                f"--{opt} does not apply to --stream (streaming reads .npy/HDF5 "
                "samples as uniformly spaced)"
            )
    ch = channel if channel is not None else getattr(args, "channel", None)
    kw: dict[str, Any] = {}
    if ch is not None and str(ch).lstrip("-").isdigit() and str(args.input).endswith(".npy"):
        kw["column"] = int(ch)
    elif ch is not None:
        kw["dataset"] = str(ch)
    scale = getattr(args, "scale", None)
    if isinstance(scale, dict):
        scale = scale.get(str(ch))
    fs, side = args.fs, None
    if str(args.input).lower().endswith(".npy"):
        from .io import read_npy_sidecar

        side = read_npy_sidecar(args.input)  # `gmwm simulate -o x.npy` keeps fs and unit there
        if fs is None and side is not None and "fs_hz" in side:
            fs = float(side["fs_hz"])
    src = open_series(args.input, fs=fs, **kw)
    name = _loaded_name(args.input, src, side)
    if fs is None and src.fs is None:
        warn_fs_unknown(args, str(args.input))
    units = getattr(args, "units", None)
    unit = units.get(name, None) if isinstance(units, dict) else units
    if unit is None and side is not None and isinstance(side.get("units"), dict):
        unit = side["units"].get(name)
    wv = wavelet_variance_stream(
        src, fs=fs, levels=args.levels, scale=scale, alpha=alpha, unit=unit
    )
    if not np.any(wv.variance > 0):
        raise _cli_error(
            f"{args.input}: channel {name!r} is constant: there is no noise to analyse"
        )
    return wv, name


def warn_fs_unknown(args: argparse.Namespace, path: str) -> None:
    """Queue the loud stderr warning that the sampling frequency of ``path`` is unknown (1 Hz
    assumed); ``gmwm`` prints queued warnings with the result (an error stays one line)."""
    msg = (
        f"gmwm: warning: {path} does not say its sampling frequency: fs = 1 Hz ASSUMED, so "
        "every time in seconds and every datasheet value is per sample; pass --fs HZ"
    )
    queued = getattr(args, "warnings", None)
    if queued is None:
        queued = args.warnings = []
    if msg not in queued:
        queued.append(msg)


def _loaded_name(path: Any, src: Any, side: dict[str, Any] | None) -> str:
    """The name :func:`engine.io.load_log` gives the streamed channel, so that ``--stream``
    and the in-memory WV label it alike: for ``.npy`` the sidecar's channel name, else ``x``
    (1-D) or ``col<j>`` (2-D); for HDF5 the dataset name."""
    if not str(path).lower().endswith(".npy"):
        return src.name
    column = int(getattr(src, "column", 0) or 0)
    names = side.get("channels") if side is not None else None
    if isinstance(names, list) and len(names) == getattr(src, "k", 1) and column < len(names):
        return str(names[column])
    return "x" if np.load(path, mmap_mode="r").ndim == 1 else f"col{column}"


def _small_multipliers(spec: str, opt: str, limit: int = 100) -> str:
    """Refuse ``k*CODE`` with a huge k before the model is built (k copies of a process)."""
    import re

    for k in re.findall(r"(\d+)\s*\*|\*\s*(\d+)", spec):
        v = int(k[0] or k[1])
        if v > limit:
            raise _cli_error(
                f"{opt}: the multiplier {v} is too large (a model has at most "
                f"{limit} terms of a kind)"
            )
    return spec


def add_export_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``export`` sub-command to the ``gmwm`` sub-parsers."""
    from .cli import _positive
    from .export.registry import FORMATS

    ex = sub.add_parser(
        "export",
        help="fit channels and export Kalibr imu.yaml, a JSON report, "
        "WV curves (CSV) or a datasheet table",
    )
    ex.add_argument("input", help="log file: CSV/TSV/text, NPY/NPZ, HDF5, ROS bag, WV summary")
    ex.add_argument("--model", required=True, help="model for every channel, e.g. 'GM+WN+RW'")
    ex.add_argument(
        "--model-for",
        action="append",
        default=[],
        metavar="CH=SPEC",
        help="model of one channel (repeatable), e.g. gyro_z=2*GM+WN+RW",
    )
    ex.add_argument("--channels", help="channels separated by commas (default: all)")
    ex.add_argument(
        "--format",
        default="kalibr",
        choices=list(FORMATS),
        help="; ".join(f"{f.name}: {f.description}" for f in FORMATS.values())
        + " (default kalibr)",
    )
    ex.add_argument("-o", "--output", required=True, help="output file, or - for stdout")
    ex.add_argument("--fs", type=_positive(float, "--fs"), help="sampling frequency in Hz")
    ex.add_argument("--levels", type=_positive(int, "--levels"), help="number of WV levels J")
    ex.add_argument("--robust", action="store_true", help="robust (Tukey biweight) WV")
    ex.add_argument("--eff", type=float, default=0.6, help="robust WV efficiency (0.6)")
    ex.add_argument(
        "--weights",
        default="ci",
        choices=["ci", "identity", "efficient"],
        help="weighting matrix: ci (default), identity, or efficient (two-step, V^-1)",
    )
    ex.add_argument("--ci", choices=["asymptotic", "bootstrap"], help="parameter intervals")
    ex.add_argument("--level", type=float, default=0.95, help="interval level (0.95)")
    ex.add_argument(
        "-B",
        "--bootstrap",
        type=_positive(int, "-B"),
        default=100,
        help="bootstrap replicates for --ci bootstrap (100)",
    )
    ex.add_argument("--seed", type=int, default=0, help="bootstrap seed (0)")
    ex.add_argument(
        "--workers",
        type=_positive(int, "--workers"),
        default=2,
        help="processes for the bootstrap (2)",
    )
    ex.add_argument("--rostopic", default="/imu0", help="Kalibr rostopic entry (/imu0)")
    ex.add_argument(
        "--partial",
        action="store_true",
        help="Kalibr: allow a file with only gyroscope or only accelerometer keys",
    )
    ex.add_argument("--json", action="store_true", help="print one JSON object (what was written)")
    add_log_options(ex)
    return ex


def cmd_export(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run ``gmwm export``; returns the text to print (or a JSON-ready dict)."""
    from .export import export
    from .fit import fit_gmwm
    from .inference import fit_efficient, param_intervals
    from .io import load_log, pick_channel
    from .models import parse_model
    from .wv import wavelet_variance

    if not 0 < args.level < 1:
        raise _cli_error(f"--level must be in (0, 1), got {args.level}")
    if args.robust and not 0 < args.eff < 0.99:
        raise _cli_error(f"--eff must be in (0, 0.99), got {args.eff}")
    model = parse_model(_small_multipliers(args.model, "--model"))
    per: dict[str, Any] = {}
    for item in args.model_for:
        ch, sep, spec = item.partition("=")
        if not sep or not ch.strip():
            raise _cli_error(f"--model-for takes CH=SPEC, got {item!r}")
        per[ch.strip()] = parse_model(_small_multipliers(spec, "--model-for"))
    wanted = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
    log = None
    wvs: dict[str, Any] = {}
    if args.stream:
        if not wanted:
            raise _cli_error("--stream needs --channels (dataset names or .npy columns)")
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
            if log.is_summary:
                if ch not in log.wv:
                    raise _cli_error(
                        f"{args.input} has no channel {ch!r}; channels: {', '.join(log.names)}"
                    )
                if args.robust:
                    raise _cli_error(
                        f"{args.input}: a WV summary file holds a fixed WV; "
                        "--robust needs the raw log"
                    )
                wv = log.wv[ch]
                if args.levels is not None:
                    if args.levels > wv.n_levels:
                        raise _cli_error(
                            f"--levels {args.levels} is too many: {ch} has {wv.n_levels} levels"
                        )
                    wv = wv.truncate(args.levels)
            else:
                x = log[ch]
                if np.ptp(x) == 0:
                    raise _cli_error(
                        f"{args.input}: channel {ch!r} is constant: there is no noise to analyse"
                    )
                wv = wavelet_variance(
                    x,
                    fs=log.fs,
                    levels=args.levels,
                    robust=args.robust,
                    eff=args.eff,
                    unit=log.units.get(ch, ""),
                )
            wvs[ch] = wv
    unknown = [c for c in per if c not in wvs]
    if unknown:
        raise _cli_error(
            f"--model-for names unknown channel(s) {unknown}; channels: {', '.join(wvs)}"
        )
    fits, intervals = {}, {}
    for ch, wv in wvs.items():
        m = per.get(ch, model)
        fits[ch] = (
            fit_efficient(wv, m)
            if args.weights == "efficient"
            else fit_gmwm(wv, m, weights=args.weights)
        )
        if args.ci:
            intervals[ch] = param_intervals(
                fits[ch],
                method=args.ci,
                level=args.level,
                B=args.bootstrap,
                seed=args.seed,
                workers=args.workers,
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
        rostopic=args.rostopic,
        allow_partial=args.partial,
    )
    if out is None:
        return text.rstrip("\n")
    if args.json:
        return {
            "output": out,
            "format": args.format,
            "channels": list(fits),
            "models": {ch: r.model.spec(values=True) for ch, r in fits.items()},
        }
    return f"wrote {args.format} export of {len(fits)} channel(s) ({', '.join(fits)}) to {out}"
