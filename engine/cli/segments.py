"""``gmwm segments`` (:func:`add_parser`, :func:`run`): the still segments of a flight log::

    gmwm segments LOG [--window S] [--threshold K] [--min-length S] [--json]

Lists the still parts of a log (:func:`engine.io.segments.still_segments`: moving standard
deviation of the gyroscopes and accelerometers against their still floor) as sample ranges
and times, and the ``--segments`` value that analyses them (every command takes
``--segments auto|LIST``).
"""

from __future__ import annotations

import argparse
from typing import Any

from ..io import load_log
from ..io.segments import still_segments
from .common import add_log_options, log_kwargs, positive

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``segments`` sub-command to the ``gmwm`` sub-parsers."""
    sp = sub.add_parser("segments")
    sp.add_argument("input", help="log file (.ulg, .bin, CSV, HDF5, ...)")
    sp.add_argument(
        "--fs", type=positive(float, "--fs"), help="sampling frequency in Hz (default: the file's)"
    )
    sp.add_argument(
        "--window",
        type=positive(float, "--window"),
        default=1.0,
        help="still segments: the window of the moving deviation (s), 1",
    )
    sp.add_argument(
        "--threshold",
        type=positive(float, "--threshold"),
        default=3.0,
        help="still segments: moving when the window's deviation exceeds K x the still floor (3)",
    )
    sp.add_argument(
        "--min-length",
        type=positive(float, "--min-length"),
        default=5.0,
        help="still segments: the shortest kept (s), 5",
    )
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    add_log_options(sp, stream=False)
    return sp


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """The segments as a JSON-ready dict or a table."""
    kw = {k: v for k, v in log_kwargs(args).items() if k != "segments"}
    log = load_log(args.input, fs=args.fs, **kw)
    segs = still_segments(
        log, window_s=args.window, threshold=args.threshold, min_s=args.min_length
    )
    fs = log.fs
    rows = [{"start": a, "stop": b, "start_s": a / fs, "duration_s": (b - a) / fs} for a, b in segs]
    still = sum(b - a for a, b in segs)
    out = {
        "file": args.input,
        "fs": fs,
        "n": log.n,
        "segments": rows,
        "still_fraction": still / log.n,
        "option": "--segments " + ",".join(f"{a}:{b}" for a, b in segs) if segs else "",
    }
    if args.json:
        return out
    lines = [
        f"{args.input}: {len(segs)} still segment(s), {still / fs:.1f} s of {log.n / fs:.1f} s "
        f"({100 * still / log.n:.0f} %) at {fs:g} Hz",
        f"{'start [sample]':>15} {'stop [sample]':>14} {'start [s]':>10} {'length [s]':>11}",
    ]
    lines += [
        f"{r['start']:>15d} {r['stop']:>14d} {r['start_s']:>10.2f} {r['duration_s']:>11.2f}"
        for r in rows
    ]
    if segs:
        lines.append(f"analyse them with --segments auto, or {out['option']}")
    return "\n".join(lines)
