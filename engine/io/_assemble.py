"""From raw columns to an :class:`~engine.io.log.ImuLog`: the steps every reader shares.

Attribute and unit parsing, the sampling-frequency check, the time column (checked by
:mod:`engine.io.timecheck`, then the segment policy), scale factors, the conversion to float
with NaN/Inf and magnitude checks, and the choice of ``fs`` (:func:`finish_log`). The module is
private to :mod:`engine.io`; its names are public for the readers (text, NPY, HDF5, bags).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _checks
from .._limits import check_memory
from .log import ImuLog, LoadError, pick_channel
from .timecols import spacing_divisor, time_divisor

__all__ = [
    "LoadOptions",
    "RawLog",
    "finish_log",
    "attr_value",
    "clean_unit",
    "units_map",
    "time_divisor",
    "check_fs",
    "ordered_names",
    "FS_KEYS",
    "UNIT_RE",
    "array_memory_need",
    "check_array_memory",
    "stored_size",
    "check_channel_count",
    "MAX_CHANNELS",
]

#: Most channels a log may have once one is selected (``channel=`` picks one of a wider
#: file). An IMU log has a handful; a file declaring 1e5 or 1e6 columns is refused before its
#: values are converted (each channel costs tens of microseconds of checks).
MAX_CHANNELS = 10_000

UNIT_RE = re.compile(r"(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*")
FS_KEYS = ("fs_hz", "fs", "sample_rate", "sampling_rate")
_NO_UNIT = {"", "unknown", "none", "n/a", "-", "?"}


def attr_value(v: Any) -> Any:
    """HDF5/NumPy attribute value as a plain Python value (None when not worth showing)."""
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.generic):
        return attr_value(v.item())
    if isinstance(v, np.ndarray):
        return [attr_value(x) for x in v.tolist()] if v.size <= 64 else None
    return v


def clean_unit(u: Any) -> str:
    u = str(attr_value(u)).strip() if u is not None else ""
    return "" if u.lower() in _NO_UNIT else u


def units_map(v: Any, src: str, notes: list[str]) -> dict[str, str]:
    """Parse a JSON ``units`` map (``{"gyro_x": "deg/s", ...}``); ignore it when malformed."""
    v = attr_value(v)
    if isinstance(v, str):
        try:
            v = json.loads(v)
        except json.JSONDecodeError:
            notes.append(f"the 'units' attribute of '{src}' is not a JSON map; units ignored")
            return {}
    return {str(k): clean_unit(x) for k, x in v.items()} if isinstance(v, dict) else {}


def check_fs(value: Any, src: str, what: str, fix: str) -> float:
    try:
        # a file's attribute or text, as a number; then the one check (engine._checks)
        return _checks.check_fs(value if isinstance(value, bool) else float(value))
    except (TypeError, ValueError):
        raise LoadError(
            f"file '{src}': {what} = {value!r} is not a valid sampling frequency "
            f"(it must be a finite number of Hz > 0, from {_checks.MIN_FS:g} to "
            f"{_checks.MAX_FS:g}): {fix}"
        ) from None


def ordered_names(names: list[str], units: Mapping[str, str]) -> list[str]:
    """Names in the order of the file's ``units`` map first (gyro_x..accel_z), then as found.

    Linear in the number of names (set look-ups): a file may declare 1e6 of them."""
    have = set(names)
    first = [k for k in units if k in have]
    seen = set(first)
    return first + [k for k in names if k not in seen]


def array_memory_need(shape: tuple[int, ...], dtype: np.dtype) -> int:
    """Peak memory (bytes) of reading an array of ``shape`` and ``dtype`` and making channels of
    it (:func:`finish_log`): the array, plus the float64 copy of integer, boolean or
    long-double data (or of each field of a structured array), else plus the contiguous copies
    of the columns of a 2-D ``(N, k)`` array. Measured with tracemalloc in
    tests/engine/test_io_safety.py."""
    dtype = np.dtype(dtype)
    count = math.prod(int(d) for d in shape)
    raw = count * dtype.itemsize
    if dtype.names:
        return raw + count * len(dtype.names) * 8
    if dtype.kind in "iub" or (dtype.kind == "f" and dtype.itemsize > 8):
        return raw + count * 8
    return 2 * raw if len(shape) == 2 and min(shape) > 1 else raw


def check_array_memory(need: int, src: str, what: str, stored: int | None = None) -> None:
    """LoadError when reading arrays that need ``need`` bytes (:func:`array_memory_need`)
    cannot fit in the available memory, or expand too far from the ``stored`` bytes of the
    file (see :func:`engine._limits.check_memory`)."""
    fix = "load one channel (channel=) of an HDF5 file, or compute the WV of a .npy/HDF5 log "
    fix += "in blocks (wavelet_variance_stream)"
    check_memory(need, src, what=what, fix=fix, error=LoadError, stored=stored)


def stored_size(path: Any) -> int:
    """Size (bytes) of a file given as a path or as content (``io.BytesIO``)."""
    if hasattr(path, "getbuffer"):
        return int(path.getbuffer().nbytes)
    return int(os.stat(path).st_size)


def check_channel_count(src: str, count: int, what: str = "columns") -> None:
    """LoadError when a file offers more than :data:`MAX_CHANNELS` channels at once."""
    if count > MAX_CHANNELS:
        raise LoadError(
            f"file '{src}' has {count} {what}, more than the {MAX_CHANNELS} channels a log may "
            "have: select one (channel=) or save the IMU channels in a file of their own"
        )


def _where(i: int, rows: np.ndarray | None) -> str:
    return f"line {int(rows[i])} (sample {i})" if rows is not None else f"sample {i}"


def _as_float(src: str, name: str, a: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
    """Float64 (float32 kept) contiguous copy, rejecting non-numeric data and NaN/Inf."""
    a = np.asarray(a)
    if a.dtype.kind in "iub" or (a.dtype.kind == "f" and a.dtype.itemsize > 8):
        a = a.astype(np.float64)
    elif a.dtype == np.float16:
        a = a.astype(np.float32)
    elif a.dtype.kind != "f":
        raise LoadError(
            f"file '{src}', column '{name}': dtype {a.dtype} is not real-valued numeric data: "
            "store the samples as integers or floats"
        )
    # NaN and Inf propagate to the extremes: two passes, no temporaries, for clean data
    finite = a.size == 0 or (math.isfinite(float(np.min(a))) and math.isfinite(float(np.max(a))))
    bad = np.flatnonzero(~np.isfinite(a)) if not finite else np.empty(0, dtype=np.intp)
    if bad.size:
        raise LoadError(
            f"file '{src}': column '{name}' has {bad.size} NaN/Inf value(s), first at "
            f"{_where(int(bad[0]), rows)}: remove or interpolate them"
        )
    return np.ascontiguousarray(a)


@dataclass(frozen=True)
class LoadOptions:
    """Loader options shared by every reader (see :func:`load_log`)."""

    fs_user: float | None = None
    segment: str | tuple[int, int] | None = None
    scale: float | Mapping[str, float] | None = None
    units: str | Mapping[str, str] | None = None
    topic: str | None = None


_SEGMENT_HELP = (
    "choose segment='longest' to analyse the longest "
    "clean segment, segment=(start, stop) for another one, or segment='report' to "
    "keep every sample as if uniformly spaced (samples joined across the breaks); "
    "or fix the log, or pass fs= to ignore the time column"
)


def _time_scale(name: str, t: np.ndarray, div: tuple[float, bool], notes: list[str]) -> float:
    """Divisor of the stamps to seconds; unitless stamps with huge steps are nanoseconds."""
    scale, explicit = div
    if explicit:
        return scale
    with np.errstate(invalid="ignore"):
        d = np.diff(np.asarray(t[: min(t.size, 100_001)], dtype=np.float64))
    pos = d[d > 0]
    med = float(np.median(pos)) if pos.size else 0.0
    guess = spacing_divisor(med)  # (engine.io.timecols: the unit from the spacing)
    if guess is not None:
        notes.append(
            f"time column '{name}' has a median step of {med:g}: read as {guess[1]} "
            f"({guess[0] / med:.6g} Hz; name it time_s, time_ms, time_us or time_ns, or pass "
            "fs=, to be explicit)"
        )
        return guess[0]
    return scale


def _check_known(src: str, what: str, given: Mapping[Any, Any], names: list[str]) -> None:
    """LoadError naming the keys of a per-channel ``what`` mapping that are not channels."""
    have = set(names)
    unknown = [k for k in given if k not in have]
    if unknown:
        raise LoadError(
            f"file '{src}': {what} given for unknown channel(s) {unknown}; "
            f"channels: {', '.join(names)}"
        )


def _check_scale(src: str, scale: Any, names: list[str]) -> dict[str, float]:
    """Per-channel scale factors from a number or a {channel: factor} mapping."""

    def num(v: Any, what: str) -> float:
        try:
            f = float(v)
        except (TypeError, ValueError):
            f = math.nan
        if isinstance(v, bool) or not math.isfinite(f) or f == 0:
            raise LoadError(
                f"file '{src}': {what} = {v!r} is not a valid scale factor (a finite, "
                "non-zero number of units per count, e.g. scale=0.05)"
            )
        return f

    if isinstance(scale, Mapping):
        _check_known(src, "scale", scale, names)
        return {str(k): num(v, f"scale[{k!r}]") for k, v in scale.items()}
    s = num(scale, "scale")
    return dict.fromkeys(names, s)


def _apply_time(
    src: str,
    cols: dict[str, Any],
    n: int,
    time: tuple[str, np.ndarray, tuple[float, bool]],
    rows: np.ndarray | None,
    opts: LoadOptions,
    notes: list[str],
    meta: dict[str, Any],
) -> tuple[dict[str, Any], np.ndarray | None, float]:
    """Check the time column, apply the segment policy; return (cols, rows, fs of the stamps)."""
    from .timecheck import check_time, segment_fs

    name, t, div = time
    scale = _time_scale(name, t, div, notes)
    rep = check_time(t, scale=scale, rows=rows, column=name)
    meta["time_report"] = rep.to_dict()
    policy = opts.segment
    if policy is None:
        policy = "report" if opts.fs_user is not None else "stop"
    if isinstance(policy, str) and policy not in ("stop", "longest", "report"):
        raise LoadError(
            f"file '{src}': segment={policy!r} is not a choice: use 'stop', "
            "'longest', 'report' or a (start, stop) pair of sample indices"
        )
    if rep.jitter > 0.01:
        notes.append(
            f"time column '{name}' jitters: the regular steps vary by "
            f"{100 * rep.jitter:.3g} % (relative std); samples are treated as "
            "uniformly spaced"
        )
    ts = None
    if not isinstance(policy, str):
        a, b = _segment_range(src, policy, n)
        inside = [
            e for e in rep.events if a < e.index < b or (e.kind == "invalid" and a <= e.index < b)
        ]
        if inside:
            raise LoadError(
                f"file '{src}': segment=({a}, {b}) is not clean: "
                f"{inside[0].describe()}; clean segments are listed in the time "
                "report (segment='report' keeps every sample)"
            )
        sel = (a, b)
    elif rep.ok or policy == "report":
        sel = (0, n)
        if not rep.ok:
            notes.append(
                f"{rep.message()}; segment='report': every sample kept as if "
                "uniformly spaced (samples joined across the breaks)"
            )
    elif policy == "longest":
        sel = rep.longest
        notes.append(
            f"{rep.message()}; segment='longest': samples {sel[0]} to {sel[1] - 1} "
            "analysed, the rest dropped"
        )
    else:
        raise LoadError(f"file '{src}': {rep.message()}. To go on, {_SEGMENT_HELP}")
    if sel != (0, n):
        cols = {k: _slice(v, *sel) for k, v in cols.items()}
        rows = None if rows is None else rows[sel[0] : sel[1]]
        meta["segment"] = [int(sel[0]), int(sel[1])]
        ts = np.asarray(t[sel[0] : sel[1]])
    if rep.ok or sel != (0, n):
        from .timecheck import as_seconds

        fs = segment_fs(as_seconds(ts if ts is not None else t, scale))
    else:  # report mode across breaks: the median step
        fs = float(f"{1.0 / rep.median_step:.12g}") if rep.median_step > 0 else math.nan
    return cols, rows, fs


def _check_magnitude(src: str, name: str, x: np.ndarray) -> None:
    """Refuse samples so large that the squares in a variance overflow float64."""
    if x.size and x.dtype.itemsize == 8:
        big = max(float(np.max(x)), -float(np.min(x)))  # no |x| temporary
        if big * x.size > 1e150:
            raise LoadError(
                f"file '{src}', column '{name}': values up to {big:.3g} are too large "
                "for a variance in float64 (their squares overflow): check the units "
                "or the scale factor"
            )


def _segment_range(src: str, segment: Any, n: int) -> tuple[int, int]:
    """Validate an explicit ``segment=(start, stop)``."""
    try:
        a, b = (int(v) for v in segment)
    except (TypeError, ValueError):
        raise LoadError(
            f"file '{src}': segment={segment!r} is not a (start, stop) pair of sample indices"
        ) from None
    if not 0 <= a < b <= n:
        raise LoadError(
            f"file '{src}': segment=({a}, {b}) is outside the log's samples "
            f"0..{n}: give 0 <= start < stop <= {n}"
        )
    return a, b


def _slice(a: Any, start: int, stop: int) -> Any:
    if callable(a):
        return lambda: a()[start:stop]
    return a[start:stop]


def _length(a: Any) -> int:
    shape = getattr(a, "shape", None)
    if shape is not None and len(shape) >= 1:
        return int(shape[0])
    return int(np.asarray(a() if callable(a) else a).shape[0])


@dataclass
class RawLog:
    """What a reader found in a file, before :func:`finish_log` selects, checks and converts it.

    Attributes
    ----------
    cols : dict
        Channel name to an array, or to a zero-argument callable returning one (lazy HDF5).
    units : dict
        Channel name to its unit as written in the file.
    fs_file : (value, where) or None
        A sampling frequency the file states, and where (for messages).
    time : (name, stamps, (divisor, integer)) or None
        A time column (:func:`time_divisor` gives the divisor to seconds).
    rows : ndarray or None
        File line of every sample (text logs), for messages.
    meta, notes : dict, list of str
        Metadata for ``ImuLog.meta`` and the reader's notes.
    aux : list of str
        Names in ``cols`` that are auxiliary channels (temperatures: ``ImuLog.aux``).
    """

    cols: dict[str, Any] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    fs_file: tuple[Any, str] | None = None
    time: tuple[str, np.ndarray, tuple[float, bool]] | None = None
    rows: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    aux: list[str] = field(default_factory=list)


def finish_log(
    src: str, raw: RawLog, *, fmt: str, channel: str | int | None, opts: LoadOptions
) -> ImuLog:
    """Select, check the time column, convert and scale the channels, resolve fs, build the log.

    ``raw.cols`` values are arrays or zero-argument callables returning arrays (lazy HDF5
    reads).
    """
    cols, units, fs_file, time, rows = raw.cols, raw.units, raw.fs_file, raw.time, raw.rows
    notes = raw.notes
    meta = {"format": fmt, **raw.meta}
    if not cols:
        raise LoadError(
            f"file '{src}' contains no numeric channel: expected 1-D numeric "
            "columns/datasets of samples"
        )
    if channel is not None:
        name = pick_channel(src, [k for k in cols if k not in raw.aux], channel)
        cols = {k: cols[k] for k in cols if k == name or k in raw.aux}
    check_channel_count(src, len(cols), "channels")
    n = _length(next(iter(cols.values())))
    fs_time = None
    if time is not None:
        meta["time_column"] = time[0]
        if np.asarray(time[1]).shape == (n,):
            cols, rows, fs_time = _apply_time(src, cols, n, time, rows, opts, notes, meta)
        else:
            notes.append(
                f"time column '{time[0]}' has {np.asarray(time[1]).size} stamps for "
                f"{n} samples: ignored"
            )
            time = None
    if time is None and opts.segment is not None and not isinstance(opts.segment, str):
        a, b = _segment_range(src, opts.segment, n)  # a sample range, without time stamps
        cols = {k: _slice(v, a, b) for k, v in cols.items()}
        rows = None if rows is None else rows[a:b]
        meta["segment"] = [a, b]
    elif time is None and opts.segment not in (None, "stop", "longest", "report"):
        raise LoadError(
            f"file '{src}': segment={opts.segment!r} is not a choice: use 'stop', "
            "'longest', 'report' or a (start, stop) pair of sample indices"
        )
    scales = {} if opts.scale is None else _check_scale(src, opts.scale, list(cols))
    out: dict[str, np.ndarray] = {}
    for name, a in cols.items():
        x = _as_float(src, name, a() if callable(a) else a, rows)
        if name in scales:
            with np.errstate(over="ignore", invalid="ignore"):  # checked just below
                x = np.multiply(x, scales[name], dtype=np.float64)  # counts x scale: 1 rounding
            if not np.all(np.isfinite(x)):
                raise LoadError(
                    f"file '{src}', column '{name}': the scale factor "
                    f"{scales[name]:g} makes values overflow: check it"
                )
        _check_magnitude(src, name, x)
        out[name] = x
    if scales:
        meta["scale"] = {k: scales[k] for k in out if k in scales}
    n = next(iter(out.values())).size
    if n < 4:
        what = " in the selected segment" if "segment" in meta else " per channel"
        raise LoadError(
            f"file '{src}' has only {n} sample(s){what}: a wavelet variance "
            "needs at least 4 (a static log of minutes to hours is typical)"
        )
    if opts.fs_user is not None:
        fs, fs_source = opts.fs_user, "user"
    elif fs_file is not None:
        fix = "fix it in the file, or pass fs= to override it"
        fs, fs_source = check_fs(fs_file[0], src, fs_file[1], fix), "file"
        if fs_time is not None and math.isfinite(fs_time) and abs(fs_time / fs - 1) > 0.01:
            notes.append(
                f"the time column gives {fs_time:g} Hz but {fs_file[1]} says {fs:g} Hz; "
                "the file's value is used"
            )
    elif fs_time is not None and math.isfinite(fs_time):
        fs, fs_source = fs_time, "time column"
    else:
        fs, fs_source = 1.0, "default"
        notes.append("no sampling frequency in the file: fs = 1 Hz assumed (pass fs= to set it)")
    unit_map = {k: clean_unit(units.get(k, "")) for k in out}
    if opts.units is not None:
        if isinstance(opts.units, Mapping):
            _check_known(src, "units", opts.units, list(out))
            unit_map.update({str(k): clean_unit(v) for k, v in opts.units.items()})
        else:
            unit_map = dict.fromkeys(out, clean_unit(opts.units))
    if notes:
        meta["notes"] = notes
    aux = {k: out.pop(k) for k in raw.aux if k in out}  # (their units stay in unit_map)
    return ImuLog(
        channels=out, fs=fs, fs_source=fs_source, units=unit_map, source=src, meta=meta, aux=aux
    )
