"""What the ``gmwm`` subcommands share: the user-error types, argument converters, the log
options (``--segment --scale --units --topic --stream``), the loading of one channel's WV, the
output check run before any work (:func:`check_output`), sample counts (:func:`sample_count`),
the options every fitting sub-command takes (:data:`INPUT_HELP`, :data:`CHANNELS_HELP`,
:func:`add_wv_options`, :func:`add_weights_option`), the confidence option
(:func:`add_confidence_option`), deprecated spellings of options (:func:`add_deprecated_alias`)
and the queue of one-line warnings (:func:`queue_warning`)."""

from __future__ import annotations

import argparse
import glob
import math
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .._checks import check_fs
from .._files import check_not_input
from .._limits import check_replicates, check_sample_count
from ..errors import CliError, UsageError
from ..formats.common import text_lines
from ..wv import WaveletVariance

__all__ = [
    "ARGUMENT_FLAGS",
    "add_check_options",
    "say",
    "checked_log",
    "temperature_fit",
    "without_compensation",
    "cli_text",
    "CliError",
    "UsageError",
    "usage_error",
    "positive",
    "INPUT_HELP",
    "CHANNELS_HELP",
    "WEIGHTS_HELP",
    "add_log_options",
    "add_wv_options",
    "add_weights_option",
    "add_bootstrap_options",
    "bootstrap_kwargs",
    "log_kwargs",
    "stream_wv",
    "warn_fs_unknown",
    "load_wv",
    "check_output",
    "sample_count",
    "confidence",
    "add_confidence_option",
    "alpha_of",
    "add_deprecated_alias",
    "queue_warning",
    "terminal_text",
    "input_paths",
    "DeprecatedAlias",
]


#: The engine's keyword arguments and the ``gmwm`` options that set them: the one mapping by
#: which the CLI words an engine message (which names arguments, ``units=``) in its flags.
ARGUMENT_FLAGS: dict[str, str] = {
    "units": "--units",
    "inflate": "--inflate",
    "scheduler": "--scheduler",
    "filter_rate": "--filter-rate",
    "allow_partial": "--partial",
    "channel": "--channel",
    "dataset": "--channel",
    "segment": "--segment",
    "topic": "--topic",
    "spec": "--spec",
    "static": "--static",
    "levels": "--levels",
    "robust": "--robust",
    "segments": "--segments",
    "drop_warmup": "--drop-warmup",
    "temperature": "--temperature",
    # gmwm export's options (engine.formats.ExportOptions); "--no-" flags take no value
    "rostopic": "--rostopic",
    "projection": "--projection",
    "horizon_s": "--horizon",
    "band": "--bound-band",
    "confidence": "--bound-confidence",
    "ci": "--no-intervals",
    "data": "--bound-data",
    "tails": "--no-tails",
    "vehicle_id": "--vehicle-id",
    "scale_factor_std_ppm": "--scale-factor-std",
    "consumers": "--consumer",
}

_ARGUMENT = re.compile(
    r"(?<![\w.])(" + "|".join(ARGUMENT_FLAGS) + r")="
    r"(\{[^}]*\}|'[^']*'|\"[^\"]*\"|\([^)]*\)|[^\s,;:)]*)"
)


def _flag(m: re.Match[str]) -> str:
    flag, value = ARGUMENT_FLAGS[m.group(1)], m.group(2)
    if value in ("", "...", "True") or flag.startswith("--no-"):  # tails=False: --no-tails
        return flag
    if value.startswith("("):  # a Python tuple (segment=(start, stop)): no CLI form
        return m.group(0)
    if value.startswith("{"):  # units={'gyro_x': 'deg/s'} -> --units gyro_x=deg/s
        pairs = re.findall(r"['\"]([^'\"]*)['\"]\s*:\s*['\"]([^'\"]*)['\"]", value)
        return f"{flag} " + ",".join(f"{k}={v}" for k, v in pairs) if pairs else flag
    inner = value.strip(chr(39) + chr(34))
    return f"{flag} {value if inner.split() != [inner] else inner}"  # quotes kept around spaces


def cli_text(message: str) -> str:
    """An engine message in the words of the ``gmwm`` command: ``levels=30`` -> ``--levels
    30``, ``allow_partial=True`` -> ``--partial``, ``units={'gyro_x': 'deg/s'}`` -> ``--units
    gyro_x=deg/s`` (:data:`ARGUMENT_FLAGS`)."""
    return _ARGUMENT.sub(_flag, message)


def terminal_text(text: str) -> str:
    """``text`` as it may reach a terminal: every control character but the line breaks
    escaped (``\x1b`` for ESC), so that a channel or file name such as ``"\x1b]0;pwned\x07"``
    cannot retitle, recolour or rewrite the user's terminal
    (:func:`engine.formats.common.clean_text`, line by line)."""
    return text_lines(text.split("\n"), end="")


def positive(kind: type[int] | type[float], name: str) -> Callable[[str], float]:
    def conv(text: str) -> float:
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"{name} must be > 0, got {text!r}")
        if name == "--fs":  # the engine's range (engine._checks)
            try:
                check_fs(v, name)
            except ValueError as e:
                raise argparse.ArgumentTypeError(str(e)) from None
        return v

    return conv


def load_wv(
    args: argparse.Namespace, alpha: float = 0.05, *, check: bool = False, label: str = ""
) -> tuple[WaveletVariance, str]:
    """The WV of the selected channel (computed, or read from a summary file).

    With ``check`` (``gmwm fit``, ``gmwm select``): the log check runs first
    (:func:`checked_log`), and with a temperature channel (``--temperature``) the WV is that
    of the compensated signal; the check and the temperature fit are left on ``args``
    (``qualification``, ``temperature_fit``). ``label`` starts the lines said on stderr (the
    file's name, when a command reads several).
    """
    from ..io import load_log

    if getattr(args, "stream", False):  # long logs: blocks from .npy/HDF5, bounded memory
        if check:
            say(args, "log check: skipped with --stream (the log is not held in memory)")
        return stream_wv(args, alpha)
    log = load_log(args.input, channel=args.channel, fs=args.fs, **log_kwargs(args))
    name = log.names[0]
    if check:
        log, args.qualification = checked_log(args, log, [name], label=label)
        args.temperature_fit = temperature_fit(args, log, name, alpha=alpha, label=label)
        if args.temperature_fit is not None:
            if not log.is_summary and log.fs_source == "default":
                warn_fs_unknown(args, args.input)
            return args.temperature_fit.wv, name
    wv = log.wavelet_variance(
        name, robust=args.robust, eff=args.eff, levels=args.levels, alpha=alpha
    )
    if not log.is_summary and log.fs_source == "default":
        warn_fs_unknown(args, args.input)
    return wv, name


def add_check_options(sp: argparse.ArgumentParser, *, temperature: bool = True) -> None:
    """Add ``--drop-warmup`` (and ``--temperature``) to a sub-command that fits a log."""
    sp.add_argument(
        "--drop-warmup",
        action="store_true",
        help="drop the warm-up the log check finds (the samples before its suggested start) "
        "before the fit",
    )
    if temperature:
        sp.add_argument(
            "--temperature",
            default="auto",
            metavar="auto|none|COLUMN",
            help="temperature channel whose bias-temperature polynomial is fitted and removed "
            "before the GMWM: auto (default: a channel named like temp/temperature, if any, "
            "removed only when its sensitivity's interval excludes 0), none, or its name "
            "(always removed)",
        )


def say(args: argparse.Namespace, msg: str) -> None:
    """Print one line on stderr now, as ``gmwm COMMAND: MSG`` in the command's words."""
    print(terminal_text(f"gmwm {args.command}: {cli_text(msg)}"), file=sys.stderr)


def checked_log(
    args: argparse.Namespace, log: Any, channels: list[str] | None = None, *, label: str = ""
) -> tuple[Any, Any]:
    """Run the log check (:func:`engine.io.qualify_log`) on a loaded log, drop the warm-up
    with ``--drop-warmup``, and say what was found in one line on stderr (nothing for a
    clean log), after ``label`` (the file's name when a command reads several).

    Returns
    -------
    (ImuLog, Qualification)
        The log (without its warm-up with ``--drop-warmup``) and the check of that log.
    """
    from ..io import drop_warmup, qualify_log

    q = qualify_log(log, channels)
    if getattr(args, "drop_warmup", False) and q.suggested_start:
        log = drop_warmup(log, q.suggested_start)
        q = qualify_log(log, channels)
    if q.findings or q.dropped:  # a clean log is not worth a line (the JSON has the check)
        say(args, label + q.line())
    return log, q


def temperature_fit(
    args: argparse.Namespace,
    log: Any,
    name: str,
    *,
    alpha: float = 0.05,
    model: Any = None,
    label: str = "",
) -> Any:
    """The temperature compensation of channel ``name`` (``--temperature``,
    :func:`engine.inference.temperature.fit_log_temperature`), said in one line on stderr; None
    when the log has no temperature channel (or is a summary). With ``--temperature auto`` the
    signal is compensated only when the data show an effect (the line says when it is not); a
    channel named is always compensated. A log cut into segments is fitted on them, each with
    its own offset."""
    from ..inference.temperature import find_temperature, fit_log_temperature

    choice = getattr(args, "temperature", "none") or "none"
    tname = None if log.is_summary else find_temperature(log, choice, channel=name)
    try:
        tf = fit_log_temperature(
            log,
            name,
            tname or "none",
            compensate="auto" if choice == "auto" else True,
            model=model,
            levels=args.levels,
            robust=getattr(args, "robust", False),
            eff=getattr(args, "eff", 0.6),
            alpha=alpha,
            weights=getattr(args, "weights", None) or "ci",
        )
    except ValueError as e:
        if choice != "auto":
            raise
        say(args, f"{label}temperature: '{tname}' not used ({e})")  # too short, constant ...
        return None
    if tf is not None:
        say(args, label + cli_text(tf.line()))
    return tf


def without_compensation(what: str, raw: Any) -> str:
    """The line under a fit of temperature-compensated signals (``what``: "the compensated
    signal", "the temperature-compensated gyro_x, gyro_y") that gives the fit of the raw
    signals beside it (``raw``: a fit of the same model to them)."""
    return f"the fit above is of {what}; without compensation: {raw.model.spec(values=True)}"


def usage_error(msg: str) -> Exception:
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
        "--segments",
        metavar="auto|LIST",
        help="analyse only these parts of a flight log: auto (its still segments, see "
        "`gmwm segments`) or START:STOP sample ranges, e.g. 0:5000,8000:12000; their "
        "wavelet variances are pooled",
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
    sp.add_argument(
        "--topic",
        help="ROS bag: the sensor_msgs/Imu topic; PX4 ULog: the IMU topic (sensor_combined, "
        "sensor_gyro, sensor_accel, vehicle_imu)",
    )
    if stream:
        sp.add_argument(
            "--stream",
            action="store_true",
            help="stream a .npy/HDF5 log larger than memory in blocks (classical WV)",
        )


#: The help of the one-log ``input`` argument of ``check``, ``export`` and ``report``.
INPUT_HELP = "log file: CSV/TSV/text, NPY/NPZ, HDF5, ROS bag, PX4 .ulg, ArduPilot .bin, WV summary"
#: The help of ``--channels`` where it selects the channels to fit, each on its own.
CHANNELS_HELP = "channels separated by commas (default: all)"
#: The help of ``--weights`` where a sub-command says nothing more of it.
WEIGHTS_HELP = "weighting matrix: ci (default), identity, or efficient (two-step, V^-1)"


def add_wv_options(sp: argparse.ArgumentParser, *, robust: bool = False) -> None:
    """Add the WV options of a sub-command: ``--fs`` (sampling frequency in Hz), ``--levels``
    (number of WV levels J) and, with ``robust``, ``--robust`` and ``--eff`` (the robust
    WV and its efficiency)."""
    sp.add_argument("--fs", type=positive(float, "--fs"), help="sampling frequency in Hz")
    sp.add_argument("--levels", type=positive(int, "--levels"), help="number of WV levels J")
    if robust:
        sp.add_argument("--robust", action="store_true", help="robust (Tukey biweight) WV")
        sp.add_argument(
            "--eff",
            type=float,
            default=0.6,
            help="efficiency of the robust WV, in (0, 0.99) (default 0.6)",
        )


def add_weights_option(sp: argparse.ArgumentParser, help: str = WEIGHTS_HELP) -> None:
    """Add ``--weights {ci,identity,efficient}`` (default ci) to a sub-command."""
    sp.add_argument("--weights", default="ci", choices=["ci", "identity", "efficient"], help=help)


def add_bootstrap_options(
    sp: argparse.ArgumentParser, *, replicates: str, workers: str = "processes for the bootstrap"
) -> None:
    """Add ``-B/--bootstrap`` (100 replicates), ``--seed`` (0) and ``--workers`` (2) to a
    sub-command; ``replicates`` and ``workers`` are the help texts, before the default."""
    sp.add_argument(
        "-B", "--bootstrap", type=_replicates("-B"), default=100, help=f"{replicates} (100)"
    )
    sp.add_argument("--seed", type=int, default=0, help="bootstrap seed (0)")
    sp.add_argument("--workers", type=positive(int, "--workers"), default=2, help=f"{workers} (2)")


def _replicates(option: str) -> Callable[[str], int]:
    """An argparse type: a number of bootstrap replicates (``500`` or ``1e3``), checked by
    :func:`engine._limits.check_replicates` (a whole number from 2 to its maximum)."""

    def conv(text: str) -> int:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} must be a number, got {text!r}") from None
        if not (math.isfinite(v) and v == int(v)):
            raise argparse.ArgumentTypeError(
                f"{option} must be a whole number of replicates, got {text!r}"
            )
        try:
            return check_replicates(int(text) if text.strip().isdigit() else int(v))
        except ValueError as e:
            msg = f"{option} {text}: {e}".replace("B must", "must")
            raise argparse.ArgumentTypeError(msg) from None

    return conv


def bootstrap_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """``B``, ``seed`` and ``workers`` from the options of :func:`add_bootstrap_options`."""
    return {"B": args.bootstrap, "seed": args.seed, "workers": args.workers}


def log_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The :func:`engine.io.load_log` keyword arguments given on the command line."""
    return {
        k: getattr(args, k)
        for k in ("segment", "scale", "units", "topic", "segments")
        if getattr(args, k, None) is not None
    }


def stream_wv(
    args: argparse.Namespace, alpha: float = 0.05, channel: str | None = None
) -> tuple[Any, str]:
    """``(WaveletVariance, channel name)`` of ``--stream``."""
    from ..wv import open_series, wavelet_variance_stream

    if getattr(args, "robust", False):
        raise usage_error(
            "--stream computes the classical WV; the robust WV needs the whole "
            "log in memory (drop --robust or --stream)"
        )
    for opt in ("segment", "topic"):
        if getattr(args, opt, None) is not None:
            raise usage_error(
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
        from ..io import read_npy_sidecar

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
        raise usage_error(
            f"{args.input}: channel {name!r} is constant: there is no noise to analyse"
        )
    return wv, name


def warn_fs_unknown(args: argparse.Namespace, path: str) -> None:
    """Queue (:func:`queue_warning`) the loud warning that the sampling frequency of ``path``
    is unknown (1 Hz assumed)."""
    queue_warning(
        args,
        f"{path} does not say its sampling frequency: fs = 1 Hz ASSUMED, so every time in "
        "seconds and every datasheet value is per sample; pass --fs HZ",
    )


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


def check_output(
    path: str | os.PathLike[str] | None,
    option: str,
    *,
    kind: Literal["file", "dir"] = "file",
    suffixes: tuple[str, ...] = (),
    inputs: Iterable[str | os.PathLike[str] | None] = (),
) -> None:
    """Refuse an output path that cannot be written, or that is an input, before any
    computation.

    Every subcommand that writes (``simulate -o``, ``export -o``, ``virtual -o``, ``report -o``,
    ``batch -o DIR``, ``study -o DIR``) calls this first, so that a typo in a folder name
    costs a second, not the whole run.

    Parameters
    ----------
    path : path, None or ``"-"``
        The output as the user gave it; None (no output) and ``"-"`` (stdout) pass.
    option : str
        The option that gave it, for the message (``-o``).
    kind : {"file", "dir"}
        A file: its folder must exist and be writable, and the path must not be a folder.
        A folder (created with its parents when missing): it must not be a file, and its
        nearest existing ancestor must be a writable folder.
    suffixes : tuple of str
        File names must end with one of these (lower case), when given.
    inputs : iterable of paths
        The files the command reads (:func:`input_paths`): a file output that is one of them
        (the same file, through a symlink or a hard link too) is refused.

    Raises
    ------
    UsageError
        One line naming the option and the path as given, and what to do.
    """
    if path is None or str(path) == "-":
        return
    p = Path(path)
    if kind == "file":
        if p.is_dir():
            raise usage_error(f"{option} {path} is a folder: give a file name inside it")
        if suffixes and not str(path).lower().endswith(suffixes):
            names = ", ".join(suffixes[:-1]) + f" or {suffixes[-1]}" if len(suffixes) > 1 else ""
            raise usage_error(f"{option} {path}: use a {names or suffixes[0]} file name")
        folder = p.parent
        if not folder.is_dir():
            raise usage_error(
                f"{option} {path}: the folder {folder} does not exist"
                + (" (it is a file)" if folder.exists() else "")
                + "; create it or choose another path"
            )
        check_not_input(path, inputs, what=f"{option} {path}", error=UsageError)
        if p.exists() and not os.access(p, os.W_OK):
            raise usage_error(f"{option} {path}: the file exists and is not writable")
    else:
        if p.exists() and not p.is_dir():
            raise usage_error(f"{option} {path} is a file: give a folder (created if missing)")
        folder = p
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if not folder.is_dir():
            raise usage_error(
                f"{option} {path}: {folder} is a file, so the folder cannot be created"
            )
    if not _writable(folder):
        raise usage_error(
            f"{option} {path}: the folder {folder} is not writable; choose another path"
        )


def input_paths(args: argparse.Namespace) -> list[str]:
    """The files a command reads: its ``input`` or ``inputs`` (glob patterns expanded) and its
    ``--datasheet-file``."""
    found: list[str] = []
    for name in ("input", "inputs", "datasheet_file"):
        v = getattr(args, name, None)
        for item in [] if v is None else [v] if isinstance(v, (str, os.PathLike)) else v:
            found.append(str(item))
            if glob.has_magic(str(item)):
                found.extend(glob.glob(str(item)))
    return found


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (tried, not inferred from the mode bits:
    they do not tell about read-only mounts, ACLs or root)."""
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".gmwm-write-check-")
    except OSError:
        return False
    os.close(fd)
    os.unlink(name)
    return True


def sample_count(option: str, *, copies: int = 1) -> Any:
    """An argparse type: a number of samples to simulate (``100000`` or ``1e5``), checked by
    :func:`engine._limits.check_sample_count` (integer, >= 1, within the memory limit)."""

    def conv(text: str) -> int:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{option} must be a number of samples, got {text!r}"
            ) from None
        if not (math.isfinite(v) and v == int(v)):
            raise argparse.ArgumentTypeError(
                f"{option} must be a whole number of samples, got {text!r}"
            )
        k = int(text) if text.strip().lstrip("+").isdigit() else int(v)
        try:
            return check_sample_count(k, name=option, copies=copies)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    return conv


def queue_warning(args: argparse.Namespace, msg: str) -> None:
    """Queue a one-line warning; ``gmwm`` prints it as ``gmwm COMMAND: warning: MSG`` on
    stderr after the result (an error stays one line), once however often it was queued."""
    queued = getattr(args, "warnings", None)
    if queued is None:
        queued = args.warnings = []
    if msg not in queued:
        queued.append(msg)


def confidence(option: str, example: str = "0.95") -> Callable[[str], float]:
    """An argparse type: a number in (0, 1), e.g. 0.95 (``example`` in the message)."""

    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{option} must be a number in (0, 1), e.g. {example}, got {text!r}"
            ) from None
        if not 0 < v < 1:
            raise argparse.ArgumentTypeError(
                f"{option} must be in (0, 1), e.g. {example}, got {text!r}"
            )
        return v

    return conv


def add_confidence_option(
    sp: argparse.ArgumentParser, what: str, old: Literal["--level", "--alpha"] | None = None
) -> argparse.Action:
    """Add ``--confidence`` (default 0.95) to a sub-command, with its old spelling there as a
    deprecated alias: ``--level`` (the same number) or ``--alpha`` (1 - confidence); None for a
    command that never had another spelling. Only the command's own old spelling: elsewhere
    ``--level`` stays an abbreviation of ``--levels``."""
    new = sp.add_argument(
        "--confidence",
        type=confidence("--confidence"),
        default=0.95,
        metavar="C",
        help=f"confidence level of {what}, in (0, 1) (0.95)",
    )
    if old is None:
        return new
    if old == "--level":
        add_deprecated_alias(sp, "--level", new, type=confidence("--level"))
        return new
    add_deprecated_alias(
        sp,
        "--alpha",
        new,
        type=confidence("--alpha", "0.05"),
        convert=lambda a: 1.0 - a,
        note="1 - alpha",
    )
    return new


def alpha_of(confidence: float) -> float:
    """``1 - confidence`` rounded to 12 decimals, so that 0.95 gives the engine's ``alpha``
    0.05 as typed (not 0.050000000000000044)."""
    return round(1.0 - confidence, 12)


class DeprecatedAlias(argparse.Action):
    """An old spelling of an option: it still works (the value, converted, goes to the new
    option's destination) and queues a one-line message naming the new option."""

    def __init__(
        self,
        option_strings: list[str],
        dest: str,
        *,
        new: str,
        convert: Callable[[Any], Any] | None = None,
        note: str = "",
        **kwargs: Any,
    ) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.new, self.convert, self.note = new, convert, note

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        value = self.convert(values) if self.convert is not None else values
        setattr(namespace, self.dest, value)
        shown = f"{value:g}" if isinstance(value, float) else str(value)
        queue_warning(
            namespace,
            f"{option_string} is deprecated: use {self.new} {shown}"
            + (f" (= {self.note})" if self.note else ""),
        )


def add_deprecated_alias(
    container: Any,
    old: str,
    new: argparse.Action,
    *,
    type: Callable[[str], Any] | None = None,
    convert: Callable[[Any], Any] | None = None,
    note: str = "",
) -> argparse.Action:
    """Keep ``old`` as a deprecated spelling of the option ``new`` (an action returned by
    ``add_argument``); ``container`` is the parser or the mutually exclusive group that holds
    ``new``. Hidden from ``--help``; using it queues ``OLD is deprecated: use NEW VALUE``."""
    return container.add_argument(
        old,
        action=DeprecatedAlias,
        dest=new.dest,
        new="/".join(new.option_strings),
        convert=convert,
        note=note,
        type=type if type is not None else new.type,
        metavar=new.metavar,
        default=argparse.SUPPRESS,
        help=argparse.SUPPRESS,
    )
